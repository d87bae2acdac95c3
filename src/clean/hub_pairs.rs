//! Broad phase of the coplanar step that stays near-linear at high-valence points.
//!
//! Why: every triangle of a fan contains its apex, so the boxes of all `d`
//! triangles around a point of valence `d` overlap each other and a box tree
//! hands the narrow phase `d²/2` pairs (a 10k fan: 50 M pairs, seconds per round).
//!
//! How: a point used by at least [`HUB_VALENCE`] triangles is a *hub*. Each
//! triangle joins the group of its most used hub corner (when it has one and
//! faces the hub's axis, see below); every other triangle goes to the box tree
//! as before. Around a hub the triangles are seen from above, projected along
//! the hub's axis `m` (the sum of its triangles' area vectors), where each
//! covers an angular *sector* narrower than π. A triangle lies inside its
//! sector's cone, so two coplanar triangles sharing the hub overlap only where
//! their sectors do: sorting the sectors and sweeping finds those pairs in
//! `O(d log d + k)`. Any other triangle near the group is looked up by its own
//! angular span around the hub (one sector for a triangle with a corner there,
//! the whole circle when it covers the hub). The projection along `m` is an
//! affine bijection on a plane that is not parallel to `m`; triangles steeper
//! than [`MIN_AXIS_COSINE`] stay in the box tree. Sectors are widened by the
//! angle that a tilt within the plane tolerance subtends (zero on a flat fan),
//! so near-coplanar pairs are not missed.
//!
//! The result is a superset of the overlapping pairs, filtered by the same
//! padded box test as before and sorted, so the narrow phase sees the pairs it
//! saw with the box tree alone, in the same order.

use super::spatial::{Aabb, AabbTree};
use glam::DVec3;
use std::f64::consts::{PI, TAU};

/// A point used by at least this many triangles is a hub (ordinary meshes stay below ~16).
pub(crate) const HUB_VALENCE: usize = 32;
/// A triangle joins its hub's group only when `|n · m| >=` this (n, m unit):
/// steeper planes project too thin along the hub's axis.
const MIN_AXIS_COSINE: f64 = 0.5;

/// Candidate pairs `(a, b)`, `a < b`, sorted, whose padded boxes overlap, and a
/// count of the candidate pairs enumerated to find them (the work done).
pub(crate) struct Candidates {
    pub pairs: Vec<(u32, u32)>,
    pub enumerated: usize,
}

/// Finds every pair of triangles whose padded boxes overlap and that may overlap
/// in a plane (see the module doc). `points[t]` are triangle `t`'s point ids,
/// `corners[t]` its positions; `boxes[t]` is [`Aabb::EMPTY`] for triangles to skip.
pub(crate) fn candidate_pairs(points: &[[u32; 3]], corners: &[[DVec3; 3]], boxes: &[Aabb], plane_tol: f64) -> Candidates {
    let n = boxes.len();
    let live = |t: usize| boxes[t] != Aabb::EMPTY;
    let hubs = find_hubs(points, n, &live);
    let pad = plane_tol;
    let mut groups = build_groups(points, corners, &hubs, &live, pad);
    // Pairs between two triangles outside every group come out sorted; the rest
    // (a group member in the pair) are sorted and merged in at the end.
    let mut tree_pairs: Vec<(u32, u32)> = Vec::new();
    let mut found: Vec<(u32, u32)> = Vec::new();
    let mut enumerated = 0;

    // Triangles outside every group: the box tree, as before.
    let rest: Vec<u32> = (0..n as u32).filter(|&t| live(t as usize) && groups.group_of[t as usize] == NO_GROUP).collect();
    let tree = AabbTree::build(rest.iter().map(|&t| boxes[t as usize]).collect());
    let mut hits = Vec::new();
    for t in (0..n).filter(|&t| live(t)) {
        hits.clear();
        tree.query(&boxes[t], &mut hits);
        enumerated += hits.len();
        let others = hits.iter().map(|&i| rest[i as usize]);
        if groups.group_of[t] == NO_GROUP {
            let start = tree_pairs.len();
            tree_pairs.extend(others.filter(|&o| o as usize > t).map(|o| (t as u32, o)));
            tree_pairs[start..].sort_unstable();
        } else {
            found.extend(others.map(|o| ordered(t as u32, o)));
        }
    }

    // Within each group: overlapping sectors.
    for g in &mut groups.list {
        g.sort_pieces();
        enumerated += g.sweep(&mut found);
    }
    // Any triangle near a group (its own members aside): its angular span around the hub.
    let group_tree = AabbTree::build(groups.list.iter().map(|g| g.bounds).collect());
    let mut near = Vec::new();
    for t in (0..n).filter(|&t| live(t)) {
        near.clear();
        group_tree.query(&boxes[t], &mut near);
        for &gi in &near {
            if groups.group_of[t] == gi {
                continue;
            }
            let g = &groups.list[gi as usize];
            let Some(span) = g.span_of(corners[t], pad) else { continue };
            enumerated += g.lookup(span, t as u32, &mut found);
        }
    }

    found.retain(|&(a, b)| boxes[a as usize].overlaps(&boxes[b as usize]));
    found.sort_unstable();
    found.dedup();
    let pairs = merge_sorted(tree_pairs, found);
    Candidates { pairs, enumerated }
}

