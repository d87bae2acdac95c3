//! The MERL isotropic measured-BRDF layout (Matusik et al. 2003, "A
//! data-driven reflectance model"; the database's `BRDFRead.cpp`).
//!
//! A file is a header of three little-endian i32 (90, 90, 180: the θ_h, θ_d
//! and φ_d resolutions) and then 3 × 90·90·180 little-endian f64, red block,
//! green block, blue block, each indexed `(i_h · 90 + i_d) · 180 + i_φ`.
//! `i_h = sqrt(θ_h / 90°) · 90` (finer near the specular peak),
//! `i_d = θ_d / 90° · 90`, `i_φ = φ_d / 180° · 180` with φ_d taken modulo
//! 180° (reciprocity). Values are scaled by 1/1500, 1.15/1500, 1.66/1500;
//! negative values mark unmeasured configurations and read as 0.
//!
//! The reference code looks values up by flooring the indices, that is, each
//! value covers its cell; here value `i` sits at its cell's centre `i + ½`
//! and lookups interpolate trilinearly (periodically in φ_d), which agrees
//! with the reference at every cell centre and removes its steps.
//!
//! Sampling draws from a GGX lobe fitted to the data (`merl_fit`) mixed with
//! a cosine lobe, and returns the mixture's exact density: unbiased for any
//! fit, since the cosine part covers every direction above the surface.

use super::frame::both_above;
use super::merl_fit::fit_lobe;
pub use super::merl_fit::FittedLobe;
pub use super::merl_grid::cell_centre;
use super::microfacet::{lobe_or_cosine_pdf, sample_lobe_or_cosine};
use super::text_format::MAX_VALUE;
use super::{read_brdf_file, Brdf, BrdfError, BrdfSample};
use glam::Vec3;
use std::f32::consts::{FRAC_PI_2, PI};
use std::path::Path;

/// Cells along θ_h, θ_d and φ_d: the header every MERL file carries.
pub const RESOLUTION: [usize; 3] = [90, 90, 180];
/// Values per channel.
pub const CELLS: usize = 90 * 90 * 180;
/// Exact size of a MERL file: the header and three channels of f64.
pub const FILE_BYTES: usize = 12 + 3 * CELLS * 8;
/// The database's channel scales (RED_SCALE, GREEN_SCALE, BLUE_SCALE).
pub const CHANNEL_SCALE: [f64; 3] = [1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0];

/// A MERL BRDF, scaled, as RGB f32 per cell, with its fitted sampling lobe.
#[derive(Clone)]
pub struct MerlBrdf {
    /// `values[(i_h · 90 + i_d) · 180 + i_φ]`, in 1/sr.
    values: Vec<[f32; 3]>,
    lobe: FittedLobe,
    unmeasured: usize,
}

impl MerlBrdf {
    /// Reads a MERL `.binary` file (at most `Limit::Brdf` bytes; exactly
    /// [`FILE_BYTES`] are accepted).
    pub fn load(path: &Path) -> Result<MerlBrdf, BrdfError> {
        let bytes = read_brdf_file(path)?;
        MerlBrdf::from_bytes(&bytes, path)
    }

    /// Decodes the bytes of a MERL file; `path` names the source in errors.
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<MerlBrdf, BrdfError> {
        let malformed = |message: String| BrdfError::Malformed { path: path.to_path_buf(), message };
        if bytes.len() < 12 {
            return Err(malformed(format!("{} bytes: shorter than the 12-byte MERL header", bytes.len())));
        }
        let dims: [i32; 3] = std::array::from_fn(|k| i32::from_le_bytes(bytes[4 * k..4 * k + 4].try_into().unwrap_or_default()));
        if dims.iter().zip(RESOLUTION).any(|(&d, r)| i64::from(d) != r as i64) {
            return Err(malformed(format!(
                "header gives {} × {} × {} cells, expected 90 × 90 × 180 (θ_h, θ_d, φ_d): not an isotropic MERL BRDF",
                dims[0], dims[1], dims[2]
            )));
        }
        if bytes.len() != FILE_BYTES {
            let what = if bytes.len() < FILE_BYTES { "truncated" } else { "trailing bytes" };
            return Err(malformed(format!(
                "{} bytes, expected exactly {FILE_BYTES} (12-byte header + 3 × {CELLS} doubles): {what}",
                bytes.len()
            )));
        }
        let mut values = vec![[0.0f32; 3]; CELLS];
        let mut unmeasured = 0;
        for (channel, scale) in CHANNEL_SCALE.iter().enumerate() {
            let block = &bytes[12 + channel * CELLS * 8..12 + (channel + 1) * CELLS * 8];
            for (cell, (raw, slot)) in block.chunks_exact(8).zip(values.iter_mut()).enumerate() {
                let v = f64::from_le_bytes(raw.try_into().unwrap_or_default());
                let scaled = v * scale;
                if !v.is_finite() || scaled > MAX_VALUE {
                    let (i_h, i_d, i_phi) = (cell / (90 * 180), cell / 180 % 90, cell % 180);
                    return Err(malformed(format!(
                        "{} value at cell (θ_h {i_h}, θ_d {i_d}, φ_d {i_phi}), byte offset {}, is {v:e}: not a finite BRDF value up to {MAX_VALUE:e} 1/sr",
                        ["red", "green", "blue"][channel],
                        12 + (channel * CELLS + cell) * 8
                    )));
                }
                if v < 0.0 {
                    unmeasured += 1;
                }
                slot[channel] = scaled.max(0.0) as f32;
            }
        }
        let lobe = fit_lobe(&values);
        Ok(MerlBrdf { values, lobe, unmeasured })
    }

