//! The viewer against the CPU evaluation of its shading formula: headless
//! frames on whatever adapter exists (CI: Mesa's lavapipe); skipped with a
//! notice when there is none.

use glam::Vec3;
use prtbake::bundle::{Bundle, LayerKind, Quantization, SunSeries, SunStep, Transfer, TransferLayer};
use prtbake::mesh::Mesh;
use prtbake::sh;
use prtbake::verify::shapes;
use prtbake::view::scene::prepare_scene;
use prtbake::view::tonemap::{self, ToneMap, ToneOperator};
use prtbake::view::{reference, render_image, Backdrop, Camera, FrameSettings, Gpu, Image, LayerSelection, ViewError};

/// Largest allowed difference per channel, in 8-bit codes. Derivation: the
/// HDR target is binary16 (relative error ≤ 2⁻¹¹, i.e. ≤ 0.06 codes after
/// gamma 1/2.2 at exposure ≤ 1); f32 interpolation differences are far below
/// that; each side rounds to the nearest code (≤ ½ code each). So ≤ 1 code,
/// plus one code of margin for the rasteriser's fixed-point pixel positions.
pub const MAX_CODE_DIFF: i32 = 2;

pub fn gpu_or_skip(test: &str) -> Option<Gpu> {
    match Gpu::headless() {
        Ok(gpu) => {
            eprintln!("{test}: adapter {}", gpu.adapter_name());
            Some(gpu)
        }
        Err(ViewError::NoAdapter) => {
            eprintln!("SKIP: {test}: no GPU adapter at all (install mesa-vulkan-drivers for lavapipe)");
            None
        }
        Err(e) => panic!("{test}: {e}"),
    }
}

/// Open-mode transfer of an unoccluded convex object: t_lm = (Â_l/π)·y_lm(n).
pub fn unoccluded_transfer(mesh: &Mesh, order: usize) -> Vec<f32> {
    let n2 = order * order;
    let mut y = vec![0.0f32; n2];
    let mut out = Vec::with_capacity(mesh.vertex_count() * n2);
    for n in &mesh.normals {
        sh::eval_basis(order, n.normalize(), &mut y);
        out.extend((0..n2).map(|i| (sh::clamped_cosine_kernel(sh::band_of_index(i)) / std::f64::consts::PI) as f32 * y[i]));
    }
    out
}

pub fn bundle_of(mesh: Mesh, order: usize, transfer: Vec<f32>, sun: Option<SunSeries>) -> Bundle {
    Bundle {
        meta: serde_json::json!({}),
        mesh,
        transfer: Some(Transfer {
            order: order as u32,
            channels: 1,
            quantization: Quantization::F32,
            layers: vec![TransferLayer { kind: LayerKind::Total, data: transfer }],
            front_share: Vec::new(),
        }),
        sun,
        texels: None,
    }
}

pub fn linear_tonemap(exposure_stops: f32) -> ToneMap {
    ToneMap { operator: ToneOperator::Linear, exposure_stops, gamma: 2.2, ..ToneMap::default() }
}

/// Möller–Trumbore: distance and barycentrics (of corners 1 and 2) of the nearest hit.
pub fn nearest_hit(mesh: &Mesh, origin: Vec3, dir: Vec3) -> Option<(usize, f32, f32)> {
    let mut best: Option<(f32, usize, f32, f32)> = None;
    for t in 0..mesh.triangle_count() {
        let [a, b, c] = mesh.triangle_positions(t);
        let (e1, e2) = (b - a, c - a);
        let p = dir.cross(e2);
        let det = e1.dot(p);
        if det.abs() < 1e-12 {
            continue;
        }
        let s = origin - a;
        let u = s.dot(p) / det;
        let q = s.cross(e1);
        let v = dir.dot(q) / det;
        let distance = e2.dot(q) / det;
        if u < 0.0 || v < 0.0 || u + v > 1.0 || distance <= 0.0 {
            continue;
        }
        if best.is_none_or(|(d, ..)| distance < d) {
            best = Some((distance, t, u, v));
        }
    }
    best.map(|(_, t, u, v)| (t, u, v))
}

fn background(image: &Image, x: u32, y: u32) -> bool {
    // A black backdrop: zero radiance → code 0.
    image.pixel(x, y)[..3] == [0, 0, 0]
}

#[test]
fn sphere_matches_cpu_shading_pixel_for_pixel() {
    let Some(gpu) = gpu_or_skip("sphere_matches_cpu_shading_pixel_for_pixel") else { return };
    let order = 3;
    let mut mesh = shapes::icosphere(3);
    mesh.materials[0].albedo = [0.8, 0.6, 0.4];
    let transfer = unoccluded_transfer(&mesh, order);
    let bundle = bundle_of(mesh.clone(), order, transfer, None);
    let scene = prepare_scene(&bundle, &LayerSelection::Total, &[]).unwrap();
    // A known lighting: bright from +Y and +Z, tinted, with some band-2 detail.
    let lighting: Vec<[f32; 3]> = vec![
        [1.2, 1.1, 1.0],
        [0.5, 0.45, 0.4],
        [0.6, 0.6, 0.7],
        [0.2, -0.1, 0.0],
        [0.05, 0.0, 0.02],
        [0.1, 0.1, 0.1],
        [-0.15, -0.1, -0.05],
        [0.0, 0.05, 0.1],
        [0.1, 0.0, -0.05],
    ];
    let settings = FrameSettings { lighting: lighting.clone(), sun_step: None, backdrop: Backdrop::Black, tonemap: linear_tonemap(0.5) };
    let (width, height) = (128, 128);
    let camera = Camera::look_at(Vec3::new(0.8, 1.1, 2.8), Vec3::ZERO, scene.bounds);
    let image = render_image(&gpu, &scene, None, &camera, &settings, width, height).unwrap();

    // CPU: per vertex E, then for every pixel centre the perspective-correct
    // interpolation (a ray hit's barycentrics), albedo, tone map, quantize.
    let vertex_light: Vec<[f32; 3]> =
        (0..mesh.vertex_count()).map(|v| reference::vertex_light(&scene, &lighting, None, v, mesh.normals[v].to_array(), true)).collect();
    let albedo = mesh.materials[0].albedo;
    let mut expected: Vec<Option<[u8; 3]>> = Vec::with_capacity((width * height) as usize);
    for y in 0..height {
        for x in 0..width {
            let (origin, dir) = camera.pixel_ray(x as f32 + 0.5, y as f32 + 0.5, width, height);
            expected.push(nearest_hit(&mesh, origin, dir).map(|(t, u, v)| {
                let [a, b, c] = mesh.triangle(t).map(|i| vertex_light[i as usize]);
                let light: [f32; 3] = std::array::from_fn(|k| a[k] * (1.0 - u - v) + b[k] * u + c[k] * v);
                let rgb = tonemap::linear(reference::radiance(albedo, light), 0.5, 2.2);
                rgb.map(tonemap::to_u8)
            }));
        }
    }
    let at = |x: i64, y: i64| -> Option<Option<[u8; 3]>> {
        (x >= 0 && y >= 0 && x < width as i64 && y < height as i64).then(|| expected[(y * width as i64 + x) as usize])
    };
    let (mut compared, mut background_checked, mut max_diff, mut sum_diff) = (0, 0, 0, 0i64);
    for y in 0..height as i64 {
        for x in 0..width as i64 {
            let neighbours: Vec<Option<Option<[u8; 3]>>> =
                (-1..=1).flat_map(|dy| (-1..=1).map(move |dx| (dx, dy))).map(|(dx, dy)| at(x + dx, y + dy)).collect();
            // Skip the silhouette: coverage of pixels cut by it is a rasterisation rule, not shading.
            if neighbours.iter().all(|n| matches!(n, Some(Some(_)))) {
                let want = expected[(y * width as i64 + x) as usize].unwrap();
                let got = image.pixel(x as u32, y as u32);
                let diff = (0..3).map(|k| (got[k] as i32 - want[k] as i32).abs()).max().unwrap();
                assert!(diff <= MAX_CODE_DIFF, "pixel ({x}, {y}): GPU {got:?}, CPU {want:?}");
                max_diff = max_diff.max(diff);
                sum_diff += diff as i64;
                compared += 1;
            } else if neighbours.iter().all(|n| matches!(n, Some(None))) {
                assert!(
                    background(&image, x as u32, y as u32),
                    "pixel ({x}, {y}) should be background, is {:?}",
                    image.pixel(x as u32, y as u32)
                );
                background_checked += 1;
            }
        }
    }
    eprintln!(
        "sphere: {compared} pixels compared, max difference {max_diff} codes, mean {:.3}; {background_checked} background pixels",
        sum_diff as f64 / compared as f64
    );
    assert!(compared > 4000, "only {compared} interior pixels");
    assert!(background_checked > 4000);
    assert!((sum_diff as f64) / (compared as f64) < 0.5, "mean difference too large");
}

