//! Real orthonormal spherical-harmonic basis, evaluated without trigonometry.
//!
//! Conventions (see docs/conventions.md): real SH **without** the
//! Condon–Shortley phase, polar axis +Z, θ measured from +Z, φ from +X toward
//! +Y; coefficient index `i = l(l+1)+m`; "order n" means bands `l < n`.
//!
//!   y_l0  =      N_l0 P_l(z)
//!   y_lm  = √2 · N_lm P_l^m(z)   · cos(mφ)    (m > 0)
//!   y_l-m = √2 · N_lm P_l^m(z)   · sin(mφ)    (m > 0)
//!
//! With `sin^m θ · cos(mφ) = Re((x+iy)^m)` and `sin^m θ · sin(mφ) = Im((x+iy)^m)`,
//! every basis function is a polynomial in x, y, z. The Legendre part uses
//! the fully normalised, numerically stable recurrence
//!   P̄_l^m = a_lm (z P̄_{l-1}^m − b_lm P̄_{l-2}^m)
//! (e.g. Holmes & Featherstone 2002, J. Geodesy 76), and the azimuthal part
//! the complex power recurrence; this follows the structure of P.-P. Sloan,
//! "Efficient Spherical Harmonic Evaluation", JCGT 2(2), 2013.

use std::f64::consts::PI;
use std::sync::OnceLock;

use glam::{DVec3, Vec3};

/// Highest order whose recurrence tables are precomputed and whose accuracy
/// (basis, rotation, projection) is covered by tests. Higher orders still
/// work (tables are then built per call) but are untested.
pub const MAX_ORDER: usize = 16;

/// Number of coefficients of an SH expansion of the given order: `order²`.
pub const fn coeff_count(order: usize) -> usize {
    order * order
}

/// Flat coefficient index of band `l`, index `m` (`-l ≤ m ≤ l`): `l(l+1)+m`.
///
/// # Panics
/// In debug builds, if `|m| > l`.
pub fn sh_index(l: usize, m: i32) -> usize {
    debug_assert!(m.unsigned_abs() as usize <= l, "sh_index: |m| > l");
    let centre = (l * (l + 1)) as i64;
    (centre + i64::from(m)) as usize
}

/// Band `l` of a flat coefficient index `i` (inverse of [`sh_index`]).
pub fn band_of_index(i: usize) -> usize {
    // l = floor(sqrt(i)); fix up rounding of the float square root.
    let mut l = (i as f64).sqrt() as usize;
    while l * l > i {
        l -= 1;
    }
    while (l + 1) * (l + 1) <= i {
        l += 1;
    }
    l
}

/// Recurrence coefficients for the normalised associated Legendre functions.
struct RecurrenceTable {
    order: usize,
    /// `a_lm`, triangular index `l(l+1)/2 + m`.
    a: Vec<f64>,
    /// `b_lm`, same index.
    b: Vec<f64>,
    /// `P̄_m^m / sin^m θ` = N_mm (2m−1)!!, index m.
    diagonal: Vec<f64>,
}

impl RecurrenceTable {
    fn new(order: usize) -> Self {
        let tri = order * (order + 1) / 2;
        let mut a = vec![0.0; tri];
        let mut b = vec![0.0; tri];
        for l in 0..order {
            for m in 0..=l {
                let idx = l * (l + 1) / 2 + m;
                let (lf, mf) = (l as f64, m as f64);
                if l > m {
                    a[idx] = ((4.0 * lf * lf - 1.0) / (lf * lf - mf * mf)).sqrt();
                    let lp = lf - 1.0;
                    b[idx] = ((lp * lp - mf * mf) / (4.0 * lp * lp - 1.0)).sqrt();
                }
            }
        }
        // N_mm (2m−1)!! obeys d_m = d_{m−1} · sqrt((2m+1)/(2m)), d_0 = 1/sqrt(4π).
        let mut diagonal = Vec::with_capacity(order);
        let mut d = 1.0 / (4.0 * PI).sqrt();
        for m in 0..order {
            if m > 0 {
                let mf = m as f64;
                d *= ((2.0 * mf + 1.0) / (2.0 * mf)).sqrt();
            }
            diagonal.push(d);
        }
        Self { order, a, b, diagonal }
    }
}

