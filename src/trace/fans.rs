//! Fans: the triangles around a point of very high valence (a cone's apex,
//! a disc's centre, a polygon fanned from one corner), traced through a tree
//! of spherical caps around that point instead of the box tree.
//!
//! Why: every triangle of a fan touches its hub, so their bounding boxes
//! overlap there, and on a fan that does not lie in an axis plane (a cone, a
//! tilted disc) a point of the fan lies inside the boxes of a fixed share of
//! its triangles. Every ray from such a point walks O(valence) leaves, and a
//! bake, whose points sit on the fan, takes time quadratic in the valence (a
//! closed cone at `--rays 4 --threads 1`: 0.34 s at apex valence 2.5k, 17.6 s
//! at 20k, 95% of it in the walk). Splitting the boxes does not help: a
//! sliver's box is as wide as the sliver is long, so boxes as narrow as the
//! triangles take about valence pieces per triangle.
//!
//! Seen from its hub, though, a fan is one-dimensional: a triangle (h, a, b)
//! is the great-circle arc between the directions of a and b. A ray whose
//! line misses the hub lies in one plane through the hub and can meet the
//! triangle only where that plane separates a from b, that is where the
//! plane's great circle crosses the arc. The arcs are bounded by spherical
//! caps in a binary tree (split at the median of the arcs' mid directions
//! along their widest axis), and a walk enters only the caps the ray's great
//! circle crosses: O(log valence) caps and the few leaves where the circle
//! crosses the fan (twice on a cone or a disc), whose triangles are tested by
//! the same leaf blocks, with the same bits, as every other triangle.
//!
//! The caps are widened by what float rounding in the triangle test may
//! accept ([`Fans::slack`]), so a triangle the test could report is never
//! skipped; a line that passes that close to the hub tests every leaf.
//!
//! A fan's triangles leave the box tree; a small box tree over the fans'
//! boxes leads rays to them. A mesh with no point of valence
//! [`FAN_MIN_VALENCE`] (none of the real scenes: the Ferrari's highest is
//! 80, the grey-white room's 65) has no fans and is traced as before, bit
//! for bit.

use glam::{DVec3, Vec3};
use obvhs::aabb::Aabb;

use super::bvh8::{self, Bvh8, LeafResult, Leaves, Node8, NodeTest, RayBoxes};
use crate::mesh::Mesh;

/// Triangles around one point from which they are traced as a fan: where
/// the fans overtake the box tree. A closed cone at 1,024 rays per point, 1
/// thread (rays/s, box tree against fans): valence 256 6.1–6.6 M against
/// 4.7–5.0 M, 512 4.9–5.0 M against 3.8–4.2 M, 1,000 3.6 M against 3.8–4.1 M,
/// 2,500 1.4 M against 3.1 M. Ordinary meshes stay far below it.
pub const FAN_MIN_VALENCE: u32 = 1024;
/// Triangles per fan leaf: one leaf-block test.
const FAN_LEAF: usize = 8;
/// Distance, relative to the scene's size (its diagonal or largest
/// coordinate, whichever is larger), within which the f32 triangle test may
/// report a hit on a triangle whose exact geometry the ray misses, as caps
/// widen for it: 2⁻¹⁷ = 64 ε. The test's rounding is a few ε of the
/// distances it forms (origin to corner, edges) over the cosine of the
/// incidence, so this covers rays up to about 6° from grazing; nearer
/// grazing the test is as unreliable with the box tree. Its cost grows
/// with it (widened caps hold more triangles): 2⁻¹⁴ took a 20k-valence
/// cone's bake from 1.7 to 2.1 s.
const SLACK: f64 = 1.0 / 131072.0;
/// Reference of a leaf cap: `LEAF | first << 4 | count`.
const LEAF: u32 = 1 << 31;
/// Deepest cap tree the walk's stack holds (a median split halves the
/// triangles per level, so 2³² triangles need 30 levels).
const MAX_DEPTH: usize = 60;

