//! Accumulates vertices and triangles from any loader into one flat [`Mesh`], then
//! checks and completes it (normals, defaults for missing attributes, invariants).

use std::collections::HashMap;
use std::path::Path;

use glam::{Vec2, Vec3};

use super::normals::repair_normals;
use super::{Material, Mesh, MeshError};

/// Colour given to vertices of a part without vertex colours when another part has
/// them: white, the neutral multiplier (glTF's rule for a missing `COLOR_0`).
const DEFAULT_COLOR: [f32; 3] = [1.0, 1.0, 1.0];

/// Builds a [`Mesh`] piece by piece. Missing normals are stored as `Vec3::NAN` and
/// computed in [`MeshBuilder::finish`].
pub(crate) struct MeshBuilder {
    mesh: Mesh,
    any_uvs: bool,
    any_colors: bool,
    /// Lightmap coordinates as pushed (glTF `TEXCOORD_1`); kept only when
    /// every vertex has one ([`MeshBuilder::finish`]).
    lightmap: Vec<Option<Vec2>>,
    /// Vertices pushed without a normal (so not a fault of the file).
    normals_absent: usize,
    group_lookup: HashMap<String, u32>,
}

impl MeshBuilder {
    /// Starts an empty mesh with the given material table.
    pub(crate) fn new(materials: Vec<Material>) -> MeshBuilder {
        MeshBuilder {
            mesh: Mesh { materials, ..Mesh::default() },
            any_uvs: false,
            any_colors: false,
            lightmap: Vec::new(),
            normals_absent: 0,
            group_lookup: HashMap::new(),
        }
    }

    /// Index of the group called `name`, created on first use (groups are
    /// identified by name: OBJ parts split by `usemtl` share their object's group).
    pub(crate) fn group_index(&mut self, name: &str) -> u32 {
        if let Some(&index) = self.group_lookup.get(name) {
            return index;
        }
        let index = self.mesh.groups.len() as u32;
        self.mesh.groups.push(name.to_string());
        self.group_lookup.insert(name.to_string(), index);
        index
    }

    /// Number of vertices so far: the base to add to a part's local indices.
    pub(crate) fn vertex_count(&self) -> usize {
        self.mesh.positions.len()
    }

    /// Reserves room for `vertices` more vertices and `triangles` more triangles.
    pub(crate) fn reserve(&mut self, vertices: usize, triangles: usize) {
        self.mesh.positions.reserve(vertices);
        self.mesh.normals.reserve(vertices);
        self.mesh.indices.reserve(3 * triangles);
        self.mesh.tri_material.reserve(triangles);
        self.mesh.tri_group.reserve(triangles);
    }

    /// Appends one vertex; `None` attributes get defaults (normal computed later).
    pub(crate) fn push_vertex(&mut self, position: Vec3, normal: Option<Vec3>, uv: Option<Vec2>, color: Option<[f32; 3]>) {
        self.mesh.positions.push(position);
        self.mesh.normals.push(normal.unwrap_or(Vec3::NAN));
        if normal.is_none() {
            self.normals_absent += 1;
        }
        // Keep uvs/colours in lockstep with positions once any part has them.
        if uv.is_some() && !self.any_uvs {
            self.any_uvs = true;
            self.mesh.uvs = vec![Vec2::ZERO; self.mesh.positions.len() - 1];
        }
        if self.any_uvs {
            self.mesh.uvs.push(uv.unwrap_or(Vec2::ZERO));
        }
        if color.is_some() && !self.any_colors {
            self.any_colors = true;
            self.mesh.colors = vec![DEFAULT_COLOR; self.mesh.positions.len() - 1];
        }
        if self.any_colors {
            self.mesh.colors.push(color.unwrap_or(DEFAULT_COLOR));
        }
    }

    /// Sets the lightmap coordinates of the vertex just pushed (`None`: it has none).
    pub(crate) fn push_lightmap_uv(&mut self, uv: Option<Vec2>) {
        self.lightmap.resize(self.mesh.positions.len() - 1, None);
        self.lightmap.push(uv);
    }

