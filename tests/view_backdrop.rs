//! The backdrop (env map, sky and sun disc behind the geometry), window glass
//! and the photographic exposure, against CPU evaluations: headless frames,
//! skipped with a notice when no adapter exists.

use glam::{Mat3, Vec3};
use prtbake::mesh::{Material, MaterialRole, Mesh};
use prtbake::sh::EquirectImage;
use prtbake::verify::shapes;
use prtbake::view::scene::prepare_scene;
use prtbake::view::tonemap::{self, ToneMap, ToneOperator};
use prtbake::view::{backdrop, lighting, reference, render_image, Backdrop, Camera, FrameSettings, Image, LayerSelection, SkyBackdrop};

use crate::view::{bundle_of, gpu_or_skip, linear_tonemap, nearest_hit, unoccluded_transfer, MAX_CODE_DIFF};

/// A smooth map (periodic in longitude), 64×32: every bilinear neighbourhood is nearly linear.
fn smooth_env() -> EquirectImage {
    let (width, height) = (64u32, 32u32);
    let tau = std::f32::consts::TAU;
    let rgb = (0..height)
        .flat_map(|row| (0..width).map(move |col| ((col as f32 + 0.5) / width as f32, (row as f32 + 0.5) / height as f32)))
        .map(|(u, v)| [0.5 + 0.4 * (tau * u).sin(), 0.2 + 0.7 * v, 0.45 + 0.35 * (tau * u).cos() * (std::f32::consts::PI * v).sin()])
        .collect();
    EquirectImage { width, height, rgb }
}

/// The icosphere of radius 1 at the origin with the closed-form transfer, as a prepared scene.
fn sphere_scene(extra: Option<Mesh>) -> (Mesh, prtbake::view::PreparedScene) {
    let order = 3;
    let mut mesh = shapes::icosphere(3);
    mesh.materials[0].albedo = [0.8, 0.6, 0.4];
    if let Some(extra) = extra {
        shapes::append(&mut mesh, &extra);
    }
    let transfer = unoccluded_transfer(&mesh, order);
    let scene = prepare_scene(&bundle_of(mesh.clone(), order, transfer, None), &LayerSelection::Total, &[]).unwrap();
    (mesh, scene)
}

/// Pixels whose 3×3 neighbourhood all share `class` (so rasterisation rules at edges do not matter).
fn interior_pixels<T: PartialEq + Copy>(width: u32, height: u32, class: impl Fn(u32, u32) -> T) -> Vec<(u32, u32, T)> {
    let classes: Vec<T> = (0..height).flat_map(|y| (0..width).map(move |x| (x, y))).map(|(x, y)| class(x, y)).collect();
    let at = |x: u32, y: u32| classes[(y * width + x) as usize];
    let mut out = Vec::new();
    for y in 1..height - 1 {
        for x in 1..width - 1 {
            let c = at(x, y);
            if (0..9).all(|k| at(x + k % 3 - 1, y + k / 3 - 1) == c) {
                out.push((x, y, c));
            }
        }
    }
    out
}

/// Largest and mean code difference between the image and expected codes at `pixels`; asserts ≤ MAX_CODE_DIFF.
fn compare(image: &Image, pixels: &[(u32, u32, [u8; 3])], what: &str) -> (i32, f64) {
    let (mut max, mut sum) = (0, 0i64);
    for &(x, y, want) in pixels {
        let got = image.pixel(x, y);
        let diff = (0..3).map(|k| (got[k] as i32 - want[k] as i32).abs()).max().unwrap();
        assert!(diff <= MAX_CODE_DIFF, "{what}: pixel ({x}, {y}): GPU {got:?}, CPU {want:?}");
        max = max.max(diff);
        sum += diff as i64;
    }
    (max, sum as f64 / pixels.len().max(1) as f64)
}

