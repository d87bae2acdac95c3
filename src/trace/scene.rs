//! The ray-tracing layer every pass shares: one 8-wide BVH over the mesh's
//! triangles (built by obvhs, collapsed and walked by [`super::bvh8`]), with
//! the queries the bake needs: closest hit with barycentrics and facing, and
//! occlusion (first hit ends the walk), each with an AVX2 and a portable path.
//!
//! Triangles are copied once into BVH leaf order, a struct-of-arrays block
//! per leaf ([`super::leaf_blocks`]), so a leaf visit is one contiguous read
//! and one SIMD test, without an index indirection.
//!
//! Ties: real CAD models are double-sided (every surface doubled by a twin
//! with opposite winding). Two hits closer than `tie_distance` count as one
//! surface; of those the one facing the ray wins, then the lower mesh index,
//! so the result never depends on traversal order or thread count.

use std::time::{Duration, Instant};

use glam::Vec3;
use obvhs::{
    bvh2::{builder::build_bvh2_from_tris, leaf_collapser::collapse},
    ray::Ray,
    rt_triangle::RtTriangle,
    triangle::Triangle,
    BvhBuildParams,
};

use super::bvh8::{self, Bvh8, Node8, NodeTest, ScalarTest};
use super::fans::{find_fans, Fans};
use super::leaf_blocks::{LeafBlocks, LeafTest, ScalarLeaf};
use super::queries::{self, ClosestWalk, OcclusionWalk, QueryWalk};
use crate::sampling;

use crate::mesh::Mesh;

/// A closest hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Mesh triangle index.
    pub triangle: u32,
    /// Distance along the (unit) ray direction.
    pub t: f32,
    /// Barycentric weights of the triangle's second and third vertex.
    pub u: f32,
    pub v: f32,
    /// True when the ray hit the triangle's back (the side its winding normal points away from).
    pub back_face: bool,
}

/// Which builder makes the binary BVH that is collapsed to 8-wide nodes.
/// `Sah` minimises total bake time on every scene we measured (the build is
/// < 2% of a bake); `Ploc` is kept for comparison (docs/performance.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BuildQuality {
    /// Top-down binned SAH ([`super::sah`]).
    Sah,
    /// obvhs's bottom-up PLOC with its medium preset (reinsertion on).
    Ploc,
}

/// Which node-test code the walks run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Traversal {
    /// Eight boxes per AVX2 instruction (x86-64 CPUs that have it).
    Avx2,
    /// Plain Rust, any CPU.
    Portable,
}

/// How a batch of queries runs its rays ([`super::queries`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BatchMode {
    #[default]
    /// One ray after another.
    OneByOne,
    /// Several rays at once, a step of each in turn.
    Interleaved,
}

impl std::fmt::Display for BatchMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            BatchMode::OneByOne => "one by one",
            BatchMode::Interleaved => "interleaved",
        })
    }
}

/// How each kind of batched query runs: chosen per scene by measuring
/// both on probe rays when the scene is built (answers are the same either way).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Batching {
    pub closest_hit: BatchMode,
    pub occlusion: BatchMode,
}

/// Trees smaller than this (nodes and leaf blocks) stay in cache and are
/// never measured for interleaving.
const INTERLEAVE_MIN_TREE_BYTES: usize = 4 << 20;
/// Interleaving is kept only when its best probe time is below this
/// fraction of one-by-one's: a near tie keeps the simpler way.
const INTERLEAVE_MIN_GAIN: f64 = 0.95;

/// Triangles per BVH leaf at most; the SAH leaf collapse picks smaller
/// leaves where they pay. A leaf of up to eight is one AVX test
/// ([`super::leaf_blocks`]), so 8 measured best on the Ferrari and the
/// cabin (4, 8, 12, 15 tried; docs/performance.md).
const LEAF_TRIANGLES: u32 = 8;
/// Cost of a node visit relative to one triangle test, for the leaf
/// collapse (3, 6, 10, 15 tried with 8-triangle leaves: 6–10 equal, 3 worse).
const NODE_COST: f32 = 6.0;