/// Plane (41×41 vertices, side 4) with a sphere (radius 0.5, centre height 1)
/// above it, and two time-lapse steps with the sun on opposite sides.
pub fn plane_and_sphere_time_lapse() -> (Bundle, Vec<Vec3>, usize) {
    let order = 2;
    let mut mesh = shapes::plane_grid(40, 4.0);
    let plane_vertices = mesh.vertex_count();
    let (radius, centre) = (0.5f32, Vec3::new(0.0, 1.0, 0.0));
    let mut sphere = shapes::icosphere(3);
    shapes::transform(&mut sphere, radius, centre);
    shapes::append(&mut mesh, &sphere);
    let suns = [Vec3::new(1.0, 1.0, 0.0).normalize(), Vec3::new(-1.0, 1.0, 0.3).normalize()];
    // Exact bits: a plane vertex is sunlit when the ray toward the sun misses the
    // analytic sphere; a sphere vertex when it faces the sun (convex, plane below).
    let hits_sphere = |p: Vec3, d: Vec3| {
        let oc = p - centre;
        let b = oc.dot(d);
        let c = oc.length_squared() - radius * radius;
        b * b - c > 0.0 && -b > 0.0
    };
    let (words_per_vertex, masks) = SunSeries::pack(2, mesh.vertex_count(), |v, k| {
        if v < plane_vertices {
            !hits_sphere(mesh.positions[v], suns[k])
        } else {
            mesh.normals[v].dot(suns[k]) > 0.0
        }
    });
    let steps = suns
        .iter()
        .enumerate()
        .map(|(k, s)| SunStep {
            unix_time_utc: 1_773_993_600.0 + 3600.0 * k as f64,
            direction: s.to_array(),
            elevation_deg: s.y.asin().to_degrees(),
            azimuth_deg: 0.0,
            sun_rgb: [1.5, 1.5, 1.5],
            night: false,
            sky_sh: Vec::new(),
        })
        .collect();
    let sun = SunSeries::per_vertex(0, steps, words_per_vertex, masks);
    let transfer = unoccluded_transfer(&mesh, order);
    (bundle_of(mesh, order, transfer, Some(sun)), suns.to_vec(), plane_vertices)
}

#[test]
fn time_lapse_shadow_moves_where_the_bits_say() {
    let Some(gpu) = gpu_or_skip("time_lapse_shadow_moves_where_the_bits_say") else { return };
    let (bundle, _suns, plane_vertices) = plane_and_sphere_time_lapse();
    let sun = bundle.sun.as_ref().unwrap();
    let scene = prepare_scene(&bundle, &LayerSelection::Total, &[]).unwrap();
    // Constant ambient radiance a: L_00 = a·√(4π) gives E = a on any unoccluded normal.
    let ambient = 0.1f32;
    let lighting = vec![[ambient * (4.0 * std::f32::consts::PI).sqrt(); 3]];
    let (width, height) = (160, 160);
    let camera = Camera::look_at(Vec3::new(0.0, 6.0, 0.5), Vec3::ZERO, scene.bounds);
    let albedo = bundle.mesh.materials[0].albedo;
    let n = 41usize;
    let mut moved = [0usize; 2];
    let mut checked = 0;
    let images: Vec<Image> = (0..2)
        .map(|k| {
            let settings =
                FrameSettings { lighting: lighting.clone(), sun_step: Some(k), backdrop: Backdrop::Black, tonemap: linear_tonemap(0.0) };
            render_image(&gpu, &scene, Some(sun), &camera, &settings, width, height).unwrap()
        })
        .collect();
    for j in 1..n - 1 {
        for i in 1..n - 1 {
            let v = j * n + i;
            let p = bundle.mesh.positions[v];
            // Hidden behind the sphere (with margin)?
            let to_p = (p - camera.eye).normalize();
            let oc = camera.eye - Vec3::new(0.0, 1.0, 0.0);
            let b = oc.dot(to_p);
            if b * b - (oc.length_squared() - 0.6 * 0.6) > 0.0 {
                continue;
            }
            let Some((x, y)) = camera.project(p, width, height) else { continue };
            let (px, py) = (x.floor() as u32, y.floor() as u32);
            let neighbours = [v - n - 1, v - n, v - n + 1, v - 1, v + 1, v + n - 1, v + n, v + n + 1];
            for k in 0..2 {
                // Only where the vertex and its whole fan share the bit: the pixel is then exactly the vertex's value.
                if neighbours.iter().any(|&w| sun.bit(w, k) != sun.bit(v, k)) {
                    continue;
                }
                let light = reference::vertex_light(&scene, &lighting, Some((sun, k)), v, [0.0, 1.0, 0.0], true);
                let want = tonemap::linear(reference::radiance(albedo, light), 0.0, 2.2).map(tonemap::to_u8);
                let got = images[k].pixel(px, py);
                let diff = (0..3).map(|c| (got[c] as i32 - want[c] as i32).abs()).max().unwrap();
                assert!(diff <= MAX_CODE_DIFF, "step {k}, vertex {v} at ({px}, {py}): GPU {got:?}, CPU {want:?} (bit {})", sun.bit(v, k));
                checked += 1;
                let other = 1 - k;
                if !sun.bit(v, k) && sun.bit(v, other) && neighbours.iter().all(|&w| sun.bit(w, other)) {
                    // In shadow at step k and sunlit at the other: the pixel got darker by the sun term.
                    let lit = images[other].pixel(px, py);
                    assert!(lit[1] as i32 - got[1] as i32 > 60, "vertex {v}: shadow at step {k} {got:?} vs lit {lit:?}");
                    moved[k] += 1;
                }
            }
        }
    }
    assert!(plane_vertices == n * n);
    eprintln!("time lapse: {checked} vertex pixels checked; in shadow only at step 0: {}, only at step 1: {}", moved[0], moved[1]);
    assert!(moved[0] >= 20 && moved[1] >= 20, "the shadow did not move: {moved:?}");
    assert!(checked > 1500);
}

