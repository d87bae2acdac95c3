//! Refinement: split over-long edges, and flip edges to improve slivers, so that
//! per-vertex storage can resolve shadows (Dellepiane et al. §5.2: large
//! triangles "recursively splitted into smaller triangles").
//!
//! Long edges: every point edge longer than `max_edge` is split at its midpoint,
//! in *all* triangles that use it (so no T-junction appears), with the red-green
//! patterns (one, two or three split sides); repeated until none is too long.
//! Each pass halves the longest edge, so the number of passes is
//! `ceil(log2(longest / max_edge))`.
//!
//! Slivers: Lawson-style flips on the edges of triangles whose smallest angle is
//! below the threshold. An edge is flipped only when it is shared by exactly two
//! triangles that traverse it in opposite directions with the same two vertices
//! (no hard edge or UV seam on it), the same material and group, lie in one plane
//! (within the plane tolerance), form a convex quad, and the flip strictly raises
//! the smaller of their two smallest angles (the local Delaunay criterion). Flips
//! keep the area exactly. Needles (one very short side) cannot be flipped away and
//! stay listed in the report.

use super::work::{edge_runs, min_angle, sorted_edges, Work};
use glam::DVec3;
use std::collections::{HashMap, VecDeque};

/// Upper bound on long-edge passes (each halves the longest edge: 2^40 is plenty).
const MAX_SPLIT_PASSES: usize = 40;
/// A flip must raise the smallest angle by more than this (radians): no flip-flopping on ties.
const FLIP_MARGIN: f64 = 1e-7;

/// Most triangles `--max-edge` may make: tens of bytes each through the
/// clean's passes, a few GiB at this count.
pub(crate) const MAX_SPLIT_TRIANGLES: f64 = 50e6;

/// Refuses a `max_edge` that would split `mesh` into more than
/// [`MAX_SPLIT_TRIANGLES`] (`--max-edge 1e-9` on a 4 m floor ran until
/// killed): per triangle about ⌈longest / max_edge⌉ × ⌈height / max_edge⌉
/// pieces, which counts a sliver by its length, not its area.
pub(crate) fn check_split_size(mesh: &crate::mesh::Mesh, max_edge: f32) -> Result<(), super::CleanError> {
    let asked = max_edge;
    let max_edge = max_edge as f64;
    let estimate: f64 = (0..mesh.triangle_count())
        .map(|t| {
            let [a, b, c] = mesh.triangle_positions(t).map(|p| p.as_dvec3());
            let longest = a.distance(b).max(b.distance(c)).max(c.distance(a));
            let height = if longest > 0.0 { (b - a).cross(c - a).length() / longest } else { 0.0 };
            (longest / max_edge).ceil().max(1.0) * (height / max_edge).ceil().max(1.0)
        })
        .sum();
    if estimate > MAX_SPLIT_TRIANGLES {
        return Err(super::CleanError::InvalidParams {
            name: "max_edge",
            problem: format!(
                "{asked} would split the mesh into about {estimate:.3e} triangles, more than {MAX_SPLIT_TRIANGLES:.0e}: choose a longer edge"
            ),
        });
    }
    Ok(())
}

/// Splits every point edge longer than `max_edge` (recursively); returns the number of edges split.
pub(crate) fn split_long_edges(work: &mut Work, max_edge: f32) -> usize {
    let max_edge = max_edge as f64;
    let mut split = 0;
    for _ in 0..MAX_SPLIT_PASSES {
        let long =
            |work: &Work, lo: u32, hi: u32| work.points[lo as usize].as_dvec3().distance(work.points[hi as usize].as_dvec3()) > max_edge;
        let n = split_marked_edges(work, long);
        if n == 0 {
            break;
        }
        split += n;
    }
    split
}

/// Splits once, at its midpoint, every point edge `(lo, hi)` (`lo < hi`)
/// for which `marked` holds, in all triangles that use it (red-green
/// patterns); returns the number of edges split. Midpoints are numbered in
/// sorted edge order, so the result is deterministic.
pub(crate) fn split_marked_edges(work: &mut Work, marked: impl Fn(&Work, u32, u32) -> bool) -> usize {
    let edges = sorted_edges(work);
    let mut mid_point: HashMap<(u32, u32), u32> = HashMap::new();
    for run in edge_runs(&edges) {
        let (lo, hi) = (run[0].lo, run[0].hi);
        if marked(work, lo, hi) {
            let (a, b) = (work.points[lo as usize].as_dvec3(), work.points[hi as usize].as_dvec3());
            let m = work.push_point(((a + b) * 0.5).as_vec3());
            mid_point.insert((lo, hi), m);
        }
    }
    if mid_point.is_empty() {
        return 0;
    }
    let mut mid_vertex: HashMap<(u32, u32), u32> = HashMap::new();
    for t in 0..work.tris.len() {
        if !work.tri_alive[t] {
            continue;
        }
        let p = work.tri_points(t);
        let v = work.tris[t];
        let mut mids: [Option<u32>; 3] = [None; 3];
        for c in 0..3 {
            let key = (p[c].min(p[(c + 1) % 3]), p[c].max(p[(c + 1) % 3]));
            if let Some(&point) = mid_point.get(&key) {
                let (va, vb) = (v[c], v[(c + 1) % 3]);
                let vkey = (va.min(vb), va.max(vb));
                let mid = *mid_vertex.entry(vkey).or_insert_with(|| work.push_vertex_lerp(va, vb, 0.5, point));
                mids[c] = Some(mid);
            }
        }
        subdivide(work, t, mids);
    }
    mid_point.len()
}

