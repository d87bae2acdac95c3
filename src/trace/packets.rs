//! Occlusion of parallel rays (the sun's: every ray of a time step shares
//! one direction) walked as packets: one walk through the tree for up to
//! [`PACKET`] rays from nearby origins.
//!
//! Parallel rays from origins inside a box sweep a beam. A node's eight
//! child boxes are tested against the beam in one pass, as a lone ray's are
//! (the slab test with the origin box's far corner for each entry plane and
//! its near corner for each exit plane), so the packet fetches and tests
//! each node once instead of once per ray. The beam test is conservative:
//! a box that any of the rays enters passes it.
//!
//! Same answers as [`Scene::occluded`], bit for bit. A lone ray's walk
//! reaches a leaf exactly when the ray's slab test passes at the leaf and
//! at every node above it; a node's box contains its children's (float
//! minima and maxima, exact), and the slab test is monotone in the box, so
//! that is exactly when the leaf's own box test passes. At each leaf the
//! beam reaches, every ray still unanswered takes that exact test (the lone
//! walk's arithmetic) and then the lone walk's triangle test.

use glam::Vec3;
use obvhs::{ray::Ray, rt_triangle::RtTriangle};

use super::bvh8::{self, Node8, RayBoxes, WIDTH};
use super::leaf_blocks::{LeafBlocks, LeafTest, ScalarLeaf};
use super::scene::{RayQuery, Scene, Traversal};

/// Rays per packet: one bit each in a `u32` mask.
pub const PACKET: usize = 16;
/// Largest extent of a packet's origins along any axis, relative to the
/// scene's diagonal: a packet ends early rather than span it. Consecutive
/// points can lie far apart (texels along an atlas row cross charts), and
/// one wide beam enters most of the tree: unbounded, the grey-white room's
/// texel sun took 3.0 s against 1.2 s one ray at a time; from 0.02 to 0.1
/// it takes 0.8–0.85 s, and the colonnade is the same within noise (0.002
/// cuts its packets too short: 8.3 s against 6.1–6.5 s).
const SPREAD: f32 = 0.05;
/// Distinct hints a packet tests before its walk (one and four measured
/// alike on the colonnade, four 2.9 s against one 4.1 s on the room's
/// texel sun before `SPREAD` bounded the packets).
pub const HINTS_TRIED: usize = 4;
/// Stack entries of a packet walk before it spills to the heap.
const STACK: usize = 64;

/// How far the rays of a parallel query reach: all alike, or each its own.
#[derive(Clone, Copy)]
enum Reach<'a> {
    All(f32),
    Each(&'a [f32]),
}

impl Reach<'_> {
    #[inline(always)]
    fn at(&self, k: usize) -> f32 {
        match self {
            Reach::All(t) => *t,
            Reach::Each(t) => t[k],
        }
    }
}

/// A packet's origins swept along the shared direction, prepared for box tests.
#[derive(Clone, Copy, Debug)]
pub struct Beam {
    /// Per axis, the origin coordinate that gives the smallest entry distance (the box's near plane).
    pub near_origin: [f32; 3],
    /// Per axis, the origin coordinate that gives the largest exit distance (the far plane).
    pub far_origin: [f32; 3],
    pub inverse: [f32; 3],
    /// Row of the near plane per axis, as [`RayBoxes::near_row`].
    pub near_row: [usize; 3],
}

