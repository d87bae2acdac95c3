//! Checks a bake against closed forms (DESIGN.md "Analytic oracles"): every
//! scene here is baked through [`crate::bake::bake_mesh`], the path `bake` uses.
//!
//! - Unoccluded convex object: t_lm = (Â_l/π)·y_lm(n).
//! - Plane under a sphere occluder (angular radius α, centre at angle β from n):
//!   t_00 = y_00·(1 − sin²α·cos β) when the cap is above the horizon; every
//!   other coefficient by quadrature over the cap.
//! - Integrating sphere with an opening of area fraction f, albedo ρ:
//!   t_00⁽ᵇ⁾ = y_00·f·(ρ(1−f))^b; the total over b ≤ B is the partial sum
//!   (→ y_00·f/(1−ρ(1−f)) as B → ∞).

pub mod shapes;

use glam::{DVec3, Vec3};

use crate::bake::{bake_mesh, BakeError, BakeParams, Mode};
use crate::sh;

/// y_00 = 1/(2√π).
pub const Y00: f64 = 0.282_094_791_773_878_14;

/// Error of one SH band over the checked vertices.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BandError {
    pub band: usize,
    pub max: f64,
    pub rms: f64,
}

/// The outcome of one analytic check.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Check {
    pub name: String,
    /// What was compared, in a few words.
    pub detail: String,
    pub bands: Vec<BandError>,
    /// Scalar comparisons (e.g. DC per bounce): (label, measured, expected, relative error).
    pub values: Vec<(String, f64, f64, f64)>,
    pub max_tolerance: f64,
    pub rms_tolerance: f64,
    pub passed: bool,
    pub rays: u64,
    pub seconds: f64,
}

/// Settings of a verification run.
#[derive(Clone, Copy, Debug)]
pub struct VerifyParams {
    pub rays: u32,
    pub seed: u32,
}

impl Default for VerifyParams {
    fn default() -> Self {
        VerifyParams { rays: 1024, seed: 1 }
    }
}

/// Runs every check.
pub fn verify_all(v: VerifyParams) -> Result<Vec<Check>, BakeError> {
    let mut checks = vec![unoccluded_sphere(4, v)?, plane_under_sphere(4, v)?];
    for (mode, f_height, albedo) in [(Mode::Window, 0.8, 0.5), (Mode::Window, 0.5, 0.8), (Mode::Open, 0.8, 0.8), (Mode::Open, 0.5, 0.5)] {
        checks.push(integrating_sphere(mode, f_height, albedo, v)?);
    }
    Ok(checks)
}

fn band_errors(order: usize, errors: &[Vec<f64>]) -> Vec<BandError> {
    (0..order)
        .map(|l| {
            let mut max = 0.0f64;
            let mut sum = 0.0f64;
            let mut count = 0usize;
            for e in errors {
                for i in l * l..(l + 1) * (l + 1) {
                    max = max.max(e[i].abs());
                    sum += e[i] * e[i];
                    count += 1;
                }
            }
            BandError { band: l, max, rms: (sum / count.max(1) as f64).sqrt() }
        })
        .collect()
}

fn passes(bands: &[BandError], max_tolerance: f64, rms_tolerance: f64) -> bool {
    let all_rms = (bands.iter().map(|b| b.rms * b.rms).sum::<f64>() / bands.len().max(1) as f64).sqrt();
    bands.iter().all(|b| b.max <= max_tolerance) && all_rms <= rms_tolerance
}

fn basis_f64(order: usize, d: DVec3) -> Vec<f64> {
    let mut y = vec![0.0f32; sh::coeff_count(order)];
    sh::eval_basis(order, d.as_vec3().normalize(), &mut y);
    y.into_iter().map(f64::from).collect()
}

/// Unoccluded icosphere (2,562 vertices): t_lm = (Â_l/π)·y_lm(n) at every vertex.
pub fn unoccluded_sphere(order: usize, v: VerifyParams) -> Result<Check, BakeError> {
    let mesh = shapes::icosphere(4);
    let params = BakeParams { order, rays: v.rays, seed: v.seed, ..BakeParams::default() };
    let (result, _, _) = bake_mesh(&mesh, &params, &[])?;
    let errors: Vec<Vec<f64>> = (0..mesh.vertex_count())
        .map(|i| {
            let y = basis_f64(order, mesh.normals[i].as_dvec3());
            let got = result.coefficients(i, 0);
            (0..sh::coeff_count(order))
                .map(|k| {
                    let l = (k as f64).sqrt() as usize;
                    got[k] as f64 - sh::clamped_cosine_kernel(l) / std::f64::consts::PI * y[k]
                })
                .collect()
        })
        .collect();
    let bands = band_errors(order, &errors);
    // Tolerances from the spine issue: RMS ≤ 1e-3, max ≤ 5e-3 at 1,024 rays.
    let (max_tolerance, rms_tolerance) = (5e-3, 1e-3);
    Ok(Check {
        name: "unoccluded-sphere".into(),
        detail: format!("icosphere, {} vertices, order {order}, every coefficient vs (Â_l/π)·y_lm(n)", mesh.vertex_count()),
        passed: passes(&bands, max_tolerance, rms_tolerance),
        bands,
        values: Vec::new(),
        max_tolerance,
        rms_tolerance,
        rays: result.stats.rays,
        seconds: result.stats.seconds,
    })
}

