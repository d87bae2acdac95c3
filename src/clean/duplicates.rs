//! Duplicate triangles: triangles over the same three points, in either winding.
//!
//! Triangles are sorted by their sorted point triple (points are already welded,
//! so near-duplicates that coincide after welding are found too). In each group
//! the lowest triangle index is kept. A member whose cyclic order is opposite to
//! the kept one is a *flipped* duplicate.
//!
//! Two-sided sheets: by default a flipped duplicate is removed. The baker handles
//! two-sidedness itself (|n·ω| in window mode, ray origins pushed to the side the
//! ray leaves from), and a coincident twin only risks self-shadowing. With
//! `keep_two_sided` the lowest-index member of each winding is kept, so a sheet
//! modelled as two faces back to back survives.

use super::work::Work;
use crate::mesh::Mesh;

/// What [`remove_duplicates`] removed.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct DuplicateCounts {
    /// Same winding as the kept triangle.
    pub same: usize,
    /// Opposite winding.
    pub flipped: usize,
    /// Of the above, those whose input corner positions were not bit-identical.
    pub near: usize,
    /// Total area of the removed triangles.
    pub area: f64,
}

/// Removes duplicate live triangles (see the module doc for the keep-rule).
/// `input` is the mesh the triangles' origins refer to.
pub(crate) fn remove_duplicates(work: &mut Work, input: &Mesh, keep_two_sided: bool) -> DuplicateCounts {
    let mut keyed: Vec<([u32; 3], bool, u32)> = (0..work.tris.len())
        .filter(|&t| work.tri_alive[t])
        .map(|t| {
            let (key, parity) = canonical(work.tri_points(t));
            (key, parity, t as u32)
        })
        .collect();
    keyed.sort_unstable();
    let mut counts = DuplicateCounts::default();
    for group in keyed.chunk_by(|a, b| a.0 == b.0) {
        // Sorted by (key, parity, index): re-sort by index so the lowest index wins.
        let mut members: Vec<(bool, u32)> = group.iter().map(|g| (g.1, g.2)).collect();
        members.sort_unstable_by_key(|m| m.1);
        let (keep_parity, keep_tri) = members[0];
        let mut kept_opposite = false;
        for &(parity, t) in &members[1..] {
            let flipped = parity != keep_parity;
            if flipped && keep_two_sided && !kept_opposite {
                kept_opposite = true;
                continue;
            }
            work.tri_alive[t as usize] = false;
            counts.area += work.tri_area(t as usize);
            if flipped {
                counts.flipped += 1;
            } else {
                counts.same += 1;
            }
            let origin_t = work.tri_origin[t as usize] as usize;
            let origin_k = work.tri_origin[keep_tri as usize] as usize;
            if input_corner_bits(input, origin_t) != input_corner_bits(input, origin_k) {
                counts.near += 1;
            }
        }
    }
    counts
}

/// The sorted point triple and the winding parity (true when the cyclic order,
/// started at the smallest id, ascends).
fn canonical(p: [u32; 3]) -> ([u32; 3], bool) {
    let start = (0..3).min_by_key(|&i| p[i]).unwrap_or(0);
    let (x, y) = (p[(start + 1) % 3], p[(start + 2) % 3]);
    let mut key = p;
    key.sort_unstable();
    (key, x < y)
}

/// The bit patterns of an input triangle's corner positions, sorted.
fn input_corner_bits(input: &Mesh, t: usize) -> Vec<[u32; 3]> {
    let mut bits: Vec<[u32; 3]> =
        input.indices[3 * t..3 * t + 3].iter().map(|&v| input.positions[v as usize].to_array().map(f32::to_bits)).collect();
    bits.sort_unstable();
    bits
}
