//! The working mesh every clean-up step edits: attribute vertices over shared points.
//!
//! Two levels of identity, as in meshoptimizer's remap tables:
//! - a **point** is a position; every topological question (edges, boundaries,
//!   duplicates, orientation) is asked on points, so a hard edge (two vertices
//!   at one position with different normals) is still a shared edge;
//! - a **vertex** carries the attributes (normal, UV, colour) and a point id.
//!
//! Triangles index vertices; a triangle's points are `vertex_point` of its corners.
//! Point ids and vertex ids grow only by appending, so "lower id" means "older",
//! which the steps use as their deterministic keep-rule.

use glam::{DVec3, Vec2, Vec3};

/// Mutable mesh state shared by the clean-up steps.
#[derive(Clone, Debug, Default)]
pub(crate) struct Work {
    /// Positions, indexed by point id.
    pub points: Vec<Vec3>,
    /// Point id of each vertex.
    pub vertex_point: Vec<u32>,
    pub normals: Vec<Vec3>,
    /// Empty when the input has no UVs.
    pub uvs: Vec<Vec2>,
    /// Empty when the input has no lightmap atlas (`TEXCOORD_1`).
    pub lightmap_uvs: Vec<Vec2>,
    /// Empty when the input has no colours.
    pub colors: Vec<[f32; 3]>,
    /// Triangles as vertex-id triples, counter-clockwise front.
    pub tris: Vec<[u32; 3]>,
    pub tri_material: Vec<u16>,
    pub tri_group: Vec<u32>,
    /// Input triangle each triangle descends from (for reports).
    pub tri_origin: Vec<u32>,
    /// False once a step removed the triangle; [`Work::compact_triangles`] drops them.
    pub tri_alive: Vec<bool>,
}

impl Work {
    /// The point ids of triangle `t`.
    #[inline]
    pub fn tri_points(&self, t: usize) -> [u32; 3] {
        let [a, b, c] = self.tris[t];
        [self.vertex_point[a as usize], self.vertex_point[b as usize], self.vertex_point[c as usize]]
    }

    /// The corner positions of triangle `t`.
    #[inline]
    pub fn tri_positions(&self, t: usize) -> [Vec3; 3] {
        let [a, b, c] = self.tri_points(t);
        [self.points[a as usize], self.points[b as usize], self.points[c as usize]]
    }

    /// Twice the area vector of triangle `t` (cross product of two edges), in f64.
    pub fn tri_cross(&self, t: usize) -> DVec3 {
        let [a, b, c] = self.tri_positions(t).map(|p| p.as_dvec3());
        (b - a).cross(c - a)
    }

    /// Area of triangle `t`.
    pub fn tri_area(&self, t: usize) -> f64 {
        0.5 * self.tri_cross(t).length()
    }

    /// Sum of the areas of the live triangles.
    pub fn total_area(&self) -> f64 {
        (0..self.tris.len()).filter(|&t| self.tri_alive[t]).map(|t| self.tri_area(t)).sum()
    }

    /// Appends a point and returns its id.
    pub fn push_point(&mut self, p: Vec3) -> u32 {
        self.points.push(p);
        (self.points.len() - 1) as u32
    }

    /// Appends a vertex whose attributes are interpolated from vertices `a` and `b`
    /// at parameter `t` (0 gives `a`), placed at `point`; returns its id.
    /// The normal is renormalised (left zero when the blend cancels).
    pub fn push_vertex_lerp(&mut self, a: u32, b: u32, t: f32, point: u32) -> u32 {
        let (a, b) = (a as usize, b as usize);
        let n = self.normals[a].lerp(self.normals[b], t);
        self.normals.push(n.normalize_or_zero());
        if !self.uvs.is_empty() {
            let uv = self.uvs[a].lerp(self.uvs[b], t);
            self.uvs.push(uv);
        }
        if !self.lightmap_uvs.is_empty() {
            let uv = self.lightmap_uvs[a].lerp(self.lightmap_uvs[b], t);
            self.lightmap_uvs.push(uv);
        }
        if !self.colors.is_empty() {
            let (ca, cb) = (self.colors[a], self.colors[b]);
            self.colors.push([0, 1, 2].map(|i| ca[i] + (cb[i] - ca[i]) * t));
        }
        self.vertex_point.push(point);
        (self.vertex_point.len() - 1) as u32
    }