/// Replaces triangle `t` by the red-green pattern for its split sides
/// (`mids[c]`: midpoint vertex of the side from corner `c` to `c + 1`).
fn subdivide(work: &mut Work, t: usize, mids: [Option<u32>; 3]) {
    let v = work.tris[t];
    let pos = |work: &Work, x: u32| work.points[work.vertex_point[x as usize] as usize].as_dvec3();
    let new: Vec<[u32; 3]> = match mids {
        [None, None, None] => return,
        [Some(m0), Some(m1), Some(m2)] => vec![[v[0], m0, m2], [m0, v[1], m1], [m2, m1, v[2]], [m0, m1, m2]],
        _ => {
            let count = mids.iter().filter(|m| m.is_some()).count();
            if count == 1 {
                let c = (0..3).find(|&c| mids[c].is_some()).unwrap_or(0);
                let m = mids[c].unwrap_or(v[c]);
                let (a, b, o) = (v[c], v[(c + 1) % 3], v[(c + 2) % 3]);
                vec![[a, m, o], [m, b, o]]
            } else {
                // Rotate so sides a→b and b→c are split and c→a is not.
                let unsplit = (0..3).find(|&c| mids[c].is_none()).unwrap_or(2);
                let r = (unsplit + 1) % 3;
                let (a, b, c) = (v[r], v[(r + 1) % 3], v[(r + 2) % 3]);
                let (m, n) = (mids[r].unwrap_or(a), mids[(r + 1) % 3].unwrap_or(b));
                // The quad a, m, n, c takes its shorter diagonal.
                if pos(work, a).distance(pos(work, n)) <= pos(work, m).distance(pos(work, c)) {
                    vec![[m, b, n], [a, m, n], [a, n, c]]
                } else {
                    vec![[m, b, n], [a, m, c], [m, n, c]]
                }
            }
        }
    };
    work.tris[t] = new[0];
    for &tri in &new[1..] {
        work.push_tri_like(tri, t);
    }
}

/// Number of live triangles whose smallest angle is below `min_angle_rad`.
pub(crate) fn count_slivers(work: &Work, min_angle_rad: f64) -> usize {
    (0..work.tris.len()).filter(|&t| work.tri_alive[t] && min_angle(work.tri_positions(t).map(|p| p.as_dvec3())) < min_angle_rad).count()
}

/// Users of an undirected point edge: two triangle ids, `u32::MAX` where absent;
/// both `u32::MAX` marks a non-manifold edge.
type EdgeTris = (u32, u32);
const NONE: u32 = u32::MAX;

/// Edges flipped so far, as their two end positions (bits, sorted), across the
/// rounds of one clean. An edge is flipped at most once: on the grey-white room
/// at `--max-edge 0.3` a flip made a triangle that another covered, the next
/// round removed it and zipped the hole shut with the old edge, and the flip
/// came back every round (not converged after 8).
#[derive(Default)]
pub(crate) struct FlippedEdges(std::collections::HashSet<([u32; 3], [u32; 3])>);

impl FlippedEdges {
    /// Records the edge between `a` and `b`; false when it was recorded before.
    fn insert(&mut self, a: glam::Vec3, b: glam::Vec3) -> bool {
        let (a, b) = (a.to_array().map(f32::to_bits), b.to_array().map(f32::to_bits));
        self.0.insert((a.min(b), a.max(b)))
    }
}

