//! Wavefront OBJ loading via tobj (triangulated, single index) into one flat [`Mesh`].
//!
//! Text that is not UTF-8 but has no NUL byte is read as Latin-1 (old exporters
//! write names that way), with a warning; NUL bytes (UTF-16, binary) are refused.
//! Before tobj sees the file, a light pre-scan checks what tobj would trip on or
//! report vaguely: NaN/infinite vertex positions
//! (named by vertex number and line) and face indices outside the elements defined
//! so far (tobj does unchecked `index * 2 + 1` arithmetic on them, which overflows).
//! tobj gives each object/material block its own copy of the vertices it uses;
//! a vertex identical in every attribute across blocks is one vertex again, so
//! `write_obj` → `load_mesh` keeps the vertex count (and a cleaned mesh bakes
//! the same through OBJ as inline). OBJ `l` polylines are skipped with a warning.
//! A missing or broken `.mtl` is not fatal: parts fall back to a default grey
//! material and a warning says why.

use std::borrow::Cow;
use std::cell::RefCell;
use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};

use super::builder::MeshBuilder;
use super::{Material, MaterialRole, Mesh, MeshError, UpAxis, DEFAULT_ALBEDO};

/// `.mtl` keys written by `write_obj` to keep prtbake's material role and glass
/// transmittance (other tools ignore unknown keys; tobj keeps them).
pub(crate) const MTL_ROLE_KEY: &str = "prtbake_role";
pub(crate) const MTL_TRANSMITTANCE_KEY: &str = "prtbake_transmittance";

