//! Tests of `load_mesh` and the writers on tiny files generated in a temp dir.

use std::path::{Path, PathBuf};

use base64::Engine;
use glam::{Mat4, Quat, Vec2, Vec3};
use serde_json::{json, Value};

use super::write::assemble_glb;
use super::*;

/// Positions written as decimal text by hand are exact in f32 at this tolerance.
const EPS: f32 = 1e-5;

fn write_file(dir: &Path, name: &str, contents: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, contents).unwrap();
    path
}

fn load(path: &Path) -> Result<LoadedMesh, MeshError> {
    load_mesh(path, &LoadOptions::default())
}

/// Unit cube centred at the origin, quads wound counter-clockwise seen from outside.
const CUBE_OBJ: &str = "o cube
v -0.5 -0.5 0.5
v -0.5 -0.5 -0.5
v -0.5 0.5 -0.5
v -0.5 0.5 0.5
v 0.5 -0.5 0.5
v 0.5 -0.5 -0.5
v 0.5 0.5 -0.5
v 0.5 0.5 0.5
f 4 3 2 1
f 2 6 5 1
f 3 7 6 2
f 8 7 3 4
f 5 8 4 1
f 6 7 8 5
";

/// Outward geometric normal of triangle `t`.
fn face_normal(mesh: &Mesh, t: usize) -> Vec3 {
    let [a, b, c] = mesh.triangle_positions(t);
    (b - a).cross(c - a).normalize()
}

#[test]
fn obj_cube_without_normals_gets_outward_unit_normals() {
    let dir = tempfile::tempdir().unwrap();
    let loaded = load(&write_file(dir.path(), "cube.obj", CUBE_OBJ)).unwrap();
    let mesh = &loaded.mesh;
    assert_eq!(mesh.triangle_count(), 12);
    assert_eq!(mesh.vertex_count(), 8);
    assert_eq!(mesh.groups, vec!["cube"]);
    // No material at all: one default 0.8 grey material.
    assert_eq!(mesh.materials, vec![Material::opaque("default", DEFAULT_ALBEDO)]);
    for (p, n) in mesh.positions.iter().zip(&mesh.normals) {
        // Angle-and-area weighting gives exactly the corner diagonal on a cube.
        assert!((n.length() - 1.0).abs() < EPS);
        assert!((*n - p.normalize()).length() < EPS, "normal {n} at {p}");
    }
    for t in 0..12 {
        let [a, b, c] = mesh.triangle_positions(t);
        assert!(face_normal(mesh, t).dot((a + b + c) / 3.0) > 0.0, "triangle {t} faces inward");
    }
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
}

#[test]
fn obj_z_up_is_rotated_to_y_up_keeping_winding() {
    let dir = tempfile::tempdir().unwrap();
    // A triangle in the z = 1 plane facing +Z (up in a Z-up file).
    let path = write_file(dir.path(), "zup.obj", "v 0 0 1\nv 1 0 1\nv 0 1 1\nvn 0 0 1\nf 1//1 2//1 3//1\n");
    let mesh = load_mesh(&path, &LoadOptions { up: UpAxis::Z }).unwrap().mesh;
    assert_eq!(mesh.positions, vec![Vec3::new(0., 1., 0.), Vec3::new(1., 1., 0.), Vec3::new(0., 1., -1.)]);
    assert_eq!(mesh.normals, vec![Vec3::Y; 3]);
    assert!((face_normal(&mesh, 0) - Vec3::Y).length() < EPS, "winding no longer matches the normal");
}

#[test]
fn obj_missing_mtl_gives_default_material_and_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_file(dir.path(), "m.obj", "mtllib nowhere.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl Red\nf 1 2 3\n");
    let loaded = load(&path).unwrap();
    assert_eq!(loaded.mesh.materials.len(), 1);
    assert_eq!(loaded.mesh.materials[0].albedo, [DEFAULT_ALBEDO; 3]);
    let text = loaded.warnings.join("\n");
    assert!(text.contains("nowhere.mtl") && text.contains("Red"), "{text}");
}