/// A single-layer plane whose every bit is set, in a window-mode bundle (bits
/// for points lit from either side), under a sun from above: seen from above
/// it takes the sun (`n·s` of its upward normal), seen from below the side the
/// eye sees faces away from the sun and takes none, the sky term alone,
/// pixel for pixel as the CPU formula gives with the normal turned toward
/// the eye.
#[test]
fn the_sun_lights_only_the_side_of_a_surface_that_faces_it() {
    let Some(gpu) = gpu_or_skip("the_sun_lights_only_the_side_of_a_surface_that_faces_it") else { return };
    let order = 1;
    let mesh = shapes::plane_grid(8, 4.0);
    let sun_dir = Vec3::new(0.3, 1.0, 0.2).normalize();
    let (words_per_vertex, masks) = SunSeries::pack(1, mesh.vertex_count(), |_, _| true);
    let step = SunStep {
        unix_time_utc: 1_773_993_600.0,
        direction: sun_dir.to_array(),
        elevation_deg: sun_dir.y.asin().to_degrees(),
        azimuth_deg: 0.0,
        sun_rgb: [1.5, 1.5, 1.5],
        night: false,
        sky_sh: Vec::new(),
    };
    let sun = SunSeries::per_vertex(0, vec![step], words_per_vertex, masks);
    // A flat transfer, the same on both sides: the sky term is `ambient` whichever side is seen.
    let transfer = vec![1.0 / (4.0 * std::f32::consts::PI).sqrt(); mesh.vertex_count()];
    let mut bundle = bundle_of(mesh, order, transfer, Some(sun));
    bundle.meta = serde_json::json!({ "params": { "mode": "window" } });
    let scene = prepare_scene(&bundle, &LayerSelection::Total, &[]).unwrap();
    let ambient = 0.1f32;
    let lighting = vec![[ambient * (4.0 * std::f32::consts::PI).sqrt(); 3]];
    let settings = FrameSettings { lighting: lighting.clone(), sun_step: Some(0), backdrop: Backdrop::Black, tonemap: linear_tonemap(0.0) };
    let albedo = bundle.mesh.materials[0].albedo;
    let sun = bundle.sun.as_ref().unwrap();
    for (eye, seen_normal) in [(Vec3::new(0.0, 3.0, 0.5), [0.0, 1.0, 0.0]), (Vec3::new(0.0, -3.0, 0.5), [0.0, -1.0, 0.0])] {
        let camera = Camera::look_at(eye, Vec3::ZERO, scene.bounds);
        let image = render_image(&gpu, &scene, Some(sun), &camera, &settings, 64, 64).unwrap();
        let light = reference::vertex_light(&scene, &lighting, Some((sun, 0)), 0, seen_normal, seen_normal[1] > 0.0);
        let want = tonemap::linear(reference::radiance(albedo, light), 0.0, 2.2).map(tonemap::to_u8);
        let got = image.pixel(32, 32);
        let diff = (0..3).map(|c| (got[c] as i32 - want[c] as i32).abs()).max().unwrap();
        assert!(diff <= MAX_CODE_DIFF, "eye {eye}: GPU {got:?}, CPU {want:?}");
        let sky_only = tonemap::linear(reference::radiance(albedo, [ambient; 3]), 0.0, 2.2).map(tonemap::to_u8);
        if eye.y < 0.0 {
            assert_eq!(want, sky_only, "seen from below, the sun must add nothing");
        } else {
            assert!(want[1] as i32 - sky_only[1] as i32 > 60, "seen from above, the sun must light it: {want:?} against {sky_only:?}");
        }
    }
}

/// Window-mode side shares (SIDE, TSID): a plane facing up whose every
/// receiver took 0.8 of its light through its front, drawn per vertex and
/// per texel from above and below, shows 0.8 and 0.2 of its transfer's
/// light, through an encoded and decoded bundle; the CPU formula agrees.
#[test]
fn each_side_of_a_surface_shows_its_share_of_the_light() {
    let Some(gpu) = gpu_or_skip("each_side_of_a_surface_shows_its_share_of_the_light") else { return };
    let mut mesh = shapes::plane_grid(4, 2.0);
    mesh.materials[0].albedo = [0.5; 3];
    let share = prtbake::bundle::quantize_share(0.8);
    assert_eq!(share, 204.0 / 255.0);
    let (vertex_dc, texel_dc) = (3.0f32, 2.0f32);
    let mut vertex_bundle = bundle_of(mesh.clone(), 1, vec![vertex_dc; mesh.vertex_count()], None);
    vertex_bundle.meta = serde_json::json!({ "params": { "mode": "window" } });
    vertex_bundle.transfer.as_mut().unwrap().front_share = vec![share; mesh.vertex_count()];
    // Texel mode: the texels carry the shares, the vertices none.
    let mut texel_bundle = bundle_of(mesh.clone(), 1, vec![vertex_dc; mesh.vertex_count()], None);
    texel_bundle.meta = vertex_bundle.meta.clone();
    let atlas = prtbake::atlas::Atlas::unwrap(&mesh, 0.05).unwrap();
    let texels = prtbake::atlas::coverage::Coverage::of(&atlas).texels;
    texel_bundle.texels = Some(prtbake::bundle::TexelLayers {
        atlas,
        transfer: Some(Transfer {
            order: 1,
            channels: 1,
            quantization: Quantization::F32,
            layers: vec![TransferLayer { kind: LayerKind::Total, data: vec![texel_dc; texels.len()] }],
            front_share: vec![share; texels.len()],
        }),
        texels,
    });
    let lighting = vec![[1.0f32; 3]];
    let settings = FrameSettings { lighting: lighting.clone(), sun_step: None, backdrop: Backdrop::Black, tonemap: linear_tonemap(0.0) };
    for (bundle, dc) in [(vertex_bundle, vertex_dc), (texel_bundle, texel_dc)] {
        let bytes = prtbake::bundle::encode_bundle(&bundle).unwrap();
        let sections: Vec<String> = prtbake::bundle::list_sections(&bytes).unwrap().iter().map(|s| s.tag_name()).collect();
        let decoded = prtbake::bundle::decode_bundle(&bytes).unwrap();
        assert_eq!(decoded, bundle, "shares round-trip ({sections:?})");
        let texel_mode = decoded.texels.is_some();
        assert!(sections.contains(&(if texel_mode { "TSID" } else { "SIDE" }).to_string()), "{sections:?}");
        let scene = prepare_scene(&decoded, &LayerSelection::Total, &[]).unwrap();
        for (eye, side_share) in [(Vec3::new(0.0, 2.5, 0.01), share), (Vec3::new(0.0, -2.5, 0.01), 1.0 - share)] {
            let camera = Camera::look_at(eye, Vec3::ZERO, scene.bounds);
            let image = prtbake::view::render_linear(&gpu, &scene, None, &camera, &settings, 32, 32).unwrap();
            let got = image.pixel(16, 16)[0];
            let want = 0.5 * dc * side_share;
            assert!((got / want - 1.0).abs() < 0.01, "texels {texel_mode}, eye {eye}: {got} against {want}");
            if !texel_mode {
                let normal = if eye.y > 0.0 { [0.0, 1.0, 0.0] } else { [0.0, -1.0, 0.0] };
                let light = reference::vertex_light(&scene, &lighting, None, 0, normal, eye.y > 0.0);
                assert!((light[0] / (dc * side_share) - 1.0).abs() < 1e-6, "CPU formula: {light:?}");
            }
        }
    }
}

#[test]
fn frame_settings_follow_the_step_sky() {
    // The time-lapse state feeds the step's sky SH and the sun step (no GPU needed).
    let (mut bundle, _, _) = plane_and_sphere_time_lapse();
    let sun = bundle.sun.as_mut().unwrap();
    sun.sky_order = 1;
    sun.steps[0].sky_sh = vec![[1.0, 2.0, 3.0]];
    sun.steps[1].sky_sh = vec![[4.0, 5.0, 6.0]];
    let state = prtbake::view::ViewState {
        source: prtbake::view::LightingSource::StepSky { up: Vec3::Y, turbidity: 3.0 },
        car_rotation_deg: [0.0; 3],
        step: Some(1),
        sun_on: true,
        tonemap: ToneMap::default(),
        layers: LayerSelection::Total,
    };
    let settings = state.frame_settings(bundle.sun.as_ref(), 2);
    assert_eq!(settings.lighting, vec![[4.0, 5.0, 6.0], [0.0; 3], [0.0; 3], [0.0; 3]]);
    assert_eq!(settings.sun_step, Some(1));
    // The backdrop is the step's sky with its sun disc, unturned; without the sun term, no disc.
    let step = &bundle.sun.as_ref().unwrap().steps[1];
    let Backdrop::Sky(sky) = settings.backdrop else { panic!("{:?}", settings.backdrop) };
    assert_eq!((sky.sun, sky.sun_irradiance, sky.rotation), (Vec3::from(step.direction), Some(step.sun_rgb), glam::Mat3::IDENTITY));
    let dark = prtbake::view::ViewState { sun_on: false, ..state }.frame_settings(bundle.sun.as_ref(), 2);
    assert!(matches!(dark.backdrop, Backdrop::Sky(s) if s.sun_irradiance.is_none()));
}