/// Largest bounding-box diagonal a scene may have. The bake works in f32,
/// and the largest value it forms is the squared length of an edge cross
/// product (normalised for face normals and areas), which grows as the
/// fourth power of the extent D: at D = 1e9 it is at most 1e36, 340× below
/// f32::MAX (it overflows from about 4.3e9 on, where a flat plane silently
/// baked to zero before this limit). The ray–triangle distance (≤ 3·D³) and
/// the areas (≤ D²) stay further below. Larger scenes are refused, never
/// traced with infinities.
pub const MAX_SCENE_EXTENT: f32 = 1e9;

/// Why a mesh cannot be traced.
#[derive(Debug, PartialEq, thiserror::Error)]
pub enum SceneError {
    #[error("vertex {vertex} has a non-finite coordinate {position}")]
    NonFiniteCoordinate { vertex: usize, position: Vec3 },
    #[error(
        "coordinates up to {max_coordinate:.1e} and a bounding-box diagonal of {extent:.1e}: beyond the {MAX_SCENE_EXTENT:.0e} the baker's \
         single-precision geometry handles without overflow; rescale the model"
    )]
    ExtentTooLarge { max_coordinate: f64, extent: f64 },
}

/// Refuses a mesh whose coordinates are not finite or whose extent exceeds
/// [`MAX_SCENE_EXTENT`]. The extent is measured in f64, where it cannot overflow.
pub fn check_extent(mesh: &Mesh) -> Result<(), SceneError> {
    if let Some(vertex) = mesh.positions.iter().position(|p| !p.is_finite()) {
        return Err(SceneError::NonFiniteCoordinate { vertex, position: mesh.positions[vertex] });
    }
    let (lo, hi) = mesh.bounds();
    let extent = (hi.as_dvec3() - lo.as_dvec3()).length();
    if extent > f64::from(MAX_SCENE_EXTENT) {
        let max_coordinate = lo.as_dvec3().abs().max(hi.as_dvec3().abs()).max_element();
        return Err(SceneError::ExtentTooLarge { max_coordinate, extent });
    }
    Ok(())
}

/// A built acceleration structure over a mesh.
pub struct Scene {
    pub(super) nodes: Vec<Node8>,
    traversal: Traversal,
    batching: Batching,
    /// Triangles in BVH leaf order, one SoA block per leaf.
    pub(super) leaf_triangles: LeafBlocks,
    /// Leaf order → mesh triangle index (the box tree's leaves, then the fans').
    pub(super) leaf_to_mesh: Vec<u32>,
    /// The triangles around points of very high valence, traced apart ([`super::fans`]).
    pub(super) fans: Option<Fans>,
    /// Unit geometric normals per mesh triangle (zero for degenerate ones).
    face_normals: Vec<Vec3>,
    /// Bounding-box diagonal of the mesh: every epsilon is relative to it.
    pub diagonal: f32,
    /// Largest absolute coordinate, for offsets that must survive f32 rounding.
    pub max_coordinate: f32,
    /// Hits closer together than this are treated as one surface (coincident twins).
    pub tie_distance: f32,
    /// Distance a ray origin is pushed off its surface.
    pub origin_offset: f32,
    /// Time the BVH build took.
    pub build_time: Duration,
}