/// The triangles each fan takes, from [`find_fans`].
pub struct FanPlan {
    /// Per fan: its hub and its triangles (mesh indices, ascending).
    fans: Vec<(Vec3, Vec<u32>)>,
    /// Per mesh triangle: whether a fan holds it.
    pub in_fan: Vec<bool>,
}

/// Finds the fans of `mesh`: every position (vertices with bitwise equal
/// positions are one point, so split normals do not hide a hub) that at
/// least [`FAN_MIN_VALENCE`] triangle corners share. A triangle touching
/// several goes to the one of highest valence (then the lowest vertex
/// index); a hub left with fewer than half of [`FAN_MIN_VALENCE`] triangles
/// gives them back to the box tree. `None` when there is no fan.
pub fn find_fans(mesh: &Mesh) -> Option<FanPlan> {
    if mesh.indices.len() < FAN_MIN_VALENCE as usize {
        return None;
    }
    let mut corners = vec![0u32; mesh.positions.len()];
    for &i in &mesh.indices {
        corners[i as usize] += 1;
    }
    // A hub's corners all fall in the bucket its position hashes to: only
    // vertices in buckets of FAN_MIN_VALENCE corners or more can be hubs (in
    // an ordinary mesh, none), so only they are sorted.
    let key = |v: u32| {
        let p = mesh.positions[v as usize];
        (p.x.to_bits(), p.y.to_bits(), p.z.to_bits(), v)
    };
    let buckets = mesh.positions.len().next_power_of_two();
    let bucket = |v: u32| {
        let (x, y, z, _) = key(v);
        let h = (u64::from(x) ^ u64::from(y).rotate_left(21) ^ u64::from(z).rotate_left(42)).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        (h >> 32) as usize & (buckets - 1)
    };
    let mut per_bucket = vec![0u32; buckets];
    for v in 0..mesh.positions.len() as u32 {
        per_bucket[bucket(v)] += corners[v as usize];
    }
    let mut order: Vec<u32> =
        (0..mesh.positions.len() as u32).filter(|&v| corners[v as usize] > 0 && per_bucket[bucket(v)] >= FAN_MIN_VALENCE).collect();
    // Points: those vertices grouped by position bits, each group's corners summed.
    order.sort_unstable_by_key(|&v| key(v));
    // (valence, first vertex, group range in `order`)
    let mut hubs: Vec<(u32, u32, std::ops::Range<usize>)> = Vec::new();
    let mut start = 0;
    while start < order.len() {
        let (x, y, z, first) = key(order[start]);
        let end = start + order[start..].iter().take_while(|&&v| (key(v).0, key(v).1, key(v).2) == (x, y, z)).count();
        let valence: u64 = order[start..end].iter().map(|&v| u64::from(corners[v as usize])).sum();
        if valence >= u64::from(FAN_MIN_VALENCE) {
            hubs.push((valence.min(u64::from(u32::MAX)) as u32, first, start..end));
        }
        start = end;
    }
    if hubs.is_empty() {
        return None;
    }
    hubs.sort_unstable_by_key(|&(valence, first, _)| (std::cmp::Reverse(valence), first));
    let mut rank = vec![u32::MAX; mesh.positions.len()];
    for (r, (_, _, group)) in hubs.iter().enumerate() {
        order[group.clone()].iter().for_each(|&v| rank[v as usize] = r as u32);
    }
    let mut taken: Vec<Vec<u32>> = vec![Vec::new(); hubs.len()];
    for (t, corners) in mesh.indices.chunks_exact(3).enumerate() {
        let best = corners.iter().map(|&v| rank[v as usize]).min().unwrap_or(u32::MAX);
        if best != u32::MAX {
            taken[best as usize].push(t as u32);
        }
    }
    let mut in_fan = vec![false; mesh.triangle_count()];
    let mut fans = Vec::new();
    for ((_, first, _), triangles) in hubs.into_iter().zip(taken) {
        if triangles.len() < (FAN_MIN_VALENCE / 2) as usize {
            continue;
        }
        triangles.iter().for_each(|&t| in_fan[t as usize] = true);
        fans.push((mesh.positions[first as usize], triangles));
    }
    (!fans.is_empty()).then_some(FanPlan { fans, in_fan })
}

