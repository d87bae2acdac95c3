//! `load_mesh` over real third-party files: the assimp bad-and-edge corpus and the
//! Ferrari. Both skip with a notice when ../shared/data is absent.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::*;

const CORPUS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/bad-and-edge-inputs");
const FERRARI_DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/car-ferrari458");

/// Every file under `dir` (iteratively), sorted.
fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut pending = vec![dir.to_path_buf()];
    while let Some(folder) = pending.pop() {
        for entry in std::fs::read_dir(&folder).into_iter().flatten().flatten() {
            let path = entry.path();
            if path.is_dir() {
                pending.push(path);
            } else {
                found.push(path);
            }
        }
    }
    found.sort();
    found
}

/// Each corpus file loads or fails cleanly (a panic or stack overflow fails the
/// test run); the known-bad files fail for the right reason.
#[test]
fn every_bad_and_edge_input_loads_or_fails_cleanly() {
    let corpus = Path::new(CORPUS);
    if !corpus.is_dir() {
        eprintln!("SKIP every_bad_and_edge_input_loads_or_fails_cleanly: {CORPUS} is absent");
        return;
    }
    let wanted = |p: &Path| {
        let relative = p.strip_prefix(corpus).unwrap_or(p).to_string_lossy().into_owned();
        let ext = p.extension().and_then(|e| e.to_str()).unwrap_or("");
        (relative.starts_with("OBJ/") && ext == "obj") || (relative.starts_with("glTF2/") && (ext == "gltf" || ext == "glb"))
    };
    let files: Vec<PathBuf> = files_under(corpus).into_iter().filter(|p| wanted(p)).collect();
    assert!(files.len() > 50, "only {} corpus files found", files.len());

    let mut outcomes = Vec::new();
    for file in &files {
        let relative = file.strip_prefix(corpus).unwrap().to_string_lossy().into_owned();
        let outcome = load_mesh(file, &LoadOptions::default());
        let line = match &outcome {
            Ok(loaded) => format!(
                "OK  {:>7} tris  {relative}{}",
                loaded.mesh.triangle_count(),
                match loaded.warnings.len() {
                    0 => String::new(),
                    n => format!("  ({n} warnings: {})", loaded.warnings.join(" | ")),
                }
            ),
            Err(e) => format!("ERR               {relative}: {}", e.to_string().replace(&format!("{CORPUS}/"), "")),
        };
        eprintln!("{line}");
        if let Ok(loaded) = &outcome {
            loaded.mesh.validate().unwrap();
        }
        outcomes.push((relative, outcome));
    }
    let error_of = |name: &str| -> String {
        let (_, outcome) = outcomes.iter().find(|(r, _)| r == name).unwrap_or_else(|| panic!("{name} not in corpus"));
        match outcome {
            Ok(loaded) => panic!("{name} loaded ({} triangles) but must be refused", loaded.mesh.triangle_count()),
            Err(e) => e.to_string(),
        }
    };
    let cycle = error_of("glTF2/RecursiveNodes/RecursiveNodes.gltf");
    assert!(cycle.ends_with("RecursiveNodes.gltf: node cycle at node 0"), "{cycle}");
    for name in ["glTF2/IndexOutOfRange/IndexOutOfRange.gltf", "glTF2/IndexOutOfRange/AllIndicesOutOfRange.gltf"] {
        let message = error_of(name);
        assert!(message.contains("out of range") && message.contains("primitive 0"), "{message}");
    }
    let infinite = error_of("glTF2/BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb");
    assert!(infinite.contains("non-finite position"), "{infinite}");
    let draco = error_of("glTF2/draco/2CylinderEngine.gltf");
    assert!(draco.contains("requires extension KHR_draco_mesh_compression"), "{draco}");
    let missing = error_of("glTF2/MissingBin/BoxTextured.gltf");
    assert!(missing.contains("BoxTextured0.bin") && missing.contains("cannot be read"), "{missing}");
    let utf16 = error_of("OBJ/box_UTF16BE.obj");
    assert!(utf16.contains("UTF-16"), "{utf16}");
    // Files the raw crates read fine keep their triangle counts.
    let triangles_of =
        |name: &str| outcomes.iter().find(|(r, _)| r == name).and_then(|(_, o)| o.as_ref().ok()).map(|l| l.mesh.triangle_count());
    assert_eq!(triangles_of("OBJ/box.obj"), Some(12));
    let colored = outcomes.iter().find(|(r, _)| r == "OBJ/cube_with_vertexcolors.obj").and_then(|(_, o)| o.as_ref().ok()).unwrap();
    assert_eq!(colored.mesh.colors.len(), colored.mesh.vertex_count());
    assert_eq!(triangles_of("OBJ/spider.obj"), Some(1368));
    assert_eq!(triangles_of("glTF2/BoxBadNormals-glTF-Binary/BoxBadNormals.glb"), Some(12));
    assert_eq!(triangles_of("glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb"), Some(121_496));
    assert_eq!(triangles_of("glTF2/textureTransform/TextureTransformTest.gltf"), Some(24));
    // The asset generator draws one quad in every triangle mode: strips and fans
    // must give the same two faces, wound the same way, as plain triangles.
    let quad_normals = |n: u32| {
        let (_, outcome) = outcomes.iter().find(|(r, _)| r.ends_with(&format!("Mesh_PrimitiveMode_{n:02}.gltf"))).unwrap();
        let mesh = &outcome.as_ref().unwrap().mesh;
        assert_eq!(mesh.triangle_count(), 2, "mode file {n}");
        let mut area = 0.0;
        for t in 0..2 {
            let [a, b, c] = mesh.triangle_positions(t);
            let normal = (b - a).cross(c - a);
            assert!(normal.normalize().dot(glam::Vec3::Z) > 0.999, "mode file {n} triangle {t}: {normal}");
            area += normal.length() / 2.0;
        }
        area
    };
    let reference_area = quad_normals(6);
    for n in [4, 5, 11, 12, 13, 14, 15] {
        assert!((quad_normals(n) - reference_area).abs() < 1e-6, "mode file {n} covers a different area");
    }
    let ok = outcomes.iter().filter(|(_, o)| o.is_ok()).count();
    eprintln!("{} files: {ok} loaded, {} refused", outcomes.len(), outcomes.len() - ok);
}