#[test]
fn env_backdrop_matches_the_cpu_lookup_turned_with_the_car() {
    let Some(gpu) = gpu_or_skip("env_backdrop_matches_the_cpu_lookup_turned_with_the_car") else { return };
    let (mesh, mut scene) = sphere_scene(None);
    let env = smooth_env();
    scene.environment = Some(env.clone());
    let rotation = lighting::car_to_env_rotation(30.0, 10.0, 0.0);
    let settings = FrameSettings {
        lighting: vec![[0.0; 3]; 9],
        sun_step: None,
        backdrop: Backdrop::EnvMap { rotation },
        tonemap: linear_tonemap(0.0),
    };
    let (width, height) = (128, 96);
    let mut camera = Camera::look_at(Vec3::new(0.5, 0.8, 3.0), Vec3::ZERO, scene.bounds);
    camera.fov_y_deg = 90.0;
    let image = render_image(&gpu, &scene, None, &camera, &settings, width, height).unwrap();
    let ray = |x: u32, y: u32| camera.pixel_ray(x as f32 + 0.5, y as f32 + 0.5, width, height);
    let sky: Vec<(u32, u32, [u8; 3])> = interior_pixels(width, height, |x, y| {
        let (origin, dir) = ray(x, y);
        nearest_hit(&mesh, origin, dir).is_none()
    })
    .into_iter()
    .filter(|&(_, _, background)| background)
    .map(|(x, y, _)| {
        let radiance = backdrop::radiance(&settings.backdrop, Some(&env), ray(x, y).1);
        (x, y, tonemap::linear(radiance, 0.0, 2.2).map(tonemap::to_u8))
    })
    .collect();
    let (max, mean) = compare(&image, &sky, "env backdrop");
    eprintln!("env backdrop: {} pixels compared, max difference {max} codes, mean {mean:.3}", sky.len());
    assert!(sky.len() > 6000, "only {} backdrop pixels", sky.len());
    assert!(mean < 0.5);
}

#[test]
fn sky_backdrop_matches_preetham_with_the_sun_disc() {
    let Some(gpu) = gpu_or_skip("sky_backdrop_matches_preetham_with_the_sun_disc") else { return };
    // Geometry far behind the camera; the view is all sky around the sun.
    let mut far = shapes::icosphere(1);
    shapes::transform(&mut far, 0.1, Vec3::new(0.0, 0.0, 50.0));
    let transfer = unoccluded_transfer(&far, 1);
    let scene = prepare_scene(&bundle_of(far, 1, transfer, None), &LayerSelection::Total, &[]).unwrap();
    let sun = Vec3::new(0.3, 0.5, -0.8).normalize();
    let sky = SkyBackdrop {
        sun,
        up: Vec3::Y,
        turbidity: 3.0,
        scale: 1.0,
        sun_irradiance: Some([1.0e5, 0.95e5, 0.85e5]),
        rotation: Mat3::IDENTITY,
    };
    let exposure = -16.0; // sky radiance ~10⁴ cd/m² → 0.15; the disc (clamped at 65504) → 1.
    let settings =
        FrameSettings { lighting: vec![[0.0; 3]], sun_step: None, backdrop: Backdrop::Sky(sky), tonemap: linear_tonemap(exposure) };
    let (width, height) = (128, 128);
    let mut camera = Camera::look_at(Vec3::ZERO, sun * 10.0 + Vec3::new(0.0, -0.2, 0.0), scene.bounds);
    camera.fov_y_deg = 5.0; // 0.04° per pixel: the disc (0.53° across) spans ~13 pixels.
    let image = render_image(&gpu, &scene, None, &camera, &settings, width, height).unwrap();
    let dir = |x: u32, y: u32| camera.pixel_ray(x as f32 + 0.5, y as f32 + 0.5, width, height).1;
    let in_disc = |x: u32, y: u32| dir(x, y).dot(sun) >= (backdrop::SUN_ANGULAR_RADIUS_DEG as f32).to_radians().cos();
    let pixels: Vec<(u32, u32, bool)> = interior_pixels(width, height, in_disc);
    let expected: Vec<(u32, u32, [u8; 3])> = pixels
        .iter()
        .map(|&(x, y, _)| {
            (x, y, tonemap::linear(backdrop::radiance(&settings.backdrop, None, dir(x, y)), exposure, 2.2).map(tonemap::to_u8))
        })
        .collect();
    let (max, mean) = compare(&image, &expected, "sky backdrop");
    let disc = pixels.iter().filter(|p| p.2).count();
    eprintln!("sky backdrop: {} pixels compared ({disc} inside the sun disc), max difference {max} codes, mean {mean:.3}", pixels.len());
    assert!(disc >= 50, "only {disc} compared pixels inside the sun disc");
    assert!(pixels.iter().filter(|p| p.2).all(|&(x, y, _)| image.pixel(x, y)[..3] == [255, 255, 255]));
    assert!(pixels.len() > 12000);
}

