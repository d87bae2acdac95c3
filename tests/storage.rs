//! "No more than needed": quantized and budgeted transfer storage, and
//! view-box culling, through the binary and the library.

use glam::Vec3;
use prtbake::bake::{self, cull, BakeParams};
use prtbake::bundle::budget;
use prtbake::bundle::read_bundle;

use crate::util::{prtbake, shared_data, write_scene_obj, Scratch};

fn bake(dir: &Scratch, name: &str, extra: &[&str]) -> (std::path::PathBuf, serde_json::Value) {
    let obj = dir.path("scene.obj");
    if !obj.exists() {
        write_scene_obj(&obj);
    }
    let out = dir.path(name);
    let mut args = vec!["bake", obj.to_str().unwrap(), "-o", out.to_str().unwrap(), "--rays", "64", "--bounces", "1", "--json"];
    args.extend(extra);
    let o = prtbake(&args);
    assert!(o.status.success(), "bake {extra:?} failed: {}", String::from_utf8_lossy(&o.stderr));
    (out, serde_json::from_slice(&o.stdout).unwrap())
}

/// Every quantization decodes to within the shaded error the bundle records,
/// measured again here from the decoded bundle against the f32 one.
#[test]
fn quantized_bundles_decode_within_recorded_error() {
    let dir = Scratch::new("quantize");
    let (f32_path, _) = bake(&dir, "f32.prtb", &["--order", "3"]);
    let exact = read_bundle(&f32_path).unwrap().transfer.unwrap();
    assert!(read_bundle(&f32_path).unwrap().meta.get("storage").is_none());
    let lights = budget::reference_lightings(3);
    for (q, bytes) in [("f16", 54), ("i16", 58), ("f16-tinted", 24)] {
        let (path, _) = bake(&dir, &format!("{q}.prtb"), &["--order", "3", "--quantize", q]);
        let b = read_bundle(&path).unwrap();
        let t = b.transfer.unwrap();
        let storage = &b.meta["storage"];
        assert_eq!(storage["quantization"], q);
        assert_eq!(storage["bytes_per_vertex_per_layer"], bytes);
        assert_eq!(t.quantization.name(), q);
        let recorded = storage["shaded_error"].as_f64().unwrap();
        let measured = lights
            .iter()
            .map(|l| {
                budget::relative_rms(
                    &budget::shade(&exact.layers[0].data, 3, 3, &l.sh),
                    &budget::shade(&t.layers[0].data, t.order as usize, t.channels as usize, &l.sh),
                )
            })
            .fold(0.0, f64::max);
        eprintln!("{q}: recorded shaded error {recorded:.3e}, measured from the decoded bundle {measured:.3e}");
        assert!((measured - recorded).abs() <= 1e-9 + 1e-6 * recorded, "{q}: {measured} vs {recorded}");
        assert!(recorded < if q == "f16-tinted" { 0.2 } else { 1e-3 });
    }
}

/// A loose budget stores a lower order (and says so in META); a tight one keeps everything.
#[test]
fn max_error_picks_lower_order_when_the_budget_allows() {
    let dir = Scratch::new("budget");
    // --adaptive 1 keeps the bake's own noise well inside the budget (with the
    // default 0.25 the noise leaves storage no room), so it can drop an order.
    let (loose, report) = bake(&dir, "loose.prtb", &["--order", "4", "--max-error", "0.05", "--adaptive", "1"]);
    let b = read_bundle(&loose).unwrap();
    let s = &b.meta["storage"];
    eprintln!("--max-error 0.05 on order 4: {s}");
    let t = b.transfer.unwrap();
    assert_eq!(s["baked_order"], 4);
    assert!(t.order < 4, "order {} kept", t.order);
    assert_eq!(s["order"], t.order);
    assert_eq!(s["channels"], t.channels);
    assert!(s["shaded_error"].as_f64().unwrap() <= 0.05);
    assert_eq!(s["max_error"], 0.05);
    assert_eq!(report["storage"], *s);
    // A budget of 0 no bake meets: the storage may add only a hundredth to the noise.
    let (tight, _) = bake(&dir, "tight.prtb", &["--order", "4", "--max-error", "0"]);
    let b = read_bundle(&tight).unwrap();
    let s = &b.meta["storage"];
    let (noise, total) = (s["noise_error"].as_f64().unwrap(), s["total_error"].as_f64().unwrap());
    assert!(s["within_budget"] == false && total >= noise && total <= noise * 1.01 * (1.0 + 1e-12), "{s}");
    assert_eq!(b.transfer.unwrap().quantization.name(), s["quantization"]);
    let o = prtbake(&["bake", "x.obj", "-o", "y.prtb", "--max-error", "-1"]);
    assert_eq!(o.status.code(), Some(2));
}

