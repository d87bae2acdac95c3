//! `scripts/convert_mitsuba.py` on tiny Mitsuba scenes: area-light shapes are
//! dropped (and named) or kept under their own material, BSDF ids nested in
//! `bumpmap` / `mask` / `twosided` resolve with the inner reflectance, `--pane`
//! adds window glass that prtbake's loader reads as a window, and an undefined
//! BSDF is a clear error. Skipped (with a notice) where python3 is absent.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use prtbake::mesh::MaterialRole;

/// A wall quad (BSDF `Walls`, reflectance 0.2 0.3 0.4) and, behind it, an area
/// light: a rectangle with an inline black BSDF and an `<emitter>` child. The
/// light is shape 1, so the converter calls it `rectangle1`; its corners are
/// (±0.5, ±0.5, -1).
const WALL_AND_LIGHT: &str = r#"<?xml version="1.0" encoding="utf-8"?>
<scene version="0.5.0">
	<sensor type="perspective">
		<transform name="toWorld">
			<matrix value="1 0 0 0 0 1 0 1 0 0 1 5 0 0 0 1"/>
		</transform>
	</sensor>
	<bsdf type="twosided" id="Walls">
		<bsdf type="diffuse">
			<rgb name="reflectance" value="0.2, 0.3, 0.4"/>
		</bsdf>
	</bsdf>
	<shape type="rectangle">
		<transform name="toWorld">
			<matrix value="1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1"/>
		</transform>
		<ref id="Walls"/>
	</shape>
	<shape type="rectangle">
		<transform name="toWorld">
			<matrix value="0.5 0 0 0 0 0.5 0 0 0 0 1 -1 0 0 0 1"/>
		</transform>
		<bsdf type="twosided">
			<bsdf type="diffuse">
				<rgb name="reflectance" value="0, 0, 0"/>
			</bsdf>
		</bsdf>
		<emitter type="area">
			<spectrum name="radiance" value="10"/>
		</emitter>
	</shape>
</scene>
"#;

/// Ids at every place a wrapper allows: inside a `bumpmap` (on the `twosided`
/// it wraps, as the kitchen's `Cushion1`), on a `mask` around a `twosided`, on
/// the `diffuse` inside a `mask`, on the `diffuse` inside a `twosided`, and on a
/// `twosided` around a `bumpmap`. One rectangle refers to each.
const NESTED_IDS: &str = r#"<?xml version="1.0" encoding="utf-8"?>
<scene version="0.5.0">
	<bsdf type="bumpmap">
		<texture name="map" type="bitmap">
			<string name="filename" value="textures/bump.png"/>
		</texture>
		<bsdf type="twosided" id="Cushion1">
			<bsdf type="diffuse">
				<rgb name="reflectance" value="0.1, 0.2, 0.3"/>
			</bsdf>
		</bsdf>
	</bsdf>
	<bsdf type="mask" id="Blinds">
		<spectrum name="opacity" value="0.6"/>
		<bsdf type="twosided">
			<bsdf type="diffuse">
				<rgb name="reflectance" value="0.4, 0.5, 0.6"/>
			</bsdf>
		</bsdf>
	</bsdf>
	<bsdf type="mask">
		<spectrum name="opacity" value="0.5"/>
		<bsdf type="diffuse" id="Leaf">
			<rgb name="reflectance" value="0.25, 0.5, 0.75"/>
		</bsdf>
	</bsdf>
	<bsdf type="twosided">
		<bsdf type="diffuse" id="Paper">
			<rgb name="reflectance" value="0.7, 0.8, 0.9"/>
		</bsdf>
	</bsdf>
	<bsdf type="twosided" id="Bumpy">
		<bsdf type="bumpmap">
			<texture name="map" type="bitmap">
				<string name="filename" value="textures/bump.png"/>
			</texture>
			<bsdf type="diffuse">
				<rgb name="reflectance" value="0.05, 0.15, 0.35"/>
			</bsdf>
		</bsdf>
	</bsdf>
	<shape type="rectangle"><ref id="Cushion1"/></shape>
	<shape type="rectangle"><ref id="Blinds"/></shape>
	<shape type="rectangle"><ref id="Leaf"/></shape>
	<shape type="rectangle"><ref id="Paper"/></shape>
	<shape type="rectangle"><ref id="Bumpy"/></shape>
</scene>
"#;