/// A vertical glass square at z = `z` covering x < 0, with its coincident
/// twin of opposite winding (double-sided CAD glass), transmittance `tau`.
fn glass_pane(z: f32, tau: f32) -> Mesh {
    let positions = vec![Vec3::new(-6.0, -6.0, z), Vec3::new(0.0, -6.0, z), Vec3::new(0.0, 6.0, z), Vec3::new(-6.0, 6.0, z)];
    Mesh {
        normals: vec![Vec3::Z; 4],
        positions,
        indices: vec![0, 1, 2, 0, 2, 3, 0, 2, 1, 0, 3, 2],
        tri_material: vec![0; 4],
        tri_group: vec![0; 4],
        materials: vec![Material { name: "glass".into(), albedo: [0.0; 3], role: MaterialRole::Window, transmittance: tau }],
        groups: vec!["pane".into()],
        ..Mesh::default()
    }
}

#[test]
fn glass_lets_its_transmittance_of_the_env_and_the_body_through_once() {
    let Some(gpu) = gpu_or_skip("glass_lets_its_transmittance_of_the_env_and_the_body_through_once") else { return };
    let tau = 0.4;
    let (mesh, mut scene) = sphere_scene(Some(glass_pane(1.5, tau)));
    let env = smooth_env();
    scene.environment = Some(env.clone());
    let sphere_triangles = shapes::icosphere(3).triangle_count();
    let lighting: Vec<[f32; 3]> = vec![[1.5, 1.4, 1.3], [0.5, 0.45, 0.4], [0.6, 0.6, 0.7], [0.2, -0.1, 0.0]];
    let settings = FrameSettings {
        lighting: lighting.clone(),
        sun_step: None,
        backdrop: Backdrop::EnvMap { rotation: Mat3::IDENTITY },
        tonemap: linear_tonemap(0.0),
    };
    let (width, height) = (128, 128);
    let mut camera = Camera::look_at(Vec3::new(0.3, 0.4, 4.0), Vec3::ZERO, scene.bounds);
    camera.fov_y_deg = 60.0;
    let image = render_image(&gpu, &scene, None, &camera, &settings, width, height).unwrap();

    let sphere = {
        let mut m = mesh.clone();
        m.indices.truncate(3 * sphere_triangles);
        m
    };
    let light: Vec<[f32; 3]> = (0..sphere.vertex_count())
        .map(|v| reference::vertex_light(&scene, &lighting, None, v, sphere.normals[v].to_array(), true))
        .collect();
    let ray = |x: u32, y: u32| camera.pixel_ray(x as f32 + 0.5, y as f32 + 0.5, width, height);
    // Class: (through the glass, sphere triangle hit or none).
    let class = |x: u32, y: u32| {
        let (origin, dir) = ray(x, y);
        let t = (1.5 - origin.z) / dir.z;
        let through_glass = t > 0.0 && (origin + dir * t).x < 0.0;
        (through_glass, nearest_hit(&sphere, origin, dir).map(|(tri, ..)| tri))
    };
    let pixels = interior_pixels(width, height, |x, y| {
        let (glass, hit) = class(x, y);
        (glass, hit.is_some())
    });
    let expected: Vec<(u32, u32, [u8; 3])> = pixels
        .iter()
        .map(|&(x, y, (glass, _))| {
            let (origin, dir) = ray(x, y);
            let radiance = match nearest_hit(&sphere, origin, dir) {
                Some((tri, u, v)) => {
                    let [a, b, c] = sphere.triangle(tri).map(|i| light[i as usize]);
                    let e: [f32; 3] = std::array::from_fn(|k| a[k] * (1.0 - u - v) + b[k] * u + c[k] * v);
                    reference::radiance(sphere.materials[0].albedo, e)
                }
                None => backdrop::radiance(&settings.backdrop, Some(&env), dir),
            };
            let seen = if glass { radiance.map(|c| c * tau) } else { radiance };
            (x, y, tonemap::linear(seen, 0.0, 2.2).map(tonemap::to_u8))
        })
        .collect();
    let (max, mean) = compare(&image, &expected, "glass");
    let count = |glass: bool, body: bool| pixels.iter().filter(|p| p.2 == (glass, body)).count();
    eprintln!(
        "glass: {} pixels compared (env through glass {}, body through glass {}, env {}, body {}), max difference {max} codes, mean {mean:.3}",
        pixels.len(),
        count(true, false),
        count(true, true),
        count(false, false),
        count(false, true)
    );
    assert!(count(true, false) > 1500 && count(true, true) > 800 && count(false, false) > 1500 && count(false, true) > 800);
    assert!(mean < 0.5);
}

