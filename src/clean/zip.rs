//! Zipping cracks and T-junctions between patches (Sloan et al. §4.1.1: "cracks
//! between patches resulting from the NURBS tessellation").
//!
//! Only boundary edges (used by one triangle) and their end points take part, so
//! a closed surface is never touched. Two steps:
//! 1. *Weld boundary points* closer than the zip tolerance (representative: the
//!    smallest point id, i.e. the older patch keeps its position), and closer
//!    than either point's shortest boundary edge: a boundary whose own edges are
//!    shorter than the tolerance (a finely tessellated rim) is not a crack, and
//!    welding along it would collapse it. Nor where the weld would put three or
//!    more triangles on one edge: two sheets' rims that close are no crack
//!    (a chair's tube ends in the dining room made non-manifold edges so).
//! 2. *Split at T-junctions*: a boundary point within the tolerance of the interior
//!    of another triangle's boundary edge (and farther than the tolerance from both
//!    of its ends) splits that triangle there. The split vertex takes the point
//!    itself, with attributes interpolated along the edge. Where the point goes:
//!    onto the edge when the edge is older (its end points have smaller ids),
//!    otherwise it stays and the edge bends to it; so the older patch never moves
//!    and the area it describes is kept. Repeated until nothing splits, since a
//!    triangle splits one edge per pass. An edge along which the other
//!    boundary edges overlap each other (two or more layers on one line:
//!    coplanar copies stacked along a base, fins on one axis) takes no point:
//!    that is no crack, and zipping every layer into every other made n²
//!    pieces of n layers.

use super::spatial::{cluster_points_limited, Aabb, AabbTree};
use super::work::{count_boundary_and_non_manifold, edge_runs, sorted_edges, EdgeUse, Work};
use std::collections::{HashMap, HashSet};

/// Upper bound on T-junction passes (each pass splits one edge per triangle).
const MAX_PASSES: usize = 16;

/// What [`zip_boundaries`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct ZipOutcome {
    /// Boundary edges before minus boundary edges after.
    pub zipped_edges: usize,
    /// Boundary points inserted into another triangle's edge.
    pub tjunctions: usize,
    /// Boundary points merged into another by step 1.
    pub welded_points: usize,
    /// Triangles collapsed by step 1 (two corners merged) and removed.
    pub collapsed: usize,
}

/// Zips boundary edges closer than `tol` (see the module doc).
pub(crate) fn zip_boundaries(work: &mut Work, tol: f32) -> ZipOutcome {
    let (before, _) = count_boundary_and_non_manifold(work);
    let mut out = ZipOutcome::default();

    // Steps 1 and 2 until neither changes anything: a split can bring points together.
    for _ in 0..MAX_PASSES {
        let (welded, collapsed) = weld_boundary_points(work, tol);
        out.welded_points += welded;
        out.collapsed += collapsed;
        let mut split_any = 0;
        for _ in 0..MAX_PASSES {
            let split = split_tjunctions(work, tol);
            if split == 0 {
                break;
            }
            split_any += split;
        }
        out.tjunctions += split_any;
        if welded == 0 && split_any == 0 {
            break;
        }
    }
    let (after, _) = count_boundary_and_non_manifold(work);
    out.zipped_edges = before.saturating_sub(after);
    out
}

/// Step 1: welds boundary points closer than `tol` and removes the triangles that
/// collapse. Returns (points merged, triangles removed).
fn weld_boundary_points(work: &mut Work, tol: f32) -> (usize, usize) {
    let edges = sorted_edges(work);
    let mut boundary_points: Vec<u32> = boundary_edges(&edges).flat_map(|e| [e.lo, e.hi]).collect();
    boundary_points.sort_unstable();
    boundary_points.dedup();
    // A point joins only points closer than its shortest boundary edge: welding
    // the two ends of a boundary edge closes no crack, it collapses the boundary
    // (a rim finer than the tolerance would collapse to a point).
    let mut shortest = vec![f32::INFINITY; work.points.len()];
    for e in boundary_edges(&edges) {
        let len = work.points[e.lo as usize].distance(work.points[e.hi as usize]);
        shortest[e.lo as usize] = shortest[e.lo as usize].min(len);
        shortest[e.hi as usize] = shortest[e.hi as usize].min(len);
    }
    let limit: Vec<f32> = boundary_points.iter().map(|&p| shortest[p as usize]).collect();
    let reps = cluster_points_limited(&work.points, &boundary_points, tol, Some(&limit));
    let mut remap: Vec<u32> = (0..work.points.len() as u32).collect();
    let mut welded = 0;
    for (&p, &r) in boundary_points.iter().zip(&reps) {
        if p != r {
            remap[p as usize] = r;
            welded += 1;
        }
    }
    welded -= undo_non_manifold_merges(work, &mut remap);
    let mut collapsed = 0;
    if welded > 0 {
        work.remap_points(&remap);
        for t in 0..work.tris.len() {
            let [a, b, c] = work.tri_points(t);
            if work.tri_alive[t] && (a == b || b == c || c == a) {
                work.tri_alive[t] = false;
                collapsed += 1;
            }
        }
    }
    (welded, collapsed)
}

