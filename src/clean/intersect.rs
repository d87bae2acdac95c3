//! Cutting where surfaces pass through each other (issue 20, "cut where
//! geometry interpenetrates").
//!
//! Why: in architectural and CAD models a wall runs past another wall and a
//! floor runs under and past a wall. A vertex's transfer is the hat-weighted
//! mean over its one-ring, and a triangle that spans both sides of a wall is
//! interpolated across it, so the sky seen outside bleeds into the room as
//! bright bands along the junction (seed 000 calls interpenetrating CAD
//! geometry "a really big problem"). Cutting every triangle along the lines
//! where other triangles cross it makes those lines edges; the weld then keeps
//! the triangles on either side of such a line apart ([`super::weld`], wedges),
//! so no sample from one side enters a vertex of the other.
//!
//! How:
//! 1. *Pairs*: the coplanar step's broad phase ([`super::hub_pairs`], a box
//!    tree and, around high-valence points, angular sectors, which find every
//!    pair with a common point away from the hub), boxes padded by the contact
//!    tolerance. Pairs that share an edge are skipped (non-coplanar triangles
//!    sharing an edge meet only along it), and so are coplanar pairs (within
//!    the plane tolerance: overlaps are [`super::coplanar`]'s).
//! 2. *Segment*: each triangle's corners are classified against the other's
//!    plane with [`robust::orient3d`] (Shewchuk's adaptive exact predicate:
//!    the sign is exact however close to the plane a corner is), then a corner
//!    within the contact tolerance of the plane counts as on it (positions
//!    closer than the weld tolerance are one point for every step, and a wall
//!    resting on a floor 1e-7 off it is a contact). Each triangle meets the
//!    other's plane in a segment of their common line; the pair's
//!    intersection is the overlap of the two. A pair that meets in a point
//!    (a shared corner, a touch) is not cut, nor one whose segment lies on a
//!    boundary edge of both (two patches' rims along each other: zipping's job).
//!    Nor are segments shorter than the zip tolerance, pairs whose planes
//!    meet at less than about 3° ([`MIN_CUT_SINE`]), or a pair of input
//!    triangles cut before in this clean ([`CutPairs`]): each of these made
//!    pieces thinner than the weld tolerance that the next round removed and
//!    the cut re-made (the dining room did not converge).
//! 3. *Points*: segment ends within the contact tolerance of a corner of the
//!    pair are that corner; new ends closer than it to each other are one
//!    point (the smallest id), so both triangles of a pair, and the pairs along
//!    one line, share point ids. Then, until nothing changes: a point on an
//!    edge goes into every triangle that uses the edge (no T-junction), a point
//!    on a segment splits it in both triangles of its pair, and two segments
//!    crossing inside a triangle (three triangles meeting at a point) add the
//!    crossing to all three segments and triangles.
//! 4. *Triangulate*: each triangle with new points is replaced by a
//!    constrained Delaunay triangulation (the `spade` crate, robust
//!    predicates) of its corners and points with its edges and segments as
//!    constraints, in an affine frame of the triangle in which every point on
//!    an edge lies exactly on that edge's line (barycentric coordinates
//!    rounded to multiples of 2^-30, the corner `C` to multiples of 2^-10:
//!    every coordinate is exact), so the triangulation covers the triangle
//!    exactly. New vertices interpolate the triangle's attributes
//!    barycentrically. The pieces tile the triangle: its area is kept up to
//!    the rounding of the new points to f32.
//!
//! Limits: a segment is straight in each triangle, so curved intersections are
//! cut as polylines at the tessellation's resolution. Two segments that cross
//! in a triangle's frame but were not found crossing in 3D (rounding) are
//! split there for that triangle alone ([`CutOutcome::unshared_splits`]); a
//! piece the triangulation still cannot insert is left out and counted
//! ([`CutOutcome::dropped_pieces`]). Both are reported; both are zero on the
//! fixtures and the dining room (5 unshared crossings on the Ferrari). A piece
//! is oriented by the triangle's frame, where new points sit at their rounded
//! barycentric coordinates; their 3D positions are the rounded f32 points, so
//! a piece a few tolerances wide can fold over its neighbour in 3D (the
//! grey-white room reports a few overlaps between pieces of one triangle, of
//! 1e-5 to 4e-5 m²). Measurements: docs/performance.md.

use super::hub_pairs;
use super::spatial::{cluster_points, Aabb};
use super::work::{sorted_edges, EdgeUse, Work};
use glam::{DVec3, Vec3};
use spade::{ConstrainedDelaunayTriangulation, Point2, Triangulation};
use std::collections::{BTreeMap, HashMap, VecDeque};

/// What [`cut_intersections`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct CutOutcome {
    /// Intersection segments inserted (one per pair of triangles that cross).
    pub segments: usize,
    /// Triangles replaced by their pieces (the cut ones and their edge neighbours).
    pub triangles_cut: usize,
    /// Crossings of two segments that only one triangle's frame found (split
    /// there alone, not shared with the other triangles).
    pub unshared_splits: usize,
    /// Segment pieces the triangulation could not insert (left uncut).
    pub dropped_pieces: usize,
    /// Triangles whose triangulation failed (left whole).
    pub failed_triangles: usize,
}

