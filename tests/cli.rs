//! The binary as a user runs it: real files, bad input, JSON, exit codes.

use crate::util::{prtbake, shared_data, write_scene_obj, Scratch};

#[test]
fn bake_inspect_round_trip_and_thread_independence() {
    let dir = Scratch::new("bake");
    let obj = dir.path("scene.obj");
    write_scene_obj(&obj);
    let out1 = dir.path("one.prtb");
    let out2 = dir.path("two.prtb");
    let common = ["--rays", "64", "--bounces", "1", "--order", "3", "--seed", "7", "--quiet"];
    let run = |out: &std::path::Path, threads: &str| {
        let mut args = vec!["bake", obj.to_str().unwrap(), "-o", out.to_str().unwrap(), "--threads", threads];
        args.extend(common);
        let o = prtbake(&args);
        assert!(o.status.success(), "bake failed: {}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8(o.stdout).unwrap()
    };
    let line = run(&out1, "1");
    assert!(line.contains("rays") && line.contains("Mrays/s"), "stats line: {line}");
    run(&out2, "2");
    assert_eq!(std::fs::read(&out1).unwrap(), std::fs::read(&out2).unwrap(), "bundles differ between 1 and 2 threads");

    let o = prtbake(&["inspect", out1.to_str().unwrap(), "--json"]);
    assert!(o.status.success());
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(doc["triangles"], 14);
    assert_eq!(doc["transfer"]["order"], 3);
    // The red box makes interreflection coloured: three channels.
    assert_eq!(doc["transfer"]["channels"], 3);
    assert_eq!(doc["meta"]["params"]["seed"], 7);
    // No temporary files are left behind.
    let leftovers: Vec<_> =
        std::fs::read_dir(&dir.0).unwrap().filter_map(|e| e.ok()).filter(|e| e.file_name().to_string_lossy().contains(".tmp")).collect();
    assert!(leftovers.is_empty());
}

#[test]
fn bake_json_reports_stats() {
    let dir = Scratch::new("json");
    let obj = dir.path("scene.obj");
    write_scene_obj(&obj);
    let out = dir.path("s.prtb");
    let o = prtbake(&["bake", obj.to_str().unwrap(), "-o", out.to_str().unwrap(), "--rays", "32", "--json", "--bounces", "2"]);
    assert!(o.status.success());
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let s = &doc["stats"];
    assert_eq!(s["triangles"], 14);
    assert_eq!(s["rays_per_bounce"].as_array().unwrap().len(), 3);
    let rays: u64 = s["rays_per_bounce"].as_array().unwrap().iter().map(|r| r.as_u64().unwrap()).sum();
    assert_eq!(s["rays"].as_u64().unwrap(), rays);
    // The rate counts traced rays only; evaluations answered from the hit
    // records (bounces 1 and 2 here) are reported apart, not as rays.
    let traced = s["rays_traced"].as_u64().unwrap();
    let (rate, seconds) = (s["rays_per_second"].as_f64().unwrap(), s["seconds"].as_f64().unwrap());
    assert!((rate * seconds - traced as f64).abs() <= 1e-6 * traced as f64, "{rate} * {seconds} != {traced}");
    let per_bounce: Vec<u64> = s["rays_per_bounce"].as_array().unwrap().iter().map(|r| r.as_u64().unwrap()).collect();
    assert_eq!(s["rays_gathered"].as_u64().unwrap(), per_bounce[1] + per_bounce[2]);
    let evaluations_rate = s["evaluations_per_second"].as_f64().unwrap();
    assert!((evaluations_rate * seconds - rays as f64).abs() <= 1e-6 * rays as f64);
    assert!(doc["peak_memory_bytes"].as_u64().unwrap() > 0);
}

/// Bad input: a clear message naming the file, exit code 2, never a panic.
#[test]
fn bad_input_is_refused_with_the_path() {
    let dir = Scratch::new("bad");
    let missing = dir.path("missing.obj");
    let nan = dir.path("nan.obj");
    std::fs::write(&nan, "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n").unwrap();
    let empty = dir.path("empty.obj");
    std::fs::write(&empty, "# nothing\n").unwrap();
    let garbage = dir.path("garbage.prtb");
    std::fs::write(&garbage, b"PRTB\r\n\x1a\n garbage").unwrap();
    let empty_bundle = dir.path("empty.prtb");
    std::fs::write(&empty_bundle, b"").unwrap();
    let out = dir.path("o.prtb");
    for (args, needle) in [
        (vec!["bake", missing.to_str().unwrap(), "-o", out.to_str().unwrap()], "missing.obj"),
        (vec!["bake", nan.to_str().unwrap(), "-o", out.to_str().unwrap()], "nan.obj"),
        (vec!["bake", empty.to_str().unwrap(), "-o", out.to_str().unwrap()], "empty.obj"),
        (vec!["inspect", garbage.to_str().unwrap()], "garbage.prtb"),
        (vec!["sun", garbage.to_str().unwrap(), "-o", out.to_str().unwrap()], "garbage.prtb: not a valid bundle"),
        (vec!["sun", empty_bundle.to_str().unwrap(), "-o", out.to_str().unwrap()], "empty.prtb: not a valid bundle"),
        (vec!["bake", nan.to_str().unwrap(), "-o", out.to_str().unwrap(), "--order", "0"], "order"),
        (vec!["bake", nan.to_str().unwrap(), "-o", out.to_str().unwrap(), "--rays", "100000"], "rays"),
    ] {
        let o = prtbake(&args);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(needle), "{args:?}: message does not name {needle}: {stderr}");
        assert!(!stderr.contains("panicked"), "{args:?} panicked: {stderr}");
    }
    assert!(!out.exists(), "a failed bake left an output file");
}

