//! The previous bounce at a hit point, read from a fit to the hit
//! triangle's own points (`--gather-fit`). A bounce ≥ 1 gathers
//! `t⁽ᵇ⁻¹⁾(h)` at each ray's hit `h` by blending three corner rows with the
//! hit's barycentrics. By default those rows are the corner vertices'
//! values, hat-weighted means over their whole one-rings; near a corner,
//! where light falls off faster than linearly, a hit then reads light from
//! farther out (the grey-white room reads 1.6% bright at 3 bounces against
//! Mitsuba 3, docs/speed-accuracy.md).
//!
//! Here each triangle gets its own three corner rows: the linear function
//! `c(b) = Σ_k b_k C_k` that fits the triangle's points in least squares,
//! weighted as the transfer weighs them (`area / n` each),
//! `min Σ_j w_j (c(b_j) − x_j)²`, pulled toward the vertex rows `V_k` by a
//! ridge worth [`PRIOR_POINTS`] points: `(M + λI) C = S + λV` with
//! `M = Σ_j w_j b_j b_jᵀ`, `S_k = Σ_j w_j b_jk x_j` (the item's corner sums
//! the bake already forms) and `λ = PRIOR_POINTS · w / 6` (a point's mean
//! `w · b_k²`). As a triangle's points grow the data outweighs the prior,
//! so the bias falls with work, not only with the mesh. A triangle without
//! points (a window, zero area, every point inside geometry) keeps its
//! vertex rows. The gather kernel is unchanged: it reads rows through
//! corner indices, here one row per triangle corner.

use rayon::prelude::*;

use super::items::{triangle_area, triangle_sample, Items};
use crate::bake::BakeParams;
use crate::mesh::Mesh;

/// The ridge's weight toward the vertex rows, in points.
pub(crate) const PRIOR_POINTS: f64 = 3.0;

/// Per item, the fit's normal matrix with its ridge, `M + λI`, as the six
/// entries `[m00, m01, m02, m11, m12, m22]`, and `λ`.
pub(crate) struct FitMatrices {
    pub(crate) normal: Vec<[f64; 6]>,
    pub(crate) lambda: Vec<f64>,
}

/// `M + λI` of every item of an interior layout, over its points not
/// `rejected` (the points a bounce adds to its corner sums).
pub(crate) fn fit_matrices(mesh: &Mesh, items: &Items, params: &BakeParams, rejected: &[bool]) -> FitMatrices {
    let seed = params.point_seed.unwrap_or(params.seed);
    let (normal, lambda) = (0..items.len())
        .into_par_iter()
        .filter_map(|item| items.samples(item))
        .map(|item| {
            let w = f64::from(triangle_area(mesh, item.triangle)) / f64::from(item.weight_count.max(1));
            let corners = mesh.triangle(item.triangle as usize);
            let mut m = [0.0f64; 6];
            for s in 0..item.count {
                if rejected.get((item.first_sample + s) as usize).copied().unwrap_or(false) {
                    continue;
                }
                let b = triangle_sample(params.pattern, seed, item.triangle, corners, item.first_index + s).map(f64::from);
                let entries = [b[0] * b[0], b[0] * b[1], b[0] * b[2], b[1] * b[1], b[1] * b[2], b[2] * b[2]];
                m.iter_mut().zip(entries).for_each(|(m, e)| *m += w * e);
            }
            let lambda = PRIOR_POINTS * w / 6.0;
            (m[0] += lambda, m[3] += lambda, m[5] += lambda);
            (m, lambda)
        })
        .unzip();
    FitMatrices { normal, lambda }
}

/// Fills `rows` (`3 · triangles` rows of `stride`) with the corner rows a
/// bounce gathers from, one per triangle corner, and returns the corner
/// indices that read them (`0, 1, 2, …`). `item_sums`: each item's three
/// corner sums `S_k` from the bounce just run; `vertex_rows`: that
/// bounce's vertex rows `V`, which a triangle without an item keeps.
pub(crate) fn fill_corner_table(
    rows: &mut [f32],
    mesh: &Mesh,
    items: &Items,
    fit: &FitMatrices,
    item_sums: &[f32],
    vertex_rows: &[f32],
    stride: usize,
) -> Vec<u32> {
    let triangle_count = mesh.triangle_count();
    let mut item_of = vec![u32::MAX; triangle_count];
    for item in 0..items.len() {
        if let Some(samples) = items.samples(item) {
            item_of[samples.triangle as usize] = item as u32;
        }
    }
    rows.par_chunks_mut(3 * stride).zip(item_of.par_iter()).enumerate().for_each(|(t, (dst, &item))| {
        let corners = mesh.triangle(t);
        let prior = |l: usize, c: usize| f64::from(vertex_rows[corners[l] as usize * stride + c]);
        if item == u32::MAX {
            for (k, &v) in corners.iter().enumerate() {
                dst[k * stride..][..stride].copy_from_slice(&vertex_rows[v as usize * stride..][..stride]);
            }
            return;
        }
        let item = item as usize;
        let inverse = symmetric_inverse(&fit.normal[item]);
        let sums = &item_sums[item * 3 * stride..][..3 * stride];
        for c in 0..stride {
            let s = std::array::from_fn(|l| f64::from(sums[l * stride + c]));
            for (k, value) in fit_corners(&inverse, fit.lambda[item], s, std::array::from_fn(|l| prior(l, c))).into_iter().enumerate() {
                dst[k * stride + c] = value as f32;
            }
        }
    });
    (0..3 * triangle_count as u32).collect()
}

