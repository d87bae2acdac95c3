//! The checks every BRDF's tests run: Monte Carlo albedo against quadrature,
//! the density against the samples, and the uniform numbers they use.

use super::frame::from_mu_phi;
use super::{albedo_quadrature, pdf_quadrature, AntiGlare, Brdf};
use crate::sampling::hash_seed;
use glam::Vec3;
use std::f64::consts::TAU;

/// Outgoing polar angles the checks visit (21° and 45° fall between 2° table rows).
pub const THETA_OUT_DEG: [f32; 5] = [0.0, 21.0, 45.0, 65.0, 80.0];

/// Samples per Monte Carlo estimate.
pub const MC_SAMPLES: u32 = 1 << 16;

/// Independent uniform numbers in [0,1)² (a hash, so σ is a true standard error).
pub fn uniform_pair(seed: u32, index: u32) -> [f32; 2] {
    let unit = |x: u32| (x >> 8) as f32 * (1.0 / (1u32 << 24) as f32);
    [unit(hash_seed(&[seed, index, 0])), unit(hash_seed(&[seed, index, 1]))]
}

/// The eye direction at polar angle `deg`, at an azimuth off the axes.
pub fn wo_at(deg: f32) -> Vec3 {
    super::frame::from_spherical(deg.to_radians(), 0.7)
}

/// The analytic coating with distinct channels, so a swapped channel shows.
pub fn tinted_coating() -> AntiGlare {
    AntiGlare::new([0.02, 0.03, 0.045], 0.2, 1.5).unwrap()
}

/// Mean and standard error of `f cos θi / pdf` over `n` samples (lost samples count 0).
pub struct McEstimate {
    pub mean: [f64; 3],
    pub sigma: [f64; 3],
    pub lost: u32,
}

pub fn mc_albedo(brdf: &dyn Brdf, wo: Vec3, n: u32, seed: u32) -> McEstimate {
    let (mut sum, mut sum2, mut lost) = ([0.0f64; 3], [0.0f64; 3], 0);
    for i in 0..n {
        let Some(s) = brdf.sample(wo, uniform_pair(seed, i)) else {
            lost += 1;
            continue;
        };
        let f = brdf.eval(s.wi, wo);
        for c in 0..3 {
            let x = f64::from(f[c]) * f64::from(s.wi.z) / f64::from(s.pdf);
            sum[c] += x;
            sum2[c] += x * x;
        }
    }
    let n = f64::from(n);
    let mean = sum.map(|s| s / n);
    let sigma = std::array::from_fn(|c| ((sum2[c] / n - mean[c] * mean[c]).max(0.0) / (n - 1.0)).sqrt());
    McEstimate { mean, sigma, lost }
}

/// (a) For each θ_out, the Monte Carlo albedo matches a 512 × 1024 quadrature
/// within 4σ plus the quadrature's own error (its change from 256 × 512).
pub fn check_unbiased(name: &str, brdf: &dyn Brdf, theta_out_deg: &[f32]) {
    for (k, &deg) in theta_out_deg.iter().enumerate() {
        let wo = wo_at(deg);
        let mc = mc_albedo(brdf, wo, MC_SAMPLES, 1000 + k as u32);
        let fine = albedo_quadrature(brdf, wo, 512, 1024);
        let coarse = albedo_quadrature(brdf, wo, 256, 512);
        for c in 0..3 {
            let quadrature_error = (fine[c] - coarse[c]).abs();
            let tolerance = 4.0 * mc.sigma[c] + quadrature_error + 1e-7;
            let gap = mc.mean[c] - fine[c];
            if c == 1 {
                println!(
                    "{name} theta_out {deg:>4}: MC {:.5} ± {:.5} (σ), quadrature {:.5} (±{:.1e}), gap {:+.2}σ, lost {}",
                    mc.mean[c],
                    mc.sigma[c],
                    fine[c],
                    quadrature_error,
                    gap / mc.sigma[c].max(1e-30),
                    mc.lost
                );
            }
            assert!(
                gap.abs() <= tolerance,
                "{name} theta_out {deg} channel {c}: MC {} vs quadrature {} (σ {}, tolerance {tolerance})",
                mc.mean[c],
                fine[c],
                mc.sigma[c]
            );
        }
    }
}