#[test]
fn view_command_writes_a_screenshot_and_refuses_bad_input() {
    use crate::util::{prtbake, Scratch};
    let scratch = Scratch::new("view-cli");
    let (with_sun, _, _) = plane_and_sphere_time_lapse();
    let mut without_sun = with_sun.clone();
    without_sun.sun = None;
    let (sun_path, plain_path) = (scratch.path("sun.prtb"), scratch.path("plain.prtb"));
    ::prtbake::bundle::write_bundle(&sun_path, &with_sun).unwrap();
    ::prtbake::bundle::write_bundle(&plain_path, &without_sun).unwrap();
    let s = |p: &std::path::Path| p.to_str().unwrap().to_string();

    // Bad input is refused before any GPU work: exit 2 and a message naming the problem.
    let no_lapse = prtbake(&["view", &s(&plain_path), "--time", "09:00", "--screenshot", &s(&scratch.path("x.png"))]);
    assert_eq!(no_lapse.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&no_lapse.stderr).contains("no time lapse"));
    let bad_step = prtbake(&["view", &s(&sun_path), "--step", "7", "--screenshot", &s(&scratch.path("x.png"))]);
    assert_eq!(bad_step.status.code(), Some(2));
    let bad_size = prtbake(&["view", &s(&sun_path), "--size", "0x10", "--screenshot", &s(&scratch.path("x.png"))]);
    assert_eq!(bad_size.status.code(), Some(2));
    let bad_layers = prtbake(&["view", &s(&sun_path), "--layers", "direct", "--screenshot", &s(&scratch.path("x.png"))]);
    assert!(String::from_utf8_lossy(&bad_layers.stderr).contains("--store-bounces"));
    let no_panel = prtbake(&["view", &s(&sun_path), "--panel", "lcd*", "--screenshot", &s(&scratch.path("x.png"))]);
    let message = String::from_utf8_lossy(&no_panel.stderr);
    assert_eq!(no_panel.status.code(), Some(2), "{message}");
    assert!(message.contains("sun.prtb") && message.contains("lcd*"), "{message}");
    let bad_texels = prtbake(&["view", &s(&sun_path), "--panel-texels", "0x8", "--screenshot", &s(&scratch.path("x.png"))]);
    assert_eq!(bad_texels.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad_texels.stderr).contains("--panel-texels"));
    assert!(!scratch.path("x.png").exists());

    if gpu_or_skip("view_command_writes_a_screenshot").is_none() {
        return;
    }
    let png_path = scratch.path("shot.png");
    let run = prtbake(&["view", &s(&sun_path), "--step", "1", "--screenshot", &s(&png_path), "--size", "96x64", "--json"]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let report: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    assert_eq!(report["step"], 1);
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png_path).unwrap()));
    let info = decoder.read_info().unwrap().info().clone();
    assert_eq!((info.width, info.height), (96, 64));
}

/// The LCD panel scene: a 1 × 0.5 m panel (role panel, albedo 0.05, no UVs:
/// planar texels) facing +Z at z = 0, a bright wall (albedo 0.9) behind the
/// camera that the panel reflects, under a synthetic SH sky; open-mode transfer
/// of unoccluded surfaces. Returns the bundle and its panel mapping (16 × 8 texels).
fn panel_scene() -> (Bundle, prtbake::view::panel::PanelMapping) {
    use prtbake::fixtures::builder::MeshBuilder;
    use prtbake::mesh::{Material, MaterialRole};
    let material = |name: &str, albedo: f32, role| Material { name: name.into(), albedo: [albedo; 3], role, transmittance: 1.0 };
    let mut b = MeshBuilder::new(vec![material("lcd", 0.05, MaterialRole::Panel), material("wall", 0.9, MaterialRole::Opaque)]);
    let (lcd, wall) = (b.material("lcd"), b.material("wall"));
    b.grid("screen", Vec3::new(-0.5, -0.25, 0.0), Vec3::X, Vec3::Y * 0.5, 8, 4, |_, _| lcd);
    b.grid("wall", Vec3::new(3.0, -2.0, 3.5), -Vec3::X * 6.0, Vec3::Y * 4.0, 6, 4, |_, _| wall);
    let mesh = b.mesh;
    mesh.validate().unwrap();
    let order = 3;
    let transfer = unoccluded_transfer(&mesh, order);
    let bundle = bundle_of(mesh, order, transfer, None);
    let mapping = prtbake::view::panel::PanelMapping::find(&bundle.mesh, None, Some((16, 8)), "panel.prtb".as_ref()).unwrap().unwrap();
    (bundle, mapping)
}

/// A sky brightest toward +Z (where the panel faces) and some colour.
fn panel_lighting() -> Vec<[f32; 3]> {
    vec![
        [2.0, 1.9, 1.7],
        [0.3, 0.3, 0.3],
        [0.2, 0.25, 0.3],
        [0.0, 0.05, 0.1],
        [0.0; 3],
        [0.05, 0.0, 0.0],
        [-0.1, -0.1, -0.1],
        [0.0; 3],
        [0.0; 3],
    ]
}

/// The panel's texture after `passes` gather passes from `eye`.
fn panel_texture(
    bundle: &Bundle,
    mapping: &prtbake::view::panel::PanelMapping,
    settings: &FrameSettings,
    eye: Vec3,
    passes: u32,
) -> prtbake::view::panel::PanelTexture {
    let mut source = prtbake::view::panel::PanelSource::new(bundle, mapping, None).unwrap();
    let request = prtbake::view::panel::PanelRequest::new(eye, settings, &LayerSelection::Total, 0);
    source.texture(&request, passes)
}

/// Renders the panel scene with the texture of `passes` passes (`None`: no texture).
fn render_panel(
    gpu: &Gpu,
    bundle: &Bundle,
    mapping: &prtbake::view::panel::PanelMapping,
    camera: &Camera,
    settings: &FrameSettings,
    passes: Option<u32>,
) -> Image {
    let mut scene = prtbake::view::scene::prepare_scene_with_panel(bundle, &LayerSelection::Total, &[], Some(mapping)).unwrap();
    scene.panel.as_mut().unwrap().texture = passes.map(|p| panel_texture(bundle, mapping, settings, camera.eye, p));
    render_image(gpu, &scene, None, camera, settings, PANEL_SIZE.0, PANEL_SIZE.1).unwrap()
}

const PANEL_SIZE: (u32, u32) = (160, 120);

/// The panel scene, a camera in front of the panel and the frame settings
/// (the panel sky, black backdrop, linear curve at −1 stop).
fn panel_fixture() -> (Bundle, prtbake::view::panel::PanelMapping, Camera, FrameSettings) {
    let (bundle, mapping) = panel_scene();
    let bounds = prepare_scene(&bundle, &LayerSelection::Total, &[]).unwrap().bounds;
    let camera = Camera::look_at(Vec3::new(0.25, 0.15, 1.6), Vec3::ZERO, bounds);
    let settings = FrameSettings { lighting: panel_lighting(), sun_step: None, backdrop: Backdrop::Black, tonemap: linear_tonemap(-1.0) };
    (bundle, mapping, camera, settings)
}