/// Loads an OBJ file already read into `bytes`; `.mtl` files are read relative to
/// `path`'s folder. Positions and normals are rotated to +Y up when `up` is `Z`.
pub(crate) fn load_obj(
    path: &Path,
    bytes: &[u8],
    up: UpAxis,
    warnings: &mut Vec<String>,
    sources: &mut Vec<PathBuf>,
) -> Result<Mesh, MeshError> {
    let (text, latin1) = decode_text(bytes).map_err(|e| MeshError::obj(path, e))?;
    if latin1 {
        warnings.push("the file is not UTF-8; it was read as Latin-1".to_string());
    }
    let Prescan { used_materials: material_names_used, polylines } = prescan(path, &text)?;
    // tobj reads `l 1 2 3` as a triangle: polylines have no area, so they are
    // blanked (keeping line numbers) and skipped, as glTF line primitives are.
    let text = if polylines.is_empty() { text } else { Cow::Owned(blank_lines(&text, &polylines)) };
    if !polylines.is_empty() {
        warnings.push(format!(
            "{} polyline statement(s) (`l`, first at line {}) skipped: lines have no surface to bake",
            polylines.len(),
            polylines[0] + 1
        ));
    }
    let base_dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let mtl_warnings = RefCell::new(Vec::new());
    let mtl_sources = RefCell::new(Vec::new());
    let options = tobj::LoadOptions { triangulate: true, single_index: true, ignore_points: true, ignore_lines: true };
    let (models, tobj_materials) = tobj::load_obj_buf(&mut std::io::Cursor::new(text.as_bytes()), &options, |mtl_path| {
        let mtl_file = base_dir.join(mtl_path);
        mtl_sources.borrow_mut().push(mtl_file.clone());
        let result = load_mtl(&mtl_file).and_then(|parsed| parsed.map_err(|e| e.to_string()));
        if let Err(e) = &result {
            mtl_warnings
                .borrow_mut()
                .push(format!("material library {} could not be loaded ({e}); its parts use a default grey material", mtl_path.display()));
        }
        result.map_err(|_| tobj::LoadError::GenericFailure)
    })
    .map_err(|e| MeshError::obj(path, describe_tobj_error(&text, &e)))?;
    warnings.extend(mtl_warnings.into_inner());
    sources.extend(mtl_sources.into_inner());
    // Errors were reported as they happened, above.
    let tobj_materials = tobj_materials.unwrap_or_default();

    let materials: Vec<Material> = tobj_materials.iter().map(convert_material).collect();
    if u16::try_from(materials.len()).is_err() {
        return Err(MeshError::TooLarge {
            path: path.to_path_buf(),
            message: format!("{} materials exceed the u16 limit", materials.len()),
        });
    }
    let material_count = materials.len();
    let mut builder = MeshBuilder::new(materials);
    let mut default_material = None;
    let mut unresolved = false;
    let mut first_vertex: HashMap<VertexKey, u32> = HashMap::new();

    for model in &models {
        let mesh = &model.mesh;
        let n = mesh.positions.len() / 3;
        if mesh.indices.is_empty() {
            continue;
        }
        let material = match mesh.material_id.filter(|&m| m < material_count) {
            Some(m) => m as u16, // < material_count <= u16::MAX + 1, checked above
            None => {
                unresolved = true;
                match default_material {
                    Some(index) => index,
                    None => {
                        let index = builder.push_material(Material::opaque("default", DEFAULT_ALBEDO)).ok_or_else(|| {
                            MeshError::TooLarge { path: path.to_path_buf(), message: "too many materials for u16 material indices".into() }
                        })?;
                        default_material = Some(index);
                        index
                    }
                }
            }
        };
        let group = builder.group_index(if model.name.is_empty() { "unnamed" } else { &model.name });
        // tobj emits an attribute only for vertices that name one: partial data cannot be aligned.
        let normals = (mesh.normals.len() == 3 * n).then_some(&mesh.normals);
        if normals.is_none() && !mesh.normals.is_empty() {
            warnings.push(format!("object '{}': only some vertices have normals; all were recomputed", model.name));
        }
        let uvs = (mesh.texcoords.len() == 2 * n).then_some(&mesh.texcoords);
        let colors = (mesh.vertex_color.len() == 3 * n).then_some(&mesh.vertex_color);

        if builder.vertex_count().checked_add(n).and_then(|end| u32::try_from(end).ok()).is_none() {
            return Err(MeshError::TooLarge { path: path.to_path_buf(), message: "more than 2^32 vertices".into() });
        }
        builder.reserve(n, mesh.indices.len() / 3);
        let mut local_to_global = Vec::with_capacity(n);
        for v in 0..n {
            let vec3 = |values: &Vec<f32>| Vec3::new(values[3 * v], values[3 * v + 1], values[3 * v + 2]);
            let position = up.to_y_up(vec3(&mesh.positions));
            let normal = normals.map(|values| up.to_y_up(vec3(values)));
            let uv = uvs.map(|values| Vec2::new(values[2 * v], values[2 * v + 1]));
            let color = colors.map(|values| vec3(values).to_array());
            // tobj gives each object/material block its own vertices: a vertex the
            // file shares between blocks (same position, normal, uv, colour) is
            // one vertex again, as it is in the file and in a GLB of the same mesh.
            let key = VertexKey::new(position, normal, uv, color);
            let next = builder.vertex_count() as u32;
            let index = *first_vertex.entry(key).or_insert(next);
            if index == next {
                builder.push_vertex(position, normal, uv, color);
            }
            local_to_global.push(index);
        }
        for triangle in mesh.indices.chunks_exact(3) {
            if triangle.iter().any(|&i| i as usize >= n) {
                return Err(MeshError::obj(path, format!("object '{}' has a face index past its {n} vertices", model.name)));
            }
            builder.push_triangle([triangle[0], triangle[1], triangle[2]].map(|i| local_to_global[i as usize]), material, group);
        }
    }
    if unresolved && !material_names_used.is_empty() {
        let known: BTreeSet<&str> = tobj_materials.iter().map(|m| m.name.as_str()).collect();
        let missing: Vec<&str> = material_names_used.iter().map(String::as_str).filter(|name| !known.contains(name)).collect();
        if !missing.is_empty() {
            warnings.push(format!("materials not found in any loaded .mtl, replaced by default grey: {}", missing.join(", ")));
        }
    }
    builder.finish(path, warnings)
}

/// A vertex's attributes bit for bit, to find the same vertex in two blocks.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
struct VertexKey {
    position: [u32; 3],
    normal: Option<[u32; 3]>,
    uv: Option<[u32; 2]>,
    color: Option<[u32; 3]>,
}

impl VertexKey {
    fn new(position: Vec3, normal: Option<Vec3>, uv: Option<Vec2>, color: Option<[f32; 3]>) -> VertexKey {
        VertexKey {
            position: position.to_array().map(f32::to_bits),
            normal: normal.map(|n| n.to_array().map(f32::to_bits)),
            uv: uv.map(|t| t.to_array().map(f32::to_bits)),
            color: color.map(|c| c.map(f32::to_bits)),
        }
    }
}