/// Barycentric coordinates are rounded to multiples of this in a triangle's frame.
const QUANTUM: f64 = 1.0 / (1u64 << 30) as f64;
/// The frame's corner `C` is rounded to multiples of this (relative to `|AB|`).
const SHAPE_QUANTUM: f64 = 1.0 / 1024.0;
/// Pairs whose planes meet at a smaller angle (sine; about 3°) are not cut:
/// an offset δ of either moves their common line by δ / sin θ, so the cut is
/// ill-conditioned, and such pairs are mostly one surface modelled twice a
/// hair apart (a car's double-sided panels) rather than a wall through a floor.
const MIN_CUT_SINE: f64 = 0.05;
/// Rounds of the point propagation (each adds points; real meshes settle in 2).
const MAX_PROPAGATION_ROUNDS: usize = 16;

/// One pair's intersection: the two triangles and the points along it.
#[derive(Clone, Debug)]
struct Segment {
    tris: [u32; 2],
    ends: [u32; 2],
    /// Points inside the segment, unordered.
    inner: Vec<u32>,
}

/// Where a point lies on a triangle.
#[derive(Clone, Copy, Debug)]
enum Loc {
    Corner(usize),
    /// On the edge from corner `k` to `k + 1`, at parameter `s` in (0, 1).
    Edge(usize, f64),
    /// Barycentric coordinates of corners 1 and 2.
    Interior(f64, f64),
    /// Outside the triangle by more than the tolerance: not inserted.
    Outside,
}

/// Cuts every live triangle along the segments where other triangles cross it
/// (see the module doc). `plane_tol` is the coplanar step's tolerance, `tol`
/// the contact tolerance (the weld tolerance).
pub(crate) fn cut_intersections(
    work: &mut Work,
    plane_tol: f64,
    tol: f64,
    min_length: f64,
    cut: &mut CutPairs,
    input_of: &[u32],
) -> CutOutcome {
    let n = work.tris.len();
    let corners: Vec<[DVec3; 3]> = (0..n).map(|t| work.tri_positions(t).map(|p| p.as_dvec3())).collect();
    let points: Vec<[u32; 3]> = (0..n).map(|t| work.tri_points(t)).collect();
    let usable = |t: usize| {
        let [a, b, c] = points[t];
        work.tri_alive[t] && a != b && b != c && c != a && work.tri_cross(t).length_squared() > 0.0
    };
    let boxes: Vec<Aabb> =
        (0..n).map(|t| if usable(t) { Aabb::of_points(&work.tri_positions(t), tol as f32) } else { Aabb::EMPTY }).collect();
    let candidates = hub_pairs::candidate_pairs(&points, &corners, &boxes, tol);

    // 1-2. Segments of the crossing pairs, ends as positions.
    let mut raw: Vec<(u32, u32, [DVec3; 2])> = Vec::new();
    for &(a, b) in &candidates.pairs {
        let (a, b) = (a as usize, b as usize);
        let shared = points[a].iter().filter(|p| points[b].contains(p)).count();
        if shared >= 2 || cut.0.contains(&origin_pair(work, input_of, a, b)) {
            continue;
        }
        if let Some(ends) = pair_segment(corners[a], corners[b], plane_tol, tol).filter(|e| e[0].distance(e[1]) >= min_length) {
            raw.push((a as u32, b as u32, ends));
        }
    }

    // 3. Point ids: a corner of the pair within `tol`, else a new point (clustered).
    let mut new_positions: Vec<Vec3> = Vec::new();
    let mut ends_of: Vec<[EndRef; 2]> = Vec::with_capacity(raw.len());
    for &(a, b, ends) in &raw {
        let pair_corners: Vec<(u32, DVec3)> = (0..3)
            .map(|k| (points[a as usize][k], corners[a as usize][k]))
            .chain((0..3).map(|k| (points[b as usize][k], corners[b as usize][k])))
            .collect();
        ends_of.push(ends.map(|p| {
            let nearest = pair_corners
                .iter()
                .map(|&(id, c)| (c.distance(p), id))
                .filter(|&(d, _)| d <= tol)
                .min_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
            match nearest {
                Some((_, id)) => EndRef::Point(id),
                None => {
                    new_positions.push(p.as_vec3());
                    EndRef::New(new_positions.len() as u32 - 1)
                }
            }
        }));
    }
    let ids: Vec<u32> = (0..new_positions.len() as u32).collect();
    let reps = cluster_points(&new_positions, &ids, tol as f32);
    let mut new_point = vec![u32::MAX; new_positions.len()];
    for i in 0..new_positions.len() {
        let r = reps[i] as usize;
        if new_point[r] == u32::MAX {
            new_point[r] = work.push_point(new_positions[r]);
        }
        new_point[i] = new_point[r];
    }
    let mut segments: Vec<Segment> = Vec::new();
    for (&(a, b, _), ends) in raw.iter().zip(&ends_of) {
        let ends = ends.map(|e| match e {
            EndRef::Point(id) => id,
            EndRef::New(i) => new_point[i as usize],
        });
        if ends[0] == ends[1] {
            continue;
        }
        segments.push(Segment { tris: [a, b], ends, inner: Vec::new() });
    }

    if segments.is_empty() {
        return CutOutcome::default();
    }
    // Edge users on points (sorted by edge), for the boundary rule and the propagation.
    let edge_users = EdgeUsers(sorted_edges(work));
    // Boundary rule: a segment on a rim edge of both triangles is zipping's.
    let mut planner = Planner {
        work,
        corners: &corners,
        points: &points,
        tol,
        edge_users: &edge_users,
        extra: BTreeMap::new(),
        segs_of: BTreeMap::new(),
    };
    segments.retain(|s| !planner.on_rims_of_both(s));
    for (i, s) in segments.iter().enumerate() {
        for &t in &s.tris {
            planner.segs_of.entry(t).or_default().push(i as u32);
        }
    }
    let segment_count = segments.len();
    for s in &segments {
        cut.0.insert(origin_pair(planner.work, input_of, s.tris[0] as usize, s.tris[1] as usize));
    }
    if segment_count == 0 {
        return CutOutcome::default();
    }

    // 3. Propagate points until nothing changes.
    let mut queue: VecDeque<(u32, u32)> = VecDeque::new();
    for s in &mut segments {
        // A corner of either triangle on the segment splits it (else the
        // piece between them is thinner than the tolerance).
        let (a, b) = (planner.position(s.ends[0]), planner.position(s.ends[1]));
        for &t in &s.tris {
            for (k, &p) in points[t as usize].iter().enumerate() {
                if !s.ends.contains(&p) && !s.inner.contains(&p) && on_segment(a, b, corners[t as usize][k], tol) {
                    s.inner.push(p);
                }
            }
        }
        for &t in &s.tris {
            for &p in s.ends.iter().chain(&s.inner) {
                queue.push_back((t, p));
            }
        }
    }
    let pair_segment_of: HashMap<(u32, u32), u32> =
        segments.iter().enumerate().map(|(i, s)| ((s.tris[0].min(s.tris[1]), s.tris[0].max(s.tris[1])), i as u32)).collect();
    let mut crossings: HashMap<[u32; 3], u32> = HashMap::new();
    for _ in 0..MAX_PROPAGATION_ROUNDS {
        planner.propagate(&mut queue, &mut segments);
        if !planner.find_crossings(&mut segments, &pair_segment_of, &mut crossings, &mut queue) {
            break;
        }
    }

    // 4. Triangulate every triangle that gained a point.
    let mut out = CutOutcome { segments: segment_count, ..CutOutcome::default() };
    let extra = std::mem::take(&mut planner.extra);
    let segs_of = std::mem::take(&mut planner.segs_of);
    for (&t, pts) in &extra {
        let segs: Vec<&Segment> = segs_of.get(&t).map(|v| v.iter().map(|&i| &segments[i as usize]).collect()).unwrap_or_default();
        match triangulate(work, t as usize, pts, &segs, tol) {
            Some(pieces) => {
                out.triangles_cut += usize::from(pieces.count > 1);
                out.unshared_splits += pieces.unshared;
                out.dropped_pieces += pieces.dropped;
            }
            None => out.failed_triangles += 1,
        }
    }
    out
}

