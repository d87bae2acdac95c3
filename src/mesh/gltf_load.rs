//! glTF 2.0 / GLB loading into one flat [`Mesh`], using the gltf crate for JSON and
//! schema only (no `import` feature): buffers, accessors and the node walk are done
//! here with every length checked, so no input can make the loader panic.
//!
//! Why not `gltf::Gltf::from_slice` as is: in gltf 1.4.1 it underflows (panics in
//! debug) on a GLB header length below 12, and its validation indexes the
//! POSITION accessor unchecked. So the GLB container is split here, the JSON is
//! deserialised with `gltf::json`, those indices are checked first, and then the
//! crate's own validation runs (minus the rule that POSITION must carry min/max,
//! which this loader does not need: it computes bounds itself, and refusing such
//! files would hide the more useful "non-finite vertex" error).

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use glam::{Mat3, Mat4, Vec2, Vec3};
use gltf::json::mesh::{Mode, Semantic};
use gltf::json::validation::{Checked, Validate};
use gltf::json::{self, Root};

use super::builder::MeshBuilder;
use super::gltf_accessor::{read_floats, read_indices};
use super::gltf_buffers::{is_glb, load_buffers, split_glb};
use super::gltf_scene::{collect_mesh_instances, MeshInstance};
use super::{Material, MaterialRole, Mesh, MeshError, DEFAULT_ALBEDO};

/// Required extensions that change neither geometry nor the diffuse albedo, so the
/// file can be loaded without understanding them. Anything else listed in
/// `extensionsRequired` is refused.
const GEOMETRY_NEUTRAL_EXTENSIONS: &[&str] = &[
    "KHR_materials_transmission",
    "KHR_mesh_quantization", // integer attributes: decoded by gltf_accessor
    "KHR_texture_transform",
    "KHR_texture_basisu",
    "EXT_texture_webp",
    "EXT_texture_avif",
    "KHR_materials_emissive_strength",
    "KHR_materials_ior",
    "KHR_materials_volume",
    "KHR_materials_specular",
    "KHR_materials_clearcoat",
    "KHR_materials_sheen",
    "KHR_materials_unlit",
    "KHR_materials_iridescence",
    "KHR_materials_anisotropy",
    "KHR_materials_dispersion",
];

/// Loads a `.gltf` or `.glb` file already read into `bytes`. `path` is used for
/// messages and to resolve external buffers. Non-fatal problems go to `warnings`.
pub(crate) fn load_gltf(
    path: &Path,
    bytes: &[u8],
    warnings: &mut Vec<String>,
    sources: &mut Vec<std::path::PathBuf>,
) -> Result<Mesh, MeshError> {
    let (json_bytes, glb_bin) = if is_glb(bytes) {
        let chunks = split_glb(bytes).map_err(|e| MeshError::gltf(path, e))?;
        (chunks.json, chunks.bin)
    } else {
        (bytes, None)
    };
    let root: Root = json::deserialize::from_slice(json_bytes).map_err(|e| MeshError::gltf(path, e.to_string()))?;
    check_required_extensions(&root, path)?;
    validate(&root, path)?;
    let base_color_given = probe_base_color_factors(json_bytes);
    let document = gltf::Document::from_json_without_validation(root);
    let base_dir = path.parent().unwrap_or(Path::new("."));
    let buffers = load_buffers(&document, glb_bin, base_dir, path, sources)?;
    let materials = convert_materials(&document, &base_color_given);
    let root = document.as_json();

    let instances = collect_mesh_instances(root, path, warnings)?;
    let mut loader = PrimitiveLoader {
        root,
        buffers: &buffers,
        path,
        builder: MeshBuilder::new(materials),
        default_material: None,
        skipped_modes: BTreeMap::new(),
        placed_vertices: HashMap::new(),
    };
    for instance in &instances {
        loader.emit_instance(instance, warnings)?;
    }
    for (mode, count) in &loader.skipped_modes {
        warnings.push(format!("skipped {count} primitives of mode {mode} (only triangles, strips and fans are loaded)"));
    }
    loader.builder.finish(path, warnings)
}

