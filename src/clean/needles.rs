//! Raising the smallest angle of the triangles the cut made.
//!
//! Why: the cut re-triangulates each plane it cuts, but two things it
//! cannot change leave needles there (the dining room: 1,469 new triangles
//! under 1°, the smallest 1.6e-5°): points of one cut line a fraction of a
//! millimetre apart (ends of pieces from different crossings), and a
//! region's outline, which it keeps whole because triangles outside the
//! region share it. A vertex interpolated across a needle cannot resolve the
//! light, and the next round removes the thinnest as degenerate and zips the
//! holes shut, which joins surfaces again (non-manifold edges).
//!
//! Here, on the whole mesh (a point on a shared edge goes into every
//! triangle that uses it, so no T-junction appears), each made triangle
//! under the target angle is repaired by the first of:
//! 1. **collapse** a side under the zip tolerance (its points move by less
//!    than the clean already allows), if the link condition holds (no new
//!    non-manifold edge), no triangle around turns over by 10° or more, and
//!    none that stays gets worse than the target or than it was;
//! 2. **snap a cap**: a corner within the zip tolerance of the opposite
//!    side moves onto it, at its foot, and the triangle across that side is
//!    split there (same conditions);
//! 3. **insert** its circumcentre (Chew's and Ruppert's Delaunay
//!    refinement, on the surface): walk there across free edges (two
//!    triangles of one plane, material and group over the same vertices: no
//!    seam, no cut line, no crease); a point beyond a constrained edge, or
//!    in its diametral circle, splits that edge at its midpoint instead, in
//!    every triangle that uses it; then **flip** the free edges around the
//!    new point while that raises the smaller angle of their two triangles
//!    (Lawson);
//! 4. at a small angle between two constrained edges (which no point can
//!    raise), **flip across a crease**: an edge of a curved surface whose
//!    flip moves the surface by less than the zip tolerance, each new
//!    triangle facing within 30° of both old ones.
//!
//! Left as they are: a small angle between two edges that cannot flip (a
//! hard edge, a seam, a sharper crease), and a point that would come closer
//! than the zip tolerance to a corner of its triangle or than a few weld
//! tolerances to any point (another sheet's, which the next round's weld
//! would join to it). In-plane flips and new points keep the area exactly;
//! collapses, snaps and crease flips move the surface by less than the zip
//! tolerance.

use super::work::{edge_runs, min_angle, sorted_edges, Work};
use glam::DVec3;
use std::collections::{HashMap, VecDeque};

/// Tolerances of [`repair_needles`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct NeedleTolerances {
    /// Target smallest angle (radians).
    pub min_angle: f64,
    /// Sides shorter than this may collapse (the zip tolerance).
    pub collapse: f64,
    /// Distance within which two triangles count as one plane.
    pub plane: f64,
    /// No new triangle has a height under this (the weld tolerance), and no
    /// new point comes within a few of it of any point.
    pub height: f64,
    /// No new point comes closer than this to a corner of the triangle it
    /// goes in, or to an end of the edge it splits or lands on.
    pub spacing: f64,
}

/// What [`repair_needles`] did.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct NeedleOutcome {
    /// Triangles under the target angle before and after.
    pub needles_before: usize,
    pub needles_after: usize,
    pub sides_collapsed: usize,
    pub points_inserted: usize,
    pub edges_split: usize,
    pub edges_flipped: usize,
    /// Smallest angle (radians) of the made triangles after; infinite when none.
    pub min_angle_after: f64,
}

/// Operations per needle at most (each adds at most one point).
const OPS_PER_NEEDLE: usize = 64;
/// Steps of the walk to a circumcentre.
const MAX_WALK: usize = 256;
/// A collapse or snap that turns a triangle by more than this (cosine of 10°) is refused.
const COLLAPSE_MIN_COS: f64 = 0.984_807_753;
/// No new point within this many height tolerances of any point (another
/// sheet's too), which the next round's weld would join to it.
const CROWD_HEIGHTS: f64 = 4.0;
/// A flip across a crease makes triangles facing within this (cosine, 30°) of both old ones.
const CREASE_MIN_COS: f64 = 0.866_025_404;
/// A flip must raise the smaller angle by more than this (radians).
const FLIP_MARGIN: f64 = 1e-7;