#[test]
fn nan_and_infinite_vertices_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let obj = write_file(dir.path(), "nan.obj", "v 0 0 0\n# comment\nv NaN 0 0\nv 0 1 0\nf 1 2 3\n");
    let message = load(&obj).unwrap_err().to_string();
    assert!(message.contains("nan.obj") && message.contains("vertex 2 (line 3)") && message.contains("non-finite"), "{message}");

    let doc = gltf_doc(&[[0., 0., 0.], [1., 0., 0.], [0., f32::INFINITY, 0.]], &[0, 1, 2], json!([{"mesh": 0}]));
    let gltf = write_file(dir.path(), "inf.gltf", doc.to_string());
    let message = load(&gltf).unwrap_err().to_string();
    assert!(message.contains("mesh 'tri' (0) primitive 0 vertex 2") && message.contains("inf"), "{message}");
}

#[test]
fn empty_and_unknown_files_are_refused_with_the_path() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["empty.obj", "empty.gltf", "empty.glb"] {
        let path = write_file(dir.path(), name, "");
        let message = load(&path).unwrap_err().to_string();
        assert!(message.starts_with(&path.display().to_string()), "{message}");
    }
    assert!(matches!(load(&dir.path().join("empty.obj")), Err(MeshError::Empty { .. })));
    // Only points and lines: no triangles.
    let lines = write_file(dir.path(), "lines.obj", "v 0 0 0\nv 1 0 0\nl 1 2\np 1\n");
    assert!(matches!(load(&lines), Err(MeshError::Empty { .. })));

    let stl = write_file(dir.path(), "part.stl", "solid x");
    let message = load(&stl).unwrap_err().to_string();
    assert!(message.contains("part.stl") && message.contains("unsupported mesh format \"stl\""), "{message}");
    let missing = dir.path().join("absent.glb");
    let message = load(&missing).unwrap_err().to_string();
    assert!(message.contains("absent.glb: cannot read"), "{message}");
}

#[test]
fn unknown_required_gltf_extension_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = gltf_doc(&TRIANGLE, &[0, 1, 2], json!([{"mesh": 0}]));
    doc["extensionsRequired"] = json!(["KHR_materials_transmission", "EXT_future_geometry"]);
    let path = write_file(dir.path(), "ext.gltf", doc.to_string());
    let message = load(&path).unwrap_err().to_string();
    assert!(message.contains("requires extension EXT_future_geometry, which prtbake does not support"), "{message}");
}

// ---- glTF generation ----

const TRIANGLE: [[f32; 3]; 3] = [[0., 0., 0.], [1., 0., 0.], [0., 1., 0.]];

fn floats_to_bytes(values: impl IntoIterator<Item = f32>) -> Vec<u8> {
    values.into_iter().flat_map(f32::to_le_bytes).collect()
}

/// A glTF document with one mesh `tri` (positions, +Z normals, u32 indices) in a
/// base64 data URI, scene 0 listing every node without a parent.
fn gltf_doc(positions: &[[f32; 3]], indices: &[u32], nodes: Value) -> Value {
    let mut bytes = floats_to_bytes(positions.iter().flatten().copied());
    let normal_offset = bytes.len();
    bytes.extend(floats_to_bytes(positions.iter().flat_map(|_| [0.0, 0.0, 1.0])));
    let index_offset = bytes.len();
    bytes.extend(indices.iter().flat_map(|i| i.to_le_bytes()));
    let n = positions.len();
    let children: Vec<u64> = nodes
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|n| n["children"].as_array().cloned().unwrap_or_default())
        .filter_map(|c| c.as_u64())
        .collect();
    let roots: Vec<usize> = (0..nodes.as_array().unwrap().len()).filter(|i| !children.contains(&(*i as u64))).collect();
    json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": roots}],
        "nodes": nodes,
        "meshes": [{"name": "tri", "primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2, "material": 0}]}],
        "materials": [{"name": "Glass", "pbrMetallicRoughness": {"baseColorFactor": [0.1, 0.2, 0.3, 1.0]},
                       "extensions": {"KHR_materials_transmission": {"transmissionFactor": 0.75}}}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": n, "type": "VEC3"},
            {"bufferView": 0, "byteOffset": normal_offset, "componentType": 5126, "count": n, "type": "VEC3"},
            {"bufferView": 0, "byteOffset": index_offset, "componentType": 5125, "count": indices.len(), "type": "SCALAR"}
        ],
        "bufferViews": [{"buffer": 0, "byteLength": bytes.len()}],
        "buffers": [{"byteLength": bytes.len(),
                     "uri": format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(&bytes))}],
    })
}