impl Beam {
    /// The beam of the rays in `active` (which share one direction).
    #[inline(always)]
    fn of(rays: &[Ray; PACKET], active: u32) -> Beam {
        let first = RayBoxes::from_ray(&rays[active.trailing_zeros() as usize]);
        let (mut lo, mut hi) = (first.origin, first.origin);
        let mut rest = active;
        while rest != 0 {
            let o = rays[rest.trailing_zeros() as usize].origin.to_array();
            rest &= rest - 1;
            for axis in 0..3 {
                lo[axis] = lo[axis].min(o[axis]);
                hi[axis] = hi[axis].max(o[axis]);
            }
        }
        // Toward +axis the entry (b − o)·inv is smallest for the largest o,
        // the exit largest for the smallest; toward −axis the other way round.
        let pick = |axis: usize, toward_plus: bool| if toward_plus { hi[axis] } else { lo[axis] };
        let inverse = first.inverse;
        let plus = [inverse[0] >= 0.0, inverse[1] >= 0.0, inverse[2] >= 0.0];
        Beam {
            near_origin: [pick(0, plus[0]), pick(1, plus[1]), pick(2, plus[2])],
            far_origin: [pick(0, !plus[0]), pick(1, !plus[1]), pick(2, !plus[2])],
            inverse,
            near_row: first.near_row,
        }
    }
}

/// The origins of a packet's rays, a row per axis, and each ray's `t_max`
/// (lanes past the packet's rays hold copies of its first).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub struct PacketOrigins {
    pub rows: [[f32; PACKET]; 3],
    pub t_max: [f32; PACKET],
}

/// The box tests of a packet walk.
pub trait BeamTest {
    /// The mask of `node`'s children that some ray of `beam` may enter within `[0, t_max]`.
    fn test(node: &Node8, beam: &Beam, t_max: f32) -> u32;
    /// The mask of the rays (lanes of `origins`, each along `template`'s
    /// direction, within its own `t_max`) that hit `triangle`: per lane
    /// exactly `RtTriangle::intersect` (the leaf tests' arithmetic).
    fn rays_blocked_by(triangle: &RtTriangle, origins: &PacketOrigins, template: &Ray) -> u32;
    /// The mask of the rays (lanes of `origins`, all along `beam`'s
    /// direction) whose lone walk enters child `slot` of `node` within
    /// `[0, t_max]`, each its own `t_max`: the lone walk's slab test
    /// ([`bvh8::ScalarTest`], whose lanes the AVX2 test matches bit for
    /// bit) with `t_min` 0.
    fn rays_entering(node: &Node8, slot: usize, origins: &PacketOrigins, beam: &Beam) -> u32;
}

/// Portable path.
pub struct ScalarBeam;

impl BeamTest for ScalarBeam {
    #[inline(always)]
    fn test(node: &Node8, beam: &Beam, t_max: f32) -> u32 {
        let mut mask = 0;
        for slot in 0..WIDTH {
            mask |= u32::from(slab_passes(node, slot, beam, beam.near_origin, beam.far_origin, t_max)) << slot;
        }
        mask
    }

    #[inline(always)]
    fn rays_blocked_by(triangle: &RtTriangle, origins: &PacketOrigins, template: &Ray) -> u32 {
        let mut mask = 0;
        for lane in 0..PACKET {
            let origin = glam::Vec3A::new(origins.rows[0][lane], origins.rows[1][lane], origins.rows[2][lane]);
            let ray = Ray { origin, tmax: origins.t_max[lane], ..*template };
            mask |= u32::from(triangle.intersect(&ray).is_finite()) << lane;
        }
        mask
    }

    #[inline(always)]
    fn rays_entering(node: &Node8, slot: usize, origins: &PacketOrigins, beam: &Beam) -> u32 {
        let mut mask = 0;
        for lane in 0..PACKET {
            let origin = [origins.rows[0][lane], origins.rows[1][lane], origins.rows[2][lane]];
            mask |= u32::from(slab_passes(node, slot, beam, origin, origin, origins.t_max[lane])) << lane;
        }
        mask
    }
}

