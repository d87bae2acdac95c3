//! Whether the driver can read the display: the contrast ratio of a white and
//! a black pixel under the reflected light, `CR = (L_white + L_r) / (L_black + L_r)`
//! (the ambient contrast ratio of ISO 9241-303 / IEC 62341: reflected light
//! adds to both). Luminance from linear RGB with the Rec. 709 / sRGB weights
//! `Y = 0.2126 R + 0.7152 G + 0.0722 B`.

use super::gather::TexelResult;

/// Rec. 709 luminance of linear RGB.
pub fn luminance(rgb: [f32; 3]) -> f32 {
    0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
}

pub(crate) fn luminance_f64(rgb: [f64; 3]) -> f64 {
    0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
}

/// The display's own luminances (cd/m²).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Display {
    pub white_cd_m2: f32,
    pub black_cd_m2: f32,
}

impl Default for Display {
    /// Typical automotive LCD values: 500 cd/m² white, 1000:1 native contrast.
    fn default() -> Self {
        Display { white_cd_m2: 500.0, black_cd_m2: 0.5 }
    }
}

/// `(L_white + L_r) / (L_black + L_r)` for reflected luminance `reflected`.
pub fn contrast_ratio(display: Display, reflected: f32) -> f32 {
    (display.white_cd_m2 + reflected) / (display.black_cd_m2 + reflected)
}

/// Readability statistics over the texels on the panel.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Readability {
    pub texels: usize,
    pub min_contrast_ratio: f32,
    pub median_contrast_ratio: f32,
    pub threshold: f32,
    /// Fraction of texels whose contrast ratio is below `threshold`.
    pub fraction_below_threshold: f32,
    /// Reflected luminance (cd/m² in physical units): mean and maximum over the texels.
    pub mean_reflected_luminance: f32,
    pub max_reflected_luminance: f32,
    /// Mean over the texels (with any reflected light) of the share of reflected luminance that came through windows.
    pub window_share: f32,
    /// Mean over the texels (with any reflected light) of the share that came
    /// straight from the sky or the sun, through windows or not (open mode).
    pub sky_share: f32,
    /// `1 − sky_share`: the share the interior's surfaces reflected.
    pub interior_share: f32,
    /// Largest standard error of a texel's reflected luminance, relative to the texel's value.
    pub max_relative_error: f32,
}

impl Readability {
    /// Statistics of `results` (texels off the panel are `None`). `None` when no texel has a result.
    pub fn of(results: &[Option<TexelResult>], display: Display, threshold: f32) -> Option<Readability> {
        let texels: Vec<&TexelResult> = results.iter().flatten().collect();
        if texels.is_empty() {
            return None;
        }
        let reflected: Vec<f32> = texels.iter().map(|t| luminance(t.radiance).max(0.0)).collect();
        let mut ratios: Vec<f32> = reflected.iter().map(|&l| contrast_ratio(display, l)).collect();
        ratios.sort_by(f32::total_cmp);
        let n = ratios.len();
        let median = if n % 2 == 1 { ratios[n / 2] } else { 0.5 * (ratios[n / 2 - 1] + ratios[n / 2]) };
        let below = ratios.iter().filter(|&&r| r < threshold).count();
        let mean_share = |part: fn(&TexelResult) -> [f32; 3]| {
            let shares: Vec<f64> = texels
                .iter()
                .zip(&reflected)
                .filter(|(_, &l)| l > 0.0)
                .map(|(t, &l)| (f64::from(luminance(part(t))) / f64::from(l)).clamp(0.0, 1.0))
                .collect();
            if shares.is_empty() {
                0.0
            } else {
                (shares.iter().sum::<f64>() / shares.len() as f64) as f32
            }
        };
        let window_share = mean_share(|t| t.through_windows);
        let sky_share = mean_share(|t| t.from_sky);
        let max_relative_error =
            texels.iter().zip(&reflected).filter(|(_, &l)| l > 0.0).map(|(t, &l)| t.luminance_error / l).fold(0.0f32, f32::max);
        Some(Readability {
            texels: n,
            min_contrast_ratio: ratios[0],
            median_contrast_ratio: median,
            threshold,
            fraction_below_threshold: below as f32 / n as f32,
            mean_reflected_luminance: (reflected.iter().map(|&l| f64::from(l)).sum::<f64>() / n as f64) as f32,
            max_reflected_luminance: reflected.iter().copied().fold(0.0, f32::max),
            window_share,
            sky_share,
            interior_share: 1.0 - sky_share,
            max_relative_error,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contrast_ratio_and_statistics_follow_their_definitions() {
        let display = Display::default();
        assert_eq!(contrast_ratio(display, 0.0), 1000.0);
        // L_r = (500 − 3·0.5)/2 = 249.25 gives exactly 3:1.
        assert!((contrast_ratio(display, 249.25) - 3.0).abs() < 1e-6);
        assert!((luminance([1.0, 1.0, 1.0]) - 1.0).abs() < 1e-6);
        let texel = |y: f32, window: f32| {
            Some(TexelResult { radiance: [y; 3], through_windows: [window; 3], from_sky: [window; 3], luminance_error: 0.0 })
        };
        let results = vec![texel(0.0, 0.0), None, texel(249.25, 249.25), texel(500.0, 125.0), texel(10.0, 0.0)];
        let r = Readability::of(&results, display, 3.0).unwrap();
        assert_eq!(r.texels, 4);
        assert!((r.min_contrast_ratio - 1000.0 / 500.5).abs() < 1e-5);
        assert_eq!(r.fraction_below_threshold, 0.25, "only 500 (1.998) is below; 249.25 gives 3.0 exactly");
        // Shares over the three texels with light: 1, 0.25, 0.
        assert!((r.window_share - 1.25 / 3.0).abs() < 1e-6);
        assert!((r.sky_share - 1.25 / 3.0).abs() < 1e-6 && (r.interior_share - 1.75 / 3.0).abs() < 1e-6);
        let median = 0.5 * (contrast_ratio(display, 10.0) + contrast_ratio(display, 249.25));
        assert!((r.median_contrast_ratio - median).abs() < 1e-4);
        assert!(Readability::of(&[None, None], display, 3.0).is_none());
    }
}