impl Scene {
    /// Builds the BVH over every triangle of `mesh` (degenerate ones included:
    /// they never report a hit). Refuses meshes [`check_extent`] refuses.
    pub fn build(mesh: &Mesh, quality: BuildQuality) -> Result<Scene, SceneError> {
        check_extent(mesh)?;
        let start = Instant::now();
        let triangles: Vec<Triangle> = (0..mesh.triangle_count())
            .map(|t| {
                let [a, b, c] = mesh.triangle_positions(t);
                Triangle { v0: a.into(), v1: b.into(), v2: c.into() }
            })
            .collect();
        let face_normals = triangles.iter().map(|t| Vec3::from((t.v1 - t.v0).cross(t.v2 - t.v0)).normalize_or_zero()).collect();
        let (lo, hi) = mesh.bounds();
        let diagonal = (hi - lo).length().max(f32::MIN_POSITIVE);
        let max_coordinate = lo.abs().max(hi.abs()).max_element();
        // Triangles around a point of very high valence are traced as fans;
        // the box tree holds the others (all of them in an ordinary mesh).
        let fan_plan = find_fans(mesh);
        let boxed: Vec<u32> = match &fan_plan {
            Some(plan) => (0..triangles.len() as u32).filter(|&t| !plan.in_fan[t as usize]).collect(),
            None => (0..triangles.len() as u32).collect(),
        };
        let (nodes, mut leaf_to_mesh, mut leaves) = if boxed.is_empty() {
            (Vec::new(), Vec::new(), Vec::new())
        } else {
            let boxed_triangles: Vec<Triangle> = boxed.iter().map(|&t| triangles[t as usize]).collect();
            let mut bvh2 = match quality {
                BuildQuality::Sah => {
                    let boxes: Vec<obvhs::aabb::Aabb> = boxed_triangles.iter().map(|t| t.aabb()).collect();
                    super::sah::build_bvh2_sah(&boxes)
                }
                BuildQuality::Ploc => {
                    let params = BvhBuildParams { max_prims_per_leaf: 1, ..BvhBuildParams::medium_build() };
                    build_bvh2_from_tris(&boxed_triangles, params, &mut Duration::default())
                }
            };
            collapse(&mut bvh2, LEAF_TRIANGLES, NODE_COST);
            let bvh8 = Bvh8::from_bvh2(&bvh2);
            let leaves: Vec<(u32, u32)> = bvh8.leaves().collect();
            let leaf_to_mesh = bvh8.primitive_order.iter().map(|&i| boxed[i as usize]).collect();
            // The array every ray walks first sits on huge pages (the blocks too, below).
            (super::hugepages::copy_to_huge_pages(&bvh8.nodes), leaf_to_mesh, leaves)
        };
        let fans = fan_plan.map(|plan| Fans::build(plan, mesh, diagonal.max(max_coordinate), &mut leaf_to_mesh, &mut leaves));
        let in_leaf_order: Vec<RtTriangle> = leaf_to_mesh.iter().map(|&t| RtTriangle::from(&triangles[t as usize])).collect();
        let leaf_triangles = LeafBlocks::new(&in_leaf_order, leaves);
        // Offsets: relative to scene size, and never below what f32 can resolve
        // at the largest coordinate (64 ulps), so 1e-3 m and 1e4 m scenes behave alike.
        let ulp_floor = max_coordinate * f32::EPSILON * 64.0;
        let origin_offset = (diagonal * 1e-6).max(ulp_floor);
        let mut scene = Scene {
            nodes,
            traversal: if bvh8::avx2_available() { Traversal::Avx2 } else { Traversal::Portable },
            batching: Batching { closest_hit: BatchMode::OneByOne, occlusion: BatchMode::OneByOne },
            leaf_triangles,
            leaf_to_mesh,
            fans,
            face_normals,
            diagonal,
            max_coordinate,
            tie_distance: origin_offset,
            origin_offset,
            build_time: Duration::ZERO,
        };
        scene.batching = scene.measure_batching(mesh);
        scene.build_time = start.elapsed();
        Ok(scene)
    }