/// Mean 8-bit value (RGB) of an image.
fn mean_code(image: &Image) -> f64 {
    let sum: u64 = image.rgba.chunks_exact(4).map(|p| p[0] as u64 + p[1] as u64 + p[2] as u64).sum();
    sum as f64 / (3 * image.width as u64 * image.height as u64) as f64
}

/// The sphere under `env` (projected to SH, drawn behind) with `operator`.
fn render_under(gpu: &prtbake::view::Gpu, env: &EquirectImage, operator: ToneOperator) -> Image {
    let (_, mut scene) = sphere_scene(None);
    scene.environment = Some(env.clone());
    let settings = FrameSettings {
        lighting: prtbake::sh::project_equirect(env, 3),
        sun_step: None,
        backdrop: Backdrop::EnvMap { rotation: Mat3::IDENTITY },
        tonemap: ToneMap { operator, ..ToneMap::default() },
    };
    let camera = Camera::look_at(Vec3::new(0.8, 1.1, 2.8), Vec3::ZERO, scene.bounds);
    render_image(gpu, &scene, None, &camera, &settings, 96, 96).unwrap()
}

fn scaled(env: &EquirectImage, factor: f32) -> EquirectImage {
    EquirectImage { rgb: env.rgb.iter().map(|p| p.map(|c| c * factor)).collect(), ..env.clone() }
}

#[test]
fn photographic_exposure_keeps_a_dim_scene_dark_where_drago_does_not() {
    let Some(gpu) = gpu_or_skip("photographic_exposure_keeps_a_dim_scene_dark_where_drago_does_not") else { return };
    // The same scene at 10⁻³ and 10³ cd/m²: Drago sees only L/L_a (same picture),
    // the photographic key follows the absolute adaptation luminance.
    let env = smooth_env();
    let [dim, bright] = [1e-3f32, 1e3].map(|f| scaled(&env, f));
    let photo = [&dim, &bright].map(|e| mean_code(&render_under(&gpu, e, ToneOperator::Photographic)));
    let drago = [&dim, &bright].map(|e| mean_code(&render_under(&gpu, e, ToneOperator::Drago)));
    eprintln!("mean code, dim vs bright: photographic {:.1} vs {:.1}; Drago {:.1} vs {:.1}", photo[0], photo[1], drago[0], drago[1]);
    // Key 0.03 vs 0.63 on the same relative image: the dim frame is far darker.
    assert!(photo[0] < 0.5 * photo[1], "{photo:?}");
    assert!((drago[0] - drago[1]).abs() < 1.0, "{drago:?}");
}