/// Pairs of input triangles cut so far, across the
/// rounds of one clean: their pieces are not cut against each other again.
/// Rounding the new points to f32 and removing the slivers a cut leaves
/// (thinner than the weld tolerance) can make a cut pair's pieces cross again
/// by a hair; on the dining room (269k triangles) the same 246 pairs were
/// re-cut every round and the clean never converged.
#[derive(Default)]
pub(crate) struct CutPairs(std::collections::HashSet<(u32, u32)>);

/// The input triangles of triangles `a` and `b` (`input_of` maps this round's
/// input triangles to the clean's), in order.
fn origin_pair(work: &Work, input_of: &[u32], a: usize, b: usize) -> (u32, u32) {
    let (x, y) = (input_of[work.tri_origin[a] as usize], input_of[work.tri_origin[b] as usize]);
    (x.min(y), x.max(y))
}

/// A segment end before the new points are clustered.
#[derive(Clone, Copy, Debug)]
enum EndRef {
    Point(u32),
    New(u32),
}

/// The pair's intersection segment, or `None` when the triangles do not cross
/// (disjoint, coplanar, or meeting in a point).
fn pair_segment(a: [DVec3; 3], b: [DVec3; 3], plane_tol: f64, tol: f64) -> Option<[DVec3; 2]> {
    let sign = |d: f64| {
        if d.abs() <= tol {
            0
        } else if d > 0.0 {
            1
        } else {
            -1
        }
    };
    let one_side = |s: [i32; 3]| s.iter().all(|&x| x > 0) || s.iter().all(|&x| x < 0);
    // Most candidate pairs end here: one triangle on one side of the other's plane.
    let db = plane_distances(a, b);
    let sb = db.map(sign);
    if one_side(sb) {
        return None;
    }
    let da = plane_distances(b, a);
    let sa = da.map(sign);
    if one_side(sa) {
        return None;
    }
    // Coplanar within the plane tolerance: the coplanar step's.
    if da.iter().all(|d| d.abs() <= plane_tol) && db.iter().all(|d| d.abs() <= plane_tol) {
        return None;
    }
    if sa == [0; 3] || sb == [0; 3] {
        return None;
    }
    let dir = normal(a).cross(normal(b));
    // Shallow crossings are not cut (see MIN_CUT_SINE).
    if dir.length() < MIN_CUT_SINE {
        return None;
    }
    let (ea, eb) = (plane_crossing(a, da, sa)?, plane_crossing(b, db, sb)?);
    let param = |p: DVec3| p.dot(dir);
    let order = |e: [DVec3; 2]| if param(e[0]) <= param(e[1]) { e } else { [e[1], e[0]] };
    let (ea, eb) = (order(ea), order(eb));
    let start = if param(eb[0]) > param(ea[0]) { eb[0] } else { ea[0] };
    let end = if param(eb[1]) < param(ea[1]) { eb[1] } else { ea[1] };
    if param(end) - param(start) <= 0.0 || start.distance(end) <= tol {
        return None;
    }
    Some([start, end])
}