    /// The scene's geometry (face normals, diagonal, offsets) without a BVH,
    /// for passes that only gather from recorded hits (a sharded bake's
    /// rounds ≥ 1): building the BVH would be most of their time. A ray
    /// traced in it hits nothing.
    pub fn without_bvh(mesh: &Mesh) -> Result<Scene, SceneError> {
        check_extent(mesh)?;
        let empty = Mesh {
            positions: mesh.positions.clone(),
            indices: Vec::new(),
            tri_material: Vec::new(),
            tri_group: Vec::new(),
            materials: mesh.materials.clone(),
            ..Mesh::default()
        };
        let mut scene = Scene::build(&empty, BuildQuality::Sah)?;
        // The same arithmetic as `build`'s, so gathers see the same bits.
        scene.face_normals = (0..mesh.triangle_count())
            .map(|t| {
                let [a, b, c] = mesh.triangle_positions(t);
                let t = Triangle { v0: a.into(), v1: b.into(), v2: c.into() };
                Vec3::from((t.v1 - t.v0).cross(t.v2 - t.v0)).normalize_or_zero()
            })
            .collect();
        Ok(scene)
    }

    /// Unit geometric normal of mesh triangle `t` (counter-clockwise front).
    #[inline]
    pub fn face_normal(&self, t: u32) -> Vec3 {
        self.face_normals[t as usize]
    }

    /// Moves `point` off the surface with geometric normal `face_normal` toward
    /// the side `direction` leaves from, so a ray cannot stop on its own
    /// surface or on a coincident twin of it.
    #[inline]
    pub fn offset_origin(&self, point: Vec3, face_normal: Vec3, direction: Vec3) -> Vec3 {
        let side = if face_normal.dot(direction) >= 0.0 { 1.0 } else { -1.0 };
        point + face_normal * (side * self.origin_offset)
    }

    /// The node-test code the queries run.
    pub fn traversal(&self) -> Traversal {
        self.traversal
    }

    /// Chooses the node-test code (tests compare both paths). Asking for AVX2
    /// on a CPU without it keeps the portable path; returns what is in use.
    pub fn set_traversal(&mut self, traversal: Traversal) -> Traversal {
        self.traversal = if traversal == Traversal::Avx2 && !bvh8::avx2_available() { Traversal::Portable } else { traversal };
        self.traversal
    }

    /// How [`Scene::closest_hits`] and [`Scene::occluded_each`] run their rays
    /// (measured when the scene was built).
    pub fn batching(&self) -> Batching {
        self.batching
    }

