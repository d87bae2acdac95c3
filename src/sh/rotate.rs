//! Rotation of SH expansions, block-diagonal per band.
//!
//! Band matrices come from the recurrence of J. Ivanic & K. Ruedenberg,
//! "Rotation Matrices for Real Spherical Harmonics. Direct Determination by
//! Recursion", J. Phys. Chem. 100(15), 1996, with the sign corrections of
//! their erratum, J. Phys. Chem. A 102(45), 1998 (the m < 0 case of V).
//! Built in f64 from the band-1 matrix, stored in f32.

use glam::{DMat3, Mat3};

use super::basis::coeff_count;

/// The SH rotation of every band `l < order` for one 3×3 rotation.
///
/// Semantics: if `f(ω) = Σ c_i y_i(ω)` and `g = apply(c)`, then
/// `Σ g_i y_i(R ω) = f(ω)` for every ω: `g` is `f` rotated by `R`
/// (`g(ω') = f(Rᵀ ω')`). Consequently `new(R1·R2)` equals applying
/// `new(R2)` then `new(R1)`, and every band keeps its L2 norm.
#[derive(Clone, Debug)]
pub struct ShRotation {
    order: usize,
    /// Band matrices concatenated; band l is (2l+1)² values, row-major,
    /// rows = output m, columns = input m, both from −l to l.
    blocks: Vec<f32>,
}

/// Offset of band l's block: Σ_{k<l} (2k+1)² = l(2l−1)(2l+1)/3.
fn block_offset(l: usize) -> usize {
    if l == 0 {
        0
    } else {
        l * (2 * l - 1) * (2 * l + 1) / 3
    }
}

/// A square band matrix indexed by centred m, n ∈ [−l, l].
struct BandMatrix {
    l: i32,
    values: Vec<f64>,
}

impl BandMatrix {
    fn zeros(l: i32) -> Self {
        let side = (2 * l + 1) as usize;
        Self { l, values: vec![0.0; side * side] }
    }

    fn index(&self, m: i32, n: i32) -> usize {
        let side = 2 * self.l + 1;
        ((m + self.l) * side + (n + self.l)) as usize
    }

    fn get(&self, m: i32, n: i32) -> f64 {
        self.values[self.index(m, n)]
    }

    fn set(&mut self, m: i32, n: i32, v: f64) {
        let i = self.index(m, n);
        self.values[i] = v;
    }
}

impl ShRotation {
    /// Builds the band matrices of `rotation` for bands `l < order`.
    ///
    /// `rotation` must be orthonormal with determinant +1 (a proper
    /// rotation); other matrices give meaningless (but finite for finite
    /// input) results. Any order works; orders ≤ [`super::MAX_ORDER`] are
    /// tested. Cost O(order³) time and memory.
    pub fn new(order: usize, rotation: Mat3) -> Self {
        let r = rotation.as_dmat3();
        let mut blocks = Vec::with_capacity(block_offset(order));
        if order > 0 {
            blocks.push(1.0);
        }
        if order > 1 {
            let band1 = band1_matrix(&r);
            blocks.extend(band1.values.iter().map(|&v| v as f32));
            let mut previous = band1_matrix(&r);
            for l in 2..order as i32 {
                let next = next_band(&band1, &previous, l);
                blocks.extend(next.values.iter().map(|&v| v as f32));
                previous = next;
            }
        }
        Self { order, blocks }
    }

    /// The order this rotation was built for.
    pub fn order(&self) -> usize {
        self.order
    }

    /// Band l's (2l+1)×(2l+1) matrix, row-major (rows: output m = −l..l).
    /// Empty if `l ≥ order`.
    pub fn band_matrix(&self, l: usize) -> &[f32] {
        if l >= self.order {
            return &[];
        }
        &self.blocks[block_offset(l)..block_offset(l + 1)]
    }

    /// Rotates one channel: `output[0..order²] = D(R) · input[0..order²]`.
    /// Entries past `order²` are left untouched.
    ///
    /// # Panics
    /// If `input` or `output` is shorter than `order²`.
    pub fn apply(&self, input: &[f32], output: &mut [f32]) {
        let n = coeff_count(self.order);
        assert!(input.len() >= n && output.len() >= n, "ShRotation::apply: need {n} coefficients");
        for l in 0..self.order {
            let side = 2 * l + 1;
            let start = l * l;
            let matrix = self.band_matrix(l);
            let band_in = &input[start..start + side];
            for (row, out) in matrix.chunks_exact(side).zip(&mut output[start..start + side]) {
                *out = row.iter().zip(band_in).map(|(a, b)| a * b).sum();
            }
        }
    }

