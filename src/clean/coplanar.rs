//! Overlapping coplanar triangles that are not vertex-identical: a patch
//! tessellated twice at different densities, or two CAD patches overlapping.
//!
//! Broad phase: an AABB tree over the triangles, boxes padded by the plane
//! tolerance, except around high-valence points, where angular sectors replace
//! the boxes that a fan's triangles all share ([`super::hub_pairs`]). Narrow
//! phase: a pair is *coplanar* when each triangle's corners lie within the plane
//! tolerance of the other's plane; its overlap is the area of the
//! intersection polygon (the other triangle clipped against this one in this one's
//! plane, Sutherland–Hodgman, in f64). Pairs overlapping by less than
//! [`OVERLAP_EPS`] of the smaller area are neighbours that merely touch.
//!
//! Covered rule: triangles are visited from the highest index down (lowest index
//! wins, as for duplicates); a triangle is removed when the still-present coplanar
//! triangles overlapping it (a) sum to at least its area (within [`COVER_EPS`])
//! and (b) contain each of seven sample points: its corners, edge midpoints and
//! centroid. Limits: (a) overcounts when the covering triangles overlap each other
//! (layered copies), and (b) then only samples, so a hole in such a layered cover
//! that misses all seven points goes unseen. For covers that are themselves a clean
//! tessellation, (a) alone is exact.
//!
//! Overlapping pairs left after removal are reported as partial overlaps.

use super::hub_pairs;
use super::spatial::Aabb;
use super::work::Work;
use super::OverlapReport;
use glam::{DVec2, DVec3};

/// Pairs overlapping by less than this fraction of the smaller triangle only touch.
pub(crate) const OVERLAP_EPS: f64 = 1e-4;
/// A triangle counts as covered when covers sum to at least `1 - COVER_EPS` of its area.
pub(crate) const COVER_EPS: f64 = 1e-5;
/// Barycentric slack for "sample point inside a covering triangle".
const INSIDE_EPS: f64 = 1e-5;
/// At most this many partial overlaps are listed (all are counted).
pub(crate) const MAX_LISTED_OVERLAPS: usize = 64;

/// What [`remove_covered_coplanar`] did.
#[derive(Clone, Debug, Default)]
pub(crate) struct CoplanarOutcome {
    pub removed: usize,
    pub removed_area: f64,
    /// Largest partial overlaps first, at most [`MAX_LISTED_OVERLAPS`].
    pub partial: Vec<OverlapReport>,
    pub partial_count: usize,
    /// Candidate pairs the broad phase enumerated: the step's work.
    pub pairs_enumerated: usize,
}

/// A triangle's plane frame: origin, in-plane axes `u`, `v` and unit normal `n`.
#[derive(Clone, Copy, Debug)]
struct Frame {
    o: DVec3,
    u: DVec3,
    v: DVec3,
    n: DVec3,
    area: f64,
}

impl Frame {
    fn of(p: [DVec3; 3]) -> Option<Frame> {
        let cross = (p[1] - p[0]).cross(p[2] - p[0]);
        let n = cross.try_normalize()?;
        let u = (p[1] - p[0]).try_normalize()?;
        Some(Frame { o: p[0], u, v: n.cross(u), n, area: 0.5 * cross.length() })
    }
    fn project(&self, p: DVec3) -> DVec2 {
        let d = p - self.o;
        DVec2::new(d.dot(self.u), d.dot(self.v))
    }
    fn unproject(&self, q: DVec2) -> DVec3 {
        self.o + self.u * q.x + self.v * q.y
    }
}

