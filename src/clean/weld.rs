//! Welding: positions closer than a tolerance become one point; vertices at one
//! point merge when their attributes agree, so hard edges and UV seams survive.
//!
//! After meshoptimizer's `meshopt_generateVertexRemap`: a remap table, then the
//! buffers rewritten through it. Representatives are the smallest original index,
//! and a representative keeps its own attributes (no averaging), so welding a
//! welded mesh changes nothing.

use super::spatial::{cluster_points, find, union};
use super::work::{edge_runs, sorted_edges, EdgeUse, Work};
use crate::mesh::Mesh;
use std::collections::{HashMap, HashSet};

/// Two vertices at one point keep separate UVs when these differ by more (UV units).
pub(crate) const UV_WELD_TOLERANCE: f32 = 1e-4;
/// Two vertices at one point keep separate colours when a channel differs by more.
pub(crate) const COLOR_WELD_TOLERANCE: f32 = 1e-4;

/// Builds the working mesh from `mesh`, clustering positions within `tol`
/// (any two closer than `tol` share a point, transitively; the point sits at the
/// position of the smallest vertex index in its cluster).
///
/// Precondition: `mesh` passed [`Mesh::validate`].
pub(crate) fn weld_points(mesh: &Mesh, tol: f32) -> Work {
    let ids: Vec<u32> = (0..mesh.positions.len() as u32).collect();
    let rep = cluster_points(&mesh.positions, &ids, tol);
    // Point ids in order of their representative vertex: older geometry keeps lower ids.
    let mut point_of_rep = vec![u32::MAX; mesh.positions.len()];
    let mut points = Vec::new();
    let mut vertex_point = Vec::with_capacity(mesh.positions.len());
    for (v, &r) in rep.iter().enumerate() {
        if r as usize == v {
            point_of_rep[v] = points.len() as u32;
            points.push(mesh.positions[v]);
        }
        vertex_point.push(point_of_rep[r as usize]);
    }
    let tris: Vec<[u32; 3]> = mesh.indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let n = tris.len();
    Work {
        points,
        vertex_point,
        normals: mesh.normals.clone(),
        uvs: mesh.uvs.clone(),
        lightmap_uvs: mesh.lightmap_uvs.clone(),
        colors: mesh.colors.clone(),
        tris,
        tri_material: mesh.tri_material.clone(),
        tri_group: mesh.tri_group.clone(),
        tri_origin: (0..n as u32).collect(),
        tri_alive: vec![true; n],
    }
}

/// How [`merge_vertices`] treats wedges (see [`corner_wedges`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Seams {
    /// Merge at a point whatever the wedges (the default clean).
    Ignore,
    /// Merge only vertices of one wedge (a vertex's wedge: its first corner's).
    Keep,
    /// Split vertices per wedge first ([`split_wedges`]), then as `Keep`.
    Split,
}

/// Merges vertices that share a point and whose normals differ by at most the hard-edge
/// angle (`cos_hard_edge` is its cosine) and whose UVs and colours agree within
/// [`UV_WELD_TOLERANCE`] / [`COLOR_WELD_TOLERANCE`]. Returns the number of vertices
/// merged into another, and the number of copies [`split_wedges`] made.
///
/// With [`Seams::Split`], vertices are first split per wedge ([`split_wedges`]);
/// with it or [`Seams::Keep`], only vertices of one wedge merge: the sides of a
/// cut stay apart (see [`super::intersect`]), however alike their attributes.
///
/// Only vertices used by live triangles take part (unused ones are dropped on output).
///
/// Greedy and deterministic: within a point, vertices are visited by index and each
/// joins the first earlier representative it agrees with (so agreement never chains).
pub(crate) fn merge_vertices(work: &mut Work, cos_hard_edge: f32, seams: Seams, cut_seams: &SeamEdges) -> (usize, usize) {
    let split = if seams == Seams::Split { split_wedges(work, cut_seams) } else { 0 };
    let wedge = if seams == Seams::Ignore { vec![0; work.vertex_point.len()] } else { vertex_wedges(work, cut_seams) };
    let mut used = vec![false; work.vertex_point.len()];
    for (tri, _) in work.tris.iter().zip(&work.tri_alive).filter(|(_, &alive)| alive) {
        tri.iter().for_each(|&v| used[v as usize] = true);
    }
    let key = |v: u32| (work.vertex_point[v as usize], wedge[v as usize]);
    let mut order: Vec<u32> = (0..work.vertex_point.len() as u32).filter(|&v| used[v as usize]).collect();
    order.sort_unstable_by_key(|&v| (key(v), v));
    let mut remap: Vec<u32> = (0..work.vertex_point.len() as u32).collect();
    let mut merged = 0;
    let mut reps: Vec<u32> = Vec::new();
    for group in order.chunk_by(|&a, &b| key(a) == key(b)) {
        reps.clear();
        for &v in group {
            match reps.iter().find(|&&r| attributes_agree(work, r, v, cos_hard_edge)) {
                Some(&r) => {
                    remap[v as usize] = r;
                    merged += 1;
                }
                None => reps.push(v),
            }
        }
    }
    if merged > 0 {
        work.remap_vertices(&remap);
    }
    (merged, split)
}

/// Point edges along which a cut separates a surface (lower point id first):
/// wedges do not join across them ([`super::intersect::find_seams`]).
pub(crate) type SeamEdges = HashSet<(u32, u32)>;