    /// Chooses how batches run (tests and benchmarks compare both; the
    /// answers are the same).
    pub fn set_batching(&mut self, batching: Batching) {
        self.batching = batching;
    }

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
    fn run<W: QueryWalk>(&self, queries: &[RayQuery], out: &mut [W::Answer], mode: BatchMode) {
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
            BatchMode::OneByOne => queries::one_by_one::<W, T, Lf>(self, queries, out),
            BatchMode::Interleaved => queries::interleaved::<W, T, Lf>(self, queries, out),
        }
    }

    /// Times both ways of running a batch on probe rays like the bake's (a
    /// point's 64 rays over the sphere from triangles spread over the mesh),
    /// the best of four alternating rounds each, and keeps interleaving only
    /// where it is clearly faster. Trees under 4 MiB stay one by one: they
    /// stay in cache, where nothing waits on memory.
    fn measure_batching(&self, mesh: &Mesh) -> Batching {
        // `PRTBAKE_BATCHING=one_by_one|interleaved` forces a way, for measurements.
        match std::env::var("PRTBAKE_BATCHING").as_deref() {
            Ok("one_by_one") => return Batching { closest_hit: BatchMode::OneByOne, occlusion: BatchMode::OneByOne },
            Ok("interleaved") => return Batching { closest_hit: BatchMode::Interleaved, occlusion: BatchMode::Interleaved },
            _ => {}
        }
        let tree_bytes = std::mem::size_of_val(self.nodes.as_slice()) + self.leaf_triangles.len() * 4 * super::leaf_blocks::ROWS;
        if tree_bytes < INTERLEAVE_MIN_TREE_BYTES {
            return Batching { closest_hit: BatchMode::OneByOne, occlusion: BatchMode::OneByOne };
        }
        const POINTS: u32 = 64;
        const RAYS: u32 = 64;
        let count = self.face_normals.len() as u32;
        let mut queries = Vec::new();
        for p in 0..POINTS {
            let t = (u64::from(p) * u64::from(count) / u64::from(POINTS)) as u32;
            let normal = self.face_normal(t);
            if normal == Vec3::ZERO {
                continue;
            }
            let [a, b, c] = mesh.triangle_positions(t as usize);
            let centroid = (a + b + c) / 3.0;
            for k in 0..RAYS {
                let (u1, u2) = sampling::sample_2d(sampling::DirectionPattern::Sobol, k, 0, p);
                let direction = sampling::cosine_sphere(normal, u1, u2);
                queries.push(RayQuery { origin: self.offset_origin(centroid, normal, direction), direction, t_max: f32::INFINITY });
            }
        }
        // Best of four alternating rounds each way, a point's rays per batch.
        fn faster<W: QueryWalk>(scene: &Scene, queries: &[RayQuery]) -> BatchMode {
            let mut best = [f64::INFINITY; 2];
            let mut out: Vec<W::Answer> = (0..RAYS).map(|_| W::Answer::default()).collect();
            for round in 0..4 {
                for which in [round % 2, 1 - round % 2] {
                    let mode = [BatchMode::OneByOne, BatchMode::Interleaved][which];
                    let start = Instant::now();
                    for chunk in queries.chunks(RAYS as usize) {
                        scene.run::<W>(chunk, &mut out[..chunk.len()], mode);
                    }
                    std::hint::black_box(&out);
                    best[which] = best[which].min(start.elapsed().as_secs_f64());
                }
            }
            if best[1] < INTERLEAVE_MIN_GAIN * best[0] {
                BatchMode::Interleaved
            } else {
                BatchMode::OneByOne
            }
        }
        let closest_hit = faster::<ClosestWalk>(self, &queries);
        let occlusion = faster::<OcclusionWalk>(self, &queries);
        Batching { closest_hit, occlusion }
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
            let ray = Ray::new(origin.into(), direction.into(), 0.0, t_max);
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

    /// Number of triangles in the BVH.
    pub fn triangle_count(&self) -> usize {
        self.leaf_triangles.len()
    }
}

/// One ray of a batched query: a unit `direction` from `origin`, hits within `(0, t_max]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayQuery {
    pub origin: Vec3,
    pub direction: Vec3,
    pub t_max: f32,
}

impl RayQuery {
    /// A finite origin and direction and a reach that is not NaN: what the
    /// walks need to stay inside the tree (answers are "no hit" otherwise).
    #[inline(always)]
    pub fn is_traceable(&self) -> bool {
        self.origin.is_finite() && self.direction.is_finite() && !self.t_max.is_nan()
    }

    /// The query as obvhs's ray (which holds the inverse direction the box test uses).
    #[inline(always)]
    pub fn ray(&self) -> Ray {
        Ray::new(self.origin.into(), self.direction.into(), 0.0, self.t_max)
    }
}