/// True when `python3` runs; otherwise prints a skip notice.
fn python3_available() -> bool {
    match Command::new("python3").arg("--version").output() {
        Ok(output) if output.status.success() => true,
        _ => {
            eprintln!("SKIP: python3 is not available, scripts/convert_mitsuba.py was not run");
            false
        }
    }
}

/// Writes `xml` as `dir/scene/scene.xml`; returns the scene folder.
fn write_scene(dir: &Path, xml: &str) -> PathBuf {
    let scene = dir.join("scene");
    std::fs::create_dir_all(&scene).unwrap();
    std::fs::write(scene.join("scene.xml"), xml).unwrap();
    scene
}

/// Runs the converter on `scene`, writing `out` (and the `.mtl` beside it).
fn convert(scene: &Path, out: &Path, extra: &[&str]) -> Output {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts").join("convert_mitsuba.py");
    Command::new("python3").arg(&script).arg(scene).arg(out).args(extra).output().expect("cannot run python3")
}

/// What the tests read back from a converted OBJ + MTL.
struct Converted {
    /// `f` lines (the converter writes triangles only).
    triangles: usize,
    /// Triangles per `usemtl` material, in order of first use.
    materials: Vec<(String, usize)>,
    /// `o` names, in order.
    objects: Vec<String>,
    positions: Vec<[f64; 3]>,
    obj_text: String,
    mtl_text: String,
    stderr: String,
}

/// Converts and asserts success; reads the OBJ and MTL back.
fn convert_ok(scene: &Path, out: &Path, extra: &[&str]) -> Converted {
    let output = convert(scene, out, extra);
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(output.status.success(), "converter failed ({:?}) with {extra:?}: {stderr}", output.status.code());
    let obj_text = std::fs::read_to_string(out).unwrap();
    let mtl_text = std::fs::read_to_string(out.with_extension("mtl")).unwrap();
    let mut converted = Converted {
        triangles: 0,
        materials: Vec::new(),
        objects: Vec::new(),
        positions: Vec::new(),
        obj_text: String::new(),
        mtl_text,
        stderr,
    };
    let mut current: Option<usize> = None;
    for line in obj_text.lines() {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.first().copied() {
            Some("v") => {
                let p: Vec<f64> = words[1..4].iter().map(|w| w.parse::<f64>().unwrap()).collect();
                converted.positions.push([p[0], p[1], p[2]]);
            }
            Some("o") => converted.objects.push(words[1].to_string()),
            Some("usemtl") => {
                let name = words[1].to_string();
                let known = converted.materials.iter().position(|(m, _)| *m == name);
                current = Some(match known {
                    Some(index) => index,
                    None => {
                        converted.materials.push((name, 0));
                        converted.materials.len() - 1
                    }
                });
            }
            Some("f") => {
                assert_eq!(words.len(), 4, "not a triangle: {line}");
                converted.triangles += 1;
                converted.materials[current.expect("a face before any usemtl")].1 += 1;
            }
            _ => {}
        }
    }
    converted.obj_text = obj_text;
    converted
}

/// The lines of the `newmtl name` block of an MTL (without the `newmtl` line).
fn mtl_block(mtl: &str, name: &str) -> Vec<String> {
    let mut block = Vec::new();
    let mut inside = false;
    for line in mtl.lines() {
        let line = line.trim();
        if let Some(rest) = line.strip_prefix("newmtl ") {
            inside = rest.trim() == name;
        } else if inside && !line.is_empty() {
            block.push(line.to_string());
        }
    }
    assert!(mtl.lines().any(|l| l.trim() == format!("newmtl {name}")), "no material {name} in the MTL:\n{mtl}");
    block
}

/// The `Kd` of material `name`.
fn kd(mtl: &str, name: &str) -> [f64; 3] {
    let block = mtl_block(mtl, name);
    let line = block.iter().find(|l| l.starts_with("Kd ")).unwrap_or_else(|| panic!("material {name} has no Kd: {block:?}"));
    let values: Vec<f64> = line.split_whitespace().skip(1).map(|w| w.parse::<f64>().unwrap()).collect();
    assert_eq!(values.len(), 3, "{line}");
    [values[0], values[1], values[2]]
}

fn materials(pairs: &[(&str, usize)]) -> Vec<(String, usize)> {
    pairs.iter().map(|(name, count)| (name.to_string(), *count)).collect()
}