/// Unit normal of a triangle (zero for a degenerate one).
fn normal(t: [DVec3; 3]) -> DVec3 {
    (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero()
}

/// Signed distances of `pts` from the plane of `tri` (along its normal): the
/// sign from the exact `orient3d`, the size from the same determinant.
fn plane_distances(tri: [DVec3; 3], pts: [DVec3; 3]) -> [f64; 3] {
    let c = |p: DVec3| robust::Coord3D { x: p.x, y: p.y, z: p.z };
    let twice_area = (tri[1] - tri[0]).cross(tri[2] - tri[0]).length();
    // orient3d is positive below the plane, where the normal points away.
    pts.map(|p| -robust::orient3d(c(tri[0]), c(tri[1]), c(tri[2]), c(p)) / twice_area)
}

/// Where a triangle meets a plane, from its corners' signed distances `d` and
/// signs `s` (not all on one side): two points (equal for a touch).
fn plane_crossing(t: [DVec3; 3], d: [f64; 3], s: [i32; 3]) -> Option<[DVec3; 2]> {
    let mut found = [DVec3::ZERO; 2];
    let mut n = 0;
    let mut push = |p: DVec3| {
        if n < 2 {
            found[n] = p;
        }
        n += 1;
    };
    for i in 0..3 {
        if s[i] == 0 {
            push(t[i]);
        }
    }
    for i in 0..3 {
        let j = (i + 1) % 3;
        if s[i] * s[j] < 0 {
            let u = d[i] / (d[i] - d[j]);
            push(t[i] + (t[j] - t[i]) * u);
        }
    }
    match n {
        1 => Some([found[0], found[0]]),
        2 => Some(found),
        _ => None,
    }
}

/// The live triangles' point edges, sorted ([`sorted_edges`]).
struct EdgeUsers(Vec<EdgeUse>);

impl EdgeUsers {
    /// The uses of the edge between points `a` and `b`.
    fn of(&self, a: u32, b: u32) -> &[EdgeUse] {
        let key = (a.min(b), a.max(b));
        let start = self.0.partition_point(|e| (e.lo, e.hi) < key);
        let end = start + self.0[start..].partition_point(|e| (e.lo, e.hi) == key);
        &self.0[start..end]
    }
}

/// The state of step 3: the points each triangle gains.
struct Planner<'a> {
    work: &'a mut Work,
    corners: &'a [[DVec3; 3]],
    points: &'a [[u32; 3]],
    tol: f64,
    edge_users: &'a EdgeUsers,
    /// New points of each triangle (sorted by triangle: deterministic order).
    extra: BTreeMap<u32, Vec<u32>>,
    /// Segments of each triangle.
    segs_of: BTreeMap<u32, Vec<u32>>,
}