/// Repairs the triangles `made` marks (indexed like `work.tris`) whose
/// smallest angle is under the target (see the module doc).
pub(crate) fn repair_needles(work: &mut Work, made: &[bool], tol: &NeedleTolerances) -> NeedleOutcome {
    let mut mesh = Surface::new(work, made, CROWD_HEIGHTS * tol.height);
    let mut out = NeedleOutcome { min_angle_after: f64::INFINITY, ..NeedleOutcome::default() };
    let mut queue: VecDeque<u32> = (0..mesh.work.tris.len() as u32).filter(|&t| mesh.is_needle(t, tol.min_angle)).collect();
    out.needles_before = queue.len();
    let mut budget = OPS_PER_NEEDLE * queue.len() + 64;
    while let Some(t) = queue.pop_front() {
        if budget == 0 {
            break;
        }
        if !mesh.is_needle(t, tol.min_angle) {
            continue;
        }
        budget -= 1;
        let mut touched = mesh.repair(t, tol, &mut out);
        // A point put elsewhere (where the walk ended) may leave `t` as it was: again.
        if !touched.is_empty() {
            touched.push(t);
        }
        touched.sort_unstable();
        touched.dedup();
        queue.extend(touched.into_iter().filter(|&u| mesh.is_needle(u, tol.min_angle)));
    }
    for t in 0..mesh.work.tris.len() as u32 {
        if mesh.made[t as usize] && mesh.work.tri_alive[t as usize] {
            let a = mesh.angle(t);
            out.min_angle_after = out.min_angle_after.min(a);
            out.needles_after += usize::from(a < tol.min_angle);
        }
    }
    out
}

/// The mesh with its point-edge users and the triangles around each point, kept current.
struct Surface<'a> {
    work: &'a mut Work,
    made: Vec<bool>,
    users: HashMap<(u32, u32), Vec<u32>>,
    around: Vec<Vec<u32>>,
    /// Points by cell of side `crowd`: a new point comes no closer than
    /// that to any point, another sheet's too (which the next round's weld
    /// would otherwise join to it, making non-manifold edges).
    cells: HashMap<[i64; 3], Vec<u32>>,
    crowd: f64,
}

fn key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

/// Twice the area vector of a triangle.
fn cross(p: [DVec3; 3]) -> DVec3 {
    (p[1] - p[0]).cross(p[2] - p[0])
}

/// Its height over its longest side.
fn height(p: [DVec3; 3]) -> f64 {
    let longest = p[0].distance(p[1]).max(p[1].distance(p[2])).max(p[2].distance(p[0]));
    if longest > 0.0 {
        cross(p).length() / longest
    } else {
        0.0
    }
}

fn circumcentre(p: [DVec3; 3]) -> Option<DVec3> {
    let (ab, ac) = (p[1] - p[0], p[2] - p[0]);
    let n = ab.cross(ac);
    let d = 2.0 * n.length_squared();
    (d > 0.0).then(|| p[0] + (ac.length_squared() * n.cross(ab) + ab.length_squared() * ac.cross(n)) / d)
}

/// Where a walk to a point ends.
enum Walk {
    /// In this triangle, at these barycentric coordinates.
    Inside(u32, [f64; 3]),
    /// Beyond this constrained edge of this triangle (corner index of its start).
    Beyond(u32, usize),
    Lost,
}

impl<'a> Surface<'a> {
    fn new(work: &'a mut Work, made: &[bool], crowd: f64) -> Self {
        let mut users: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
        let edges = sorted_edges(work);
        for run in edge_runs(&edges) {
            users.insert((run[0].lo, run[0].hi), run.iter().map(|e| e.tri).collect());
        }
        let mut around = vec![Vec::new(); work.points.len()];
        for t in 0..work.tris.len() {
            if work.tri_alive[t] {
                for p in work.tri_points(t) {
                    around[p as usize].push(t as u32);
                }
            }
        }
        let mut made = made.to_vec();
        made.resize(work.tris.len(), false);
        let mut surface = Surface { work, made, users, around, cells: HashMap::new(), crowd };
        for p in 0..surface.around.len() as u32 {
            if !surface.around[p as usize].is_empty() {
                surface.add_to_cell(p);
            }
        }
        surface
    }

    fn cell(&self, x: DVec3) -> [i64; 3] {
        (x / self.crowd).floor().as_i64vec3().to_array()
    }

    fn add_to_cell(&mut self, p: u32) {
        let c = self.cell(self.pos(p));
        self.cells.entry(c).or_default().push(p);
    }

    /// True when a point other than `except` lies within `crowd` of `x`.
    fn crowded(&self, x: DVec3, except: &[u32]) -> bool {
        let c = self.cell(x);
        (-1..=1).any(|i| {
            (-1..=1).any(|j| {
                (-1..=1).any(|k| {
                    self.cells
                        .get(&[c[0] + i, c[1] + j, c[2] + k])
                        .is_some_and(|ps| ps.iter().any(|&p| !except.contains(&p) && self.pos(p).distance(x) < self.crowd))
                })
            })
        })
    }

    fn pos(&self, p: u32) -> DVec3 {
        self.work.points[p as usize].as_dvec3()
    }

    fn corners(&self, t: u32) -> [DVec3; 3] {
        self.work.tri_points(t as usize).map(|p| self.pos(p))
    }

