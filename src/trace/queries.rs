//! The walks behind each query (closest hit, occlusion), as state a step at
//! a time, and the two ways of running a batch of them: one ray after
//! another, or several interleaved.
//!
//! Interleaving: a ray's walk is a chain of dependent node fetches. When
//! the tree does not fit in cache each fetch waits ~200 ns here, and one ray
//! alone leaves the core idle. Walking [`IN_FLIGHT`] rays at once, a step of
//! each in turn, lets every ray's fetch (prefetched when its parent was
//! tested) arrive while the others work. That pays on a latency-bound scene
//! (519k-triangle cabin, 1 thread: closest hit +52%, occlusion +118%) and
//! costs on one bound by instructions and branch mispredictions instead
//! (Ferrari interior: closest hit −22%; callgrind: +6% instructions, +19%
//! mispredicted branches), so the scene times both on its own rays when it
//! is built and keeps the faster ([`super::Scene`], docs/performance.md).
//! Each ray's walk is the same whichever runs beside it, so both give the
//! same answers bit for bit.

use glam::Vec3;
use obvhs::ray::Ray;

use super::bvh8::ScalarTest;
use super::bvh8::{self, LeafResult, NodeTest, RayBoxes};
use super::leaf_blocks::ScalarLeaf;
use super::leaf_blocks::{LeafBlocks, LeafTest};
use super::scene::{BatchMode, Hit, RayQuery, Scene, Traversal};

/// The queries, on the fastest node and leaf tests this CPU has.
impl Scene {
    /// Closest hit along a unit `direction` from `origin` within `(0, t_max]`.
    pub fn closest_hit(&self, origin: Vec3, direction: Vec3, t_max: f32) -> Option<Hit> {
        let mut answer = [None];
        self.run::<ClosestWalk>(&[RayQuery { origin, direction, t_max }], &mut answer, BatchMode::OneByOne);
        answer[0]
    }

    /// [`Scene::closest_hit`] of every query, into `out` (same length), run
    /// the scene's way ([`Scene::batching`]). Same answers, bit for bit.
    pub fn closest_hits(&self, queries: &[RayQuery], out: &mut [Option<Hit>]) {
        assert_eq!(queries.len(), out.len(), "one answer per query");
        super::ray_log::record(queries, super::ray_log::LoggedQuery::ClosestHit);
        self.run::<ClosestWalk>(queries, out, self.batching.closest_hit);
    }

    /// True when anything lies along `direction` from `origin` within `(0, t_max]`.
    pub fn occluded(&self, origin: Vec3, direction: Vec3, t_max: f32) -> bool {
        self.occluder(&RayQuery { origin, direction, t_max }).is_some()
    }

    /// [`Scene::occluded`] of every query, into `out` (same length), run the
    /// scene's way ([`Scene::batching`]).
    pub fn occluded_each(&self, queries: &[RayQuery], out: &mut [bool]) {
        assert_eq!(queries.len(), out.len(), "one answer per query");
        super::ray_log::record(queries, super::ray_log::LoggedQuery::Occlusion);
        let mut blockers = [None; 64];
        for (queries, out) in queries.chunks(64).zip(out.chunks_mut(64)) {
            let blockers = &mut blockers[..queries.len()];
            self.run::<OcclusionWalk>(queries, blockers, self.batching.occlusion);
            out.iter_mut().zip(blockers.iter()).for_each(|(o, b)| *o = b.is_some());
        }
    }

    /// Leaf index of some triangle blocking the ray (not necessarily the nearest).
    #[inline]
    fn occluder(&self, query: &RayQuery) -> Option<u32> {
        let mut answer = [None];
        self.run::<OcclusionWalk>(std::slice::from_ref(query), &mut answer, BatchMode::OneByOne);
        answer[0]
    }