/// (b) The density integrates to at most 1 (to `expect_total` when given),
/// every sample's returned pdf is `pdf(wo, wi)`, and the samples fall into a
/// 16 × 24 grid of (cos θ, φ) bins as often as the density says (χ² test,
/// the lost samples as one more bin).
pub fn check_pdf(name: &str, brdf: &dyn Brdf, theta_out_deg: &[f32], expect_total: Option<f64>) {
    const BINS_MU: usize = 16;
    const BINS_PHI: usize = 24;
    const SUB: usize = 12;
    for (k, &deg) in theta_out_deg.iter().enumerate() {
        let wo = wo_at(deg);
        let total = pdf_quadrature(brdf, wo, 512, 1024);
        assert!(total <= 1.0 + 2e-3, "{name} theta_out {deg}: pdf integrates to {total}");
        if let Some(expected) = expect_total {
            assert!((total - expected).abs() < 2e-3, "{name} theta_out {deg}: pdf integrates to {total}, expected {expected}");
        }
        // Expected share of each bin, by a SUB × SUB midpoint rule inside it.
        let mut expected = vec![0.0f64; BINS_MU * BINS_PHI];
        let cell = (1.0 / (BINS_MU * SUB) as f64) * (TAU / (BINS_PHI * SUB) as f64);
        for m in 0..BINS_MU * SUB {
            let mu = ((m as f64 + 0.5) / (BINS_MU * SUB) as f64) as f32;
            for p in 0..BINS_PHI * SUB {
                let phi = ((p as f64 + 0.5) * TAU / (BINS_PHI * SUB) as f64) as f32;
                expected[(m / SUB) * BINS_PHI + p / SUB] += f64::from(brdf.pdf(wo, from_mu_phi(mu, phi))) * cell;
            }
        }
        let mut observed = vec![0u32; BINS_MU * BINS_PHI];
        let mut lost = 0u32;
        for i in 0..MC_SAMPLES {
            let Some(s) = brdf.sample(wo, uniform_pair(2000 + k as u32, i)) else {
                lost += 1;
                continue;
            };
            assert!(s.wi.z > 0.0 && (s.wi.length() - 1.0).abs() < 1e-4, "{name}: sample {} is not an upper unit direction", s.wi);
            assert!(s.pdf.is_finite() && s.pdf > 0.0, "{name}: sample pdf {}", s.pdf);
            let again = brdf.pdf(wo, s.wi);
            assert!((again - s.pdf).abs() <= 1e-5 * s.pdf, "{name} theta_out {deg}: sample pdf {} but pdf() {again} at {}", s.pdf, s.wi);
            let mu_bin = ((s.wi.z * BINS_MU as f32) as usize).min(BINS_MU - 1);
            let phi = f64::from(s.wi.y.atan2(s.wi.x)).rem_euclid(TAU);
            let phi_bin = ((phi / TAU * BINS_PHI as f64) as usize).min(BINS_PHI - 1);
            observed[mu_bin * BINS_PHI + phi_bin] += 1;
        }
        // χ² over bins expecting at least 20 samples; the rest are pooled, with the lost ones.
        let n = f64::from(MC_SAMPLES);
        let (mut chi2, mut bins) = (0.0f64, 0usize);
        let (mut pooled_expected, mut pooled_observed) = (n * (1.0 - expected.iter().sum::<f64>()).max(0.0), f64::from(lost));
        for (e, &o) in expected.iter().zip(&observed) {
            let e = e * n;
            if e >= 20.0 {
                chi2 += (f64::from(o) - e).powi(2) / e;
                bins += 1;
            } else {
                pooled_expected += e;
                pooled_observed += f64::from(o);
            }
        }
        if pooled_expected >= 20.0 {
            chi2 += (pooled_observed - pooled_expected).powi(2) / pooled_expected;
            bins += 1;
        } else {
            assert!(
                pooled_observed <= pooled_expected + 5.0 * pooled_expected.sqrt() + 10.0,
                "{name}: {pooled_observed} samples where {pooled_expected} expected"
            );
        }
        let dof = bins.saturating_sub(1).max(1) as f64;
        let limit = dof + 5.0 * (2.0 * dof).sqrt();
        println!("{name} theta_out {deg:>4}: ∫pdf = {total:.5}, χ² = {chi2:.1} over {dof} dof (limit {limit:.1}), lost {lost}");
        assert!(chi2 < limit, "{name} theta_out {deg}: samples do not follow pdf(): χ² {chi2} over {dof} dof");
    }
}

