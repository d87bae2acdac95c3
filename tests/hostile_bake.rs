//! Inputs the bake cannot trace, run through the binary: each is refused
//! with exit 2 and a message naming the file and the reason, never a panic.

use std::path::Path;

use base64::Engine;
use glam::Vec3;

use crate::util::{prtbake, write_scene_obj, Scratch};

/// Runs `args`; expects exit 2 with `file` and every one of `reasons` in
/// stderr, and no panic.
fn assert_refused(args: &[&str], file: &Path, reasons: &[&str]) {
    let output = prtbake(args);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{args:?}: {stderr}");
    assert!(!stderr.contains("panicked"), "{args:?} panicked: {stderr}");
    let name = file.file_name().unwrap().to_string_lossy();
    assert!(stderr.contains(&*name), "{args:?}: the error does not name {name}: {stderr}");
    for reason in reasons {
        assert!(stderr.contains(reason), "{args:?}: {reason:?} missing from: {stderr}");
    }
}

fn path_str(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// A glTF holding one upward triangle (0,0,0), (1,0,0), (0,0,−1), its
/// buffer embedded as base64, under one node with the given transform
/// properties (e.g. `"scale": [1e30, 1e30, 1e30]`).
fn write_one_triangle_gltf(path: &Path, node_transform: serde_json::Value) {
    let positions: Vec<u8> = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0].iter().flat_map(|v| v.to_le_bytes()).collect();
    let uri = format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(&positions));
    let mut node = serde_json::json!({ "mesh": 0 });
    node.as_object_mut().unwrap().extend(node_transform.as_object().unwrap().clone());
    let document = serde_json::json!({
        "asset": { "version": "2.0" },
        "buffers": [{ "byteLength": positions.len(), "uri": uri }],
        "bufferViews": [{ "buffer": 0, "byteLength": positions.len() }],
        "accessors": [{ "bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, -1], "max": [1, 0, 0] }],
        "meshes": [{ "primitives": [{ "attributes": { "POSITION": 0 } }] }],
        "nodes": [node],
        "scenes": [{ "nodes": [0] }],
        "scene": 0,
    });
    std::fs::write(path, serde_json::to_string(&document).unwrap()).unwrap();
}

const TOO_LARGE: &str = "rescale the model";

#[test]
fn coordinates_of_1e20_are_refused_by_bake_and_sun() {
    let dir = Scratch::new("hostile-big-obj");
    let obj = dir.path("big.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1e20 0 0\nv 0 1e20 0\nf 1 2 3\n").unwrap();
    let out = dir.path("out.prtb");
    let reasons = ["coordinates up to 1.0e20", TOO_LARGE];
    assert_refused(&["bake", path_str(&obj), "-o", path_str(&out), "--quiet"], &obj, &reasons);
    assert_refused(&["bake", path_str(&obj), "-o", path_str(&out), "--quiet", "--view-box", "0,0,0,1,1,1"], &obj, &reasons);
    assert_refused(&["sun", path_str(&obj), "-o", path_str(&out), "--quiet", "--steps", "4"], &obj, &reasons);
    // Cleaning computes f32 areas too: refused, not emptied into a bake of nothing.
    assert_refused(&["bake", path_str(&obj), "-o", path_str(&out), "--quiet", "--clean"], &obj, &reasons);
    assert!(!out.exists(), "nothing is written");
}

#[test]
fn a_gltf_node_scaled_by_1e30_is_refused() {
    let dir = Scratch::new("hostile-gltf-scale");
    let gltf = dir.path("scaled.gltf");
    write_one_triangle_gltf(&gltf, serde_json::json!({ "scale": [1e30, 1e30, 1e30] }));
    let out = dir.path("out.prtb");
    let reasons = ["coordinates up to 1.0e30", TOO_LARGE];
    assert_refused(&["bake", path_str(&gltf), "-o", path_str(&out), "--quiet"], &gltf, &reasons);
    assert_refused(&["sun", path_str(&gltf), "-o", path_str(&out), "--quiet", "--steps", "4"], &gltf, &reasons);
}

/// Bakes fixtures/scene.obj into `dir`, lets `edit` change the bundle's
/// mesh, and writes it as `name`: a bundle the reader accepts (finite
/// positions, valid checksums) for `sun` to build its scene from.
fn edited_bundle(dir: &Scratch, name: &str, edit: impl FnOnce(&mut prtbake::mesh::Mesh)) -> std::path::PathBuf {
    let obj = dir.path("scene.obj");
    write_scene_obj(&obj);
    let baked = dir.path("baked.prtb");
    let o = prtbake(&["bake", path_str(&obj), "-o", path_str(&baked), "--rays", "8", "--quiet"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut bundle = prtbake::bundle::read_bundle(&baked).unwrap();
    edit(&mut bundle.mesh);
    let edited = dir.path(name);
    prtbake::bundle::write_bundle(&edited, &bundle).unwrap();
    prtbake::bundle::read_bundle(&edited).expect("the reader accepts the bundle");
    edited
}

#[test]
fn a_bundle_with_a_position_of_1e30_is_refused_by_sun() {
    let dir = Scratch::new("hostile-bundle-far");
    let far = edited_bundle(&dir, "far.prtb", |mesh| mesh.positions[0] = Vec3::new(1e30, 0.0, 0.0));
    let out = dir.path("out.prtb");
    assert_refused(
        &["sun", path_str(&far), "-o", path_str(&out), "--quiet", "--steps", "4"],
        &far,
        &["coordinates up to 1.0e30", TOO_LARGE],
    );
}

#[test]
fn every_triangle_a_window_is_refused_by_bake_and_sun() {
    let dir = Scratch::new("hostile-all-windows");
    let obj = dir.path("scene.obj");
    write_scene_obj(&obj);
    let out = dir.path("out.prtb");
    let (input, output) = (path_str(&obj), path_str(&out));
    let reasons = ["nothing to bake", "every triangle is a window", "no surface receives light"];
    assert_refused(&["bake", input, "-o", output, "--quiet", "--window", "*"], &obj, &reasons);
    assert_refused(&["bake", input, "-o", output, "--quiet", "--window", "*", "--view-box", "0,1,0,0,1,0"], &obj, &reasons);
    assert_refused(&["sun", input, "-o", output, "--quiet", "--steps", "4", "--window", "*"], &obj, &reasons);
    assert!(!out.exists(), "nothing is written");
}

#[test]
fn an_all_degenerate_mesh_is_refused_by_bake_and_sun() {
    let dir = Scratch::new("hostile-degenerate");
    let obj = dir.path("collinear.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 2 3 4\n").unwrap();
    let out = dir.path("out.prtb");
    let reasons = ["nothing to bake", "all 2 triangles are degenerate (zero area)"];
    assert_refused(&["bake", path_str(&obj), "-o", path_str(&out), "--quiet"], &obj, &reasons);
    assert_refused(&["sun", path_str(&obj), "-o", path_str(&out), "--quiet", "--steps", "4"], &obj, &reasons);
    // A bundle whose mesh collapsed to a point, through sun.
    let point = edited_bundle(&dir, "point.prtb", |mesh| mesh.positions.iter_mut().for_each(|p| *p = Vec3::ONE));
    let reasons = ["nothing to bake", "triangles are degenerate (zero area)"];
    assert_refused(&["sun", path_str(&point), "-o", path_str(&out), "--quiet", "--steps", "4"], &point, &reasons);
}

#[test]
fn a_gltf_node_with_a_zero_matrix_is_refused() {
    let dir = Scratch::new("hostile-gltf-zero");
    let gltf = dir.path("zero.gltf");
    write_one_triangle_gltf(&gltf, serde_json::json!({ "matrix": vec![0.0f32; 16] }));
    let out = dir.path("out.prtb");
    let reasons = ["nothing to bake", "the only triangle is degenerate (zero area)"];
    assert_refused(&["bake", path_str(&gltf), "-o", path_str(&out), "--quiet"], &gltf, &reasons);
    assert_refused(&["sun", path_str(&gltf), "-o", path_str(&out), "--quiet", "--steps", "4"], &gltf, &reasons);
}