/// Wedges: around each point, the corners of the live triangles joined across
/// manifold edges (exactly two users) that are not in `cut_seams`. A cut
/// line is such a seam (the cut surface's two sides share it, the cutting
/// surface does not), so it separates wedges, as a boundary does; so does a
/// non-manifold edge or a bow-tie point. Returns the wedge of every corner
/// (`3 t + c`) as the smallest corner index in it; collapsed triangles'
/// corners are wedges of their own.
pub(crate) fn corner_wedges(work: &Work, cut_seams: &SeamEdges) -> Vec<u32> {
    let mut parent: Vec<u32> = (0..3 * work.tris.len() as u32).collect();
    let edges = sorted_edges(work);
    let corner_at = |e: &EdgeUse, p: u32| {
        let c = e.corner as u32;
        let start = if e.forward { e.lo } else { e.hi };
        3 * e.tri + if p == start { c } else { (c + 1) % 3 }
    };
    for run in edge_runs(&edges) {
        if let [e, f] = run {
            if collapsed(work, e.tri as usize) || collapsed(work, f.tri as usize) || cut_seams.contains(&(e.lo, e.hi)) {
                continue;
            }
            for p in [e.lo, e.hi] {
                union(&mut parent, corner_at(e, p), corner_at(f, p));
            }
        }
    }
    (0..parent.len() as u32).map(|c| find(&mut parent, c)).collect()
}

/// Gives each vertex used in several wedges ([`corner_wedges`]) one copy per
/// extra wedge (the wedge of its first corner keeps it), so that no vertex
/// spans a cut line; returns the number of copies. Collapsed triangles are
/// left alone (they are about to be removed).
pub(crate) fn split_wedges(work: &mut Work, cut_seams: &SeamEdges) -> usize {
    let wedge = corner_wedges(work, cut_seams);
    let mut first_wedge: Vec<u32> = vec![u32::MAX; work.vertex_point.len()];
    let mut copies: HashMap<(u32, u32), u32> = HashMap::new();
    let mut split = 0;
    for t in 0..work.tris.len() {
        if !work.tri_alive[t] || collapsed(work, t) {
            continue;
        }
        for c in 0..3 {
            let v = work.tris[t][c];
            let w = wedge[3 * t + c];
            if first_wedge[v as usize] == u32::MAX {
                first_wedge[v as usize] = w;
            }
            if first_wedge[v as usize] != w {
                let copy = *copies.entry((v, w)).or_insert_with(|| {
                    split += 1;
                    work.push_vertex_copy(v)
                });
                work.tris[t][c] = copy;
            }
        }
    }
    split
}

/// The wedge of each vertex: that of its first live corner ([`corner_wedges`]),
/// `u32::MAX` for a vertex no live triangle uses.
fn vertex_wedges(work: &Work, cut_seams: &SeamEdges) -> Vec<u32> {
    let wedge = corner_wedges(work, cut_seams);
    let mut of = vec![u32::MAX; work.vertex_point.len()];
    for t in (0..work.tris.len()).filter(|&t| work.tri_alive[t]) {
        for c in 0..3 {
            let v = work.tris[t][c] as usize;
            if of[v] == u32::MAX {
                of[v] = wedge[3 * t + c];
            }
        }
    }
    of
}

fn collapsed(work: &Work, t: usize) -> bool {
    let [a, b, c] = work.tri_points(t);
    a == b || b == c || c == a
}

fn attributes_agree(work: &Work, a: u32, b: u32, cos_hard_edge: f32) -> bool {
    let (a, b) = (a as usize, b as usize);
    let (na, nb) = (work.normals[a], work.normals[b]);
    let (la, lb) = (na.length(), nb.length());
    let normals_agree = if la == 0.0 || lb == 0.0 { la == lb } else { na.dot(nb) >= cos_hard_edge * la * lb };
    let uvs_agree = work.uvs.is_empty() || work.uvs[a].abs_diff_eq(work.uvs[b], UV_WELD_TOLERANCE);
    // A lightmap chart's border stays a seam: welding across it would pull
    // one chart's corner into another's texels.
    let lightmap_agree = work.lightmap_uvs.is_empty() || work.lightmap_uvs[a].abs_diff_eq(work.lightmap_uvs[b], UV_WELD_TOLERANCE);
    let colors_agree = work.colors.is_empty() || (0..3).all(|i| (work.colors[a][i] - work.colors[b][i]).abs() <= COLOR_WELD_TOLERANCE);
    normals_agree && uvs_agree && lightmap_agree && colors_agree
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Material;
    use glam::Vec3;

    fn two_vertices(n1: Vec3, n2: Vec3) -> Mesh {
        Mesh {
            positions: vec![Vec3::ZERO, Vec3::new(1e-9, 0.0, 0.0), Vec3::X, Vec3::Z],
            normals: vec![n1, n2, Vec3::Y, Vec3::Y],
            indices: vec![0, 2, 3, 1, 3, 2],
            tri_material: vec![0, 0],
            tri_group: vec![0, 0],
            materials: vec![Material::opaque("m", 0.5)],
            groups: vec!["g".into()],
            ..Default::default()
        }
    }

    #[test]
    fn hard_edges_stay_apart_and_soft_ones_merge() {
        let cos60 = 60f32.to_radians().cos();
        // 90 degrees apart: same point, two vertices.
        let mut w = weld_points(&two_vertices(Vec3::Y, Vec3::X), 1e-6);
        assert_eq!(w.vertex_point[0], w.vertex_point[1]);
        assert_eq!(merge_vertices(&mut w, cos60, Seams::Ignore, &SeamEdges::new()), (0, 0));
        // 30 degrees apart: merged into the smaller index, which keeps its normal.
        let n2 = Vec3::new(0.5, 3f32.sqrt() / 2.0, 0.0);
        let mut w = weld_points(&two_vertices(Vec3::Y, n2), 1e-6);
        assert_eq!(merge_vertices(&mut w, cos60, Seams::Ignore, &SeamEdges::new()), (1, 0));
        assert_eq!(w.tris[1][0], 0);
        assert_eq!(w.normals[0], Vec3::Y);
    }
}