/// `--max-error` budgets the total error: the bake's own estimated noise and
/// the storage's error in quadrature. Over the noise the budget leaves
/// storage only the rest; under it no storage fits, the least bytes that
/// add at most 1% to the noise are kept, META says the budget was missed
/// and stderr warns. A bake that measures no noise
/// (vertex sampling) budgets storage alone.
#[test]
fn max_error_counts_the_bakes_own_noise() {
    let dir = Scratch::new("budget-total");
    let (path, _) = bake(&dir, "noisy.prtb", &["--order", "3", "--max-error", "0.2"]);
    let s = read_bundle(&path).unwrap().meta["storage"].clone();
    let (noise, storage, total) =
        (s["noise_error"].as_f64().unwrap(), s["shaded_error"].as_f64().unwrap(), s["total_error"].as_f64().unwrap());
    eprintln!("64 rays, --max-error 0.2: noise {noise:.4}, storage {storage:.4}, total {total:.4}");
    assert!(noise > 0.02 && noise < 0.2, "a 64-ray bake of the fixture is noisy, but under 20%: {noise}");
    assert!(total <= 0.2 && total >= noise && total >= storage && s["within_budget"] == true, "{s}");
    assert!(total <= noise.hypot(storage) * (1.0 + 1e-9) + 1e-12, "the worst sky's total is at most the two worsts in quadrature: {s}");

    // Under the noise: nothing fits. Stored in the least bytes that add at
    // most 1% to the noise (not f32: i16 adds ~1e-5), with a warning.
    let obj = dir.path("scene.obj");
    let tight = dir.path("tight.prtb");
    let budget = format!("{}", noise / 2.0);
    let o =
        prtbake(&["bake", obj.to_str().unwrap(), "-o", tight.to_str().unwrap(), "--rays", "64", "--bounces", "1", "--max-error", &budget]);
    assert!(o.status.success());
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("estimated noise") && stderr.contains("tight.prtb") && stderr.contains("no storage meets it"), "{stderr}");
    let b = read_bundle(&tight).unwrap();
    let s = &b.meta["storage"];
    let (noise, total) = (s["noise_error"].as_f64().unwrap(), s["total_error"].as_f64().unwrap());
    assert!(s["within_budget"] == false && total >= noise && total <= noise * 1.01 * (1.0 + 1e-12), "{s}");
    assert!(s["bytes_per_vertex_per_layer"].as_u64() < s["f32_bytes_per_vertex_per_layer"].as_u64(), "{s}");
    assert_eq!(b.transfer.as_ref().unwrap().quantization.name(), s["quantization"]);

    // Vertex sampling measures no noise: the budget is the storage's alone.
    let (vertex, _) = bake(&dir, "vertex.prtb", &["--order", "3", "--sampling", "vertex", "--max-error", "0.2"]);
    let s = read_bundle(&vertex).unwrap().meta["storage"].clone();
    assert!(s.get("noise_error").is_none() && s["shaded_error"].as_f64().unwrap() <= 0.2, "{s}");
}