/// Every fan of a scene, ready to trace.
pub struct Fans {
    /// Box tree over the fans' boxes; its leaf ranges index `hubs`.
    nodes: Vec<Node8>,
    hubs: Vec<Hub>,
    caps: Vec<Cap>,
    /// [`SLACK`] in scene units.
    slack: f64,
}

#[derive(Clone, Copy, Debug)]
struct Hub {
    point: DVec3,
    /// Its root cap.
    root: u32,
}

/// A spherical cap around a hub holding the arcs of some of its triangles.
#[derive(Clone, Copy, Debug)]
struct Cap {
    /// Unit centre.
    centre: DVec3,
    /// Sine and cosine of the angular radius (1 and 0 from 90° on: every
    /// great circle crosses it).
    sin: f64,
    cos: f64,
    /// A leaf ([`LEAF`] set): its triangles' leaf-order range; otherwise the
    /// first of its two children (the second follows it).
    child: u32,
}

impl Cap {
    /// Whether the great circle of unit normal `normal` passes within the
    /// angle `s` (given by its sine and cosine) of the cap.
    #[inline(always)]
    fn crossed(&self, normal: DVec3, sin_s: f64, cos_s: f64) -> bool {
        // Radius r + s reaching 90°: every great circle crosses it.
        if self.cos * cos_s - self.sin * sin_s <= 0.0 {
            return true;
        }
        // The circle's angular distance from the centre, asin |n·c|, against r + s.
        normal.dot(self.centre).abs() <= self.sin * cos_s + self.cos * sin_s + 1e-9
    }
}

/// A fan's triangle while its tree is built.
struct Arc {
    triangle: u32,
    /// Unit directions from the hub of the triangle's other two corners (zero for a corner on the hub).
    ends: [DVec3; 2],
    /// Where the arc sits: the mean of its ends.
    middle: DVec3,
}

impl Fans {
    /// Builds the cap trees of `plan`'s fans and the box tree over them. Each
    /// fan's triangles are appended to `leaf_order` (mesh indices) in the
    /// order of its leaves, and the leaves (`(first, count)` in leaf order)
    /// to `leaves`. `scale` is the scene's size, for the rounding slack.
    pub fn build(plan: FanPlan, mesh: &Mesh, scale: f32, leaf_order: &mut Vec<u32>, leaves: &mut Vec<(u32, u32)>) -> Fans {
        let mut caps = Vec::new();
        let mut hubs = Vec::new();
        let mut boxes = Vec::new();
        for (point, triangles) in plan.fans {
            let hub = point.as_dvec3();
            let mut arcs: Vec<Arc> = triangles
                .iter()
                .map(|&t| {
                    // The directions of the corners off the hub (one corner at least is on it).
                    let mut ends = [DVec3::ZERO; 2];
                    let off = mesh.triangle_positions(t as usize).into_iter().map(|p| p.as_dvec3() - hub).filter(|d| *d != DVec3::ZERO);
                    for (end, d) in ends.iter_mut().zip(off) {
                        *end = d.normalize();
                    }
                    let middle = (ends[0] + ends[1]).try_normalize().unwrap_or(ends[0]);
                    Arc { triangle: t, ends, middle }
                })
                .collect();
            let mut bounds = Aabb::empty();
            for &t in &triangles {
                mesh.triangle_positions(t as usize).iter().for_each(|p| {
                    bounds.extend((*p).into());
                });
            }
            let root = caps.len() as u32;
            caps.push(Cap { centre: DVec3::ZERO, sin: 1.0, cos: 0.0, child: 0 });
            let depth = build_caps(&mut arcs, root, &mut caps, leaf_order, leaves);
            assert!(depth <= MAX_DEPTH, "fan tree of depth {depth}");
            hubs.push(Hub { point: hub, root });
            boxes.push(bounds);
        }
        let bvh8 = Bvh8::from_bvh2(&super::sah::build_bvh2_sah(&boxes));
        let hubs = bvh8.primitive_order.iter().map(|&h| hubs[h as usize]).collect();
        Fans { nodes: bvh8.nodes, hubs, caps, slack: SLACK * f64::from(scale) }
    }