    /// Answers `queries` with walk `W`, in `mode`, on the fastest node and leaf tests this CPU has.
    #[inline]
    pub(super) fn run<W: QueryWalk>(&self, queries: &[RayQuery], out: &mut [W::Answer], mode: BatchMode) {
        if self.nodes.is_empty() && self.fans.is_none() {
            out.iter_mut().for_each(|o| *o = W::Answer::default());
            return;
        }
        if !queries.iter().all(RayQuery::is_traceable) {
            return self.run_traceable::<W>(queries, out, mode);
        }
        #[cfg(target_arch = "x86_64")]
        if self.traversal == Traversal::Avx2 {
            // SAFETY: `traversal` is Avx2 only when the CPU reported AVX2.
            return unsafe { self.run_avx2::<W>(queries, out, mode) };
        }
        self.run_with::<W, ScalarTest, ScalarLeaf>(queries, out, mode)
    }

    /// [`Scene::run`] for a batch holding rays that cannot be traced: those
    /// answer "no hit" (a NaN ray would enter every box, empty child slots
    /// included, and index past the leaves); the others are walked one at a
    /// time, which gives the same answers as a batch.
    #[cold]
    fn run_traceable<W: QueryWalk>(&self, queries: &[RayQuery], out: &mut [W::Answer], mode: BatchMode) {
        for (query, answer) in queries.iter().zip(out.iter_mut()) {
            if query.is_traceable() {
                self.run::<W>(std::slice::from_ref(query), std::slice::from_mut(answer), mode);
            } else {
                *answer = W::Answer::default();
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn run_avx2<W: QueryWalk>(&self, queries: &[RayQuery], out: &mut [W::Answer], mode: BatchMode) {
        self.run_with::<W, bvh8::Avx2Test, super::leaf_blocks::AvxLeaf>(queries, out, mode)
    }

    #[inline(always)]
    fn run_with<W: QueryWalk, T: NodeTest, Lf: LeafTest>(&self, queries: &[RayQuery], out: &mut [W::Answer], mode: BatchMode) {
        match mode {
            BatchMode::OneByOne => one_by_one::<W, T, Lf>(self, queries, out),
            BatchMode::Interleaved => interleaved::<W, T, Lf>(self, queries, out),
        }
    }

    /// [`Scene::occluded`] with a shadow cache for coherent rays (Haines &
    /// Greenberg's light buffer idea, one entry): the leaf triangle in `hint`
    /// (from the previous call; `u32::MAX` = none) is tested first, and the
    /// leaf that occludes this ray is stored back. Neighbouring rays toward
    /// the same light are usually blocked by the same triangle, so a shadowed
    /// ray often costs one triangle test instead of a walk. Same answer as
    /// [`Scene::occluded`].
    #[inline]
    pub fn occluded_cached(&self, origin: Vec3, direction: Vec3, t_max: f32, hint: &mut u32) -> bool {
        if !(RayQuery { origin, direction, t_max }).is_traceable() {
            return false;
        }
        if (*hint as usize) < self.leaf_triangles.len() {
            let ray = Ray::new(origin.into(), direction.into(), 0.0, hint_reach(t_max));
            if self.leaf_triangles.triangle(*hint).intersect(&ray).is_finite() {
                return true;
            }
        }
        match self.occluder(&RayQuery { origin, direction, t_max }) {
            Some(leaf) => {
                *hint = leaf;
                true
            }
            None => false,
        }
    }
}

/// How much of a finite reach a shadow-cache hint may block within: the
/// hint's triangle skips the box tests, whose entry distances round, so a
/// triangle within rounding of the reach could block a ray the walk finds
/// unblocked. Short of the reach by this fraction, a blocking hint is one
/// the walk finds too, and the answer never depends on the hints.
pub const HINT_MARGIN: f32 = 1e-4;

/// The reach a hint is tested within (infinite stays infinite).
#[inline(always)]
pub fn hint_reach(t_max: f32) -> f32 {
    t_max * (1.0 - HINT_MARGIN)
}

/// Rays walked at once when interleaving: enough that a node fetch is
/// covered by the other walks' steps (2, 4, 8, 16 tried on the cabin: 8 best).
pub const IN_FLIGHT: usize = 8;

/// One query's walk: its state, advanced a step at a time, then its answer.
pub trait QueryWalk {
    type Answer: Default;
    fn new(query: &RayQuery) -> Self;
    /// Starts over for another query, reusing the stack's memory.
    fn restart(&mut self, query: &RayQuery);
    /// One step of the walk; false once it has ended.
    fn step<T: NodeTest, Lf: LeafTest, const INTERLEAVED: bool>(&mut self, scene: &Scene) -> bool;
    fn finish(&self, scene: &Scene) -> Self::Answer;
}

/// Answers every query, one ray after another. The scene must have a tree.
#[inline(always)]
pub fn one_by_one<W: QueryWalk, T: NodeTest, Lf: LeafTest>(scene: &Scene, queries: &[RayQuery], out: &mut [W::Answer]) {
    for (query, answer) in queries.iter().zip(out) {
        let mut walk = W::new(query);
        while walk.step::<T, Lf, false>(scene) {}
        *answer = walk.finish(scene);
    }
}

/// Answers every query, [`IN_FLIGHT`] walks at a time, a step of each in
/// turn; a finished walk's slot takes the next query. The scene must have a tree.
#[inline(always)]
pub fn interleaved<W: QueryWalk, T: NodeTest, Lf: LeafTest>(scene: &Scene, queries: &[RayQuery], out: &mut [W::Answer]) {
    if queries.is_empty() {
        return;
    }
    let mut walks: [W; IN_FLIGHT] = std::array::from_fn(|k| W::new(&queries[k.min(queries.len() - 1)]));
    let mut owner = [0usize; IN_FLIGHT];
    let active_at_start = queries.len().min(IN_FLIGHT);
    for (k, slot) in owner.iter_mut().enumerate().take(active_at_start) {
        *slot = k;
    }
    let (mut active, mut fed) = (active_at_start, active_at_start);
    while active > 0 {
        let mut i = 0;
        while i < active {
            if walks[i].step::<T, Lf, true>(scene) {
                i += 1;
                continue;
            }
            out[owner[i]] = walks[i].finish(scene);
            if fed < queries.len() {
                walks[i].restart(&queries[fed]);
                owner[i] = fed;
                (i, fed) = (i + 1, fed + 1);
            } else {
                active -= 1;
                walks.swap(i, active);
                owner.swap(i, active);
            }
        }
    }
}

/// A closest-hit walk and the best hit it has met.
pub struct ClosestWalk {
    boxes: RayBoxes,
    walk: bvh8::Walk,
    best: ClosestSoFar,
}

struct ClosestSoFar {
    ray: Ray,
    t: f32,
    leaf: u32,
    back: bool,
    mesh: u32,
}

impl ClosestSoFar {
    #[inline(always)]
    fn new(query: &RayQuery) -> ClosestSoFar {
        let ray = query.ray();
        ClosestSoFar { ray, t: f32::INFINITY, leaf: u32::MAX, back: false, mesh: u32::MAX }
    }
}

/// The closest-hit leaf test, for one step of a walk.
struct ClosestLeaves<'a, Lf> {
    scene: &'a Scene,
    best: &'a mut ClosestSoFar,
    test: std::marker::PhantomData<Lf>,
}

impl<Lf: LeafTest> bvh8::Leaves for ClosestLeaves<'_, Lf> {
    #[inline(always)]
    fn block_address(&self, first: u32) -> *const u8 {
        self.scene.leaf_triangles.block_address(first)
    }

    #[inline(always)]
    fn visit(&mut self, first: u32, count: u32, t_max: f32) -> LeafResult {
        let (best, tie) = (&mut *self.best, self.scene.tie_distance);
        #[cfg(test)]
        work::add(u64::from(count));
        let mut reach = t_max;
        let hits = Lf::test_leaf(&self.scene.leaf_triangles, first, count, &best.ray, reach);
        let mut lanes = hits.mask;
        // Lanes in leaf order, each against the reach left by the ones before.
        while lanes != 0 {
            let lane = lanes.trailing_zeros();
            lanes &= lanes - 1;
            let t = hits.t[lane as usize];
            // `ng` of RtTriangle points against the winding normal.
            let back = hits.back >> lane & 1 == 1;
            let leaf = first + lane;
            let mesh_index = self.scene.leaf_to_mesh[leaf as usize];
            let better = if t < best.t - tie {
                true
            } else if t <= best.t + tie {
                // Same surface: prefer the face that looks at the ray, then the lower index.
                (best.back && !back) || (best.back == back && mesh_index < best.mesh)
            } else {
                false
            };
            if better {
                (best.t, best.leaf, best.back, best.mesh) = (t, leaf, back, mesh_index);
                reach = (t + tie).min(best.ray.tmax);
            }
        }
        LeafResult::Continue(reach)
    }
}

impl QueryWalk for ClosestWalk {
    type Answer = Option<Hit>;