/// Texel mode under `--max-error`: the vertices and the texels are stored
/// at one order, channel count and quantization (the viewer reads both
/// together), the smallest whose total error the budget holds on each, the
/// texels measured with their own noise (META `texels.storage`). A budget
/// under the texels' noise keeps the least bytes that add at most 1% to it,
/// and warns.
#[test]
fn a_texel_bake_stores_vertices_and_texels_at_one_storage_within_the_budget_on_each() {
    let dir = Scratch::new("budget-texels");
    let texels = ["--order", "3", "--texel-size", "0.1", "--texel-points", "8"];
    fn with<'a>(texels: &[&'a str], budget: &'a str) -> Vec<&'a str> {
        texels.iter().copied().chain(["--max-error", budget]).collect()
    }
    let (path, report) = bake(&dir, "texels.prtb", &with(&texels, "0.3"));
    let b = read_bundle(&path).unwrap();
    let (vertices, texel_transfer) = (b.transfer.as_ref().unwrap(), b.texels.as_ref().unwrap().transfer.as_ref().unwrap());
    assert_eq!(
        (texel_transfer.order, texel_transfer.channels, texel_transfer.quantization),
        (vertices.order, vertices.channels, vertices.quantization),
        "vertices and texels are stored alike"
    );
    assert!(vertices.order < 3 || vertices.quantization.name() != "f32", "the budget left room to store less: {}", b.meta["storage"]);
    let s = &b.meta["texels"]["storage"];
    let total = s["total_error"].as_f64().unwrap();
    assert!(total <= 0.3 && total >= s["noise_error"].as_f64().unwrap() && s["within_budget"] == true, "{s}");
    assert_eq!(report["texels"]["storage"], *s, "--json reports the texels' measure");
    assert_eq!(b.meta["storage"]["order"], vertices.order);

    // Under the texels' noise: both stored alike in the least bytes that add
    // at most 1% to the texels' noise, and stderr says why.
    let noise = s["noise_error"].as_f64().unwrap();
    let tight = format!("{}", noise / 2.0);
    let obj = dir.path("scene.obj");
    let out = dir.path("tight.prtb");
    let mut args = vec!["bake", obj.to_str().unwrap(), "-o", out.to_str().unwrap(), "--rays", "64", "--bounces", "1"];
    args.extend(with(&texels, &tight));
    let o = prtbake(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stderr).contains("the texels' own estimated noise"), "{}", String::from_utf8_lossy(&o.stderr));
    let b = read_bundle(&out).unwrap();
    let (vertices, t) = (b.transfer.as_ref().unwrap(), b.texels.as_ref().unwrap().transfer.as_ref().unwrap());
    assert_eq!((t.order, t.channels, t.quantization), (vertices.order, vertices.channels, vertices.quantization));
    let s = &b.meta["texels"]["storage"];
    let (noise, total) = (s["noise_error"].as_f64().unwrap(), s["total_error"].as_f64().unwrap());
    assert!(s["within_budget"] == false && total >= noise && total <= noise * 1.01 * (1.0 + 1e-12), "{s}");
    assert!(t.quantization.name() != "f32", "i16 adds ~1e-5 to the noise: {s}");
}

/// A box room with an object sealed in a crate: a view-box bake drops the
/// sealed object and leaves the transfer of every kept vertex as in a full bake.
#[test]
fn view_box_culls_the_hidden_and_keeps_transfer() {
    let mut b = prtbake::fixtures::builder::MeshBuilder::new(vec![prtbake::mesh::Material::opaque("wall", 0.7)]);
    b.cuboid("room", Vec3::splat(-2.0), Vec3::splat(2.0), 3.0, 0);
    b.flip_groups("room");
    b.cuboid("crate", Vec3::new(0.8, -2.0, 0.8), Vec3::new(1.6, -1.2, 1.6), 6.0, 0);
    let hidden_start = b.mesh.triangle_count();
    b.cuboid("hidden", Vec3::new(1.0, -1.9, 1.0), Vec3::new(1.4, -1.5, 1.4), 6.0, 0);
    let mesh = b.mesh;
    let params = BakeParams { order: 2, rays: 128, ..BakeParams::default() };
    let surfaces = bake::Surfaces::resolve(&mesh, &[]).unwrap();
    let scene = prtbake::trace::Scene::build(&mesh, prtbake::trace::BuildQuality::Sah).unwrap();
    let view = cull::ViewBox { min: Vec3::new(-1.0, -0.5, -1.0), max: Vec3::new(0.0, 0.5, 0.0) };
    let (visible, report) = cull::visible_triangles(&mesh, &scene, &surfaces, &view, &cull::CullParams::default());
    assert!((hidden_start..mesh.triangle_count()).all(|t| !visible[t]));
    assert!(report.triangles_removed as usize >= mesh.triangle_count() - hidden_start);
    let full = bake::bake_transfer(&mesh, &scene, &surfaces, &params).unwrap();
    let culled = bake::bake_transfer_receivers(&mesh, &scene, &surfaces, &params, Some(&visible)).unwrap();
    // Vertices all of whose triangles are kept get exactly the same rays: bit-identical.
    let mut touches_culled = vec![false; mesh.vertex_count()];
    let mut touches_kept = vec![false; mesh.vertex_count()];
    for t in 0..mesh.triangle_count() {
        for v in mesh.triangle(t) {
            if visible[t] {
                touches_kept[v as usize] = true
            } else {
                touches_culled[v as usize] = true
            }
        }
    }
    let n = 4;
    let (mut identical, mut boundary, mut max_boundary_diff) = (0, 0, 0.0f32);
    for v in (0..mesh.vertex_count()).filter(|&v| touches_kept[v]) {
        let (a, b) = (&full.total[v * n..][..n], &culled.total[v * n..][..n]);
        if touches_culled[v] {
            boundary += 1;
            max_boundary_diff = a.iter().zip(b).fold(max_boundary_diff, |m, (x, y)| m.max((x - y).abs()));
        } else {
            assert_eq!(a, b, "vertex {v}");
            identical += 1;
        }
    }
    eprintln!("view-box fixture: {} of {} triangles removed; {identical} kept vertices bit-identical, {boundary} on the cut differ by ≤ {max_boundary_diff:.2e}", report.triangles_removed, report.triangles_before);
    assert!(max_boundary_diff < 0.05);
    assert!(culled.stats.rays < full.stats.rays);
}