    fn angle(&self, t: u32) -> f64 {
        min_angle(self.corners(t))
    }

    fn is_needle(&self, t: u32, target: f64) -> bool {
        let t = t as usize;
        t < self.work.tris.len() && self.made[t] && self.work.tri_alive[t] && min_angle(self.corners(t as u32)) < target
    }

    fn users(&self, a: u32, b: u32) -> &[u32] {
        self.users.get(&key(a, b)).map_or(&[], |v| v.as_slice())
    }

    fn unlink(&mut self, t: u32) {
        let p = self.work.tri_points(t as usize);
        for i in 0..3 {
            let k = key(p[i], p[(i + 1) % 3]);
            if let Some(v) = self.users.get_mut(&k) {
                v.retain(|&u| u != t);
                if v.is_empty() {
                    self.users.remove(&k);
                }
            }
            self.around[p[i] as usize].retain(|&u| u != t);
        }
    }

    fn link(&mut self, t: u32) {
        let p = self.work.tri_points(t as usize);
        for i in 0..3 {
            self.users.entry(key(p[i], p[(i + 1) % 3])).or_default().push(t);
            if self.around.len() <= p[i] as usize {
                self.around.resize(p[i] as usize + 1, Vec::new());
            }
            self.around[p[i] as usize].push(t);
        }
    }

    fn set(&mut self, t: u32, tri: [u32; 3]) {
        self.unlink(t);
        self.work.tris[t as usize] = tri;
        self.made[t as usize] = true;
        self.link(t);
    }

    fn push(&mut self, tri: [u32; 3], parent: u32) -> u32 {
        self.work.push_tri_like(tri, parent as usize);
        self.made.push(true);
        let t = (self.work.tris.len() - 1) as u32;
        self.link(t);
        t
    }

    /// The triangle across edge `i` (corner `i` to `i + 1`) of `t` when that
    /// edge is free: two users of one plane, material and group, wound
    /// oppositely over the same two vertices. Returns it and its corner
    /// opposite the edge.
    fn across_free(&self, t: u32, i: usize, plane: f64) -> Option<(u32, usize)> {
        let p = self.work.tri_points(t as usize);
        let (a, b) = (p[i], p[(i + 1) % 3]);
        let users = self.users(a, b);
        if users.len() != 2 {
            return None;
        }
        let u = if users[0] == t { users[1] } else { users[0] };
        let (tu, uu) = (t as usize, u as usize);
        if self.work.tri_material[tu] != self.work.tri_material[uu] || self.work.tri_group[tu] != self.work.tri_group[uu] {
            return None;
        }
        let q = self.work.tri_points(uu);
        let j = (0..3).find(|&j| q[j] == b && q[(j + 1) % 3] == a)?;
        let (vt, vu) = (self.work.tris[tu], self.work.tris[uu]);
        if vu[j] != vt[(i + 1) % 3] || vu[(j + 1) % 3] != vt[i] {
            return None;
        }
        let d = q[(j + 2) % 3];
        let n = cross(self.corners(t)).try_normalize()?;
        let nu = cross(self.corners(u)).try_normalize()?;
        ((self.pos(d) - self.pos(a)).dot(n).abs() <= plane && n.dot(nu) > 0.0).then_some((u, (j + 2) % 3))
    }