    /// Appends a vertex whose attributes are the blend of vertices `v` with
    /// barycentric weights `w`, placed at `point`; returns its id. The normal is
    /// renormalised (left zero when the blend cancels).
    pub fn push_vertex_bary(&mut self, v: [u32; 3], w: [f32; 3], point: u32) -> u32 {
        let v = v.map(|x| x as usize);
        let n = self.normals[v[0]] * w[0] + self.normals[v[1]] * w[1] + self.normals[v[2]] * w[2];
        self.normals.push(n.normalize_or_zero());
        if !self.uvs.is_empty() {
            let uv = self.uvs[v[0]] * w[0] + self.uvs[v[1]] * w[1] + self.uvs[v[2]] * w[2];
            self.uvs.push(uv);
        }
        if !self.lightmap_uvs.is_empty() {
            let uv = self.lightmap_uvs[v[0]] * w[0] + self.lightmap_uvs[v[1]] * w[1] + self.lightmap_uvs[v[2]] * w[2];
            self.lightmap_uvs.push(uv);
        }
        if !self.colors.is_empty() {
            let c = [0, 1, 2].map(|i| self.colors[v[0]][i] * w[0] + self.colors[v[1]][i] * w[1] + self.colors[v[2]][i] * w[2]);
            self.colors.push(c);
        }
        self.vertex_point.push(point);
        (self.vertex_point.len() - 1) as u32
    }

    /// Appends a copy of vertex `v` (same point and attributes); returns its id.
    pub fn push_vertex_copy(&mut self, v: u32) -> u32 {
        let v = v as usize;
        self.normals.push(self.normals[v]);
        if !self.uvs.is_empty() {
            self.uvs.push(self.uvs[v]);
        }
        if !self.lightmap_uvs.is_empty() {
            self.lightmap_uvs.push(self.lightmap_uvs[v]);
        }
        if !self.colors.is_empty() {
            self.colors.push(self.colors[v]);
        }
        self.vertex_point.push(self.vertex_point[v]);
        (self.vertex_point.len() - 1) as u32
    }

    /// Appends a triangle that inherits material, group and origin from triangle `parent`.
    pub fn push_tri_like(&mut self, tri: [u32; 3], parent: usize) {
        self.tris.push(tri);
        self.tri_material.push(self.tri_material[parent]);
        self.tri_group.push(self.tri_group[parent]);
        self.tri_origin.push(self.tri_origin[parent]);
        self.tri_alive.push(true);
    }

    /// Drops removed triangles, keeping the order of the others.
    pub fn compact_triangles(&mut self) {
        let keep: Vec<usize> = (0..self.tris.len()).filter(|&t| self.tri_alive[t]).collect();
        self.tris = keep.iter().map(|&t| self.tris[t]).collect();
        self.tri_material = keep.iter().map(|&t| self.tri_material[t]).collect();
        self.tri_group = keep.iter().map(|&t| self.tri_group[t]).collect();
        self.tri_origin = keep.iter().map(|&t| self.tri_origin[t]).collect();
        self.tri_alive = vec![true; self.tris.len()];
    }

    /// Rewrites every vertex's point id through `point_remap` (meshoptimizer's remap step).
    pub fn remap_points(&mut self, point_remap: &[u32]) {
        for p in &mut self.vertex_point {
            *p = point_remap[*p as usize];
        }
    }

    /// Rewrites every triangle corner through `vertex_remap`.
    pub fn remap_vertices(&mut self, vertex_remap: &[u32]) {
        for tri in &mut self.tris {
            *tri = tri.map(|v| vertex_remap[v as usize]);
        }
    }
}

