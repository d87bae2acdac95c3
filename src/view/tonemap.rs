//! Tone mapping: HDR radiance → display values in 0..1.
//!
//! - **Linear** (seed 001 §4): `c · 2^stops`, clamped to 0..1, then `x^(1/gamma)`.
//! - **Drago** (Drago et al. 2003, "Adaptive logarithmic mapping for displaying
//!   high contrast scenes", used by seed 000 §5): with world luminance
//!   `L_w = 2^stops · Y(c) / L_a` and `L_max' = 2^stops · L_max / L_a`,
//!
//!   ```text
//!   L_d = (L_dmax / 100) / log10(L_max' + 1) · ln(L_w + 1) / ln(2 + 8 · (L_w / L_max')^(ln b / ln ½))
//!   ```
//!
//!   and the colour is scaled by `L_d / Y(c)`, clamped, then gamma-encoded.
//!   `L_a` (log-average luminance) and `L_max` come from a 128×128 point-sampled
//!   pass over the HDR frame (covered pixels only), with dark pixels floored at
//!   10⁻⁴·L_max so empty shadows do not drag the average to zero, and adapt
//!   over time: `ln L_a ← ln L_a + (ln target − ln L_a)·(1 − e^(−dt/τ))`, τ =
//!   0.5 s when brightening and 2 s when darkening (the eye adapts to light
//!   faster than to dark; a simple stand-in for Pattanaik et al. 2000).
//!
//! `Y` is Rec. 709 luminance `0.2126 R + 0.7152 G + 0.0722 B`.

/// Which tone-mapping operator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ToneOperator {
    /// Exposure, clamp, gamma (seed 001).
    Linear,
    /// Drago's adaptive logarithmic mapping with temporal adaptation (seed 000).
    Drago,
}

/// Tone-mapping parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ToneMap {
    pub operator: ToneOperator,
    /// Exposure in stops: radiance is multiplied by `2^stops` first.
    pub exposure_stops: f32,
    /// Display gamma (2.2): output `x^(1/gamma)`.
    pub gamma: f32,
    /// Drago's bias b (0.85 in the paper; 0.7–0.9 useful).
    pub bias: f32,
    /// Drago's maximum display luminance L_dmax, cd/m² (100).
    pub display_max: f32,
}

impl Default for ToneMap {
    fn default() -> Self {
        ToneMap { operator: ToneOperator::Drago, exposure_stops: 0.0, gamma: 2.2, bias: 0.85, display_max: 100.0 }
    }
}

/// Time constants of the adaptation (seconds): brightening, darkening.
pub const ADAPT_TAU_BRIGHTEN_S: f32 = 0.5;
pub const ADAPT_TAU_DARKEN_S: f32 = 2.0;
/// Side of the point-sampled grid of the luminance pass.
pub const LUMINANCE_GRID: u32 = 128;
/// Dark pixels count as this fraction of the frame's maximum luminance.
pub const LUMINANCE_FLOOR: f32 = 1e-4;

/// Rec. 709 luminance of linear RGB.
pub fn luminance(c: [f32; 3]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

/// The linear operator on the CPU, exactly as tonemap.wgsl computes it.
pub fn linear(c: [f32; 3], exposure_stops: f32, gamma: f32) -> [f32; 3] {
    let scale = exposure_stops.exp2();
    c.map(|x| (x * scale).clamp(0.0, 1.0).powf(1.0 / gamma))
}

/// Drago's operator on the CPU for a given adaptation luminance `l_a` and frame maximum `l_max`.
pub fn drago(c: [f32; 3], t: &ToneMap, l_a: f32, l_max: f32) -> [f32; 3] {
    let scale = t.exposure_stops.exp2() / l_a.max(1e-20);
    let y = luminance(c) * scale;
    let y_max = (l_max * scale).max(1e-6);
    let exponent = t.bias.ln() / 0.5f32.ln();
    let l_d = (t.display_max / 100.0) / (y_max + 1.0).log10() * (y + 1.0).ln() / (2.0 + 8.0 * (y / y_max).powf(exponent)).ln();
    let ratio = if y > 0.0 { l_d / y } else { 0.0 };
    c.map(|x| (x * scale * ratio).clamp(0.0, 1.0).powf(1.0 / t.gamma))
}

/// A display value in 0..1 as an 8-bit code, rounded to nearest like a UNORM8 store.
pub fn to_u8(x: f32) -> u8 {
    (x.clamp(0.0, 1.0) * 255.0).round() as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_clamps_and_encodes() {
        assert_eq!(linear([0.0, 1.0, 4.0], 0.0, 2.2), [0.0, 1.0, 1.0]);
        let half = linear([0.25, 0.25, 0.25], 1.0, 2.2)[0];
        assert!((half - 0.5f32.powf(1.0 / 2.2)).abs() < 1e-6);
    }

    #[test]
    fn drago_maps_maximum_to_display_maximum_and_is_monotonic() {
        let t = ToneMap { gamma: 1.0, ..ToneMap::default() };
        // At L_w = L_max the denominator is ln(10), so L_d = 1 (L_dmax = 100).
        let top = drago([50.0; 3], &t, 2.0, 50.0);
        assert!((top[0] - 1.0).abs() < 1e-5, "{top:?}");
        let mut last = 0.0;
        for k in 1..50 {
            let v = drago([k as f32; 3], &t, 2.0, 50.0)[0];
            assert!(v > last);
            last = v;
        }
    }
}