/// Finds overlapping coplanar pairs, removes covered triangles when `remove` is set,
/// and reports the overlaps that remain. With `keep_two_sided`, opposite-facing
/// triangles never cover or overlap each other (they are the two sides of a sheet).
///
/// `max_sine`: pairs whose planes meet at an angle with a larger sine are
/// not coplanar however small they are (with the cut on, they are crossings:
/// two small triangles on either side of a cut line lie within the plane
/// tolerance of each other's plane); `None` for no limit.
pub(crate) fn remove_covered_coplanar(
    work: &mut Work,
    plane_tol: f32,
    keep_two_sided: bool,
    remove: bool,
    max_sine: Option<f64>,
) -> CoplanarOutcome {
    let n = work.tris.len();
    let corners: Vec<[DVec3; 3]> = (0..n).map(|t| work.tri_positions(t).map(|p| p.as_dvec3())).collect();
    let frames: Vec<Option<Frame>> = (0..n).map(|t| if work.tri_alive[t] { Frame::of(corners[t]) } else { None }).collect();
    let (pairs, enumerated) = find_overlapping_pairs(work, &corners, &frames, plane_tol as f64, keep_two_sided, max_sine);

    // Adjacency in CSR form: for each triangle, its overlapping partners and areas.
    let mut start = vec![0usize; n + 1];
    for p in &pairs {
        start[p.a as usize + 1] += 1;
        start[p.b as usize + 1] += 1;
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut partner = vec![(0u32, 0f64); start[n]];
    for p in &pairs {
        partner[fill[p.a as usize]] = (p.b, p.area);
        fill[p.a as usize] += 1;
        partner[fill[p.b as usize]] = (p.a, p.area);
        fill[p.b as usize] += 1;
    }

    let mut out = CoplanarOutcome { pairs_enumerated: enumerated, ..CoplanarOutcome::default() };
    if remove {
        // Highest index first: the lowest index of a mutually covering set survives.
        for t in (0..n).rev() {
            let Some(frame) = frames[t] else { continue };
            let partners = &partner[start[t]..start[t + 1]];
            if partners.is_empty() || !work.tri_alive[t] {
                continue;
            }
            let alive: Vec<(u32, f64)> = partners.iter().copied().filter(|&(c, _)| work.tri_alive[c as usize]).collect();
            let covered_area: f64 = alive.iter().map(|&(_, a)| a).sum();
            if covered_area < (1.0 - COVER_EPS) * frame.area {
                continue;
            }
            if samples_covered(&frame, corners[t], &alive, &corners) {
                work.tri_alive[t] = false;
                out.removed += 1;
                out.removed_area += frame.area;
            }
        }
    }

    let mut partial: Vec<OverlapReport> = pairs
        .iter()
        .filter(|p| work.tri_alive[p.a as usize] && work.tri_alive[p.b as usize])
        .map(|p| OverlapReport {
            tri_a: work.tri_origin[p.a as usize],
            tri_b: work.tri_origin[p.b as usize],
            location: p.location.as_vec3().to_array(),
            area: p.area as f32,
        })
        .collect();
    partial.sort_by(|x, y| y.area.total_cmp(&x.area).then((x.tri_a, x.tri_b).cmp(&(y.tri_a, y.tri_b))));
    out.partial_count = partial.len();
    partial.truncate(MAX_LISTED_OVERLAPS);
    out.partial = partial;
    out
}

struct Pair {
    a: u32,
    b: u32,
    area: f64,
    location: DVec3,
}

/// The overlapping coplanar pairs, and the number of candidate pairs the broad phase enumerated.
fn find_overlapping_pairs(
    work: &Work,
    corners: &[[DVec3; 3]],
    frames: &[Option<Frame>],
    plane_tol: f64,
    keep_two_sided: bool,
    max_sine: Option<f64>,
) -> (Vec<Pair>, usize) {
    let pad = plane_tol as f32;
    let boxes: Vec<Aabb> = (0..work.tris.len())
        .map(|t| if frames[t].is_some() { Aabb::of_points(&work.tri_positions(t), pad) } else { Aabb::EMPTY })
        .collect();
    let points: Vec<[u32; 3]> = (0..work.tris.len()).map(|t| work.tri_points(t)).collect();
    let candidates = hub_pairs::candidate_pairs(&points, corners, &boxes, plane_tol);
    let mut pairs = Vec::new();
    for &(a, b) in &candidates.pairs {
        let (a, b) = (a as usize, b as usize);
        let (Some(fa), Some(fb)) = (frames[a], frames[b]) else { continue };
        if keep_two_sided && fa.n.dot(fb.n) < 0.0 {
            continue;
        }
        if max_sine.is_some_and(|m| fa.n.cross(fb.n).length() > m) {
            continue;
        }
        let on_plane = |f: &Frame, ps: &[DVec3; 3]| ps.iter().all(|&p| (p - f.o).dot(f.n).abs() <= plane_tol);
        if !on_plane(&fa, &corners[b]) || !on_plane(&fb, &corners[a]) {
            continue;
        }
        let poly = clip_to_triangle(&fa, corners[a], corners[b]);
        let (area, centroid) = polygon_area_centroid(&poly);
        if area > OVERLAP_EPS * fa.area.min(fb.area) {
            pairs.push(Pair { a: a as u32, b: b as u32, area, location: fa.unproject(centroid) });
        }
    }
    (pairs, candidates.enumerated)
}

/// The part of triangle `other` inside triangle `this`, in `this`'s plane frame.
fn clip_to_triangle(frame: &Frame, this: [DVec3; 3], other: [DVec3; 3]) -> Vec<DVec2> {
    let t = this.map(|p| frame.project(p));
    let mut poly: Vec<DVec2> = other.iter().map(|&p| frame.project(p)).collect();
    // `this` is counter-clockwise in its own frame: keep the left of each edge.
    for i in 0..3 {
        let (a, b) = (t[i], t[(i + 1) % 3]);
        let side = |q: DVec2| (b - a).perp_dot(q - a);
        let mut next = Vec::with_capacity(poly.len() + 2);
        for j in 0..poly.len() {
            let (p, q) = (poly[j], poly[(j + 1) % poly.len()]);
            let (sp, sq) = (side(p), side(q));
            if sp >= 0.0 {
                next.push(p);
            }
            if (sp >= 0.0) != (sq >= 0.0) {
                next.push(p + (q - p) * (sp / (sp - sq)));
            }
        }
        poly = next;
        if poly.is_empty() {
            break;
        }
    }
    poly
}

/// Unsigned area and area centroid of a simple polygon.
fn polygon_area_centroid(poly: &[DVec2]) -> (f64, DVec2) {
    if poly.len() < 3 {
        return (0.0, DVec2::ZERO);
    }
    let mut twice = 0.0;
    let mut c = DVec2::ZERO;
    for i in 0..poly.len() {
        let (p, q) = (poly[i], poly[(i + 1) % poly.len()]);
        let w = p.perp_dot(q);
        twice += w;
        c += (p + q) * w;
    }
    if twice.abs() < f64::MIN_POSITIVE {
        return (0.0, poly[0]);
    }
    (0.5 * twice.abs(), c / (3.0 * twice))
}

/// True when each of the seven sample points of `this` lies inside some triangle of `covers`.
fn samples_covered(frame: &Frame, this: [DVec3; 3], covers: &[(u32, f64)], corners: &[[DVec3; 3]]) -> bool {
    let [a, b, c] = this;
    let samples = [a, b, c, (a + b) * 0.5, (b + c) * 0.5, (c + a) * 0.5, (a + b + c) / 3.0];
    let covers2: Vec<[DVec2; 3]> = covers.iter().map(|&(t, _)| corners[t as usize].map(|p| frame.project(p))).collect();
    samples.iter().all(|&s| {
        let q = frame.project(s);
        covers2.iter().any(|tri| inside_triangle(q, tri))
    })
}

fn inside_triangle(q: DVec2, [a, b, c]: &[DVec2; 3]) -> bool {
    let d = (b - *a).perp_dot(*c - *a);
    if d == 0.0 {
        return false;
    }
    let w0 = (*b - q).perp_dot(*c - q) / d;
    let w1 = (*c - q).perp_dot(*a - q) / d;
    let w2 = 1.0 - w0 - w1;
    w0 >= -INSIDE_EPS && w1 >= -INSIDE_EPS && w2 >= -INSIDE_EPS
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clipped_overlap_of_two_half_squares_is_exact() {
        // Triangle (0,0)-(2,0)-(0,2) against (0,0)-(2,0)-(2,2): overlap is the
        // triangle (0,0)-(2,0)-(1,1) of area 1.
        let a = [DVec3::ZERO, DVec3::new(2.0, 0.0, 0.0), DVec3::new(0.0, 2.0, 0.0)];
        let b = [DVec3::ZERO, DVec3::new(2.0, 0.0, 0.0), DVec3::new(2.0, 2.0, 0.0)];
        let f = Frame::of(a).unwrap();
        let (area, c) = polygon_area_centroid(&clip_to_triangle(&f, a, b));
        assert!((area - 1.0).abs() < 1e-12);
        let c3 = f.unproject(c);
        assert!((c3 - DVec3::new(1.0, 1.0 / 3.0, 0.0)).length() < 1e-12);
    }
}