/// Flips edges of slivers while that raises their smallest angles (see module
/// doc), each edge at most once per clean (`flipped`). Returns the number of flips.
pub(crate) fn flip_slivers(
    work: &mut Work,
    min_angle_rad: f64,
    plane_tol: f32,
    height_tol: f32,
    max_edge: Option<f32>,
    flipped: &mut FlippedEdges,
) -> usize {
    if min_angle_rad <= 0.0 {
        return 0;
    }
    let edges = sorted_edges(work);
    let mut map: HashMap<(u32, u32), EdgeTris> = HashMap::with_capacity(edges.len());
    for run in edge_runs(&edges) {
        let users = match run {
            [e] => (e.tri, NONE),
            [e, f] => (e.tri, f.tri),
            _ => (NONE, NONE),
        };
        map.insert((run[0].lo, run[0].hi), users);
    }
    let mut queue: VecDeque<(u32, u32)> = VecDeque::new();
    for t in 0..work.tris.len() {
        if work.tri_alive[t] && min_angle(work.tri_positions(t).map(|p| p.as_dvec3())) < min_angle_rad {
            let p = work.tri_points(t);
            for c in 0..3 {
                queue.push_back(key(p[c], p[(c + 1) % 3]));
            }
        }
    }
    let limit = 10 * work.tris.len() + 100;
    let mut flips = 0;
    while let Some(edge) = queue.pop_front() {
        if flips >= limit {
            break;
        }
        let Some(&(t1, t2)) = map.get(&edge) else { continue };
        if t1 == NONE || t2 == NONE {
            continue;
        }
        let Some(flip) = plan_flip(work, &map, edge, t1 as usize, t2 as usize, plane_tol as f64, height_tol as f64, max_edge) else {
            continue;
        };
        let Flip { a, b, c, d, va, vb, vc, vd } = flip;
        if !flipped.insert(work.points[a as usize], work.points[b as usize]) {
            continue;
        }
        work.tris[t1 as usize] = [va, vd, vc];
        work.tris[t2 as usize] = [vd, vb, vc];
        map.remove(&edge);
        map.insert(key(c, d), (t1, t2));
        replace_user(&mut map, key(b, c), t1, t2);
        replace_user(&mut map, key(a, d), t2, t1);
        queue.extend([key(c, a), key(a, d), key(d, b), key(b, c)]);
        flips += 1;
    }
    flips
}

fn key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

fn replace_user(map: &mut HashMap<(u32, u32), EdgeTris>, edge: (u32, u32), old: u32, new: u32) {
    if let Some(users) = map.get_mut(&edge) {
        if users.0 == old {
            users.0 = new;
        } else if users.1 == old {
            users.1 = new;
        }
    }
}

/// A planned flip of edge a–b (triangles a→b→c and b→a→d) to c–d: point ids and vertex ids.
struct Flip {
    a: u32,
    b: u32,
    c: u32,
    d: u32,
    va: u32,
    vb: u32,
    vc: u32,
    vd: u32,
}

fn plan_flip(
    work: &Work,
    map: &HashMap<(u32, u32), EdgeTris>,
    edge: (u32, u32),
    t1: usize,
    t2: usize,
    plane_tol: f64,
    height_tol: f64,
    max_edge: Option<f32>,
) -> Option<Flip> {
    if work.tri_material[t1] != work.tri_material[t2] || work.tri_group[t1] != work.tri_group[t2] {
        return None;
    }
    let (p1, p2) = (work.tri_points(t1), work.tri_points(t2));
    let i = (0..3).find(|&i| key(p1[i], p1[(i + 1) % 3]) == edge)?;
    let (a, b, c) = (p1[i], p1[(i + 1) % 3], p1[(i + 2) % 3]);
    // The neighbour must run b→a (consistent winding) over the same vertices.
    let j = (0..3).find(|&j| p2[j] == b && p2[(j + 1) % 3] == a)?;
    let d = p2[(j + 2) % 3];
    let (w1, w2) = (work.tris[t1], work.tris[t2]);
    let (va, vb, vc) = (w1[i], w1[(i + 1) % 3], w1[(i + 2) % 3]);
    if w2[j] != vb || w2[(j + 1) % 3] != va || c == d || map.contains_key(&key(c, d)) {
        return None;
    }
    let vd = w2[(j + 2) % 3];
    let pos = |x: u32| work.points[x as usize].as_dvec3();
    let (pa, pb, pc, pd) = (pos(a), pos(b), pos(c), pos(d));
    let n = (pb - pa).cross(pc - pa).try_normalize()?;
    if (pd - pa).dot(n).abs() > plane_tol {
        return None;
    }
    if let Some(max) = max_edge {
        if pc.distance(pd) > max as f64 {
            return None;
        }
    }
    // Convex quad: both new triangles face the old way, each with a smallest
    // height above the degenerate pass's tolerance. (A flip across nearly
    // collinear points, as long-edge splits line up along a sliver's sides,
    // could otherwise make a triangle the next round removes as degenerate,
    // leaving a T-junction for zipping to close: on the grey-white room at
    // `--max-edge 0.3`, 7,447 removals and non-manifold edges 0.70 → 1.69 m.)
    let sound = |x: DVec3, y: DVec3, z: DVec3| {
        let twice_area = (y - x).cross(z - x).dot(n);
        let longest = x.distance(y).max(y.distance(z)).max(z.distance(x));
        twice_area > height_tol * longest
    };
    if !sound(pa, pd, pc) || !sound(pd, pb, pc) {
        return None;
    }
    let before = min_angle([pa, pb, pc]).min(min_angle([pb, pa, pd]));
    let after = min_angle([pa, pd, pc]).min(min_angle([pd, pb, pc]));
    (after > before + FLIP_MARGIN).then_some(Flip { a, b, c, d, va, vb, vc, vd })
}
