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
//! - **Photographic** (the default): Reinhard et al. 2002's scaling `c · a / L_a`
//!   with the key `a` chosen from the *absolute* adaptation luminance `L_a`
//!   (cd/m², the same adapted log-average as Drago's) as Krawczyk, Myszkowski
//!   and Seidel 2005 do, `a = 1.03 − 2 / (2 + log10(L_a + 1))`: about 0.03 for
//!   a night scene, 0.16 at 1 cd/m², 0.63 at 10³, 0.70 at 10⁴ (daylight). A night
//!   stays dark and a sunny scene keeps its highlights, where Drago's mapping
//!   (scale-invariant: only `L/L_a` matters) makes both look alike. Then
//!   `2^stops`, the ACES filmic fit of Narkowicz 2015 per channel,
//!   `f(x) = x(2.51x + 0.03) / (x(2.43x + 0.59) + 0.14)` (a toe, a shoulder,
//!   display white only from x ≈ 7.2, i.e. ≈ 10–40× the adaptation
//!   luminance), clamp, gamma. A highlight guard lowers the exposure when
//!   the brightest 1% of the frame (`L_99`, the 99th percentile of the same
//!   pass, from a histogram of quarter stops below the maximum, adapted as
//!   `L_a`) would pass `x = 5` (filmic 0.985, just short of white): the
//!   scale becomes `a / L_a · min(1, 5 / (L_99 · a / L_a))`, so the sun
//!   patches of a dim room keep their shape instead of clipping (the dining
//!   room at 09:00 showed its blinds' sun only at `--exposure -3` before;
//!   with the guard the default looks as that did).
//!
//! `Y` is Rec. 709 luminance `0.2126 R + 0.7152 G + 0.0722 B`. Every operator
//! reads the HDR pixel's radiance as `rgb · alpha` (alpha: the transmittance of
//! the window glass in front of it, 1 elsewhere).

/// Which tone-mapping operator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ToneOperator {
    /// Exposure, clamp, gamma (seed 001).
    Linear,
    /// Drago's adaptive logarithmic mapping with temporal adaptation (seed 000).
    Drago,
    /// Key from the absolute adaptation luminance, filmic curve, temporal adaptation (the default).
    Photographic,
}

impl ToneOperator {
    /// The operator named `text` (`photographic`, `drago`, `linear`).
    pub fn parse(text: &str) -> Option<ToneOperator> {
        match text {
            "photographic" => Some(ToneOperator::Photographic),
            "drago" => Some(ToneOperator::Drago),
            "linear" => Some(ToneOperator::Linear),
            _ => None,
        }
    }

    /// The next operator (the window's `M` key): photographic → Drago → linear → photographic.
    pub fn next(self) -> ToneOperator {
        match self {
            ToneOperator::Photographic => ToneOperator::Drago,
            ToneOperator::Drago => ToneOperator::Linear,
            ToneOperator::Linear => ToneOperator::Photographic,
        }
    }

    /// Whether the operator needs the luminance pass (adapted log-average).
    pub fn adapts(self) -> bool {
        self != ToneOperator::Linear
    }
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
        ToneMap { operator: ToneOperator::Photographic, exposure_stops: 0.0, gamma: 2.2, bias: 0.85, display_max: 100.0 }
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

/// The photographic key for adaptation luminance `l_a` (cd/m²), Krawczyk et al. 2005.
pub fn photographic_key(l_a: f32) -> f32 {
    1.03 - 2.0 / (2.0 + (l_a + 1.0).log10())
}

/// The ACES filmic fit (Narkowicz 2015) of one channel.
pub fn filmic(x: f32) -> f32 {
    (x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)
}

/// Filmic input the brightest 1% of the frame may reach before the
/// photographic operator lowers its exposure for them (filmic(5) = 0.985).
pub const HIGHLIGHT: f32 = 5.0;

/// The photographic operator on the CPU for adaptation luminance `l_a` and
/// 99th-percentile luminance `l_99`, as tonemap.wgsl computes it.
pub fn photographic(c: [f32; 3], t: &ToneMap, l_a: f32, l_99: f32) -> [f32; 3] {
    let l_a = l_a.max(1e-20);
    let scale = photographic_key(l_a) / l_a;
    let guard = (HIGHLIGHT / (l_99 * scale).max(1e-20)).min(1.0);
    c.map(|x| filmic(x.max(0.0) * t.exposure_stops.exp2() * scale * guard).clamp(0.0, 1.0).powf(1.0 / t.gamma))
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
    fn photographic_key_keeps_night_dark_and_day_bright() {
        // Closed forms: L_a = 0 → 1.03 − 1 = 0.03; L_a = 9 → 1.03 − 2/3; monotonic in between and beyond.
        assert!((photographic_key(0.0) - 0.03).abs() < 1e-6);
        assert!((photographic_key(9.0) - (1.03 - 2.0 / 3.0)).abs() < 1e-6);
        let keys: Vec<f32> = [1e-4f32, 1e-2, 1.0, 1e2, 1e4, 1e6].iter().map(|&l| photographic_key(l)).collect();
        assert!(keys.windows(2).all(|w| w[1] > w[0]), "{keys:?}");
        // The same scene 10⁶ times dimmer maps darker: the operator is not scale-invariant.
        let t = ToneMap { gamma: 1.0, ..ToneMap::default() };
        let day = photographic([1e4; 3], &t, 1e4, 1e4)[0];
        let night = photographic([1e-2; 3], &t, 1e-2, 1e-2)[0];
        assert!(day > 3.0 * night, "day {day}, night {night}");
    }

    #[test]
    fn filmic_curve_is_an_s_curve_reaching_white_near_seven() {
        assert_eq!(filmic(0.0), 0.0);
        // Toe: slope at 0 is 0.03/0.14 < 1; white (1.0) is reached at the root of 0.08x² − 0.56x − 0.14.
        let white = (0.56 + (0.56f32 * 0.56 + 4.0 * 0.08 * 0.14).sqrt()) / 0.16;
        assert!((filmic(white) - 1.0).abs() < 1e-5, "{white}");
        assert!(filmic(0.9 * white) < 1.0);
        let mut last = 0.0;
        for k in 1..200 {
            let v = filmic(k as f32 * 0.05);
            assert!(v > last);
            last = v;
        }
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