/// Per pixel: the panel hit's texture coordinate and PRT light (`None` off the panel).
fn panel_pixels(
    bundle: &Bundle,
    mapping: &prtbake::view::panel::PanelMapping,
    camera: &Camera,
    lighting: &[[f32; 3]],
) -> Vec<Option<(glam::Vec2, [f32; 3])>> {
    let mesh = &bundle.mesh;
    let scene = prepare_scene(bundle, &LayerSelection::Total, &[]).unwrap();
    let (width, height) = PANEL_SIZE;
    (0..width * height)
        .map(|i| {
            let (origin, dir) = camera.pixel_ray((i % width) as f32 + 0.5, (i / width) as f32 + 0.5, width, height);
            let (t, u, v) = nearest_hit(mesh, origin, dir)?;
            mapping.triangles.binary_search(&(t as u32)).ok()?;
            let w = [1.0 - u - v, u, v];
            let corners = mesh.triangle(t);
            let texcoord = corners.iter().zip(w).map(|(&c, w)| glam::Vec2::from(mapping.texcoord(mesh, c)) * w).sum();
            let light = corners.iter().zip(w).fold([0.0f32; 3], |acc, (&c, w)| {
                let e = reference::vertex_light(&scene, lighting, None, c as usize, mesh.normals[c as usize].to_array(), true);
                std::array::from_fn(|k| acc[k] + e[k] * w)
            });
            Some((texcoord, light))
        })
        .collect()
}

/// Pixels whose 3 × 3 neighbourhood is all panel (no silhouette) and whose
/// texel is unambiguous (the coordinate ≥ 0.02 texel from a texel edge).
fn inner_panel_pixels(pixels: &[Option<(glam::Vec2, [f32; 3])>], texels: (u32, u32)) -> Vec<usize> {
    let (w, h) = (PANEL_SIZE.0 as i64, PANEL_SIZE.1 as i64);
    let edge = |x: f32| (x - x.round()).abs() < 0.02;
    (0..pixels.len())
        .filter(|&i| {
            let (x, y) = (i as i64 % w, i as i64 / w);
            let inside = (-1..=1).all(|dy| {
                (-1..=1).all(|dx| {
                    (0..w).contains(&(x + dx)) && (0..h).contains(&(y + dy)) && pixels[((y + dy) * w + x + dx) as usize].is_some()
                })
            });
            inside && pixels[i].is_some_and(|(c, _)| !edge(c.x * texels.0 as f32) && !edge(c.y * texels.1 as f32))
        })
        .collect()
}

/// The panel shows what the gather reflects, and nothing else: its BRDF's
/// diffuse haze is already in the gathered radiance, so adding the PRT
/// shading albedo · E again would draw it twice.
#[test]
fn panel_texels_show_the_gathered_texture() {
    let Some(gpu) = gpu_or_skip("panel_texels_show_the_gathered_texture") else { return };
    let (bundle, mapping, camera, settings) = panel_fixture();
    let texture = panel_texture(&bundle, &mapping, &settings, camera.eye, 4);
    let image = render_panel(&gpu, &bundle, &mapping, &camera, &settings, Some(4));
    let pixels = panel_pixels(&bundle, &mapping, &camera, &settings.lighting);
    let albedo = bundle.mesh.materials[0].albedo;
    let (mut max_diff, mut prt_share) = (0, 0.0f64);
    let inner = inner_panel_pixels(&pixels, (16, 8));
    for &i in &inner {
        let (texcoord, light) = pixels[i].unwrap();
        let prt = reference::radiance(albedo, light);
        let reflected = texture.at(texcoord);
        let want = tonemap::linear(reflected, -1.0, 2.2).map(tonemap::to_u8);
        let got = image.pixel(i as u32 % PANEL_SIZE.0, i as u32 / PANEL_SIZE.0);
        let diff = (0..3).map(|k| (got[k] as i32 - want[k] as i32).abs()).max().unwrap();
        assert!(diff <= MAX_CODE_DIFF, "pixel {i}: GPU {got:?}, CPU {want:?} (texel {reflected:?})");
        max_diff = max_diff.max(diff);
        prt_share += f64::from(prt[1] / reflected[1].max(1e-6)) / inner.len() as f64;
    }
    eprintln!("panel: {} pixels compared, max difference {max_diff} codes; albedo·E would add {:.0}%", inner.len(), 100.0 * prt_share);
    assert!(inner.len() > 2000, "only {} panel pixels", inner.len());
    // The double count the shader no longer makes would have been visible.
    assert!(prt_share > 0.05, "{prt_share}");
}

