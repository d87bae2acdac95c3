//! The panel's images as bytes: the reflected radiance as an OpenEXR (RGB
//! f32, linear, cd/m² when the light is photometric) and the contrast ratio as
//! a PNG with a legend (a log-scale colour bar with labelled ticks; texels off
//! the panel are grey).

use super::gather::TexelResult;
use super::readability::{contrast_ratio, luminance, Display};

/// EXR bytes of the reflected radiance (`width × height`, row 0 at the top; zero off the panel).
pub fn radiance_exr(results: &[Option<TexelResult>], width: u32, height: u32) -> Result<Vec<u8>, exr::error::Error> {
    let w = width as usize;
    crate::files::rgb_exr_bytes(w, height as usize, |x, y| results[y * w + x].map_or([0.0; 3], |t| t.radiance))
}

/// Contrast ratios shown by the colour bar (log scale) and labelled.
const TICKS: [f32; 7] = [1.0, 2.0, 3.0, 10.0, 30.0, 100.0, 1000.0];
const SCALE_MAX: f32 = 1000.0;

/// Colour of contrast ratio `cr` on a log scale from 1 to 1000: red below
/// 2, orange to yellow toward 3 (the usual readability limit), green to 30,
/// blue-white above.
pub fn colour_of(cr: f32) -> [u8; 3] {
    let stops: [(f32, [f32; 3]); 6] = [
        (1.0, [0.55, 0.0, 0.0]),
        (2.0, [0.95, 0.15, 0.1]),
        (3.0, [1.0, 0.85, 0.1]),
        (10.0, [0.3, 0.8, 0.25]),
        (100.0, [0.1, 0.45, 0.85]),
        (SCALE_MAX, [0.9, 0.95, 1.0]),
    ];
    let x = cr.clamp(1.0, SCALE_MAX).log10();
    let mut colour = stops[stops.len() - 1].1;
    for pair in stops.windows(2) {
        let (a, b) = (pair[0].0.log10(), pair[1].0.log10());
        if x <= b {
            let t = ((x - a) / (b - a)).clamp(0.0, 1.0);
            colour = [0, 1, 2].map(|c| pair[0].1[c] + t * (pair[1].1[c] - pair[0].1[c]));
            break;
        }
    }
    colour.map(|c| (c * 255.0).round() as u8)
}

/// 3×5 glyphs (rows top to bottom, 3 bits each, high bit left) for the legend's labels.
fn glyph(c: char) -> Option<[u8; 5]> {
    Some(match c {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        ':' => [0, 2, 0, 2, 0],
        '.' => [0, 0, 0, 0, 2],
        'C' => [7, 4, 4, 4, 7],
        'R' => [6, 5, 6, 5, 5],
        ' ' => [0; 5],
        _ => return None,
    })
}

/// An RGB canvas.
struct Canvas {
    width: usize,
    height: usize,
    rgb: Vec<u8>,
}

impl Canvas {
    fn fill(&mut self, x0: usize, y0: usize, w: usize, h: usize, colour: [u8; 3]) {
        for y in y0..(y0 + h).min(self.height) {
            for x in x0..(x0 + w).min(self.width) {
                self.rgb[3 * (y * self.width + x)..][..3].copy_from_slice(&colour);
            }
        }
    }
    /// Text at (x, y), each glyph pixel `scale` pixels, centred on x when `centred`.
    fn text(&mut self, text: &str, x: usize, y: usize, scale: usize, centred: bool) {
        let advance = 4 * scale;
        let width = text.chars().count() * advance;
        let x0 = if centred { x.saturating_sub(width / 2) } else { x };
        for (i, c) in text.chars().enumerate() {
            let Some(rows) = glyph(c) else { continue };
            for (r, bits) in rows.iter().enumerate() {
                for col in 0..3 {
                    if bits >> (2 - col) & 1 == 1 {
                        self.fill(x0 + i * advance + col * scale, y + r * scale, scale, scale, [0; 3]);
                    }
                }
            }
        }
    }
}

/// PNG bytes of the contrast-ratio map with its legend below: each texel
/// drawn as a square block (at least 480 pixels across in all).
pub fn contrast_png(results: &[Option<TexelResult>], width: u32, height: u32, display: Display) -> Result<Vec<u8>, png::EncodingError> {
    let block = (480 / width as usize).clamp(1, 16);
    let (map_w, map_h) = (width as usize * block, height as usize * block);
    let margin = 24;
    let canvas_w = map_w.max(360) + 2 * margin;
    let bar_h = 16;
    let canvas_h = margin + map_h + margin + bar_h + 40;
    let mut canvas = Canvas { width: canvas_w, height: canvas_h, rgb: vec![255; canvas_w * canvas_h * 3] };
    let map_x = (canvas_w - map_w) / 2;
    for row in 0..height as usize {
        for col in 0..width as usize {
            let colour = match results[row * width as usize + col] {
                Some(t) => colour_of(contrast_ratio(display, luminance(t.radiance).max(0.0))),
                None => [128; 3],
            };
            canvas.fill(map_x + col * block, margin + row * block, block, block, colour);
        }
    }
    // The colour bar: log10 CR from 0 to 3 across the bar.
    let (bar_x, bar_y, bar_w) = (margin, margin + map_h + margin, canvas_w - 2 * margin);
    for x in 0..bar_w {
        let cr = 10f32.powf(3.0 * x as f32 / (bar_w - 1) as f32);
        canvas.fill(bar_x + x, bar_y, 1, bar_h, colour_of(cr));
    }
    for tick in TICKS {
        let x = bar_x + (tick.log10() / 3.0 * (bar_w - 1) as f32).round() as usize;
        canvas.fill(x.saturating_sub(1).max(bar_x), bar_y + bar_h, 2, 5, [0; 3]);
        canvas.text(&format!("{tick}"), x, bar_y + bar_h + 8, 2, true);
    }
    canvas.text("CR", bar_x, margin.saturating_sub(16), 2, false);
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, canvas_w as u32, canvas_h as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header()?;
        writer.write_image_data(&canvas.rgb)?;
    }
    Ok(out)
}