/// Refuses the file when it requires an extension outside [`GEOMETRY_NEUTRAL_EXTENSIONS`].
fn check_required_extensions(root: &Root, path: &Path) -> Result<(), MeshError> {
    match root.extensions_required.iter().find(|e| !GEOMETRY_NEUTRAL_EXTENSIONS.contains(&e.as_str())) {
        None => Ok(()),
        Some(extension) => Err(MeshError::UnsupportedExtension {
            path: path.to_path_buf(),
            extension: extension.clone(),
            hint: match extension.as_str() {
                "KHR_draco_mesh_compression" | "EXT_meshopt_compression" => "decode it first (e.g. gltf-transform)",
                _ => "remove or bake it into plain geometry first (e.g. gltf-transform)",
            },
        }),
    }
}

/// Runs the gltf crate's schema validation (with the checks it needs first).
fn validate(root: &Root, path: &Path) -> Result<(), MeshError> {
    // The crate's POSITION min/max rule indexes `accessors[i]` unchecked.
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            for (semantic, accessor) in &primitive.attributes {
                if accessor.value() >= root.accessors.len() {
                    return Err(MeshError::gltf(
                        path,
                        format!(
                            "meshes[{m}].primitives[{p}] attribute {semantic:?} refers to accessor {}, which does not exist",
                            accessor.value()
                        ),
                    ));
                }
            }
        }
    }
    let mut errors = Vec::new();
    root.validate(root, json::Path::new, &mut |where_, error| {
        let where_ = where_().to_string();
        let bounds_rule =
            error == json::validation::Error::Missing && (where_.ends_with("[\"POSITION\"].min") || where_.ends_with("[\"POSITION\"].max"));
        // Required extensions were judged by check_required_extensions.
        let extension_rule = where_.starts_with("extensionsRequired");
        if !bounds_rule && !extension_rule {
            errors.push(format!("{where_}: {error}"));
        }
    });
    if errors.is_empty() {
        return Ok(());
    }
    let shown = errors.len().min(5);
    let more = if errors.len() > shown { format!(" (and {} more)", errors.len() - shown) } else { String::new() };
    Err(MeshError::gltf(path, format!("{}{more}", errors[..shown].join("; "))))
}

/// For each material, whether its JSON states `baseColorFactor` (gltf-json fills
/// in the spec default of 1.0, but prtbake's default albedo is 0.8). When the
/// probe fails every factor counts as given.
fn probe_base_color_factors(json_bytes: &[u8]) -> Vec<bool> {
    #[derive(serde::Deserialize)]
    struct Probe {
        #[serde(default)]
        materials: Vec<MaterialProbe>,
    }
    #[derive(serde::Deserialize)]
    struct MaterialProbe {
        #[serde(rename = "pbrMetallicRoughness")]
        pbr: Option<PbrProbe>,
    }
    #[derive(serde::Deserialize)]
    struct PbrProbe {
        #[serde(rename = "baseColorFactor")]
        base_color_factor: Option<serde::de::IgnoredAny>,
    }
    match serde_json::from_slice::<Probe>(json_bytes) {
        Ok(probe) => probe.materials.iter().map(|m| m.pbr.as_ref().is_some_and(|p| p.base_color_factor.is_some())).collect(),
        Err(_) => Vec::new(),
    }
}

/// prtbake's own material hints, written by `write_glb` into material `extras`.
#[derive(serde::Deserialize, Default)]
struct PrtbakeExtras {
    prtbake_role: Option<MaterialRole>,
}

/// Converts the glTF materials: albedo = base colour factor RGB (nothing else
/// multiplied in), role `Window` when KHR_materials_transmission has a factor > 0
/// (transmittance = factor), unless prtbake's own `extras.prtbake_role` says otherwise.
fn convert_materials(document: &gltf::Document, base_color_given: &[bool]) -> Vec<Material> {
    document
        .materials()
        .enumerate()
        .map(|(i, material)| {
            let factor = material.pbr_metallic_roughness().base_color_factor();
            let given = base_color_given.get(i).copied().unwrap_or(true);
            let rgb = [factor[0], factor[1], factor[2]];
            let albedo = if given && rgb.iter().all(|c| c.is_finite()) { rgb } else { [DEFAULT_ALBEDO; 3] };
            let transmission = material.transmission().map(|t| t.transmission_factor()).filter(|t| t.is_finite());
            let extras: PrtbakeExtras = material.extras().as_ref().and_then(|raw| serde_json::from_str(raw.get()).ok()).unwrap_or_default();
            let role = match (extras.prtbake_role, transmission) {
                (Some(role), _) => role,
                (None, Some(t)) if t > 0.0 => MaterialRole::Window,
                _ => MaterialRole::Opaque,
            };
            Material {
                name: material.name().map_or_else(|| format!("material{i}"), str::to_string),
                albedo,
                role,
                transmittance: transmission.unwrap_or(1.0),
            }
        })
        .collect()
}

