//! Clear-sky radiance: the Preetham daylight model.
//!
//! A. J. Preetham, P. Shirley, B. Smits, "A Practical Analytic Model for
//! Daylight", SIGGRAPH 1999, §3 and Appendix A.2. Luminance Y and
//! chromaticity x, y each follow the Perez distribution
//!
//!   F(θ, γ) = (1 + A·e^(B/cos θ)) · (1 + C·e^(D·γ) + E·cos²γ),
//!   Y(θ, γ) = Y_z · F(θ, γ) / F(0, θ_s)      (same for x and y),
//!
//! with θ the view zenith angle, γ the angle to the sun, θ_s the sun's zenith
//! angle, A..E linear in turbidity T, and the zenith values Y_z (kcd/m²),
//! x_z, y_z given by the paper's fits. The fits were made for T in 2..10 and
//! the sun above the horizon. Below the horizon the sky radiance is 0 (the
//! ground is not modelled). The sun disc itself is not part of the sky.

use glam::DVec3;

use super::sun_color::xyz_to_linear_srgb;

/// Turbidity used when none is given: a clear, slightly hazy summer sky.
pub const DEFAULT_TURBIDITY: f64 = 3.0;
/// Range of turbidity over which Preetham's fits hold; inputs are clamped.
pub const TURBIDITY_RANGE: (f64, f64) = (2.0, 10.0);

/// Clamps `turbidity` to [`TURBIDITY_RANGE`]; NaN becomes [`DEFAULT_TURBIDITY`].
pub fn clamp_turbidity(turbidity: f64) -> f64 {
    if turbidity.is_nan() {
        DEFAULT_TURBIDITY
    } else {
        turbidity.clamp(TURBIDITY_RANGE.0, TURBIDITY_RANGE.1)
    }
}

/// Zenith luminance in kcd/m² (Preetham eq. in App. A.2):
/// χ = (4/9 − T/120)(π − 2θ_s), Y_z = (4.0453T − 4.9710)·tan χ − 0.2155T + 2.4192.
pub fn zenith_luminance_kcd(sun_zenith_rad: f64, turbidity: f64) -> f64 {
    let t = turbidity;
    let chi = (4.0 / 9.0 - t / 120.0) * (std::f64::consts::PI - 2.0 * sun_zenith_rad);
    (4.0453 * t - 4.9710) * chi.tan() - 0.2155 * t + 2.4192
}

/// Zenith chromaticity: `[T², T, 1] · M · [θ_s³, θ_s², θ_s, 1]ᵀ` (App. A.2).
fn zenith_chromaticity(matrix: &[[f64; 4]; 3], sun_zenith_rad: f64, turbidity: f64) -> f64 {
    let s = sun_zenith_rad;
    let theta_powers = [s * s * s, s * s, s, 1.0];
    let t_powers = [turbidity * turbidity, turbidity, 1.0];
    matrix.iter().zip(t_powers).map(|(row, tp)| tp * row.iter().zip(theta_powers).map(|(m, th)| m * th).sum::<f64>()).sum()
}

const ZENITH_X: [[f64; 4]; 3] =
    [[0.00166, -0.00375, 0.00209, 0.0], [-0.02903, 0.06377, -0.03202, 0.00394], [0.11693, -0.21196, 0.06052, 0.25886]];
const ZENITH_Y: [[f64; 4]; 3] =
    [[0.00275, -0.00610, 0.00317, 0.0], [-0.04214, 0.08970, -0.04153, 0.00516], [0.15346, -0.26756, 0.06670, 0.26688]];

/// Perez coefficients A..E as `[slope, intercept]` in T (App. A.2).
const PEREZ_LUMINANCE: [[f64; 2]; 5] = [[0.1787, -1.4630], [-0.3554, 0.4275], [-0.0227, 5.3251], [0.1206, -2.5771], [-0.0670, 0.3703]];
const PEREZ_X: [[f64; 2]; 5] = [[-0.0193, -0.2592], [-0.0665, 0.0008], [-0.0004, 0.2125], [-0.0641, -0.8989], [-0.0033, 0.0452]];
const PEREZ_Y: [[f64; 2]; 5] = [[-0.0167, -0.2608], [-0.0950, 0.0092], [-0.0079, 0.2102], [-0.0441, -1.6537], [-0.0109, 0.0529]];