fn shared_table() -> &'static RecurrenceTable {
    static TABLE: OnceLock<RecurrenceTable> = OnceLock::new();
    TABLE.get_or_init(|| RecurrenceTable::new(MAX_ORDER))
}

/// Runs the polynomial recurrence and hands every `(index, value)` to `emit`.
#[inline(always)]
fn run_recurrence(table: &RecurrenceTable, order: usize, d: DVec3, mut emit: impl FnMut(usize, f64)) {
    debug_assert!(order <= table.order);
    let (x, y, z) = (d.x, d.y, d.z);
    let sqrt2 = std::f64::consts::SQRT_2;
    // cos_m + i·sin_m = (x + i y)^m, i.e. sin^m θ · (cos mφ + i sin mφ).
    let (mut cos_m, mut sin_m) = (1.0_f64, 0.0_f64);
    for m in 0..order {
        if m > 0 {
            let next_cos = x * cos_m - y * sin_m;
            sin_m = x * sin_m + y * cos_m;
            cos_m = next_cos;
        }
        let (scale_cos, scale_sin) = if m == 0 { (1.0, 0.0) } else { (sqrt2 * cos_m, sqrt2 * sin_m) };
        // Walk up the bands for this m.
        let mut p_prev2 = 0.0;
        let mut p_prev = table.diagonal[m];
        for l in m..order {
            let p = if l == m {
                p_prev
            } else {
                let idx = l * (l + 1) / 2 + m;
                let p = table.a[idx] * (z * p_prev - table.b[idx] * p_prev2);
                p_prev2 = p_prev;
                p_prev = p;
                p
            };
            let centre = l * (l + 1);
            emit(centre + m, p * scale_cos);
            if m > 0 {
                emit(centre - m, p * scale_sin);
            }
        }
    }
}

/// Calls `run_recurrence` with the shared table, or a one-off table for
/// orders above [`MAX_ORDER`].
#[inline(always)]
fn with_recurrence(order: usize, d: DVec3, emit: impl FnMut(usize, f64)) {
    if order <= MAX_ORDER {
        run_recurrence(shared_table(), order, d, emit);
    } else {
        run_recurrence(&RecurrenceTable::new(order), order, d, emit);
    }
}

/// Evaluates all `order²` real SH basis functions at the unit direction `dir`
/// into `out[0..order²]` (index `l(l+1)+m`). Entries past `order²` are left
/// untouched.
///
/// Orders ≤ 4 use hard-coded polynomials; higher orders the normalised
/// recurrence in f64. No trigonometry either way, so this is cheap enough to
/// call per ray. `dir` must be unit length: it is not normalised here, and a
/// non-unit vector gives values of the polynomial extension, not of y_lm.
///
/// # Panics
/// If `out.len() < order²`.
///
/// See also [`eval_basis_f64`] (reference precision), [`evaluate`].
pub fn eval_basis(order: usize, dir: Vec3, out: &mut [f32]) {
    let n = coeff_count(order);
    assert!(out.len() >= n, "eval_basis: out has {} slots, order {order} needs {n}", out.len());
    if order <= 4 {
        eval_basis_low_order(order, dir, &mut out[..n]);
    } else {
        with_recurrence(order, dir.as_dvec3(), |i, v| out[i] = v as f32);
    }
}

/// Evaluates all `order²` real SH basis functions in f64 at the unit
/// direction `dir` into `out[0..order²]`. Same conventions as [`eval_basis`];
/// always uses the general recurrence, so it doubles as its reference.
///
/// # Panics
/// If `out.len() < order²`.
pub fn eval_basis_f64(order: usize, dir: DVec3, out: &mut [f64]) {
    let n = coeff_count(order);
    assert!(out.len() >= n, "eval_basis_f64: out has {} slots, order {order} needs {n}", out.len());
    with_recurrence(order, dir, |i, v| out[i] = v);
}

