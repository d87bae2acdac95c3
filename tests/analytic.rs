//! The analytic oracles of `prtbake verify`, as tests (DESIGN.md "Analytic oracles").

use prtbake::bake::{bake_mesh, BakeParams, DirectionPattern, Mode, Sampling};
use prtbake::sh;
use prtbake::verify::{self, shapes, VerifyParams};

fn assert_check(check: verify::Check) {
    eprint!("{}", verify::format_table(std::slice::from_ref(&check)));
    assert!(check.passed, "{} failed", check.name);
}

/// Spine issue: order 4, 1,024 rays, RMS ≤ 1e-3 and max ≤ 5e-3 against (Â_l/π)·y_lm(n).
#[test]
fn unoccluded_sphere_matches_closed_form() {
    assert_check(verify::unoccluded_sphere(4, VerifyParams::default()).unwrap());
}

/// Spine issue: DC within 2e-3 wherever the occluder is wholly above the horizon.
#[test]
fn plane_under_sphere_matches_closed_form() {
    assert_check(verify::plane_under_sphere(4, VerifyParams::default()).unwrap());
}

/// Car-interior issue: DC of every bounce 0..4 and the total within 1%, window
/// mode (a cap of window triangles) and open mode (a hole), two f and two ρ.
#[test]
fn integrating_sphere_every_bounce_window_and_hole() {
    let v = VerifyParams { rays: 512, seed: 3 };
    for (mode, cap_height, albedo) in [(Mode::Window, 0.8, 0.5), (Mode::Window, 0.5, 0.8), (Mode::Open, 0.8, 0.8), (Mode::Open, 0.5, 0.5)] {
        assert_check(verify::integrating_sphere(mode, cap_height, albedo, v).unwrap());
    }
}

/// RMS coefficient error of the unoccluded sphere (order 4) at several ray
/// counts, Sobol against independent random directions. Sobol must win at
/// every count from 256 up, and converge faster than N^-1/2 overall.
#[test]
fn sobol_converges_faster_than_random() {
    let mesh = shapes::icosphere(3);
    let order = 4;
    let rms = |rays: u32, pattern: DirectionPattern| -> f64 {
        let params = BakeParams { order, rays, pattern, sampling: Sampling::Vertex, ..BakeParams::default() };
        let (r, _, _) = bake_mesh(&mesh, &params, &[]).unwrap();
        let mut y = vec![0.0f32; order * order];
        let mut sum = 0.0f64;
        for v in 0..mesh.vertex_count() {
            sh::eval_basis(order, mesh.normals[v], &mut y);
            for k in 0..order * order {
                let l = (k as f64).sqrt() as usize;
                let expected = sh::clamped_cosine_kernel(l) / std::f64::consts::PI * y[k] as f64;
                sum += (r.coefficients(v, 0)[k] as f64 - expected).powi(2);
            }
        }
        (sum / (mesh.vertex_count() * order * order) as f64).sqrt()
    };
    eprintln!("{:>6} {:>12} {:>12} {:>7}", "rays", "sobol rms", "random rms", "ratio");
    let mut table = Vec::new();
    for rays in [64, 256, 1024, 4096] {
        let (s, r) = (rms(rays, DirectionPattern::Sobol), rms(rays, DirectionPattern::Random));
        eprintln!("{rays:>6} {s:>12.3e} {r:>12.3e} {:>7.1}", r / s);
        table.push((rays, s, r));
    }
    for &(rays, s, r) in &table[1..] {
        assert!(s < r, "Sobol not better at {rays} rays: {s} vs {r}");
    }
    // Random error falls as N^-1/2 (×1/8 over 64×); Sobol's must fall faster.
    let (s64, s4096) = (table[0].1, table[3].1);
    assert!(s4096 < s64 / 8.0, "Sobol RMS only fell from {s64} to {s4096}");
}

/// Window sampling (next-event estimation toward the glass) is unbiased: the
/// integrating sphere's window-mode bounces still match within 1%.
#[test]
fn integrating_sphere_with_window_sampling() {
    use prtbake::bake::{bake_mesh, BakeParams, Mode};
    let (mesh, f) = shapes::integrating_sphere(3, 0.6, 0.7, shapes::Opening::Window);
    let params = BakeParams {
        order: 1,
        rays: 512,
        mode: Mode::Window,
        bounces: 2,
        store_bounces: true,
        window_sampling: true,
        ..BakeParams::default()
    };
    let (r, surfaces, _) = bake_mesh(&mesh, &params, &[]).unwrap();
    let mut on_wall = vec![true; mesh.vertex_count()];
    for t in 0..mesh.triangle_count() {
        if surfaces.window_transmittance[t].is_some() {
            mesh.triangle(t).iter().for_each(|&i| on_wall[i as usize] = false);
        }
    }
    let wall: Vec<usize> = (0..mesh.vertex_count()).filter(|&i| on_wall[i]).collect();
    for (b, layer) in r.bounces.iter().enumerate() {
        let got = wall.iter().map(|&i| layer[i] as f64).sum::<f64>() / wall.len() as f64;
        let expected = verify::Y00 * f * (0.6 * (1.0 - f)).powi(b as i32);
        eprintln!("window sampling, bounce {b}: {got:.6} vs {expected:.6}");
        assert!((got - expected).abs() / expected < 0.01, "bounce {b}: {got} vs {expected}");
    }
}