/// One Perez distribution, pre-divided by its value at the zenith.
#[derive(Debug, Clone, Copy)]
struct Perez {
    coefficients: [f64; 5],
    /// zenith value / F(0, θ_s)
    scale: f64,
}

impl Perez {
    fn new(table: &[[f64; 2]; 5], turbidity: f64, zenith_value: f64, sun_zenith_rad: f64) -> Perez {
        let coefficients = table.map(|[slope, intercept]| slope * turbidity + intercept);
        let mut perez = Perez { coefficients, scale: 1.0 };
        perez.scale = zenith_value / perez.distribution(1.0, sun_zenith_rad, sun_zenith_rad.cos());
        perez
    }

    /// F(θ, γ) from cos θ (> 0), γ and cos γ.
    fn distribution(&self, cos_theta: f64, gamma: f64, cos_gamma: f64) -> f64 {
        let [a, b, c, d, e] = self.coefficients;
        (1.0 + a * (b / cos_theta).exp()) * (1.0 + c * (d * gamma).exp() + e * cos_gamma * cos_gamma)
    }

    fn value(&self, cos_theta: f64, gamma: f64, cos_gamma: f64) -> f64 {
        self.scale * self.distribution(cos_theta, gamma, cos_gamma)
    }
}

/// A clear sky for one sun position, ready to evaluate.
#[derive(Debug, Clone, Copy)]
pub struct PreethamSky {
    up: DVec3,
    sun: DVec3,
    luminance: Perez,
    chroma_x: Perez,
    chroma_y: Perez,
}

impl PreethamSky {
    /// Builds the sky for unit-able `sun_dir` and `up` (world frame).
    ///
    /// Returns `None` at night (sun at or below the horizon, `sun·up ≤ 0`)
    /// or when either vector is zero or not finite. `turbidity` is clamped
    /// with [`clamp_turbidity`].
    pub fn new(sun_dir: DVec3, up: DVec3, turbidity: f64) -> Option<PreethamSky> {
        let sun = sun_dir.try_normalize()?;
        let up = up.try_normalize()?;
        let cos_sun_zenith = sun.dot(up);
        if cos_sun_zenith <= 0.0 {
            return None;
        }
        let t = clamp_turbidity(turbidity);
        let theta_s = cos_sun_zenith.min(1.0).acos();
        Some(PreethamSky {
            up,
            sun,
            luminance: Perez::new(&PEREZ_LUMINANCE, t, zenith_luminance_kcd(theta_s, t) * 1000.0, theta_s),
            chroma_x: Perez::new(&PEREZ_X, t, zenith_chromaticity(&ZENITH_X, theta_s, t), theta_s),
            chroma_y: Perez::new(&PEREZ_Y, t, zenith_chromaticity(&ZENITH_Y, theta_s, t), theta_s),
        })
    }

    /// The three Perez distributions (luminance Y, chromaticity x, chromaticity
    /// y) as `[A, B, C, D, E, s]` with value `s · F(θ, γ)`: what the viewer's
    /// sky shader evaluates per pixel.
    pub fn perez_parameters(&self) -> [[f64; 6]; 3] {
        [self.luminance, self.chroma_x, self.chroma_y].map(|p| {
            let [a, b, c, d, e] = p.coefficients;
            [a, b, c, d, e, p.scale]
        })
    }

    /// Unit zenith and unit direction toward the sun.
    pub fn frame(&self) -> (DVec3, DVec3) {
        (self.up, self.sun)
    }

    /// Sky luminance Y (cd/m²) and chromaticity x, y seen along unit `dir`;
    /// `None` at or below the horizon.
    pub fn luminance_xy(&self, dir: DVec3) -> Option<[f64; 3]> {
        let cos_theta = dir.dot(self.up);
        if cos_theta.is_nan() || cos_theta <= 0.0 {
            return None;
        }
        let cos_gamma = dir.dot(self.sun).clamp(-1.0, 1.0);
        let gamma = cos_gamma.acos();
        Some([
            self.luminance.value(cos_theta, gamma, cos_gamma),
            self.chroma_x.value(cos_theta, gamma, cos_gamma),
            self.chroma_y.value(cos_theta, gamma, cos_gamma),
        ])
    }