/// A text table of `brdf` on a grid with nodes every `step` degrees from
/// `from` to `to` (θ) and over `phi_from..=phi_to` (Δφ), `wo` at azimuth 0.
pub fn table_text(brdf: &dyn Brdf, step: f32, (from, to): (f32, f32), (phi_from, phi_to): (f32, f32)) -> String {
    let nodes = |a: f32, b: f32| -> Vec<f32> { (0..).map(|k| a + step * k as f32).take_while(|&x| x <= b + 1e-3).collect() };
    let (theta, phi) = (nodes(from, to), nodes(phi_from, phi_to));
    let list = |v: &[f32]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(" ");
    let mut text = format!(
        "# synthetic table\nprtbake-brdf 1\ntheta_in_deg {}\ntheta_out_deg {}\ndelta_phi_deg {}\n",
        list(&theta),
        list(&theta),
        list(&phi)
    );
    for &to in &theta {
        for &ti in &theta {
            for &p in &phi {
                let wi = super::frame::from_spherical(ti.to_radians(), p.to_radians());
                let wo = super::frame::from_spherical(to.to_radians(), 0.0);
                let [r, g, b] = brdf.eval(wi, wo);
                text.push_str(&format!("{ti} {to} {p} {r} {g} {b}\n"));
            }
        }
    }
    text
}

/// Writes a MERL file whose raw (unscaled) value of channel `c` at cell
/// `(i_h, i_d, i_φ)` is `raw(c, i_h, i_d, i_φ)`.
pub fn write_merl(path: &std::path::Path, raw: impl Fn(usize, usize, usize, usize) -> f64) {
    let mut bytes = Vec::with_capacity(super::merl::FILE_BYTES);
    for d in [90i32, 90, 180] {
        bytes.extend_from_slice(&d.to_le_bytes());
    }
    for c in 0..3 {
        for h in 0..90 {
            for d in 0..90 {
                for p in 0..180 {
                    bytes.extend_from_slice(&raw(c, h, d, p).to_le_bytes());
                }
            }
        }
    }
    std::fs::write(path, bytes).unwrap();
}

/// A MERL file of `brdf` sampled at the cell centres; configurations with a
/// direction below the surface are written as −1 ("not measured"), as in the database.
pub fn write_merl_of(path: &std::path::Path, brdf: &dyn Brdf) {
    let values: Vec<[f32; 3]> = (0..super::merl::CELLS)
        .map(|cell| {
            let (h, d, p) = super::merl::cell_centre(cell / (90 * 180), cell / 180 % 90, cell % 180);
            let (wi, wo) = super::merl::directions_from_half_diff(h, d, p);
            if wi.z > 0.0 && wo.z > 0.0 {
                brdf.eval(wi, wo)
            } else {
                [-1.0; 3]
            }
        })
        .collect();
    write_merl(path, |c, h, d, p| {
        let v = f64::from(values[(h * 90 + d) * 180 + p][c]);
        if v < 0.0 {
            -1.0
        } else {
            v / super::merl::CHANNEL_SCALE[c]
        }
    });
}