/// The union of two sorted lists without repeats.
fn merge_sorted(a: Vec<(u32, u32)>, b: Vec<(u32, u32)>) -> Vec<(u32, u32)> {
    if b.is_empty() {
        return a;
    }
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() || j < b.len() {
        let next = match (a.get(i), b.get(j)) {
            (Some(&x), Some(&y)) if x <= y => {
                i += 1;
                j += (x == y) as usize;
                x
            }
            (_, Some(&y)) => {
                j += 1;
                y
            }
            (Some(&x), None) => {
                i += 1;
                x
            }
            (None, None) => break,
        };
        out.push(next);
    }
    out
}

fn ordered(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

const NO_GROUP: u32 = u32::MAX;

/// Valence (live triangle uses) of every point that reaches [`HUB_VALENCE`], else 0.
fn find_hubs(points: &[[u32; 3]], n: usize, live: &impl Fn(usize) -> bool) -> Vec<u32> {
    let count = points.iter().flatten().map(|&p| p as usize + 1).max().unwrap_or(0);
    let mut valence = vec![0u32; count];
    for t in (0..n).filter(|&t| live(t)) {
        for &p in &points[t] {
            valence[p as usize] += 1;
        }
    }
    valence.iter_mut().filter(|v| (**v as usize) < HUB_VALENCE).for_each(|v| *v = 0);
    valence
}

struct Groups {
    list: Vec<HubGroup>,
    /// Group index of each triangle, or [`NO_GROUP`].
    group_of: Vec<u32>,
}

/// The triangles around one hub, as angular sectors seen along the hub's axis.
struct HubGroup {
    hub: DVec3,
    /// Orthonormal frame: `u`, `v` span the projection plane.
    u: DVec3,
    v: DVec3,
    bounds: Aabb,
    /// Sectors as pieces `[start, end]` within `[0, 2π]` (a sector across 0 is two pieces), with their triangle.
    pieces: Vec<(f64, f64, u32)>,
    /// The widest piece: a lookup scans starts from `lo - widest`.
    widest: f64,
}

fn build_groups(points: &[[u32; 3]], corners: &[[DVec3; 3]], valence: &[u32], live: &impl Fn(usize) -> bool, pad: f64) -> Groups {
    let n = points.len();
    // Each triangle's most used hub corner (ties: the lowest point id).
    let hub_of: Vec<Option<(usize, u32)>> = (0..n)
        .map(|t| {
            if !live(t) {
                return None;
            }
            (0..3)
                .filter(|&c| valence[points[t][c] as usize] > 0)
                .max_by_key(|&c| (valence[points[t][c] as usize], u32::MAX - points[t][c]))
                .map(|c| (c, points[t][c]))
        })
        .collect();
    // Axis of each hub: the sum of its triangles' area vectors, in triangle order.
    let mut axis_of: std::collections::BTreeMap<u32, DVec3> = std::collections::BTreeMap::new();
    for t in 0..n {
        if let Some((_, hub)) = hub_of[t] {
            let [a, b, c] = corners[t];
            *axis_of.entry(hub).or_insert(DVec3::ZERO) += (b - a).cross(c - a);
        }
    }
    let mut index_of = std::collections::BTreeMap::new();
    let mut list: Vec<HubGroup> = Vec::new();
    let mut group_of = vec![NO_GROUP; n];
    for t in 0..n {
        let Some((corner, hub)) = hub_of[t] else { continue };
        let [a, b, c] = corners[t];
        let normal = (b - a).cross(c - a).normalize_or_zero();
        let Some(m) = axis_of[&hub].try_normalize() else { continue };
        if normal.dot(m).abs() < MIN_AXIS_COSINE {
            continue;
        }
        let gi = *index_of.entry(hub).or_insert_with(|| {
            let u = m.any_orthonormal_vector();
            list.push(HubGroup { hub: corners[t][corner], u, v: m.cross(u), bounds: Aabb::EMPTY, pieces: Vec::new(), widest: 0.0 });
            list.len() - 1
        });
        group_of[t] = gi as u32;
    }
    Groups { list, group_of }.with_members(corners, pad)
}

impl Groups {
    /// Fills each group's bounds and sectors from its members.
    fn with_members(mut self, corners: &[[DVec3; 3]], pad: f64) -> Groups {
        for (t, &gi) in self.group_of.iter().enumerate() {
            if gi == NO_GROUP {
                continue;
            }
            let g = &mut self.list[gi as usize];
            g.bounds = g.bounds.union(Aabb::of_points(&corners[t].map(|p| p.as_vec3()), 0.0));
            if let Some(span) = g.span_of(corners[t], pad) {
                g.push_span(span, t as u32);
            }
        }
        self
    }
}

/// An angular interval `[start, start + width]` around a hub, or the whole circle.
#[derive(Clone, Copy, Debug)]
enum Span {
    Arc { start: f64, width: f64 },
    Full,
}

impl HubGroup {
    /// The angular span of a triangle's projection around the hub, widened by
    /// the angle that the shift of a point `plane_tol` off its plane subtends at
    /// its nearest corner (the shift between projecting along its normal, as the
    /// narrow phase does, and along the hub's axis: twice `plane_tol · tan` of
    /// their angle). `None` when it projects to a single point at the hub.
    fn span_of(&self, corners: [DVec3; 3], plane_tol: f64) -> Option<Span> {
        let flat = corners.map(|p| {
            let d = p - self.hub;
            (d.dot(self.u), d.dot(self.v))
        });
        // The hub inside the projected triangle (not at a corner): the whole circle.
        let side = |i: usize| {
            let ((x0, y0), (x1, y1)) = (flat[i], flat[(i + 1) % 3]);
            x0 * y1 - x1 * y0
        };
        let s = [side(0), side(1), side(2)];
        let at_corner = flat.iter().any(|&(x, y)| x == 0.0 && y == 0.0);
        if !at_corner && (s.iter().all(|&x| x >= 0.0) || s.iter().all(|&x| x <= 0.0)) {
            return Some(Span::Full);
        }
        let mut angles: Vec<f64> = Vec::with_capacity(3);
        let mut nearest = f64::INFINITY;
        for &(x, y) in &flat {
            let r = x.hypot(y);
            if r > 0.0 {
                angles.push(y.atan2(x).rem_euclid(TAU));
                nearest = nearest.min(r);
            }
        }
        if angles.is_empty() {
            return None;
        }
        angles.sort_by(f64::total_cmp);
        // The span is the circle minus the largest gap between consecutive angles.
        let k = angles.len();
        let (mut gap, mut after) = (TAU - (angles[k - 1] - angles[0]), 0);
        for i in 1..k {
            if angles[i] - angles[i - 1] > gap {
                (gap, after) = (angles[i] - angles[i - 1], i);
            }
        }
        let [a, b, c] = corners;
        let cos = (b - a).cross(c - a).normalize_or_zero().dot(self.u.cross(self.v)).abs().max(1e-3);
        let shift = 2.0 * plane_tol * (1.0 - cos * cos).sqrt() / cos;
        let widen = (shift / nearest).min(PI);
        let width = TAU - gap + 2.0 * widen;
        if width >= PI {
            return Some(Span::Full);
        }
        Some(Span::Arc { start: (angles[after] - widen).rem_euclid(TAU), width })
    }

    /// Adds a member's span as pieces within `[0, 2π]`.
    fn push_span(&mut self, span: Span, t: u32) {
        for (lo, hi) in pieces(span) {
            self.widest = self.widest.max(hi - lo);
            self.pieces.push((lo, hi, t));
        }
    }

    fn sort_pieces(&mut self) {
        self.pieces.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.2.cmp(&y.2)));
    }

    /// Pairs of members whose pieces overlap (touching counts: shared edges are
    /// left to the narrow phase). Returns the number of pairs enumerated.
    fn sweep(&self, out: &mut Vec<(u32, u32)>) -> usize {
        // Touching pieces count too (shared edges are the narrow phase's to judge).
        const SLACK: f64 = 1e-9;
        let mut active: Vec<(f64, u32)> = Vec::new();
        let mut enumerated = 0;
        for &(lo, hi, t) in &self.pieces {
            active.retain(|&(end, _)| end + SLACK >= lo);
            enumerated += active.len();
            out.extend(active.iter().filter(|&&(_, o)| o != t).map(|&(_, o)| ordered(t, o)));
            active.push((hi, t));
        }
        enumerated
    }

    /// Members whose pieces overlap `span`, paired with `t`. Returns the number enumerated.
    fn lookup(&self, span: Span, t: u32, out: &mut Vec<(u32, u32)>) -> usize {
        let mut enumerated = 0;
        for (lo, hi) in pieces(span) {
            let first = self.pieces.partition_point(|p| p.0 < lo - self.widest);
            for &(plo, phi, o) in self.pieces[first..].iter().take_while(|p| p.0 <= hi) {
                enumerated += 1;
                if phi >= lo && plo <= hi && o != t {
                    out.push(ordered(t, o));
                }
            }
        }
        enumerated
    }
}

