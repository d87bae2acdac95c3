//! The flat mesh every stage passes around: struct-of-arrays, `u32` indices.

use glam::{Vec2, Vec3};

/// What a material does to light in the bake.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MaterialRole {
    /// Reflects diffusely with its albedo; blocks rays.
    Opaque,
    /// Glass: in window mode light enters only through it (transmittance `tau`).
    Window,
    /// A display panel (LCD): opaque for transfer, flagged for the viewer.
    Panel,
}

/// One entry of the material table.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Material {
    pub name: String,
    /// Diffuse albedo (linear RGB, 0..1): OBJ `Kd`, glTF base colour factor.
    pub albedo: [f32; 3],
    pub role: MaterialRole,
    /// Glass transmittance for `Window` materials (1 = clear); ignored otherwise.
    pub transmittance: f32,
}

impl Material {
    /// A grey opaque material.
    pub fn opaque(name: &str, albedo: f32) -> Material {
        Material { name: name.to_string(), albedo: [albedo; 3], role: MaterialRole::Opaque, transmittance: 1.0 }
    }
}

/// A triangle mesh in world space (right-handed, +Y up after loading).
///
/// Invariants (checked by [`Mesh::validate`]): `indices.len() == 3 * triangle_count`,
/// every index `< positions.len()`, `normals.len() == positions.len()`,
/// `uvs`, `lightmap_uvs` and `colors` are empty or one per vertex, `tri_material` and `tri_group`
/// have one entry per triangle and index into `materials` / `groups`,
/// every coordinate is finite.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    /// Unit vertex normals (computed, area-and-angle weighted, when the file has none).
    pub normals: Vec<Vec3>,
    /// Texture coordinates, empty when the file has none.
    pub uvs: Vec<Vec2>,
    /// The file's own lightmap coordinates (glTF `TEXCOORD_1`, in [0, 1]),
    /// empty when it has none: texel mode keeps this atlas instead of
    /// unwrapping one ([`crate::atlas::Atlas::for_mesh`]).
    pub lightmap_uvs: Vec<Vec2>,
    /// Vertex colours (linear RGB), empty when the file has none.
    pub colors: Vec<[f32; 3]>,
    /// Triangle list: triangle `t` is `indices[3t..3t+3]`, counter-clockwise front.
    pub indices: Vec<u32>,
    /// Material index per triangle.
    pub tri_material: Vec<u16>,
    /// Group (OBJ object / glTF mesh) index per triangle.
    pub tri_group: Vec<u32>,
    pub materials: Vec<Material>,
    /// Group names (OBJ `o`/`g` names, glTF mesh names), for `--window` globs.
    pub groups: Vec<String>,
}