impl Planner<'_> {
    fn position(&self, p: u32) -> DVec3 {
        self.work.points[p as usize].as_dvec3()
    }

    /// Where point `p` lies on triangle `t`.
    fn locate(&self, t: u32, p: u32) -> Loc {
        let ids = self.points[t as usize];
        if let Some(k) = ids.iter().position(|&c| c == p) {
            return Loc::Corner(k);
        }
        locate(self.corners[t as usize], self.position(p), self.tol)
    }

    /// True when the segment lies on a rim edge (one user) of both its triangles.
    fn on_rims_of_both(&self, s: &Segment) -> bool {
        s.tris.iter().all(|&t| match self.edge_holding(t, s.ends) {
            Some(k) => {
                let [a, b] = [self.points[t as usize][k], self.points[t as usize][(k + 1) % 3]];
                self.edge_users.of(a, b).len() <= 1
            }
            None => false,
        })
    }

    /// The edge of `t` that holds both points, if any.
    fn edge_holding(&self, t: u32, ends: [u32; 2]) -> Option<usize> {
        let on = |loc: Loc| -> [bool; 3] {
            match loc {
                Loc::Corner(k) => {
                    let mut e = [false; 3];
                    e[k] = true;
                    e[(k + 2) % 3] = true;
                    e
                }
                Loc::Edge(k, _) => {
                    let mut e = [false; 3];
                    e[k] = true;
                    e
                }
                _ => [false; 3],
            }
        };
        let (x, y) = (on(self.locate(t, ends[0])), on(self.locate(t, ends[1])));
        (0..3).find(|&k| x[k] && y[k])
    }

    /// Adds queued (triangle, point) pairs and what follows from them.
    fn propagate(&mut self, queue: &mut VecDeque<(u32, u32)>, segments: &mut [Segment]) {
        while let Some((t, p)) = queue.pop_front() {
            let loc = self.locate(t, p);
            if matches!(loc, Loc::Corner(_) | Loc::Outside) {
                continue;
            }
            let list = self.extra.entry(t).or_default();
            if list.contains(&p) {
                continue;
            }
            list.push(p);
            // On an edge: every other user of the edge gets it too.
            if let Loc::Edge(k, _) = loc {
                let ids = self.points[t as usize];
                let (a, b) = (ids[k], ids[(k + 1) % 3]);
                queue.extend(self.edge_users.of(a, b).iter().filter(|e| e.tri != t).map(|e| (e.tri, p)));
            }
            // On a segment of this triangle: the segment is split there, in both its triangles.
            let segs = self.segs_of.get(&t).cloned().unwrap_or_default();
            for si in segs {
                let s = &mut segments[si as usize];
                if s.ends.contains(&p) || s.inner.contains(&p) {
                    continue;
                }
                let (a, b) = (self.work.points[s.ends[0] as usize].as_dvec3(), self.work.points[s.ends[1] as usize].as_dvec3());
                if on_segment(a, b, self.position(p), self.tol) {
                    s.inner.push(p);
                    queue.extend(s.tris.iter().filter(|&&u| u != t).map(|&u| (u, p)));
                }
            }
        }
    }

    /// Crossings of two segments inside a triangle: three triangles meet at a
    /// point, which goes into all three segments. Returns whether any was new.
    fn find_crossings(
        &mut self,
        segments: &mut [Segment],
        pair_segment_of: &HashMap<(u32, u32), u32>,
        crossings: &mut HashMap<[u32; 3], u32>,
        queue: &mut VecDeque<(u32, u32)>,
    ) -> bool {
        let mut found = false;
        let tris: Vec<u32> = self.segs_of.iter().filter(|(_, s)| s.len() >= 2).map(|(&t, _)| t).collect();
        for t in tris {
            let segs = self.segs_of[&t].clone();
            for (i, &s1) in segs.iter().enumerate() {
                for &s2 in &segs[i + 1..] {
                    let (x, y) = (&segments[s1 as usize], &segments[s2 as usize]);
                    let other = |s: &Segment| if s.tris[0] == t { s.tris[1] } else { s.tris[0] };
                    let mut key = [t, other(x), other(y)];
                    key.sort_unstable();
                    if crossings.contains_key(&key) || x.ends.iter().any(|e| y.ends.contains(e)) {
                        continue;
                    }
                    let pos = |p: u32| self.work.points[p as usize].as_dvec3();
                    let Some(q) = segment_crossing([pos(x.ends[0]), pos(x.ends[1])], [pos(y.ends[0]), pos(y.ends[1])], self.tol) else {
                        continue;
                    };
                    let mut touched = vec![s1, s2];
                    let (o1, o2) = (other(x), other(y));
                    if let Some(&s3) = pair_segment_of.get(&(o1.min(o2), o1.max(o2))) {
                        let s = &segments[s3 as usize];
                        if on_segment(pos(s.ends[0]), pos(s.ends[1]), q, 2.0 * self.tol) {
                            touched.push(s3);
                        }
                    }
                    let point = self.work.push_point(q.as_vec3());
                    crossings.insert(key, point);
                    found = true;
                    for si in touched {
                        let s = &mut segments[si as usize];
                        s.inner.push(point);
                        queue.extend(s.tris.iter().map(|&u| (u, point)));
                    }
                }
            }
        }
        found
    }
}

/// Where `p` lies on the triangle with corners `c`, within `tol` of its edges.
fn locate(c: [DVec3; 3], p: DVec3, tol: f64) -> Loc {
    let (e0, e1, e2) = (c[1] - c[0], c[2] - c[0], p - c[0]);
    let (d00, d01, d11) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
    let (d20, d21) = (e2.dot(e0), e2.dot(e1));
    let denom = d00 * d11 - d01 * d01;
    if denom <= 0.0 {
        return Loc::Outside;
    }
    let b1 = (d11 * d20 - d01 * d21) / denom;
    let b2 = (d00 * d21 - d01 * d20) / denom;
    let bary = [1.0 - b1 - b2, b1, b2];
    let twice_area = e0.cross(e1).length();
    // Distance from the edge opposite corner i: its barycentric times the height.
    let dist: [f64; 3] = [0, 1, 2].map(|i| bary[i] * twice_area / c[(i + 1) % 3].distance(c[(i + 2) % 3]));
    if dist.iter().any(|&d| d < -tol) {
        return Loc::Outside;
    }
    let near: Vec<usize> = (0..3).filter(|&i| dist[i] <= tol).collect();
    match near.as_slice() {
        [] => Loc::Interior(b1, b2),
        [i] => {
            let k = (i + 1) % 3;
            let (bk, bn) = (bary[k], bary[(k + 1) % 3]);
            Loc::Edge(k, (bn / (bk + bn)).clamp(0.0, 1.0))
        }
        // Near two edges: at their common corner, which it is not (ids differ):
        // on the edge it is nearer to.
        _ => {
            let i = *near.iter().min_by(|&&x, &&y| dist[x].total_cmp(&dist[y]).then(x.cmp(&y))).unwrap_or(&near[0]);
            let k = (i + 1) % 3;
            let (bk, bn) = (bary[k].max(0.0), bary[(k + 1) % 3].max(0.0));
            if bk + bn <= 0.0 {
                return Loc::Outside;
            }
            Loc::Edge(k, (bn / (bk + bn)).clamp(0.0, 1.0))
        }
    }
}