/// A triangle's corner positions as bits, sorted: what it is, whatever its
/// ids or corner order (to tell triangles one step made from those it kept).
pub(crate) fn corner_key(corners: [Vec3; 3]) -> [[u32; 3]; 3] {
    let mut k = corners.map(|p| p.to_array().map(f32::to_bits));
    k.sort_unstable();
    k
}

/// Interior angles (radians) of a triangle at its three corners; zero for a corner
/// with a zero-length side.
pub(crate) fn triangle_angles(p: [DVec3; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| {
        let e1 = p[(i + 1) % 3] - p[i];
        let e2 = p[(i + 2) % 3] - p[i];
        let (l1, l2) = (e1.length(), e2.length());
        if l1 == 0.0 || l2 == 0.0 {
            return 0.0;
        }
        (e1.dot(e2) / (l1 * l2)).clamp(-1.0, 1.0).acos()
    })
}

/// The smallest interior angle of a triangle, in radians.
pub(crate) fn min_angle(p: [DVec3; 3]) -> f64 {
    let a = triangle_angles(p);
    a[0].min(a[1]).min(a[2])
}

/// Point-topology edges of the live triangles, sorted: `(lo, hi, triangle, corner)`
/// where the edge runs from corner `corner` to corner `corner + 1` and `lo < hi`
/// are its point ids. Edges with a collapsed end (`lo == hi`) are skipped.
pub(crate) fn sorted_edges(work: &Work) -> Vec<EdgeUse> {
    let mut edges = Vec::with_capacity(work.tris.len() * 3);
    for t in 0..work.tris.len() {
        if !work.tri_alive[t] {
            continue;
        }
        let p = work.tri_points(t);
        for corner in 0..3 {
            let (a, b) = (p[corner], p[(corner + 1) % 3]);
            if a != b {
                edges.push(EdgeUse { lo: a.min(b), hi: a.max(b), tri: t as u32, corner: corner as u8, forward: a < b });
            }
        }
    }
    edges.sort_unstable_by_key(|e| (e.lo, e.hi, e.tri, e.corner));
    edges
}

/// One use of an undirected point edge by a triangle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct EdgeUse {
    pub lo: u32,
    pub hi: u32,
    pub tri: u32,
    /// The edge runs from this corner to the next one.
    pub corner: u8,
    /// True when the triangle traverses the edge from `lo` to `hi`.
    pub forward: bool,
}

/// Splits sorted edge uses into runs that share one undirected edge.
pub(crate) fn edge_runs(edges: &[EdgeUse]) -> impl Iterator<Item = &[EdgeUse]> {
    edges.chunk_by(|a, b| a.lo == b.lo && a.hi == b.hi)
}

/// Counts (boundary edges, non-manifold edges) of the live triangles on points.
pub(crate) fn count_boundary_and_non_manifold(work: &Work) -> (usize, usize) {
    let edges = sorted_edges(work);
    let mut boundary = 0;
    let mut non_manifold = 0;
    for run in edge_runs(&edges) {
        match run.len() {
            1 => boundary += 1,
            2 => {}
            _ => non_manifold += 1,
        }
    }
    (boundary, non_manifold)
}

#[cfg(test)]
/// A work mesh of the given points and triangles (one material, one group).
pub(crate) fn work_of(points: &[[f32; 3]], tris: &[[u32; 3]]) -> Work {
    let mut w = Work { points: points.iter().map(|&p| Vec3::from(p)).collect(), ..Work::default() };
    for i in 0..points.len() as u32 {
        w.vertex_point.push(i);
        w.normals.push(Vec3::Z);
    }
    for (i, &t) in tris.iter().enumerate() {
        w.tris.push(t);
        w.tri_material.push(0);
        w.tri_group.push(0);
        w.tri_origin.push(i as u32);
        w.tri_alive.push(true);
    }
    w
}
