//! Decoder for Radiance RGBE (.hdr) images: header, resolution string,
//! flat, old-style run-length and new-style (per-channel) RLE scanlines.
//! Format: G. Ward, "Real Pixels", Graphics Gems II, 1991, and the Radiance
//! sources (color.c). Never panics on bad bytes; allocation grows row by row
//! with the bytes actually decoded.

use thiserror::Error;

/// What is wrong with a Radiance HDR file.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum HdrProblem {
    /// Does not start with `#?` (e.g. `#?RADIANCE`).
    #[error("missing '#?' signature")]
    MissingSignature,
    /// The header never ends with an empty line.
    #[error("header has no terminating empty line")]
    UnterminatedHeader,
    /// `FORMAT=` names something other than `32-bit_rle_rgbe`.
    #[error("unsupported pixel format '{0}' (only 32-bit_rle_rgbe)")]
    UnsupportedFormat(String),
    /// The resolution line cannot be parsed.
    #[error("bad resolution line '{0}'")]
    BadResolution(String),
    /// A resolution line other than `-Y h +X w` or `+Y h +X w`.
    #[error("unsupported orientation '{0}' (only -Y h +X w and +Y h +X w)")]
    UnsupportedOrientation(String),
    /// Width or height beyond the decoder's pixel limit.
    #[error("image too large: {width}×{height}")]
    TooLarge { width: u32, height: u32 },
    /// The data ends inside scanline `row` (file order).
    #[error("truncated in scanline {row}")]
    Truncated { row: u32 },
    /// A run overflows the scanline or has length zero.
    #[error("bad run length in scanline {row}")]
    BadRunLength { row: u32 },
    /// A new-style RLE scanline header announces another width.
    #[error("scanline {row} declares width {found}, image width is {expected}")]
    ScanlineWidthMismatch { row: u32, found: u32, expected: u32 },
}

/// Largest image the decoders accept, in pixels (16384×8192, 1.5 GiB as f32 RGB).
pub const MAX_PIXELS: u64 = 16384 * 8192;

/// Largest width or height the HDR decoder accepts.
const MAX_SIDE: u32 = 65536;

/// A decoded RGBE image, rows top to bottom.
pub(crate) struct DecodedRgbe {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<[f32; 3]>,
}

/// What a `.hdr` file's header says: the image's size and where its scanlines start.
pub(crate) struct HdrHeader {
    pub width: u32,
    pub height: u32,
    bottom_up: bool,
    /// Offset of the first scanline.
    pub data_start: usize,
}

impl HdrHeader {
    /// The most bytes a file with this header can hold: the header, then
    /// per scanline at most a 4-byte RLE marker and 16 bytes a pixel (a
    /// pixel and three repeat codes that repeat nothing, the worst the flat
    /// form decodes; per-channel RLE takes at most 8). Anything past that is
    /// not this image.
    pub fn max_file_bytes(&self) -> u64 {
        self.data_start as u64 + u64::from(self.height) * (4 + 16 * u64::from(self.width))
    }
}

/// Parses the header and resolution line at the start of `bytes` (a prefix
/// of the file is enough) and checks the size against the decoder's limits.
pub(crate) fn parse_header(bytes: &[u8]) -> Result<HdrHeader, HdrProblem> {
    if !bytes.starts_with(b"#?") {
        return Err(HdrProblem::MissingSignature);
    }
    let mut cursor = 0usize;
    // Header: lines up to the first empty one.
    loop {
        let line = next_line(bytes, &mut cursor).ok_or(HdrProblem::UnterminatedHeader)?;
        if line.is_empty() {
            break;
        }
        if let Some(format) = line.strip_prefix(b"FORMAT=") {
            let format = String::from_utf8_lossy(format).trim().to_string();
            if format != "32-bit_rle_rgbe" {
                return Err(HdrProblem::UnsupportedFormat(format));
            }
        }
    }
    let resolution = next_line(bytes, &mut cursor).ok_or_else(|| HdrProblem::BadResolution(String::new()))?;
    let resolution = String::from_utf8_lossy(resolution).trim().to_string();
    let (width, height, bottom_up) = parse_resolution(&resolution)?;
    // The side limit bounds the scanline buffer before any pixel is read.
    if width > MAX_SIDE || height > MAX_SIDE || u64::from(width) * u64::from(height) > MAX_PIXELS {
        return Err(HdrProblem::TooLarge { width, height });
    }
    Ok(HdrHeader { width, height, bottom_up, data_start: cursor })
}

/// Decodes a whole `.hdr` file held in memory.
pub(crate) fn decode_rgbe(bytes: &[u8]) -> Result<DecodedRgbe, HdrProblem> {
    let HdrHeader { width, height, bottom_up, data_start: cursor } = parse_header(bytes)?;
    if width == 0 || height == 0 {
        // The caller reports the zero size with the file name.
        return Ok(DecodedRgbe { width, height, rgb: Vec::new() });
    }
    let mut reader = ScanlineReader { bytes, cursor, previous: None };
    let mut rgb = Vec::new();
    let mut scanline = vec![[0u8; 4]; width as usize];
    for row in 0..height {
        reader.read_scanline(&mut scanline, row)?;
        rgb.extend(scanline.iter().map(|&p| rgbe_to_float(p)));
    }
    if bottom_up {
        let w = width as usize;
        let flipped: Vec<[f32; 3]> = rgb.chunks_exact(w.max(1)).rev().flatten().copied().collect();
        rgb = flipped;
    }
    Ok(DecodedRgbe { width, height, rgb })
}