#[test]
fn gltf_trs_node_with_two_instances_places_both_copies() {
    let dir = tempfile::tempdir().unwrap();
    let rotation = Quat::from_rotation_y(std::f32::consts::FRAC_PI_2);
    let nodes = json!([
        {"mesh": 0, "translation": [10.0, 0.0, 0.0]},
        {"translation": [0.0, 5.0, 0.0], "children": [2]},
        {"mesh": 0, "rotation": rotation.to_array(), "scale": [2.0, 2.0, 2.0]}
    ]);
    let path = write_file(dir.path(), "two.gltf", gltf_doc(&TRIANGLE, &[0, 1, 2], nodes).to_string());
    let loaded = load(&path).unwrap();
    let mesh = &loaded.mesh;
    assert_eq!(mesh.triangle_count(), 2);
    assert_eq!(mesh.groups, vec!["tri"]);
    assert_eq!(mesh.tri_group, vec![0, 0]);
    let first = Mat4::from_translation(Vec3::new(10., 0., 0.));
    let second =
        Mat4::from_translation(Vec3::new(0., 5., 0.)) * Mat4::from_scale_rotation_translation(Vec3::splat(2.), rotation, Vec3::ZERO);
    for (t, world) in [first, second].iter().enumerate() {
        let expected = TRIANGLE.map(|p| world.transform_point3(Vec3::from(p)));
        let got = mesh.triangle_positions(t);
        for k in 0..3 {
            assert!((got[k] - expected[k]).length() < EPS, "triangle {t} corner {k}: {} vs {}", got[k], expected[k]);
        }
        // The file's +Z normal follows the node rotation.
        let normal = world.transform_vector3(Vec3::Z).normalize();
        assert!((mesh.normals[mesh.triangle(t)[0] as usize] - normal).length() < EPS);
    }
    // Material: transmission > 0 makes a window.
    let glass = &mesh.materials[0];
    assert_eq!(
        (glass.name.as_str(), glass.role, glass.transmittance, glass.albedo),
        ("Glass", MaterialRole::Window, 0.75, [0.1, 0.2, 0.3])
    );
}

#[test]
fn gltf_materials_default_to_grey_and_primitives_without_one_share_a_default() {
    let dir = tempfile::tempdir().unwrap();
    let mut doc = gltf_doc(&TRIANGLE, &[0, 1, 2], json!([{"mesh": 0}, {"mesh": 1}]));
    doc["materials"][0] = json!({"name": "Plain"});
    let second = doc["meshes"][0]["primitives"][0].clone();
    doc["meshes"][0]["primitives"] = json!([second.clone(), second.clone()]);
    doc["meshes"][0]["primitives"][1].as_object_mut().unwrap().remove("material");
    doc["meshes"] = json!([doc["meshes"][0].clone(), {"primitives": [second]}]);
    let mesh = load(&write_file(dir.path(), "grey.gltf", doc.to_string())).unwrap().mesh;
    assert_eq!(mesh.materials, vec![Material::opaque("Plain", DEFAULT_ALBEDO), Material::opaque("default", DEFAULT_ALBEDO)]);
    assert_eq!(mesh.tri_material, vec![0, 1, 0]);
    // All three primitives (two glTF meshes, one node transform) share accessors,
    // so they share their 3 vertices.
    assert_eq!(mesh.vertex_count(), 3);
    assert_eq!(mesh.groups, vec!["tri", "mesh1"]);
    assert_eq!(mesh.tri_group, vec![0, 0, 1]);
}

