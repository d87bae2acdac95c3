//! Writers: OBJ (+ `.mtl`) and GLB. Both write a temp file beside the target and
//! rename it, so a reader never sees a half-written file.
//!
//! Both preserve what `load_mesh` reads back: positions, normals, uvs (GLB also
//! the lightmap's, `TEXCOORD_1`), colours,
//! triangle order within each (group, material) run, material names, albedos,
//! roles and transmittance, group names. Floats are written with Rust's shortest
//! round-tripping formatting (`{}`), so OBJ positions reload bit-exactly.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use serde_json::{json, Value};

use super::obj::{MTL_ROLE_KEY, MTL_TRANSMITTANCE_KEY};
use super::{Material, MaterialRole, Mesh, MeshError};
use crate::files::Staged;

/// Stages `path`'s content among a command's outputs ([`Staged`]).
fn stage_file(staged: &mut Staged, path: &Path, fill: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>) -> Result<(), MeshError> {
    staged.stage(path, fill).map_err(|source| MeshError::Write { path: path.to_path_buf(), source })
}

/// Renames a writer's staged files into place.
fn commit(staged: Staged, path: &Path) -> Result<(), MeshError> {
    staged.commit().map_err(|source| MeshError::Write { path: path.to_path_buf(), source })
}

/// The `.mtl` that [`write_obj`] writes beside `path` (beside the file a
/// symbolic link points to, named after it, as `mtllib` refers to it).
pub fn mtl_path_for(path: &Path) -> PathBuf {
    let target = crate::files::outputs::final_target(path).unwrap_or_else(|_| path.to_path_buf());
    // Byte for byte: two OBJ names that differ only in bytes that are not
    // UTF-8 must not share one .mtl (a lossy name would make both `…\u{FFFD}.mtl`).
    match target.file_stem() {
        Some(stem) => {
            let mut name = stem.to_os_string();
            name.push(".mtl");
            target.with_file_name(name)
        }
        None => target.with_file_name("mesh.mtl"),
    }
}

fn check_writable(path: &Path, mesh: &Mesh) -> Result<(), MeshError> {
    mesh.validate().map_err(|message| MeshError::InvalidForWrite { path: path.to_path_buf(), message })
}

/// A name safe for one OBJ/MTL line (no line breaks, not empty; tobj trims the ends).
fn obj_name(name: &str) -> String {
    let cleaned: String = name.trim().chars().map(|c| if c.is_control() { '_' } else { c }).collect();
    if cleaned.is_empty() {
        "unnamed".to_string()
    } else {
        cleaned
    }
}

/// Writes `mesh` as Wavefront OBJ at `path`, with its materials in `<stem>.mtl`
/// beside it (`mtllib` refers to it by file name).
///
/// Vertices carry their colour as `v x y z r g b` when the mesh has colours; every
/// face gives position/uv/normal indices (one shared index, as `load_mesh` reads
/// them). A new `o <group>` line starts whenever the group changes along the
/// triangle list and `usemtl` whenever the material does, so triangle order is
/// kept. The `.mtl` has `Kd` per material plus `prtbake_role` /
/// `prtbake_transmittance` keys. Refuses a mesh that fails [`Mesh::validate`].
pub fn write_obj(path: &Path, mesh: &Mesh) -> Result<(), MeshError> {
    let mut staged = Staged::new();
    stage_obj(&mut staged, path, mesh)?;
    commit(staged, path)
}

/// [`write_obj`] into a command's staged outputs: the OBJ and its `.mtl`
/// land together with the command's other outputs, or not at all.
pub fn stage_obj(staged: &mut Staged, path: &Path, mesh: &Mesh) -> Result<(), MeshError> {
    check_writable(path, mesh)?;
    let mtl_path = mtl_path_for(path);
    let Some(mtl_name) = mtl_path.file_name().and_then(|n| n.to_str()).map(str::to_owned) else {
        return Err(MeshError::InvalidForWrite {
            path: path.to_path_buf(),
            message: "the OBJ names its .mtl inside the file as text, so the name must be UTF-8".into(),
        });
    };
    stage_file(staged, &mtl_path, |w| write_mtl_text(w, &mesh.materials))?;
    stage_file(staged, path, |w| write_obj_text(w, mesh, &mtl_name))
}