    /// Walks every fan the ray reaches within `t_max`, passing each leaf it
    /// enters to `leaves`, the way [`bvh8::Walk`] does (`NEAREST_FIRST`: fans
    /// nearest first, and none beyond the reach `leaves` leaves).
    #[inline(always)]
    pub fn walk<T: NodeTest, L: Leaves, const NEAREST_FIRST: bool>(
        &self,
        origin: Vec3,
        direction: Vec3,
        boxes: &RayBoxes,
        t_max: f32,
        leaves: &mut L,
    ) {
        let mut fans = FanLeaves { fans: self, origin: origin.as_dvec3(), direction: direction.as_dvec3(), leaves };
        let mut walk = bvh8::Walk::new(t_max);
        while walk.step::<T, _, NEAREST_FIRST, false>(&self.nodes, boxes, 0.0, &mut fans) {}
    }

    /// Walks one fan's caps: every leaf whose cap the plane through the hub
    /// and the ray crosses goes to `leaves`.
    #[inline(always)]
    fn walk_hub<L: Leaves>(&self, hub: &Hub, origin: DVec3, direction: DVec3, mut t_max: f32, leaves: &mut L) -> LeafResult {
        // The plane through the hub that holds the ray, and the line's distance from the hub.
        let normal = (origin - hub.point).cross(direction);
        let distance = normal.length() / direction.length();
        // A hit the triangle test reports lies within `slack` of its triangle,
        // so at least `distance - slack` from the hub, within the angle
        // asin(slack / (distance - slack)) of the plane; nearer, anywhere.
        let (sin_s, cos_s) = if distance > 2.0 * self.slack {
            let s = self.slack / (distance - self.slack);
            (s, (1.0 - s * s).sqrt())
        } else {
            (1.0, 0.0)
        };
        let normal = normal.normalize_or_zero();
        let mut stack = [0u32; MAX_DEPTH + 2];
        let mut len = 1;
        stack[0] = hub.root;
        while len > 0 {
            len -= 1;
            let cap = &self.caps[stack[len] as usize];
            #[cfg(test)]
            super::queries::work::add(1);
            if !cap.crossed(normal, sin_s, cos_s) {
                continue;
            }
            if cap.child & LEAF != 0 {
                let (first, count) = ((cap.child & !LEAF) >> 4, cap.child & 0xf);
                match leaves.visit(first, count, t_max) {
                    LeafResult::Continue(t) => t_max = t,
                    LeafResult::Stop => return LeafResult::Stop,
                }
            } else {
                stack[len] = cap.child + 1;
                stack[len + 1] = cap.child;
                len += 2;
            }
        }
        LeafResult::Continue(t_max)
    }
}

/// Fills cap `index` (already pushed) with `arcs` and builds its subtree;
/// returns the subtree's depth.
fn build_caps(arcs: &mut [Arc], index: u32, caps: &mut Vec<Cap>, leaf_order: &mut Vec<u32>, leaves: &mut Vec<(u32, u32)>) -> usize {
    let cap = &mut caps[index as usize];
    (cap.centre, cap.sin, cap.cos) = bound_arcs(arcs);
    if arcs.len() <= FAN_LEAF {
        let first = leaf_order.len() as u32;
        assert!(first < 1 << 27, "too many triangles for a fan leaf reference");
        leaf_order.extend(arcs.iter().map(|a| a.triangle));
        leaves.push((first, arcs.len() as u32));
        caps[index as usize].child = LEAF | first << 4 | arcs.len() as u32;
        return 1;
    }
    // Split at the median of the middles along their widest axis (ties by triangle index).
    let (lo, hi) = arcs.iter().fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), a| (lo.min(a.middle), hi.max(a.middle)));
    let extent = hi - lo;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    let half = arcs.len() / 2;
    arcs.select_nth_unstable_by(half, |a, b| a.middle[axis].total_cmp(&b.middle[axis]).then(a.triangle.cmp(&b.triangle)));
    let child = caps.len() as u32;
    caps.push(Cap { centre: DVec3::ZERO, sin: 1.0, cos: 0.0, child: 0 });
    caps.push(Cap { centre: DVec3::ZERO, sin: 1.0, cos: 0.0, child: 0 });
    caps[index as usize].child = child;
    let (left, right) = arcs.split_at_mut(half);
    let depth = build_caps(left, child, caps, leaf_order, leaves).max(build_caps(right, child + 1, caps, leaf_order, leaves));
    depth + 1
}