#[test]
fn mirrored_instance_flips_winding() {
    let dir = tempfile::tempdir().unwrap();
    let nodes = json!([{"mesh": 0}, {"mesh": 0, "scale": [-1.0, 1.0, 1.0]}]);
    let path = write_file(dir.path(), "mirror.gltf", gltf_doc(&TRIANGLE, &[0, 1, 2], nodes).to_string());
    let mesh = load(&path).unwrap().mesh;
    assert_eq!(mesh.triangle_count(), 2);
    for t in 0..2 {
        // Winding (counter-clockwise front) agrees with the transformed +Z normal.
        let vertex_normal = mesh.normals[mesh.triangle(t)[0] as usize];
        assert!((face_normal(&mesh, t) - vertex_normal).length() < EPS, "triangle {t}");
        assert!((vertex_normal - Vec3::Z).length() < EPS);
    }
    assert_eq!(mesh.triangle(0), [0, 1, 2]);
    assert_eq!(mesh.triangle(1), [3, 5, 4]);
}

#[test]
fn gltf_out_of_range_index_is_refused_naming_mesh_and_primitive() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_file(dir.path(), "oor.gltf", gltf_doc(&TRIANGLE, &[0, 1, 3], json!([{"mesh": 0}])).to_string());
    let message = load(&path).unwrap_err().to_string();
    assert!(message.contains("mesh 'tri' (0) primitive 0: index 3 (at position 2) is out of range (3 vertices)"), "{message}");
}

#[test]
fn gltf_short_or_hostile_data_is_an_error_not_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    // Buffer declares more bytes than its data URI holds.
    let mut doc = gltf_doc(&TRIANGLE, &[0, 1, 2], json!([{"mesh": 0}]));
    doc["buffers"][0]["byteLength"] = json!(1000);
    let message = load(&write_file(dir.path(), "short.gltf", doc.to_string())).unwrap_err().to_string();
    assert!(message.contains("declares byteLength 1000 but holds only 84 bytes"), "{message}");
    // Accessor runs past its view.
    let mut doc = gltf_doc(&TRIANGLE, &[0, 1, 2], json!([{"mesh": 0}]));
    doc["accessors"][0]["count"] = json!(100);
    assert!(load(&write_file(dir.path(), "long.gltf", doc.to_string())).is_err());
    // POSITION refers to a missing accessor (the gltf crate's validation would index it).
    let mut doc = gltf_doc(&TRIANGLE, &[0, 1, 2], json!([{"mesh": 0}]));
    doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(99);
    let message = load(&write_file(dir.path(), "badpos.gltf", doc.to_string())).unwrap_err().to_string();
    assert!(message.contains("accessor 99, which does not exist"), "{message}");
    // GLB whose header length is below 12 (underflows in the gltf crate).
    let mut glb = assemble_glb(b"{}".to_vec(), Vec::new()).unwrap();
    glb[8..12].copy_from_slice(&4u32.to_le_bytes());
    assert!(load(&write_file(dir.path(), "tiny.glb", glb)).unwrap_err().to_string().contains("too small"));
    // External buffer that is missing: the message names the file.
    let mut doc = gltf_doc(&TRIANGLE, &[0, 1, 2], json!([{"mesh": 0}]));
    doc["buffers"][0]["uri"] = json!("gone.bin");
    let message = load(&write_file(dir.path(), "ext.gltf", doc.to_string())).unwrap_err().to_string();
    assert!(message.contains("gone.bin"), "{message}");
}

#[test]
fn gltf_external_buffer_is_read_relative_to_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let sub = dir.path().join("model");
    std::fs::create_dir(&sub).unwrap();
    let mut doc = gltf_doc(&TRIANGLE, &[0, 1, 2], json!([{"mesh": 0}]));
    let uri = doc["buffers"][0]["uri"].as_str().unwrap().to_string();
    let bytes = base64::engine::general_purpose::STANDARD.decode(uri.split_once(',').unwrap().1).unwrap();
    write_file(&sub, "data 1.bin", bytes);
    doc["buffers"][0]["uri"] = json!("data%201.bin");
    let path = write_file(&sub, "ext.gltf", doc.to_string());
    assert_eq!(load(&path).unwrap().mesh.triangle_count(), 1);
}