/// Attribute accessors that make up a vertex: primitives sharing them under the
/// same world transform share their vertices, across glTF meshes too (prtbake's
/// own GLB gives every group's primitives one vertex pool).
type VertexKey = [Option<usize>; 5];

/// A [`VertexKey`] placed by a world transform (its bits).
type PlacedVertexKey = (VertexKey, [u32; 16]);

/// A primitive's vertices: already placed (first vertex, count), or decoded
/// and to be pushed once the primitive turns out to have triangles.
enum Vertices {
    Placed { base: u32, count: u32 },
    New(LocalVertices),
}

/// Decoded attributes of one primitive, in its local frame.
struct LocalVertices {
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    uvs: Option<Vec<Vec2>>,
    lightmap_uvs: Option<Vec<Vec2>>,
    colors: Option<Vec<[f32; 3]>>,
}

struct PrimitiveLoader<'a> {
    root: &'a Root,
    buffers: &'a [Cow<'a, [u8]>],
    path: &'a Path,
    builder: MeshBuilder,
    default_material: Option<u16>,
    skipped_modes: BTreeMap<String, usize>,
    /// First vertex and count of each placed vertex set already pushed.
    placed_vertices: HashMap<PlacedVertexKey, (u32, u32)>,
}

impl PrimitiveLoader<'_> {
    /// Appends every triangle primitive of one mesh instance, transformed to world space.
    fn emit_instance(&mut self, instance: &MeshInstance, warnings: &mut Vec<String>) -> Result<(), MeshError> {
        let root = self.root;
        let Some(mesh) = root.meshes.get(instance.mesh) else {
            return Err(MeshError::gltf(
                self.path,
                format!("node {} refers to mesh {}, which does not exist", instance.node, instance.mesh),
            ));
        };
        let mesh_label = format!("'{}' ({})", mesh.name.as_deref().unwrap_or(""), instance.mesh);
        let group_name = mesh.name.clone().unwrap_or_else(|| format!("mesh{}", instance.mesh));
        let flip_winding = instance.world.determinant() < 0.0;
        let normal_matrix = Mat3::from_mat4(instance.world).inverse().transpose();
        let world_bits = instance.world.to_cols_array().map(f32::to_bits);

        for (p, primitive) in mesh.primitives.iter().enumerate() {
            let mode = match primitive.mode {
                Checked::Valid(mode @ (Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan)) => mode,
                other => {
                    let name = match other {
                        Checked::Valid(mode) => format!("{mode:?}"),
                        Checked::Invalid => "(invalid)".to_string(),
                    };
                    *self.skipped_modes.entry(name).or_insert(0) += 1;
                    continue;
                }
            };
            let attribute = |semantic: Semantic| primitive.attributes.get(&Checked::Valid(semantic)).map(|a| a.value());
            let Some(position_accessor) = attribute(Semantic::Positions) else {
                return Err(MeshError::gltf(self.path, format!("mesh {mesh_label} primitive {p} has no POSITION")));
            };
            let key: VertexKey = [
                Some(position_accessor),
                attribute(Semantic::Normals),
                attribute(Semantic::TexCoords(0)),
                attribute(Semantic::Colors(0)),
                attribute(Semantic::TexCoords(1)),
            ];
            // Vertices placed before (a shared pool) are neither decoded nor pushed again.
            let placed = (key, world_bits);
            let vertices = match self.placed_vertices.get(&placed) {
                Some(&(base, count)) => Vertices::Placed { base, count },
                None => Vertices::New(self.read_vertices(&key, &mesh_label, p, warnings)?),
            };
            let vertex_count = match &vertices {
                Vertices::Placed { count, .. } => *count as usize,
                Vertices::New(local) => local.positions.len(),
            };

            // Indices: explicit or implicit 0..n, then range-checked before use.
            let local_indices = match primitive.indices {
                Some(accessor) => read_indices(self.root, accessor.value(), self.buffers)
                    .map_err(|e| MeshError::gltf(self.path, format!("mesh {mesh_label} primitive {p} indices: {e}")))?,
                None => (0..vertex_count as u32).collect(),
            };
            if let Some((position, &index)) = local_indices.iter().enumerate().find(|(_, &i)| i as usize >= vertex_count) {
                return Err(MeshError::IndexOutOfRange {
                    path: self.path.to_path_buf(),
                    mesh: mesh_label,
                    primitive: p,
                    index,
                    position,
                    vertex_count,
                });
            }
            let (triangles, leftover) = triangulate(mode, &local_indices);
            if leftover > 0 {
                warnings
                    .push(format!("mesh {mesh_label} primitive {p}: {leftover} trailing indices do not form a triangle and were ignored"));
            }
            if triangles.is_empty() {
                continue;
            }

            let base = match vertices {
                Vertices::Placed { base, .. } => base,
                Vertices::New(local) => {
                    let base = self.push_vertices(&local, &instance.world, &normal_matrix)?;
                    self.placed_vertices.insert(placed, (base, vertex_count as u32));
                    base
                }
            };
            let material = self.material_index(primitive.material.map(|m| m.value()))?;
            let group = self.builder.group_index(&group_name);
            self.builder.reserve(0, triangles.len());
            for [a, b, c] in triangles {
                let corners = if flip_winding { [a, c, b] } else { [a, b, c] };
                self.builder.push_triangle(corners.map(|i| base + i), material, group);
            }
        }
        Ok(())
    }

    /// Decodes POSITION (refusing non-finite values) and the optional NORMAL,
    /// TEXCOORD_0, COLOR_0 and TEXCOORD_1 (the lightmap's; dropped with a
    /// warning when their count differs).
    fn read_vertices(&self, key: &VertexKey, mesh_label: &str, p: usize, warnings: &mut Vec<String>) -> Result<LocalVertices, MeshError> {
        let context = |what: &str, e: String| MeshError::gltf(self.path, format!("mesh {mesh_label} primitive {p} {what}: {e}"));
        let [position_accessor, normal_accessor, uv_accessor, color_accessor, lightmap_accessor] = *key;
        let (flat, _) =
            read_floats(self.root, position_accessor.unwrap_or(usize::MAX), self.buffers, &[3]).map_err(|e| context("POSITION", e))?;
        let positions: Vec<Vec3> = flat.chunks_exact(3).map(Vec3::from_slice).collect();
        if let Some((v, p_bad)) = positions.iter().enumerate().find(|(_, q)| !q.is_finite()) {
            return Err(MeshError::NonFinitePosition {
                path: self.path.to_path_buf(),
                vertex: format!("mesh {mesh_label} primitive {p} vertex {v}"),
                position: p_bad.to_array(),
            });
        }
        let n = positions.len();
        let mut optional = |accessor: Option<usize>, name: &str, allowed: &[usize]| -> Result<Option<(Vec<f32>, usize)>, MeshError> {
            let Some(accessor) = accessor else { return Ok(None) };
            let (values, components) = read_floats(self.root, accessor, self.buffers, allowed).map_err(|e| context(name, e))?;
            if values.len() != n * components {
                warnings.push(format!(
                    "mesh {mesh_label} primitive {p}: {name} has {} elements for {n} vertices; ignored",
                    values.len() / components
                ));
                return Ok(None);
            }
            Ok(Some((values, components)))
        };
        let normals = optional(normal_accessor, "NORMAL", &[3])?.map(|(v, _)| v.chunks_exact(3).map(Vec3::from_slice).collect());
        // Set 0 on set 1's accessor is how a mesh with a lightmap atlas and no
        // texture coordinates is written (glTF wants set 0 first): none.
        let uv_accessor = uv_accessor.filter(|&a| Some(a) != lightmap_accessor);
        let uvs = optional(uv_accessor, "TEXCOORD_0", &[2])?.map(|(v, _)| v.chunks_exact(2).map(Vec2::from_slice).collect());
        let colors = optional(color_accessor, "COLOR_0", &[3, 4])?.map(|(v, k)| v.chunks_exact(k).map(|c| [c[0], c[1], c[2]]).collect());
        let lightmap_uvs = optional(lightmap_accessor, "TEXCOORD_1", &[2])?.map(|(v, _)| v.chunks_exact(2).map(Vec2::from_slice).collect());
        Ok(LocalVertices { positions, normals, uvs, lightmap_uvs, colors })
    }

    /// Transforms and appends a primitive's vertices; returns the index of the first.
    fn push_vertices(&mut self, local: &LocalVertices, world: &Mat4, normal_matrix: &Mat3) -> Result<u32, MeshError> {
        let base = self.builder.vertex_count();
        let Some(base_u32) = base.checked_add(local.positions.len()).and_then(|end| u32::try_from(end).ok()).map(|_| base as u32) else {
            return Err(MeshError::TooLarge { path: self.path.to_path_buf(), message: "more than 2^32 vertices after instancing".into() });
        };
        self.builder.reserve(local.positions.len(), 0);
        for (i, &position) in local.positions.iter().enumerate() {
            // Made unit (or, from a singular transform, recomputed) by the
            // builder's normal repair, which keeps an already unit normal bit for bit.
            let normal = local.normals.as_ref().and_then(|n| n.get(i)).map(|&n| *normal_matrix * n);
            let uv = local.uvs.as_ref().and_then(|u| u.get(i)).copied();
            let color = local.colors.as_ref().and_then(|c| c.get(i)).copied();
            self.builder.push_vertex(world.transform_point3(position), normal, uv, color);
            self.builder.push_lightmap_uv(local.lightmap_uvs.as_ref().and_then(|u| u.get(i)).copied());
        }
        Ok(base_u32)
    }

    /// The mesh material index for glTF material `material` (or the default one).
    fn material_index(&mut self, material: Option<usize>) -> Result<u16, MeshError> {
        if let Some(index) = material {
            return u16::try_from(index).map_err(|_| MeshError::TooLarge {
                path: self.path.to_path_buf(),
                message: format!("material {index} is past the u16 material limit"),
            });
        }
        if let Some(index) = self.default_material {
            return Ok(index);
        }
        let index = self.builder.push_material(Material::opaque("default", DEFAULT_ALBEDO)).ok_or_else(|| MeshError::TooLarge {
            path: self.path.to_path_buf(),
            message: "too many materials for u16 material indices".into(),
        })?;
        self.default_material = Some(index);
        Ok(index)
    }
}