/// True when `p` lies within `tol` of segment `a`–`b`, farther than `tol` from both ends.
fn on_segment(a: DVec3, b: DVec3, p: DVec3, tol: f64) -> bool {
    let ab = b - a;
    let len2 = ab.length_squared();
    if len2 == 0.0 || p.distance(a) <= tol || p.distance(b) <= tol {
        return false;
    }
    let u = (p - a).dot(ab) / len2;
    u > 0.0 && u < 1.0 && p.distance(a + ab * u) <= tol
}

/// The crossing of two segments (nearly in one plane) inside both, farther
/// than `tol` from their ends, when they pass within `2 tol` of each other there.
fn segment_crossing(x: [DVec3; 2], y: [DVec3; 2], tol: f64) -> Option<DVec3> {
    let (d1, d2, r) = (x[1] - x[0], y[1] - y[0], x[0] - y[0]);
    let (a, e, f) = (d1.dot(d1), d2.dot(d2), d2.dot(r));
    let (b, c) = (d1.dot(d2), d1.dot(r));
    let denom = a * e - b * b;
    if denom <= 1e-12 * a * e {
        return None;
    }
    let s = (b * f - c * e) / denom;
    let u = (a * f - b * c) / denom;
    if !(0.0..=1.0).contains(&s) || !(0.0..=1.0).contains(&u) {
        return None;
    }
    let (p, q) = (x[0] + d1 * s, y[0] + d2 * u);
    let mid = (p + q) * 0.5;
    let away = |seg: [DVec3; 2]| mid.distance(seg[0]) > tol && mid.distance(seg[1]) > tol;
    (p.distance(q) <= 2.0 * tol && away(x) && away(y)).then_some(mid)
}

/// Rounds to a multiple of [`QUANTUM`].
fn quantize(x: f64) -> f64 {
    (x / QUANTUM).round() * QUANTUM
}

/// The triangle's frame: `A = (0, 0)`, `B = (1, 0)`, `C = (c, h)`, the shape of
/// the triangle rounded so that every coordinate below is exact.
struct Frame {
    c: f64,
    h: f64,
}

impl Frame {
    fn of(p: [DVec3; 3]) -> Frame {
        let (ab, ac) = (p[1] - p[0], p[2] - p[0]);
        let l2 = ab.length_squared();
        let round = |x: f64| (x / SHAPE_QUANTUM).round() * SHAPE_QUANTUM;
        let c = round(ac.dot(ab) / l2).clamp(-1024.0, 1024.0);
        let h = round(ac.cross(ab).length() / l2).clamp(SHAPE_QUANTUM, 1024.0);
        Frame { c, h }
    }

    /// The 2D point of barycentric coordinates (of corners 1 and 2), multiples of [`QUANTUM`].
    fn at(&self, b1: f64, b2: f64) -> Point2<f64> {
        Point2::new(b1 + b2 * self.c, b2 * self.h)
    }

    /// Barycentric coordinates (of corners 1 and 2) of a 2D point.
    fn bary(&self, p: Point2<f64>) -> (f64, f64) {
        let b2 = p.y / self.h;
        (p.x - b2 * self.c, b2)
    }
}

/// Frame coordinates (barycentric, of corners 1 and 2, exact) of a point at `loc`.
fn frame_bary(loc: Loc) -> Option<(f64, f64)> {
    let q = |s: f64| quantize(s).clamp(QUANTUM, 1.0 - QUANTUM);
    match loc {
        Loc::Corner(0) => Some((0.0, 0.0)),
        Loc::Corner(1) => Some((1.0, 0.0)),
        Loc::Corner(_) => Some((0.0, 1.0)),
        Loc::Edge(0, s) => Some((q(s), 0.0)),
        Loc::Edge(1, s) => {
            let s = q(s);
            Some((1.0 - s, s))
        }
        Loc::Edge(_, s) => Some((0.0, 1.0 - q(s))),
        Loc::Interior(b1, b2) => {
            let (mut b1, mut b2) = (quantize(b1).max(QUANTUM), quantize(b2).max(QUANTUM));
            let excess = b1 + b2 - (1.0 - QUANTUM);
            if excess > 0.0 {
                if b1 >= b2 {
                    b1 -= excess;
                } else {
                    b2 -= excess;
                }
            }
            (b1 >= QUANTUM && b2 >= QUANTUM).then_some((b1, b2))
        }
        Loc::Outside => None,
    }
}

/// Barycentric weights of the three corners at `loc` (exact parameters, for attributes).
fn weights(loc: Loc) -> [f32; 3] {
    match loc {
        Loc::Corner(k) => {
            let mut w = [0.0; 3];
            w[k] = 1.0;
            w
        }
        Loc::Edge(k, s) => {
            let mut w = [0.0; 3];
            w[k] = (1.0 - s) as f32;
            w[(k + 1) % 3] = s as f32;
            w
        }
        Loc::Interior(b1, b2) => [(1.0 - b1 - b2) as f32, b1 as f32, b2 as f32],
        Loc::Outside => [1.0 / 3.0; 3],
    }
}