/// A GLB longer or shorter than its header's length is refused after its
/// header (20 bytes), as is a glTF buffer file shorter than its
/// `byteLength` (10¹⁵ here) before a byte of it is read: a 3 GiB sparse
/// file costs what its header does.
#[test]
fn sizes_are_checked_against_glb_headers_and_byte_lengths_before_reading() {
    use crate::files::read::bytes_read;
    let dir = tempfile::tempdir().unwrap();
    let big = 3u64 << 30;
    let grow = |path: &Path, len: u64| std::fs::OpenOptions::new().write(true).open(path).unwrap().set_len(len).unwrap();
    let glb = dir.path().join("grown.glb");
    let mut mesh = Mesh::default();
    mesh.positions.extend(TRIANGLE.map(Vec3::from));
    mesh.normals.extend([Vec3::Z; 3]);
    mesh.indices.extend([0, 1, 2]);
    mesh.tri_group.push(0);
    mesh.tri_material.push(0);
    mesh.materials.push(Material::opaque("grey", 0.5));
    mesh.groups.push("g".into());
    write_glb(&glb, &mesh).unwrap();
    let len = std::fs::metadata(&glb).unwrap().len();
    bytes_read::take();
    assert_eq!(load(&glb).unwrap().mesh.triangle_count(), 1);
    assert_eq!(bytes_read::take(), 20 + len);
    grow(&glb, big);
    let message = load(&glb).unwrap_err().to_string();
    assert_eq!(bytes_read::take(), 20);
    assert!(
        message.contains("grown.glb")
            && message.contains(&format!("declares {len} bytes but the file has {big}"))
            && message.contains("past its end"),
        "{message}"
    );
    grow(&glb, len - 4);
    let message = load(&glb).unwrap_err().to_string();
    assert_eq!(bytes_read::take(), 20);
    assert!(message.contains("GLB truncated"), "{message}");

    let bin = dir.path().join("big.bin");
    std::fs::File::create(&bin).unwrap().set_len(big).unwrap();
    let json = r#"{"asset":{"version":"2.0"},"buffers":[{"uri":"big.bin","byteLength":1000000000000000}]}"#;
    let gltf = write_file(dir.path(), "huge.gltf", json);
    let message = load(&gltf).unwrap_err().to_string();
    assert_eq!(bytes_read::take(), 20 + json.len() as u64, "the .gltf file read, not its buffer");
    assert!(message.contains("huge.gltf") && message.contains("byteLength 1000000000000000") && message.contains("big.bin"), "{message}");
}

// ---- writer round trips ----

/// A mesh in the writers' canonical order: triangles sorted by (group, material),
/// each (group, material) run using its own ascending vertex range (as tobj
/// re-indexes per run), with uvs and colours.
fn sample_mesh() -> Mesh {
    let mut mesh = Mesh::default();
    let quad = |z: f32| [Vec3::new(0.1, 0.2, z), Vec3::new(1.0 / 3.0, 0.0, z), Vec3::new(1.0, 1.0, z), Vec3::new(0.0, 1e-7, z)];
    for (run, (group, material)) in [(0u32, 0u16), (0, 1), (1, 1), (1, 2)].into_iter().enumerate() {
        let base = mesh.positions.len() as u32;
        mesh.positions.extend(quad(0.0 - 2.5 * run as f32));
        mesh.normals.extend([Vec3::Z; 4]);
        mesh.uvs.extend([Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(1.0, 1.0), Vec2::new(0.125, 1.0)]);
        // A lightmap chart per quad, side by side (TEXCOORD_1; GLB only).
        let corner = Vec2::new(0.25 * run as f32, 0.0);
        mesh.lightmap_uvs.extend([Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y].map(|c| corner + 0.2 * c));
        mesh.colors.extend([[1.0, 0.5, 0.25 * run as f32]; 4]);
        mesh.indices.extend([0, 1, 2, 0, 2, 3].map(|i| base + i));
        mesh.tri_group.extend([group; 2]);
        mesh.tri_material.extend([material; 2]);
    }
    mesh.groups = vec!["body".into(), "glass parts".into()];
    mesh.materials = vec![
        Material::opaque("Paint", 0.5),
        Material { name: "Glass_Gray".into(), albedo: [0.1, 0.2, 0.3], role: MaterialRole::Window, transmittance: 0.6 },
        Material { name: "Screen".into(), albedo: [0.05; 3], role: MaterialRole::Panel, transmittance: 1.0 },
    ];
    mesh.validate().unwrap();
    mesh
}