    #[inline(always)]
    fn new(query: &RayQuery) -> ClosestWalk {
        let best = ClosestSoFar::new(query);
        ClosestWalk { boxes: RayBoxes::from_ray(&best.ray), walk: bvh8::Walk::new(query.t_max), best }
    }

    #[inline(always)]
    fn restart(&mut self, query: &RayQuery) {
        self.best = ClosestSoFar::new(query);
        self.boxes = RayBoxes::from_ray(&self.best.ray);
        self.walk.restart(query.t_max);
    }

    #[inline(always)]
    fn step<T: NodeTest, Lf: LeafTest, const INTERLEAVED: bool>(&mut self, scene: &Scene) -> bool {
        let mut leaves = ClosestLeaves::<Lf> { scene, best: &mut self.best, test: std::marker::PhantomData };
        let more = !scene.nodes.is_empty() && self.walk.step::<T, _, true, INTERLEAVED>(&scene.nodes, &self.boxes, 0.0, &mut leaves);
        if !more {
            // The box tree done, the fans (if any) within the reach it left.
            if let Some(fans) = &scene.fans {
                let (origin, direction) = (Vec3::from(leaves.best.ray.origin), Vec3::from(leaves.best.ray.direction));
                fans.walk::<T, _, true>(origin, direction, &self.boxes, self.walk.t_max(), &mut leaves);
            }
        }
        more
    }