fn has_position(converted: &Converted, p: [f64; 3]) -> bool {
    converted.positions.iter().any(|q| (0..3).all(|k| (q[k] - p[k]).abs() < 1e-9))
}

#[test]
fn emitter_shapes_are_dropped_and_named_or_kept_under_their_own_material() {
    if !python3_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = write_scene(dir.path(), WALL_AND_LIGHT);

    // Default: the light is gone (the old converter kept it as 2 grey `default` triangles).
    let out = dir.path().join("dropped.obj");
    let converted = convert_ok(&scene, &out, &[]);
    assert_eq!(converted.triangles, 2, "{}", converted.obj_text);
    assert_eq!(converted.materials, materials(&[("Walls", 2)]));
    assert_eq!(converted.objects, vec!["rectangle0".to_string()]);
    assert_eq!(converted.positions.len(), 4);
    assert!(converted.stderr.contains("dropped emitter shape rectangle1"), "stderr: {}", converted.stderr);
    assert!(!converted.mtl_text.contains("default") && !converted.mtl_text.contains("emitter"), "{}", converted.mtl_text);
    assert!(
        converted.stderr.contains("kept 1 shape (2 triangles); dropped 1 emitter shape (2 triangles); added 0 panes (0 triangles)"),
        "stderr: {}",
        converted.stderr
    );
    let mesh = prtbake::mesh::load_mesh(&out, &Default::default()).unwrap().mesh;
    assert_eq!(mesh.triangle_count(), 2);
    assert_eq!(mesh.materials.iter().map(|m| m.name.as_str()).collect::<Vec<_>>(), vec!["Walls"]);

    // --keep-emitters: the light stays, under `emitter_rectangle1` with its own
    // BSDF's Kd and no role key (prtbake has no emitter role: it loads as opaque).
    let out = dir.path().join("kept.obj");
    let converted = convert_ok(&scene, &out, &["--keep-emitters"]);
    assert_eq!(converted.triangles, 4);
    assert_eq!(converted.materials, materials(&[("Walls", 2), ("emitter_rectangle1", 2)]));
    assert_eq!(kd(&converted.mtl_text, "emitter_rectangle1"), [0.0, 0.0, 0.0]);
    assert!(mtl_block(&converted.mtl_text, "emitter_rectangle1").iter().all(|l| !l.starts_with("prtbake_")), "{}", converted.mtl_text);
    assert!(!converted.stderr.contains("dropped emitter shape"), "stderr: {}", converted.stderr);
    let mesh = prtbake::mesh::load_mesh(&out, &Default::default()).unwrap().mesh;
    assert_eq!(mesh.triangle_count(), 4);
    let emitter = mesh.materials.iter().find(|m| m.name == "emitter_rectangle1").expect("emitter material loaded");
    assert_eq!(emitter.role, MaterialRole::Opaque);
}

#[test]
fn bsdf_ids_nested_in_bumpmap_mask_and_twosided_resolve_with_the_inner_reflectance() {
    if !python3_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = write_scene(dir.path(), NESTED_IDS);
    let out = dir.path().join("nested.obj");
    // The old converter stopped at "shape 0 refers to BSDF 'Cushion1', which is not defined".
    let converted = convert_ok(&scene, &out, &[]);
    assert_eq!(converted.triangles, 10);
    assert_eq!(converted.materials, materials(&[("Cushion1", 2), ("Blinds", 2), ("Leaf", 2), ("Paper", 2), ("Bumpy", 2)]));
    // Kd from the innermost diffuse, not the 0.5 grey a wrapper without a reflectance gave.
    assert_eq!(kd(&converted.mtl_text, "Cushion1"), [0.1, 0.2, 0.3]);
    assert_eq!(kd(&converted.mtl_text, "Blinds"), [0.4, 0.5, 0.6]);
    assert_eq!(kd(&converted.mtl_text, "Leaf"), [0.25, 0.5, 0.75]);
    assert_eq!(kd(&converted.mtl_text, "Paper"), [0.7, 0.8, 0.9]);
    assert_eq!(kd(&converted.mtl_text, "Bumpy"), [0.05, 0.15, 0.35]);
    let mesh = prtbake::mesh::load_mesh(&out, &Default::default()).unwrap().mesh;
    let blinds = mesh.materials.iter().find(|m| m.name == "Blinds").expect("Blinds loaded");
    assert_eq!(blinds.albedo, [0.4f32, 0.5, 0.6]);
}