/// Undoes the merges of `remap` that would join three or more triangles on
/// one edge (the rims of two sheets within the tolerance of each other are no
/// crack: joining them makes a non-manifold edge). Returns the points kept apart.
fn undo_non_manifold_merges(work: &Work, remap: &mut [u32]) -> usize {
    let mut kept = 0;
    for _ in 0..MAX_PASSES {
        let moved: HashSet<u32> = (0..remap.len() as u32).filter(|&p| remap[p as usize] != p).collect();
        if moved.is_empty() {
            break;
        }
        let involved: HashSet<u32> = moved.iter().map(|&p| remap[p as usize]).chain(moved.iter().copied()).collect();
        // Users of each edge at an involved point after the merge, and whether a moved corner made it.
        let mut users: HashMap<(u32, u32), (u32, bool)> = HashMap::new();
        for t in 0..work.tris.len() {
            let p = work.tri_points(t);
            if !work.tri_alive[t] || !p.iter().any(|q| involved.contains(q)) {
                continue;
            }
            let m = p.map(|q| remap[q as usize]);
            if m[0] == m[1] || m[1] == m[2] || m[2] == m[0] {
                continue;
            }
            for i in 0..3 {
                let key = (m[i].min(m[(i + 1) % 3]), m[i].max(m[(i + 1) % 3]));
                let entry = users.entry(key).or_insert((0, false));
                entry.0 += 1;
                entry.1 |= moved.contains(&p[i]) || moved.contains(&p[(i + 1) % 3]);
            }
        }
        let blamed: HashSet<u32> = users.iter().filter(|(_, &(n, by_merge))| n > 2 && by_merge).flat_map(|(&(a, b), _)| [a, b]).collect();
        if blamed.is_empty() {
            break;
        }
        for p in 0..remap.len() {
            if remap[p] != p as u32 && blamed.contains(&remap[p]) {
                remap[p] = p as u32;
                kept += 1;
            }
        }
    }
    kept
}

fn boundary_edges(edges: &[EdgeUse]) -> impl Iterator<Item = EdgeUse> + '_ {
    edge_runs(edges).filter(|run| run.len() == 1).map(|run| run[0])
}

/// A boundary point to insert into a boundary edge.
#[derive(Clone, Copy, Debug)]
struct Split {
    tri: u32,
    corner: u8,
    /// Parameter along the edge from corner `corner` to the next.
    s: f64,
    point: u32,
    projection: glam::DVec3,
}

/// One pass of step 2; returns the number of points inserted.
fn split_tjunctions(work: &mut Work, tol: f32) -> usize {
    let edges = sorted_edges(work);
    let boundary: Vec<EdgeUse> = boundary_edges(&edges).collect();
    if boundary.is_empty() {
        return 0;
    }
    let boxes: Vec<Aabb> =
        boundary.iter().map(|e| Aabb::of_points(&[work.points[e.lo as usize], work.points[e.hi as usize]], tol)).collect();
    let tree = AabbTree::build(boxes);
    let mut points: Vec<u32> = boundary.iter().flat_map(|e| [e.lo, e.hi]).collect();
    points.sort_unstable();
    points.dedup();

    // Find, for each boundary point, the nearest boundary edge it lies on.
    let tol = tol as f64;
    let mut splits: Vec<Split> = Vec::new();
    let mut found = Vec::new();
    let mut layered: Vec<Option<bool>> = vec![None; boundary.len()];
    for &v in &points {
        let pv = work.points[v as usize];
        found.clear();
        tree.query(&Aabb { min: pv, max: pv }, &mut found);
        found.sort_unstable();
        let pv = pv.as_dvec3();
        let mut best: Option<(f64, Split)> = None;
        for &i in &found {
            let e = boundary[i as usize];
            let tri_points = work.tri_points(e.tri as usize);
            if tri_points.contains(&v) {
                continue;
            }
            let corner = e.corner as usize;
            let a = work.points[tri_points[corner] as usize].as_dvec3();
            let b = work.points[tri_points[(corner + 1) % 3] as usize].as_dvec3();
            let ab = b - a;
            let len = ab.length();
            if len == 0.0 {
                continue;
            }
            let s = (pv - a).dot(ab) / (len * len);
            let projection = a + ab * s;
            let dist = pv.distance(projection);
            let interior = s * len > tol && (1.0 - s) * len > tol;
            if dist <= tol
                && interior
                && !matches!(best, Some((d, _)) if d <= dist)
                && !*layered[i as usize].get_or_insert_with(|| is_layered(work, &boundary, &tree, i as usize, tol))
            {
                best = Some((dist, Split { tri: e.tri, corner: e.corner, s, point: v, projection }));
            }
        }
        if let Some((_, split)) = best {
            splits.push(split);
        }
    }

    // Apply: per triangle, the splits of its lowest split corner; others wait a pass.
    splits.sort_by(|x, y| (x.tri, x.corner).cmp(&(y.tri, y.corner)).then(x.s.total_cmp(&y.s)));
    let mut inserted = 0;
    for tri_splits in splits.chunk_by(|x, y| x.tri == y.tri) {
        let corner = tri_splits[0].corner;
        let edge_splits: Vec<Split> = tri_splits.iter().copied().filter(|x| x.corner == corner).collect();
        inserted += split_triangle_edge(work, &edge_splits);
    }
    inserted
}