    /// Repairs needle `t`; returns the triangles it changed or made (none when it could not).
    fn repair(&mut self, t: u32, tol: &NeedleTolerances, out: &mut NeedleOutcome) -> Vec<u32> {
        let p = self.work.tri_points(t as usize);
        let c = self.corners(t);
        // 1. A side short enough to collapse.
        let mut sides: Vec<usize> = (0..3).filter(|&i| c[i].distance(c[(i + 1) % 3]) < tol.collapse).collect();
        sides.sort_by(|&i, &j| c[i].distance(c[(i + 1) % 3]).total_cmp(&c[j].distance(c[(j + 1) % 3])));
        for i in sides {
            if let Some(touched) = self.collapse(p[i], p[(i + 1) % 3], tol) {
                out.sides_collapsed += 1;
                return touched;
            }
        }
        let angles = super::work::triangle_angles(c);
        // 2. A cap (a corner within the collapse distance of the opposite
        //    side): the corner moves onto that side, which takes it.
        let big = (0..3).max_by(|&i, &j| angles[i].total_cmp(&angles[j])).unwrap_or(0);
        if angles[big] > std::f64::consts::FRAC_PI_2 {
            if let Some(touched) = self.snap_cap(t, big, tol) {
                out.sides_collapsed += 1;
                return touched;
            }
        }
        // 2b. A cap whose long side is free: flipping that side may be enough.
        if angles[big] > std::f64::consts::FRAC_PI_2 {
            if let Some(u) = self.flip(t, (big + 1) % 3, tol) {
                out.edges_flipped += 1;
                return vec![t, u];
            }
        }
        // 3. Its smallest angle between two constrained edges: no point helps.
        let k = (0..3).min_by(|&i, &j| angles[i].total_cmp(&angles[j])).unwrap_or(0);
        let free_before = self.across_free(t, (k + 2) % 3, tol.plane).is_some();
        let free_after = self.across_free(t, k, tol.plane).is_some();
        if !free_before && !free_after {
            // On a curved surface: a flip across a crease at that corner,
            // moving the surface by less than the collapse distance.
            for e in [(k + 2) % 3, k] {
                if let Some(u) = self.flip_within(t, e, tol.collapse, tol) {
                    out.edges_flipped += 1;
                    return vec![t, u];
                }
            }
            return Vec::new();
        }
        let Some(centre) = circumcentre(c) else { return Vec::new() };
        let made = match self.walk(t, centre, tol.plane) {
            Walk::Inside(u, w) => {
                let cu = self.corners(u);
                // On an edge (within the height tolerance): that edge takes the point.
                let twice_area = cross(cu).length();
                let on_edge = (0..3).find(|&k| w[k] * twice_area < tol.height * cu[(k + 1) % 3].distance(cu[(k + 2) % 3]));
                match (self.encroached(u, centre, tol.plane), on_edge) {
                    (Some(e), _) => self.split_edge(u, e, 0.5, tol, out),
                    _ if cu.iter().any(|&x| x.distance(centre) < tol.spacing) || self.crowded(centre, &[]) => return Vec::new(),
                    (None, Some(k)) => self.split_edge(u, (k + 1) % 3, w[(k + 2) % 3] / (w[(k + 1) % 3] + w[(k + 2) % 3]), tol, out),
                    (None, None) => self.insert(u, w, centre, tol, out),
                }
            }
            Walk::Beyond(u, e) => self.split_edge(u, e, 0.5, tol, out),
            Walk::Lost => return Vec::new(),
        };
        let Some((point, mut touched)) = made else { return Vec::new() };
        self.legalise(point, &mut touched, tol, out);
        touched
    }

    /// Moves corner `big` of cap `t` onto the opposite side a–b, at its foot,
    /// when that is within the collapse distance: `t` goes, and the triangle
    /// across a–b (if any) is split at the moved point. Refused when the
    /// triangles around would turn over or get worse than the target.
    fn snap_cap(&mut self, t: u32, big: usize, tol: &NeedleTolerances) -> Option<Vec<u32>> {
        let p = self.work.tri_points(t as usize);
        let (apex, a, b) = (p[big], p[(big + 1) % 3], p[(big + 2) % 3]);
        let (pa, pb, px) = (self.pos(a), self.pos(b), self.pos(apex));
        let along = (px - pa).dot(pb - pa) / pa.distance_squared(pb);
        let foot = pa.lerp(pb, along);
        if !(0.0..=1.0).contains(&along)
            || foot.distance(px) >= tol.collapse
            || foot.distance(pa).min(foot.distance(pb)) < tol.spacing
            || self.crowded(foot, &[apex])
        {
            return None;
        }
        let users = self.users(a, b);
        if users.len() > 2 {
            return None;
        }
        let across = users.iter().copied().find(|&u| u != t);
        // The triangle across, split at the foot: (b, apex, d) and (apex, a, d).
        let mut split: Option<(u32, usize)> = None;
        if let Some(u) = across {
            let q = self.work.tri_points(u as usize);
            let j = (0..3).find(|&j| q[j] == b && q[(j + 1) % 3] == a)?;
            let d = q[(j + 2) % 3];
            if d == apex || !self.users(apex, d).is_empty() {
                return None;
            }
            split = Some((u, j));
        }
        let moved = |x: u32| if x == apex { foot } else { self.pos(x) };
        let mut before = f64::INFINITY;
        let mut after = f64::INFINITY;
        for &r in self.around[apex as usize].iter().filter(|&&r| r != t) {
            let c = self.corners(r);
            let m = self.work.tri_points(r as usize).map(moved);
            let (n0, n1) = (cross(c), cross(m));
            if n0.dot(n1) <= COLLAPSE_MIN_COS * n0.length() * n1.length() || height(m) < tol.height {
                return None;
            }
            before = before.min(min_angle(c));
            after = after.min(min_angle(m));
        }
        if let Some((u, j)) = split {
            let c = self.corners(u);
            let (cb, ca, cd) = (c[j], c[(j + 1) % 3], c[(j + 2) % 3]);
            for piece in [[cb, foot, cd], [foot, ca, cd]] {
                if height(piece) < tol.height || cross(piece).dot(cross(c)) <= 0.0 {
                    return None;
                }
                after = after.min(min_angle(piece));
            }
            before = before.min(min_angle(c));
        }
        if after < before.min(tol.min_angle) {
            return None;
        }
        // Apply: the point moves; the cap goes; the triangle across is split.
        let ring: Vec<u32> = self.around[apex as usize].clone();
        for &r in &ring {
            self.unlink(r);
        }
        self.work.points[apex as usize] = foot.as_vec3();
        self.add_to_cell(apex);
        self.work.tri_alive[t as usize] = false;
        let mut touched = Vec::new();
        for &r in ring.iter().filter(|&&r| r != t) {
            self.made[r as usize] = true;
            self.link(r);
            touched.push(r);
        }
        if let Some((u, j)) = split {
            let v = self.work.tris[u as usize];
            let (vb, va, vd) = (v[j], v[(j + 1) % 3], v[(j + 2) % 3]);
            let mid = self.work.push_vertex_lerp(va, vb, along as f32, apex);
            self.set(u, [vb, mid, vd]);
            let u2 = self.push([mid, va, vd], u);
            touched.extend([u, u2]);
        }
        Some(touched)
    }