/// `view --screenshot OUT.exr` (linear, before tone mapping) shows on the
/// panel the radiance `prtbake panel` writes for the same bundle, light and
/// eye: the viewer's panel pixels against the panel command's EXR, texel by
/// texel, within the gather's noise.
#[test]
fn viewer_panel_pixels_equal_the_panel_command_exr() {
    if gpu_or_skip("viewer_panel_pixels_equal_the_panel_command_exr").is_none() {
        return;
    }
    let dir = crate::util::Scratch::new("view-panel-exr");
    let s = |p: &std::path::Path| p.to_str().unwrap().to_string();
    let (bundle, mapping) = panel_scene();
    let bundle_path = dir.path("panel.prtb");
    prtbake::bundle::write_bundle(&bundle_path, &bundle).unwrap();
    // An environment brightest toward +Z and the zenith, with some colour.
    let env = dir.path("env.exr");
    {
        use exr::prelude::*;
        let (w, h) = (64usize, 32usize);
        let pixel = |x: usize, y: usize| {
            let d = prtbake::sh::equirect_direction((x as f64 + 0.5) / w as f64, (y as f64 + 0.5) / h as f64);
            let l = (0.5 + 1.5 * d.z.max(0.0) + d.y.max(0.0)) as f32;
            (l, 0.9 * l, 0.8 * l)
        };
        write_rgb_file(&env, w, h, |x, y| pixel(x, y)).unwrap();
    }
    let (eye, samples) = ("0.25,0.15,1.6", 128u32);
    let panel_exr = dir.path("panel.exr");
    let o = crate::util::prtbake(&[
        "panel",
        &s(&bundle_path),
        "--env",
        &s(&env),
        "--eye",
        eye,
        "--texels",
        "16x8",
        "--samples",
        &samples.to_string(),
        "-o",
        &s(&panel_exr),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let noise = report["readability"]["max_relative_error"].as_f64().unwrap();
    let view_exr = dir.path("view.exr");
    let passes = prtbake::view::panel::passes_for(samples).to_string();
    let size = format!("{}x{}", PANEL_SIZE.0, PANEL_SIZE.1);
    let o = crate::util::prtbake(&[
        "view",
        &s(&bundle_path),
        "--env",
        &s(&env),
        "--camera",
        &format!("{eye},0,0,0"),
        "--fov",
        "45",
        "--panel-texels",
        "16x8",
        "--panel-passes",
        &passes,
        "--size",
        &size,
        "--screenshot",
        &s(&view_exr),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let panel_image = prtbake::sh::load_equirect(&panel_exr).unwrap();
    let view_image = prtbake::sh::load_equirect(&view_exr).unwrap();
    assert_eq!((view_image.width, view_image.height), PANEL_SIZE);
    let bounds = prepare_scene(&bundle, &LayerSelection::Total, &[]).unwrap().bounds;
    let mut camera = Camera::look_at(Vec3::new(0.25, 0.15, 1.6), Vec3::ZERO, bounds);
    camera.fov_y_deg = 45.0;
    let pixels = panel_pixels(&bundle, &mapping, &camera, &panel_lighting());
    let inner = inner_panel_pixels(&pixels, (16, 8));
    assert!(inner.len() > 2000, "only {} panel pixels", inner.len());
    let (mut worst, mut sum_view, mut sum_panel) = (0.0f64, 0.0f64, 0.0f64);
    for &i in &inner {
        let (texcoord, _) = pixels[i].unwrap();
        let (tx, ty) = ((texcoord.x * 16.0) as usize, (texcoord.y * 8.0) as usize);
        let want = panel_image.rgb[ty.min(7) * 16 + tx.min(15)];
        let got = view_image.rgb[i];
        for k in 0..3 {
            let relative = f64::from((got[k] - want[k]).abs() / want[k].max(1e-6));
            worst = worst.max(relative);
        }
        sum_view += f64::from(got[1]);
        sum_panel += f64::from(want[1]);
    }
    let ratio = sum_view / sum_panel;
    eprintln!("viewer panel / panel EXR: mean ratio {ratio:.4}, worst texel {worst:.4} (gather noise up to {noise:.4}, half floats 2^-11)");
    // The two run the same gather: what is left is the viewer's half-float target.
    assert!((ratio - 1.0).abs() < 0.01, "{ratio}");
    assert!(worst < 3.0 * noise + 2e-3, "worst texel {worst} against the gather's noise {noise}");
}

#[test]
fn panel_noise_falls_with_more_passes() {
    let Some(gpu) = gpu_or_skip("panel_noise_falls_with_more_passes") else { return };
    let (bundle, mapping, camera, settings) = panel_fixture();
    let pixels = panel_pixels(&bundle, &mapping, &camera, &settings.lighting);
    let inner = inner_panel_pixels(&pixels, (16, 8));
    // Reference: 1024 samples per texel (pass 36).
    let reference_passes = (1..100).find(|&p| prtbake::view::panel::samples_after(p) >= 1024).unwrap();
    let reference = render_panel(&gpu, &bundle, &mapping, &camera, &settings, Some(reference_passes));
    let rms: Vec<f64> = [1u32, 3, 5]
        .iter()
        .map(|&passes| {
            let image = render_panel(&gpu, &bundle, &mapping, &camera, &settings, Some(passes));
            let sum: f64 = inner
                .iter()
                .map(|&i| {
                    let (a, b) = (
                        image.pixel(i as u32 % PANEL_SIZE.0, i as u32 / PANEL_SIZE.0),
                        reference.pixel(i as u32 % PANEL_SIZE.0, i as u32 / PANEL_SIZE.0),
                    );
                    (0..3).map(|k| f64::from(a[k] as i32 - b[k] as i32).powi(2)).sum::<f64>() / 3.0
                })
                .sum();
            (sum / inner.len() as f64).sqrt()
        })
        .collect();
    eprintln!("panel noise vs 1024 spp: RMS {:.2} / {:.2} / {:.2} codes at 2 / 8 / 32 samples per texel", rms[0], rms[1], rms[2]);
    assert!(rms[0] > 1.0, "the rough pass should be visibly noisy: {rms:?}");
    assert!(rms[1] < rms[0] && rms[2] < rms[1], "{rms:?}");
    assert!(rms[2] < 0.5 * rms[0], "{rms:?}");
}

#[test]
fn panel_texture_leaves_every_other_pixel_unchanged() {
    let Some(gpu) = gpu_or_skip("panel_texture_leaves_every_other_pixel_unchanged") else { return };
    // Linear tone mapping (the fixture's): the adaptive operators' exposure follows the whole frame, panel included.
    let (bundle, mapping, camera, settings) = panel_fixture();
    let plain_scene = prepare_scene(&bundle, &LayerSelection::Total, &[]).unwrap();
    let plain = render_image(&gpu, &plain_scene, None, &camera, &settings, PANEL_SIZE.0, PANEL_SIZE.1).unwrap();
    let untextured = render_panel(&gpu, &bundle, &mapping, &camera, &settings, None);
    let textured = render_panel(&gpu, &bundle, &mapping, &camera, &settings, Some(3));
    assert!(plain.rgba == untextured.rgba, "the panel without its texture is drawn as before");
    let pixels = panel_pixels(&bundle, &mapping, &camera, &settings.lighting);
    let (w, h) = (PANEL_SIZE.0 as i64, PANEL_SIZE.1 as i64);
    let near_panel = |x: i64, y: i64| {
        (-1..=1).any(|dy| {
            (-1..=1)
                .any(|dx| (0..w).contains(&(x + dx)) && (0..h).contains(&(y + dy)) && pixels[((y + dy) * w + x + dx) as usize].is_some())
        })
    };
    let (mut changed, mut other) = (0, 0);
    for y in 0..h {
        for x in 0..w {
            let (a, b) = (plain.pixel(x as u32, y as u32), textured.pixel(x as u32, y as u32));
            if near_panel(x, y) {
                changed += (a != b) as usize;
            } else {
                assert_eq!(a, b, "pixel ({x}, {y}) away from the panel changed");
                other += 1;
            }
        }
    }
    eprintln!("panel texture: {changed} panel pixels changed, {other} others identical");
    assert!(changed > 2000 && other > 5000, "{changed} {other}");
}

/// The window's worker (no GPU needed): it refines to 256 samples per texel and
/// hands back the very texture a screenshot computes after as many passes; a
/// new eye restarts it, and its textures carry the new request's generation.
#[test]
fn panel_worker_refines_to_the_screenshot_texture_and_restarts_on_a_new_eye() {
    use prtbake::view::panel::{passes_for, PanelRequest, PanelSource, INTERACTIVE_SAMPLES};
    use prtbake::view::panel_worker::PanelWorker;
    let (bundle, mapping, camera, settings) = panel_fixture();
    let worker = PanelWorker::start(PanelSource::new(&bundle, &mapping, None).unwrap(), 2).unwrap();
    let wait_for = |generation: u64| {
        let started = std::time::Instant::now();
        let mut seen = Vec::new();
        loop {
            if let Some(texture) = worker.latest(generation) {
                seen.push(texture.samples);
                if texture.samples == INTERACTIVE_SAMPLES {
                    return (texture, seen);
                }
            }
            assert!(started.elapsed().as_secs() < 120, "the worker stalled at {seen:?}");
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
    };
    let eyes = [camera.eye, camera.eye + Vec3::new(-0.4, 0.1, 0.0)];
    for (k, eye) in eyes.into_iter().enumerate() {
        let request = PanelRequest::new(eye, &settings, &LayerSelection::Total, k as u64 + 1);
        worker.request(request.clone());
        let (texture, seen) = wait_for(k as u64 + 1);
        assert!(seen.windows(2).all(|w| w[0] < w[1]), "samples must only grow within a request: {seen:?}");
        assert_eq!(texture.generation, k as u64 + 1);
        let mut headless = PanelSource::new(&bundle, &mapping, None).unwrap().texture(&request, passes_for(INTERACTIVE_SAMPLES));
        headless.generation = texture.generation;
        assert!(texture == headless, "eye {k}: the window's texture differs from the screenshot's");
        eprintln!("worker, eye {k}: textures seen at {seen:?} samples per texel");
    }
}

/// A bundle of sun masks alone is shown (albedo × the sun term) instead of
/// refused; steps from a list of directions have no time of day, so the
/// report gives none and `--time` is refused in favour of `--step`.
#[test]
fn sun_only_and_direction_bundles_are_viewed() {
    if gpu_or_skip("sun_only_and_direction_bundles_are_viewed").is_none() {
        return;
    }
    let dir = crate::util::Scratch::new("view-sun-only");
    let obj = dir.path("scene.obj");
    crate::util::write_scene_obj(&obj);
    let csv = dir.path("suns.csv");
    std::fs::write(&csv, "0.3,1,0.2\n-0.5,0.8,0.4\n").unwrap();
    let sun = dir.path("sun.prtb");
    let s = |p: &std::path::Path| p.to_str().unwrap().to_string();
    let o = crate::util::prtbake(&["sun", &s(&obj), "-o", &s(&sun), "--directions", &s(&csv), "--quiet"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let shot = dir.path("sun.png");
    let o = crate::util::prtbake(&["view", &s(&sun), "--step", "0", "--screenshot", &s(&shot), "--size", "96x64", "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(report["step_local_time"].is_null(), "{report}");
    let image = Image::decode_png(&std::fs::read(&shot).unwrap()).unwrap();
    let lit = (0..image.height)
        .flat_map(|y| (0..image.width).map(move |x| (x, y)))
        .filter(|&(x, y)| image.pixel(x, y)[..3].iter().any(|&c| c > 8));
    assert!(lit.count() > 100, "the sunlit ground shows");
    let o = crate::util::prtbake(&["view", &s(&sun), "--time", "09:00", "--screenshot", &s(&shot), "--size", "96x64"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--step"), "{}", String::from_utf8_lossy(&o.stderr));
}

/// The photographic default keeps the sun patch of a dim scene from
/// clipping (the highlight guard): a floor in skylight with a small patch
/// of sun some 240 times brighter. Without the guard every pixel of the
/// patch was white (code 255, measured); with it none is (253), and the
/// patch stays far brighter than the shade (75).
#[test]
fn photographic_default_keeps_sun_patches_of_a_dim_scene() {
    let Some(gpu) = gpu_or_skip("photographic_default_keeps_sun_patches_of_a_dim_scene") else { return };
    let (mut bundle, _suns, plane_vertices) = plane_and_sphere_time_lapse();
    // A dim room in daylight, in absolute units: 30 of skylight, a sun of
    // 10,000 through a small opening: a 0.8 m square patch of the 4 m floor.
    let series = bundle.sun.as_mut().unwrap();
    series.steps.iter_mut().for_each(|s| s.sun_rgb = [1.0e4; 3]);
    let positions = bundle.mesh.positions.clone();
    let (words, masks) =
        SunSeries::pack(2, positions.len(), |v, _| v < plane_vertices && positions[v].x.abs() < 0.4 && (positions[v].z - 1.2).abs() < 0.4);
    (series.words_per_vertex, series.masks) = (words, masks);
    let sun = bundle.sun.as_ref().unwrap();
    let scene = prepare_scene(&bundle, &LayerSelection::Total, &[]).unwrap();
    let ambient = 30.0f32;
    let lighting = vec![[ambient * (4.0 * std::f32::consts::PI).sqrt(); 3]];
    let (width, height) = (160, 160);
    let camera = Camera::look_at(Vec3::new(0.0, 6.0, 0.5), Vec3::ZERO, scene.bounds);
    let tonemap = ToneMap { operator: ToneOperator::Photographic, ..ToneMap::default() };
    let settings = FrameSettings { lighting, sun_step: Some(0), backdrop: Backdrop::Black, tonemap };
    let image = render_image(&gpu, &scene, Some(sun), &camera, &settings, width, height).unwrap();
    let n = 41usize;
    let (mut lit, mut shade) = (Vec::new(), Vec::new());
    for v in (0..plane_vertices).filter(|v| (v % n).abs_diff(n / 2) < 18 && (v / n).abs_diff(n / 2) < 18) {
        let Some((x, y)) = camera.project(bundle.mesh.positions[v], width, height) else { continue };
        let code = image.pixel(x.floor() as u32, y.floor() as u32)[1];
        if sun.bit(v, 0) {
            lit.push(code)
        } else {
            shade.push(code)
        }
    }
    lit.sort_unstable();
    shade.sort_unstable();
    let clipped = lit.iter().filter(|&&c| c == 255).count() as f64 / lit.len() as f64;
    let (lit_median, shade_median) = (lit[lit.len() / 2], shade[shade.len() / 2]);
    eprintln!("sunlit {} pixels: {:.0}% clipped, median code {lit_median}; shade median {shade_median}", lit.len(), 100.0 * clipped);
    assert!(lit.len() > 40 && shade.len() > 200, "{} lit, {} in shade", lit.len(), shade.len());
    assert!(clipped < 0.1, "{:.0}% of the sunlit pixels clip", 100.0 * clipped);
    assert!(f64::from(lit_median) > 1.5 * f64::from(shade_median).max(1.0), "sun {lit_median} against shade {shade_median}");
}

/// The affine map from atlas to world of a one-chart flat mesh, from its first triangle.
fn atlas_to_world(atlas: &prtbake::atlas::Atlas, mesh: &Mesh) -> impl Fn(glam::DVec2) -> glam::DVec3 {
    let uv = atlas.triangle_uv(0).map(|p| p.as_dvec2());
    let world = mesh.triangle_positions(0).map(|p| p.as_dvec3());
    let det = (uv[1] - uv[0]).perp_dot(uv[2] - uv[0]);
    move |p: glam::DVec2| {
        let l1 = (p - uv[0]).perp_dot(uv[2] - uv[0]) / det;
        let l2 = (uv[1] - uv[0]).perp_dot(p - uv[0]) / det;
        world[0] + (world[1] - world[0]) * l1 + (world[2] - world[0]) * l2
    }
}

/// Texel mode: a plane whose texels hold a known linear function of their
/// centre's position is drawn with that function at every pixel (a
/// bilinear read of a linear function is exact), where the vertices hold
/// something else entirely: the opaque draws shade from the texels.
#[test]
fn texel_bundles_are_shaded_per_pixel_from_their_texels() {
    let Some(gpu) = gpu_or_skip("texel_bundles_are_shaded_per_pixel_from_their_texels") else { return };
    let mut mesh = shapes::plane_grid(4, 2.0);
    mesh.materials[0].albedo = [0.5, 0.5, 0.5];
    let atlas = prtbake::atlas::Atlas::unwrap(&mesh, 0.05).unwrap();
    assert_eq!(atlas.chart_count, 1, "a flat plane is one chart");
    let texels = prtbake::atlas::coverage::Coverage::of(&atlas).texels;
    let to_world = atlas_to_world(&atlas, &mesh);
    let f = |p: glam::DVec3| 1.0 + 0.3 * p.x + 0.2 * p.z;
    let values: Vec<f32> = texels
        .iter()
        .map(|&t| f(to_world(glam::DVec2::new((t % atlas.width) as f64 + 0.5, (t / atlas.width) as f64 + 0.5))) as f32)
        .collect();
    // The vertices hold a constant 3: a vertex-shaded frame would be flat.
    let mut bundle = bundle_of(mesh.clone(), 1, vec![3.0; mesh.vertex_count()], None);
    bundle.texels = Some(prtbake::bundle::TexelLayers {
        atlas,
        texels,
        transfer: Some(Transfer {
            order: 1,
            channels: 1,
            quantization: Quantization::F32,
            layers: vec![TransferLayer { kind: LayerKind::Total, data: values }],
            front_share: Vec::new(),
        }),
    });
    let scene = prepare_scene(&bundle, &LayerSelection::Total, &[]).unwrap();
    let settings = FrameSettings { lighting: vec![[1.0; 3]], sun_step: None, backdrop: Backdrop::Black, tonemap: linear_tonemap(0.0) };
    let (width, height) = (96, 96);
    let camera = Camera::look_at(Vec3::new(0.0, 2.5, 0.01), Vec3::ZERO, scene.bounds);
    let image = prtbake::view::render_linear(&gpu, &scene, None, &camera, &settings, width, height).unwrap();
    let (mut compared, mut worst) = (0, 0.0f64);
    for y in 0..height {
        for x in 0..width {
            let (origin, dir) = camera.pixel_ray(x as f32 + 0.5, y as f32 + 0.5, width, height);
            let t = -origin.y / dir.y;
            let p = (origin + dir * t).as_dvec3();
            // Inside the plane by more than two texels: every bilinear neighbour is covered.
            if p.x.abs() > 0.9 || p.z.abs() > 0.9 {
                continue;
            }
            let expected = 0.5 * f(p);
            let got = image.pixel(x, y)[0] as f64;
            worst = worst.max((got / expected - 1.0).abs());
            compared += 1;
        }
    }
    assert!(compared > 2000, "{compared} pixels");
    // Binary16 target (2⁻¹¹) and the pixel centre's position against the rasteriser's.
    assert!(worst < 0.01, "largest relative difference {worst}");
}

/// Sun bits per texel are drawn per pixel: a sun-only texel bundle (no
/// transfer) whose texels are lit left of x = 0.13, a line no vertex or
/// triangle edge follows, while every vertex's bit says lit. Under an
/// overhead sun of irradiance π, a pixel two texels left of the line shows
/// the albedo (cos = 1), two texels right of it black, and the line itself
/// lies within one texel of where the bits put it; with each texel's lit
/// share stored (TSUF), within a quarter of a texel. With the bits on an
/// atlas of their own (TSAT) of quarter-size texels beside the texel
/// transfer's, the line lies within one of their texels: the sun's atlas,
/// not the transfer's, draws it.
#[test]
fn texel_sun_bits_draw_their_shadow_edge_per_pixel() {
    let Some(gpu) = gpu_or_skip("texel_sun_bits_draw_their_shadow_edge_per_pixel") else { return };
    let mut mesh = shapes::plane_grid(4, 2.0);
    mesh.materials[0].albedo = [0.5, 0.5, 0.5];
    let texel = 0.05f32;
    let edge = 0.13f64;
    // An atlas of texel size `size`, its covered texels, their bits (lit
    // where the centre is left of the line) and their lit shares in 4 bits.
    let sun_texels = |size: f32| {
        let atlas = prtbake::atlas::Atlas::unwrap(&mesh, size).unwrap();
        let texels = prtbake::atlas::coverage::Coverage::of(&atlas).texels;
        let to_world = atlas_to_world(&atlas, &mesh);
        // A texel's share left of the line, on an 8 × 8 grid of its square.
        let share = |t: u32| {
            let (x, y) = ((t % atlas.width) as f64, (t / atlas.width) as f64);
            let lit = (0..64)
                .filter(|g| {
                    to_world(glam::DVec2::new(x + (g % 8) as f64 / 8.0 + 1.0 / 16.0, y + (g / 8) as f64 / 8.0 + 1.0 / 16.0)).x < edge
                })
                .count();
            lit as f64 / 64.0
        };
        let centre = |t: u32| to_world(glam::DVec2::new((t % atlas.width) as f64 + 0.5, (t / atlas.width) as f64 + 0.5));
        let (_, bits) = SunSeries::pack(1, texels.len(), |i, _| centre(texels[i]).x < edge);
        let fractions: Vec<u32> = texels.iter().map(|&t| (share(t) * 15.0).round() as u32).collect();
        (atlas, texels, bits, fractions)
    };
    let (atlas, texels, texel_masks, fractions) = sun_texels(texel);
    let fine = texel / 4.0;
    let (fine_atlas, fine_texels, fine_masks, _) = sun_texels(fine);
    let (words, masks) = SunSeries::pack(1, mesh.vertex_count(), |_, _| true);
    let step = SunStep {
        unix_time_utc: 1_773_993_600.0,
        direction: [0.0, 1.0, 0.0],
        elevation_deg: 90.0,
        azimuth_deg: 0.0,
        sun_rgb: [std::f32::consts::PI; 3],
        night: false,
        sky_sh: Vec::new(),
    };
    // (fractions, own atlas, tolerance in texels of `texel`)
    for (with_fractions, own_atlas, tolerance) in [(false, false, 1.0), (true, false, 0.25), (false, true, 0.25)] {
        let texel_fractions = if with_fractions { fractions.clone() } else { Vec::new() };
        let sun = SunSeries {
            sky_order: 0,
            steps: vec![step.clone()],
            words_per_vertex: words,
            masks: masks.clone(),
            texel_masks: if own_atlas { fine_masks.clone() } else { texel_masks.clone() },
            texel_fractions,
            texel_atlas: own_atlas.then(|| prtbake::bundle::TexelAtlas { atlas: fine_atlas.clone(), texels: fine_texels.clone() }),
        };
        let mut bundle = bundle_of(mesh.clone(), 1, vec![0.0; mesh.vertex_count()], Some(sun));
        bundle.transfer = None;
        // Its own atlas sits beside texel transfer (here dark: the sky is black).
        let texel_transfer = own_atlas.then(|| Transfer::zero(texels.len()));
        bundle.texels = Some(prtbake::bundle::TexelLayers { atlas: atlas.clone(), texels: texels.clone(), transfer: texel_transfer });
        let bundle = prtbake::bundle::decode_bundle(&prtbake::bundle::encode_bundle(&bundle).unwrap()).unwrap();
        let mut shown = bundle.clone();
        shown.transfer = Some(Transfer::zero(mesh.vertex_count()));
        let scene = prepare_scene(&shown, &LayerSelection::Total, &[]).unwrap();
        let settings =
            FrameSettings { lighting: vec![[0.0; 3]], sun_step: Some(0), backdrop: Backdrop::Black, tonemap: linear_tonemap(0.0) };
        let (width, height) = (160, 160);
        let camera = Camera::look_at(Vec3::new(0.0, 2.5, 0.01), Vec3::ZERO, scene.bounds);
        let image = prtbake::view::render_linear(&gpu, &scene, bundle.sun.as_ref(), &camera, &settings, width, height).unwrap();
        let (mut lit, mut dark, mut worst) = (0, 0, 0.0f64);
        // Per image row, where the value crosses half the albedo.
        let mut crossings = Vec::new();
        for y in 0..height {
            let mut previous: Option<(f64, f64)> = None;
            for x in 0..width {
                let (origin, dir) = camera.pixel_ray(x as f32 + 0.5, y as f32 + 0.5, width, height);
                let p = (origin + dir * (-origin.y / dir.y)).as_dvec3();
                if p.x.abs() > 0.9 || p.z.abs() > 0.9 {
                    previous = None;
                    continue;
                }
                let got = image.pixel(x, y)[0] as f64;
                if p.x < edge - 2.0 * texel as f64 {
                    worst = worst.max((got - 0.5).abs());
                    lit += 1;
                } else if p.x > edge + 2.0 * texel as f64 {
                    worst = worst.max(got.abs());
                    dark += 1;
                }
                if let Some((px, pv)) = previous {
                    if (pv - 0.25) * (got - 0.25) < 0.0 {
                        crossings.push(px + (p.x - px) * (0.25 - pv) / (got - pv));
                    }
                }
                previous = Some((p.x, got));
            }
        }
        assert!(lit > 1000 && dark > 1000, "{lit} lit and {dark} dark pixels");
        assert!(worst < 0.01, "largest difference from the sun term {worst}");
        assert!(!crossings.is_empty());
        let off = crossings.iter().map(|x| (x - edge).abs()).fold(0.0, f64::max) / texel as f64;
        eprintln!("fractions {with_fractions}, own atlas {own_atlas}: the edge drawn at most {off:.3} texels from the line");
        assert!(
            off < tolerance,
            "fractions {with_fractions}, own atlas {own_atlas}: the shadow edge drawn {off} texels from where the texels put it"
        );
    }
}