/// What triangulating one triangle did.
#[derive(Default)]
struct Pieces {
    count: usize,
    /// Crossings of two constraints this triangle's frame found and split alone.
    unshared: usize,
    /// Constraint pieces the triangulation could not insert.
    dropped: usize,
}

/// Upper bound on the crossings split within one triangle's frame.
const MAX_FRAME_SPLITS: usize = 64;

/// Replaces triangle `t` by the constrained triangulation of its corners, the
/// points `pts` and the segments `segs`. `None` when it failed (the triangle
/// is left whole).
fn triangulate(work: &mut Work, t: usize, pts: &[u32], segs: &[&Segment], tol: f64) -> Option<Pieces> {
    let corners = work.tri_positions(t).map(|p| p.as_dvec3());
    let ids = work.tri_points(t);
    let frame = Frame::of(corners);
    let locate_point = |work: &Work, p: u32| -> Loc {
        match ids.iter().position(|&c| c == p) {
            Some(k) => Loc::Corner(k),
            None => locate(corners, work.points[p as usize].as_dvec3(), tol),
        }
    };
    // The points: (point id, location, frame position); the index is the local id.
    let mut local: Vec<(u32, Loc, Point2<f64>)> = Vec::new();
    let mut local_of: HashMap<u32, usize> = HashMap::new();
    let mut at_position: HashMap<[u64; 2], usize> = HashMap::new();
    let mut add = |local: &mut Vec<(u32, Loc, Point2<f64>)>, p: u32, loc: Loc| -> Option<usize> {
        let (b1, b2) = frame_bary(loc)?;
        let xy = frame.at(b1, b2);
        // Two points at one frame position are one vertex (the older id).
        let i = *at_position.entry([xy.x.to_bits(), xy.y.to_bits()]).or_insert_with(|| {
            local.push((p, loc, xy));
            local.len() - 1
        });
        Some(i)
    };
    for (k, &corner) in ids.iter().enumerate() {
        let i = add(&mut local, corner, Loc::Corner(k))?;
        local_of.insert(corner, i);
    }
    let mut on_edge: [Vec<(f64, usize)>; 3] = Default::default();
    for &p in pts {
        let loc = locate_point(work, p);
        if matches!(loc, Loc::Outside | Loc::Corner(_)) {
            continue;
        }
        if let Some(i) = add(&mut local, p, loc) {
            local_of.insert(p, i);
            if let Loc::Edge(k, s) = loc {
                on_edge[k].push((s, i));
            }
        }
    }
    let mut boundary: Vec<[usize; 2]> = Vec::new();
    for (k, list) in on_edge.iter_mut().enumerate() {
        list.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        let mut chain = vec![k];
        chain.extend(list.iter().map(|&(_, i)| i));
        chain.push((k + 1) % 3);
        chain.dedup();
        boundary.extend(chain.windows(2).map(|w| [w[0], w[1]]));
    }
    // Segment pieces inside the triangle (pieces along an edge are boundary).
    let on_edges = |loc: Loc| -> u8 {
        match loc {
            Loc::Corner(k) => (1 << k) | (1 << ((k + 2) % 3)),
            Loc::Edge(k, _) => 1 << k,
            _ => 0,
        }
    };
    let mut pieces: Vec<[usize; 2]> = Vec::new();
    for s in segs {
        let (a, b) = (work.points[s.ends[0] as usize].as_dvec3(), work.points[s.ends[1] as usize].as_dvec3());
        let mut along: Vec<(f64, usize)> = s
            .ends
            .iter()
            .chain(&s.inner)
            .filter_map(|&p| local_of.get(&p).map(|&i| ((work.points[p as usize].as_dvec3() - a).dot(b - a), i)))
            .collect();
        along.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        along.dedup_by_key(|x| x.1);
        for w in along.windows(2) {
            let (i, j) = (w[0].1, w[1].1);
            if i != j && on_edges(local[i].1) & on_edges(local[j].1) == 0 {
                pieces.push([i.min(j), i.max(j)]);
            }
        }
    }
    pieces.sort_unstable();
    pieces.dedup();
    // Crossings the 3D pass missed, in this frame's exact arithmetic: split both pieces.
    let mut out = Pieces::default();
    let xy = |local: &[(u32, Loc, Point2<f64>)], i: usize| robust::Coord { x: local[i].2.x, y: local[i].2.y };
    for _ in 0..MAX_FRAME_SPLITS {
        let Some((x, y, q)) = first_crossing(&pieces, |i| xy(&local, i)) else { break };
        let (b1, b2) = frame.bary(q);
        let loc = Loc::Interior(b1, b2);
        let Some((b1, b2)) = frame_bary(loc) else { break };
        let point = corners[0] + (corners[1] - corners[0]) * b1 + (corners[2] - corners[0]) * b2;
        let id = work.push_point(point.as_vec3());
        let Some(m) = add(&mut local, id, Loc::Interior(b1, b2)) else { break };
        out.unshared += 1;
        let [p, q] = [pieces[x], pieces[y]];
        pieces.retain(|e| *e != p && *e != q);
        for [a, b] in [[p[0], m], [m, p[1]], [q[0], m], [m, q[1]]] {
            if a != b {
                pieces.push([a.min(b), a.max(b)]);
            }
        }
        pieces.sort_unstable();
        pieces.dedup();
    }

    let mut cdt: ConstrainedDelaunayTriangulation<Point2<f64>> = ConstrainedDelaunayTriangulation::new();
    let mut handles = Vec::with_capacity(local.len());
    for &(_, _, xy) in &local {
        handles.push(cdt.insert(xy).ok()?);
    }
    for [i, j] in boundary.into_iter().chain(pieces) {
        let (a, b) = (handles[i], handles[j]);
        if a != b && !cdt.exists_constraint(a, b) && cdt.try_add_constraint(a, b).is_empty() {
            out.dropped += 1;
        }
    }
    // Spade numbers vertices in insertion order (no two share a position).
    if handles.iter().enumerate().any(|(i, h)| h.index() != i) {
        return None;
    }
    // Vertices: the corners keep theirs, new points get one interpolated here.
    let tri_vertices = work.tris[t];
    let vertex_of: Vec<u32> = local
        .iter()
        .map(|&(p, loc, _)| match loc {
            Loc::Corner(k) => tri_vertices[k],
            _ => work.push_vertex_bary(tri_vertices, weights(loc), p),
        })
        .collect();
    let faces: Vec<[u32; 3]> = cdt.inner_faces().map(|f| f.vertices().map(|v| vertex_of[v.fix().index()])).collect();
    if faces.is_empty() {
        return None;
    }
    work.tris[t] = faces[0];
    for &f in &faces[1..] {
        work.push_tri_like(f, t);
    }
    out.count = faces.len();
    Some(out)
}