    /// Walks from `t` toward `x` across free edges.
    fn walk(&self, mut t: u32, x: DVec3, plane: f64) -> Walk {
        for _ in 0..MAX_WALK {
            let c = self.corners(t);
            let n = cross(c);
            let nn = n.length_squared();
            if nn == 0.0 {
                return Walk::Lost;
            }
            let w = [0, 1, 2].map(|i| (c[(i + 1) % 3] - x).cross(c[(i + 2) % 3] - x).dot(n) / nn);
            let k = (0..3).min_by(|&i, &j| w[i].total_cmp(&w[j])).unwrap_or(0);
            if w[k] >= 0.0 {
                return Walk::Inside(t, w);
            }
            // Coordinate k is negative: x lies beyond the edge opposite corner k.
            let e = (k + 1) % 3;
            match self.across_free(t, e, plane) {
                Some((u, _)) => t = u,
                None => return Walk::Beyond(t, e),
            }
        }
        Walk::Lost
    }

    /// A constrained edge of `t` whose diametral circle holds `x`.
    fn encroached(&self, t: u32, x: DVec3, plane: f64) -> Option<usize> {
        let c = self.corners(t);
        (0..3).find(|&i| {
            let (a, b) = (c[i], c[(i + 1) % 3]);
            self.across_free(t, i, plane).is_none() && (x - 0.5 * (a + b)).length_squared() < 0.25 * a.distance_squared(b)
        })
    }

    /// Puts a point at `x` (barycentric `w`) inside `t`: three triangles.
    fn insert(&mut self, t: u32, w: [f64; 3], x: DVec3, tol: &NeedleTolerances, out: &mut NeedleOutcome) -> Option<(u32, Vec<u32>)> {
        let v = self.work.tris[t as usize];
        let c = self.corners(t);
        let pieces = [[c[0], c[1], x], [c[1], c[2], x], [c[2], c[0], x]];
        if pieces.iter().any(|&q| height(q) < tol.height) {
            return None;
        }
        let point = self.work.push_point(x.as_vec3());
        self.add_to_cell(point);
        let vertex = self.work.push_vertex_bary(v, w.map(|x| x as f32), point);
        self.set(t, [v[0], v[1], vertex]);
        let t1 = self.push([v[1], v[2], vertex], t);
        let t2 = self.push([v[2], v[0], vertex], t);
        out.points_inserted += 1;
        Some((point, vec![t, t1, t2]))
    }

    /// Splits edge `e` of `t` (corner `e` to `e + 1`) at parameter `s` from
    /// corner `e`, in every triangle that uses it.
    fn split_edge(&mut self, t: u32, e: usize, s: f64, tol: &NeedleTolerances, out: &mut NeedleOutcome) -> Option<(u32, Vec<u32>)> {
        let p = self.work.tri_points(t as usize);
        let (a, b) = (p[e], p[(e + 1) % 3]);
        let users = self.users(a, b).to_vec();
        let (pa, pb) = (self.pos(a), self.pos(b));
        let m = pa.lerp(pb, s);
        if users.is_empty() || users.len() > 2 || m.distance(pa).min(m.distance(pb)) < tol.spacing || self.crowded(m, &[]) {
            return None;
        }
        // Every new triangle must keep a height.
        for &u in &users {
            let q = self.work.tri_points(u as usize);
            let i = (0..3).find(|&i| key(q[i], q[(i + 1) % 3]) == key(a, b))?;
            let cu = self.corners(u);
            let o = cu[(i + 2) % 3];
            if height([cu[i], m, o]) < tol.height || height([m, cu[(i + 1) % 3], o]) < tol.height {
                return None;
            }
        }
        let point = self.work.push_point(m.as_vec3());
        self.add_to_cell(point);
        let mut vertex_of: HashMap<(u32, u32), u32> = HashMap::new();
        let mut touched = Vec::new();
        for u in users {
            let q = self.work.tri_points(u as usize);
            let v = self.work.tris[u as usize];
            let i = (0..3).find(|&i| key(q[i], q[(i + 1) % 3]) == key(a, b))?;
            let (va, vb, vo) = (v[i], v[(i + 1) % 3], v[(i + 2) % 3]);
            // One new vertex per pair of vertices at the ends (a, b).
            let ends = if q[i] == a { (va, vb) } else { (vb, va) };
            let mid = *vertex_of.entry(ends).or_insert_with(|| self.work.push_vertex_lerp(ends.0, ends.1, s as f32, point));
            self.set(u, [va, mid, vo]);
            let u2 = self.push([mid, vb, vo], u);
            touched.extend([u, u2]);
        }
        out.edges_split += 1;
        Some((point, touched))
    }

