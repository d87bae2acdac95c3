//! Splitting chosen edges of a finished mesh, for adaptive refinement
//! (`crate::refine`): the bake says where light changes, this splits there.
//!
//! The chosen edges are closed over longest edges first (Rivara's
//! longest-edge bisection): a triangle with a chosen side also splits its
//! longest side, and so on until no triangle has a chosen side that is not
//! its longest or a longest side that is not chosen. Then every chosen edge
//! is split at its midpoint in all triangles that use it (the red-green
//! patterns of `--max-edge`), so no T-junction appears and repeated
//! refinement keeps the smallest angles bounded away from zero.
//!
//! Edges are point edges (a hard edge's two vertices at one position are one
//! edge), so both sides of a crease split together. The input's vertices keep
//! their ids and attributes; new ones are appended and interpolate theirs.

use std::collections::HashSet;

use super::work::Work;
use super::{refine, weld, write_vertices};
use crate::mesh::Mesh;

/// A mesh after [`split_edges`].
#[derive(Clone, Debug)]
pub struct EdgeSplit {
    /// Vertices `0..input.vertex_count()` are the input's, unchanged; the rest are new.
    pub mesh: Mesh,
    /// Point edges split (the chosen ones and the longest edges they pulled in).
    pub edges_split: usize,
    /// Per output triangle: true when it is not an input triangle left as it was.
    pub changed_triangles: Vec<bool>,
}

/// Splits the edges `edges` (vertex pairs of `mesh`, in any order and
/// orientation; pairs that are not an edge of a triangle are ignored),
/// closed over longest edges as the module doc says.
pub fn split_edges(mesh: &Mesh, edges: &[[u32; 2]]) -> EdgeSplit {
    let mut work = weld::weld_points(mesh, 0.0);
    let point_pair = |a: u32, b: u32| {
        let (pa, pb) = (work.vertex_point[a as usize], work.vertex_point[b as usize]);
        (pa.min(pb), pa.max(pb))
    };
    let mut chosen: HashSet<(u32, u32)> = edges.iter().map(|&[a, b]| point_pair(a, b)).filter(|(a, b)| a != b).collect();
    close_over_longest_edges(&work, &mut chosen);
    let before = work.tris.clone();
    let edges_split = refine::split_marked_edges(&mut work, |_, lo, hi| chosen.contains(&(lo, hi)));
    let changed_triangles = (0..work.tris.len()).map(|t| before.get(t) != Some(&work.tris[t])).collect();
    let used = vec![true; work.vertex_point.len()];
    EdgeSplit { mesh: write_vertices(&work, mesh, &used), edges_split, changed_triangles }
}

/// Adds to `chosen` the longest side of every triangle with a chosen side,
/// until that holds for every triangle (ties: the smaller point pair).
fn close_over_longest_edges(work: &Work, chosen: &mut HashSet<(u32, u32)>) {
    let sides = |t: usize| {
        let p = work.tri_points(t);
        [0, 1, 2].map(|c| (p[c].min(p[(c + 1) % 3]), p[c].max(p[(c + 1) % 3])))
    };
    let length = |(a, b): (u32, u32)| work.points[a as usize].as_dvec3().distance(work.points[b as usize].as_dvec3());
    loop {
        let mut added = false;
        for t in 0..work.tris.len() {
            let s = sides(t);
            if s.iter().any(|e| e.0 == e.1) || !s.iter().any(|e| chosen.contains(e)) {
                continue;
            }
            let longest = s.into_iter().max_by(|&x, &y| length(x).total_cmp(&length(y)).then(y.cmp(&x))).unwrap_or(s[0]);
            added |= chosen.insert(longest);
        }
        if !added {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::builder::MeshBuilder;
    use crate::mesh::Material;
    use glam::Vec3;

    /// A `size`-square floor of `n`×`n` cells facing +Y, corner at the origin.
    fn grid(n: u32, size: f32) -> Mesh {
        let mut b = MeshBuilder::new(vec![Material::opaque("grey", 0.5)]);
        b.grid("floor", Vec3::ZERO, Vec3::Z * size, Vec3::X * size, n, n, |_, _| 0);
        b.mesh
    }

    fn boundary_and_non_manifold(mesh: &Mesh) -> (usize, usize) {
        let work = weld::weld_points(mesh, 0.0);
        super::super::work::count_boundary_and_non_manifold(&work)
    }

    #[test]
    fn a_split_keeps_the_surface_and_its_old_vertices() {
        let mesh = grid(4, 4.0);
        let before = boundary_and_non_manifold(&mesh);
        // One interior edge: its two triangles and the longest-edge closure split.
        let [a, b, _] = mesh.triangle(5);
        let s = split_edges(&mesh, &[[a, b]]);
        assert!(s.edges_split >= 1);
        assert_eq!(&s.mesh.positions[..mesh.vertex_count()], &mesh.positions[..]);
        assert_eq!(&s.mesh.normals[..mesh.vertex_count()], &mesh.normals[..]);
        assert!(s.mesh.vertex_count() > mesh.vertex_count());
        // Exact split: same area, no new boundary (no T-junction), still manifold.
        assert!((s.mesh.area() - mesh.area()).abs() < 1e-9 * mesh.area());
        let after = boundary_and_non_manifold(&s.mesh);
        assert_eq!(after.1, 0);
        assert!(after.0 >= before.0 && after.0 <= before.0 + 2, "boundary edges {before:?} -> {after:?}");
        let changed = s.changed_triangles.iter().filter(|&&c| c).count();
        assert_eq!(s.changed_triangles.len(), s.mesh.triangle_count());
        assert!(changed >= 4 && changed < s.mesh.triangle_count());
    }

    #[test]
    fn repeated_splits_keep_angles_bounded() {
        // Split the edges at one corner 12 times: longest-edge bisection keeps
        // the smallest angle at least half the input's (45° right triangles here).
        let mut mesh = grid(2, 1.0);
        for _ in 0..12 {
            let corner = (0..mesh.vertex_count()).find(|&v| mesh.positions[v].length() < 1e-9).map(|v| v as u32);
            let corner = corner.unwrap_or(0);
            let edges: Vec<[u32; 2]> = (0..mesh.triangle_count())
                .flat_map(|t| {
                    let v = mesh.triangle(t);
                    [0, 1, 2].map(|c| [v[c], v[(c + 1) % 3]])
                })
                .filter(|e| e.contains(&corner))
                .collect();
            mesh = split_edges(&mesh, &edges).mesh;
        }
        let smallest = (0..mesh.triangle_count())
            .map(|t| super::super::work::min_angle(mesh.triangle_positions(t).map(|p| p.as_dvec3())))
            .fold(f64::INFINITY, f64::min);
        assert!(smallest.to_degrees() > 22.5 - 1e-6, "smallest angle {}", smallest.to_degrees());
        assert_eq!(boundary_and_non_manifold(&mesh).1, 0);
    }
}