#[test]
fn glb_round_trip_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = sample_mesh();
    let path = dir.path().join("out.glb");
    write_glb(&path, &mesh).unwrap();
    let loaded = load(&path).unwrap();
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    assert_eq!(loaded.mesh, mesh);
    // The writer left no temp file behind.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    // A lightmap atlas without texture coordinates: glTF wants set 0 before
    // set 1, so set 0 is set 1's accessor, which reads back as none.
    let mut atlas_only = mesh.clone();
    atlas_only.uvs.clear();
    let path = dir.path().join("atlas-only.glb");
    write_glb(&path, &atlas_only).unwrap();
    let document = gltf::Gltf::open(&path).unwrap();
    for primitive in document.meshes().flat_map(|m| m.primitives().collect::<Vec<_>>()) {
        let set = |i: u32| primitive.get(&gltf::Semantic::TexCoords(i)).map(|a| a.index());
        assert!(set(0).is_some() && set(0) == set(1));
    }
    let loaded = load(&path).unwrap();
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    assert_eq!(loaded.mesh, atlas_only);
}

#[test]
fn obj_round_trip_keeps_positions_indices_materials_and_groups() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = sample_mesh();
    let path = dir.path().join("out.obj");
    write_obj(&path, &mesh).unwrap();
    assert!(dir.path().join("out.mtl").exists());
    let loaded = load(&path).unwrap();
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    let back = loaded.mesh;
    // tobj re-indexes per object and material run; in canonical order that is the identity.
    assert_eq!(back.positions, mesh.positions);
    assert_eq!(back.indices, mesh.indices);
    assert_eq!(back.normals, mesh.normals);
    assert_eq!(back.uvs, mesh.uvs);
    assert!(back.lightmap_uvs.is_empty(), "OBJ has one texture coordinate set");
    assert_eq!(back.colors, mesh.colors);
    assert_eq!(back.groups, mesh.groups);
    assert_eq!(back.tri_group, mesh.tri_group);
    assert_eq!(back.materials, mesh.materials);
    assert_eq!(back.tri_material, mesh.tri_material);
}

/// Out of canonical order, both writers still keep every triangle's corners,
/// material and group (the GLB writer sorts by group and material).
#[test]
fn round_trips_of_unsorted_meshes_keep_the_triangle_set() {
    let dir = tempfile::tempdir().unwrap();
    let mut mesh = sample_mesh();
    // Interleave groups and materials.
    let tris: Vec<[u32; 3]> = (0..8).map(|t| mesh.triangle(t)).collect();
    let order = [0, 4, 2, 6, 1, 5, 3, 7];
    mesh.indices = order.iter().flat_map(|&t| tris[t]).collect();
    mesh.tri_group = order.iter().map(|&t| mesh.tri_group[t]).collect();
    mesh.tri_material = order.iter().map(|&t| mesh.tri_material[t]).collect();
    let key = |m: &Mesh| {
        let mut triangles: Vec<String> = (0..m.triangle_count())
            .map(|t| {
                format!(
                    "{:?} {} {}",
                    m.triangle_positions(t),
                    m.groups[m.tri_group[t] as usize],
                    m.materials[m.tri_material[t] as usize].name
                )
            })
            .collect();
        triangles.sort();
        triangles
    };
    for name in ["u.glb", "u.obj"] {
        let path = dir.path().join(name);
        if name.ends_with("glb") {
            write_glb(&path, &mesh).unwrap()
        } else {
            write_obj(&path, &mesh).unwrap()
        }
        assert_eq!(key(&load(&path).unwrap().mesh), key(&mesh), "{name}");
    }
}

