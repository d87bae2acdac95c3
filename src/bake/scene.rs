//! The ray-tracing layer every pass shares: one CWBVH (obvhs) over the mesh's
//! triangles, with the queries the bake needs: closest hit with barycentrics
//! and facing, and occlusion (first hit ends the walk).
//!
//! Triangles are copied once into BVH leaf order so traversal reads them
//! without the `primitive_indices` indirection (obvhs `cornell_box_cwbvh.rs`).
//!
//! Ties: real CAD models are double-sided (every surface doubled by a twin
//! with opposite winding). Two hits closer than `tie_distance` count as one
//! surface; of those the one facing the ray wins, then the lower mesh index,
//! so the result never depends on traversal order or thread count.

use std::time::{Duration, Instant};

use glam::{UVec2, Vec3, Vec3A};
use obvhs::{
    cwbvh::{builder::build_cwbvh_from_tris, CwBvh},
    ray::Ray,
    rt_triangle::RtTriangle,
    traverse,
    triangle::Triangle,
    BvhBuildParams,
};

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

/// Which BVH build preset to use. `Medium` minimises total bake time on the
/// scenes we measured (the build is < 2% of a bake).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BuildQuality {
    Fast,
    Medium,
}

/// A built acceleration structure over a mesh.
pub struct Scene {
    bvh: CwBvh,
    /// Triangles in BVH leaf order.
    leaf_triangles: Vec<RtTriangle>,
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
        let face_normals = triangles
            .iter()
            .map(|t| Vec3::from((t.v1 - t.v0).cross(t.v2 - t.v0)).normalize_or_zero())
            .collect();
        let params = match quality {
            BuildQuality::Fast => BvhBuildParams::fast_build(),
            BuildQuality::Medium => BvhBuildParams::medium_build(),
        };
        let (bvh, leaf_to_mesh, leaf_triangles) = if triangles.is_empty() {
            (CwBvh::default(), Vec::new(), Vec::new())
        } else {
            let mut bvh = build_cwbvh_from_tris(&triangles, params, &mut Duration::default());
            let leaf_to_mesh = bvh.primitive_indices.clone();
            let leaf_triangles: Vec<RtTriangle> =
                leaf_to_mesh.iter().map(|&i| RtTriangle::from(&triangles[i as usize])).collect();
            // The two arrays every ray walks: back them with huge pages.
            bvh.nodes = super::hugepages::copy_to_huge_pages(&bvh.nodes);
            (bvh, leaf_to_mesh, super::hugepages::copy_to_huge_pages(&leaf_triangles))
        };
        let (lo, hi) = mesh.bounds();
        let diagonal = (hi - lo).length().max(f32::MIN_POSITIVE);
        let max_coordinate = lo.abs().max(hi.abs()).max_element();
        // Offsets: relative to scene size, and never below what f32 can resolve
        // at the largest coordinate (64 ulps), so 1e-3 m and 1e4 m scenes behave alike.
        let ulp_floor = max_coordinate * f32::EPSILON * 64.0;
        let origin_offset = (diagonal * 1e-6).max(ulp_floor);
        Scene {
            bvh,
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

    /// Closest hit along a unit `direction` from `origin` within `(0, t_max]`.
    pub fn closest_hit(&self, origin: Vec3, direction: Vec3, t_max: f32) -> Option<Hit> {
        if self.leaf_triangles.is_empty() {
            return None;
        }
        let ray = Ray::new(origin.into(), direction.into(), 0.0, t_max);
        let mut traverse_ray = ray;
        let mut best_t = f32::INFINITY;
        let mut best_leaf = u32::MAX;
        let mut best_back = false;
        let mut best_mesh = u32::MAX;
        let mut state = self.bvh.new_traversal(ray.direction);
        let mut node;
        let tie = self.tie_distance;
        traverse!(self.bvh, node, state, node.intersect_ray(&traverse_ray, state.oct_inv4), {
            let leaf = state.primitive_id;
            let tri = &self.leaf_triangles[leaf as usize];
            let t = tri.intersect(&traverse_ray);
            if t.is_finite() {
                // `ng` of RtTriangle points against the winding normal.
                let back = tri.ng.dot(ray.direction) < 0.0;
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
                    traverse_ray.tmax = (t + tie).min(ray.tmax);
                }
            }
        });
        if best_leaf == u32::MAX {
            return None;
        }
        let tri = &self.leaf_triangles[best_leaf as usize];
        let (u, v) = barycentrics(tri, origin + direction * best_t);
        Some(Hit { triangle: best_mesh, t: best_t, u, v, back_face: best_back })
    }

    /// True when anything lies along `direction` from `origin` within `(0, t_max]`.
    pub fn occluded(&self, origin: Vec3, direction: Vec3, t_max: f32) -> bool {
        if self.leaf_triangles.is_empty() {
            return false;
        }
        let ray = Ray::new(origin.into(), direction.into(), 0.0, t_max);
        !self.bvh.ray_traverse_miss(ray, |r, leaf| self.leaf_triangles[leaf].intersect(r))
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
        if self.leaf_triangles.is_empty() {
            return false;
        }
        let ray = Ray::new(origin.into(), direction.into(), 0.0, t_max);
        if let Some(tri) = self.leaf_triangles.get(*hint as usize) {
            if tri.intersect(&ray) < ray.tmax {
                return true;
            }
        }
        let mut found = u32::MAX;
        let miss = self.bvh.ray_traverse_miss(ray, |r, leaf| {
            let t = self.leaf_triangles[leaf].intersect(r);
            if t < r.tmax {
                found = leaf as u32;
            }
            t
        });
        if !miss {
            *hint = found;
        }
        !miss
    }

    /// Number of triangles in the BVH.
    pub fn triangle_count(&self) -> usize {
        self.leaf_triangles.len()
    }
}

/// Barycentric weights (of vertices 1 and 2) of `p`, which lies on `tri`'s plane.
fn barycentrics(tri: &RtTriangle, p: Vec3) -> (f32, f32) {
    // RtTriangle stores v0, e1 = v0 − v1, e2 = v2 − v0.
    let v0: Vec3A = tri.v0;
    let a = -tri.e1;
    let b = tri.e2;
    let d = Vec3A::from(p) - v0;
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
