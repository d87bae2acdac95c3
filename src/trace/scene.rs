//! The scene every pass traces: one 8-wide BVH over the mesh's triangles
//! (built in [`super::build`], walked by [`super::bvh8`]), its offsets and
//! tie rules, and the types of a query and its hit. The queries themselves
//! (closest hit with barycentrics and facing, occlusion, each with an AVX2
//! and a portable path) are in [`super::queries`].
//!
//! Triangles are copied once into BVH leaf order, a struct-of-arrays block
//! per leaf ([`super::leaf_blocks`]), so a leaf visit is one contiguous read
//! and one SIMD test, without an index indirection.
//!
//! Ties: real CAD models are double-sided (every surface doubled by a twin
//! with opposite winding). Two hits closer than `tie_distance` count as one
//! surface; of those the one facing the ray wins, then the lower mesh index,
//! so the result never depends on traversal order or thread count.

use std::time::Duration;

use glam::Vec3;
use obvhs::{ray::Ray, rt_triangle::RtTriangle};

use super::bvh8::{self, Node8};
use super::fans::Fans;
use super::leaf_blocks::LeafBlocks;

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
    pub(super) traversal: Traversal,
    pub(super) batching: Batching,
    /// Triangles in BVH leaf order, one SoA block per leaf.
    pub(super) leaf_triangles: LeafBlocks,
    /// Leaf order → mesh triangle index (the box tree's leaves, then the fans').
    pub(super) leaf_to_mesh: Vec<u32>,
    /// The triangles around points of very high valence, traced apart ([`super::fans`]).
    pub(super) fans: Option<Fans>,
    /// Every node's child boxes lie inside its own ([`bvh8::boxes_nest`]):
    /// parallel rays may then walk as packets ([`super::packets`]).
    pub(super) boxes_nest: bool,
    /// Unit geometric normals per mesh triangle (zero for degenerate ones).
    pub(super) face_normals: Vec<Vec3>,
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
    /// Unit geometric normal of mesh triangle `t` (counter-clockwise front).
    #[inline]
    pub fn face_normal(&self, t: u32) -> Vec3 {
        self.face_normals[t as usize]
    }

    /// The mesh triangle at leaf position `leaf` (what shadow-cache hints
    /// name), if there is one.
    #[inline]
    pub fn mesh_triangle_of_leaf(&self, leaf: u32) -> Option<u32> {
        self.leaf_to_mesh.get(leaf as usize).copied()
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