/// The lone walk's slab test ([`bvh8::ScalarTest`]) of child `slot` of
/// `node` along `beam`'s direction, with `t_min` 0 and its own origin for
/// the entry planes and for the exit planes (one ray: the same origin).
#[inline(always)]
fn slab_passes(node: &Node8, slot: usize, beam: &Beam, near_origin: [f32; 3], far_origin: [f32; 3], t_max: f32) -> bool {
    let (mut near, mut far) = (0.0f32, f32::INFINITY);
    for axis in 0..3 {
        let n = node.bounds[beam.near_row[axis]][slot];
        let f = node.bounds[beam.near_row[axis] ^ 1][slot];
        near = ((n - near_origin[axis]) * beam.inverse[axis]).max(near);
        far = ((f - far_origin[axis]) * beam.inverse[axis]).min(far);
    }
    near <= (far * bvh8::EXIT_STRETCH).min(t_max)
}

/// AVX2 path: the eight boxes in one register per plane.
#[cfg(target_arch = "x86_64")]
pub struct Avx2Beam;

#[cfg(target_arch = "x86_64")]
impl BeamTest for Avx2Beam {
    #[inline(always)]
    fn test(node: &Node8, beam: &Beam, t_max: f32) -> u32 {
        use std::arch::x86_64::*;
        // SAFETY: reached only from `#[target_feature(enable = "avx2")]`
        // functions called after runtime detection; every load reads one
        // aligned row of `node`.
        unsafe {
            let rows = node.bounds.as_ptr();
            let plane = |row: usize, origin: f32, inverse: f32| {
                let b = _mm256_load_ps((*rows.add(row)).as_ptr());
                _mm256_mul_ps(_mm256_sub_ps(b, _mm256_set1_ps(origin)), _mm256_set1_ps(inverse))
            };
            let mut near = _mm256_setzero_ps();
            let mut far = _mm256_set1_ps(f32::INFINITY);
            for axis in 0..3 {
                let row = beam.near_row[axis];
                near = _mm256_max_ps(plane(row, beam.near_origin[axis], beam.inverse[axis]), near);
                far = _mm256_min_ps(plane(row ^ 1, beam.far_origin[axis], beam.inverse[axis]), far);
            }
            far = _mm256_min_ps(_mm256_mul_ps(far, _mm256_set1_ps(bvh8::EXIT_STRETCH)), _mm256_set1_ps(t_max));
            _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(near, far)) as u32
        }
    }

    #[inline(always)]
    fn rays_blocked_by(triangle: &RtTriangle, origins: &PacketOrigins, template: &Ray) -> u32 {
        use std::arch::x86_64::*;
        // SAFETY: as `test`; every load reads one aligned row of `origins`.
        // The leaf test's arithmetic with rays in the lanes instead of
        // triangles: each lane gives `RtTriangle::intersect`'s bits.
        unsafe {
            let splat = _mm256_set1_ps;
            let (v0, e1, e2, ng, d) = (triangle.v0, triangle.e1, triangle.e2, triangle.ng, template.direction);
            let rows = [v0.x, v0.y, v0.z, e1.x, e1.y, e1.z, e2.x, e2.y, e2.z, ng.x, ng.y, ng.z].map(|x| splat(x));
            let direction = [splat(d.x), splat(d.y), splat(d.z)];
            let mut mask = 0;
            for half in 0..PACKET / 8 {
                let origin = std::array::from_fn(|axis| _mm256_load_ps(origins.rows[axis].as_ptr().add(8 * half)));
                let t_max = _mm256_load_ps(origins.t_max.as_ptr().add(8 * half));
                let (hits, _, _) = super::leaf_blocks::moller_trumbore_lanes(&rows, origin, direction, template.tmin, t_max);
                mask |= hits << (8 * half);
            }
            mask
        }
    }

    #[inline(always)]
    fn rays_entering(node: &Node8, slot: usize, origins: &PacketOrigins, beam: &Beam) -> u32 {
        use std::arch::x86_64::*;
        // SAFETY: as `test`; every load reads one aligned row of `origins`.
        unsafe {
            let mut mask = 0;
            for half in 0..PACKET / 8 {
                let plane = |row: usize, axis: usize| {
                    let b = _mm256_set1_ps(node.bounds[row][slot]);
                    let o = _mm256_load_ps(origins.rows[axis].as_ptr().add(8 * half));
                    _mm256_mul_ps(_mm256_sub_ps(b, o), _mm256_set1_ps(beam.inverse[axis]))
                };
                let mut near = _mm256_setzero_ps();
                let mut far = _mm256_set1_ps(f32::INFINITY);
                for axis in 0..3 {
                    let row = beam.near_row[axis];
                    near = _mm256_max_ps(plane(row, axis), near);
                    far = _mm256_min_ps(plane(row ^ 1, axis), far);
                }
                let t_max = _mm256_load_ps(origins.t_max.as_ptr().add(8 * half));
                far = _mm256_min_ps(_mm256_mul_ps(far, _mm256_set1_ps(bvh8::EXIT_STRETCH)), t_max);
                mask |= (_mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(near, far)) as u32) << (8 * half);
            }
            mask
        }
    }
}