    /// [`ShRotation::apply`] for RGB coefficients.
    ///
    /// # Panics
    /// If `input` or `output` is shorter than `order²`.
    pub fn apply_rgb(&self, input: &[[f32; 3]], output: &mut [[f32; 3]]) {
        let n = coeff_count(self.order);
        assert!(input.len() >= n && output.len() >= n, "ShRotation::apply_rgb: need {n} coefficients");
        for l in 0..self.order {
            let side = 2 * l + 1;
            let start = l * l;
            let matrix = self.band_matrix(l);
            let band_in = &input[start..start + side];
            for (row, out) in matrix.chunks_exact(side).zip(&mut output[start..start + side]) {
                let mut acc = [0.0_f32; 3];
                for (a, c) in row.iter().zip(band_in) {
                    for k in 0..3 {
                        acc[k] += a * c[k];
                    }
                }
                *out = acc;
            }
        }
    }
}

/// Band 1 in the order m = −1, 0, 1 ↔ (y, z, x): D₁[a][b] = R[p(a)][p(b)].
/// With y₁ = k·(y, z, x) this gives y₁(Rᵀω) = D₁ᵀ y₁(ω), i.e. the semantics
/// documented on [`ShRotation`].
fn band1_matrix(r: &DMat3) -> BandMatrix {
    // glam is column-major: r.col(j)[i] is row i, column j.
    let axis = |m: i32| -> usize {
        match m {
            -1 => 1,
            0 => 2,
            _ => 0,
        }
    };
    let mut band = BandMatrix::zeros(1);
    for a in -1..=1 {
        for b in -1..=1 {
            band.set(a, b, r.col(axis(b))[axis(a)]);
        }
    }
    band
}

/// Ivanic–Ruedenberg helper P: the band-1 matrix times band l−1.
fn p_term(i: i32, a: i32, b: i32, l: i32, band1: &BandMatrix, previous: &BandMatrix) -> f64 {
    let (ri1, ri0, rim1) = (band1.get(i, 1), band1.get(i, 0), band1.get(i, -1));
    if b == l {
        ri1 * previous.get(a, l - 1) - rim1 * previous.get(a, -l + 1)
    } else if b == -l {
        ri1 * previous.get(a, -l + 1) + rim1 * previous.get(a, l - 1)
    } else {
        ri0 * previous.get(a, b)
    }
}

/// Band l from band 1 and band l−1 (Ivanic & Ruedenberg 1996, Table 2, with
/// the 1998 erratum).
fn next_band(band1: &BandMatrix, previous: &BandMatrix, l: i32) -> BandMatrix {
    let p = |i, a, b| p_term(i, a, b, l, band1, previous);
    let mut band = BandMatrix::zeros(l);
    for m in -l..=l {
        for n in -l..=l {
            let lf = f64::from(l);
            let d = if m == 0 { 1.0 } else { 0.0 };
            let denom = if n.abs() == l { (2.0 * lf) * (2.0 * lf - 1.0) } else { f64::from((l + n) * (l - n)) };
            let am = f64::from(m.abs());
            let u = (f64::from((l + m) * (l - m)) / denom).sqrt();
            let v = 0.5 * ((1.0 + d) * (lf + am - 1.0) * (lf + am) / denom).sqrt() * (1.0 - 2.0 * d);
            let w = -0.5 * ((lf - am - 1.0) * (lf - am) / denom).max(0.0).sqrt() * (1.0 - d);
            let mut value = 0.0;
            // Terms with a zero coefficient would index outside band l−1.
            if u != 0.0 {
                value += u * p(0, m, n);
            }
            if v != 0.0 {
                value += v * match m.signum() {
                    0 => p(1, 1, n) + p(-1, -1, n),
                    1 => {
                        let d1: f64 = if m == 1 { 1.0 } else { 0.0 };
                        let second = if m == 1 { 0.0 } else { p(-1, -m + 1, n) };
                        p(1, m - 1, n) * (1.0 + d1).sqrt() - second
                    }
                    _ => {
                        let d1: f64 = if m == -1 { 1.0 } else { 0.0 };
                        let first = if m == -1 { 0.0 } else { p(1, m + 1, n) };
                        first + p(-1, -m - 1, n) * (1.0 + d1).sqrt()
                    }
                };
            }
            if w != 0.0 {
                value += w * if m > 0 { p(1, m + 1, n) + p(-1, -m - 1, n) } else { p(1, m - 1, n) - p(-1, -m + 1, n) };
            }
            band.set(m, n, value);
        }
    }
    band
}

#[cfg(test)]
mod tests {
    use glam::{Quat, Vec3};

    use super::*;
    use crate::sh::basis::{eval_basis, evaluate};

    /// f32 matrices and sums of up to 17 products of O(1) values; errors
    /// ~1e-6 relative to the coefficient norm. 1e-4 relative leaves margin.
    const ROTATION_REL_TOL: f32 = 1e-4;