    /// Lawson flips around `point`: each edge opposite it is flipped while
    /// that raises the smaller angle of its two triangles.
    fn legalise(&mut self, point: u32, touched: &mut Vec<u32>, tol: &NeedleTolerances, out: &mut NeedleOutcome) {
        let mut stack: Vec<u32> = self.around[point as usize].clone();
        let mut flips = 0;
        while let Some(t) = stack.pop() {
            if flips > 4 * OPS_PER_NEEDLE {
                break;
            }
            if !self.work.tri_alive[t as usize] {
                continue;
            }
            let p = self.work.tri_points(t as usize);
            let Some(k) = (0..3).find(|&k| p[k] == point) else { continue };
            let e = (k + 1) % 3;
            if let Some(u) = self.flip(t, e, tol) {
                flips += 1;
                out.edges_flipped += 1;
                touched.extend([t, u]);
                stack.extend([t, u]);
            }
        }
    }

    /// Flips edge `e` of `t` (a→b, its third corner c; the other side b→a→d)
    /// to c–d when free, convex and better; returns the other triangle.
    fn flip(&mut self, t: u32, e: usize, tol: &NeedleTolerances) -> Option<u32> {
        self.flip_within(t, e, tol.plane, tol)
    }

    /// [`Self::flip`] across an edge whose two triangles lie within `plane`
    /// of one plane. Beyond the plane tolerance (a crease of a curved
    /// surface) the flip moves the surface by at most that much, and each
    /// new triangle must face within [`CREASE_MIN_COS`] of both old ones.
    fn flip_within(&mut self, t: u32, e: usize, plane: f64, tol: &NeedleTolerances) -> Option<u32> {
        let (u, j) = self.across_free(t, e, plane)?;
        let p = self.work.tri_points(t as usize);
        let (a, b, c) = (p[e], p[(e + 1) % 3], p[(e + 2) % 3]);
        let d = self.work.tri_points(u as usize)[j];
        if c == d || !self.users(c, d).is_empty() {
            return None;
        }
        let (pa, pb, pc, pd) = (self.pos(a), self.pos(b), self.pos(c), self.pos(d));
        let n = cross([pa, pb, pc]);
        let sound = |x: [DVec3; 3]| cross(x).dot(n) > 0.0 && height(x) >= tol.height;
        if !sound([pa, pd, pc]) || !sound([pd, pb, pc]) {
            return None;
        }
        if plane > tol.plane {
            let old = [cross([pa, pb, pc]).normalize(), cross([pb, pa, pd]).normalize()];
            let facing = |x: [DVec3; 3]| old.iter().all(|o| cross(x).normalize().dot(*o) > CREASE_MIN_COS);
            if !facing([pa, pd, pc]) || !facing([pd, pb, pc]) {
                return None;
            }
        }
        let before = min_angle([pa, pb, pc]).min(min_angle([pb, pa, pd]));
        let after = min_angle([pa, pd, pc]).min(min_angle([pd, pb, pc]));
        if after <= before + FLIP_MARGIN {
            return None;
        }
        let v = self.work.tris[t as usize];
        let (va, vb, vc) = (v[e], v[(e + 1) % 3], v[(e + 2) % 3]);
        let vd = self.work.tris[u as usize][j];
        self.set(t, [va, vd, vc]);
        self.set(u, [vd, vb, vc]);
        Some(u)
    }