#[test]
fn pane_adds_two_window_triangles() {
    if !python3_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = write_scene(dir.path(), WALL_AND_LIGHT);

    // An explicit parallelogram: corners A, B, C; the fourth is B + C - A = (2, 3, 4).
    let out = dir.path().join("pane.obj");
    let converted = convert_ok(&scene, &out, &["--pane", "2,0,0:2,3,0:2,0,4"]);
    assert_eq!(converted.triangles, 4, "2 wall + 2 pane triangles");
    assert_eq!(converted.materials, materials(&[("Walls", 2), ("pane", 2)]));
    assert_eq!(converted.objects, vec!["rectangle0".to_string(), "pane0".to_string()]);
    for corner in [[2.0, 0.0, 0.0], [2.0, 3.0, 0.0], [2.0, 3.0, 4.0], [2.0, 0.0, 4.0]] {
        assert!(has_position(&converted, corner), "pane corner {corner:?} missing:\n{}", converted.obj_text);
    }
    // The wall's normals are +Z; the pane's is (B - A) x (C - A) = +X.
    assert!(converted.obj_text.lines().any(|l| l == "vn 1 0 0"), "pane normal:\n{}", converted.obj_text);
    let block = mtl_block(&converted.mtl_text, "pane");
    assert!(block.iter().any(|l| l == "prtbake_role window"), "{block:?}");
    assert!(block.iter().any(|l| l == "prtbake_transmittance 1"), "{block:?}");
    assert!(converted.stderr.contains("added 1 pane (2 triangles)"), "stderr: {}", converted.stderr);
    let mesh = prtbake::mesh::load_mesh(&out, &Default::default()).unwrap().mesh;
    assert_eq!(mesh.triangle_count(), 4);
    let pane = mesh.materials.iter().position(|m| m.name == "pane").expect("pane material loaded");
    assert_eq!(mesh.materials[pane].role, MaterialRole::Window);
    assert_eq!(mesh.materials[pane].transmittance, 1.0);
    assert_eq!(mesh.tri_material.iter().filter(|&&m| m as usize == pane).count(), 2);
    let walls = mesh.materials.iter().find(|m| m.name == "Walls").expect("Walls loaded");
    assert_eq!(walls.role, MaterialRole::Opaque);

    // A pane where the light was, the light dropped; grown by 0.25 on each side.
    let out = dir.path().join("from-emitter.obj");
    let converted = convert_ok(&scene, &out, &["--pane-from-emitter", "rectangle1", "--pane-grow", "0.25"]);
    assert_eq!(converted.triangles, 4);
    assert_eq!(converted.materials, materials(&[("Walls", 2), ("pane", 2)]));
    assert_eq!(converted.objects, vec!["rectangle0".to_string(), "pane_rectangle1".to_string()]);
    for corner in [[-0.75, -0.75, -1.0], [0.75, -0.75, -1.0], [0.75, 0.75, -1.0], [-0.75, 0.75, -1.0]] {
        assert!(has_position(&converted, corner), "pane corner {corner:?} missing:\n{}", converted.obj_text);
    }
    assert!(converted.stderr.contains("dropped emitter shape rectangle1"), "stderr: {}", converted.stderr);

    // A degenerate pane is refused before anything is written.
    let out = dir.path().join("flat.obj");
    let output = convert(&scene, &out, &["--pane", "0,0,0:1,1,1:2,2,2"]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "stderr: {stderr}");
    assert!(stderr.contains("collinear"), "stderr: {stderr}");
    assert!(!out.exists());
}

#[test]
fn an_undefined_bsdf_is_named_and_nothing_is_written() {
    if !python3_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let xml = NESTED_IDS.replace(r#"<ref id="Paper"/>"#, r#"<ref id="Nowhere"/>"#);
    let scene = write_scene(dir.path(), &xml);
    let out = dir.path().join("broken.obj");
    let output = convert(&scene, &out, &[]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "stderr: {stderr}");
    assert_eq!(output.status.code(), Some(1), "stderr: {stderr}");
    assert!(stderr.contains("shape 3 refers to BSDF 'Nowhere', which is not defined"), "stderr: {stderr}");
    assert!(!stderr.contains("Traceback"), "stderr: {stderr}");
    assert!(!out.exists() && !out.with_extension("mtl").exists());
}