    /// Appends a triangle of absolute vertex indices (checked in `finish`).
    pub(crate) fn push_triangle(&mut self, corners: [u32; 3], material: u16, group: u32) {
        self.mesh.indices.extend_from_slice(&corners);
        self.mesh.tri_material.push(material);
        self.mesh.tri_group.push(group);
    }

    /// Appends a material and returns its index, or `None` past the u16 limit.
    pub(crate) fn push_material(&mut self, material: Material) -> Option<u16> {
        let index = u16::try_from(self.mesh.materials.len()).ok()?;
        self.mesh.materials.push(material);
        Some(index)
    }

    /// Checks and completes the mesh: refuses an empty mesh and non-finite
    /// positions, fills in missing or unusable normals, replaces non-finite
    /// uvs/colours (with a warning) and verifies every [`Mesh`] invariant.
    pub(crate) fn finish(self, path: &Path, warnings: &mut Vec<String>) -> Result<Mesh, MeshError> {
        let MeshBuilder { mut mesh, normals_absent, lightmap, .. } = self;
        if mesh.indices.is_empty() {
            return Err(MeshError::Empty { path: path.to_path_buf(), notes: warnings.clone() });
        }
        if u32::try_from(mesh.positions.len()).is_err() {
            return Err(MeshError::TooLarge {
                path: path.to_path_buf(),
                message: format!("{} vertices exceed the u32 index range", mesh.positions.len()),
            });
        }
        // Loaders name the bad vertex in file terms first; this catches transforms
        // that overflow to infinity.
        if let Some((i, p)) = mesh.positions.iter().enumerate().find(|(_, p)| !p.is_finite()) {
            return Err(MeshError::NonFinitePosition {
                path: path.to_path_buf(),
                vertex: format!("vertex {i} (after node transforms)"),
                position: p.to_array(),
            });
        }
        let replaced = repair_normals(&mut mesh.normals, &mesh.positions, &mesh.indices);
        let bad_in_file = replaced.saturating_sub(normals_absent);
        if bad_in_file > 0 {
            warnings.push(format!("{bad_in_file} zero or non-finite normals in the file were recomputed"));
        }
        let bad_uvs = mesh.uvs.iter_mut().filter(|uv| !uv.is_finite()).map(|uv| *uv = Vec2::ZERO).count();
        if bad_uvs > 0 {
            warnings.push(format!("{bad_uvs} non-finite texture coordinates were set to (0, 0)"));
        }
        let bad_colors = mesh.colors.iter_mut().filter(|c| !c.iter().all(|x| x.is_finite())).map(|c| *c = DEFAULT_COLOR).count();
        if bad_colors > 0 {
            warnings.push(format!("{bad_colors} non-finite vertex colours were set to white"));
        }
        // A lightmap atlas is all or nothing: texel mode keeps it whole or unwraps its own.
        let with_lightmap = lightmap.iter().filter(|uv| uv.is_some()).count();
        if with_lightmap > 0 {
            let finite = lightmap.iter().flatten().all(|uv| uv.is_finite());
            if with_lightmap == mesh.positions.len() && finite {
                mesh.lightmap_uvs = lightmap.into_iter().flatten().collect();
            } else if !finite {
                warnings.push("TEXCOORD_1 has non-finite lightmap coordinates: ignored (texel mode unwraps its own atlas)".into());
            } else {
                warnings.push(format!(
                    "TEXCOORD_1 on {with_lightmap} of {} vertices: ignored, a lightmap atlas needs every vertex (texel mode unwraps its own)",
                    mesh.positions.len()
                ));
            }
        }
        // Loaders check indices against their parts, so a failure here is a loader bug.
        mesh.validate().map_err(|message| MeshError::Inconsistent { path: path.to_path_buf(), message })?;
        Ok(mesh)
    }
}