    /// Moves point `from` onto point `to` (side `from`–`to` collapses), if
    /// the link condition holds, nothing turns over and the worst angle
    /// around rises; tries the other way round too.
    fn collapse(&mut self, x: u32, y: u32, tol: &NeedleTolerances) -> Option<Vec<u32>> {
        let plans = [self.plan_collapse(x, y, tol), self.plan_collapse(y, x, tol)];
        let (from, to, _) = plans.into_iter().flatten().max_by(|p, q| p.2.total_cmp(&q.2).then(q.0.cmp(&p.0)))?;
        let ring = self.around[from as usize].clone();
        // A vertex at `from` takes the vertex at `to` of a triangle that goes
        // (the attributes agree there but for the move), so the edges the
        // collapse joins keep one vertex per end; otherwise it moves.
        let mut same: HashMap<u32, u32> = HashMap::new();
        for &t in &ring {
            let (v, p) = (self.work.tris[t as usize], self.work.tri_points(t as usize));
            if let (Some(i), Some(j)) = ((0..3).find(|&k| p[k] == from), (0..3).find(|&k| p[k] == to)) {
                same.entry(v[i]).or_insert(v[j]);
            }
        }
        // Unlinked first: moving a vertex changes the points of every triangle using it.
        let points: Vec<[u32; 3]> = ring.iter().map(|&t| self.work.tri_points(t as usize)).collect();
        for &t in &ring {
            self.unlink(t);
        }
        let mut touched = Vec::new();
        for (t, p) in ring.into_iter().zip(points) {
            let mut v = self.work.tris[t as usize];
            if p.contains(&to) {
                self.work.tri_alive[t as usize] = false;
                continue;
            }
            for k in 0..3 {
                if p[k] == from {
                    match same.get(&v[k]) {
                        Some(&w) => v[k] = w,
                        None => self.work.vertex_point[v[k] as usize] = to,
                    }
                }
            }
            self.work.tris[t as usize] = v;
            self.made[t as usize] = true;
            self.link(t);
            touched.push(t);
        }
        Some(touched)
    }

    /// `(from, to, worst angle after)` when `from` may move onto `to`.
    fn plan_collapse(&self, from: u32, to: u32, tol: &NeedleTolerances) -> Option<(u32, u32, f64)> {
        let shared = self.users(from, to);
        if shared.is_empty() || shared.len() > 2 {
            return None;
        }
        // Every edge at `from` manifold; a point on the border moves only along it.
        let ring = &self.around[from as usize];
        let mut neighbours_from: Vec<u32> = Vec::new();
        let mut on_border = false;
        for &t in ring {
            for q in self.work.tri_points(t as usize) {
                if q != from {
                    let n = self.users(from, q).len();
                    if n > 2 {
                        return None;
                    }
                    on_border |= n == 1;
                    neighbours_from.push(q);
                }
            }
        }
        if on_border && shared.len() != 1 {
            return None;
        }
        // Link condition: the common neighbours are exactly the corners opposite the side.
        neighbours_from.sort_unstable();
        neighbours_from.dedup();
        let mut neighbours_to: Vec<u32> =
            self.around[to as usize].iter().flat_map(|&t| self.work.tri_points(t as usize)).filter(|&q| q != to).collect();
        neighbours_to.sort_unstable();
        neighbours_to.dedup();
        let common = neighbours_from.iter().filter(|q| neighbours_to.binary_search(q).is_ok()).count();
        let mut opposite: Vec<u32> =
            shared.iter().flat_map(|&t| self.work.tri_points(t as usize)).filter(|&q| q != from && q != to).collect();
        opposite.sort_unstable();
        opposite.dedup();
        if common != opposite.len() || opposite.len() != shared.len() {
            return None;
        }
        let target = self.pos(to);
        let mut before = f64::INFINITY;
        let mut after = f64::INFINITY;
        for &t in ring {
            let c = self.corners(t);
            if shared.contains(&t) {
                continue;
            }
            before = before.min(min_angle(c));
            let p = self.work.tri_points(t as usize);
            let moved = [0, 1, 2].map(|k| if p[k] == from { target } else { c[k] });
            let (n0, n1) = (cross(c), cross(moved));
            if n1.length_squared() == 0.0 || n0.dot(n1) <= COLLAPSE_MIN_COS * n0.length() * n1.length() || height(moved) < tol.height {
                return None;
            }
            after = after.min(min_angle(moved));
        }
        // The triangles that stay get no worse than the target, or than they were.
        (after >= before.min(tol.min_angle)).then_some((from, to, after))
    }
}

#[cfg(test)]
mod tests {
    use super::super::work::work_of;
    use super::*;

    fn tolerances() -> NeedleTolerances {
        NeedleTolerances { min_angle: 1f64.to_radians(), collapse: 2e-3, plane: 1e-5, height: 1e-6, spacing: 1e-4 }
    }

    fn worst(work: &Work) -> f64 {
        (0..work.tris.len())
            .filter(|&t| work.tri_alive[t])
            .map(|t| min_angle(work.tri_positions(t).map(|p| p.as_dvec3())))
            .fold(f64::INFINITY, f64::min)
    }

    fn edge_counts(work: &Work) -> (usize, usize) {
        super::super::work::count_boundary_and_non_manifold(work)
    }