/// A span as at most two intervals within `[0, 2π]`.
fn pieces(span: Span) -> Vec<(f64, f64)> {
    match span {
        Span::Full => vec![(0.0, TAU)],
        Span::Arc { start, width } if start + width > TAU => vec![(start, TAU), (0.0, start + width - TAU)],
        Span::Arc { start, width } => vec![(start, start + width)],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fan of `n` triangles around the origin in the xz plane, plus the same
    /// fan rotated by half a sector (every triangle overlaps two of the first).
    fn fan(n: usize, turn: f64) -> Vec<[DVec3; 3]> {
        let rim = |i: usize| {
            let a = TAU * (i as f64 + turn) / n as f64;
            DVec3::new(a.cos(), 0.0, -a.sin())
        };
        (0..n).map(|i| [DVec3::ZERO, rim(i), rim(i + 1)]).collect()
    }

    fn brute_force(corners: &[[DVec3; 3]], boxes: &[Aabb], overlap: impl Fn(usize, usize) -> bool) -> Vec<(u32, u32)> {
        let n = corners.len();
        (0..n)
            .flat_map(|a| (a + 1..n).map(move |b| (a, b)))
            .filter(|&(a, b)| boxes[a].overlaps(&boxes[b]) && overlap(a, b))
            .map(|(a, b)| (a as u32, b as u32))
            .collect()
    }

    #[test]
    fn sectors_find_every_overlap_of_two_interleaved_fans_with_linear_work() {
        let n = 200;
        let mut corners = fan(n, 0.0);
        corners.extend(fan(n, 0.5));
        // Points: the apex is point 0 in both fans; rims are distinct.
        let points: Vec<[u32; 3]> = (0..2 * n)
            .map(|t| {
                let (f, i) = (t / n, t % n);
                let rim = |j: usize| (1 + f * n + j % n) as u32;
                [0, rim(i), rim(i + 1)]
            })
            .collect();
        let boxes: Vec<Aabb> = corners.iter().map(|c| Aabb::of_points(&c.map(|p| p.as_vec3()), 1e-6)).collect();
        let got = candidate_pairs(&points, &corners, &boxes, 1e-6);
        // Interiors overlap exactly for: same-fan neighbours never (they touch),
        // cross-fan i and i or i-1 (half a sector each).
        let mut want: Vec<(u32, u32)> =
            (0..n).flat_map(|i| [(i as u32, (n + i) as u32), (i as u32, (n + (i + n - 1) % n) as u32)]).collect();
        want.sort_unstable();
        for w in &want {
            assert!(got.pairs.binary_search(w).is_ok(), "missing {w:?}");
        }
        // Only neighbours are candidates: touching same-fan pairs and the overlaps.
        let neighbours = brute_force(&corners, &boxes, |a, b| {
            let sector = |t: usize| (t % n) as f64 + if t >= n { 0.5 } else { 0.0 };
            let d = (sector(a) - sector(b)).rem_euclid(n as f64);
            d.min(n as f64 - d) <= 1.0 + 1e-9
        });
        assert!(got.pairs.iter().all(|p| neighbours.binary_search(p).is_ok()), "a candidate that is not a neighbour");
        assert!(got.enumerated <= 20 * n, "enumerated {} pairs for {} triangles", got.enumerated, 2 * n);
    }
}