#[test]
fn night_map_dimmed_renders_darker_than_a_sunny_one() {
    let Some(gpu) = gpu_or_skip("night_map_dimmed_renders_darker_than_a_sunny_one") else { return };
    let (Some(night), Some(city)) = (crate::util::shared_data("hdri-cc0/night.exr"), crate::util::shared_data("hdri-cc0/city.exr")) else {
        return;
    };
    let night = scaled(&prtbake::sh::load_equirect(&night).unwrap(), 1e-3);
    let city = prtbake::sh::load_equirect(&city).unwrap();
    let [n, c] = [&night, &city].map(|e| mean_code(&render_under(&gpu, e, ToneOperator::Photographic)));
    let [dn, dc] = [&night, &city].map(|e| mean_code(&render_under(&gpu, e, ToneOperator::Drago)));
    eprintln!("mean code: night ×1e-3 {n:.1}, city {c:.1} (photographic); Drago {dn:.1}, {dc:.1}");
    // The maps are not in absolute units (the city's sky is a few units, not
    // thousands of cd/m²), so the keys differ less than on real luminances
    // (0.03 vs ≈ 0.25); the night frame must still be clearly darker.
    assert!(n < 0.8 * c, "night {n}, city {c}");
}

/// Fraction of pixels with a saturated channel (code 255).
fn clipped_fraction(image: &Image) -> f64 {
    let clipped = image.rgba.chunks_exact(4).filter(|p| p[..3].contains(&255)).count();
    clipped as f64 / (image.width as f64 * image.height as f64)
}

fn read_png(path: &std::path::Path) -> Image {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut rgba = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut rgba).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgba);
    Image { width: info.width, height: info.height, rgba }
}

/// The colonnade at noon on the equinox (`generate colonnade --detail small`,
/// a quick bake, one sun step at 12:00), default camera, through the CLI.
///
/// Bound: with the photographic key (≈ 0.7 at daylight adaptation) a pixel
/// reaches display white only beyond x ≈ 7 on the filmic curve, ≈ 10× the
/// adaptation luminance; the sunlit marble is a few times the frame's
/// log-average, so at most 1% of the pixels may clip (measured 2026-11-24:
/// 0.0%, Drago 7.3% of the frame).
#[test]
fn colonnade_at_noon_keeps_its_highlights() {
    use crate::util::{prtbake, Scratch};
    if gpu_or_skip("colonnade_at_noon_keeps_its_highlights").is_none() {
        return;
    }
    let scratch = Scratch::new("view-noon");
    let s = |name: &str| scratch.path(name).to_str().unwrap().to_string();
    let steps: [&[&str]; 3] = [
        &["generate", "colonnade", "--detail", "small", "-o", &s("col.glb")],
        &["bake", &s("col.glb"), "-o", &s("col.prtb"), "--rays", "16", "--bounces", "1", "--quiet"],
        &["sun", &s("col.prtb"), "-o", &s("col.prtb"), "--north", "1,0,0", "--from", "12:00", "--to", "12:00", "--steps", "1", "--quiet"],
    ];
    for args in steps {
        let run = prtbake(args);
        assert!(run.status.success(), "{args:?}: {}", String::from_utf8_lossy(&run.stderr));
    }
    let mut fractions = Vec::new();
    for operator in ["photographic", "drago"] {
        let png = s(&format!("noon-{operator}.png"));
        let run = prtbake(&["view", &s("col.prtb"), "--tonemap", operator, "--screenshot", &png, "--size", "480x270"]);
        assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
        fractions.push(clipped_fraction(&read_png(std::path::Path::new(&png))));
    }
    eprintln!("colonnade at noon: clipped pixels photographic {:.1}%, Drago {:.1}%", 100.0 * fractions[0], 100.0 * fractions[1]);
    assert!(fractions[0] < 0.01, "{fractions:?}");
}

#[test]
fn turning_the_car_under_a_time_lapse_is_refused() {
    use crate::util::{prtbake, Scratch};
    let scratch = Scratch::new("view-yaw");
    let path = scratch.path("sun.prtb");
    ::prtbake::bundle::write_bundle(&path, &crate::view::plane_and_sphere_time_lapse().0).unwrap();
    let shot = scratch.path("x.png");
    let run = prtbake(&["view", path.to_str().unwrap(), "--yaw", "10", "--screenshot", shot.to_str().unwrap()]);
    assert_eq!(run.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("sun masks") && stderr.contains("sun.prtb"), "{stderr}");
    assert!(!shot.exists());
}