#[test]
fn writers_refuse_invalid_meshes() {
    let dir = tempfile::tempdir().unwrap();
    let mut mesh = sample_mesh();
    mesh.indices[0] = 99;
    let message = write_glb(&dir.path().join("bad.glb"), &mesh).unwrap_err().to_string();
    assert!(message.contains("bad.glb: cannot write this mesh"), "{message}");
    assert!(write_obj(&dir.path().join("bad.obj"), &mesh).is_err());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

/// Truncation at every length and a flip of every byte of a real GLB: each load
/// returns (mostly errors) without panicking.
#[test]
fn glb_truncations_and_byte_flips_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let source = dir.path().join("source.glb");
    write_glb(&source, &sample_mesh()).unwrap();
    let bytes = std::fs::read(&source).unwrap();
    let target = dir.path().join("mutated.glb");
    let mut loaded = 0;
    for len in 0..bytes.len() {
        std::fs::write(&target, &bytes[..len]).unwrap();
        loaded += usize::from(load(&target).is_ok());
    }
    assert_eq!(loaded, 0, "a truncated GLB loaded");
    for at in 0..bytes.len() {
        let mut mutated = bytes.clone();
        mutated[at] ^= 0xA5;
        std::fs::write(&target, &mutated).unwrap();
        if let Ok(result) = load(&target) {
            result.mesh.validate().unwrap();
        }
    }
}

/// Every byte of a written OBJ replaced by each of a few troublesome characters:
/// each load returns without panicking, and whatever loads is valid.
#[test]
fn obj_byte_substitutions_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let source = dir.path().join("source.obj");
    write_obj(&source, &sample_mesh()).unwrap();
    let bytes = std::fs::read(&source).unwrap();
    let target = dir.path().join("mutated.obj");
    for at in 0..bytes.len() {
        for replacement in [b'-', b'0', b'9', b'/', b' ', b'\n', 0xFF] {
            let mut mutated = bytes.clone();
            mutated[at] = replacement;
            std::fs::write(&target, &mutated).unwrap();
            if let Ok(result) = load(&target) {
                result.mesh.validate().unwrap();
            }
        }
    }
}

/// A mesh whose groups and materials share vertices survives OBJ → load and
/// GLB → load with the same vertices: each writer's one vertex pool and its
/// loader agree (the OBJ loader no longer splits a shared vertex per
/// `o`/`usemtl` block; the GLB's glTF meshes, one per group, share one set of
/// accessors, which the glTF loader places once).
#[test]
fn round_trips_keep_shared_vertices() {
    let (cabin, _) = crate::fixtures::cabin::generate_cabin(8.0);
    let (cleaned, _) = crate::clean::clean_mesh(&cabin, &crate::clean::CleanParams::cad()).unwrap();
    assert!(cleaned.groups.len() > 3, "the cabin has several groups");
    let dir = tempfile::tempdir().unwrap();
    for name in ["c.obj", "c.glb"] {
        let path = dir.path().join(name);
        if name.ends_with(".obj") {
            write_obj(&path, &cleaned).unwrap();
        } else {
            write_glb(&path, &cleaned).unwrap();
        }
        let back = load(&path).unwrap().mesh;
        assert_eq!(back.triangle_count(), cleaned.triangle_count(), "{name}");
        assert_eq!(back.vertex_count(), cleaned.vertex_count(), "{name}: vertices split or merged");
        // The same triangles (as corner positions), whatever the vertex order.
        let corners = |m: &Mesh| {
            let mut t: Vec<[[u32; 3]; 3]> =
                m.indices.chunks_exact(3).map(|c| [0, 1, 2].map(|k| m.positions[c[k] as usize].to_array().map(f32::to_bits))).collect();
            t.sort_unstable();
            t
        };
        assert!(corners(&back) == corners(&cleaned), "{name}: triangles differ");
    }
}