    /// SplitMix64: deterministic, no dependency.
    struct SplitMix(u64);
    impl SplitMix {
        fn next_f32(&mut self) -> f32 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            (z >> 40) as f32 / (1u64 << 24) as f32
        }
        fn signed(&mut self) -> f32 {
            2.0 * self.next_f32() - 1.0
        }
        fn unit_vector(&mut self) -> Vec3 {
            loop {
                let v = Vec3::new(self.signed(), self.signed(), self.signed());
                let len = v.length();
                if len > 0.1 && len <= 1.0 {
                    return v / len;
                }
            }
        }
        fn rotation(&mut self) -> Mat3 {
            let axis = self.unit_vector();
            let angle = self.signed() * std::f32::consts::PI;
            Mat3::from_quat(Quat::from_axis_angle(axis, angle))
        }
    }

    fn norm(c: &[f32]) -> f32 {
        c.iter().map(|x| x * x).sum::<f32>().sqrt()
    }

    #[test]
    fn rotated_expansion_at_rotated_direction_equals_original() {
        let mut rng = SplitMix(7);
        let mut worst = 0.0_f32;
        for order in 1..=8 {
            for _ in 0..10 {
                let r = rng.rotation();
                let rot = ShRotation::new(order, r);
                let c: Vec<f32> = (0..coeff_count(order)).map(|_| rng.signed()).collect();
                let mut g = vec![0.0; coeff_count(order)];
                rot.apply(&c, &mut g);
                let scale = norm(&c);
                for _ in 0..20 {
                    let w = rng.unit_vector();
                    let original = evaluate(&c, order, w);
                    let rotated = evaluate(&g, order, r * w);
                    worst = worst.max((original - rotated).abs() / scale);
                }
            }
        }
        eprintln!("rotation orders 1–8: worst |f(ω) − g(Rω)| / |c| = {worst:.2e}");
        assert!(worst < ROTATION_REL_TOL, "worst relative mismatch {worst:e}");
    }

    #[test]
    fn rotation_of_basis_function_matches_basis_at_inverse_direction() {
        // g = D e_j must equal y_j(Rᵀ ω') as a function of ω'.
        let order = 4;
        let r = Mat3::from_quat(Quat::from_rotation_y(0.7) * Quat::from_rotation_x(-1.1));
        let rot = ShRotation::new(order, r);
        let mut y = vec![0.0; 16];
        for j in 0..coeff_count(order) {
            let mut e = vec![0.0; 16];
            e[j] = 1.0;
            let mut g = vec![0.0; 16];
            rot.apply(&e, &mut g);
            for w in [Vec3::X, Vec3::new(0.2, -0.9, 0.4).normalize(), Vec3::new(-0.6, 0.1, -0.8).normalize()] {
                eval_basis(order, r.transpose() * w, &mut y);
                assert!((evaluate(&g, order, w) - y[j]).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn rotation_preserves_band_norms_and_composes() {
        let mut rng = SplitMix(11);
        for order in [1, 2, 5, 8, 16] {
            let (r1, r2) = (rng.rotation(), rng.rotation());
            let c: Vec<f32> = (0..coeff_count(order)).map(|_| rng.signed()).collect();
            let scale = norm(&c);
            let (d1, d2, d12) = (ShRotation::new(order, r1), ShRotation::new(order, r2), ShRotation::new(order, r1 * r2));
            let mut once = vec![0.0; c.len()];
            let mut twice = vec![0.0; c.len()];
            let mut direct = vec![0.0; c.len()];
            d2.apply(&c, &mut once);
            d1.apply(&once, &mut twice);
            d12.apply(&c, &mut direct);
            for l in 0..order {
                let band = l * l..(l + 1) * (l + 1);
                let (before, after) = (norm(&c[band.clone()]), norm(&once[band]));
                assert!((before - after).abs() < ROTATION_REL_TOL * scale, "order {order} band {l}: {before} → {after}");
            }
            for (a, b) in twice.iter().zip(&direct) {
                assert!((a - b).abs() < ROTATION_REL_TOL * scale, "order {order}: D(R1)D(R2) ≠ D(R1R2)");
            }
        }
    }

    #[test]
    fn identity_and_rgb_and_band_layout() {
        let order = 6;
        let id = ShRotation::new(order, Mat3::IDENTITY);
        for l in 0..order {
            let side = 2 * l + 1;
            for (k, v) in id.band_matrix(l).iter().enumerate() {
                let expected = if k / side == k % side { 1.0 } else { 0.0 };
                assert!((v - expected).abs() < 1e-6);
            }
        }
        assert!(id.band_matrix(order).is_empty());
        let r = Mat3::from_rotation_z(0.3);
        let rot = ShRotation::new(order, r);
        let c: Vec<f32> = (0..36).map(|i| (i as f32).cos()).collect();
        let rgb: Vec<[f32; 3]> = c.iter().map(|&v| [v, -v, 0.5 * v]).collect();
        let (mut mono, mut colour) = (vec![0.0; 36], vec![[0.0; 3]; 36]);
        rot.apply(&c, &mut mono);
        rot.apply_rgb(&rgb, &mut colour);
        for (m, c) in mono.iter().zip(&colour) {
            assert!((m - c[0]).abs() < 1e-6 && (m + c[1]).abs() < 1e-6 && (0.5 * m - c[2]).abs() < 1e-6);
        }
        assert_eq!(ShRotation::new(0, r).band_matrix(0), &[] as &[f32]);
    }
}