/// Reads and parses a `.mtl` file with the same text rules as the OBJ.
fn load_mtl(path: &Path) -> Result<tobj::MTLLoadResult, String> {
    let bytes = crate::files::read_limited(path, crate::files::Limit::Materials).map_err(|e| e.to_string())?;
    let (text, _) = decode_text(&bytes)?;
    Ok(tobj::load_mtl_buf(&mut std::io::Cursor::new(text.as_bytes())))
}

/// The file as text: UTF-8 as is; otherwise Latin-1 (flag `true`) unless it has
/// NUL bytes, which mean UTF-16 or binary data.
fn decode_text(bytes: &[u8]) -> Result<(Cow<'_, str>, bool), String> {
    if let Ok(text) = std::str::from_utf8(bytes) {
        return Ok((Cow::Borrowed(text), false));
    }
    if let Some(at) = bytes.iter().position(|&b| b == 0) {
        return Err(format!("byte {at} is NUL: not a text file (UTF-16 or binary?)"));
    }
    Ok((Cow::Owned(bytes.iter().map(|&b| b as char).collect()), true))
}

/// OBJ `Kd` (default 0.8 grey) and prtbake's role keys, if present.
fn convert_material(material: &tobj::Material) -> Material {
    let albedo = material.diffuse.filter(|kd| kd.iter().all(|c| c.is_finite())).unwrap_or([DEFAULT_ALBEDO; 3]);
    let role = match material.unknown_param.get(MTL_ROLE_KEY).map(|s| s.trim()) {
        Some("window") => MaterialRole::Window,
        Some("panel") => MaterialRole::Panel,
        _ => MaterialRole::Opaque,
    };
    let transmittance = material
        .unknown_param
        .get(MTL_TRANSMITTANCE_KEY)
        .and_then(|s| s.trim().parse::<f32>().ok())
        .filter(|t| t.is_finite())
        .unwrap_or(1.0);
    Material { name: material.name.clone(), albedo, role, transmittance }
}

/// What the pre-scan found besides errors.
struct Prescan {
    /// Material names `usemtl` asks for.
    used_materials: BTreeSet<String>,
    /// 0-based indices of `l` (polyline) lines.
    polylines: Vec<usize>,
}

/// `text` with the given 0-based lines emptied (line breaks kept).
fn blank_lines(text: &str, lines: &[usize]) -> String {
    let mut out = String::with_capacity(text.len());
    let mut next = lines.iter().peekable();
    for (index, line) in text.split('\n').enumerate() {
        if index > 0 {
            out.push('\n');
        }
        if next.peek() == Some(&&index) {
            next.next();
        } else {
            out.push_str(line);
        }
    }
    out
}

/// tobj's error with the line it comes from: tobj reports only the kind, so
/// the first line its rule for that kind rejects is found again here.
fn describe_tobj_error(text: &str, error: &tobj::LoadError) -> String {
    use tobj::LoadError as E;
    let floats = |words: &[&str], n: usize| words.len() >= n && words[..n].iter().all(|w| w.parse::<f32>().is_ok());
    let corner_ok = |corner: &str| {
        let mut parts = corner.split('/');
        parts.next().is_some_and(|v| v.parse::<isize>().is_ok()) && parts.all(|p| p.is_empty() || p.parse::<isize>().is_ok())
    };
    let rejects = |keyword: &str, words: &[&str]| match (error, keyword) {
        (E::PositionParseError, "v") => !floats(words, 3),
        (E::ColorParseError, "v") => !(words.len() == 3 || words.len() == 4 || (words.len() == 6 && floats(words, 6))),
        (E::TexcoordParseError, "vt") => !floats(words, 2),
        (E::NormalParseError, "vn") => !floats(words, 3),
        (E::FaceParseError, "f") => !words.iter().all(|c| corner_ok(c)),
        _ => false,
    };
    for (index, line) in text.split('\n').enumerate() {
        let mut words = line.split_whitespace();
        let Some(keyword) = words.next() else { continue };
        let rest: Vec<&str> = words.collect();
        if rejects(keyword, &rest) {
            return format!("line {}: {error} in {:?}", index + 1, line.trim());
        }
    }
    error.to_string()
}