    #[inline(always)]
    fn finish(&self, scene: &Scene) -> Option<Hit> {
        let best = &self.best;
        if best.leaf == u32::MAX {
            return None;
        }
        let (origin, direction) = (Vec3::from(best.ray.origin), Vec3::from(best.ray.direction));
        let (u, v) = barycentrics(&scene.leaf_triangles.triangle(best.leaf), origin + direction * best.t);
        Some(Hit { triangle: best.mesh, t: best.t, u, v, back_face: best.back })
    }
}

/// An occlusion walk: it ends at the first triangle hit, whichever it is.
pub struct OcclusionWalk {
    ray: Ray,
    boxes: RayBoxes,
    walk: bvh8::Walk,
    /// Leaf-order index of the blocker found.
    found: Option<u32>,
}

/// The occlusion leaf test, for one step of a walk.
struct OcclusionLeaves<'a, Lf> {
    blocks: &'a LeafBlocks,
    ray: &'a Ray,
    found: &'a mut Option<u32>,
    test: std::marker::PhantomData<Lf>,
}

impl<Lf: LeafTest> bvh8::Leaves for OcclusionLeaves<'_, Lf> {
    #[inline(always)]
    fn block_address(&self, first: u32) -> *const u8 {
        self.blocks.block_address(first)
    }

    #[inline(always)]
    fn visit(&mut self, first: u32, count: u32, t_max: f32) -> LeafResult {
        #[cfg(test)]
        work::add(u64::from(count));
        let hits = Lf::test_leaf(self.blocks, first, count, self.ray, t_max);
        if hits.mask != 0 {
            *self.found = Some(first + hits.mask.trailing_zeros());
            return LeafResult::Stop;
        }
        LeafResult::Continue(t_max)
    }
}