/// The first pair of pieces (in order) that cross properly in the frame
/// (each one's ends strictly on both sides of the other's line, exactly), and
/// the crossing point.
fn first_crossing(pieces: &[[usize; 2]], xy: impl Fn(usize) -> robust::Coord<f64>) -> Option<(usize, usize, Point2<f64>)> {
    for (x, &[a, b]) in pieces.iter().enumerate() {
        for (y, &[c, d]) in pieces.iter().enumerate().skip(x + 1) {
            if a == c || a == d || b == c || b == d {
                continue;
            }
            let (pa, pb, pc, pd) = (xy(a), xy(b), xy(c), xy(d));
            let side = |p, q, r| robust::orient2d(p, q, r);
            let (s1, s2) = (side(pa, pb, pc), side(pa, pb, pd));
            let (s3, s4) = (side(pc, pd, pa), side(pc, pd, pb));
            if s1 * s2 < 0.0 && s3 * s4 < 0.0 {
                let u = s3 / (s3 - s4);
                return Some((x, y, Point2::new(pa.x + (pb.x - pa.x) * u, pa.y + (pb.y - pa.y) * u)));
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(p: [[f64; 3]; 3]) -> [DVec3; 3] {
        p.map(DVec3::from)
    }

    #[test]
    fn crossing_triangles_meet_in_their_common_segment() {
        // A in y = 0, B in x = 0.3: they cross along x = 0.3, y = 0.
        let a = tri([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]);
        let b = tri([[0.3, -1.0, 0.2], [0.3, 1.0, 0.2], [0.3, 0.0, 0.5]]);
        let [p, q] = pair_segment(a, b, 1e-9, 1e-9).unwrap();
        let (lo, hi) = if p.z < q.z { (p, q) } else { (q, p) };
        assert!(lo.distance(DVec3::new(0.3, 0.0, 0.2)) < 1e-12, "{lo}");
        assert!(hi.distance(DVec3::new(0.3, 0.0, 0.5)) < 1e-12, "{hi}");
    }

    #[test]
    fn touching_in_a_point_or_coplanar_is_no_segment() {
        let a = tri([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]);
        // Touches A's plane in one corner only.
        let b = tri([[0.2, 0.0, 0.2], [0.2, 1.0, 0.2], [0.4, 1.0, 0.2]]);
        assert!(pair_segment(a, b, 1e-9, 1e-9).is_none());
        // Coplanar and overlapping.
        let c = tri([[0.1, 0.0, 0.1], [2.0, 0.0, 0.1], [0.1, 0.0, 2.0]]);
        assert!(pair_segment(a, c, 1e-9, 1e-9).is_none());
    }

    #[test]
    fn frame_puts_edge_points_exactly_on_the_edges() {
        let f = Frame::of(tri([[0.0, 0.0, 0.0], [3.0, 0.1, 0.0], [0.7, 2.9, 0.3]]));
        let c = |p: Point2<f64>| robust::Coord { x: p.x, y: p.y };
        let (a, b, cc) = (f.at(0.0, 0.0), f.at(1.0, 0.0), f.at(0.0, 1.0));
        for s in [0.1, 0.123456789, 0.5, 0.999] {
            for (k, (from, to)) in [(a, b), (b, cc), (cc, a)].into_iter().enumerate() {
                let (b1, b2) = frame_bary(Loc::Edge(k, s)).unwrap();
                assert_eq!(robust::orient2d(c(from), c(to), c(f.at(b1, b2))), 0.0, "edge {k} at {s}");
            }
        }
    }
}
