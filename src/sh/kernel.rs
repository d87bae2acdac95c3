//! Zonal kernels applied per band: the clamped cosine Â_l (irradiance from
//! radiance, R. Ramamoorthi & P. Hanrahan, "An Efficient Representation for
//! Irradiance Environment Maps", SIGGRAPH 2001) and the ringing windows of
//! P.-P. Sloan, "Stupid Spherical Harmonics (SH) Tricks", GDC 2008.

use std::f64::consts::PI;

use super::basis::coeff_count;

/// Â_l: the SH coefficient of the clamped cosine `max(cos θ, 0)` in the
/// Funk–Hecke sense, so that irradiance is `E_lm = Â_l · L_lm`.
///
/// Â_0 = π, Â_1 = 2π/3, Â_l = 0 for odd l > 1, and for even l
/// Â_l = 2π(−1)^(l/2−1) / ((l+2)(l−1)) · l! / (2^l ((l/2)!)²).
/// The factor l!/(2^l((l/2)!)²) = C(l, l/2)/2^l is built as a running
/// product of (2k−1)/(2k), so nothing overflows at any l.
pub fn clamped_cosine_kernel(l: usize) -> f64 {
    match l {
        0 => PI,
        1 => 2.0 * PI / 3.0,
        _ if l % 2 == 1 => 0.0,
        _ => {
            let half = l / 2;
            let central_binomial_over_pow2: f64 = (1..=half).map(|k| (2 * k - 1) as f64 / (2 * k) as f64).product();
            let sign = if half % 2 == 1 { 1.0 } else { -1.0 }; // (−1)^(l/2−1)
            let lf = l as f64;
            2.0 * PI * sign / ((lf + 2.0) * (lf - 1.0)) * central_binomial_over_pow2
        }
    }
}

/// Turns radiance coefficients into irradiance coefficients in place:
/// band l of `coeffs[0..order²]` is multiplied by Â_l. Evaluating the result
/// at a normal n gives `E(n) = ∫ L(ω) max(n·ω, 0) dω`; divide by π for the
/// outgoing radiance of a white Lambertian surface.
///
/// # Panics
/// If `coeffs.len() < order²`.
pub fn convolve_clamped_cosine(coeffs: &mut [f32], order: usize) {
    let n = coeff_count(order);
    assert!(coeffs.len() >= n, "convolve_clamped_cosine: {} coefficients, order {order} needs {n}", coeffs.len());
    scale_bands(coeffs, 1, order, |l| clamped_cosine_kernel(l) as f32);
}

/// [`convolve_clamped_cosine`] for RGB coefficients.
///
/// # Panics
/// If `coeffs.len() < order²`.
pub fn convolve_clamped_cosine_rgb(coeffs: &mut [[f32; 3]], order: usize) {
    let n = coeff_count(order);
    assert!(coeffs.len() >= n, "convolve_clamped_cosine_rgb: {} coefficients, order {order} needs {n}", coeffs.len());
    scale_bands(coeffs.as_flattened_mut(), 3, order, |l| clamped_cosine_kernel(l) as f32);
}

/// A per-band window that trades sharpness for less ringing (negative lobes)
/// in truncated SH expansions. `width` is in bands: weights fall to 0 at
/// `l = width`, so `width = order` keeps every band of the expansion
/// partially. A `width` that is not > 0 (including NaN) keeps DC only, the
/// limit as width → 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Window {
    /// All weights 1.
    None,
    /// `w_l = (1 + cos(π l / width)) / 2` for `l < width`, else 0.
    Hanning { width: f32 },
    /// `w_l = sin(π l / width) / (π l / width)` for `0 < l < width`, `w_0 = 1`, else 0.
    Lanczos { width: f32 },
}

/// Per-band weights `w_0 .. w_{order−1}` of `window`.
pub fn window_weights(order: usize, window: Window) -> Vec<f32> {
    (0..order).map(|l| window_weight(l, window)).collect()
}

fn window_weight(l: usize, window: Window) -> f32 {
    let (width, shape): (f32, fn(f64) -> f64) = match window {
        Window::None => return 1.0,
        Window::Hanning { width } => (width, |t| 0.5 * (1.0 + (PI * t).cos())),
        Window::Lanczos { width } => (width, |t| if t == 0.0 { 1.0 } else { (PI * t).sin() / (PI * t) }),
    };
    if l == 0 {
        return 1.0;
    }
    if width.is_nan() || width <= 0.0 {
        return 0.0;
    }
    let t = l as f64 / f64::from(width);
    if t >= 1.0 {
        0.0
    } else {
        shape(t) as f32
    }
}