/// Window mode with a pattern that matches nothing is an error, not a black bake.
#[test]
fn window_pattern_matching_nothing_is_an_error() {
    let dir = Scratch::new("win");
    let obj = dir.path("scene.obj");
    write_scene_obj(&obj);
    let o = prtbake(&["bake", obj.to_str().unwrap(), "-o", dir.path("w.prtb").to_str().unwrap(), "--window", "Glass*", "--rays", "8"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no triangle is a window"));
}

/// The real car's windows are material Glass_Gray: a quick window-mode bake at low rays.
#[test]
fn ferrari_window_mode_bakes() {
    let Some(car) = shared_data("car-ferrari458/ferrari_nodraco.glb") else { return };
    let dir = Scratch::new("car");
    let out = dir.path("car.prtb");
    let o = prtbake(&[
        "bake",
        car.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--window",
        "Glass_Gray",
        "--rays",
        "4",
        "--order",
        "2",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(doc["stats"]["triangles"], 358_788);
    assert_eq!(doc["stats"]["window_triangles"], 8_952);
}

#[test]
fn draco_file_is_refused_by_name() {
    let Some(car) = shared_data("car-ferrari458/ferrari.glb") else { return };
    let dir = Scratch::new("draco");
    let o = prtbake(&["bake", car.to_str().unwrap(), "-o", dir.path("x.prtb").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("KHR_draco_mesh_compression"));
}

/// Glass chosen by `--window PATTERN=TAU` is stored as a window-role material
/// with that transmittance, so the bundle says which glass was a window.
#[test]
fn window_patterns_are_stored_as_material_roles() {
    let dir = Scratch::new("roles");
    let obj = dir.path("g.obj");
    std::fs::write(
        &obj,
        "mtllib g.mtl\nusemtl wall\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nusemtl Glass_Gray\nf 2 3 4\n",
    )
    .unwrap();
    std::fs::write(dir.path("g.mtl"), "newmtl wall\nKd 0.5 0.5 0.5\nnewmtl Glass_Gray\nKd 0.1 0.1 0.1\n").unwrap();
    let out = dir.path("g.prtb");
    let o = prtbake(&["bake", obj.to_str().unwrap(), "-o", out.to_str().unwrap(), "--window", "Glass_*=0.6", "--rays", "8", "--quiet"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let b = prtbake::bundle::read_bundle(&out).unwrap();
    let roles: Vec<_> = b.mesh.materials.iter().map(|m| (m.name.as_str(), m.role, m.transmittance)).collect();
    use prtbake::mesh::MaterialRole::{Opaque, Window};
    assert_eq!(roles, [("wall", Opaque, 1.0), ("Glass_Gray", Window, 0.6)]);
}

/// `prtbake panel` on the two-object scene (the ground as the panel): images
/// and JSON at 1 and 2 threads, byte-identical; bad panels and eyes refused by name.
#[test]
fn panel_gathers_the_ground_and_refuses_bad_input() {
    let dir = Scratch::new("panel");
    let obj = dir.path("scene.obj");
    write_scene_obj(&obj);
    let bundle = dir.path("scene.prtb");
    let o = prtbake(&["bake", obj.to_str().unwrap(), "-o", bundle.to_str().unwrap(), "--rays", "64", "--bounces", "1", "--quiet"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let run = |threads: &str, out: &str, extra: &[&str]| {
        let out = dir.path(out);
        let mut args = vec!["panel", bundle.to_str().unwrap(), "--panel", "grey", "--overcast", "--texels", "16x12", "--samples", "8"];
        args.extend(["--threads", threads, "-o", out.to_str().unwrap(), "--json"]);
        args.extend(extra);
        (prtbake(&args), out)
    };
    let (one, exr1) = run("1", "one.exr", &["--eye=1,2,3"]);
    assert!(one.status.success(), "{}", String::from_utf8_lossy(&one.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&one.stdout).unwrap();
    assert_eq!(doc["texels_on_panel"], 192);
    assert_eq!(doc["mapping"], "planar");
    // Overcast: one BRDF ray per sample unless the draw is lost, each at least one query.
    let (rays, queries) = (doc["rays"].as_u64().unwrap(), doc["queries"].as_u64().unwrap());
    assert!(rays > 192 * 8 * 9 / 10 && rays <= 192 * 8 && queries >= rays, "{rays} rays, {queries} queries");
    let r = &doc["readability"];
    assert!(r["min_contrast_ratio"].as_f64().unwrap() <= r["median_contrast_ratio"].as_f64().unwrap());
    assert_eq!(r["window_share"], 0.0, "no windows in the open scene");
    // Open mode: the panel sees the sky itself, so not everything it reflects is the interior's.
    let (sky, interior) = (r["sky_share"].as_f64().unwrap(), r["interior_share"].as_f64().unwrap());
    assert!(sky > 0.05 && (sky + interior - 1.0).abs() < 1e-6, "{r}");
    let (two, exr2) = run("2", "two.exr", &["--eye=1,2,3"]);
    assert!(two.status.success());
    assert_eq!(std::fs::read(&exr1).unwrap(), std::fs::read(&exr2).unwrap(), "EXR differs between 1 and 2 threads");
    assert_eq!(std::fs::read(exr1.with_extension("cr.png")).unwrap(), std::fs::read(exr2.with_extension("cr.png")).unwrap());

    // A light past f32 gives no statistic: exit 2, nothing written.
    let (overflow, out) = run("1", "overflow.exr", &["--eye=1,2,3", "--lux", "1e39"]);
    assert_eq!(overflow.status.code(), Some(2), "{}", String::from_utf8_lossy(&overflow.stdout));
    let message = String::from_utf8_lossy(&overflow.stderr);
    assert!(message.contains("scene.prtb") && message.contains("not finite"), "{message}");
    assert!(!out.exists() && !out.with_extension("cr.png").exists());
    let (behind, _) = run("1", "behind.exr", &["--eye=0,-1,0"]);
    assert_eq!(behind.status.code(), Some(2));
    let message = String::from_utf8_lossy(&behind.stderr);
    assert!(message.contains("scene.prtb") && message.contains("behind the panel"), "{message}");
    let mut args = vec!["panel", bundle.to_str().unwrap(), "--panel", "nav*", "--overcast", "--eye=1,2,3", "-o"];
    let out = dir.path("none.exr");
    args.push(out.to_str().unwrap());
    let none = prtbake(&args);
    assert_eq!(none.status.code(), Some(2));
    let message = String::from_utf8_lossy(&none.stderr);
    assert!(message.contains("scene.prtb") && message.contains("nav*") && message.contains("grey"), "{message}");
    assert!(!out.exists() && !dir.path("behind.exr").exists(), "no output on error");
}

/// `bake --clean --max-edge` and `clean --max-edge` → OBJ or
/// GLB → `bake` give the same vertices (positions, order) and the same
/// transfer, bit for bit.
#[test]
fn bake_clean_max_edge_equals_clean_then_bake() {
    let dir = Scratch::new("clean-then-bake");
    let obj = dir.path("scene.obj");
    write_scene_obj(&obj);
    let common = ["--rays", "16", "--bounces", "1", "--seed", "3", "--quiet"];
    let bake = |input: &std::path::Path, out: &str, extra: &[&str]| {
        let out = dir.path(out);
        let mut args = vec!["bake", input.to_str().unwrap(), "-o", out.to_str().unwrap()];
        args.extend(common);
        args.extend(extra);
        let o = prtbake(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        prtbake::bundle::read_bundle(&out).unwrap()
    };
    let direct = bake(&obj, "direct.prtb", &["--clean", "--max-edge", "0.3"]);
    // The ground's 4 m edges and the box's 0.5 m edges were split.
    assert!(direct.mesh.triangle_count() > 300, "{} triangles", direct.mesh.triangle_count());
    let direct_transfer = direct.transfer.as_ref().unwrap();
    for cleaned in ["cleaned.obj", "cleaned.glb"] {
        let path = dir.path(cleaned);
        let o = prtbake(&["clean", obj.to_str().unwrap(), "-o", path.to_str().unwrap(), "--max-edge", "0.3", "--quiet"]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let via_file = bake(&path, &format!("{cleaned}.prtb"), &[]);
        assert_eq!(via_file.mesh.vertex_count(), direct.mesh.vertex_count(), "{cleaned}");
        assert_eq!(via_file.mesh.positions, direct.mesh.positions, "{cleaned}");
        assert_eq!(via_file.mesh.indices, direct.mesh.indices, "{cleaned}");
        let differ: Vec<_> = (0..via_file.mesh.vertex_count())
            .filter(|&v| via_file.mesh.normals[v] != direct.mesh.normals[v])
            .map(|v| (v, via_file.mesh.positions[v], via_file.mesh.normals[v], direct.mesh.normals[v]))
            .take(8)
            .collect();
        assert!(differ.is_empty(), "{cleaned}: {differ:?}");
        assert_eq!(via_file.mesh.tri_material, direct.mesh.tri_material, "{cleaned}");
        assert_eq!(via_file.mesh.tri_group, direct.mesh.tri_group, "{cleaned}");
        assert_eq!(via_file.mesh.materials, direct.mesh.materials, "{cleaned}");
        let layers = &via_file.transfer.as_ref().unwrap().layers;
        assert_eq!(layers.len(), direct_transfer.layers.len());
        for (a, b) in layers.iter().zip(&direct_transfer.layers) {
            assert!(a.data.iter().zip(&b.data).all(|(x, y)| x.to_bits() == y.to_bits()), "{cleaned}: transfer differs");
        }
    }
    // --max-edge means nothing without --clean.
    let o = prtbake(&["bake", obj.to_str().unwrap(), "-o", dir.path("x.prtb").to_str().unwrap(), "--max-edge", "0.3"]);
    assert_eq!(o.status.code(), Some(2), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn bake_and_sun_refine_deterministically_and_refuse_what_they_cannot_do() {
    let dir = Scratch::new("refine");
    let obj = dir.path("scene.obj");
    write_scene_obj(&obj);
    let run = |args: &[&str]| {
        let o = prtbake(args);
        assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
        o
    };
    let mut bytes = Vec::new();
    for threads in ["1", "2"] {
        let out = dir.path(&format!("refined-{threads}.prtb"));
        let args = ["bake", obj.to_str().unwrap(), "-o", out.to_str().unwrap(), "--rays", "32", "--bounces", "1", "--quiet"];
        run(&[&args[..], &["--refine", "0.1", "--max-vertices", "400", "--threads", threads]].concat());
        bytes.push(std::fs::read(&out).unwrap());
    }
    assert!(bytes[0] == bytes[1], "refined bundles differ between 1 and 2 threads");
    let refined = prtbake::bundle::read_bundle(&dir.path("refined-1.prtb")).unwrap();
    let meta = &refined.meta["refine"];
    let input_vertices = meta["input_vertices"].as_u64().unwrap() as usize;
    assert!(refined.mesh.vertex_count() > input_vertices && refined.mesh.vertex_count() <= 400, "{meta}");
    assert_eq!(meta["output_vertices"].as_u64(), Some(refined.mesh.vertex_count() as u64));

    // Sun masks refine the mesh too, from a mesh file.
    let sun = dir.path("sun.prtb");
    run(&[
        "sun",
        obj.to_str().unwrap(),
        "-o",
        sun.to_str().unwrap(),
        "--steps",
        "6",
        "--refine",
        "0.2",
        "--max-vertices",
        "600",
        "--quiet",
    ]);
    let sun_bundle = prtbake::bundle::read_bundle(&sun).unwrap();
    assert!(sun_bundle.mesh.vertex_count() > input_vertices, "{}", sun_bundle.meta);
    assert_eq!(sun_bundle.sun.as_ref().unwrap().masks.len(), sun_bundle.mesh.vertex_count());

    // A bundle with a transfer: the sun refines its mesh and the transfer is
    // baked again on it, as `export`, `bake` (same parameters), `sun` would.
    let baked = dir.path("baked.prtb");
    let bake_args = ["--rays", "16", "--bounces", "1", "--quantize", "f16", "--store-bounces", "--quiet"];
    run(&[&["bake", obj.to_str().unwrap(), "-o", baked.to_str().unwrap()][..], &bake_args].concat());
    let both = dir.path("both.prtb");
    let sun_args = ["--steps", "6", "--quiet"];
    run(&[&["sun", baked.to_str().unwrap(), "-o", both.to_str().unwrap(), "--refine", "0.2", "--max-vertices", "600"][..], &sun_args]
        .concat());
    let both_bundle = prtbake::bundle::read_bundle(&both).unwrap();
    assert!(both_bundle.mesh.vertex_count() > input_vertices && both_bundle.mesh.vertex_count() <= 600);
    // Its transfer is a whole bake of the refined mesh with the bundle's own
    // parameters, stored as the input was (f16): nothing stale, nothing partial.
    let params: prtbake::bake::BakeParams = serde_json::from_value(both_bundle.meta["params"].clone()).unwrap();
    let (result, _, _) = prtbake::bake::bake_mesh(&both_bundle.mesh, &params, &[]).unwrap();
    let f16 = prtbake::bundle::budget::Storage { order: 3, channels: result.channels, quantization: prtbake::bundle::Quantization::F16 };
    let lightings = prtbake::bundle::budget::reference_lightings(3);
    let choice = prtbake::bundle::budget::choose(&result.total, 3, result.channels, &[f16], f64::INFINITY, &lightings);
    let again = prtbake::bundle::make_bundle_stored(&both_bundle.mesh, &result, &params, serde_json::json!({}), Some(&choice));
    // Through the codec, which rounds the layers to f16 as stored.
    let again = prtbake::bundle::decode_bundle(&prtbake::bundle::encode_bundle(&again).unwrap()).unwrap();
    assert!(again.transfer == both_bundle.transfer, "the transfer is not a bake of the refined mesh");
    assert!(both_bundle.sun.as_ref().is_some_and(|s| s.masks.len() == both_bundle.mesh.vertex_count()));
    let stored = both_bundle.transfer.as_ref().unwrap();
    assert_eq!((stored.quantization, stored.layers.len()), (prtbake::bundle::Quantization::F16, 3), "stored as the input was");
    assert_eq!(both_bundle.meta["params"]["rays"].as_u64(), Some(16));
    assert!(both_bundle.meta["sun"]["refine"]["output_vertices"].as_u64().is_some());

    // A bundle of sun masks alone refines further (no transfer to re-bake).
    let sun_again = dir.path("sun-again.prtb");
    run(&[&["sun", sun.to_str().unwrap(), "-o", sun_again.to_str().unwrap(), "--refine", "0.1", "--max-vertices", "800"][..], &sun_args]
        .concat());
    let sun_again = prtbake::bundle::read_bundle(&sun_again).unwrap();
    assert!(sun_again.mesh.vertex_count() >= sun_bundle.mesh.vertex_count() && sun_again.transfer.is_none());
    assert_eq!(sun_again.sun.as_ref().unwrap().masks.len(), sun_again.mesh.vertex_count());

    // A culled bundle's mesh is only what its box sees: refining it is refused, by name.
    let culled = dir.path("culled.prtb");
    run(&["bake", obj.to_str().unwrap(), "-o", culled.to_str().unwrap(), "--rays", "16", "--view-box", "-1,0,-1,1,1,1", "--quiet"]);
    let again = dir.path("again.prtb");
    let o = prtbake(&["sun", culled.to_str().unwrap(), "-o", again.to_str().unwrap(), "--refine", "0.2"]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("culled.prtb") && err.contains("view box"), "{err}");
    assert!(!again.exists());
    let bad_requests = [
        &["--refine", "nan"][..],
        &["--refine", "-1"],
        &["--max-vertices", "0"],
        &["--min-edge", "0.1"],
        &["--refine-noise", "2"],
        &["--refine", "0.1", "--refine-noise", "-1"],
        &["--refine", "0.1", "--refine-noise", "inf"],
        // Past what fits: refused at once (it ran for minutes, then aborted on allocation).
        &["--max-vertices", "4294967295"],
    ];
    for bad in bad_requests {
        let out = dir.path("bad.prtb");
        for command in ["bake", "sun"] {
            if command == "sun" && bad.contains(&"--refine-noise") {
                continue;
            }
            let o = prtbake(&[&[command, obj.to_str().unwrap(), "-o", out.to_str().unwrap()][..], bad].concat());
            assert_eq!(o.status.code(), Some(2), "{command} {bad:?}");
            assert!(!out.exists());
            if bad[1] == "4294967295" {
                assert!(String::from_utf8_lossy(&o.stderr).contains("at most 25000000"), "{}", String::from_utf8_lossy(&o.stderr));
            }
        }
    }
    // Sun masks have no noise estimate to discount: asking for it is refused, not ignored.
    let out = dir.path("bad.prtb");
    let o = prtbake(&["sun", obj.to_str().unwrap(), "-o", out.to_str().unwrap(), "--refine", "0.2", "--refine-noise", "1"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--refine-noise"));
    assert!(!out.exists());
}

/// `clean --cut-intersections` reports the segments and
/// triangles it cut (summary and JSON), `bake --clean --cut-intersections`
/// bakes the same cleaned mesh as `clean --cut-intersections` to GLB then
/// `bake`, an OBJ output warns that loading it welds the cut's sides back,
/// and the flag means nothing without `--clean`. Crossings whose cut leaves
/// needles stay uncut and are listed, unless `--cut-every-crossing`.
#[test]
fn clean_and_bake_cut_intersections() {
    let dir = Scratch::new("cut-intersections");
    let obj = dir.path("room.obj");
    prtbake::mesh::write_obj(&obj, &prtbake::verify::shapes::room_with_walls_running_past()).unwrap();
    let cleaned = dir.path("cut.glb");
    let run = |args: &[&str]| {
        let o = prtbake(args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        (String::from_utf8_lossy(&o.stdout).into_owned(), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    let (json, _) = run(&["clean", obj.to_str().unwrap(), "-o", cleaned.to_str().unwrap(), "--cut-intersections", "--json"]);
    let report: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert!(report["intersections_cut"].as_u64().unwrap() > 0 && report["triangles_cut"].as_u64().unwrap() > 0, "{report}");
    let (plain, _) = run(&["clean", obj.to_str().unwrap(), "-o", dir.path("plain.obj").to_str().unwrap()]);
    assert!(plain.contains("intersections cut      0"), "{plain}");
    let (_, warned) = run(&["clean", obj.to_str().unwrap(), "-o", dir.path("cut.obj").to_str().unwrap(), "--cut-intersections", "--quiet"]);
    assert!(warned.contains("write .glb"), "{warned}");
    let common = ["--rays", "16", "--bounces", "0", "--seed", "3", "--quiet"];
    let bake = |input: &std::path::Path, out: &str, extra: &[&str]| {
        let out = dir.path(out);
        let mut args = vec!["bake", input.to_str().unwrap(), "-o", out.to_str().unwrap()];
        args.extend(common);
        args.extend(extra);
        run(&args);
        prtbake::bundle::read_bundle(&out).unwrap()
    };
    let direct = bake(&obj, "direct.prtb", &["--clean", "--cut-intersections"]);
    let via_file = bake(&cleaned, "via-file.prtb", &[]);
    assert_eq!(direct.mesh.vertex_count(), via_file.mesh.vertex_count(), "vertex counts");
    assert_eq!(direct.mesh.positions, via_file.mesh.positions);
    assert_eq!(direct.mesh.indices, via_file.mesh.indices);
    let o = prtbake(&["bake", obj.to_str().unwrap(), "-o", dir.path("x.prtb").to_str().unwrap(), "--cut-intersections"]);
    assert_eq!(o.status.code(), Some(2), "{}", String::from_utf8_lossy(&o.stderr));

    // Twenty thin triangles through one point: the cut's needles there
    // cannot be repaired, so those crossings stay uncut and are named;
    // --cut-every-crossing cuts them and leaves the needles.
    let thin = dir.path("thin.obj");
    prtbake::mesh::write_obj(&thin, &prtbake::clean::fixtures::thin_crossing(20)).unwrap();
    let thin_out = dir.path("thin-out.glb");
    let clean_thin = |extra: &[&str]| {
        let mut args = vec!["clean", thin.to_str().unwrap(), "-o", thin_out.to_str().unwrap(), "--cut-intersections", "--json"];
        args.extend(extra);
        serde_json::from_str::<serde_json::Value>(&run(&args).0).unwrap()
    };
    let careful = clean_thin(&[]);
    let left =
        |r: &serde_json::Value| r["cut_surface_pairs_left_uncut"].as_u64().unwrap() + r["cut_triangle_pairs_left_uncut"].as_u64().unwrap();
    assert!(left(&careful) > 0 && careful["cut_left_uncut"][0]["materials"].is_array(), "{careful}");
    assert!(careful["cut_min_angle_deg"].as_f64().unwrap() >= 1.0 && careful["cut_needles_left"] == 0, "{careful}");
    let every = clean_thin(&["--cut-every-crossing"]);
    assert_eq!(left(&every), 0, "{every}");
    assert!(every["cut_min_angle_deg"].as_f64().unwrap() < 1.0 && every["cut_needles_left"].as_u64().unwrap() > 0, "{every}");
    let o = prtbake(&["clean", thin.to_str().unwrap(), "-o", dir.path("y.glb").to_str().unwrap(), "--cut-every-crossing"]);
    assert_eq!(o.status.code(), Some(2), "{}", String::from_utf8_lossy(&o.stderr));
}

/// `bake --adaptive F` adds points after bounce 0 and records the
/// factor in META; it is on (0.25, at 32 rays) by default, off with `--sampling vertex`; a
/// factor outside 0..=16, or one with `--sampling vertex`, is refused with
/// exit 2 and nothing written, and so is an adaptive shard's round without
/// the merged pilot.
#[test]
fn bake_adaptive_records_its_factor_and_refuses_what_it_cannot_do() {
    let dir = Scratch::new("adaptive");
    let obj = dir.path("scene.obj");
    write_scene_obj(&obj);
    let base_out = dir.path("base.prtb");
    let adaptive_out = dir.path("adaptive.prtb");
    let base = ["bake", obj.to_str().unwrap(), "--rays", "32", "--bounces", "1", "--quiet", "--json"];
    let mut points = Vec::new();
    for (out, extra) in [(&base_out, &["--adaptive", "0"][..]), (&adaptive_out, &["--adaptive", "1"][..])] {
        let o = prtbake(&[&base[..], &["-o", out.to_str().unwrap()], extra].concat());
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        points.push(report["stats"]["points"].as_u64().unwrap());
    }
    assert!(points[1] > points[0] && points[1] <= 2 * points[0], "points {points:?}");
    let meta = |path: &std::path::Path| prtbake::bundle::read_bundle(path).unwrap().meta;
    let added = meta(&adaptive_out)["stats"]["points_added"].as_u64();
    assert_eq!(added, Some(points[1] - points[0]), "META counts the added points");
    assert_eq!(meta(&adaptive_out)["params"]["adaptive"].as_f64(), Some(1.0));
    assert!(meta(&base_out)["params"].get("adaptive").is_none(), "a bake without it records nothing new");
    // The default is adaptive at 32 rays: the same bytes as `--rays 32 --adaptive 0.25`.
    let default_out = dir.path("default.prtb");
    let quarter_out = dir.path("quarter.prtb");
    let defaults = ["bake", obj.to_str().unwrap(), "--bounces", "1", "--quiet", "--json"];
    let o = prtbake(&[&defaults[..], &["-o", default_out.to_str().unwrap()]].concat());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = prtbake(&[&base[..], &["-o", quarter_out.to_str().unwrap(), "--adaptive", "0.25"]].concat());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(std::fs::read(&default_out).unwrap() == std::fs::read(&quarter_out).unwrap(), "the default is --rays 32 --adaptive 0.25");
    assert_eq!(meta(&default_out)["params"]["adaptive"].as_f64(), Some(0.25));
    // ... but not with vertex sampling, which adaptive allocation cannot serve.
    let vertex_out = dir.path("vertex.prtb");
    let o = prtbake(&[&base[..], &["-o", vertex_out.to_str().unwrap(), "--sampling", "vertex"]].concat());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(meta(&vertex_out)["params"].get("adaptive").is_none());
    // A shard of an adaptive bake needs the pilot stage's merge (docs/scale.md).
    let part = dir.path("part.prtp");
    let o = prtbake(&["bake", obj.to_str().unwrap(), "-o", part.to_str().unwrap(), "--shard", "0/2"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--pilot"), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!part.exists());
    for bad in [
        &["--adaptive", "-1"][..],
        &["--adaptive", "nan"],
        &["--adaptive", "17"],
        &["--adaptive", "1", "--shard", "0/2"],
        &["--adaptive", "1", "--sampling", "vertex"],
    ] {
        let out = dir.path("bad.prtb");
        let o = prtbake(&[&["bake", obj.to_str().unwrap(), "-o", out.to_str().unwrap()][..], bad].concat());
        assert_eq!(o.status.code(), Some(2), "{bad:?}: {}", String::from_utf8_lossy(&o.stderr));
        assert!(!out.exists());
    }
}

/// Flags that only mean something with another are refused without it
/// (`--view-points` was ignored without `--view-box`); `export --layer
/// direct` names bounce 0 as `view --layers direct` does; messages name
/// layers and vectors as a user writes them.
#[test]
fn small_argument_rules() {
    let dir = Scratch::new("cli-small");
    let obj = dir.path("scene.obj");
    write_scene_obj(&obj);
    let out = dir.path("s.prtb");
    let o = prtbake(&["bake", obj.to_str().unwrap(), "-o", out.to_str().unwrap(), "--view-points", "100000000"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--view-box"), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!out.exists());
    let o = prtbake(&[
        "bake",
        obj.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--rays",
        "8",
        "--bounces",
        "1",
        "--store-bounces",
        "--quiet",
    ]);
    assert!(o.status.success());
    let glb = dir.path("direct.glb");
    let o = prtbake(&["export", out.to_str().unwrap(), "-o", glb.to_str().unwrap(), "--layer", "direct", "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(report["report"]["layer"], "bounce 0");
    let o = prtbake(&["export", out.to_str().unwrap(), "-o", glb.to_str().unwrap(), "--layer", "5"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("no bounce 5 layer"), "{}", String::from_utf8_lossy(&o.stderr));
    let o = prtbake(&["inspect", out.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("layers total, bounce 0, bounce 1"), "{}", String::from_utf8_lossy(&o.stdout));
    let o = prtbake(&["sun", obj.to_str().unwrap(), "-o", dir.path("n.prtb").to_str().unwrap(), "--north", "0,1,0"]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.code() == Some(2) && e.contains("--north 0,1,0") && !e.contains("Vec3"), "{e}");
}

/// `inspect MESH` lists what a mesh is made of before a bake: materials and
/// groups with exact triangle counts and areas, and their likely role.
#[test]
fn inspect_lists_a_meshs_materials_and_groups() {
    let dir = Scratch::new("cli-inspect-mesh");
    let obj = dir.path("room.obj");
    // A 2 × 1 floor (two triangles), a 1 × 1 pane, a lamp triangle of area 0.5.
    std::fs::write(dir.path("room.mtl"), "newmtl floor\nKd 0.5 0.5 0.5\nnewmtl Window_Glass\nKd 0.9 0.9 0.9\nnewmtl lamp\nKd 1 1 1\n")
        .unwrap();
    std::fs::write(
        &obj,
        "mtllib room.mtl\nv 0 0 0\nv 2 0 0\nv 2 0 1\nv 0 0 1\nv 0 1 0\nv 1 1 0\nv 1 2 0\nv 0 2 0\n\
         o floor\nusemtl floor\nf 1 3 2\nf 1 4 3\no front\nusemtl Window_Glass\nf 5 6 7\nf 5 7 8\nusemtl lamp\nf 1 2 5\n",
    )
    .unwrap();
    let o = prtbake(&["inspect", obj.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let mesh = &doc["mesh"];
    assert_eq!(mesh["triangles"], 5);
    let row = |list: &str, name: &str| mesh[list].as_array().unwrap().iter().find(|e| e["name"] == name).unwrap().clone();
    let (floor, glass, lamp) = (row("materials", "floor"), row("materials", "Window_Glass"), row("materials", "lamp"));
    assert_eq!((floor["triangles"].as_u64(), floor["area"].as_f64()), (Some(2), Some(2.0)));
    assert_eq!((glass["triangles"].as_u64(), glass["area"].as_f64(), glass["likely"].as_str()), (Some(2), Some(1.0), Some("glass?")));
    assert_eq!((lamp["triangles"].as_u64(), lamp["likely"].as_str()), (Some(1), Some("emitter?")));
    assert!(floor["likely"].is_null());
    assert_eq!(row("groups", "front")["triangles"], 3);
    let o = prtbake(&["inspect", obj.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("--window 'Window_Glass'"), "{text}");
}

/// `clean`, `bake` and `sun` end their text report with one line on where
/// the time went: "time: T s: phase t s (p%), …", the phases largest first,
/// their seconds adding up to T and their shares to 100%.
#[test]
fn step_reports_end_with_where_the_time_went() {
    let dir = Scratch::new("time-line");
    let obj = dir.path("scene.obj");
    write_scene_obj(&obj);
    let (cleaned, baked, sunned) = (dir.path("clean.glb"), dir.path("s.prtb"), dir.path("sun.prtb"));
    let runs: [(Vec<&str>, &[&str]); 3] = [
        (
            vec!["clean", obj.to_str().unwrap(), "-o", cleaned.to_str().unwrap()],
            &["load", "clean: weld", "clean: duplicates and overlaps", "clean: zip", "clean: orient", "write"],
        ),
        (
            vec!["bake", obj.to_str().unwrap(), "-o", baked.to_str().unwrap(), "--rays", "16", "--bounces", "1"],
            &["bounce 0 (traced)", "write"],
        ),
        (vec!["sun", obj.to_str().unwrap(), "-o", sunned.to_str().unwrap(), "--quiet"], &["sun rays", "sky", "write"]),
    ];
    for (args, phases) in runs {
        let o = prtbake(&args);
        assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
        let out = String::from_utf8(o.stdout).unwrap();
        let last = out.lines().last().unwrap_or_default();
        let rest = last.strip_prefix("time: ").unwrap_or_else(|| panic!("{}: last line {last:?}", args[0]));
        let (total, parts) = rest.split_once(" s: ").unwrap();
        let total: f64 = total.parse().unwrap();
        let parsed: Vec<(String, f64, f64)> = parts
            .split(", ")
            .map(|p| {
                // "bounce 0 (traced) 9.10 s (74%)"
                let (head, share) = p.rsplit_once(" (").unwrap();
                let (name, seconds) = head.strip_suffix(" s").unwrap().rsplit_once(' ').unwrap();
                (name.to_string(), seconds.parse().unwrap(), share.trim_end_matches("%)").parse().unwrap())
            })
            .collect();
        for phase in phases {
            assert!(parsed.iter().any(|(n, _, _)| n == phase), "{}: no {phase:?} in {last:?}", args[0]);
        }
        assert!(parsed.windows(2).all(|w| w[0].1 >= w[1].1), "{}: not largest first: {last:?}", args[0]);
        let sum: f64 = parsed.iter().map(|p| p.1).sum();
        // Each figure is rounded to 0.01 s and 1%.
        assert!((sum - total).abs() <= 0.006 * parsed.len() as f64 + 1e-9, "{}: {sum} != {total}", args[0]);
        let shares: f64 = parsed.iter().map(|p| p.2).sum();
        assert!((shares - 100.0).abs() <= 0.5 * parsed.len() as f64 + 0.5, "{}: shares {shares}", args[0]);
    }
}

/// `bake --gather-fit`: bounces read each hit triangle's own fit. The same
/// bytes at any thread count, the choice recorded in META (and absent from a
/// bake without it), bounce 0 unchanged by it, and refused with `--shard`,
/// `--refine` or `--sampling vertex` (exit 2, nothing written).
#[test]
fn gather_fit_is_deterministic_recorded_and_refused_where_it_cannot_apply() {
    let dir = Scratch::new("gather-fit");
    let obj = dir.path("scene.obj");
    write_scene_obj(&obj);
    let bake = |out: &str, extra: &[&str]| {
        let out = dir.path(out);
        let mut args = vec!["bake", obj.to_str().unwrap(), "-o", out.to_str().unwrap(), "--rays", "32", "--bounces", "2", "--quiet"];
        args.extend_from_slice(extra);
        (prtbake(&args), out)
    };
    let (o1, one) = bake("one.prtb", &["--gather-fit", "--threads", "1", "--store-bounces"]);
    assert!(o1.status.success(), "{}", String::from_utf8_lossy(&o1.stderr));
    let (o2, two) = bake("two.prtb", &["--gather-fit", "--threads", "2", "--store-bounces"]);
    assert!(o2.status.success());
    assert_eq!(std::fs::read(&one).unwrap(), std::fs::read(&two).unwrap(), "--gather-fit differs between 1 and 2 threads");
    let (o3, plain) = bake("plain.prtb", &["--store-bounces"]);
    assert!(o3.status.success());
    let read = |p: &std::path::Path| prtbake::bundle::read_bundle(p).unwrap();
    let (fitted, vertex) = (read(&one), read(&plain));
    assert_eq!(fitted.meta["params"]["gather_fit"], true);
    assert!(vertex.meta["params"].get("gather_fit").is_none(), "a bake without it records nothing");
    let (tf, tv) = (fitted.transfer.unwrap(), vertex.transfer.unwrap());
    let layer = |t: &prtbake::bundle::Transfer, b: u32| {
        t.layers.iter().find(|l| l.kind == prtbake::bundle::LayerKind::Bounce(b)).map(|l| l.data.clone()).unwrap()
    };
    assert_eq!(layer(&tf, 0), layer(&tv, 0), "bounce 0 gathers nothing");
    assert_ne!(layer(&tf, 1), layer(&tv, 1), "bounce 1 reads the fit");
    for extra in [
        &["--gather-fit", "--shard", "0/2"][..],
        &["--gather-fit", "--refine", "0.1"],
        &["--gather-fit", "--sampling", "vertex", "--adaptive", "0"],
    ] {
        let (o, out) = bake("refused.prtb", extra);
        assert_eq!(o.status.code(), Some(2), "{extra:?}");
        assert!(String::from_utf8_lossy(&o.stderr).contains("--gather-fit"), "{extra:?}: {}", String::from_utf8_lossy(&o.stderr));
        assert!(!out.exists());
    }
}

/// `bake --denoise K`: the same bytes at any thread count, the strength
/// recorded in META (absent from a bake without it), the filtered values
/// neither above the largest nor below the smallest of the unfiltered ones
/// (a weighted mean of neighbours), and refused with `--refine` or
/// `--sampling vertex` (exit 2, nothing written).
#[test]
fn denoise_is_deterministic_recorded_bounded_and_refused_where_it_cannot_apply() {
    let dir = Scratch::new("denoise");
    let obj = dir.path("scene.obj");
    write_scene_obj(&obj);
    let bake = |out: &str, extra: &[&str]| {
        let out = dir.path(out);
        let mut args = vec!["bake", obj.to_str().unwrap(), "-o", out.to_str().unwrap(), "--rays", "16", "--bounces", "1", "--quiet"];
        args.extend_from_slice(extra);
        (prtbake(&args), out)
    };
    let (o1, one) = bake("one.prtb", &["--denoise", "2", "--threads", "1", "--quantize", "f32"]);
    assert!(o1.status.success(), "{}", String::from_utf8_lossy(&o1.stderr));
    let (o2, two) = bake("two.prtb", &["--denoise", "2", "--threads", "2", "--quantize", "f32"]);
    assert!(o2.status.success());
    assert_eq!(std::fs::read(&one).unwrap(), std::fs::read(&two).unwrap(), "--denoise differs between 1 and 2 threads");
    let (o3, plain) = bake("plain.prtb", &["--quantize", "f32"]);
    assert!(o3.status.success());
    let read = |p: &std::path::Path| prtbake::bundle::read_bundle(p).unwrap();
    let (filtered, raw) = (read(&one), read(&plain));
    assert_eq!(filtered.meta["params"]["denoise"], 2.0);
    assert!(raw.meta["params"].get("denoise").is_none(), "a bake without it records nothing");
    let dc = |b: &prtbake::bundle::Bundle| {
        let t = b.transfer.as_ref().unwrap();
        let layer = t.layers.iter().find(|l| l.kind == prtbake::bundle::LayerKind::Total).unwrap();
        let stride = t.channels as usize * (t.order * t.order) as usize;
        layer.data.chunks_exact(stride).map(|row| row[0]).collect::<Vec<f32>>()
    };
    let (f, r) = (dc(&filtered), dc(&raw));
    assert_ne!(f, r, "the filter moved nothing");
    let (lo, hi) = r.iter().fold((f32::MAX, f32::MIN), |(lo, hi), &x| (lo.min(x), hi.max(x)));
    assert!(f.iter().all(|&x| x >= lo - 1e-6 && x <= hi + 1e-6), "a weighted mean left the range {lo}..{hi}");
    for extra in [&["--denoise", "2", "--refine", "0.1"][..], &["--denoise", "2", "--sampling", "vertex", "--adaptive", "0"]] {
        let (o, out) = bake("refused.prtb", extra);
        assert_eq!(o.status.code(), Some(2), "{extra:?}");
        assert!(String::from_utf8_lossy(&o.stderr).contains("denoise"), "{extra:?}: {}", String::from_utf8_lossy(&o.stderr));
        assert!(!out.exists());
    }
}

/// An open-mode bake of a closed box (every wall faces in) says that almost
/// nothing sees the sky and names `--window`; the same box with its lid
/// off, which the sky lights, does not.
#[test]
fn an_open_mode_bake_of_a_closed_scene_says_so() {
    let dir = Scratch::new("sealed");
    let v = glam::Vec3::new;
    // Six inward-facing quads of a 2 m box; `lid` adds the top.
    let write_box = |name: &str, lid: bool| {
        let mut mesh = prtbake::mesh::Mesh::default();
        let mut quad = |c: [glam::Vec3; 4]| {
            let base = mesh.positions.len() as u32;
            let n = (c[1] - c[0]).cross(c[2] - c[0]).normalize();
            mesh.positions.extend(c);
            mesh.normals.extend([n; 4]);
            mesh.indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
            mesh.tri_material.extend([0; 2]);
            mesh.tri_group.extend([0; 2]);
        };
        quad([v(0., 0., 0.), v(0., 0., 2.), v(2., 0., 2.), v(2., 0., 0.)]);
        quad([v(0., 0., 0.), v(2., 0., 0.), v(2., 2., 0.), v(0., 2., 0.)]);
        quad([v(0., 0., 2.), v(0., 2., 2.), v(2., 2., 2.), v(2., 0., 2.)]);
        quad([v(0., 0., 0.), v(0., 2., 0.), v(0., 2., 2.), v(0., 0., 2.)]);
        quad([v(2., 0., 0.), v(2., 0., 2.), v(2., 2., 2.), v(2., 2., 0.)]);
        if lid {
            quad([v(0., 2., 0.), v(2., 2., 0.), v(2., 2., 2.), v(0., 2., 2.)]);
        }
        mesh.materials = vec![prtbake::mesh::Material::opaque("wall", 0.5)];
        mesh.groups = vec!["box".into()];
        let path = dir.path(name);
        prtbake::mesh::write_obj(&path, &mesh).unwrap();
        path
    };
    let bake = |input: &std::path::Path| {
        let out = dir.path("b.prtb");
        let o = prtbake(&[
            "bake",
            input.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--rays",
            "16",
            "--bounces",
            "1",
            "--one-sided",
            "*",
            "--json",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let closed = bake(&write_box("closed.obj", true));
    assert!(closed.contains("see the sky") && closed.contains("--window PATTERN"), "{closed}");
    let open = bake(&write_box("open.obj", false));
    assert!(!open.contains("see the sky"), "{open}");
}

/// `sun` on a texel bundle bakes a sun bit per texel too (TSUN), the same
/// bytes on 1 and 2 threads, shown by `inspect` and `--json`; `sun MESH
/// --texel-size` makes a sun-only texel bundle with the same bits on the
/// same atlas, and on a per-vertex bundle keeps its transfer beside them; a
/// size for a bundle that has its atlas, a bad size and `--refine` with
/// texels are refused (exit 2, nothing written).
#[test]
fn texel_sun_bits_are_baked_deterministic_and_refused_where_they_cannot_apply() {
    let dir = Scratch::new("texel-sun");
    let obj = dir.path("room.obj");
    prtbake::mesh::write_obj(&obj, &prtbake::verify::shapes::room_with_walls_running_past()).unwrap();
    let texel = dir.path("texel.prtb");
    let o = prtbake(&[
        "bake",
        obj.to_str().unwrap(),
        "-o",
        texel.to_str().unwrap(),
        "--rays",
        "8",
        "--bounces",
        "0",
        "--texel-size",
        "0.1",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let sun = |input: &std::path::Path, out: &str, extra: &[&str]| {
        let out = dir.path(out);
        let mut args = vec!["sun", input.to_str().unwrap(), "-o", out.to_str().unwrap(), "--steps", "8", "--quiet"];
        args.extend(extra);
        (prtbake(&args), out)
    };
    let (o, one) = sun(&texel, "one.prtb", &["--threads", "1"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (o, two) = sun(&texel, "two.prtb", &["--threads", "2", "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read(&one).unwrap(), std::fs::read(&two).unwrap(), "texel sun bits differ across thread counts");
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let b = prtbake::bundle::read_bundle(&one).unwrap();
    let (t, series) = (b.texels.as_ref().unwrap(), b.sun.as_ref().unwrap());
    assert_eq!(report["texels"]["stats"]["texels"].as_u64(), Some(t.texels.len() as u64), "{report}");
    assert_eq!(series.texel_masks.len(), t.texels.len() * series.words_per_vertex as usize);
    let lit = |k: usize| (0..t.texels.len()).filter(|&i| series.texel_bit(i, k)).count();
    let day: Vec<usize> = (0..series.step_count()).filter(|&k| !series.steps[k].night).collect();
    assert!(day.iter().any(|&k| lit(k) > 0 && lit(k) < t.texels.len()), "no step with both lit and shadowed texels");
    assert!((0..series.step_count()).filter(|k| !day.contains(k)).all(|k| lit(k) == 0), "a texel lit at night");
    // With --texel-fractions: the same bits, and each texel's lit share beside them, agreeing with its bit.
    let (o, frac) = sun(&texel, "frac.prtb", &["--texel-fractions"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let f = prtbake::bundle::read_bundle(&frac).unwrap();
    let fs = f.sun.as_ref().unwrap();
    assert_eq!(fs.texel_masks, series.texel_masks);
    assert_eq!(fs.texel_fractions.len(), t.texels.len() * fs.step_count().div_ceil(8));
    for k in 0..fs.step_count() {
        for i in 0..t.texels.len() {
            let share = fs.texel_sun(i, k);
            assert!(
                fs.texel_bit(i, k) == (share > 0.5) || (share - 0.5).abs() < 0.04,
                "texel {i} step {k}: bit and share {share} disagree"
            );
        }
    }
    assert!((0..t.texels.len()).any(|i| day.iter().any(|&k| (0.05..0.95).contains(&fs.texel_sun(i, k)))), "no texel in partial sun");
    let shown = String::from_utf8_lossy(&prtbake(&["inspect", one.to_str().unwrap()]).stdout).to_string();
    assert!(shown.contains("sun bits per texel") && shown.contains("TSUN") && shown.contains("(vertices, texels)"), "{shown}");
    // From the mesh: a sun-only texel bundle on the atlas the bake made of the same mesh.
    let (o, sun_only) = sun(&obj, "sun-only.prtb", &["--texel-size", "0.1"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = prtbake::bundle::read_bundle(&sun_only).unwrap();
    let st = s.texels.as_ref().unwrap();
    assert!(s.transfer.is_none() && st.transfer.is_none());
    assert_eq!((&st.atlas, &st.texels), (&t.atlas, &t.texels), "the same mesh unwraps the same");
    assert_eq!(s.sun.as_ref().unwrap().texel_masks, series.texel_masks, "the same points vote the same");
    // On a per-vertex bundle: its transfer kept, the atlas added with the sun bits.
    let vertex = dir.path("vertex.prtb");
    let o = prtbake(&["bake", obj.to_str().unwrap(), "-o", vertex.to_str().unwrap(), "--rays", "8", "--bounces", "0", "--quiet"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (o, hybrid) = sun(&vertex, "hybrid.prtb", &["--texel-size", "0.1"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let h = prtbake::bundle::read_bundle(&hybrid).unwrap();
    assert_eq!(h.transfer, prtbake::bundle::read_bundle(&vertex).unwrap().transfer);
    let ht = h.texels.as_ref().unwrap();
    assert!(ht.transfer.is_none() && ht.atlas == t.atlas);
    assert_eq!(h.sun.as_ref().unwrap().texel_masks, series.texel_masks);
    // On a texel bundle, --texel-size gives the sun an atlas of its own (TSAT)
    // beside the transfer's: finer bits, the transfer's sections byte for
    // byte; at half the transfer's size its charts repacked, at another
    // size a new unwrap, whose bits a vertex bundle gets on the same atlas.
    let (o, own) = sun(&texel, "own.prtb", &["--texel-size", "0.05", "--threads", "1"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (o, own_two) = sun(&texel, "own-two.prtb", &["--texel-size", "0.05", "--threads", "2"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read(&own).unwrap(), std::fs::read(&own_two).unwrap(), "own-atlas sun bits differ across thread counts");
    let ob = prtbake::bundle::read_bundle(&own).unwrap();
    let own_sun = ob.sun.as_ref().unwrap();
    let own_atlas = own_sun.texel_atlas.as_ref().expect("TSAT");
    assert_eq!(own_atlas.atlas, t.atlas.with_texel_size(0.05).unwrap().unwrap(), "the transfer's charts at twice the scale");
    // The same partition into charts (repacking numbers them anew).
    let mut renamed = std::collections::HashMap::new();
    for (&old, &new) in t.atlas.triangle_chart.iter().zip(&own_atlas.atlas.triangle_chart) {
        assert_eq!(*renamed.entry(old).or_insert(new), new, "chart {old} split by the repacking");
    }
    assert_eq!(renamed.len(), renamed.values().collect::<std::collections::HashSet<_>>().len(), "two charts merged by the repacking");
    assert!(own_atlas.texels.len() > 3 * t.texels.len(), "{} sun texels against {}", own_atlas.texels.len(), t.texels.len());
    assert_eq!((&ob.texels, &ob.transfer), (&b.texels, &b.transfer), "the texel transfer kept");
    assert_eq!(ob.meta["sun"]["texels"]["atlas"], "the texel transfer's charts, repacked");
    let (o, odd) = sun(&texel, "odd.prtb", &["--texel-size", "0.06"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (o, odd_hybrid) = sun(&vertex, "odd-hybrid.prtb", &["--texel-size", "0.06"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (od, oh) = (prtbake::bundle::read_bundle(&odd).unwrap(), prtbake::bundle::read_bundle(&odd_hybrid).unwrap());
    let (odd_sun, odd_texels) = (od.sun.as_ref().unwrap(), oh.texels.as_ref().unwrap());
    let odd_atlas = odd_sun.texel_atlas.as_ref().expect("TSAT");
    assert_eq!((&odd_atlas.atlas, &odd_atlas.texels), (&odd_texels.atlas, &odd_texels.texels));
    assert_eq!(odd_sun.texel_masks, oh.sun.as_ref().unwrap().texel_masks, "the same points vote the same on the same atlas");
    let sections = |path: &std::path::Path| {
        let bytes = std::fs::read(path).unwrap();
        let list = prtbake::bundle::list_sections(&bytes).unwrap();
        list.iter().map(|s| (s.tag_name(), bytes[s.offset as usize..(s.offset + s.stored_len) as usize].to_vec())).collect::<Vec<_>>()
    };
    let kept = |path: &std::path::Path| {
        sections(path).into_iter().filter(|(tag, _)| ["XFER", "ATLS", "TXFR"].contains(&tag.as_str())).collect::<Vec<_>>()
    };
    assert_eq!(kept(&own), kept(&texel), "XFER, ATLS and TXFR copied byte for byte");
    let shown = String::from_utf8_lossy(&prtbake(&["inspect", own.to_str().unwrap()]).stdout).to_string();
    assert!(shown.contains("sun texels (TSAT)") && shown.contains("TSAB"), "{shown}");
    for (input, extra, what) in [
        (&sun_only, vec!["--texel-size", "0.1"], "sun bits only"),
        (&obj, vec!["--texel-size", "0"], "positive length"),
        (&obj, vec!["--texel-size", "0.1", "--refine", "0.2"], "--refine"),
        (&obj, vec!["--texel-size", "0.1", "--texel-points", "0"], "--texel-points"),
        (&hybrid, vec!["--refine", "0.2"], "holds texels"),
        (&vertex, vec!["--texel-fractions"], "--texel-fractions"),
    ] {
        let (o, out) = sun(input, "refused.prtb", &extra);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {err}");
        assert!(err.contains(what), "{extra:?}: {err}");
        assert!(!out.exists(), "{extra:?} wrote its output");
    }
}

/// `bake --texel-size` writes the atlas and texel transfer (ATLS, TXFR) next
/// to unchanged vertices, the same bytes on 1 and 2 threads; `inspect`
/// shows them; bad sizes and combinations it cannot do are refused (exit 2,
/// nothing written).
#[test]
fn texel_bakes_are_deterministic_inspected_and_refused_where_they_cannot_apply() {
    let dir = Scratch::new("texels");
    let obj = dir.path("room.obj");
    prtbake::mesh::write_obj(&obj, &prtbake::verify::shapes::room_with_walls_running_past()).unwrap();
    let bake = |out: &str, extra: &[&str]| {
        let out = dir.path(out);
        let mut args = vec!["bake", obj.to_str().unwrap(), "-o", out.to_str().unwrap(), "--rays", "8", "--quiet"];
        if !extra.contains(&"--bounces") {
            args.extend(["--bounces", "1"]);
        }
        args.extend(extra);
        let o = prtbake(&args);
        (o, out)
    };
    let (o, one) = bake("one.prtb", &["--texel-size", "0.25", "--threads", "1"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (o, two) = bake("two.prtb", &["--texel-size", "0.25", "--threads", "2"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read(&one).unwrap(), std::fs::read(&two).unwrap(), "texel bundles differ across thread counts");
    let stats = String::from_utf8_lossy(&o.stdout);
    assert!(stats.contains("texels: ") && stats.contains("covered of") && stats.contains("texels, bounce 1"), "{stats}");
    let (o, plain) = bake("plain.prtb", &["--threads", "1"]);
    assert!(o.status.success());
    let (texel, vertex) = (prtbake::bundle::read_bundle(&one).unwrap(), prtbake::bundle::read_bundle(&plain).unwrap());
    // The vertices' bounce reads the texels instead of the vertices: close, not the same bits.
    let dc_mean = |b: &prtbake::bundle::Bundle| {
        let data = &b.transfer.as_ref().unwrap().layers[0].data;
        data.iter().step_by(9).map(|&x| x as f64).sum::<f64>() / (data.len() / 9) as f64
    };
    let (with_texels, without) = (dc_mean(&texel), dc_mean(&vertex));
    assert!((with_texels / without - 1.0).abs() < 0.05, "vertex DC mean {with_texels} with texels, {without} without");
    assert_ne!(texel.transfer.as_ref().unwrap().layers, vertex.transfer.as_ref().unwrap().layers, "the bounce did not read the texels");
    // Direct light does not depend on the texels.
    let (_, direct_texels) = bake("direct-t.prtb", &["--texel-size", "0.25", "--bounces", "0"]);
    let (_, direct_plain) = bake("direct-v.prtb", &["--bounces", "0"]);
    let (a, b) = (prtbake::bundle::read_bundle(&direct_texels).unwrap(), prtbake::bundle::read_bundle(&direct_plain).unwrap());
    assert_eq!(a.transfer.as_ref().unwrap().layers, b.transfer.as_ref().unwrap().layers, "direct light differs with texels");
    let t = texel.texels.as_ref().expect("texel section");
    assert_eq!(t.atlas.triangle_count(), texel.mesh.triangle_count());
    let texel_transfer = t.transfer.as_ref().expect("texel transfer");
    assert!(!t.texels.is_empty() && texel_transfer.layers[0].data.len() == t.texels.len() * 9);
    assert!(texel_transfer.layers[0].data.iter().any(|&x| x > 0.0));
    let shown = prtbake(&["inspect", one.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&shown.stdout);
    assert!(text.contains("texels: atlas") && text.contains("ATLS") && text.contains("TXFR"), "{text}");
    for (extra, what) in [
        (vec!["--texel-size", "0"], "positive length"),
        (vec!["--texel-size", "nan"], "positive length"),
        (vec!["--texel-size", "0.25", "--refine", "0.1"], "--refine"),
        (vec!["--texel-size", "0.25", "--sampling", "vertex"], "--sampling vertex"),
        (vec!["--texel-size", "1e-6"], "texels"),
    ] {
        let (o, out) = bake("refused.prtb", &extra);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_ne!(o.status.code(), Some(0), "{extra:?} was accepted");
        assert!(err.contains(what), "{extra:?}: {err}");
        assert!(!out.exists(), "{extra:?} wrote its output");
    }
    // `--quantize f16` stores the texels as f16 too, within f16's rounding of the f32 bake.
    let (o, half) = bake("half.prtb", &["--texel-size", "0.25", "--threads", "1", "--quantize", "f16"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let half = prtbake::bundle::read_bundle(&half).unwrap();
    let h = half.texels.as_ref().unwrap().transfer.as_ref().unwrap();
    assert_eq!(h.quantization, prtbake::bundle::Quantization::F16);
    for (a, b) in h.layers[0].data.iter().zip(&texel_transfer.layers[0].data) {
        assert!((a - b).abs() <= b.abs() / 2048.0 + 1e-7, "f16 texel {a} against f32 {b}");
    }
    // Sun masks add to a texel bundle and keep its texels; refining its mesh would lose them, so it is refused.
    let sunned = dir.path("sunned.prtb");
    let o = prtbake(&["sun", one.to_str().unwrap(), "-o", sunned.to_str().unwrap(), "--steps", "6", "--quiet"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let sunned = prtbake::bundle::read_bundle(&sunned).unwrap();
    assert!(sunned.sun.is_some() && sunned.texels.as_ref().map(|t| &t.texels) == Some(&t.texels), "the texels were not kept");
    let refused = dir.path("sun-refined.prtb");
    let o = prtbake(&["sun", one.to_str().unwrap(), "-o", refused.to_str().unwrap(), "--steps", "6", "--refine", "0.2", "--quiet"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("holds texels") && err.contains("one.prtb"), "{err}");
    assert!(!refused.exists(), "the refused sun run wrote its output");
}

/// `--texel-adaptive F`: extra texel points where bounce 0 is noisiest, the
/// same bytes on 1 and 2 threads, recorded (META `texels.adaptive` and
/// `texels.points_added`, the report line, `inspect`); the vertices are
/// the same bits as without it; out of range it is
/// refused (exit 2, nothing written).
#[test]
fn texel_adaptive_points_are_deterministic_recorded_and_refused_where_they_cannot_apply() {
    let dir = Scratch::new("texel-adaptive");
    let obj = dir.path("room.obj");
    prtbake::mesh::write_obj(&obj, &prtbake::verify::shapes::room_with_walls_running_past()).unwrap();
    let bake = |out: &str, extra: &[&str]| {
        let out = dir.path(out);
        let mut args =
            vec!["bake", obj.to_str().unwrap(), "-o", out.to_str().unwrap(), "--rays", "8", "--bounces", "1", "--texel-size", "0.25"];
        args.extend(extra);
        (prtbake(&args), out)
    };
    let (o, one) = bake("one.prtb", &["--texel-adaptive", "1", "--threads", "1", "--quiet"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (o, two) = bake("two.prtb", &["--texel-adaptive", "1", "--threads", "2", "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read(&one).unwrap(), std::fs::read(&two).unwrap(), "adaptive texel bundles differ across thread counts");
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let (points, added) = (report["texels"]["points"].as_u64().unwrap(), report["texels"]["points_added"].as_u64().unwrap());
    let (o, plain) = bake("plain.prtb", &["--threads", "1", "--json"]);
    assert!(o.status.success());
    let plain_report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let base = plain_report["texels"]["points"].as_u64().unwrap();
    assert_eq!(points, base + added);
    assert!(added > 0 && added <= base, "{added} points added to {base}");
    let (adaptive, plain) = (prtbake::bundle::read_bundle(&one).unwrap(), prtbake::bundle::read_bundle(&plain).unwrap());
    assert_eq!(adaptive.meta["texels"]["points_added"].as_u64(), Some(added));
    assert_eq!(adaptive.meta["texels"]["adaptive"].as_f64(), Some(1.0));
    assert!(plain.meta["texels"].get("points_added").is_none() && plain.meta["texels"].get("adaptive").is_none());
    // Bounce 0 of the vertices reads no texel: the same bits; the texels differ.
    let layer0 = |b: &prtbake::bundle::Bundle| b.transfer.as_ref().unwrap().layers[0].data.clone();
    let texels0 = |b: &prtbake::bundle::Bundle| b.texels.as_ref().unwrap().transfer.as_ref().unwrap().layers[0].data.clone();
    assert_ne!(texels0(&adaptive), texels0(&plain), "the extra points changed no texel");
    let (o, direct_a) = bake("direct-a.prtb", &["--texel-adaptive", "1", "--bounces", "0", "--quiet"]);
    assert!(o.status.success());
    let (_, direct_p) = bake("direct-p.prtb", &["--bounces", "0", "--quiet"]);
    let (direct_a, direct_p) = (prtbake::bundle::read_bundle(&direct_a).unwrap(), prtbake::bundle::read_bundle(&direct_p).unwrap());
    assert_eq!(layer0(&direct_a), layer0(&direct_p), "the vertices' direct light changed");
    let shown = prtbake(&["inspect", one.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&shown.stdout);
    assert!(text.contains(&format!("{added} texel points added")) && text.contains("--texel-adaptive 1"), "{text}");
    for (extra, what) in [(vec!["--texel-adaptive", "17"], "0..=16"), (vec!["--texel-adaptive=-1"], "0..=16")] {
        let (o, out) = bake("refused.prtb", &extra);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {err}");
        assert!(err.contains(what), "{extra:?}: {err}");
        assert!(!out.exists(), "{extra:?} wrote its output");
    }
    let o = prtbake(&["bake", obj.to_str().unwrap(), "-o", dir.path("no-texels.prtb").to_str().unwrap(), "--texel-adaptive", "1"]);
    assert_eq!(o.status.code(), Some(2), "--texel-adaptive without --texel-size was accepted");
}

/// `--texel-levels N --max-error E`: `bake` and `sun` size each chart's
/// texels with a pilot, the same bytes on 1 and 2 threads, and record the
/// choice (META `texels.density`, `sun.texels.density`, the report line);
/// the charts' texel sizes span the levels. Without the budget, with N
/// outside 2..=4, and on a mesh's own atlas without
/// `--unwrap` it is refused (exit 2, nothing written).
#[test]
fn texel_levels_are_deterministic_recorded_and_refused_where_they_cannot_apply() {
    let dir = Scratch::new("texel-levels");
    let obj = dir.path("room.obj");
    prtbake::mesh::write_obj(&obj, &prtbake::verify::shapes::room_with_walls_running_past()).unwrap();
    let run = |command: &str, input: &std::path::Path, out: &str, extra: &[&str]| {
        let out = dir.path(out);
        let mut args = vec![command, input.to_str().unwrap(), "-o", out.to_str().unwrap()];
        if command == "bake" {
            args.extend(["--rays", "8", "--bounces", "0"]);
        } else {
            args.extend(["--steps", "8"]);
        }
        args.extend(extra);
        (prtbake(&args), out)
    };
    let levels = ["--texel-size", "0.05", "--texel-levels", "3", "--max-error", "0.02"];
    for command in ["bake", "sun"] {
        let (o, one) = run(command, &obj, &format!("{command}-1.prtb"), &[&levels[..], &["--threads", "1", "--quiet"]].concat());
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let (o, two) = run(command, &obj, &format!("{command}-2.prtb"), &[&levels[..], &["--threads", "2"]].concat());
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(
            String::from_utf8_lossy(&o.stdout).contains("texel density: 3 sizes 0.05..0.2 m"),
            "{}",
            String::from_utf8_lossy(&o.stdout)
        );
        assert!(std::fs::read(&one).unwrap() == std::fs::read(&two).unwrap(), "{command}: texel levels differ across thread counts");
        let b = prtbake::bundle::read_bundle(&one).unwrap();
        let density = if command == "bake" { &b.meta["texels"]["density"] } else { &b.meta["sun"]["texels"]["density"] };
        assert_eq!(density["levels"].as_u64(), Some(3), "{density}");
        assert_eq!(density["pilot_texel_size"].as_f64(), Some(0.2f32 as f64), "{density}");
        let per_level: Vec<u64> = density["charts_per_level"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect();
        let atlas = &b.texels.as_ref().unwrap().atlas;
        assert_eq!(per_level.iter().sum::<u64>(), u64::from(atlas.chart_count), "{density}");
        assert!(per_level[0] > 0 && per_level[2] > 0, "{command}: no chart kept coarse or made finest: {density}");
        // Within the budget, or as low as the finest texels go (the model halves a chart's squared error per level).
        let (estimated, coarsest) = (density["estimated_error"].as_f64().unwrap(), density["coarsest_error"].as_f64().unwrap());
        assert!(estimated <= 0.02 + 1e-12 || (estimated - coarsest / 2.0).abs() < 1e-9, "{density}");
        assert_eq!(atlas.texel_size, 0.05);
        let shown = String::from_utf8_lossy(&prtbake(&["inspect", one.to_str().unwrap()]).stdout).to_string();
        assert!(shown.contains("texel size per chart, 3 sizes up to 0.2 (the pilot's)"), "{shown}");
    }
    let (mesh, _) = floor_and_board_with_lightmap();
    let glb = dir.path("own.glb");
    prtbake::mesh::write_glb(&glb, &mesh).unwrap();
    for (command, input, extra, what) in [
        ("bake", &obj, vec!["--texel-size", "0.05", "--texel-levels", "3"], "--max-error"),
        ("sun", &obj, vec!["--texel-size", "0.05", "--texel-levels", "3"], "--max-error"),
        ("bake", &obj, vec!["--texel-size", "0.05", "--texel-levels", "5", "--max-error", "0.1"], "2..=4"),
        ("sun", &obj, vec!["--texel-size", "0.05", "--texel-levels", "1", "--max-error", "0.1"], "2..=4"),
        // A finest size refused as a uniform atlas would be, though the pilot's 8× coarser one fits.
        ("bake", &obj, vec!["--texel-size", "0.0002", "--texel-levels", "4", "--max-error", "0.1"], "0.0002 would need"),
        ("bake", &glb, vec!["--texel-size", "0.1", "--texel-levels", "2", "--max-error", "0.1"], "--unwrap"),
        ("sun", &glb, vec!["--texel-size", "0.1", "--texel-levels", "2", "--max-error", "0.1"], "--unwrap"),
    ] {
        let (o, out) = run(command, input, "refused.prtb", &extra);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{command} {extra:?}: {err}");
        assert!(err.contains(what), "{command} {extra:?}: {err}");
        assert!(!out.exists(), "{command} {extra:?} wrote its output");
    }
}

/// A 2 m floor and a 0.8 m board above it, each one chart of its own
/// lightmap (glTF `TEXCOORD_1`), side by side in the unit square.
fn floor_and_board_with_lightmap() -> (prtbake::mesh::Mesh, fn(glam::Vec3) -> glam::Vec2) {
    use prtbake::verify::shapes;
    let mut mesh = shapes::plane_grid(4, 2.0);
    let mut board = shapes::plane_grid(1, 0.8);
    shapes::transform(&mut board, 1.0, glam::Vec3::new(0.0, 0.5, 0.0));
    shapes::append(&mut mesh, &board);
    fn lightmap(p: glam::Vec3) -> glam::Vec2 {
        if p.y > 0.25 {
            glam::Vec2::new(0.55 + 0.5 * (p.x + 0.4), 0.05 + 0.5 * (p.z + 0.4))
        } else {
            glam::Vec2::new(0.05 + 0.2 * (p.x + 1.0), 0.05 + 0.2 * (p.z + 1.0))
        }
    }
    mesh.lightmap_uvs = mesh.positions.iter().map(|&p| lightmap(p)).collect();
    (mesh, lightmap)
}

/// A glTF mesh with its own lightmap coordinates keeps them as its atlas
/// through `clean`, `bake --texel-size` (with `--clean` too) and `sun
/// --texel-size`; `--unwrap` unwraps a new one; an OBJ output says it drops them.
#[test]
fn a_mesh_with_its_own_texcoord_1_keeps_its_atlas() {
    let dir = Scratch::new("lightmap");
    let glb = dir.path("lit.glb");
    let (mesh, lightmap) = floor_and_board_with_lightmap();
    prtbake::mesh::write_glb(&glb, &mesh).unwrap();
    let run = |args: &[&str]| {
        let o = prtbake(args);
        assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
        o
    };
    // The atlas is the file's, scaled to the texel size: each atlas vertex at
    // its mesh vertex's lightmap coordinates times the atlas's side.
    let assert_own_atlas = |bundle: &std::path::Path| {
        let b = prtbake::bundle::read_bundle(bundle).unwrap();
        let atlas = &b.texels.as_ref().expect("texels").atlas;
        // 4.64 m² on 0.32 of the atlas at 10 cm: ceil(38.08) = 39 texels across.
        assert_eq!((atlas.width, atlas.height, atlas.chart_count), (39, 39, 2), "{}", bundle.display());
        for (i, uv) in atlas.uv.iter().enumerate() {
            let p = b.mesh.positions[atlas.source_vertex[i] as usize];
            assert!(uv.abs_diff_eq(lightmap(p) * 39.0, 1e-3), "{}: atlas vertex {i} at {uv}, position {p}", bundle.display());
        }
        atlas.clone()
    };
    let shown = run(&["inspect", glb.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&shown.stdout).contains("lightmap atlas: its own (TEXCOORD_1)"));
    let baked = dir.path("baked.prtb");
    let o = run(&["bake", glb.to_str().unwrap(), "--clean", "--texel-size", "0.1", "--rays", "8", "-o", baked.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("2 charts of TEXCOORD_1"), "{}", String::from_utf8_lossy(&o.stdout));
    let own = assert_own_atlas(&baked);
    let shown = run(&["inspect", baked.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&shown.stdout).contains("2 charts of TEXCOORD_1"), "{}", String::from_utf8_lossy(&shown.stdout));
    let sunned = dir.path("sun.prtb");
    run(&["sun", glb.to_str().unwrap(), "--texel-size", "0.1", "--steps", "4", "-o", sunned.to_str().unwrap(), "--quiet"]);
    assert_own_atlas(&sunned);
    // A per-vertex bundle keeps the file's TEXCOORD_1 (MESH), so texel sun
    // bits added to it later lie on the file's atlas too.
    let per_vertex = dir.path("per-vertex.prtb");
    run(&["bake", glb.to_str().unwrap(), "--clean", "--rays", "8", "-o", per_vertex.to_str().unwrap(), "--quiet"]);
    assert!(prtbake::bundle::read_bundle(&per_vertex).unwrap().texels.is_none());
    let later = dir.path("later-sun.prtb");
    run(&["sun", per_vertex.to_str().unwrap(), "--texel-size", "0.1", "--steps", "4", "-o", later.to_str().unwrap(), "--quiet"]);
    assert_own_atlas(&later);
    let shown = run(&["inspect", sunned.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&shown.stdout).contains("2 charts of TEXCOORD_1"), "{}", String::from_utf8_lossy(&shown.stdout));
    // --unwrap: xatlas's, another layout.
    let unwrapped = dir.path("unwrapped.prtb");
    let o = run(&["bake", glb.to_str().unwrap(), "--texel-size", "0.1", "--unwrap", "--rays", "8", "-o", unwrapped.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("of xatlas"));
    let b = prtbake::bundle::read_bundle(&unwrapped).unwrap();
    assert_ne!(b.texels.as_ref().unwrap().atlas.uv, own.uv);
    // clean keeps TEXCOORD_1 in a GLB; an OBJ cannot hold it, and says so.
    let cleaned = dir.path("cleaned.glb");
    run(&["clean", glb.to_str().unwrap(), "-o", cleaned.to_str().unwrap()]);
    let back = prtbake::mesh::load_mesh(&cleaned, &Default::default()).unwrap().mesh;
    assert_eq!(back.lightmap_uvs.len(), back.vertex_count());
    for (v, uv) in back.lightmap_uvs.iter().enumerate() {
        assert!(uv.abs_diff_eq(lightmap(back.positions[v]), 1e-5), "cleaned vertex {v}");
    }
    let obj = dir.path("cleaned.obj");
    let o = run(&["clean", glb.to_str().unwrap(), "-o", obj.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("TEXCOORD_1"), "{}", String::from_utf8_lossy(&o.stderr));
    // Coordinates that would mix two places are refused, naming the way out.
    let mut stacked = mesh.clone();
    stacked.lightmap_uvs.iter_mut().filter(|uv| uv.x > 0.5).for_each(|uv| uv.x -= 0.5);
    let bad = dir.path("stacked.glb");
    prtbake::mesh::write_glb(&bad, &stacked).unwrap();
    let refused = dir.path("refused.prtb");
    let o = prtbake(&["bake", bad.to_str().unwrap(), "--texel-size", "0.1", "--rays", "8", "-o", refused.to_str().unwrap(), "--quiet"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_ne!(o.status.code(), Some(0), "{err}");
    assert!(err.contains("stacked.glb") && err.contains("TEXCOORD_1") && err.contains("--unwrap"), "{err}");
    assert!(!refused.exists());
}