#[test]
fn ferrari_loads_with_its_triangles_materials_and_glass() {
    let path = Path::new(FERRARI_DIR).join("ferrari_nodraco.glb");
    if !path.is_file() {
        eprintln!("SKIP ferrari_loads_with_its_triangles_materials_and_glass: {} is absent", path.display());
        return;
    }
    let start = Instant::now();
    let loaded = load_mesh(&path, &LoadOptions::default()).unwrap();
    let seconds = start.elapsed().as_secs_f64();
    let mesh = &loaded.mesh;
    eprintln!(
        "ferrari_nodraco.glb: {} triangles, {} vertices, {} materials, {} groups, loaded in {seconds:.3} s; warnings: {:?}",
        mesh.triangle_count(),
        mesh.vertex_count(),
        mesh.materials.len(),
        mesh.groups.len(),
        loaded.warnings
    );
    assert_eq!(mesh.triangle_count(), 358_788);
    assert_eq!(mesh.materials.len(), 17);
    let glass = mesh.materials.iter().position(|m| m.name == "Glass_Gray").expect("Glass_Gray material");
    assert_eq!(mesh.tri_material.iter().filter(|&&m| m as usize == glass).count(), 8_952);
    assert!(mesh.groups.iter().any(|g| g == "glass"), "{:?}", mesh.groups);
    // No KHR_materials_transmission in this file: the glass stays Opaque here and
    // becomes a window only by the baker's name globs.
    assert_eq!(mesh.materials[glass].role, MaterialRole::Opaque);
    assert!((mesh.materials[glass].albedo[0] - 0.50196).abs() < 1e-4);
    // SOURCE.md bbox: [-1.129, 0, -2.267] .. [1.129, 1.236, 2.267].
    let (lo, hi) = mesh.bounds();
    assert!((lo - glam::Vec3::new(-1.129, 0.0, -2.267)).abs().max_element() < 2e-3, "{lo}");
    assert!((hi - glam::Vec3::new(1.129, 1.236, 2.267)).abs().max_element() < 2e-3, "{hi}");

    // Real-size GLB round trip.
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("ferrari.glb");
    let start = Instant::now();
    write_glb(&copy, mesh).unwrap();
    let write_seconds = start.elapsed().as_secs_f64();
    let back = load_mesh(&copy, &LoadOptions::default()).unwrap().mesh;
    eprintln!("write_glb: {write_seconds:.3} s, {} bytes", std::fs::metadata(&copy).unwrap().len());
    assert_eq!(back.triangle_count(), mesh.triangle_count());
    assert_eq!(back.materials, mesh.materials);
    assert_eq!(back.groups, mesh.groups);
    assert_eq!(back.bounds(), mesh.bounds());
    let per_material =
        |m: &Mesh| (0..m.materials.len()).map(|k| m.tri_material.iter().filter(|&&x| x as usize == k).count()).collect::<Vec<_>>();
    assert_eq!(per_material(&back), per_material(mesh));

    let draco = Path::new(FERRARI_DIR).join("ferrari.glb");
    if draco.is_file() {
        let message = load_mesh(&draco, &LoadOptions::default()).unwrap_err().to_string();
        assert_eq!(
            message,
            format!(
                "{}: requires extension KHR_draco_mesh_compression, which prtbake does not support; decode it first (e.g. gltf-transform)",
                draco.display()
            )
        );
    }
}
