//! Photometry of linear RGB: luminance with the Rec. 709 / sRGB weights
//! `Y = 0.2126 R + 0.7152 G + 0.0722 B`, the one definition the panel's
//! readability and the viewer's tone mapping both read.

/// Rec. 709 luminance of linear RGB.
pub fn luminance(rgb: [f32; 3]) -> f32 {
    0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
}

/// [`luminance`] in double precision, for sums over many texels.
pub fn luminance_f64(rgb: [f64; 3]) -> f64 {
    0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
}
