//! Building a [`Scene`]: the binary BVH (SAH or PLOC) collapsed to 8-wide
//! nodes, fans around very high-valence points, triangles copied into leaf
//! blocks, offsets relative to the scene's size, and the way batches run,
//! measured on the scene's own probe rays.

use std::time::{Duration, Instant};

use glam::Vec3;
use obvhs::{
    bvh2::{builder::build_bvh2_from_tris, leaf_collapser::collapse},
    rt_triangle::RtTriangle,
    triangle::Triangle,
    BvhBuildParams,
};

use super::bvh8::{self, Bvh8};
use super::fans::{find_fans, Fans};
use super::leaf_blocks::LeafBlocks;
use super::queries::{ClosestWalk, OcclusionWalk, QueryWalk};
use super::scene::{check_extent, BatchMode, Batching, BuildQuality, RayQuery, Scene, SceneError, Traversal};
use crate::mesh::Mesh;
use crate::sampling;

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

impl Scene {
    /// Builds the BVH over every triangle of `mesh` (degenerate ones included:
    /// they never report a hit). Refuses meshes [`check_extent`] refuses.
    pub fn build(mesh: &Mesh, quality: BuildQuality) -> Result<Scene, SceneError> {
        check_extent(mesh)?;
        super::ray_log::open();
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
        let boxes_nest = bvh8::boxes_nest(&nodes);
        let mut scene = Scene {
            nodes,
            traversal: if bvh8::avx2_available() { Traversal::Avx2 } else { Traversal::Portable },
            batching: Batching { closest_hit: BatchMode::OneByOne, occlusion: BatchMode::OneByOne },
            leaf_triangles,
            leaf_to_mesh,
            fans,
            boxes_nest,
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
}