impl QueryWalk for OcclusionWalk {
    /// Leaf-order index of some triangle blocking the ray (not necessarily the nearest).
    type Answer = Option<u32>;

    #[inline(always)]
    fn new(query: &RayQuery) -> OcclusionWalk {
        let ray = query.ray();
        OcclusionWalk { ray, boxes: RayBoxes::from_ray(&ray), walk: bvh8::Walk::new(query.t_max), found: None }
    }

    #[inline(always)]
    fn restart(&mut self, query: &RayQuery) {
        self.ray = query.ray();
        self.boxes = RayBoxes::from_ray(&self.ray);
        self.walk.restart(query.t_max);
        self.found = None;
    }

    #[inline(always)]
    fn step<T: NodeTest, Lf: LeafTest, const INTERLEAVED: bool>(&mut self, scene: &Scene) -> bool {
        let mut leaves =
            OcclusionLeaves::<Lf> { blocks: &scene.leaf_triangles, ray: &self.ray, found: &mut self.found, test: std::marker::PhantomData };
        let more = !scene.nodes.is_empty() && self.walk.step::<T, _, false, INTERLEAVED>(&scene.nodes, &self.boxes, 0.0, &mut leaves);
        if !more && leaves.found.is_none() {
            // Nothing blocks the ray in the box tree: the fans (if any).
            if let Some(fans) = &scene.fans {
                let (origin, direction) = (Vec3::from(self.ray.origin), Vec3::from(self.ray.direction));
                fans.walk::<T, _, false>(origin, direction, &self.boxes, self.walk.t_max(), &mut leaves);
            }
        }
        more
    }

    #[inline(always)]
    fn finish(&self, _scene: &Scene) -> Option<u32> {
        self.found
    }
}

/// Barycentric weights (of vertices 1 and 2) of `p`, which lies on `tri`'s plane.
fn barycentrics(tri: &obvhs::rt_triangle::RtTriangle, p: Vec3) -> (f32, f32) {
    // RtTriangle stores v0, e1 = v0 − v1, e2 = v2 − v0.
    let a = Vec3::from(-tri.e1);
    let b = Vec3::from(tri.e2);
    let d = p - Vec3::from(tri.v0);
    let (aa, ab, bb) = (a.dot(a), a.dot(b), b.dot(b));
    let (da, db) = (d.dot(a), d.dot(b));
    let det = aa * bb - ab * ab;
    if det <= 0.0 || !det.is_finite() {
        return (1.0 / 3.0, 1.0 / 3.0);
    }
    let u = ((bb * da - ab * db) / det).clamp(0.0, 1.0);
    let v = ((aa * db - ab * da) / det).clamp(0.0, 1.0 - u);
    (u, v)
}

/// Work the walks on this thread have done: box nodes, fan caps and
/// triangles tested. Tests bound how it grows with a scene (a count, so the
/// bound holds whatever the machine's speed); release builds count nothing.
#[cfg(test)]
pub(crate) mod work {
    use std::cell::Cell;

    thread_local!(static DONE: Cell<u64> = const { Cell::new(0) });
    thread_local!(static NODES: Cell<u64> = const { Cell::new(0) });

    #[inline(always)]
    pub(crate) fn add(n: u64) {
        DONE.with(|done| done.set(done.get() + n));
    }

    /// One box node tested (counted in the work too).
    #[inline(always)]
    pub(crate) fn add_node() {
        add(1);
        NODES.with(|nodes| nodes.set(nodes.get() + 1));
    }

    /// The work done since the last call, on this thread.
    pub(crate) fn take() -> u64 {
        DONE.with(|done| done.replace(0))
    }

    /// The box nodes tested since the last call, on this thread.
    pub(crate) fn take_nodes() -> u64 {
        NODES.with(|nodes| nodes.replace(0))
    }
}