/// Multiplies band l of every channel by the window weight w_l.
///
/// Layout: interleaved `[coeff][channel]`, i.e. `coeffs[i·channels + c]`, so
/// a `Vec<[f32; 3]>` from [`super::project_equirect`] is passed as
/// `v.as_flattened_mut()` with `channels = 3`.
///
/// # Panics
/// If `coeffs.len() < channels · order²`.
pub fn apply_window(coeffs: &mut [f32], channels: usize, order: usize, window: Window) {
    let n = channels * coeff_count(order);
    assert!(coeffs.len() >= n, "apply_window: {} values, {channels} channels of order {order} need {n}", coeffs.len());
    let weights = window_weights(order, window);
    scale_bands(coeffs, channels, order, |l| weights[l]);
}

/// Multiplies band l of an interleaved `[coeff][channel]` buffer by `weight(l)`.
fn scale_bands(coeffs: &mut [f32], channels: usize, order: usize, weight: impl Fn(usize) -> f32) {
    for l in 0..order {
        let w = weight(l);
        let band = channels * l * l..channels * (l + 1) * (l + 1);
        for c in &mut coeffs[band] {
            *c *= w;
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::{DVec3, Vec3};

    use super::*;
    use crate::sh::basis::{eval_basis_f64, evaluate, sh_index};
    use crate::sh::quadrature::gauss_legendre;

    /// Closed forms are evaluated in f64 with a few operations: 1e-12.
    const CLOSED_FORM_TOL: f64 = 1e-12;

    fn legendre(l: usize, x: f64) -> f64 {
        let (mut p0, mut p1) = (1.0, x);
        if l == 0 {
            return 1.0;
        }
        for j in 2..=l {
            let jf = j as f64;
            let p2 = ((2.0 * jf - 1.0) * x * p1 - (jf - 1.0) * p0) / jf;
            p0 = p1;
            p1 = p2;
        }
        p1
    }

    #[test]
    fn kernel_matches_closed_forms() {
        let expected = [PI, 2.0 * PI / 3.0, PI / 4.0, 0.0, -PI / 24.0, 0.0, PI / 64.0, 0.0, -PI / 128.0];
        for (l, e) in expected.iter().enumerate() {
            assert!((clamped_cosine_kernel(l) - e).abs() < CLOSED_FORM_TOL, "Â_{l} = {}", clamped_cosine_kernel(l));
        }
        // Large l: finite, alternating sign on even bands, shrinking ~ l^(−5/2).
        for l in (4..200).step_by(2) {
            let (a, b) = (clamped_cosine_kernel(l), clamped_cosine_kernel(l + 2));
            assert!(a.is_finite() && a * b < 0.0 && b.abs() < a.abs());
        }
    }

    /// Funk–Hecke: Σ_l Â_l (2l+1)/(4π) P_l(cos θ) → max(cos θ, 0).
    /// Truncated at order 16 the error is largest at the kink θ = 90°,
    /// where the tail Σ_{l≥16} of terms ~ l^(−2) is ≈ 1/(2π·16) ≈ 1e-2; away from
    /// the kink (|cos θ| > 0.3) the oscillating tail is ≈ 7e-3.
    #[test]
    fn kernel_series_reproduces_clamped_cosine_at_order_16() {
        const KINK_TOL: f64 = 3e-2;
        const SMOOTH_TOL: f64 = 1e-2;
        let mut worst_kink = 0.0_f64;
        let mut worst_smooth = 0.0_f64;
        for k in 0..=180 {
            let c = (k as f64).to_radians().cos();
            let series: f64 = (0..16).map(|l| clamped_cosine_kernel(l) * (2 * l + 1) as f64 / (4.0 * PI) * legendre(l, c)).sum();
            let err = (series - c.max(0.0)).abs();
            if c.abs() > 0.3 {
                worst_smooth = worst_smooth.max(err);
            } else {
                worst_kink = worst_kink.max(err);
            }
        }
        eprintln!("clamped cosine series, order 16: max error {worst_kink:.2e} near 90°, {worst_smooth:.2e} elsewhere");
        assert!(worst_kink < KINK_TOL && worst_smooth < SMOOTH_TOL);
    }

    /// Convolution against brute-force irradiance ∫ L max(n·ω,0) dω of a
    /// band-limited radiance. The kink of max(·,0) limits the quadrature to
    /// O(1/N²) ≈ 1e-5 at N = 300 nodes; 1e-4 absolute on E of size ~3.
    #[test]
    fn convolution_matches_brute_force_irradiance() {
        const IRRADIANCE_TOL: f64 = 1e-4;
        let order = 4;
        let radiance: Vec<f32> = (0..coeff_count(order)).map(|i| if i == 0 { 1.0 } else { 0.3 * ((i * 7) as f32).sin() }).collect();
        let mut irradiance = radiance.clone();
        convolve_clamped_cosine(&mut irradiance, order);
        let (nodes, weights) = gauss_legendre(300);
        let n_phi = 600;
        let mut y = vec![0.0_f64; coeff_count(order)];
        for normal in [DVec3::Z, DVec3::new(1.0, 2.0, -0.5).normalize(), -DVec3::X] {
            let mut e = 0.0;
            // Quadrature in a frame whose pole is the normal, so the kink sits on a node ring.
            let (t, b) = normal.any_orthonormal_pair();
            for (&z, &w) in nodes.iter().zip(&weights) {
                if z <= 0.0 {
                    continue;
                }
                let r = (1.0 - z * z).sqrt();
                for k in 0..n_phi {
                    let phi = 2.0 * PI * (k as f64 + 0.5) / n_phi as f64;
                    let dir = t * (r * phi.cos()) + b * (r * phi.sin()) + normal * z;
                    eval_basis_f64(order, dir, &mut y);
                    let l: f64 = radiance.iter().zip(&y).map(|(c, y)| f64::from(*c) * y).sum();
                    e += w * 2.0 * PI / n_phi as f64 * l * z;
                }
            }
            let got = f64::from(evaluate(&irradiance, order, normal.as_vec3()));
            assert!((got - e).abs() < IRRADIANCE_TOL, "normal {normal}: SH {got} vs brute force {e}");
        }
    }

    #[test]
    fn window_weights_have_their_shapes() {
        assert_eq!(window_weights(4, Window::None), vec![1.0; 4]);
        let h = window_weights(5, Window::Hanning { width: 4.0 });
        let expected = [1.0, 0.853_553_4, 0.5, 0.146_446_6, 0.0];
        for (a, b) in h.iter().zip(expected) {
            assert!((a - b).abs() < 1e-6);
        }
        let lz = window_weights(3, Window::Lanczos { width: 2.0 });
        assert!((lz[0] - 1.0).abs() < 1e-7 && (lz[1] - 2.0 / std::f32::consts::PI).abs() < 1e-6 && lz[2] == 0.0);
        // Degenerate widths keep DC only instead of dividing by zero.
        for width in [0.0, -1.0, f32::NAN] {
            assert_eq!(window_weights(3, Window::Hanning { width }), vec![1.0, 0.0, 0.0]);
        }
        let mut interleaved = vec![1.0_f32; 2 * 9];
        apply_window(&mut interleaved, 2, 3, Window::Hanning { width: 4.0 });
        assert_eq!(interleaved[0..2], [1.0, 1.0]);
        assert!((interleaved[2 * 3 + 1] - 0.853_553_4).abs() < 1e-6);
        assert!((interleaved[2 * 8] - 0.5).abs() < 1e-6);
    }

    /// Zonal coefficients of the indicator of a cap of half-angle α around +Z:
    /// c_l0 = 2π N_l ∫_{cos α}^1 P_l = 2π N_l (P_{l−1}(cos α) − P_{l+1}(cos α))/(2l+1).
    fn cap_coefficients(order: usize, alpha: f64) -> Vec<f32> {
        let ca = alpha.cos();
        let mut c = vec![0.0_f32; coeff_count(order)];
        for l in 0..order {
            let norm = ((2 * l + 1) as f64 / (4.0 * PI)).sqrt();
            let integral = if l == 0 { 1.0 - ca } else { (legendre(l - 1, ca) - legendre(l + 1, ca)) / (2 * l + 1) as f64 };
            c[sh_index(l, 0)] = (2.0 * PI * norm * integral) as f32;
        }
        c
    }

    /// A 5° bright cap at order 8 rings: the reconstruction dips below zero
    /// away from the cap. The Hanning window must pull that minimum toward 0.
    #[test]
    fn hanning_window_reduces_ringing_of_small_cap() {
        let order = 8;
        let alpha = 5f64.to_radians();
        let raw = cap_coefficients(order, alpha);
        // The closed form agrees with a fine 1-D midpoint integral over the cap.
        for l in 0..order {
            let norm = ((2 * l + 1) as f64 / (4.0 * PI)).sqrt();
            let steps = 10_000;
            let dt = alpha / steps as f64;
            let integral: f64 = (0..steps).map(|k| (k as f64 + 0.5) * dt).map(|t| legendre(l, t.cos()) * t.sin() * dt).sum();
            assert!((f64::from(raw[sh_index(l, 0)]) - 2.0 * PI * norm * integral).abs() < 1e-7);
        }
        let mut windowed = raw.clone();
        apply_window(&mut windowed, 1, order, Window::Hanning { width: order as f32 });
        let min_over_sphere = |c: &[f32]| {
            (0..=1800)
                .map(|k| {
                    let theta = (k as f32 / 10.0).to_radians();
                    evaluate(c, order, Vec3::new(theta.sin(), 0.0, theta.cos()))
                })
                .fold(f32::INFINITY, f32::min)
        };
        let (min_raw, min_windowed) = (min_over_sphere(&raw), min_over_sphere(&windowed));
        let peak_raw = evaluate(&raw, order, Vec3::Z);
        eprintln!("5° cap, order 8: min {min_raw:.3e} raw, {min_windowed:.3e} Hanning(w=8); peak {peak_raw:.3e}");
        assert!(min_raw < 0.0, "the raw expansion should ring");
        assert!(min_windowed.abs() < min_raw.abs(), "windowing must bring the minimum closer to 0");
    }
}