/// Turns a primitive's index list into triangles (glTF spec, "Primitive topologies").
/// Returns the triangles and how many trailing indices were left over.
fn triangulate(mode: Mode, indices: &[u32]) -> (Vec<[u32; 3]>, usize) {
    let n = indices.len();
    let corner = |i: usize| indices.get(i).copied().unwrap_or(0);
    match mode {
        Mode::TriangleStrip if n >= 3 => {
            // Triangle i is {v_i, v_(i+1+i%2), v_(i+2-i%2)}: keeps one winding throughout.
            let triangles = (0..n - 2).map(|i| [corner(i), corner(i + 1 + i % 2), corner(i + 2 - i % 2)]).collect();
            (triangles, 0)
        }
        Mode::TriangleFan if n >= 3 => ((0..n - 2).map(|i| [corner(i + 1), corner(i + 2), corner(0)]).collect(), 0),
        Mode::TriangleStrip | Mode::TriangleFan => (Vec::new(), n),
        _ => (indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(), n % 3),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_and_fans_keep_one_winding() {
        let (strip, left) = triangulate(Mode::TriangleStrip, &[0, 1, 2, 3, 4]);
        assert_eq!((strip, left), (vec![[0, 1, 2], [1, 3, 2], [2, 3, 4]], 0));
        let (fan, _) = triangulate(Mode::TriangleFan, &[0, 1, 2, 3]);
        assert_eq!(fan, vec![[1, 2, 0], [2, 3, 0]]);
        assert_eq!(triangulate(Mode::Triangles, &[0, 1, 2, 3]), (vec![[0, 1, 2]], 1));
        assert_eq!(triangulate(Mode::TriangleFan, &[0, 1]), (vec![], 2));
    }
}