/// Exact transfer of a point with normal +Y under a sphere (centre `c`, radius `r`):
/// (Â_l/π)·y(n) minus the cap's cosine-weighted projection, by quadrature.
pub fn plane_point_reference(order: usize, x: DVec3, c: DVec3, r: f64) -> Vec<f64> {
    let n = DVec3::Y;
    let pi = std::f64::consts::PI;
    let y_n = basis_f64(order, n);
    let mut t: Vec<f64> = (0..y_n.len()).map(|k| sh::clamped_cosine_kernel((k as f64).sqrt() as usize) / pi * y_n[k]).collect();
    let axis = (c - x).normalize();
    let sin_alpha = r / (c - x).length();
    let cos_alpha = (1.0 - sin_alpha * sin_alpha).sqrt();
    let (tangent, bitangent) = axis.any_orthonormal_pair();
    // Midpoint rule in cos θ' ∈ [cos α, 1] and φ': the integrand is smooth on the cap.
    let (steps_mu, steps_phi) = (48, 96);
    let d_mu = (1.0 - cos_alpha) / steps_mu as f64;
    let d_phi = 2.0 * pi / steps_phi as f64;
    for i in 0..steps_mu {
        let mu = cos_alpha + (i as f64 + 0.5) * d_mu;
        let s = (1.0 - mu * mu).max(0.0).sqrt();
        for j in 0..steps_phi {
            let phi = (j as f64 + 0.5) * d_phi;
            let w = axis * mu + tangent * (s * phi.cos()) + bitangent * (s * phi.sin());
            let cosine = w.dot(n).max(0.0);
            let y = basis_f64(order, w);
            for k in 0..t.len() {
                t[k] -= y[k] * cosine * d_mu * d_phi / pi;
            }
        }
    }
    t
}

/// Plane (64×64 cells, side 4) under a sphere of radius 0.5 at height 1:
/// every coefficient at vertices whose occluder cap lies wholly above the
/// horizon (2° margin), against the closed form and quadrature.
pub fn plane_under_sphere(order: usize, v: VerifyParams) -> Result<Check, BakeError> {
    let (radius, height) = (0.5f32, 1.0f32);
    let mut mesh = shapes::plane_grid(64, 4.0);
    let mut sphere = shapes::icosphere(4);
    shapes::transform(&mut sphere, radius, Vec3::new(0.0, height, 0.0));
    shapes::append(&mut mesh, &sphere);
    let plane_vertices = 65 * 65;
    let params = BakeParams { order, rays: v.rays, seed: v.seed, ..BakeParams::default() };
    let (result, _, _) = bake_mesh(&mesh, &params, &[])?;
    // The polygonal sphere's silhouette lies between its vertex and face radii: use the mean.
    let effective_radius = radius as f64 * (1.0 + (1.0 - 0.001)) / 2.0;
    let centre = DVec3::new(0.0, height as f64, 0.0);
    let mut errors = Vec::new();
    let mut dc_errors = Vec::new();
    for i in 0..plane_vertices {
        let x = mesh.positions[i].as_dvec3();
        let to_centre = centre - x;
        let alpha = (effective_radius / to_centre.length()).asin();
        let beta = (to_centre.normalize().dot(DVec3::Y)).acos();
        if alpha + beta > (88.0f64).to_radians() {
            continue;
        }
        let reference = plane_point_reference(order, x, centre, effective_radius);
        // The closed form for DC, as a check on the quadrature itself.
        let dc_closed = Y00 * (1.0 - alpha.sin().powi(2) * beta.cos());
        debug_assert!((reference[0] - dc_closed).abs() < 1e-4);
        let got = result.coefficients(i, 0);
        dc_errors.push(got[0] as f64 - dc_closed);
        errors.push((0..reference.len()).map(|k| got[k] as f64 - reference[k]).collect::<Vec<_>>());
    }
    let bands = band_errors(order, &errors);
    let dc_max = dc_errors.iter().fold(0.0f64, |m, e| m.max(e.abs()));
    // DC tolerance 2e-3 (spine issue); other bands 5e-3 max, RMS 1.5e-3 at 1,024 rays.
    let (max_tolerance, rms_tolerance) = (5e-3, 1.5e-3);
    let passed = passes(&bands, max_tolerance, rms_tolerance) && dc_max <= 2e-3;
    Ok(Check {
        name: "plane-under-sphere".into(),
        detail: format!(
            "{} plane vertices with the occluder wholly above the horizon; DC max error {:.2e} (tolerance 2e-3)",
            errors.len(),
            dc_max
        ),
        bands,
        values: vec![("max |DC error|".into(), dc_max, 0.0, dc_max)],
        max_tolerance,
        rms_tolerance,
        passed,
        rays: result.stats.rays,
        seconds: result.stats.seconds,
    })
}