impl Scene {
    /// [`Scene::occluded`] of rays from every origin along one unit
    /// `direction` within `(0, t_max]`, into `out`, in packets of up to
    /// [`PACKET`] consecutive origins no further apart than [`SPREAD`]:
    /// nearby origins make tight beams.
    ///
    /// `hints` (one per origin) is a shadow cache: the leaf-order triangle
    /// that last blocked each ray's point (`u32::MAX` = none), kept by the
    /// caller from one sun step to the next, when a point is usually
    /// blocked by the same triangle again. Before its walk a packet tests
    /// the distinct hints of its rays (at most [`HINTS_TRIED`]) against all
    /// its rays, so one ray's blocker serves its neighbours too; the
    /// blockers the walk finds are written back. Same answers as
    /// [`Scene::occluded`], bit for bit, whatever the hints hold.
    pub fn occluded_parallel(&self, origins: &[Vec3], direction: Vec3, t_max: f32, hints: &mut [u32], out: &mut [bool]) {
        self.occluded_parallel_reach(origins, direction, Reach::All(t_max), hints, out);
    }

    /// [`Scene::occluded_parallel`] with each ray's own `t_max` (one per
    /// origin): the same answers as [`Scene::occluded`] of each ray within
    /// its own reach. A packet's beam reaches as far as its farthest ray; at
    /// a leaf, each ray takes its lone test within its own.
    pub fn occluded_parallel_each(&self, origins: &[Vec3], direction: Vec3, t_max: &[f32], hints: &mut [u32], out: &mut [bool]) {
        assert_eq!(origins.len(), t_max.len(), "one t_max per origin");
        self.occluded_parallel_reach(origins, direction, Reach::Each(t_max), hints, out);
    }