/// Brute-force closest hit and occlusion over every triangle: the oracle the
/// BVH paths are tested against.
pub fn brute_force_closest(mesh: &Mesh, origin: Vec3, direction: Vec3, t_max: f32) -> Option<(u32, f32)> {
    let ray = Ray::new(origin.into(), direction.into(), 0.0, t_max);
    let mut best: Option<(u32, f32)> = None;
    for t in 0..mesh.triangle_count() {
        let [a, b, c] = mesh.triangle_positions(t);
        let tri = RtTriangle::new(a.into(), b.into(), c.into());
        let d = tri.intersect(&ray);
        if d.is_finite() && best.is_none_or(|(_, bd)| d < bd) {
            best = Some((t as u32, d));
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::{bake_mesh, BakeError, BakeParams, Mode};
    use crate::verify::{shapes, Y00};

    /// A 4 × 4 plane under a sphere of radius 0.5: shadows and a bounce.
    fn plane_under_sphere() -> Mesh {
        let mut mesh = shapes::plane_grid(16, 4.0);
        let mut sphere = shapes::icosphere(2);
        shapes::transform(&mut sphere, 0.5, Vec3::new(0.0, 1.0, 0.0));
        shapes::append(&mut mesh, &sphere);
        mesh
    }

    fn scaled(mesh: &Mesh, scale: f32) -> Mesh {
        let mut mesh = mesh.clone();
        shapes::transform(&mut mesh, scale, Vec3::ZERO);
        mesh
    }

    /// The largest power of two that keeps `mesh`'s diagonal within the limit.
    fn scale_to_limit(mesh: &Mesh) -> f32 {
        let mut scale = 1.0f32;
        while mesh.diagonal() * scale * 2.0 <= MAX_SCENE_EXTENT {
            scale *= 2.0;
        }
        scale
    }

    /// Scaling by a power of two is exact in f32 and every epsilon of the
    /// bake is relative to the scene, so a scene scaled up to the extent
    /// limit bakes the same bits as at unit scale: no product overflows on
    /// the way (open mode with a bounce; window mode sampling the glass,
    /// whose weights divide areas by squared distances).
    #[test]
    fn scenes_up_to_the_extent_limit_bake_the_same_bits_as_at_unit_scale() {
        let open = BakeParams { rays: 64, bounces: 1, store_bounces: true, ..BakeParams::default() };
        let (sphere, _) = shapes::integrating_sphere(2, 0.5, 0.6, shapes::Opening::Window);
        let window = BakeParams { rays: 64, bounces: 1, mode: Mode::Window, window_sampling: true, ..BakeParams::default() };
        for (mesh, params) in [(plane_under_sphere(), open), (sphere, window)] {
            let big = scaled(&mesh, scale_to_limit(&mesh));
            assert!(big.diagonal() > MAX_SCENE_EXTENT / 2.0 && big.diagonal() <= MAX_SCENE_EXTENT, "{}", big.diagonal());
            let unit = bake_mesh(&mesh, &params, &[]).unwrap().0;
            let at_limit = bake_mesh(&big, &params, &[]).unwrap().0;
            assert!(unit.total.iter().any(|&t| t != 0.0));
            assert_eq!(unit.total, at_limit.total, "{:?} bake at diagonal {:.2e}", params.mode, big.diagonal());
            assert_eq!(unit.bounces, at_limit.bounces);
            assert_eq!(unit.stats.points_rejected, at_limit.stats.points_rejected);
        }
    }

    /// Closed form at the limit: on a plane open to the sky every ray
    /// escapes, so every vertex's DC transfer is y00 (the cosine-weighted
    /// hemisphere integrates to π, which the 1/π of the transfer cancels).
    #[test]
    fn an_open_plane_at_the_extent_limit_sees_the_whole_sky() {
        let plane = scaled(&shapes::plane_grid(8, 1.0), 0.7 * MAX_SCENE_EXTENT);
        let (result, _, _) = bake_mesh(&plane, &BakeParams { rays: 64, ..BakeParams::default() }, &[]).unwrap();
        assert_eq!(result.stats.points_rejected, 0);
        for v in 0..plane.vertex_count() {
            let dc = result.coefficients(v, 0)[0] as f64;
            assert!((dc - Y00).abs() < 1e-5, "vertex {v}: DC {dc}, expected {Y00}");
        }
    }

    /// Past the limit (1e10, where an edge cross product's squared length
    /// overflows and a plane once baked to zero; 1e20; 1e30) the scene is
    /// refused with a message naming its size and the fix.
    #[test]
    fn scenes_past_the_extent_limit_are_refused_with_the_documented_message() {
        for (half_size, shown) in [(1e10f32, "1.0e10"), (1e20, "1.0e20"), (1e30, "1.0e30")] {
            let plane = scaled(&shapes::plane_grid(1, 1.0), 2.0 * half_size);
            let Err(refused) = Scene::build(&plane, BuildQuality::Sah) else { panic!("{half_size:e} was traced") };
            assert!(matches!(refused, SceneError::ExtentTooLarge { .. }));
            let message = refused.to_string();
            assert!(message.contains(&format!("coordinates up to {shown}")), "{message}");
            assert!(
                message.contains("beyond the 1e9 the baker's single-precision geometry") && message.contains("rescale the model"),
                "{message}"
            );
            let baked = bake_mesh(&plane, &BakeParams { rays: 8, ..BakeParams::default() }, &[]);
            assert!(matches!(baked, Err(BakeError::Scene(SceneError::ExtentTooLarge { .. }))));
        }
        // Just under the limit is traced.
        let at_limit = scaled(&shapes::plane_grid(1, 1.0), 0.9999 * MAX_SCENE_EXTENT / 2f32.sqrt());
        assert!(at_limit.diagonal() > 0.999 * MAX_SCENE_EXTENT && at_limit.diagonal() <= MAX_SCENE_EXTENT);
        assert!(Scene::build(&at_limit, BuildQuality::Sah).is_ok());
    }

    #[test]
    fn non_finite_coordinates_are_refused() {
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let mut plane = shapes::plane_grid(2, 1.0);
            plane.positions[4].y = bad;
            let message = Scene::build(&plane, BuildQuality::Sah).err().expect("refused").to_string();
            assert!(message.contains("vertex 4 has a non-finite coordinate"), "{message}");
        }
    }

    /// A ray with a NaN or infinite origin or direction, or a NaN reach,
    /// answers "no hit" on every path (a NaN ray enters every box, empty
    /// child slots too, whose references decode past the leaves), and does
    /// not change the answers of the rays batched with it.
    #[test]
    fn untraceable_rays_answer_no_hit_on_every_path() {
        let mut scene = Scene::build(&shapes::plane_grid(4, 2.0), BuildQuality::Sah).unwrap();
        let good = RayQuery { origin: Vec3::new(0.1, 1.0, 0.2), direction: -Vec3::Y, t_max: f32::INFINITY };
        let bad = [
            RayQuery { origin: Vec3::NAN, ..good },
            RayQuery { origin: Vec3::new(f32::INFINITY, 1.0, 0.0), ..good },
            RayQuery { direction: Vec3::new(0.0, f32::NAN, 0.0), ..good },
            RayQuery { direction: Vec3::new(0.0, f32::NEG_INFINITY, 0.0), ..good },
            RayQuery { t_max: f32::NAN, ..good },
        ];
        let expected = scene.closest_hit(good.origin, good.direction, good.t_max);
        assert!(expected.is_some());
        let batch: Vec<RayQuery> = bad.iter().flat_map(|&b| [good, b]).collect();
        for traversal in [Traversal::Avx2, Traversal::Portable] {
            scene.set_traversal(traversal);
            for mode in [BatchMode::OneByOne, BatchMode::Interleaved] {
                scene.set_batching(Batching { closest_hit: mode, occlusion: mode });
                for q in &bad {
                    assert_eq!(scene.closest_hit(q.origin, q.direction, q.t_max), None, "{q:?}");
                    assert!(!scene.occluded(q.origin, q.direction, q.t_max), "{q:?}");
                    let mut hint = 0;
                    assert!(!scene.occluded_cached(q.origin, q.direction, q.t_max, &mut hint), "{q:?}");
                }
                let mut hits = vec![None; batch.len()];
                scene.closest_hits(&batch, &mut hits);
                let mut blocked = vec![false; batch.len()];
                scene.occluded_each(&batch, &mut blocked);
                for (k, (hit, blocked)) in hits.iter().zip(&blocked).enumerate() {
                    assert_eq!(*hit, if k % 2 == 0 { expected } else { None }, "ray {k}, {mode}");
                    assert_eq!(*blocked, k % 2 == 0, "ray {k}, {mode}");
                }
            }
        }
    }
}