/// Integrating sphere: DC per bounce b = 0..4 and the total against
/// y_00·f·(ρ(1−f))^b, averaged over the wall vertices, within 1%.
pub fn integrating_sphere(mode: Mode, cap_height: f32, albedo: f32, v: VerifyParams) -> Result<Check, BakeError> {
    let opening = if mode == Mode::Window { shapes::Opening::Window } else { shapes::Opening::Hole };
    let (mesh, f) = shapes::integrating_sphere(4, albedo, cap_height, opening);
    let bounces = 4;
    let params = BakeParams { order: 1, rays: v.rays, seed: v.seed, mode, bounces, store_bounces: true, ..BakeParams::default() };
    let (result, surfaces, _) = bake_mesh(&mesh, &params, &[])?;
    // Wall vertices only: a vertex on the opening's rim is shared with window triangles.
    let mut on_wall = vec![true; mesh.vertex_count()];
    for t in 0..mesh.triangle_count() {
        if surfaces.window_transmittance[t].is_some() {
            mesh.triangle(t).iter().for_each(|&i| on_wall[i as usize] = false);
        }
    }
    let wall: Vec<usize> = (0..mesh.vertex_count()).filter(|&i| on_wall[i] && mesh.positions[i].y < cap_height).collect();
    let rho = albedo as f64;
    let mean = |layer: &[f32]| wall.iter().map(|&i| layer[i] as f64).sum::<f64>() / wall.len().max(1) as f64;
    let mut values = Vec::new();
    for (b, layer) in result.bounces.iter().enumerate() {
        let expected = Y00 * f * (rho * (1.0 - f)).powi(b as i32);
        let got = mean(layer);
        values.push((format!("DC bounce {b}"), got, expected, (got - expected).abs() / expected));
    }
    // The bake sums bounces 0..=B: compare with the same partial sum of the series.
    let expected_total: f64 = (0..=bounces).map(|b| Y00 * f * (rho * (1.0 - f)).powi(b as i32)).sum();
    let got_total = mean(&result.total);
    values.push(("DC total".into(), got_total, expected_total, (got_total - expected_total).abs() / expected_total));
    // 1% relative (car-interior issue), for each bounce and the total.
    let tolerance = 0.01;
    let passed = values.iter().all(|(_, _, _, rel)| *rel <= tolerance);
    Ok(Check {
        name: format!("integrating-sphere-{}", if mode == Mode::Window { "window" } else { "hole" }),
        detail: format!("f = {f:.4}, ρ = {albedo}, {} wall vertices, mean DC per bounce", wall.len()),
        bands: Vec::new(),
        values,
        max_tolerance: tolerance,
        rms_tolerance: tolerance,
        passed,
        rays: result.stats.rays,
        seconds: result.stats.seconds,
    })
}

/// A plain-text table of the checks.
pub fn format_table(checks: &[Check]) -> String {
    let mut s = String::new();
    for c in checks {
        s += &format!(
            "{} {}  ({:.1} Mrays, {:.2}s)\n  {}\n",
            if c.passed { "PASS" } else { "FAIL" },
            c.name,
            c.rays as f64 / 1e6,
            c.seconds,
            c.detail
        );
        if !c.bands.is_empty() {
            s += &format!(
                "  {:>4} {:>11} {:>11}   (tolerance max {:.1e}, rms {:.1e})\n",
                "band", "max", "rms", c.max_tolerance, c.rms_tolerance
            );
            for b in &c.bands {
                s += &format!("  {:>4} {:>11.3e} {:>11.3e}\n", b.band, b.max, b.rms);
            }
        }
        for (label, got, expected, rel) in &c.values {
            if *expected != 0.0 {
                s += &format!("  {label:<16} got {got:.6}  expected {expected:.6}  rel {:.3}%\n", rel * 100.0);
            }
        }
    }
    s
}