    #[test]
    fn a_thin_strip_takes_points_on_its_long_sides_and_keeps_its_area() {
        // A 10 m × 5 cm strip (two triangles of 0.29°) between two squares of
        // another material: its long sides are constrained, so points go on
        // them and into the squares' triangles too.
        let pts = [
            [0.0, 0.0, 0.0],
            [10.0, 0.0, 0.0],
            [10.0, 0.05, 0.0],
            [0.0, 0.05, 0.0],
            [0.0, -10.0, 0.0],
            [10.0, -10.0, 0.0],
            [10.0, 10.05, 0.0],
            [0.0, 10.05, 0.0],
        ];
        let tris = [[0, 1, 2], [0, 2, 3], [4, 5, 1], [4, 1, 0], [3, 2, 6], [3, 6, 7]];
        let mut work = work_of(&pts, &tris);
        work.tri_material = vec![0, 0, 1, 1, 1, 1];
        let area = work.total_area();
        let (border, non_manifold) = edge_counts(&work);
        let made = [true, true, false, false, false, false];
        let out = repair_needles(&mut work, &made, &tolerances());
        assert_eq!(out.needles_before, 2);
        assert_eq!(out.needles_after, 0, "{out:?}");
        assert!(worst(&work) >= 1f64.to_radians(), "smallest angle {}°", worst(&work).to_degrees());
        assert!((work.total_area() - area).abs() < 1e-9 * area);
        // The outline gains points but no crack: border edges only where the
        // outline was split, none inside, and no non-manifold edge.
        let (border_after, non_manifold_after) = edge_counts(&work);
        assert_eq!(non_manifold_after, non_manifold);
        assert!(border_after >= border);
        assert!(out.edges_split > 0 && out.sides_collapsed == 0);
    }

    #[test]
    fn a_needle_with_a_side_under_the_zip_tolerance_collapses_it() {
        // A fan on a square whose two points 0.5 mm apart make needles.
        let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.5, 0.0], [0.5005, 0.5, 0.0]];
        let tris = [[0, 1, 5], [1, 2, 5], [2, 4, 5], [2, 3, 4], [3, 0, 4], [0, 5, 4]];
        let mut work = work_of(&pts, &tris);
        assert!(worst(&work) < 1f64.to_radians());
        let area = work.total_area();
        let out = repair_needles(&mut work, &[true; 6], &tolerances());
        assert_eq!(out.sides_collapsed, 1, "{out:?}");
        assert_eq!(out.needles_after, 0);
        assert_eq!(work.tri_alive.iter().filter(|&&a| a).count(), 4);
        assert!((work.total_area() - area).abs() < 1e-9);
        assert_eq!(edge_counts(&work), (4, 0));
    }

    #[test]
    fn a_cap_whose_long_side_is_free_flips_it_without_a_new_point() {
        // A cap (0.57°, its corner 5 mm off its 1 m side: too far to snap)
        // and a wide triangle across that side, in one plane.
        let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 0.005, 0.0], [0.5, -1.0, 0.0]];
        let mut work = work_of(&pts, &[[0, 1, 2], [1, 0, 3]]);
        let area = work.total_area();
        let out = repair_needles(&mut work, &[true, false], &tolerances());
        assert_eq!((out.needles_after, out.edges_flipped, out.points_inserted, out.edges_split), (0, 1, 0, 0), "{out:?}");
        assert!(worst(&work) > 20f64.to_radians() && (work.total_area() - area).abs() < 1e-9);
        assert_eq!(edge_counts(&work), (4, 0));
    }

    #[test]
    fn a_needle_on_a_crease_flips_across_it_when_the_surface_moves_less_than_the_collapse_distance() {
        // A cap (0.57°) whose long side is a crease: the triangle across it
        // bends 1.5 mm out of its plane, within the collapse distance (2 mm).
        let pts = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 0.01, 0.0], [1.0, -1.0, 0.0015]];
        let mut work = work_of(&pts, &[[0, 1, 2], [1, 0, 3]]);
        let out = repair_needles(&mut work, &[true, false], &tolerances());
        assert_eq!((out.needles_before, out.needles_after, out.edges_flipped), (1, 0, 1), "{out:?}");
        assert!(worst(&work) > 40f64.to_radians());
        assert_eq!(edge_counts(&work), (4, 0));
        // Bent 3 mm, the flip would move the surface more than that: left.
        let pts = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 0.01, 0.0], [1.0, -1.0, 0.003]];
        let mut work = work_of(&pts, &[[0, 1, 2], [1, 0, 3]]);
        let out = repair_needles(&mut work, &[true, false], &tolerances());
        assert_eq!((out.needles_after, out.edges_flipped), (1, 0), "{out:?}");
    }
}
