//! Quadrature on the sphere: Gauss–Legendre in cos θ × uniform φ, and the
//! SH projection of analytic functions built on it.

use std::f64::consts::PI;

use glam::DVec3;
use rayon::prelude::*;

use super::basis::{coeff_count, eval_basis_f64};

/// Gauss–Legendre nodes and weights on [−1, 1] with `n` points (Newton on
/// P_n from the Tricomi initial guess). Exact for polynomials of degree
/// `< 2n`; the weights sum to 2. `n = 0` gives empty vectors.
pub fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut nodes = vec![0.0; n];
    let mut weights = vec![0.0; n];
    let nf = n as f64;
    for k in 0..n.div_ceil(2) {
        let mut x = (PI * (k as f64 + 0.75) / (nf + 0.5)).cos();
        let mut derivative = 1.0;
        for _ in 0..100 {
            // P_n(x) and P_n'(x) by the three-term recurrence.
            let (mut p0, mut p1) = (1.0_f64, x);
            for j in 2..=n {
                let jf = j as f64;
                let p2 = ((2.0 * jf - 1.0) * x * p1 - (jf - 1.0) * p0) / jf;
                p0 = p1;
                p1 = p2;
            }
            let pn = if n == 1 { x } else { p1 };
            let pn_minus_1 = if n == 1 { 1.0 } else { p0 };
            derivative = nf * (x * pn - pn_minus_1) / (x * x - 1.0);
            let step = pn / derivative;
            x -= step;
            if step.abs() < 1e-16 {
                break;
            }
        }
        let w = 2.0 / ((1.0 - x * x) * derivative * derivative);
        nodes[k] = x;
        weights[k] = w;
        nodes[n - 1 - k] = -x;
        weights[n - 1 - k] = w;
    }
    (nodes, weights)
}

/// Projects an analytic RGB function onto SH: `L_i = ∫ f(ω) y_i(ω) dω`.
///
/// Quadrature: `samples_per_axis` Gauss–Legendre nodes in cos θ (θ from +Z)
/// times `2·samples_per_axis` uniform longitudes; `samples_per_axis = 0` is
/// treated as 1. The rule is exact when `f` is itself band-limited to order
/// ≤ `samples_per_axis`; for functions with edges (caps, discs) the error
/// falls like 1/samples. Accumulates in f64, parallel over θ nodes, summed
/// in a fixed order so the result does not depend on the thread count.
///
/// See also [`super::project_equirect`] for images.
pub fn project_function(order: usize, samples_per_axis: usize, f: impl Fn(DVec3) -> [f64; 3] + Sync) -> Vec<[f32; 3]> {
    let n = coeff_count(order);
    let n_theta = samples_per_axis.max(1);
    let n_phi = 2 * n_theta;
    let (nodes, weights) = gauss_legendre(n_theta);
    let sum = nodes
        .par_iter()
        .zip(weights.par_iter())
        .map(|(&z, &w)| {
            let mut acc = vec![[0.0_f64; 3]; n];
            let mut y = vec![0.0_f64; n];
            let r = (1.0 - z * z).max(0.0).sqrt();
            let dw = w * 2.0 * PI / n_phi as f64;
            for k in 0..n_phi {
                let phi = 2.0 * PI * (k as f64 + 0.5) / n_phi as f64;
                let dir = DVec3::new(r * phi.cos(), r * phi.sin(), z);
                let value = f(dir);
                eval_basis_f64(order, dir, &mut y);
                for (a, &yi) in acc.iter_mut().zip(&y) {
                    for c in 0..3 {
                        a[c] += dw * value[c] * yi;
                    }
                }
            }
            acc
        })
        .collect::<Vec<_>>()
        .into_iter()
        // Sequential sum in node order: same bits whatever the thread count.
        .fold(vec![[0.0_f64; 3]; n], add_rows);
    sum.into_iter().map(|c| c.map(|v| v as f32)).collect()
}

/// Element-wise sum of two per-coefficient RGB accumulators.
pub(crate) fn add_rows(mut a: Vec<[f64; 3]>, b: Vec<[f64; 3]>) -> Vec<[f64; 3]> {
    for (x, y) in a.iter_mut().zip(b) {
        for c in 0..3 {
            x[c] += y[c];
        }
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        for n in 1..=20 {
            let (x, w) = gauss_legendre(n);
            for degree in 0..2 * n {
                let got: f64 = x.iter().zip(&w).map(|(x, w)| w * x.powi(degree as i32)).sum();
                let exact = if degree % 2 == 1 { 0.0 } else { 2.0 / (degree as f64 + 1.0) };
                assert!((got - exact).abs() < 1e-13, "n={n} degree={degree}: {got} vs {exact}");
            }
        }
        assert!(gauss_legendre(0).0.is_empty());
    }

    #[test]
    fn project_function_of_basis_gives_unit_vector() {
        let order = 5;
        for j in 0..coeff_count(order) {
            let coeffs = project_function(order, order + 1, |d| {
                let mut b = vec![0.0; coeff_count(order)];
                eval_basis_f64(order, d, &mut b);
                [b[j], 2.0 * b[j], 0.0]
            });
            for (i, c) in coeffs.iter().enumerate() {
                let e = if i == j { 1.0 } else { 0.0 };
                assert!((c[0] - e).abs() < 1e-6 && (c[1] - 2.0 * e).abs() < 1e-6 && c[2] == 0.0);
            }
        }
        // Constant 1 projects to DC alone: L_00 = √(4π).
        let dc = project_function(order, 4, |_| [1.0; 3]);
        assert!((f64::from(dc[0][0]) - (4.0 * PI).sqrt()).abs() < 1e-6);
        assert!(dc[1..].iter().all(|c| c[0].abs() < 1e-6));
    }
}