    /// Sky radiance along unit `dir` in linear sRGB with Y in cd/m²; zero at
    /// or below the horizon. Out-of-gamut channels are clamped to 0.
    pub fn radiance_rgb(&self, dir: DVec3) -> [f64; 3] {
        let Some([luminance, x, y]) = self.luminance_xy(dir) else {
            return [0.0; 3];
        };
        // NaN fails both tests and lands here too.
        if y.is_nan() || luminance.is_nan() || y <= 0.0 || luminance <= 0.0 {
            return [0.0; 3];
        }
        let xyz = [x / y * luminance, luminance, (1.0 - x - y).max(0.0) / y * luminance];
        xyz_to_linear_srgb(xyz).map(|c| c.max(0.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Preetham 1999 App. A.2 zenith luminance, evaluated by hand (Python) at
    /// θ_s = 30°: T = 2 → 5.8867, 3 → 10.4131, 6 → 22.0667, 10 → 33.7397 kcd/m².
    /// It grows with turbidity for a sun this high.
    #[test]
    fn zenith_luminance_follows_the_paper_and_grows_with_turbidity() {
        let theta = 30f64.to_radians();
        for (t, expected) in [(2.0, 5.886_743), (3.0, 10.413_087), (6.0, 22.066_708), (10.0, 33.739_740)] {
            assert!((zenith_luminance_kcd(theta, t) - expected).abs() < 1e-5, "T={t}");
        }
        let mut previous = f64::NEG_INFINITY;
        for step in 0..=16 {
            let value = zenith_luminance_kcd(theta, 2.0 + 0.5 * f64::from(step));
            assert!(value > previous);
            previous = value;
        }
        // At the zenith the Perez ratio is 1: the model returns Y_z itself.
        let sky = PreethamSky::new(DVec3::new(0.5, 3f64.sqrt() / 2.0, 0.0), DVec3::Y, 3.0);
        let zenith = sky.and_then(|s| s.luminance_xy(DVec3::Y)).map(|v| v[0]);
        assert!(zenith.is_some_and(|y| (y - 10_413.087).abs() < 0.01), "{zenith:?}");
    }

    /// Zenith chromaticity at T = 3, θ_s = 30° is near the daylight locus
    /// (x ≈ 0.27–0.31, y ≈ 0.28–0.33 for clear skies).
    #[test]
    fn zenith_chromaticity_is_bluish_white() {
        let theta = 30f64.to_radians();
        let x = zenith_chromaticity(&ZENITH_X, theta, 3.0);
        let y = zenith_chromaticity(&ZENITH_Y, theta, 3.0);
        assert!((0.24..0.31).contains(&x) && (0.25..0.33).contains(&y), "{x} {y}");
        assert!(x < 0.3127, "bluer than D65 white");
    }

    #[test]
    fn radiance_is_zero_below_the_horizon_and_positive_above() {
        let sun = DVec3::new(0.3, 0.5, -0.8);
        let sky = PreethamSky::new(sun, DVec3::Y, 3.0);
        let Some(sky) = sky else { panic!("sun above horizon gave no sky") };
        for dir in [DVec3::NEG_Y, DVec3::new(1.0, -0.01, 0.0).normalize(), DVec3::X] {
            assert_eq!(sky.radiance_rgb(dir), [0.0; 3], "{dir}");
        }
        for dir in [DVec3::Y, DVec3::new(1.0, 0.01, 0.0).normalize(), sun.normalize()] {
            let rgb = sky.radiance_rgb(dir);
            assert!(rgb.iter().all(|&c| c > 0.0 && c.is_finite()), "{dir}: {rgb:?}");
        }
        // Brighter near the sun than opposite it, at equal height.
        let toward = sky.radiance_rgb(DVec3::new(0.3, 0.5, -0.8).normalize())[1];
        let away = sky.radiance_rgb(DVec3::new(-0.3, 0.5, 0.8).normalize())[1];
        assert!(toward > away);
    }

    #[test]
    fn night_and_bad_vectors_give_no_sky() {
        assert!(PreethamSky::new(DVec3::new(0.0, -0.1, 1.0), DVec3::Y, 3.0).is_none());
        assert!(PreethamSky::new(DVec3::new(1.0, 0.0, 0.0), DVec3::Y, 3.0).is_none());
        assert!(PreethamSky::new(DVec3::ZERO, DVec3::Y, 3.0).is_none());
        assert!(PreethamSky::new(DVec3::NAN, DVec3::Y, 3.0).is_none());
        assert_eq!(clamp_turbidity(f64::NAN), DEFAULT_TURBIDITY);
        assert_eq!(clamp_turbidity(50.0), 10.0);
    }
}