/// Checks the text before tobj parses it.
fn prescan(path: &Path, text: &str) -> Result<Prescan, MeshError> {
    let mut counts = [0usize; 3]; // v, vt, vn defined so far
    let mut used_materials = BTreeSet::new();
    let mut polylines = Vec::new();
    for (line_index, line) in text.split('\n').enumerate() {
        let line_number = line_index + 1;
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                counts[0] += 1;
                let xyz: Vec<f32> = words.take(3).filter_map(|w| w.parse().ok()).collect();
                if xyz.len() == 3 && xyz.iter().any(|c| !c.is_finite()) {
                    return Err(MeshError::NonFinitePosition {
                        path: path.to_path_buf(),
                        vertex: format!("vertex {} (line {line_number})", counts[0]),
                        position: [xyz[0], xyz[1], xyz[2]],
                    });
                }
            }
            Some("vt") => counts[1] += 1,
            Some("vn") => counts[2] += 1,
            Some("l") => polylines.push(line_index),
            Some("f") => {
                for corner in words {
                    check_face_corner(corner, &counts).map_err(|e| MeshError::obj(path, format!("line {line_number}: {e}")))?;
                }
            }
            Some("usemtl") => {
                let name = line.trim_start().split_once(' ').map_or("", |(_, rest)| rest.trim());
                if !name.is_empty() {
                    used_materials.insert(name.to_string());
                }
            }
            _ => {}
        }
    }
    Ok(Prescan { used_materials, polylines })
}

/// Checks one face corner `v[/vt[/vn]]` against the element counts so far. Numbers
/// tobj cannot parse are left for tobj to report.
fn check_face_corner(corner: &str, counts: &[usize; 3]) -> Result<(), String> {
    const KINDS: [&str; 3] = ["vertex", "texture coordinate", "normal"];
    for (k, part) in corner.split('/').enumerate().take(3) {
        let Ok(value) = part.parse::<isize>() else { continue };
        let count = counts[k];
        // tobj ignores vt/vn references when the file has none of them at all.
        if k > 0 && count == 0 {
            continue;
        }
        if value == 0 || value.unsigned_abs() > count {
            return Err(format!("face refers to {} {value}, but only {count} are defined before it", KINDS[k]));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(text: &str) -> Result<(Mesh, Vec<String>), MeshError> {
        let mut warnings = Vec::new();
        let mesh = load_obj(Path::new("t.obj"), text.as_bytes(), UpAxis::Y, &mut warnings, &mut Vec::new())?;
        Ok((mesh, warnings))
    }

    #[test]
    fn polylines_are_skipped_not_baked_as_triangles() {
        let vertices = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n";
        let only_lines = format!("{vertices}l 1 2 3\nl 2 3 4\nl 1 2\nl 3 4 1 2\nl 1 3\nl 2 4\n");
        let e = load(&only_lines).unwrap_err().to_string();
        assert!(e.contains("no triangles"), "{e}");
        let (mesh, warnings) = load(&format!("{vertices}l 1 2 3 4\nf 1 2 3\n")).unwrap();
        assert_eq!(mesh.triangle_count(), 1);
        assert!(warnings.iter().any(|w| w.contains("1 polyline statement(s) (`l`, first at line 5) skipped")), "{warnings:?}");
    }

    #[test]
    fn tobj_errors_name_their_line() {
        let cases = [
            ("v 0 0 0\nv 1 x 0\nv 0 1 0\nf 1 2 3\n", "line 2: "),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0\nf 1 2 3\n", "line 4: "),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 1\nf 1 2 3\n", "line 4: "),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 a 3\n", "line 5: "),
            ("v 0 0 0\nv 1 0 0 1 1\nv 0 1 0\nf 1 2 3\n", "line 2: "),
        ];
        for (text, needle) in cases {
            let e = load(text).err().unwrap_or_else(|| panic!("{text:?} loaded")).to_string();
            assert!(e.contains(needle), "{text:?}: {e}");
        }
    }

    #[test]
    fn face_corners_are_checked_against_counts_so_far() {
        assert!(check_face_corner("3/1/2", &[3, 1, 2]).is_ok());
        assert!(check_face_corner("-3//-2", &[3, 0, 2]).is_ok());
        assert!(check_face_corner("4", &[3, 0, 0]).unwrap_err().contains("vertex 4"));
        assert!(check_face_corner("1/-2", &[3, 1, 0]).unwrap_err().contains("texture coordinate -2"));
        assert!(check_face_corner("0", &[3, 0, 0]).is_err());
        // Huge values that would overflow tobj's arithmetic.
        assert!(check_face_corner("1/9223372036854775807/1", &[1, 1, 1]).is_err());
        assert!(check_face_corner("1/-9223372036854775807", &[1, 1, 0]).is_err());
    }
}