/// Reconstructs `Σ_i coeffs[i] · y_i(dir)` over the first `order²` coefficients.
///
/// # Panics
/// If `coeffs.len() < order²`.
pub fn evaluate(coeffs: &[f32], order: usize, dir: Vec3) -> f32 {
    let n = coeff_count(order);
    assert!(coeffs.len() >= n, "evaluate: {} coefficients, order {order} needs {n}", coeffs.len());
    if order <= MAX_ORDER {
        let mut basis = [0.0_f32; MAX_ORDER * MAX_ORDER];
        eval_basis(order, dir, &mut basis);
        coeffs[..n].iter().zip(&basis[..n]).map(|(c, y)| c * y).sum()
    } else {
        let mut sum = 0.0_f64;
        with_recurrence(order, dir.as_dvec3(), |i, v| sum += f64::from(coeffs[i]) * v);
        sum as f32
    }
}

/// Reconstructs an RGB expansion `Σ_i coeffs[i] · y_i(dir)` per channel.
///
/// # Panics
/// If `coeffs.len() < order²`.
pub fn evaluate_rgb(coeffs: &[[f32; 3]], order: usize, dir: Vec3) -> [f32; 3] {
    let n = coeff_count(order);
    assert!(coeffs.len() >= n, "evaluate_rgb: {} coefficients, order {order} needs {n}", coeffs.len());
    let mut sum = [0.0_f64; 3];
    with_recurrence(order, dir.as_dvec3(), |i, v| {
        for (s, c) in sum.iter_mut().zip(coeffs[i]) {
            *s += f64::from(c) * v;
        }
    });
    sum.map(|s| s as f32)
}