/// The corner values `C = (M + λI)⁻¹ (S + λV)` of one coefficient, from the
/// inverse of `M + λI`, the corner sums `S` and the prior `V`.
fn fit_corners(inverse: &[[f64; 3]; 3], lambda: f64, sums: [f64; 3], prior: [f64; 3]) -> [f64; 3] {
    let rhs: [f64; 3] = std::array::from_fn(|l| sums[l] + lambda * prior[l]);
    std::array::from_fn(|k| (0..3).map(|l| inverse[k][l] * rhs[l]).sum())
}

/// The inverse of the symmetric 3 × 3 matrix `[m00, m01, m02, m11, m12, m22]`
/// (positive definite here: the ridge keeps it so).
fn symmetric_inverse(m: &[f64; 6]) -> [[f64; 3]; 3] {
    let [a, b, c, d, e, f] = *m;
    let (c00, c01, c02) = (d * f - e * e, c * e - b * f, b * e - c * d);
    let (c11, c12, c22) = (a * f - c * c, b * c - a * e, a * d - b * b);
    let det = a * c00 + b * c01 + c * c02;
    let s = 1.0 / det;
    [[c00 * s, c01 * s, c02 * s], [c01 * s, c11 * s, c12 * s], [c02 * s, c12 * s, c22 * s]]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points whose values are a linear function `x(b) = Σ b_k F_k` of their
    /// barycentrics: the fit's corners approach `F` as the points grow, from
    /// a prior `V` far from it, the error falling as the prior's share
    /// (PRIOR_POINTS against n points); with no point they are the prior.
    #[test]
    fn the_fit_recovers_a_linear_field_as_its_points_grow() {
        let truth = [1.0, 0.2, 0.5];
        let prior = [0.6, 0.6, 0.6];
        let area = 0.5;
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut uniform = move || {
            state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let error = |n: usize, uniform: &mut dyn FnMut() -> f64| -> f64 {
            let w = area / n as f64;
            let mut m = [0.0f64; 6];
            let mut sums = [0.0f64; 3];
            for _ in 0..n {
                let (r1, r2) = (uniform().sqrt(), uniform());
                let b = [1.0 - r1, r1 * (1.0 - r2), r1 * r2];
                let x: f64 = (0..3).map(|k| b[k] * truth[k]).sum();
                let entries = [b[0] * b[0], b[0] * b[1], b[0] * b[2], b[1] * b[1], b[1] * b[2], b[2] * b[2]];
                m.iter_mut().zip(entries).for_each(|(m, e)| *m += w * e);
                sums.iter_mut().zip(b).for_each(|(s, b)| *s += w * b * x);
            }
            let lambda = PRIOR_POINTS * w / 6.0;
            (m[0] += lambda, m[3] += lambda, m[5] += lambda);
            let c = fit_corners(&symmetric_inverse(&m), lambda, sums, prior);
            (0..3).map(|k| (c[k] - truth[k]).abs()).fold(0.0, f64::max)
        };
        let (few, many, most) = (error(3, &mut uniform), error(48, &mut uniform), error(768, &mut uniform));
        assert!(many < few && most < many, "errors {few} {many} {most}");
        assert!(most < 0.01, "768 points: {most}");
        // Without points the corners are the prior.
        let lambda = PRIOR_POINTS / 6.0;
        let alone = [lambda, 0.0, 0.0, lambda, 0.0, lambda];
        let c = fit_corners(&symmetric_inverse(&alone), lambda, [0.0; 3], prior);
        assert!(c.iter().zip(prior).all(|(c, p)| (c - p).abs() < 1e-12), "{c:?}");
    }

    /// The inverse times the matrix is the identity.
    #[test]
    fn symmetric_inverse_inverts() {
        let m = [4.0, 1.0, 0.5, 3.0, 0.25, 2.0];
        let full = [[m[0], m[1], m[2]], [m[1], m[3], m[4]], [m[2], m[4], m[5]]];
        let inv = symmetric_inverse(&m);
        for i in 0..3 {
            for j in 0..3 {
                let p: f64 = (0..3).map(|k| full[i][k] * inv[k][j]).sum();
                assert!((p - f64::from(u8::from(i == j))).abs() < 1e-12, "{i} {j}: {p}");
            }
        }
    }
}
