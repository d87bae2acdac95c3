//! Directional albedo by quadrature, and the energy report a loader's caller
//! prints: measured files are accepted even when they reflect more than they
//! receive, but the report says so.

use super::frame::from_mu_phi;
use super::Brdf;
use glam::Vec3;
use rayon::prelude::*;
use std::f64::consts::TAU;

/// The (cos θ, φ) grid [`Brdf::albedo`] uses: 256 × 512 midpoints, within
/// 1e-4 of a 4× finer grid for the default coating up to θ_out = 80°, 2.5e-3
/// at 89° where the lobe hugs the horizon (tested).
pub const ALBEDO_GRID: (usize, usize) = (256, 512);

/// The outgoing polar angles (degrees) an [`EnergyReport`] visits.
pub const REPORT_THETA_OUT_DEG: [f32; 19] = [0., 5., 10., 15., 20., 25., 30., 35., 40., 45., 50., 55., 60., 65., 70., 75., 80., 85., 89.];

/// Directional albedo `∫ f(wi, wo) cos θi dωi` per RGB channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Albedo {
    pub rgb: [f32; 3],
}

impl Albedo {
    /// The largest channel.
    pub fn max(&self) -> f32 {
        self.rgb[0].max(self.rgb[1]).max(self.rgb[2])
    }

    /// More light out than in: impossible for a passive surface, common in
    /// noisy measurements near grazing angles.
    pub fn exceeds_one(&self) -> bool {
        self.max() > 1.0
    }
}

/// `∫ f(wi, wo) cos θi dωi` by the midpoint rule on `n_mu × n_phi` cells of
/// equal solid angle in (cos θi, φi), summed in f64 in a fixed order.
pub fn albedo_quadrature<B: Brdf + ?Sized>(brdf: &B, wo: Vec3, n_mu: usize, n_phi: usize) -> [f64; 3] {
    let cell = (1.0 / n_mu as f64) * (TAU / n_phi as f64);
    let mut sum = [0.0f64; 3];
    for k in 0..n_mu {
        let mu = ((k as f64 + 0.5) / n_mu as f64) as f32;
        let mut row = [0.0f64; 3];
        for j in 0..n_phi {
            let phi = ((j as f64 + 0.5) * TAU / n_phi as f64) as f32;
            let f = brdf.eval(from_mu_phi(mu, phi), wo);
            for c in 0..3 {
                row[c] += f64::from(f[c]);
            }
        }
        for c in 0..3 {
            sum[c] += row[c] * f64::from(mu) * cell;
        }
    }
    sum
}

/// `∫ pdf(wo, wi) dωi` over the upper hemisphere by the same midpoint rule:
/// at most 1, less when a sampler can lose samples below the surface.
pub fn pdf_quadrature<B: Brdf + ?Sized>(brdf: &B, wo: Vec3, n_mu: usize, n_phi: usize) -> f64 {
    let cell = (1.0 / n_mu as f64) * (TAU / n_phi as f64);
    let mut sum = 0.0f64;
    for k in 0..n_mu {
        let mu = ((k as f64 + 0.5) / n_mu as f64) as f32;
        for j in 0..n_phi {
            let phi = ((j as f64 + 0.5) * TAU / n_phi as f64) as f32;
            sum += f64::from(brdf.pdf(wo, from_mu_phi(mu, phi))) * cell;
        }
    }
    sum
}

/// Albedo over the outgoing angles of [`REPORT_THETA_OUT_DEG`].
#[derive(Clone, Debug, PartialEq)]
pub struct EnergyReport {
    /// `(θ_out in degrees, albedo)` in increasing θ_out.
    pub rows: Vec<(f32, Albedo)>,
}

impl EnergyReport {
    /// Measures `brdf` (isotropic: `wo` in the xz-plane suffices).
    pub fn of<B: Brdf + Sync + ?Sized>(brdf: &B) -> EnergyReport {
        let rows = REPORT_THETA_OUT_DEG
            .par_iter()
            .map(|&deg| {
                let wo = Vec3::new(deg.to_radians().sin(), 0.0, deg.to_radians().cos());
                (deg, brdf.albedo(wo))
            })
            .collect();
        EnergyReport { rows }
    }

    /// The row with the largest albedo channel.
    pub fn worst(&self) -> (f32, Albedo) {
        self.rows.iter().copied().fold((0.0, Albedo { rgb: [0.0; 3] }), |best, row| if row.1.max() > best.1.max() { row } else { best })
    }

    /// A warning for the CLI when some albedo exceeds 1, naming `what` (e.g. the file).
    pub fn warning(&self, what: &str) -> Option<String> {
        let (deg, albedo) = self.worst();
        albedo.exceeds_one().then(|| {
            let [r, g, b] = albedo.rgb;
            format!("{what}: directional albedo reaches {:.3} (RGB {r:.3} {g:.3} {b:.3}) at theta_out {deg} deg: the BRDF reflects more light than it receives", albedo.max())
        })
    }
}