    /// The GGX lobe and mixture weight the sampler uses.
    pub fn lobe(&self) -> FittedLobe {
        self.lobe
    }

    /// How many values (over all channels) were negative, "not measured", and read as 0.
    pub fn unmeasured(&self) -> usize {
        self.unmeasured
    }

    /// Trilinear lookup at half/difference angles (radians).
    fn lookup(&self, theta_h: f32, theta_d: f32, phi_d: f32) -> [f32; 3] {
        let (h0, h1, th) = clamped_cell((theta_h / FRAC_PI_2).max(0.0).sqrt() * 90.0 - 0.5, 90);
        let (d0, d1, td) = clamped_cell(theta_d / FRAC_PI_2 * 90.0 - 0.5, 90);
        let xp = (phi_d / PI * 180.0 - 0.5).rem_euclid(180.0);
        let p0 = (xp as usize).min(179);
        let (p1, tp) = ((p0 + 1) % 180, (xp - p0 as f32).clamp(0.0, 1.0));
        let at = |h: usize, d: usize, p: usize| self.values[(h * 90 + d) * 180 + p];
        let mut out = [0.0f32; 3];
        for (h, wh) in [(h0, 1.0 - th), (h1, th)] {
            for (d, wd) in [(d0, 1.0 - td), (d1, td)] {
                for (p, wp) in [(p0, 1.0 - tp), (p1, tp)] {
                    let w = wh * wd * wp;
                    let v = at(h, d, p);
                    (0..3).for_each(|c| out[c] += w * v[c]);
                }
            }
        }
        out
    }
}

/// A summary: the 1.46 M cells would drown a log.
impl std::fmt::Debug for MerlBrdf {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MerlBrdf").field("lobe", &self.lobe).field("unmeasured", &self.unmeasured).finish_non_exhaustive()
    }
}

/// Lower cell, upper cell and fraction of a continuous cell coordinate `x`
/// (cell `i`'s value at `x = i`), clamped to `0..n`.
fn clamped_cell(x: f32, n: usize) -> (usize, usize, f32) {
    let x = if x > 0.0 { x.min((n - 1) as f32) } else { 0.0 };
    let i = (x as usize).min(n - 1);
    (i, (i + 1).min(n - 1), x - i as f32)
}

/// Half-vector and difference angles `(θ_h, θ_d, φ_d)` in radians
/// (Rusinkiewicz 1998, as the MERL code computes them; `atan2` keeps θ_h
/// accurate near the specular peak).
pub fn half_diff(wi: Vec3, wo: Vec3) -> (f32, f32, f32) {
    let h = (wi + wo).normalize();
    let theta_h = h.x.hypot(h.y).atan2(h.z);
    let phi_h = h.y.atan2(h.x);
    let (sin_t, cos_t) = theta_h.sin_cos();
    let (sin_p, cos_p) = phi_h.sin_cos();
    // wi rotated by −φ_h about the normal, then by −θ_h about the binormal.
    let tangent = Vec3::new(cos_t * cos_p, cos_t * sin_p, -sin_t);
    let binormal = Vec3::new(-sin_p, cos_p, 0.0);
    let d = Vec3::new(wi.dot(tangent), wi.dot(binormal), wi.dot(h));
    (theta_h, d.x.hypot(d.y).atan2(d.z), d.y.atan2(d.x))
}

/// The directions `(wi, wo)` at half/difference angles (radians), with the
/// half vector at azimuth 0: the inverse of [`half_diff`].
pub fn directions_from_half_diff(theta_h: f32, theta_d: f32, phi_d: f32) -> (Vec3, Vec3) {
    let d = super::frame::from_spherical(theta_d, phi_d);
    let (sin_t, cos_t) = theta_h.sin_cos();
    let h = Vec3::new(sin_t, 0.0, cos_t);
    let wi = Vec3::new(d.x * cos_t + d.z * sin_t, d.y, -d.x * sin_t + d.z * cos_t);
    (wi, super::frame::reflect(wi, h))
}