/// The grey-white room from a 1 m box around its centre: what culling removes,
/// and how far the kept vertices' transfer moves against the bake's own noise
/// (two seeds of the full bake).
#[test]
fn grey_white_room_culling() {
    let Some(path) = shared_data("room-grey-white/grey_white_room_flat.obj") else { return };
    let mesh = prtbake::mesh::load_mesh(&path, &Default::default()).unwrap().mesh;
    let surfaces = bake::Surfaces::resolve(&mesh, &[]).unwrap();
    let scene = prtbake::trace::Scene::build(&mesh, prtbake::trace::BuildQuality::Sah).unwrap();
    let view = cull::ViewBox::around_centre(&mesh, 0.5);
    let (visible, report) = cull::visible_triangles(&mesh, &scene, &surfaces, &view, &cull::CullParams::default());
    eprintln!(
        "grey-white room, view box {:?}..{:?}: {} of {} triangles removed, {} kept; {} of {} vertices kept; {} rays, {} escaped",
        view.min,
        view.max,
        report.triangles_removed,
        report.triangles_before,
        report.triangles_kept,
        report.vertices_kept,
        report.vertices_before,
        report.rays,
        report.rays_escaped
    );
    assert!(report.triangles_removed > 0);
    let params = BakeParams { order: 2, rays: 32, ..BakeParams::default() };
    let full = bake::bake_transfer(&mesh, &scene, &surfaces, &params).unwrap();
    let culled = bake::bake_transfer_receivers(&mesh, &scene, &surfaces, &params, Some(&visible)).unwrap();
    let other_seed = bake::bake_transfer(&mesh, &scene, &surfaces, &BakeParams { seed: 2, ..params }).unwrap();
    let mut kept = vec![false; mesh.vertex_count()];
    (0..mesh.triangle_count()).filter(|&t| visible[t]).for_each(|t| mesh.triangle(t).iter().for_each(|&v| kept[v as usize] = true));
    let rms = |a: &[f32], b: &[f32]| {
        let (mut s, mut k) = (0.0f64, 0usize);
        for v in (0..kept.len()).filter(|&v| kept[v]) {
            for i in 0..4 {
                s += (a[v * 4 + i] as f64 - b[v * 4 + i] as f64).powi(2);
                k += 1;
            }
        }
        (s / k as f64).sqrt()
    };
    let cull_change = rms(&full.total, &culled.total);
    let noise = rms(&full.total, &other_seed.total);
    eprintln!("grey-white room: RMS transfer change of kept vertices {cull_change:.3e}; seed-to-seed noise {noise:.3e}; rays {} (culled) vs {} (full)", culled.stats.rays, full.stats.rays);
    assert!(cull_change <= noise, "culling moved kept transfer by {cull_change}, noise is {noise}");
}
