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

use super::bvh8::{self, Bvh8, LeafResult, Node8, NodeTest, RayBoxes, ScalarTest};
use super::leaf_blocks::{LeafBlocks, LeafTest, ScalarLeaf};

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

/// Triangles per BVH leaf at most; the SAH leaf collapse picks smaller
/// leaves where they pay. A leaf of up to eight is one AVX test
/// ([`super::leaf_blocks`]), so 8 measured best on the Ferrari and the
/// cabin (4, 8, 12, 15 tried; docs/performance.md).
const LEAF_TRIANGLES: u32 = 8;
/// Cost of a node visit relative to one triangle test, for the leaf
/// collapse (3, 6, 10, 15 tried with 8-triangle leaves: 6–10 equal, 3 worse).
const NODE_COST: f32 = 6.0;

/// A built acceleration structure over a mesh.
pub struct Scene {
    nodes: Vec<Node8>,
    traversal: Traversal,
    /// Triangles in BVH leaf order, one SoA block per leaf.
    leaf_triangles: LeafBlocks,
    /// Leaf order → mesh triangle index.
    leaf_to_mesh: Vec<u32>,
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
    /// they never report a hit).
    pub fn build(mesh: &Mesh, quality: BuildQuality) -> Scene {
        let start = Instant::now();
        let triangles: Vec<Triangle> = (0..mesh.triangle_count())
            .map(|t| {
                let [a, b, c] = mesh.triangle_positions(t);
                Triangle { v0: a.into(), v1: b.into(), v2: c.into() }
            })
            .collect();
        let face_normals = triangles.iter().map(|t| Vec3::from((t.v1 - t.v0).cross(t.v2 - t.v0)).normalize_or_zero()).collect();
        let (nodes, leaf_to_mesh, leaf_triangles) = if triangles.is_empty() {
            (Vec::new(), Vec::new(), LeafBlocks::new(&[], []))
        } else {
            let mut bvh2 = match quality {
                BuildQuality::Sah => {
                    let boxes: Vec<obvhs::aabb::Aabb> = triangles.iter().map(|t| t.aabb()).collect();
                    super::sah::build_bvh2_sah(&boxes)
                }
                BuildQuality::Ploc => {
                    let params = BvhBuildParams { max_prims_per_leaf: 1, ..BvhBuildParams::medium_build() };
                    build_bvh2_from_tris(&triangles, params, &mut Duration::default())
                }
            };
            collapse(&mut bvh2, LEAF_TRIANGLES, NODE_COST);
            let bvh8 = Bvh8::from_bvh2(&bvh2);
            let in_leaf_order: Vec<RtTriangle> = bvh8.primitive_order.iter().map(|&i| RtTriangle::from(&triangles[i as usize])).collect();
            let blocks = LeafBlocks::new(&in_leaf_order, bvh8.leaves());
            // The two arrays every ray walks (nodes and blocks) sit on huge pages.
            (super::hugepages::copy_to_huge_pages(&bvh8.nodes), bvh8.primitive_order, blocks)
        };
        let (lo, hi) = mesh.bounds();
        let diagonal = (hi - lo).length().max(f32::MIN_POSITIVE);
        let max_coordinate = lo.abs().max(hi.abs()).max_element();
        // Offsets: relative to scene size, and never below what f32 can resolve
        // at the largest coordinate (64 ulps), so 1e-3 m and 1e4 m scenes behave alike.
        let ulp_floor = max_coordinate * f32::EPSILON * 64.0;
        let origin_offset = (diagonal * 1e-6).max(ulp_floor);
        Scene {
            nodes,
            traversal: if bvh8::avx2_available() { Traversal::Avx2 } else { Traversal::Portable },
            leaf_triangles,
            leaf_to_mesh,
            face_normals,
            diagonal,
            max_coordinate,
            tie_distance: origin_offset,
            origin_offset,
            build_time: start.elapsed(),
        }
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

    /// Closest hit along a unit `direction` from `origin` within `(0, t_max]`.
    pub fn closest_hit(&self, origin: Vec3, direction: Vec3, t_max: f32) -> Option<Hit> {
        #[cfg(target_arch = "x86_64")]
        if self.traversal == Traversal::Avx2 {
            // SAFETY: `traversal` is Avx2 only when the CPU reported AVX2.
            return unsafe { self.closest_hit_avx2(origin, direction, t_max) };
        }
        self.closest_hit_with::<ScalarTest, ScalarLeaf>(origin, direction, t_max)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn closest_hit_avx2(&self, origin: Vec3, direction: Vec3, t_max: f32) -> Option<Hit> {
        self.closest_hit_with::<bvh8::Avx2Test, super::leaf_blocks::AvxLeaf>(origin, direction, t_max)
    }

    #[inline(always)]
    fn closest_hit_with<T: NodeTest, Lf: LeafTest>(&self, origin: Vec3, direction: Vec3, t_max: f32) -> Option<Hit> {
        let ray = Ray::new(origin.into(), direction.into(), 0.0, t_max);
        let mut reach = t_max;
        let mut best_t = f32::INFINITY;
        let mut best_leaf = u32::MAX;
        let mut best_back = false;
        let mut best_mesh = u32::MAX;
        let tie = self.tie_distance;
        let blocks = &self.leaf_triangles;
        let prefetch = |first, count| blocks.prefetch(first, count);
        bvh8::walk::<T, true>(&self.nodes, prefetch, &RayBoxes::from_ray(&ray), 0.0, t_max, |first, count, walk_t_max| {
            reach = walk_t_max;
            let hits = Lf::test_leaf(blocks, first, count, &ray, reach);
            let mut lanes = hits.mask;
            // Lanes in leaf order, each against the reach left by the ones before.
            while lanes != 0 {
                let lane = lanes.trailing_zeros();
                lanes &= lanes - 1;
                let t = hits.t[lane as usize];
                // `ng` of RtTriangle points against the winding normal.
                let back = hits.back >> lane & 1 == 1;
                let leaf = first + lane;
                let mesh_index = self.leaf_to_mesh[leaf as usize];
                let better = if t < best_t - tie {
                    true
                } else if t <= best_t + tie {
                    // Same surface: prefer the face that looks at the ray, then the lower index.
                    (best_back && !back) || (best_back == back && mesh_index < best_mesh)
                } else {
                    false
                };
                if better {
                    best_t = t;
                    best_leaf = leaf;
                    best_back = back;
                    best_mesh = mesh_index;
                    reach = (t + tie).min(t_max);
                }
            }
            LeafResult::Continue(reach)
        });
        if best_leaf == u32::MAX {
            return None;
        }
        let (u, v) = barycentrics(&self.leaf_triangles.triangle(best_leaf), origin + direction * best_t);
        Some(Hit { triangle: best_mesh, t: best_t, u, v, back_face: best_back })
    }

    /// True when anything lies along `direction` from `origin` within `(0, t_max]`.
    pub fn occluded(&self, origin: Vec3, direction: Vec3, t_max: f32) -> bool {
        self.occluder(origin, direction, t_max).is_some()
    }

    /// Leaf index of some triangle blocking the ray (not necessarily the nearest).
    #[inline]
    fn occluder(&self, origin: Vec3, direction: Vec3, t_max: f32) -> Option<u32> {
        #[cfg(target_arch = "x86_64")]
        if self.traversal == Traversal::Avx2 {
            // SAFETY: `traversal` is Avx2 only when the CPU reported AVX2.
            return unsafe { self.occluder_avx2(origin, direction, t_max) };
        }
        self.occluder_with::<ScalarTest, ScalarLeaf>(origin, direction, t_max)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn occluder_avx2(&self, origin: Vec3, direction: Vec3, t_max: f32) -> Option<u32> {
        self.occluder_with::<bvh8::Avx2Test, super::leaf_blocks::AvxLeaf>(origin, direction, t_max)
    }

    #[inline(always)]
    fn occluder_with<T: NodeTest, Lf: LeafTest>(&self, origin: Vec3, direction: Vec3, t_max: f32) -> Option<u32> {
        let ray = Ray::new(origin.into(), direction.into(), 0.0, t_max);
        let mut found = None;
        let blocks = &self.leaf_triangles;
        let prefetch = |first, count| blocks.prefetch(first, count);
        bvh8::walk::<T, false>(&self.nodes, prefetch, &RayBoxes::from_ray(&ray), 0.0, t_max, |first, count, _| {
            let hits = Lf::test_leaf(blocks, first, count, &ray, t_max);
            if hits.mask != 0 {
                found = Some(first + hits.mask.trailing_zeros());
                return LeafResult::Stop;
            }
            LeafResult::Continue(t_max)
        });
        found
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
        if (*hint as usize) < self.leaf_triangles.len() {
            let ray = Ray::new(origin.into(), direction.into(), 0.0, t_max);
            if self.leaf_triangles.triangle(*hint).intersect(&ray).is_finite() {
                return true;
            }
        }
        match self.occluder(origin, direction, t_max) {
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

/// Barycentric weights (of vertices 1 and 2) of `p`, which lies on `tri`'s plane.
fn barycentrics(tri: &RtTriangle, p: Vec3) -> (f32, f32) {
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