impl Mesh {
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }
    /// The three vertex indices of triangle `t`.
    #[inline]
    pub fn triangle(&self, t: usize) -> [u32; 3] {
        [self.indices[3 * t], self.indices[3 * t + 1], self.indices[3 * t + 2]]
    }
    /// The three corner positions of triangle `t`.
    #[inline]
    pub fn triangle_positions(&self, t: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangle(t);
        [self.positions[a as usize], self.positions[b as usize], self.positions[c as usize]]
    }
    /// Area of triangle `t`, in f64 (sums of many stay exact enough to compare).
    pub fn triangle_area(&self, t: usize) -> f64 {
        let [a, b, c] = self.triangle_positions(t).map(|p| p.as_dvec3());
        0.5 * (b - a).cross(c - a).length()
    }
    /// Total area of the triangles.
    pub fn area(&self) -> f64 {
        (0..self.triangle_count()).map(|t| self.triangle_area(t)).sum()
    }
    /// Axis-aligned bounds (min, max); `(ZERO, ZERO)` for an empty mesh.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        if self.positions.is_empty() {
            return (Vec3::ZERO, Vec3::ZERO);
        }
        self.positions.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &p| (lo.min(p), hi.max(p)))
    }
    /// Length of the bounding-box diagonal: the scene scale every epsilon is relative to.
    pub fn diagonal(&self) -> f32 {
        let (lo, hi) = self.bounds();
        (hi - lo).length()
    }
    /// Length of the bounding-box diagonal of the vertices triangles use
    /// (0 without triangles): the scale of clean's and refine's tolerances.
    pub fn referenced_diagonal(&self) -> f32 {
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        for &i in &self.indices {
            lo = lo.min(self.positions[i as usize]);
            hi = hi.max(self.positions[i as usize]);
        }
        if self.indices.is_empty() {
            0.0
        } else {
            (hi - lo).length()
        }
    }
    /// The same mesh in the writers' canonical order: triangles stably sorted
    /// by (group, material), vertices renumbered in order of first use (unused
    /// ones dropped). OBJ and GLB files of a mesh in this order load back in
    /// the same order, so `clean` → file → `bake` bakes the mesh `bake --clean` does.
    pub fn into_canonical_order(self) -> Mesh {
        let mut order: Vec<u32> = (0..self.triangle_count() as u32).collect();
        order.sort_by_key(|&t| (self.tri_group[t as usize], self.tri_material[t as usize]));
        const UNUSED: u32 = u32::MAX;
        let mut new_index = vec![UNUSED; self.vertex_count()];
        let mut old_of_new: Vec<u32> = Vec::with_capacity(self.vertex_count());
        let mut indices = Vec::with_capacity(self.indices.len());
        for &t in &order {
            for v in self.triangle(t as usize) {
                if new_index[v as usize] == UNUSED {
                    new_index[v as usize] = old_of_new.len() as u32;
                    old_of_new.push(v);
                }
                indices.push(new_index[v as usize]);
            }
        }
        let vertices = self.gather_vertices(&old_of_new);
        Mesh {
            indices,
            tri_material: order.iter().map(|&t| self.tri_material[t as usize]).collect(),
            tri_group: order.iter().map(|&t| self.tri_group[t as usize]).collect(),
            materials: self.materials,
            groups: self.groups,
            ..vertices
        }
    }
    /// The per-vertex attributes of `sources` (vertex i of the result copies
    /// vertex `sources[i]`; absent attributes stay absent); no triangles,
    /// materials or groups.
    pub fn gather_vertices(&self, sources: &[u32]) -> Mesh {
        fn gather<T: Copy>(values: &[T], sources: &[u32]) -> Vec<T> {
            if values.is_empty() {
                Vec::new()
            } else {
                sources.iter().map(|&v| values[v as usize]).collect()
            }
        }
        Mesh {
            positions: gather(&self.positions, sources),
            normals: gather(&self.normals, sources),
            uvs: gather(&self.uvs, sources),
            lightmap_uvs: gather(&self.lightmap_uvs, sources),
            colors: gather(&self.colors, sources),
            ..Mesh::default()
        }
    }
    /// Checks the invariants above; returns a description of the first one broken.
    pub fn validate(&self) -> Result<(), String> {
        let n = self.positions.len();
        if self.indices.len() % 3 != 0 {
            return Err(format!("index count {} is not a multiple of 3", self.indices.len()));
        }
        let t = self.triangle_count();
        if self.normals.len() != n {
            return Err(format!("{} normals for {} vertices", self.normals.len(), n));
        }
        if !self.uvs.is_empty() && self.uvs.len() != n {
            return Err(format!("{} uvs for {} vertices", self.uvs.len(), n));
        }
        if !self.lightmap_uvs.is_empty() && self.lightmap_uvs.len() != n {
            return Err(format!("{} lightmap uvs for {} vertices", self.lightmap_uvs.len(), n));
        }
        if !self.colors.is_empty() && self.colors.len() != n {
            return Err(format!("{} colours for {} vertices", self.colors.len(), n));
        }
        if self.tri_material.len() != t || self.tri_group.len() != t {
            return Err(format!("per-triangle arrays do not match {} triangles", t));
        }
        if let Some((i, &v)) = self.indices.iter().enumerate().find(|(_, &v)| v as usize >= n) {
            return Err(format!("index {} at position {} is out of range ({} vertices)", v, i, n));
        }
        if let Some(&m) = self.tri_material.iter().find(|&&m| m as usize >= self.materials.len()) {
            return Err(format!("material index {} out of range ({} materials)", m, self.materials.len()));
        }
        if let Some(&g) = self.tri_group.iter().find(|&&g| g as usize >= self.groups.len()) {
            return Err(format!("group index {} out of range ({} groups)", g, self.groups.len()));
        }
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(format!("vertex {} has a non-finite coordinate {:?}", i, self.positions[i]));
        }
        Ok(())
    }
}