impl Brdf for MerlBrdf {
    fn eval(&self, wi: Vec3, wo: Vec3) -> [f32; 3] {
        if !both_above(wi, wo) {
            return [0.0; 3];
        }
        let (theta_h, theta_d, phi_d) = half_diff(wi, wo);
        self.lookup(theta_h, theta_d, phi_d)
    }

    fn sample(&self, wo: Vec3, u: [f32; 2]) -> Option<BrdfSample> {
        let wi = sample_lobe_or_cosine(wo, self.lobe.alpha, self.lobe.specular_probability, u)?;
        let pdf = self.pdf(wo, wi);
        (pdf > 0.0).then_some(BrdfSample { wi, pdf })
    }

    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        lobe_or_cosine_pdf(wo, wi, self.lobe.alpha, self.lobe.specular_probability)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::*;
    use super::super::{EnergyReport, PanelBrdf};
    use super::*;
    use std::sync::OnceLock;

    /// The tinted coating written in the MERL layout and read back (as `PanelBrdf::load` does for `.binary`).
    fn coating_merl() -> &'static MerlBrdf {
        static MERL: OnceLock<MerlBrdf> = OnceLock::new();
        MERL.get_or_init(|| {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("coating.binary");
            write_merl_of(&path, &tinted_coating());
            match PanelBrdf::load(&path).unwrap() {
                PanelBrdf::Merl(merl) => merl,
                other => panic!("a .binary file loaded as {other:?}"),
            }
        })
    }

    #[test]
    fn half_diff_angles_round_trip() {
        for (h, d, p) in [(0.1f32, 0.5f32, 0.3f32), (0.7, 0.2, 2.9), (0.02, 1.2, 1.0), (0.4, 0.3, -2.0)] {
            let (wi, wo) = directions_from_half_diff(h, d, p);
            let (h2, d2, p2) = half_diff(wi, wo);
            assert!((h - h2).abs() < 1e-5 && (d - d2).abs() < 1e-5 && (p - p2).abs() < 1e-5, "({h}, {d}, {p}) -> ({h2}, {d2}, {p2})");
            // Swapping the directions turns φ_d by π: the same cell modulo 180°.
            let (h3, d3, p3) = half_diff(wo, wi);
            let turn = (p3 - p).rem_euclid(PI);
            assert!((h - h3).abs() < 1e-5 && (d - d3).abs() < 1e-5 && turn.min(PI - turn) < 1e-4, "swapped: ({h3}, {d3}, {p3})");
        }
    }

    #[test]
    fn layout_scales_and_unmeasured_values_follow_the_merl_code() {
        // Raw values linear in the cell indices, one slope per channel, and
        // −1 ("not measured") in the cells of one φ_d index.
        let value =
            |c: usize, h: usize, d: usize, p: usize| (c + 1) as f64 * (1.0 + 0.01 * h as f64 + 0.003 * d as f64 + 0.0007 * p as f64);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("layout.binary");
        write_merl(&path, |c, h, d, p| if p == 177 { -1.0 } else { value(c, h, d, p) / CHANNEL_SCALE[c] });
        let merl = MerlBrdf::load(&path).unwrap();
        assert_eq!(merl.unmeasured(), 3 * 90 * 90);
        for (h, d, p) in [(10usize, 20usize, 30usize), (50, 5, 100), (3, 40, 150), (80, 3, 7), (1, 1, 1)] {
            let (wi, wo) = directions_from_half_diff(cell_centre(h, d, p).0, cell_centre(h, d, p).1, cell_centre(h, d, p).2);
            assert!(wi.z > 0.0 && wo.z > 0.0);
            let got = merl.eval(wi, wo);
            for c in 0..3 {
                assert!(
                    (f64::from(got[c]) - value(c, h, d, p)).abs() < 1e-4 * value(c, h, d, p),
                    "cell ({h}, {d}, {p}) channel {c}: {got:?}"
                );
            }
        }
        // Half-way between φ_d cells 176 and 177 (unmeasured, read as 0): the mean.
        let (h, d, _) = cell_centre(30, 30, 0);
        let (wi, wo) = directions_from_half_diff(h, d, 177.0 / 180.0 * PI);
        let got = merl.eval(wi, wo)[0];
        assert!((f64::from(got) - value(0, 30, 30, 176) / 2.0).abs() < 1e-3, "{got}");
        // Every configuration reflects more than 1/π: the report says so.
        let warning = EnergyReport::of(&merl).warning("layout.binary").unwrap();
        assert!(warning.starts_with("layout.binary: directional albedo reaches"), "{warning}");
    }

    #[test]
    fn sampling_is_unbiased() {
        let lobe = coating_merl().lobe();
        println!("MERL fit of the coating (alpha 0.2): alpha {:.3}, lobe probability {:.3}", lobe.alpha, lobe.specular_probability);
        assert!((0.15..=0.27).contains(&lobe.alpha), "{lobe:?}");
        check_unbiased("MERL", coating_merl(), &THETA_OUT_DEG);
    }

    #[test]
    fn pdf_integrates_to_at_most_one_and_matches_the_samples() {
        check_pdf("MERL", coating_merl(), &THETA_OUT_DEG, None);
    }

    #[test]
    fn lookups_are_reciprocal() {
        let merl = coating_merl();
        let mut worst = 0.0f32;
        for i in 0..20_000 {
            let [a, b] = uniform_pair(21, i);
            let [c, d] = uniform_pair(22, i);
            let wi = super::super::frame::from_mu_phi(a, std::f32::consts::TAU * b);
            let wo = super::super::frame::from_mu_phi(c, std::f32::consts::TAU * d);
            let (x, y) = (merl.eval(wi, wo), merl.eval(wo, wi));
            for k in 0..3 {
                worst = worst.max((x[k] - y[k]).abs() / x[k].max(1e-3));
            }
        }
        println!("MERL: reciprocity, largest relative difference {worst:.2e}");
        assert!(worst < 1e-3);
    }

    #[test]
    fn the_file_reproduces_the_coating_albedo() {
        for deg in [0.0f32, 30.0, 60.0, 80.0] {
            let wo = wo_at(deg);
            let (merl, exact) = (coating_merl().albedo(wo).rgb, tinted_coating().albedo(wo).rgb);
            println!("MERL theta_out {deg}: albedo RGB {merl:.5?} vs analytic {exact:.5?}");
            for c in 0..3 {
                assert!((merl[c] - exact[c]).abs() < 0.01 * exact[c], "theta_out {deg} channel {c}: {merl:?} vs {exact:?}");
            }
        }
    }

    #[test]
    fn bad_files_are_refused_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let good = dir.path().join("good.binary");
        write_merl(&good, |_, _, _, _| 1.0);
        let bytes = std::fs::read(&good).unwrap();
        // Through a file once (the loader names it), then from memory.
        let truncated = dir.path().join("truncated.binary");
        std::fs::write(&truncated, &bytes[..bytes.len() - 8]).unwrap();
        assert_eq!(
            PanelBrdf::load(&truncated).unwrap_err().to_string(),
            format!("{}: 34992004 bytes, expected exactly 34992012 (12-byte header + 3 × 1458000 doubles): truncated", truncated.display())
        );
        let message = PanelBrdf::load(&dir.path().join("absent.binary")).unwrap_err().to_string();
        assert!(message.starts_with(&format!("{}: cannot read", dir.path().join("absent.binary").display())), "{message}");
        let refusal = |bytes: &[u8]| {
            let message = MerlBrdf::from_bytes(bytes, Path::new("panel.binary")).unwrap_err().to_string();
            message.strip_prefix("panel.binary: ").unwrap_or_else(|| panic!("{message}")).to_string()
        };
        assert_eq!(refusal(&bytes[..8]), "8 bytes: shorter than the 12-byte MERL header");
        assert!(refusal(&bytes[..bytes.len() / 2]).ends_with("truncated"));
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(refusal(&longer).ends_with("trailing bytes"));
        let mut dims = bytes.clone();
        dims[8..12].copy_from_slice(&360i32.to_le_bytes());
        assert_eq!(refusal(&dims), "header gives 90 × 90 × 360 cells, expected 90 × 90 × 180 (θ_h, θ_d, φ_d): not an isotropic MERL BRDF");
        let mut nan = bytes.clone();
        let offset = 12 + (CELLS + (2 * 90 + 3) * 180 + 4) * 8;
        nan[offset..offset + 8].copy_from_slice(&f64::NAN.to_le_bytes());
        assert_eq!(
            refusal(&nan),
            format!("green value at cell (θ_h 2, θ_d 3, φ_d 4), byte offset {offset}, is NaN: not a finite BRDF value up to 1e9 1/sr")
        );
        let mut huge = bytes;
        huge[12..20].copy_from_slice(&1e300f64.to_le_bytes());
        assert!(refusal(&huge).starts_with("red value at cell (θ_h 0, θ_d 0, φ_d 0), byte offset 12, is 1e300"));
    }
}
