//! Stability studies (docs/stability.md): each a failure and its cure side by
//! side, with the numbers printed (`cargo test --release stability -- --nocapture`).
//! Shadow leaks at covered vertices live in bake_props
//! (`interior_sampling_cures_covered_vertices`).

use glam::{DVec3, Vec3};
use prtbake::bake::{self, bake_mesh, BakeParams};
use prtbake::mesh::Mesh;
use prtbake::sh::{self, Window};
use prtbake::trace::{BuildQuality, Scene};
use prtbake::verify::{plane_point_reference, shapes, Y00};

use crate::util::shared_data;

/// Minimum and maximum over many directions of an SH function (order `order`, one channel).
fn sh_extremes(coeffs: &[f32], order: usize) -> (f32, f32) {
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for i in 0..200 {
        for j in 0..400 {
            let theta = std::f32::consts::PI * (i as f32 + 0.5) / 200.0;
            let phi = std::f32::consts::TAU * j as f32 / 400.0;
            let d = Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
            let v = sh::evaluate(coeffs, order, d);
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    (lo, hi)
}

/// A small bright source (5° disc) in SH: irradiance rings negative on the far
/// side, more so at higher order; a Hanning window (width = order + 1) removes
/// most of the negative lobe at the cost of a softer peak.
#[test]
fn sh_ringing_under_a_small_bright_source() {
    let axis = DVec3::new(0.3, 0.5, 0.81).normalize();
    let cos_radius = 5f64.to_radians().cos();
    for order in [3usize, 5, 8] {
        let source = sh::project_function(order, 256, |d| if d.dot(axis) >= cos_radius { [1000.0; 3] } else { [0.0; 3] });
        let radiance: Vec<f32> = source.iter().map(|c| c[0]).collect();
        let mut rows = Vec::new();
        for (name, window) in [
            ("none", Window::None),
            ("hanning", Window::Hanning { width: order as f32 + 1.0 }),
            ("lanczos", Window::Lanczos { width: order as f32 + 1.0 }),
        ] {
            let mut l = radiance.clone();
            sh::apply_window(&mut l, 1, order, window);
            let (rlo, rhi) = sh_extremes(&l, order);
            let mut e = l.clone();
            sh::convolve_clamped_cosine(&mut e, order);
            let (elo, ehi) = sh_extremes(&e, order);
            eprintln!(
                "ringing order {order} window {name:<8}: radiance min/max {:>7.2}%  irradiance min/max {:>7.3}%  irradiance peak {:.3}",
                100.0 * rlo / rhi,
                100.0 * elo / ehi,
                ehi
            );
            rows.push((rlo / rhi, elo / ehi));
        }
        let (none, hanning) = (rows[0], rows[1]);
        assert!(none.0 < -0.05, "order {order}: radiance should ring (min/max {})", none.0);
        assert!(hanning.0.abs() * 1.5 < none.0.abs(), "order {order}: Hanning should cut the radiance lobe ({} vs {})", hanning.0, none.0);
        assert!(hanning.1 >= none.1, "order {order}: Hanning should not deepen the irradiance lobe");
    }
    if let Some(path) = shared_data("hdri-cc0/sunset.exr") {
        let image = sh::load_equirect(&path).unwrap();
        for order in [3usize, 6] {
            let coeffs = sh::project_equirect(&image, order);
            let mut y: Vec<f32> = coeffs.iter().map(|c| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]).collect();
            let (lo, hi) = sh_extremes(&y, order);
            sh::apply_window(&mut y, 1, order, Window::Hanning { width: order as f32 + 1.0 });
            let (wlo, whi) = sh_extremes(&y, order);
            eprintln!(
                "ringing sunset.exr order {order}: luminance min/max {:.2}% raw, {:.2}% with Hanning",
                100.0 * lo / hi,
                100.0 * wlo / whi
            );
        }
    }
}

/// Grazing sun: rays leaving a flat tessellated floor toward a sun just above
/// the horizon. Started on the surface they hit the floor's own neighbours
/// (shadow acne); pushed off along the face normal (Scene::offset_origin) they
/// do not. Far from the origin (1e4 m) f32 spacing makes it worse, and the
/// offset floor of 64 ulps still cures it. Near the horizon the sky stays finite.
#[test]
fn grazing_sun_self_shadowing() {
    for offset in [0.0f32, 1e4] {
        let mut floor = shapes::plane_grid(64, 8.0);
        // A gentle slope in z: the floor is not axis-aligned, so rounding is not exact.
        floor.positions.iter_mut().for_each(|p| *p = Vec3::new(p.x + offset, p.y + 0.01 * p.z + offset, p.z + offset));
        let scene = Scene::build(&floor, BuildQuality::Sah).unwrap();
        let slope_normal = Vec3::new(0.0, 1.0, -0.01).normalize();
        for elevation_deg in [0.05f32, 0.5, 5.0] {
            let e = elevation_deg.to_radians();
            // Elevation above the sloped plane, sun toward +x.
            let (t, _) = prtbake::sampling::tangent_frame(slope_normal);
            let sun = (t * e.cos() + slope_normal * e.sin()).normalize();
            let (mut raw_hits, mut offset_hits, mut n) = (0, 0, 0);
            for tri in 0..floor.triangle_count() {
                let [a, b, c] = floor.triangle_positions(tri);
                for k in 0..4 {
                    let w = [(k as f32 + 0.5) / 5.0, 0.25, 0.0];
                    let p = a * (1.0 - w[0] - w[1]) + b * w[0] + c * w[1];
                    n += 1;
                    if scene.closest_hit(p, sun, f32::INFINITY).is_some() {
                        raw_hits += 1;
                    }
                    if scene.closest_hit(scene.offset_origin(p, scene.face_normal(tri as u32), sun), sun, f32::INFINITY).is_some() {
                        offset_hits += 1;
                    }
                }
            }
            eprintln!(
                "grazing sun {elevation_deg:>5}° floor at {offset:>6} m: {:.2}% of rays self-shadowed from the surface, {:.2}% with the offset origin ({} rays)",
                100.0 * raw_hits as f64 / n as f64, 100.0 * offset_hits as f64 / n as f64, n
            );
            assert_eq!(offset_hits, 0, "offset origins must not self-shadow ({elevation_deg}° at {offset} m)");
        }
    }
    for elevation in [-0.5f32, 0.0, 0.1, 0.5, 2.0] {
        let e = elevation.to_radians();
        let sky = prtbake::sky::preetham_sky(Vec3::new(e.cos(), e.sin(), 0.0), Vec3::Y, 3.0, 3);
        let finite = sky.sky_sh.iter().flatten().all(|v| v.is_finite()) && sky.sun_rgb_irradiance.iter().all(|v| v.is_finite());
        eprintln!("sky at sun elevation {elevation:>4}°: night {}, DC {:?}, sun {:?}", sky.night, sky.sky_sh[0], sky.sun_rgb_irradiance);
        assert!(finite);
    }
}

/// A floor under a sphere occluder, triangulated as long slivers (each row of
/// cells is two fans of 16:1 triangles). A sliver's interior samples lie far
/// from its corners, so a vertex gets the average of transfer along a 4 m
/// strip: the sphere's shadow smears. Cleaning with a maximum edge length
/// (`clean --max-edge`) splits the slivers and restores the error of a regular grid.
#[test]
fn slivers_smear_and_cleaning_cures() {
    let (cells, size) = (16u32, 4.0f32);
    let slivered = |grid: bool| -> Mesh {
        let mut m = shapes::plane_grid(cells, size);
        if !grid {
            let n = cells + 1;
            let mut indices = Vec::new();
            for j in 0..cells {
                let b = |i: u32| j * n + i;
                let t = |i: u32| (j + 1) * n + i;
                for i in 0..cells {
                    indices.extend([b(0), t(i), t(i + 1)]);
                    indices.extend([b(i), t(cells), b(i + 1)]);
                }
            }
            m.indices = indices;
            let count = m.indices.len() / 3;
            m.tri_material = vec![0; count];
            m.tri_group = vec![0; count];
        }
        let mut sphere = shapes::icosphere(3);
        shapes::transform(&mut sphere, 0.5, Vec3::new(0.3, 0.8, 0.1));
        shapes::append(&mut m, &sphere);
        m
    };
    let plane_vertices = ((cells + 1) * (cells + 1)) as usize;
    let params = BakeParams { order: 2, rays: 1024, ..BakeParams::default() };
    let centre = DVec3::new(0.3, 0.8, 0.1);
    let error = |mesh: &Mesh, vertices: &dyn Fn(&Mesh) -> Vec<usize>| -> (f64, u64) {
        let (r, _, _) = bake_mesh(mesh, &params, &[]).unwrap();
        let vs = vertices(mesh);
        let mut s = 0.0;
        for &v in &vs {
            let exact = plane_point_reference(2, mesh.positions[v].as_dvec3(), centre, 0.5 * 0.9975);
            s += (r.coefficients(v, 0)[0] as f64 - exact[0]).powi(2);
        }
        ((s / vs.len() as f64).sqrt() / Y00, r.stats.vertices_without_samples)
    };
    // The original grid vertices, found by position in whatever mesh.
    let grid_vertices = |mesh: &Mesh| -> Vec<usize> {
        (0..mesh.vertex_count())
            .filter(|&v| {
                let p = mesh.positions[v];
                let cell = size / cells as f32;
                p.y.abs() < 1e-6
                    && ((p.x / cell).fract().abs() < 1e-4 || (p.x / cell).fract().abs() > 1.0 - 1e-4)
                    && ((p.z / cell).fract().abs() < 1e-4 || (p.z / cell).fract().abs() > 1.0 - 1e-4)
            })
            .collect()
    };
    let regular = error(&slivered(true), &grid_vertices);
    let sliver_mesh = slivered(false);
    let bad = error(&sliver_mesh, &grid_vertices);
    let clean_params = prtbake::clean::CleanParams { max_edge: Some(size / cells as f32 * 1.5), ..prtbake::clean::CleanParams::cad() };
    let (cleaned, report) = prtbake::clean::clean_mesh(&sliver_mesh, &clean_params).unwrap();
    let cured = error(&cleaned, &grid_vertices);
    eprintln!(
        "slivers: DC RMS error / y00 at the {plane_vertices} grid vertices: regular grid {:.3e}, slivers {:.3e}, slivers cleaned (max edge {:.2} m, {} → {} triangles) {:.3e}",
        regular.0, bad.0, clean_params.max_edge.unwrap(), sliver_mesh.triangle_count(), cleaned.triangle_count(), cured.0
    );
    let _ = report;
    assert!(bad.0 > 2.0 * regular.0, "slivers should smear the shadow ({} vs {})", bad.0, regular.0);
    assert!(cured.0 < 0.6 * bad.0, "cleaning should cure most of it ({} vs {})", cured.0, bad.0);
}

/// The plane-under-sphere scene at 1 mm, 1 m and 10 km (the last also 10 km
/// from the origin). Epsilons relative to the scene give the same error at
/// every scale; a fixed 1e-4 offset leaks at 1 mm and self-shadows at 10 km.
#[test]
fn scale_relative_epsilons() {
    let build = |scale: f32, offset: f32| -> (Mesh, DVec3, f64) {
        let mut m = shapes::plane_grid(24, 4.0);
        let mut sphere = shapes::icosphere(3);
        shapes::transform(&mut sphere, 0.5, Vec3::new(0.0, 0.6, 0.0));
        shapes::append(&mut m, &sphere);
        m.positions.iter_mut().for_each(|p| *p = *p * scale + Vec3::splat(offset));
        (m, DVec3::new(offset as f64, 0.6 * scale as f64 + offset as f64, offset as f64), 0.5 * 0.9975 * scale as f64)
    };
    let params = BakeParams { order: 1, rays: 256, ..BakeParams::default() };
    let mut errors = Vec::new();
    for (scale, offset) in [(1e-3f32, 0.0f32), (1.0, 0.0), (1e4, 1e4)] {
        let (mesh, centre, radius) = build(scale, offset);
        let surfaces = bake::Surfaces::resolve(&mesh, &[]).unwrap();
        let mut row = Vec::new();
        for fixed in [None, Some(1e-4f32)] {
            let mut scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
            if let Some(eps) = fixed {
                scene.origin_offset = eps;
                scene.tie_distance = eps;
            }
            let r = bake::bake_transfer(&mesh, &scene, &surfaces, &params).unwrap();
            let mut s = 0.0;
            let count = 25 * 25;
            for v in 0..count {
                let x = mesh.positions[v].as_dvec3();
                let to_centre = centre - x;
                let alpha = (radius / to_centre.length()).asin();
                let beta = to_centre.normalize().dot(DVec3::Y).acos();
                let exact = if alpha + beta < std::f64::consts::FRAC_PI_2 {
                    Y00 * (1.0 - alpha.sin().powi(2) * beta.cos())
                } else {
                    plane_point_reference(1, x, centre, radius)[0]
                };
                s += (r.total[v] as f64 - exact).powi(2);
            }
            let rel = (s / count as f64).sqrt() / Y00;
            eprintln!(
                "scale {scale:>6} m at {offset:>6} m, {}: DC RMS error / y00 = {rel:.3e} (offset {:.3e})",
                if fixed.is_some() { "fixed epsilon 1e-4" } else { "relative epsilons" },
                scene.origin_offset
            );
            row.push(rel);
        }
        errors.push(row);
    }
    let relative: Vec<f64> = errors.iter().map(|r| r[0]).collect();
    let (lo, hi) = relative.iter().fold((f64::INFINITY, 0.0f64), |(a, b), &e| (a.min(e), b.max(e)));
    assert!(hi < 0.05 && hi < 2.0 * lo, "relative epsilons should behave alike at every scale: {relative:?}");
    assert!(
        errors[0][1] > 3.0 * errors[0][0] || errors[2][1] > 3.0 * errors[2][0],
        "a fixed epsilon should fail at some scale: {errors:?}"
    );
}

/// NaN and infinity: a mesh file or an environment map holding them is
/// refused with the file named; a mesh built in code is refused by the
/// baker; projecting an unchecked map would have spread NaN into every coefficient.
#[test]
fn non_finite_input_is_refused() {
    let dir = crate::util::Scratch::new("nan");
    let obj = dir.path("nan.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n").unwrap();
    let err = prtbake::mesh::load_mesh(&obj, &Default::default()).unwrap_err().to_string();
    eprintln!("NaN in an OBJ: {err}");
    assert!(err.contains("nan.obj"));
    let mut mesh = shapes::plane_grid(2, 1.0);
    mesh.positions[4].y = f32::INFINITY;
    let err = bake_mesh(&mesh, &BakeParams::default(), &[]).unwrap_err().to_string();
    eprintln!("infinity in a mesh given to bake_mesh: {err}");
    assert!(err.contains("invalid mesh"));
    // An image with one infinite pixel: projected unchecked, the SH is not finite; the loader refuses it.
    let mut image = sh::EquirectImage { width: 8, height: 4, rgb: vec![[1.0; 3]; 32] };
    image.rgb[5] = [f32::INFINITY, 0.0, 0.0];
    let projected = sh::project_equirect(&image, 2);
    eprintln!("an infinite pixel projected unchecked: DC {:?}", projected[0]);
    let exr_path = dir.path("nan.exr");
    exr::prelude::write_rgb_file(&exr_path, 4, 2, |x, y| if (x, y) == (1, 0) { (f32::NAN, 0.0, 0.0) } else { (1.0f32, 1.0, 1.0) }).unwrap();
    let err = sh::load_equirect(&exr_path).map(|_| ()).unwrap_err().to_string();
    eprintln!("a NaN pixel in an EXR: {err}");
    assert!(err.contains("nan.exr") && err.contains("not finite"));
    assert!(!projected[0][0].is_finite());
}
