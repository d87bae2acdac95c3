//! The sampling lobe of a MERL BRDF: a GGX roughness and a mixture weight
//! fitted to the data. Only the variance depends on the fit (the cosine part
//! of the mixture keeps the estimator unbiased), so a cheap fit suffices.

use super::microfacet::ggx_d;
use glam::Vec3;

/// The GGX lobe a MERL BRDF is sampled with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FittedLobe {
    /// GGX roughness of the lobe.
    pub alpha: f32,
    /// Probability of drawing from the lobe rather than the cosine, in [0.1, 0.9].
    pub specular_probability: f32,
}

/// Fits the near-normal-incidence profile `g(θ_h)` (luminance averaged over
/// θ_d < 10° and all φ_d): its floor (minimum over θ_h in 40°–75°) is the
/// diffuse part, the rest is matched by `c · D_GGX(θ_h; α)` in least squares
/// weighted by solid angle (`sin θ_h cos θ_h dθ_h`), over 64 roughnesses
/// from 0.01 to 1. The mixture weight is the lobe's share of the albedo at
/// normal incidence, clamped to [0.1, 0.9] so neither strategy starves.
pub(crate) fn fit_lobe(values: &[[f32; 3]]) -> FittedLobe {
    let theta_h: Vec<f64> = (0..90).map(|i| f64::from(super::merl_grid::cell_centre(i, 0, 0).0)).collect();
    let width: Vec<f64> = (0..90).map(|i| ((i + 1) * (i + 1) - i * i) as f64 / 8100.0 * std::f64::consts::FRAC_PI_2).collect();
    let profile: Vec<f64> = (0..90)
        .map(|h| {
            let slice = &values[h * 90 * 180..(h * 90 + 10) * 180];
            slice.iter().map(|v| v.iter().map(|&x| f64::from(x)).sum::<f64>() / 3.0).sum::<f64>() / slice.len() as f64
        })
        .collect();
    let floor =
        (0..90).filter(|&i| (40.0..=75.0).contains(&theta_h[i].to_degrees())).map(|i| profile[i]).fold(f64::INFINITY, f64::min).max(0.0);
    let excess: Vec<f64> = profile.iter().map(|&g| (g - floor).max(0.0)).collect();
    let weight: Vec<f64> = (0..90).map(|i| theta_h[i].sin() * theta_h[i].cos() * width[i]).collect();
    let ggx = |alpha: f32, i: usize| f64::from(ggx_d(Vec3::new(theta_h[i].sin() as f32, 0.0, theta_h[i].cos() as f32), alpha));
    let mut best = (f64::INFINITY, 1.0f32);
    for k in 0..64 {
        let alpha = (0.01f64 * 100f64.powf(k as f64 / 63.0)) as f32;
        let (sd, dd) =
            (0..90).fold((0.0, 0.0), |(sd, dd), i| (sd + weight[i] * excess[i] * ggx(alpha, i), dd + weight[i] * ggx(alpha, i).powi(2)));
        let scale = if dd > 0.0 { sd / dd } else { 0.0 };
        let error: f64 = (0..90).map(|i| weight[i] * (excess[i] - scale * ggx(alpha, i)).powi(2)).sum();
        if error < best.0 {
            best = (error, alpha);
        }
    }
    // Albedo at normal incidence: θ_i = 2θ_h and dω_i = 4 cos θ_h dω_h.
    let lobe_albedo: f64 = (0..90)
        .filter(|&i| theta_h[i] < std::f64::consts::FRAC_PI_4)
        .map(|i| excess[i] * (2.0 * theta_h[i]).cos() * 4.0 * theta_h[i].cos() * std::f64::consts::TAU * theta_h[i].sin() * width[i])
        .sum();
    let diffuse_albedo = std::f64::consts::PI * floor;
    let share = if lobe_albedo + diffuse_albedo > 0.0 { lobe_albedo / (lobe_albedo + diffuse_albedo) } else { 0.5 };
    FittedLobe { alpha: best.1, specular_probability: (share as f32).clamp(0.1, 0.9) }
}