/// First line of every `.mtl` prtbake writes: an existing `.mtl` without it is
/// not replaced unless forced.
pub const MTL_HEADER: &str = "# written by prtbake";

fn write_mtl_text(w: &mut impl Write, materials: &[Material]) -> std::io::Result<()> {
    writeln!(w, "{MTL_HEADER}")?;
    for material in materials {
        let [r, g, b] = material.albedo;
        writeln!(w, "\nnewmtl {}\nKd {r} {g} {b}", obj_name(&material.name))?;
        let role = match material.role {
            MaterialRole::Opaque => "opaque",
            MaterialRole::Window => "window",
            MaterialRole::Panel => "panel",
        };
        writeln!(w, "{MTL_ROLE_KEY} {role}\n{MTL_TRANSMITTANCE_KEY} {}", material.transmittance)?;
    }
    Ok(())
}

fn write_obj_text(w: &mut impl Write, mesh: &Mesh, mtl_name: &str) -> std::io::Result<()> {
    writeln!(w, "# written by prtbake: {} vertices, {} triangles\nmtllib {mtl_name}", mesh.vertex_count(), mesh.triangle_count())?;
    for (i, p) in mesh.positions.iter().enumerate() {
        match mesh.colors.get(i) {
            Some([r, g, b]) => writeln!(w, "v {} {} {} {r} {g} {b}", p.x, p.y, p.z)?,
            None => writeln!(w, "v {} {} {}", p.x, p.y, p.z)?,
        }
    }
    for uv in &mesh.uvs {
        writeln!(w, "vt {} {}", uv.x, uv.y)?;
    }
    for n in &mesh.normals {
        writeln!(w, "vn {} {} {}", n.x, n.y, n.z)?;
    }
    let has_uvs = !mesh.uvs.is_empty();
    let mut current: Option<(u32, u16)> = None;
    for t in 0..mesh.triangle_count() {
        let (group, material) = (mesh.tri_group[t], mesh.tri_material[t]);
        if current.map(|(g, _)| g) != Some(group) {
            writeln!(w, "o {}", obj_name(&mesh.groups[group as usize]))?;
            current = None;
        }
        if current.map(|(_, m)| m) != Some(material) {
            writeln!(w, "usemtl {}", obj_name(&mesh.materials[material as usize].name))?;
        }
        current = Some((group, material));
        let [a, b, c] = mesh.triangle(t).map(|i| i + 1);
        if has_uvs {
            writeln!(w, "f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}")?;
        } else {
            writeln!(w, "f {a}//{a} {b}//{b} {c}//{c}")?;
        }
    }
    Ok(())
}

/// glTF constants used by the GLB writer.
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const UNSIGNED_BYTE: u32 = 5121;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;