/// A cap holding every end of `arcs` (so every arc: an arc shorter than
/// 180° between two points of a cap narrower than 90° stays inside it), as
/// (centre, sin, cos) of its radius; from 90° on, or when the ends have no
/// mean direction, the whole sphere (sin 1, cos 0).
fn bound_arcs(arcs: &[Arc]) -> (DVec3, f64, f64) {
    let ends = || arcs.iter().flat_map(|a| a.ends).filter(|e| *e != DVec3::ZERO);
    let Some(centre) = ends().sum::<DVec3>().try_normalize() else { return (DVec3::ZERO, 1.0, 0.0) };
    // Widened by a few ulps for the rounding of the dot products.
    let cos = ends().map(|e| centre.dot(e)).fold(1.0f64, f64::min) - 1e-12;
    if cos <= 0.0 {
        return (centre, 1.0, 0.0);
    }
    (centre, (1.0 - cos * cos).max(0.0).sqrt(), cos)
}

/// The box tree's leaves, which are fans: each walks its caps.
struct FanLeaves<'a, L> {
    fans: &'a Fans,
    origin: DVec3,
    direction: DVec3,
    leaves: &'a mut L,
}

impl<L: Leaves> Leaves for FanLeaves<'_, L> {
    #[inline(always)]
    fn block_address(&self, first: u32) -> *const u8 {
        self.fans.hubs.as_ptr().wrapping_add(first as usize).cast()
    }

    #[inline(always)]
    fn visit(&mut self, first: u32, count: u32, mut t_max: f32) -> LeafResult {
        for h in first..first + count {
            // An empty child slot's reference decodes past the hubs: skipped.
            let Some(hub) = self.fans.hubs.get(h as usize) else { continue };
            match self.fans.walk_hub(hub, self.origin, self.direction, t_max, self.leaves) {
                LeafResult::Continue(t) => t_max = t,
                LeafResult::Stop => return LeafResult::Stop,
            }
        }
        LeafResult::Continue(t_max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::{bake_mesh, BakeParams};
    use crate::clean::fixtures::{fan, FanShape};
    use crate::trace::queries::work;
    use crate::trace::scene::{brute_force_closest, BatchMode, Batching, BuildQuality, RayQuery, Scene, Traversal};
    use crate::verify::shapes;
    use glam::{Mat3, Vec3};

    /// Fans of every kind in one scene, beside triangles the box tree
    /// keeps: a closed cone (apex and base centre of valence 1,200), a disc
    /// of 2,000 slivers and a 1,500-gon fanned from a corner, both tilted off
    /// the axis planes, and a plane under them.
    fn fans_scene() -> Mesh {
        let mut mesh = shapes::plane_grid(8, 6.0);
        shapes::transform(&mut mesh, 1.0, Vec3::new(0.0, -0.5, 0.0));
        let tilt = Mat3::from_rotation_x(0.7) * Mat3::from_rotation_z(0.4);
        for (shape, n, offset) in [
            (FanShape::ClosedCone, 1200, Vec3::ZERO),
            (FanShape::Disc, 2000, Vec3::new(2.0, 0.5, 0.0)),
            (FanShape::Polygon, 1500, Vec3::new(-2.0, 0.8, 0.5)),
        ] {
            let mut part = fan(shape, n);
            if shape != FanShape::ClosedCone {
                part.positions.iter_mut().for_each(|p| *p = tilt * *p);
            }
            shapes::transform(&mut part, 1.0, offset);
            shapes::append(&mut mesh, &part);
        }
        mesh
    }

    fn scene_with_paths(mesh: &Mesh) -> (Scene, Vec<Traversal>) {
        let mut scene = Scene::build(mesh, BuildQuality::Sah).unwrap();
        let mut paths = vec![Traversal::Portable];
        if scene.set_traversal(Traversal::Avx2) == Traversal::Avx2 {
            paths.push(Traversal::Avx2);
        }
        (scene, paths)
    }

    #[test]
    fn points_of_valence_1024_and_more_make_fans_and_ordinary_meshes_have_none() {
        assert!(find_fans(&fan(FanShape::Disc, FAN_MIN_VALENCE as usize - 1)).is_none());
        let plan = find_fans(&fan(FanShape::Disc, FAN_MIN_VALENCE as usize)).expect("a fan");
        assert_eq!(plan.fans.len(), 1);
        assert!(plan.in_fan.iter().all(|&f| f));
        // The closed cone: two hubs, each with its own triangles.
        let plan = find_fans(&fan(FanShape::ClosedCone, 1200)).expect("fans");
        assert_eq!(plan.fans.iter().map(|(_, t)| t.len()).collect::<Vec<_>>(), [1200, 1200]);
        // Split vertices (one per triangle at the hub) are still one point.
        let mut split = fan(FanShape::Disc, 1100);
        let hub = split.positions[1100];
        for t in 0..1100 {
            split.positions.push(hub);
            split.normals.push(Vec3::Y);
            split.indices[3 * t] = 1101 + t as u32;
        }
        assert_eq!(find_fans(&split).expect("a fan").fans[0].1.len(), 1100);
        let (cabin, _) = crate::fixtures::cabin::generate_cabin(8.0);
        assert!(find_fans(&cabin).is_none());
        assert!(find_fans(&shapes::plane_grid(64, 1.0)).is_none());
    }

    /// Random rays, rays leaving the fans as the bake's do, and rays aimed
    /// at the fans' edges and hubs from outside: closest hit and occlusion
    /// agree with testing every triangle, on every path, one by one and
    /// interleaved; a ray aimed at an edge of the closed cone always hits.
    #[test]
    fn fan_queries_match_brute_force() {
        let mesh = fans_scene();
        let (mut scene, paths) = scene_with_paths(&mesh);
        let fans = scene.fans.as_ref().expect("the scene has fans");
        assert_eq!(fans.hubs.len(), 4);
        let mut rand = crate::sampling::test_stream(99);
        let mut queries = Vec::new();
        for _ in 0..3000 {
            let origin = Vec3::new(rand() * 8.0 - 4.0, rand() * 3.0 - 1.0, rand() * 6.0 - 3.0);
            let direction = Vec3::new(rand() - 0.5, rand() - 0.5, rand() - 0.5).normalize();
            queries.push(RayQuery { origin, direction, t_max: if rand() < 0.3 { rand() * 3.0 } else { f32::INFINITY } });
        }
        for _ in 0..3000 {
            let t = (rand() * mesh.triangle_count() as f32) as usize % mesh.triangle_count();
            let [a, b, c] = mesh.triangle_positions(t);
            let (u, v) = (rand(), rand());
            let (u, v) = if u + v > 1.0 { (1.0 - u, 1.0 - v) } else { (u, v) };
            let normal = scene.face_normal(t as u32);
            let direction = crate::sampling::cosine_sphere(normal, rand(), rand());
            let origin = scene.offset_origin(a + (b - a) * u + (c - a) * v, normal, direction);
            queries.push(RayQuery { origin, direction, t_max: f32::INFINITY });
        }
        // The closed cone's edges: from its apex (0, 1, 0) to its rim, at every distance.
        let mut edge_rays = Vec::new();
        for k in 0..2000 {
            let angle = std::f32::consts::TAU * (k % 1200) as f32 / 1200.0;
            let rim = Vec3::new(angle.cos(), 0.0, -angle.sin());
            let target = Vec3::Y + (rim - Vec3::Y) * (k as f32 + 0.5) / 2000.0;
            let origin = target + (target - Vec3::new(0.0, target.y, 0.0)).normalize_or(Vec3::X) * 2.0 + Vec3::new(0.0, rand() - 0.3, 0.0);
            edge_rays.push(RayQuery { origin, direction: (target - origin).normalize(), t_max: f32::INFINITY });
        }
        queries.extend_from_slice(&edge_rays);
        let mut hits = 0;
        for &path in &paths {
            scene.set_traversal(path);
            for (i, q) in queries.iter().enumerate() {
                let found = scene.closest_hit(q.origin, q.direction, q.t_max);
                let brute = brute_force_closest(&mesh, q.origin, q.direction, q.t_max);
                match (found, brute) {
                    (Some(h), Some((t, d))) => {
                        // Hits on a shared edge tie: either triangle, at the same distance.
                        assert!(h.triangle == t || (h.t - d).abs() <= scene.tie_distance, "{path:?} ray {i}: {h:?} against {t} at {d}");
                        if h.triangle == t {
                            assert_eq!(h.t.to_bits(), d.to_bits(), "{path:?} ray {i}");
                        }
                        hits += 1;
                    }
                    (None, None) => {}
                    _ => panic!("{path:?} ray {i} {q:?}: {found:?} against brute force {brute:?}"),
                }
                assert_eq!(scene.occluded(q.origin, q.direction, q.t_max), brute.is_some(), "{path:?} ray {i}");
                let mut hint = u32::MAX;
                assert_eq!(scene.occluded_cached(q.origin, q.direction, q.t_max, &mut hint), brute.is_some(), "{path:?} ray {i}");
            }
            for q in &edge_rays {
                assert!(scene.occluded(q.origin, q.direction, q.t_max), "{path:?}: a ray at the cone's edge leaked: {q:?}");
            }
            let single: Vec<_> = queries.iter().map(|q| scene.closest_hit(q.origin, q.direction, q.t_max)).collect();
            for mode in [BatchMode::OneByOne, BatchMode::Interleaved] {
                scene.set_batching(Batching { closest_hit: mode, occlusion: mode });
                for (chunk, expected) in queries.chunks(37).zip(single.chunks(37)) {
                    let mut out = vec![None; chunk.len()];
                    scene.closest_hits(chunk, &mut out);
                    assert_eq!(out, expected, "{path:?} {mode:?}");
                    let mut blocked = vec![false; chunk.len()];
                    scene.occluded_each(chunk, &mut blocked);
                    assert_eq!(blocked, expected.iter().map(Option::is_some).collect::<Vec<_>>(), "{path:?} {mode:?}");
                }
            }
        }
        assert!(hits > 4000, "only {hits} hits");
    }

    /// The scaling bound of a bake on a closed cone, in work done (box
    /// nodes, caps and triangles tested), not time: apex valence ×8 costs
    /// at most 2 × 8 times the work. Every ray from the cone's side used to
    /// walk a fixed share of its triangles' boxes, so the work grew ×64
    /// (×58 measured on the box tree alone).
    #[test]
    fn a_bake_on_a_cone_does_work_near_linear_in_its_apex_valence() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let params = BakeParams { rays: 4, ..BakeParams::default() };
        let work_at = |valence: usize| {
            let cone = fan(FanShape::ClosedCone, valence);
            pool.install(|| {
                work::take();
                bake_mesh(&cone, &params, &[]).unwrap();
                work::take()
            })
        };
        let (small, large) = (work_at(2500), work_at(20_000));
        eprintln!("work: {small} at valence 2.5k, {large} at 20k ({:.1}×)", large as f64 / small as f64);
        assert!(large <= 2 * 8 * small, "valence ×8 did {:.1}× the work", large as f64 / small as f64);
    }
}