/// Bands 0..=3 written out (order ≤ 4). `out.len() == order²`.
#[inline]
fn eval_basis_low_order(order: usize, dir: Vec3, out: &mut [f32]) {
    let (x, y, z) = (dir.x, dir.y, dir.z);
    if order == 0 {
        return;
    }
    out[0] = 0.282_094_79;
    if order == 1 {
        return;
    }
    const K1: f32 = 0.488_602_51;
    out[1] = K1 * y;
    out[2] = K1 * z;
    out[3] = K1 * x;
    if order == 2 {
        return;
    }
    let (x2, y2, z2) = (x * x, y * y, z * z);
    const K2A: f32 = 1.092_548_4; // sqrt(15/(4π))
    const K2B: f32 = 0.315_391_57; // sqrt(5/(16π))
    const K2C: f32 = 0.546_274_2; // sqrt(15/(16π))
    out[4] = K2A * x * y;
    out[5] = K2A * y * z;
    out[6] = K2B * (3.0 * z2 - 1.0);
    out[7] = K2A * x * z;
    out[8] = K2C * (x2 - y2);
    if order == 3 {
        return;
    }
    const K3A: f32 = 0.590_043_6; // sqrt(35/(32π))
    const K3B: f32 = 2.890_611_4; // sqrt(105/(4π))
    const K3C: f32 = 0.457_045_8; // sqrt(21/(32π))
    const K3D: f32 = 0.373_176_33; // sqrt(7/(16π))
    const K3E: f32 = 1.445_305_7; // sqrt(105/(16π))
    let five_z2_minus_1 = 5.0 * z2 - 1.0;
    out[9] = K3A * y * (3.0 * x2 - y2);
    out[10] = K3B * x * y * z;
    out[11] = K3C * y * five_z2_minus_1;
    out[12] = K3D * z * (5.0 * z2 - 3.0);
    out[13] = K3C * x * five_z2_minus_1;
    out[14] = K3E * z * (x2 - y2);
    out[15] = K3A * x * (x2 - 3.0 * y2);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// f32 evaluation of values of magnitude ≤ ~1.7 with a handful of
    /// roundings each: a few ulps ≈ 1e-6.
    const CLOSED_FORM_TOL: f64 = 1e-6;
    /// f32 fast path vs f64 recurrence up to order 16: the f32 result is the
    /// f64 value rounded once (or the unrolled polynomial), so ≲ 1e-6; 1e-5
    /// leaves headroom for the input direction itself being f32-rounded.
    const F32_VS_F64_TOL: f64 = 1e-5;
    /// Gauss–Legendre × uniform-φ quadrature is exact for these polynomials;
    /// only f64 rounding over ~2·10⁴ nodes remains.
    const ORTHONORMAL_TOL: f64 = 1e-6;

    fn test_directions() -> Vec<DVec3> {
        let mut dirs = vec![DVec3::X, DVec3::Y, DVec3::Z, -DVec3::X, -DVec3::Y, -DVec3::Z];
        // Deterministic spiral over the sphere.
        let n = 200;
        for k in 0..n {
            let z = 1.0 - (2.0 * k as f64 + 1.0) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = k as f64 * 2.399_963_229_728_653;
            dirs.push(DVec3::new(r * phi.cos(), r * phi.sin(), z));
        }
        dirs
    }

    /// Bands 0–2 written from the textbook formulas in (θ, φ), no CS phase.
    fn closed_form_bands_0_to_2(d: DVec3) -> [f64; 9] {
        let theta = d.z.clamp(-1.0, 1.0).acos();
        let phi = d.y.atan2(d.x);
        let (st, ct) = theta.sin_cos();
        let k1 = (3.0 / (4.0 * PI)).sqrt();
        let k2 = (15.0 / (4.0 * PI)).sqrt();
        [
            0.5 / PI.sqrt(),
            k1 * st * phi.sin(),
            k1 * ct,
            k1 * st * phi.cos(),
            0.5 * k2 * st * st * (2.0 * phi).sin(),
            k2 * st * ct * phi.sin(),
            (5.0 / (16.0 * PI)).sqrt() * (3.0 * ct * ct - 1.0),
            k2 * st * ct * phi.cos(),
            0.5 * k2 * st * st * (2.0 * phi).cos(),
        ]
    }

    #[test]
    fn basis_matches_closed_form_bands_0_to_2() {
        let mut fast = [0.0_f32; 9];
        let mut reference = [0.0_f64; 9];
        for d in test_directions() {
            let expected = closed_form_bands_0_to_2(d);
            eval_basis(3, d.as_vec3(), &mut fast);
            eval_basis_f64(3, d, &mut reference);
            for i in 0..9 {
                assert!((f64::from(fast[i]) - expected[i]).abs() < CLOSED_FORM_TOL, "f32 y_{i} at {d}");
                assert!((reference[i] - expected[i]).abs() < 1e-12, "f64 y_{i} at {d}");
            }
        }
        // The sign convention, stated in the brief: y_1,-1 = +0.488603·y.
        eval_basis(2, Vec3::new(0.0, 1.0, 0.0), &mut fast);
        assert!((fast[1] - 0.488_603).abs() < 1e-6);
        eval_basis(2, Vec3::new(1.0, 0.0, 0.0), &mut fast);
        assert!((fast[3] - 0.488_603).abs() < 1e-6);
    }

    #[test]
    fn band_3_matches_closed_form() {
        // y_30 and y_33 from (θ, φ): N_30 P_3 and √2 N_33 · 15 sin³θ cos 3φ.
        let mut out = [0.0_f64; 16];
        for d in test_directions() {
            eval_basis_f64(4, d, &mut out);
            let ct = d.z;
            let st = (1.0 - ct * ct).max(0.0).sqrt();
            let phi = d.y.atan2(d.x);
            let y30 = (7.0 / (4.0 * PI)).sqrt() * 0.5 * (5.0 * ct.powi(3) - 3.0 * ct);
            let n33 = (7.0 / (4.0 * PI) / 720.0).sqrt();
            let y33 = 2f64.sqrt() * n33 * 15.0 * st.powi(3) * (3.0 * phi).cos();
            let y3m3 = 2f64.sqrt() * n33 * 15.0 * st.powi(3) * (3.0 * phi).sin();
            assert!((out[12] - y30).abs() < 1e-12);
            assert!((out[15] - y33).abs() < 1e-12);
            assert!((out[9] - y3m3).abs() < 1e-12);
        }
    }

    #[test]
    fn f32_fast_path_matches_f64_up_to_max_order() {
        let mut fast = vec![0.0_f32; MAX_ORDER * MAX_ORDER];
        let mut reference = vec![0.0_f64; MAX_ORDER * MAX_ORDER];
        let mut worst = 0.0_f64;
        for order in 0..=MAX_ORDER {
            for d in test_directions() {
                // Normalise in f32 so both paths see the same unit vector.
                let d32 = d.as_vec3().normalize();
                eval_basis(order, d32, &mut fast);
                eval_basis_f64(order, d32.as_dvec3(), &mut reference);
                for i in 0..coeff_count(order) {
                    worst = worst.max((f64::from(fast[i]) - reference[i]).abs());
                }
            }
        }
        assert!(worst < F32_VS_F64_TOL, "worst |f32 − f64| = {worst:e}");
    }

    #[test]
    fn basis_is_orthonormal_at_order_8() {
        let order = 8;
        let n = coeff_count(order);
        let (nodes, weights) = crate::sh::quadrature::gauss_legendre(order + 1);
        let n_phi = 2 * order + 2;
        let mut gram = vec![0.0_f64; n * n];
        let mut y = vec![0.0_f64; n];
        for (&z, &w) in nodes.iter().zip(&weights) {
            let r = (1.0 - z * z).sqrt();
            for k in 0..n_phi {
                let phi = 2.0 * PI * (k as f64 + 0.5) / n_phi as f64;
                eval_basis_f64(order, DVec3::new(r * phi.cos(), r * phi.sin(), z), &mut y);
                let dw = w * 2.0 * PI / n_phi as f64;
                for i in 0..n {
                    for j in 0..n {
                        gram[i * n + j] += dw * y[i] * y[j];
                    }
                }
            }
        }
        for i in 0..n {
            for j in 0..n {
                let expected = if i == j { 1.0 } else { 0.0 };
                assert!((gram[i * n + j] - expected).abs() < ORTHONORMAL_TOL, "<y_{i}, y_{j}> = {}", gram[i * n + j]);
            }
        }
    }

    #[test]
    fn orders_above_max_order_still_evaluate() {
        let order = MAX_ORDER + 2;
        let mut out = vec![0.0_f64; coeff_count(order)];
        eval_basis_f64(order, DVec3::Z, &mut out);
        // At the pole only m = 0 survives: y_l0(+Z) = sqrt((2l+1)/(4π)).
        for l in 0..order {
            let expected = ((2 * l + 1) as f64 / (4.0 * PI)).sqrt();
            assert!((out[sh_index(l, 0)] - expected).abs() < 1e-12);
        }
    }

    #[test]
    fn evaluate_sums_coefficients_times_basis() {
        let order = 6;
        let coeffs: Vec<f32> = (0..coeff_count(order)).map(|i| (i as f32 * 0.37).sin()).collect();
        let dir = Vec3::new(0.3, -0.5, 0.8).normalize();
        let mut y = vec![0.0_f32; coeff_count(order)];
        eval_basis(order, dir, &mut y);
        let expected: f32 = coeffs.iter().zip(&y).map(|(c, y)| c * y).sum();
        assert!((evaluate(&coeffs, order, dir) - expected).abs() < 1e-5);
        let rgb: Vec<[f32; 3]> = coeffs.iter().map(|&c| [c, 2.0 * c, -c]).collect();
        let got = evaluate_rgb(&rgb, order, dir);
        assert!((got[1] - 2.0 * expected).abs() < 1e-5 && (got[2] + expected).abs() < 1e-5);
    }

    #[test]
    fn index_helpers_round_trip() {
        for l in 0..20usize {
            for m in -(l as i32)..=(l as i32) {
                assert_eq!(band_of_index(sh_index(l, m)), l);
            }
        }
        assert_eq!(sh_index(1, -1), 1);
        assert_eq!(sh_index(2, 2), 8);
        assert_eq!(coeff_count(16), 256);
    }
}