/// Returns the bytes up to the next `\n` (without it) and advances past it.
fn next_line<'a>(bytes: &'a [u8], cursor: &mut usize) -> Option<&'a [u8]> {
    let rest = bytes.get(*cursor..)?;
    let end = rest.iter().position(|&b| b == b'\n')?;
    *cursor += end + 1;
    let line = &rest[..end];
    Some(line.strip_suffix(b"\r").unwrap_or(line))
}

/// Parses `-Y h +X w` (top-down) or `+Y h +X w` (bottom-up).
fn parse_resolution(line: &str) -> Result<(u32, u32, bool), HdrProblem> {
    let tokens: Vec<&str> = line.split_whitespace().collect();
    let [y_axis, h, x_axis, w] = tokens.as_slice() else {
        return Err(HdrProblem::BadResolution(line.to_string()));
    };
    let parse = |s: &str| s.parse::<u32>().map_err(|_| HdrProblem::BadResolution(line.to_string()));
    let (height, width) = (parse(h)?, parse(w)?);
    match (*y_axis, *x_axis) {
        ("-Y", "+X") => Ok((width, height, false)),
        ("+Y", "+X") => Ok((width, height, true)),
        _ => Err(HdrProblem::UnsupportedOrientation(line.to_string())),
    }
}

/// Radiance's `colr_color`: (m + 0.5) · 2^(e − 136), zero exponent is black.
fn rgbe_to_float(p: [u8; 4]) -> [f32; 3] {
    if p[3] == 0 {
        return [0.0; 3];
    }
    let scale = 2f64.powi(i32::from(p[3]) - 136);
    [0, 1, 2].map(|c| ((f64::from(p[c]) + 0.5) * scale) as f32)
}

struct ScanlineReader<'a> {
    bytes: &'a [u8],
    cursor: usize,
    /// Last pixel decoded, for old-style run-length repeats.
    previous: Option<[u8; 4]>,
}

impl ScanlineReader<'_> {
    fn byte(&mut self, row: u32) -> Result<u8, HdrProblem> {
        let b = *self.bytes.get(self.cursor).ok_or(HdrProblem::Truncated { row })?;
        self.cursor += 1;
        Ok(b)
    }

    fn pixel(&mut self, row: u32) -> Result<[u8; 4], HdrProblem> {
        Ok([self.byte(row)?, self.byte(row)?, self.byte(row)?, self.byte(row)?])
    }

    fn read_scanline(&mut self, out: &mut [[u8; 4]], row: u32) -> Result<(), HdrProblem> {
        let width = out.len();
        let head = self.bytes.get(self.cursor..self.cursor + 4);
        let new_rle = matches!(head, Some(&[2, 2, hi, _]) if hi & 0x80 == 0) && (8..=0x7fff).contains(&width);
        if new_rle {
            self.read_new_rle(out, row)
        } else {
            self.read_flat_or_old_rle(out, row)
        }
    }

    /// Four channel planes, each a sequence of runs (count > 128: repeat the
    /// next byte count−128 times) and literals (count ≤ 128 bytes follow).
    fn read_new_rle(&mut self, out: &mut [[u8; 4]], row: u32) -> Result<(), HdrProblem> {
        let header = self.pixel(row)?;
        let found = (u32::from(header[2]) << 8) | u32::from(header[3]);
        let width = out.len();
        if found as usize != width {
            return Err(HdrProblem::ScanlineWidthMismatch { row, found, expected: width as u32 });
        }
        for channel in 0..4 {
            let mut x = 0usize;
            while x < width {
                let count = self.byte(row)?;
                if count > 128 {
                    let run = usize::from(count - 128);
                    if x + run > width {
                        return Err(HdrProblem::BadRunLength { row });
                    }
                    let value = self.byte(row)?;
                    for p in &mut out[x..x + run] {
                        p[channel] = value;
                    }
                    x += run;
                } else {
                    let run = usize::from(count);
                    if run == 0 || x + run > width {
                        return Err(HdrProblem::BadRunLength { row });
                    }
                    for p in &mut out[x..x + run] {
                        p[channel] = self.byte(row)?;
                    }
                    x += run;
                }
            }
        }
        self.previous = out.last().copied();
        Ok(())
    }

    /// Plain RGBE quadruples, where (1, 1, 1, n) repeats the previous pixel
    /// n << shift times (shift grows by 8 for consecutive repeat codes).
    fn read_flat_or_old_rle(&mut self, out: &mut [[u8; 4]], row: u32) -> Result<(), HdrProblem> {
        let width = out.len();
        let mut x = 0usize;
        let mut shift = 0u32;
        while x < width {
            let p = self.pixel(row)?;
            if p[0] == 1 && p[1] == 1 && p[2] == 1 {
                let previous = self.previous.ok_or(HdrProblem::BadRunLength { row })?;
                let count = usize::from(p[3]).checked_shl(shift).ok_or(HdrProblem::BadRunLength { row })?;
                if shift > 16 || x + count > width {
                    return Err(HdrProblem::BadRunLength { row });
                }
                out[x..x + count].fill(previous);
                x += count;
                shift += 8;
            } else {
                out[x] = p;
                self.previous = Some(p);
                x += 1;
                shift = 0;
            }
        }
        Ok(())
    }
}