    fn occluded_parallel_reach(&self, origins: &[Vec3], direction: Vec3, reach: Reach, hints: &mut [u32], out: &mut [bool]) {
        assert!(origins.len() == out.len() && origins.len() == hints.len(), "one hint and one answer per origin");
        // The box tree alone answers, and its boxes nest; with fans, or a
        // direction that cannot be traced, each ray takes the lone path.
        if self.fans.is_some()
            || self.nodes.is_empty()
            || !self.boxes_nest
            || !(RayQuery { origin: Vec3::ZERO, direction, t_max: f32::INFINITY }).is_traceable()
        {
            for (k, ((o, answer), hint)) in origins.iter().zip(out.iter_mut()).zip(hints.iter_mut()).enumerate() {
                *answer = self.occluded_cached(*o, direction, reach.at(k), hint);
            }
            return;
        }
        #[cfg(target_arch = "x86_64")]
        if self.traversal == Traversal::Avx2 {
            // SAFETY: `traversal` is Avx2 only when the CPU reported AVX2.
            return unsafe { self.occluded_packets_avx2(origins, direction, reach, hints, out) };
        }
        self.occluded_packets::<ScalarBeam, ScalarLeaf>(origins, direction, reach, hints, out);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn occluded_packets_avx2(&self, origins: &[Vec3], direction: Vec3, reach: Reach, hints: &mut [u32], out: &mut [bool]) {
        self.occluded_packets::<Avx2Beam, super::leaf_blocks::AvxLeaf>(origins, direction, reach, hints, out)
    }

    /// [`Scene::occluded_parallel`] on traceable directions, a packet at a time.
    #[inline(always)]
    fn occluded_packets<B: BeamTest, Lf: LeafTest>(
        &self,
        origins: &[Vec3],
        direction: Vec3,
        reach: Reach,
        hints: &mut [u32],
        out: &mut [bool],
    ) {
        // The inverse direction depends on the direction alone: computed once.
        let template = Ray::new(Vec3::ZERO.into(), direction.into(), 0.0, f32::INFINITY);
        let (all_origins, all_out, all_hints) = (origins, out, hints);
        let limit = self.diagonal * SPREAD;
        let mut start = 0;
        while start < all_origins.len() {
            let mut end = start + 1;
            let (mut lo, mut hi) = (all_origins[start], all_origins[start]);
            while end < all_origins.len() && end - start < PACKET {
                let o = all_origins[end];
                let (l, h) = (lo.min(o), hi.max(o));
                if (h - l).max_element() > limit {
                    break;
                }
                (lo, hi, end) = (l, h, end + 1);
            }
            let first_index = start;
            let (origins, out, hints) = (&all_origins[start..end], &mut all_out[start..end], &mut all_hints[start..end]);
            start = end;
            let mut rays = [template; PACKET];
            let mut traceable = 0u32;
            out.fill(false);
            for (k, o) in origins.iter().enumerate() {
                let t_max = reach.at(first_index + k);
                // A ray that cannot be traced answers "no hit", as a lone
                // ray; one whose reach is not positive takes the lone path.
                if !(t_max > 0.0) && !t_max.is_nan() {
                    out[k] = self.occluded_cached(*o, direction, t_max, &mut hints[k]);
                } else if o.is_finite() && !t_max.is_nan() {
                    rays[k].origin = (*o).into();
                    rays[k].tmax = t_max;
                    traceable |= 1 << k;
                }
            }
            if traceable == 0 {
                continue;
            }
            let first = traceable.trailing_zeros() as usize;
            let (first_origin, first_t_max) = (rays[first].origin, rays[first].tmax);
            let mut lanes = PacketOrigins {
                rows: [[first_origin.x; PACKET], [first_origin.y; PACKET], [first_origin.z; PACKET]],
                t_max: [first_t_max; PACKET],
            };
            let mut packet_t_max = 0.0f32;
            for k in (0..PACKET).filter(|k| traceable >> k & 1 == 1) {
                (lanes.rows[0][k], lanes.rows[1][k], lanes.rows[2][k]) = (rays[k].origin.x, rays[k].origin.y, rays[k].origin.z);
                lanes.t_max[k] = rays[k].tmax;
                packet_t_max = packet_t_max.max(rays[k].tmax);
            }
            // Hints block within a margin short of each reach (`hint_reach`).
            let hint_lanes = PacketOrigins { t_max: lanes.t_max.map(super::queries::hint_reach), ..lanes };
            // The shadow cache: each distinct hint of a ray not yet
            // answered, tested against every ray of the packet.
            let mut by_hint = 0u32;
            let mut tried = [u32::MAX; HINTS_TRIED];
            let mut candidates = traceable;
            for attempt in 0..HINTS_TRIED {
                let Some(k) = (0..origins.len()).find(|&k| {
                    candidates >> k & 1 == 1 && (hints[k] as usize) < self.leaf_triangles.len() && !tried[..attempt].contains(&hints[k])
                }) else {
                    break;
                };
                tried[attempt] = hints[k];
                let triangle = self.leaf_triangles.triangle(hints[k]);
                by_hint |= B::rays_blocked_by(&triangle, &hint_lanes, &template) & traceable;
                candidates &= !by_hint & !(1 << k);
            }
            let active = traceable & !by_hint;
            let mut found = [None; PACKET];
            if active != 0 {
                self.packet_walk::<B, Lf>(&rays, &lanes, active, packet_t_max, &mut found);
            }
            for (k, ((answer, blocker), hint)) in out.iter_mut().zip(found).zip(hints.iter_mut()).enumerate() {
                if traceable >> k & 1 == 0 {
                    continue;
                }
                *answer = by_hint >> k & 1 == 1;
                if let Some(leaf) = blocker {
                    *answer = true;
                    *hint = leaf;
                }
            }
        }
    }

    /// Walks the tree once for the rays in `active`, writing each blocked
    /// ray's blocker (leaf order) to `found`. The beam narrows to the rays
    /// still unanswered as blockers are found; the walk ends when none is
    /// left. `t_max` is the farthest ray's reach (each ray's own is its `tmax`).
    #[inline(always)]
    fn packet_walk<B: BeamTest, Lf: LeafTest>(
        &self,
        rays: &[Ray; PACKET],
        origins: &PacketOrigins,
        mut active: u32,
        t_max: f32,
        found: &mut [Option<u32>; PACKET],
    ) {
        let (nodes, blocks) = (&self.nodes, &self.leaf_triangles);
        let mut beam = Beam::of(rays, active);
        // Nodes still to visit: a fixed array, spilling to the heap only
        // for deep trees (a node pushes at most seven more than it pops).
        let (mut stack, mut depth, mut spill) = ([0u32; STACK], 1, Vec::new());
        loop {
            let index = match spill.pop() {
                Some(index) => index,
                None if depth > 0 => {
                    depth -= 1;
                    stack[depth]
                }
                None => return,
            };
            let node = &nodes[index as usize];
            #[cfg(test)]
            super::queries::work::add_node();
            let mask = B::test(node, &beam, t_max);
            let mut inner = [0u32; WIDTH];
            let mut inner_count = 0;
            let mut pending = mask;
            while pending != 0 {
                let slot = pending.trailing_zeros() as usize;
                pending &= pending - 1;
                let child = node.children[slot];
                if !bvh8::is_leaf(child) {
                    inner[inner_count] = child;
                    inner_count += 1;
                    continue;
                }
                let entering = B::rays_entering(node, slot, origins, &beam) & active;
                let blocked = test_leaf_rays::<Lf>(blocks, child, rays, entering, found);
                if blocked != 0 {
                    active &= !blocked;
                    if active == 0 {
                        return;
                    }
                    beam = Beam::of(rays, active);
                }
            }
            // Slot order (largest box first), as the lone occlusion walk.
            for &child in inner[..inner_count].iter().rev() {
                if depth < STACK {
                    stack[depth] = child;
                    depth += 1;
                } else {
                    spill.push(child);
                }
            }
        }
    }
}

/// Tests leaf `child` against each ray in `entering` within the ray's own
/// `tmax`; returns the mask of rays it blocks, their blockers (leaf order)
/// in `found`.
#[inline(always)]
fn test_leaf_rays<Lf: LeafTest>(
    blocks: &LeafBlocks,
    child: u32,
    rays: &[Ray; PACKET],
    entering: u32,
    found: &mut [Option<u32>; PACKET],
) -> u32 {
    let (first, count) = bvh8::leaf_range(child);
    let mut blocked = 0;
    let mut rest = entering;
    while rest != 0 {
        let k = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        #[cfg(test)]
        super::queries::work::add(u64::from(count));
        let hits = Lf::test_leaf(blocks, first, count, &rays[k], rays[k].tmax);
        if hits.mask != 0 {
            found[k] = Some(first + hits.mask.trailing_zeros());
            blocked |= 1 << k;
        }
    }
    blocked
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::colonnade::{colonnade, ColonnadeParams};
    use crate::trace::queries::work;
    use crate::trace::BuildQuality;

    /// Ray origins the way the sun bake makes them: a point inside each
    /// triangle (in mesh order, so consecutive origins lie close), pushed off
    /// its surface toward `direction`.
    fn origins(scene: &Scene, mesh: &crate::mesh::Mesh, direction: Vec3) -> Vec<Vec3> {
        (0..mesh.triangle_count())
            .map(|t| {
                let [a, b, c] = mesh.triangle_positions(t);
                let p = a * 0.5 + b * 0.3 + c * 0.2;
                scene.offset_origin(p, scene.face_normal(t as u32), direction)
            })
            .collect()
    }

    /// Every ray of every packet gets the lone walk's answer, on both node
    /// tests, for sun-like, axis-parallel and grazing directions, whatever
    /// the hints, and for origins that cannot be traced.
    #[test]
    fn packets_answer_as_lone_rays_bit_for_bit() {
        let mesh = colonnade(&ColonnadeParams::small());
        let mut scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
        assert!(scene.fans.is_none() && scene.boxes_nest);
        let directions = [
            Vec3::new(0.4, 0.8, 0.3),
            Vec3::new(-0.7, 0.25, 0.1),
            Vec3::Y,
            Vec3::X,
            Vec3::new(0.999, 0.02, -0.01),
            Vec3::new(0.0, 0.05, -1.0),
        ];
        let (mut blocked_rays, mut rays) = (0, 0);
        for traversal in [Traversal::Avx2, Traversal::Portable] {
            scene.set_traversal(traversal);
            for d in directions.map(Vec3::normalize) {
                let mut from = origins(&scene, &mesh, d);
                from[7] = Vec3::NAN;
                from[20] = Vec3::new(f32::INFINITY, 0.0, 0.0);
                let lone: Vec<bool> = from.iter().map(|&o| scene.occluded(o, d, f32::INFINITY)).collect();
                // No hints; the hints this direction leaves (what the next
                // sun step starts from); hints naming arbitrary triangles.
                let mut hints = vec![u32::MAX; from.len()];
                for round in 0..3 {
                    if round == 2 {
                        hints.iter_mut().enumerate().for_each(|(i, h)| *h = (i as u32 * 7919) % scene.leaf_triangles.len() as u32);
                    }
                    let mut answers = vec![false; from.len()];
                    for ((o, a), h) in from.chunks(37).zip(answers.chunks_mut(37)).zip(hints.chunks_mut(37)) {
                        scene.occluded_parallel(o, d, f32::INFINITY, h, a);
                    }
                    let wrong = lone.iter().zip(&answers).filter(|(l, a)| l != a).count();
                    assert_eq!(wrong, 0, "{traversal:?}, {d}, hints round {round}: {wrong} of {} rays differ", from.len());
                }
                assert!(!lone[7] && !lone[20]);
                blocked_rays += lone.iter().filter(|&&b| b).count();
                rays += lone.len();
            }
        }
        // Both answers occur often enough to be tested.
        assert!(blocked_rays * 10 > rays && blocked_rays * 10 < rays * 9, "{blocked_rays} of {rays} blocked");
    }

    /// Each ray within its own reach: the lone walk's answer for every ray,
    /// whatever the hints, with reaches that cut some blockers off (at each
    /// ray's first hit, a float either side of it, short of it or past it),
    /// reaches of zero (the lone path), and NaN. At a reach within rounding
    /// of a hit a box's entry distance may round past the reach while its
    /// triangle's does not: hints block only short of the reach, so the
    /// walk answers there, as alone.
    #[test]
    fn packets_with_a_reach_per_ray_answer_as_lone_rays() {
        let mesh = colonnade(&ColonnadeParams::small());
        let mut scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
        let (mut cut, mut rays) = (0, 0);
        for traversal in [Traversal::Avx2, Traversal::Portable] {
            scene.set_traversal(traversal);
            for d in [Vec3::new(0.4, 0.8, 0.3), Vec3::new(-0.7, 0.25, 0.1), Vec3::X].map(Vec3::normalize) {
                let from = origins(&scene, &mesh, d);
                let reach: Vec<f32> = from
                    .iter()
                    .enumerate()
                    .map(|(i, &o)| {
                        let t = scene.closest_hit(o, d, f32::INFINITY).map_or(f32::INFINITY, |h| h.t);
                        match i % 6 {
                            0 => t,
                            1 => t.next_down(),
                            2 => {
                                if i % 12 == 2 {
                                    t.next_up()
                                } else {
                                    0.999 * t
                                }
                            }
                            3 => 0.5 * t,
                            4 if i % 12 == 4 => 0.0,
                            4 => f32::NAN,
                            _ => f32::INFINITY,
                        }
                    })
                    .collect();
                let lone: Vec<bool> = from.iter().zip(&reach).map(|(&o, &t)| scene.occluded(o, d, t)).collect();
                let mut hints = vec![u32::MAX; from.len()];
                for round in 0..3 {
                    if round == 2 {
                        hints.iter_mut().enumerate().for_each(|(i, h)| *h = (i as u32 * 7919) % scene.leaf_triangles.len() as u32);
                    }
                    let mut answers = vec![false; from.len()];
                    for (((o, t), a), h) in from.chunks(37).zip(reach.chunks(37)).zip(answers.chunks_mut(37)).zip(hints.chunks_mut(37)) {
                        scene.occluded_parallel_each(o, d, t, h, a);
                    }
                    let wrong = lone.iter().zip(&answers).filter(|(l, a)| l != a).count();
                    assert_eq!(wrong, 0, "{traversal:?}, {d}, round {round}: {wrong} of {} rays differ", from.len());
                }
                cut += (0..from.len()).filter(|&i| i % 6 == 1 && !lone[i] && scene.occluded(from[i], d, f32::INFINITY)).count();
                rays += from.len();
            }
        }
        // Reaches a float short of the first hit leave those rays unblocked.
        assert!(cut * 20 > rays / 6, "{cut} of {} rays cut short", rays / 6);
    }

    /// A packet walks the tree once for its rays: on the sun's coherent
    /// rays it tests far fewer box nodes than its rays walking alone, and
    /// less work in all (nodes and leaf triangles; a packet's rays test the
    /// same leaves as alone, and a blocked ray's packet walks on for the
    /// others), with no shadow cache on either side.
    #[test]
    fn a_packet_of_nearby_parallel_rays_does_less_work_than_its_rays_alone() {
        let mesh = colonnade(&ColonnadeParams::small());
        let scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
        let d = Vec3::new(0.4, 0.8, 0.3).normalize();
        let from = origins(&scene, &mesh, d);
        (work::take(), work::take_nodes());
        let lone: Vec<bool> = from.iter().map(|&o| scene.occluded(o, d, f32::INFINITY)).collect();
        let (lone_work, lone_nodes) = (work::take(), work::take_nodes());
        let mut answers = vec![false; from.len()];
        for (o, a) in from.chunks(PACKET).zip(answers.chunks_mut(PACKET)) {
            scene.occluded_parallel(o, d, f32::INFINITY, &mut [u32::MAX; PACKET][..o.len()], a);
        }
        let (packet_work, packet_nodes) = (work::take(), work::take_nodes());
        assert_eq!(lone, answers);
        assert!(packet_nodes * 3 < lone_nodes, "nodes: packets {packet_nodes}, lone rays {lone_nodes}");
        assert!(packet_work * 5 < lone_work * 4, "work: packets {packet_work}, lone rays {lone_work}");
    }
}