/// True when the other boundary edges lying along boundary edge `i`
/// (collinear with it and overlapping it, within `tol`) overlap each other:
/// two or more layers run along the line (coplanar triangles stacked along
/// one edge, fins on one axis), not the single patch across a crack. Their
/// corners are then not inserted into the edge: each layer's corners going
/// into every other layer's edges made n² pieces (and n⁴ partial overlaps)
/// of n layers. Along a crack the other patch's edges follow each other.
fn is_layered(work: &Work, boundary: &[EdgeUse], tree: &AabbTree, i: usize, tol: f64) -> bool {
    let ends = |e: &EdgeUse| [work.points[e.lo as usize].as_dvec3(), work.points[e.hi as usize].as_dvec3()];
    let [a, b] = ends(&boundary[i]);
    let len = a.distance(b);
    if len <= tol {
        return false;
    }
    let dir = (b - a) / len;
    let off_line = |p: glam::DVec3| (p - a - dir * (p - a).dot(dir)).length();
    let mut found = Vec::new();
    tree.query(&Aabb::of_points(&[a.as_vec3(), b.as_vec3()], tol as f32), &mut found);
    // Parameter intervals along the edge of the other edges on its line.
    let mut spans: Vec<(f64, f64)> = found
        .into_iter()
        .map(|j| j as usize)
        .filter(|&j| j != i && boundary[j].tri != boundary[i].tri)
        .filter_map(|j| {
            let [c, d] = ends(&boundary[j]);
            let (sc, sd) = ((c - a).dot(dir), (d - a).dot(dir));
            let on_line = off_line(c) <= tol && off_line(d) <= tol;
            (on_line && sc.max(sd).min(len) - sc.min(sd).max(0.0) > tol).then_some((sc.min(sd), sc.max(sd)))
        })
        .collect();
    spans.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.total_cmp(&y.1)));
    let mut reach = f64::NEG_INFINITY;
    for (start, end) in spans {
        if start < reach - tol {
            return true;
        }
        reach = reach.max(end);
    }
    false
}

/// Fans triangle `splits[0].tri` from its opposite corner through the split points
/// (sorted by parameter along one edge). Returns the number of points inserted.
fn split_triangle_edge(work: &mut Work, splits: &[Split]) -> usize {
    let t = splits[0].tri as usize;
    let corner = splits[0].corner as usize;
    let tri = work.tris[t];
    let (va, vb, vc) = (tri[corner], tri[(corner + 1) % 3], tri[(corner + 2) % 3]);
    let (pa, pb) = (work.vertex_point[va as usize], work.vertex_point[vb as usize]);
    let mut chain = vec![va];
    for split in splits {
        // The older side keeps its position (see the module doc).
        if split.point > pa.min(pb) {
            work.points[split.point as usize] = split.projection.as_vec3();
        }
        chain.push(work.push_vertex_lerp(va, vb, split.s as f32, split.point));
    }
    chain.push(vb);
    work.tris[t] = [chain[0], chain[1], vc];
    for w in chain[1..].windows(2) {
        work.push_tri_like([w[0], w[1], vc], t);
    }
    splits.len()
}

#[cfg(test)]
mod tests {
    use super::super::work::work_of;
    use super::*;

    #[test]
    fn rims_within_the_tolerance_are_not_joined_onto_an_edge_that_two_triangles_share() {
        // A square of two triangles, and a fin whose base runs 1 mm above the
        // square's diagonal: welding the fin's base corners onto the diagonal's
        // ends would make the diagonal an edge of three triangles.
        let pts =
            [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.001], [1.0, 1.0, 0.001], [0.5, 0.5, 1.0]];
        let mut work = work_of(&pts, &[[0, 1, 2], [0, 2, 3], [4, 5, 6]]);
        let out = zip_boundaries(&mut work, 0.002);
        assert_eq!(count_boundary_and_non_manifold(&work), (7, 0), "{out:?}");
        assert_eq!((out.welded_points, out.collapsed), (0, 0));
        // Without the square's second triangle the diagonal is a rim: a crack, zipped.
        let mut work = work_of(&pts, &[[0, 1, 2], [4, 5, 6]]);
        let out = zip_boundaries(&mut work, 0.002);
        assert_eq!(count_boundary_and_non_manifold(&work), (4, 0), "{out:?}");
        assert_eq!(out.welded_points, 2);
    }
}