/// Accumulates the BIN chunk and its bufferViews/accessors.
#[derive(Default)]
struct GlbBin {
    bytes: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl GlbBin {
    /// Appends one tightly packed view (4-byte aligned) and an accessor over it.
    fn push(&mut self, data: &[u8], target: u32, mut accessor: Value) -> usize {
        let view = self.push_view(data);
        self.views[view]["target"] = json!(target);
        accessor["bufferView"] = json!(view);
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    /// Appends one view (4-byte aligned) of `data`; returns its index.
    fn push_view(&mut self, data: &[u8]) -> usize {
        while self.bytes.len() % 4 != 0 {
            self.bytes.push(0);
        }
        self.views.push(json!({"buffer": 0, "byteOffset": self.bytes.len(), "byteLength": data.len()}));
        self.bytes.extend_from_slice(data);
        self.views.len() - 1
    }

    fn push_vec3s(&mut self, values: impl Iterator<Item = [f32; 3]>, with_bounds: bool) -> usize {
        let mut data = Vec::new();
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        let mut count = 0;
        for v in values {
            for k in 0..3 {
                data.extend_from_slice(&v[k].to_le_bytes());
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
            count += 1;
        }
        let mut accessor = json!({"componentType": FLOAT, "count": count, "type": "VEC3"});
        if with_bounds {
            accessor["min"] = json!(lo);
            accessor["max"] = json!(hi);
        }
        self.push(&data, ARRAY_BUFFER, accessor)
    }
}

fn material_json(material: &Material) -> Value {
    let [r, g, b] = material.albedo;
    let mut value = json!({
        "name": material.name,
        "pbrMetallicRoughness": {"baseColorFactor": [r, g, b, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "extras": {"prtbake_role": material.role},
    });
    if material.role == MaterialRole::Window {
        value["extensions"] = json!({"KHR_materials_transmission": {"transmissionFactor": material.transmittance}});
    }
    value
}

/// Writes `mesh` as a binary glTF (GLB) at `path`.
///
/// One glTF mesh (named after the group) per non-empty group, each placed by an
/// identity node, with one primitive per material used in it (triangles keep
/// their relative order). A group's primitives share its vertex accessors:
/// POSITION (with min/max), NORMAL, TEXCOORD_0, TEXCOORD_1 (a lightmap atlas; set 0 repeats it
/// when the mesh has no texture coordinates, as glTF wants set 0 first) and COLOR_0 when the mesh has
/// them, holding the group's vertices in ascending original index order. Indices
/// are u32. Materials carry `baseColorFactor`, `KHR_materials_transmission` for
/// windows, and `extras.prtbake_role`. Refuses a mesh that fails [`Mesh::validate`]
/// or would exceed GLB's 4 GiB limit.
pub fn write_glb(path: &Path, mesh: &Mesh) -> Result<(), MeshError> {
    write_glb_with(path, mesh, GlbAdditions::default())
}

/// [`write_glb`] into a command's staged outputs.
pub fn stage_glb(staged: &mut Staged, path: &Path, mesh: &Mesh) -> Result<(), MeshError> {
    stage_glb_with(staged, path, mesh, GlbAdditions::default())
}

/// A PNG stored in the GLB's binary chunk, with a glTF image and a texture
/// of the same index (`images[i]`, `textures[i]`) that no material uses:
/// data for an engine to bind (lightmaps), named by the document's extras.
#[derive(Clone, Debug, PartialEq)]
pub struct EmbeddedImage {
    pub name: String,
    /// The encoded PNG file.
    pub png: Vec<u8>,
    /// Sample with nearest filtering (bit masks), else linear.
    pub nearest: bool,
}

/// Per-vertex values written as an application-specific glTF vertex attribute.
///
/// The semantic must start with `_` (glTF 2.0 §3.7.2.1); it is stored with the
/// standard attributes of every primitive, over the same vertices.
#[derive(Clone, Debug, PartialEq)]
pub struct CustomAttribute {
    /// Attribute name as written, e.g. `_PRT_TRANSFER_0`.
    pub semantic: String,
    pub values: AttributeValues,
}

/// The data of a [`CustomAttribute`], one element per mesh vertex, in vertex order.
#[derive(Clone, Debug, PartialEq)]
pub enum AttributeValues {
    /// `components` (1..=4) floats per vertex (accessor SCALAR/VEC2/VEC3/VEC4 of FLOAT);
    /// `data.len() == vertex_count · components`.
    F32 { components: u8, data: Vec<f32> },
    /// Four unsigned bytes per vertex (accessor VEC4 of UNSIGNED_BYTE, not normalized):
    /// four bytes keep each element 4-byte aligned, as glTF requires of vertex attributes.
    U8x4(Vec<[u8; 4]>),
}

impl CustomAttribute {
    fn check(&self, vertex_count: usize) -> Result<(), String> {
        if !self.semantic.starts_with('_') || self.semantic.len() < 2 {
            return Err(format!("custom attribute {:?} must start with '_'", self.semantic));
        }
        let (len, per_vertex) = match &self.values {
            AttributeValues::F32 { components, data } if (1..=4).contains(components) => (data.len(), *components as usize),
            AttributeValues::F32 { components, .. } => return Err(format!("{}: {components} components (1..=4 allowed)", self.semantic)),
            AttributeValues::U8x4(data) => (data.len(), 1),
        };
        if len != vertex_count * per_vertex {
            return Err(format!("{}: {len} values for {vertex_count} vertices", self.semantic));
        }
        if let AttributeValues::F32 { data, .. } = &self.values {
            if data.iter().any(|x| !x.is_finite()) {
                return Err(format!("{}: non-finite value", self.semantic));
            }
        }
        Ok(())
    }

    /// Appends the values of `vertices` (in that order) to `bin`; returns the accessor index.
    fn push(&self, bin: &mut GlbBin, vertices: &[u32]) -> usize {
        match &self.values {
            AttributeValues::F32 { components, data } => {
                let c = *components as usize;
                let bytes: Vec<u8> =
                    vertices.iter().flat_map(|&v| &data[v as usize * c..(v as usize + 1) * c]).flat_map(|x| x.to_le_bytes()).collect();
                let kind = ["SCALAR", "VEC2", "VEC3", "VEC4"][c - 1];
                bin.push(&bytes, ARRAY_BUFFER, json!({"componentType": FLOAT, "count": vertices.len(), "type": kind}))
            }
            AttributeValues::U8x4(data) => {
                let bytes: Vec<u8> = vertices.iter().flat_map(|&v| data[v as usize]).collect();
                bin.push(&bytes, ARRAY_BUFFER, json!({"componentType": UNSIGNED_BYTE, "count": vertices.len(), "type": "VEC4"}))
            }
        }
    }
}

/// [`write_glb`] plus application-specific vertex attributes and document-level
/// `extras` (e.g. what the attributes mean).
///
/// Each attribute holds one element per mesh vertex, in mesh order, like the
/// POSITION accessor that every primitive shares. Refuses (with [`MeshError::InvalidForWrite`]) semantics that do
/// not start with `_` or repeat, lengths that do not match the vertex count,
/// and non-finite floats.
pub fn write_glb_with(path: &Path, mesh: &Mesh, additions: GlbAdditions) -> Result<(), MeshError> {
    let mut staged = Staged::new();
    stage_glb_with(&mut staged, path, mesh, additions)?;
    commit(staged, path)
}

/// What [`write_glb_with`] adds to [`write_glb`]'s document.
#[derive(Clone, Debug, Default)]
pub struct GlbAdditions<'a> {
    /// Application-specific vertex attributes.
    pub attributes: &'a [CustomAttribute],
    /// The document's `extras`.
    pub extras: Option<Value>,
    /// PNGs in the binary chunk, image and texture `i` each.
    pub images: &'a [EmbeddedImage],
    /// A second atlas's positions, one per vertex, as `TEXCOORD_2` (with
    /// the mesh's lightmap UVs as `TEXCOORD_1`); empty: none.
    pub second_lightmap_uvs: &'a [glam::Vec2],
}

/// [`write_glb_with`] into a command's staged outputs.
pub fn stage_glb_with(staged: &mut Staged, path: &Path, mesh: &Mesh, additions: GlbAdditions) -> Result<(), MeshError> {
    let GlbAdditions { attributes: attributes_in, extras, images, second_lightmap_uvs } = additions;
    check_writable(path, mesh)?;
    let invalid = |message: String| MeshError::InvalidForWrite { path: path.to_path_buf(), message };
    if !second_lightmap_uvs.is_empty() && (mesh.lightmap_uvs.is_empty() || second_lightmap_uvs.len() != mesh.vertex_count()) {
        return Err(invalid(format!(
            "{} second lightmap UVs for {} vertices with {} lightmap UVs (TEXCOORD_2 needs TEXCOORD_1 and one per vertex)",
            second_lightmap_uvs.len(),
            mesh.vertex_count(),
            mesh.lightmap_uvs.len()
        )));
    }
    if let Some(v) = second_lightmap_uvs.iter().position(|uv| !uv.is_finite()) {
        return Err(invalid(format!("second lightmap UV of vertex {v} is not finite")));
    }
    if mesh.triangle_count() == 0 {
        // glTF has no empty primitive: such a file fails validation.
        return Err(invalid("the mesh has no triangles: nothing to write".into()));
    }
    for (i, attribute) in attributes_in.iter().enumerate() {
        attribute.check(mesh.vertex_count()).map_err(invalid)?;
        if attributes_in[..i].iter().any(|a| a.semantic == attribute.semantic) {
            return Err(invalid(format!("custom attribute {} appears twice", attribute.semantic)));
        }
    }
    let too_large = || MeshError::InvalidForWrite { path: path.to_path_buf(), message: "the GLB would exceed 4 GiB".into() };
    let mut bin = GlbBin::default();
    let mut meshes = Vec::new();

    // Triangles per group, then per material (BTreeMap: material order).
    let mut by_group: Vec<BTreeMap<u16, Vec<usize>>> = vec![BTreeMap::new(); mesh.groups.len()];
    for t in 0..mesh.triangle_count() {
        by_group[mesh.tri_group[t] as usize].entry(mesh.tri_material[t]).or_default().push(t);
    }
    // One vertex pool, in mesh order, that every group's primitives index: a
    // vertex shared by two groups stays one vertex through a round trip (the
    // loader keys vertices by accessor and transform, not by glTF mesh).
    let pool: Vec<u32> = (0..mesh.vertex_count() as u32).collect();
    let position = bin.push_vec3s(mesh.positions.iter().map(|p| p.to_array()), true);
    // glTF's NORMAL is unit length: a normal that is not (a bundle built in
    // memory, a zero one) is normalised (+Y if zero); unit ones keep their bits.
    let unit = |n: &glam::Vec3| if (n.length_squared() - 1.0).abs() <= 1e-5 { *n } else { n.normalize_or(glam::Vec3::Y) };
    let normal = bin.push_vec3s(mesh.normals.iter().map(|n| unit(n).to_array()), false);
    let mut attributes = json!({"POSITION": position, "NORMAL": normal});
    if !mesh.uvs.is_empty() {
        let data: Vec<u8> = mesh.uvs.iter().flat_map(|uv| uv.to_array()).flat_map(f32::to_le_bytes).collect();
        attributes["TEXCOORD_0"] =
            json!(bin.push(&data, ARRAY_BUFFER, json!({"componentType": FLOAT, "count": pool.len(), "type": "VEC2"})));
    }
    if !mesh.lightmap_uvs.is_empty() {
        let data: Vec<u8> = mesh.lightmap_uvs.iter().flat_map(|uv| uv.to_array()).flat_map(f32::to_le_bytes).collect();
        attributes["TEXCOORD_1"] =
            json!(bin.push(&data, ARRAY_BUFFER, json!({"componentType": FLOAT, "count": pool.len(), "type": "VEC2"})));
        // glTF wants set 0 before set 1: without texture coordinates, set 0
        // is the same accessor (the loader reads that back as none).
        if mesh.uvs.is_empty() {
            attributes["TEXCOORD_0"] = attributes["TEXCOORD_1"].clone();
        }
        if !second_lightmap_uvs.is_empty() {
            let data: Vec<u8> = second_lightmap_uvs.iter().flat_map(|uv| uv.to_array()).flat_map(f32::to_le_bytes).collect();
            attributes["TEXCOORD_2"] =
                json!(bin.push(&data, ARRAY_BUFFER, json!({"componentType": FLOAT, "count": pool.len(), "type": "VEC2"})));
        }
    }
    if !mesh.colors.is_empty() {
        attributes["COLOR_0"] = json!(bin.push_vec3s(mesh.colors.iter().copied(), false));
    }
    for custom in attributes_in {
        attributes[custom.semantic.as_str()] = json!(custom.push(&mut bin, &pool));
    }
    for (group, runs) in by_group.iter().enumerate() {
        if runs.is_empty() {
            continue;
        }
        let primitives: Vec<Value> = runs
            .iter()
            .map(|(&material, triangles)| {
                let data: Vec<u8> = triangles.iter().flat_map(|&t| mesh.triangle(t)).flat_map(u32::to_le_bytes).collect();
                let indices = bin.push(
                    &data,
                    ELEMENT_ARRAY_BUFFER,
                    json!({"componentType": UNSIGNED_INT, "count": 3 * triangles.len(), "type": "SCALAR"}),
                );
                json!({"attributes": attributes.clone(), "indices": indices, "material": material, "mode": 4})
            })
            .collect();
        meshes.push(json!({"name": mesh.groups[group], "primitives": primitives}));
    }

    let image_json: Vec<Value> =
        images.iter().map(|image| json!({"bufferView": bin.push_view(&image.png), "mimeType": "image/png", "name": image.name})).collect();

    let nodes: Vec<Value> = meshes.iter().enumerate().map(|(i, m)| json!({"mesh": i, "name": m["name"]})).collect();
    let mut document = json!({
        "asset": {"version": "2.0", "generator": concat!("prtbake ", env!("CARGO_PKG_VERSION"))},
        "scene": 0,
        "scenes": [{"nodes": (0..nodes.len()).collect::<Vec<_>>()}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": mesh.materials.iter().map(material_json).collect::<Vec<_>>(),
        "accessors": bin.accessors,
        "bufferViews": bin.views,
    });
    if !bin.bytes.is_empty() {
        document["buffers"] = json!([{"byteLength": bin.bytes.len()}]);
    }
    if let Some(extras) = extras {
        document["extras"] = extras;
    }
    if !images.is_empty() {
        const NEAREST: u32 = 9728;
        const LINEAR: u32 = 9729;
        document["samplers"] = json!([{"magFilter": LINEAR, "minFilter": LINEAR}, {"magFilter": NEAREST, "minFilter": NEAREST}]);
        document["textures"] = images
            .iter()
            .enumerate()
            .map(|(i, image)| json!({"source": i, "sampler": usize::from(image.nearest), "name": image.name}))
            .collect();
        document["images"] = json!(image_json);
    }
    if mesh.materials.iter().any(|m| m.role == MaterialRole::Window) {
        document["extensionsUsed"] = json!(["KHR_materials_transmission"]);
    }
    let glb = assemble_glb(document.to_string().into_bytes(), bin.bytes).ok_or_else(too_large)?;
    stage_file(staged, path, |w| w.write_all(&glb))
}

/// Frames JSON and BIN chunks as GLB: JSON padded with spaces and BIN with zeros
/// to 4 bytes, as the spec requires. `None` when the total exceeds `u32`.
pub(crate) fn assemble_glb(mut json: Vec<u8>, mut bin: Vec<u8>) -> Option<Vec<u8>> {
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let bin_chunk_len = if bin.is_empty() { 0 } else { 8 + bin.len() };
    let total = u32::try_from(12 + 8 + json.len() + bin_chunk_len).ok()?;
    let mut out = Vec::with_capacity(total as usize);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&total.to_le_bytes());
    out.extend_from_slice(&u32::try_from(json.len()).ok()?.to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    if !bin.is_empty() {
        out.extend_from_slice(&u32::try_from(bin.len()).ok()?.to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
    }
    Some(out)
}
