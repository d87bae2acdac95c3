//! Equirectangular environment maps: loading (.exr, .hdr) and projection
//! onto SH.
//!
//! Layout (docs/conventions.md): pixel (col, row) of a W×H image has
//! u = (col+0.5)/W, v = (row+0.5)/H, polar angle from up θ = π·v (row 0 is the
//! top, +Y), longitude φ = 2π(u − 0.5), direction
//! (sin θ sin φ, cos θ, −sin θ cos φ): the image centre looks toward −Z and
//! u = 0.75 toward +X.

use std::f64::consts::PI;
use std::io::Cursor;
use std::path::{Path, PathBuf};

use glam::DVec3;
use rayon::prelude::*;
use thiserror::Error;

use super::basis::{coeff_count, eval_basis_f64};
use super::quadrature::add_rows;
use super::rgbe::{decode_rgbe, HdrProblem, MAX_PIXELS};

/// An equirectangular RGB image in linear radiance.
///
/// `rgb` is row-major with row 0 at the top (+Y) and must hold
/// `width · height` pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct EquirectImage {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<[f32; 3]>,
}

/// Why an environment map could not be loaded. Every message names the file.
#[derive(Debug, Error)]
pub enum EnvMapError {
    #[error("{}: file not found", .path.display())]
    NotFound { path: PathBuf },
    #[error("{}: cannot read: {source}", .path.display())]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{}: unknown env map extension (expected .exr or .hdr)", .path.display())]
    UnknownExtension { path: PathBuf },
    #[error("{}: not an OpenEXR file (bad magic number)", .path.display())]
    NotExr { path: PathBuf },
    #[error("{}: cannot decode EXR: {source}", .path.display())]
    Exr { path: PathBuf, source: exr::error::Error },
    #[error("{}: no layer has R, G and B channels (first layer has: {found})", .path.display())]
    NoRgbChannels { path: PathBuf, found: String },
    #[error("{}: image has zero size ({width}×{height})", .path.display())]
    ZeroSize { path: PathBuf, width: u64, height: u64 },
    #[error("{}: image too large ({width}×{height}, limit {MAX_PIXELS} pixels)", .path.display())]
    TooLarge { path: PathBuf, width: u64, height: u64 },
    #[error("{}: pixel (col {col}, row {row}) is not finite: {value:?}", .path.display())]
    NonFinite { path: PathBuf, col: u32, row: u32, value: [f32; 3] },
    #[error("{}: bad Radiance HDR file: {problem}", .path.display())]
    BadHdr { path: PathBuf, problem: HdrProblem },
    #[error(
        "{}: is {size} bytes, but the {width}×{height} image its header describes takes at most {bound}: not an image this size (data appended, or a damaged header)",
        .path.display()
    )]
    Oversized { path: PathBuf, size: u64, width: u64, height: u64, bound: u64 },
}

/// OpenEXR magic number, the first four bytes of every EXR file.
const EXR_MAGIC: [u8; 4] = [0x76, 0x2f, 0x31, 0x01];
/// Most bytes read for an EXR's headers (attributes, previews) before its size is checked.
const EXR_HEAD_MAX: u64 = 64 << 20;
/// Most bytes read for a Radiance header and resolution line.
const HDR_HEAD_MAX: u64 = 64 << 10;

/// Loads an equirectangular map from `.exr` (any compression and sample type
/// the exr crate reads; the first layer with R, G, B; alpha ignored) or
/// `.hdr` (Radiance RGBE). The extension decides the format,
/// case-insensitively.
///
/// Refuses non-finite pixels, zero-size images and images over
/// 16384×8192 pixels. The header is read first: an image over the limit,
/// or a file larger than the image its header describes can take
/// ([`EnvMapError::Oversized`]: a map with gigabytes appended), is refused
/// before the rest is read.
pub fn load_equirect(path: &Path) -> Result<EquirectImage, EnvMapError> {
    use crate::files::{read, Limit};
    let owned = || path.to_path_buf();
    let io_error = |source: std::io::Error| match source.kind() {
        std::io::ErrorKind::NotFound => EnvMapError::NotFound { path: owned() },
        _ => EnvMapError::Io { path: owned(), source },
    };
    let size = read::check_regular(path, Limit::Image).map_err(io_error)?;
    let extension = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match extension.as_deref() {
        Some("exr") => check_exr_size(path, size)?,
        Some("hdr") => {
            let head = read::read_head(path, Limit::Image, HDR_HEAD_MAX).map_err(io_error)?;
            let header = super::rgbe::parse_header(&head).map_err(|problem| EnvMapError::BadHdr { path: owned(), problem })?;
            let (width, height, bound) = (u64::from(header.width), u64::from(header.height), header.max_file_bytes());
            if size > bound {
                return Err(EnvMapError::Oversized { path: owned(), size, width, height, bound });
            }
        }
        _ => return Err(EnvMapError::UnknownExtension { path: owned() }),
    }
    let bytes = read::read_head(path, Limit::Image, size).map_err(io_error)?;
    let image = match extension.as_deref() {
        Some("exr") => decode_exr(path, bytes)?,
        Some("hdr") => {
            let decoded = decode_rgbe(&bytes).map_err(|problem| EnvMapError::BadHdr { path: owned(), problem })?;
            EquirectImage { width: decoded.width, height: decoded.height, rgb: decoded.rgb }
        }
        _ => return Err(EnvMapError::UnknownExtension { path: owned() }),
    };
    check_pixels(path, &image)?;
    Ok(image)
}

/// Reads an EXR's headers alone (magic, attributes; at most
/// [`EXR_HEAD_MAX`] bytes) and refuses it before its pixels are read when a
/// part is over the pixel limit, or when the file is larger than its headers,
/// offset tables and every chunk stored uncompressed can take (OpenEXR
/// stores a chunk uncompressed when compressing does not shrink it; 64 bytes
/// of chunk header each, `exr`'s `max_pixel_file_bytes`). Deep parts have no
/// such bound and are left to the decoder.
fn check_exr_size(path: &Path, size: u64) -> Result<(), EnvMapError> {
    use crate::files::{read, Limit};
    let owned = || path.to_path_buf();
    let magic = read::read_head(path, Limit::Image, EXR_MAGIC.len() as u64).map_err(|source| EnvMapError::Io { path: owned(), source })?;
    if magic != EXR_MAGIC {
        return Err(EnvMapError::NotExr { path: owned() });
    }
    let mut reader =
        read::HeadReader::open(path, Limit::Image, EXR_HEAD_MAX).map_err(|source| EnvMapError::Io { path: owned(), source })?;
    let meta = exr::meta::MetaData::read_from_buffered(&mut reader, false).map_err(|source| EnvMapError::Exr { path: owned(), source })?;
    let mut bound = reader.bytes_read();
    for header in &meta.headers {
        let (width, height) = (header.layer_size.width() as u64, header.layer_size.height() as u64);
        if width.saturating_mul(height) > MAX_PIXELS {
            return Err(EnvMapError::TooLarge { path: owned(), width, height });
        }
        if header.deep {
            return Ok(());
        }
        bound += 8 * header.chunk_count as u64 + header.max_pixel_file_bytes() as u64;
    }
    if size > bound {
        let (width, height) = meta.headers.first().map_or((0, 0), |h| (h.layer_size.width() as u64, h.layer_size.height() as u64));
        return Err(EnvMapError::Oversized { path: owned(), size, width, height, bound });
    }
    Ok(())
}

fn decode_exr(path: &Path, bytes: Vec<u8>) -> Result<EquirectImage, EnvMapError> {
    use exr::prelude::*;
    let owned = || path.to_path_buf();
    if !bytes.starts_with(&EXR_MAGIC) {
        return Err(EnvMapError::NotExr { path: owned() });
    }
    let exr_error = |source| EnvMapError::Exr { path: owned(), source };
    // Check channels and size from the headers before decoding any pixels.
    let meta = MetaData::read_from_buffered(Cursor::new(&bytes), false).map_err(exr_error)?;
    let has_rgb = |header: &exr::meta::header::Header| {
        let names: Vec<String> = header.channels.list.iter().map(|c| c.name.to_string()).collect();
        ["R", "G", "B"].iter().all(|want| names.iter().any(|n| n == want))
    };
    let Some(header) = meta.headers.iter().find(|h| has_rgb(h)) else {
        let found = meta
            .headers
            .first()
            .map(|h| h.channels.list.iter().map(|c| c.name.to_string()).collect::<Vec<_>>().join(", "))
            .unwrap_or_default();
        return Err(EnvMapError::NoRgbChannels { path: owned(), found });
    };
    let (width, height) = (header.layer_size.width() as u64, header.layer_size.height() as u64);
    check_size(path, width, height)?;

    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .rgba_channels(
            |size, _| (size.width(), vec![[0.0_f32; 3]; size.area()]),
            |pixels: &mut (usize, Vec<[f32; 3]>), position: Vec2<usize>, (r, g, b, _a): (f32, f32, f32, f32)| {
                let index = position.y() * pixels.0 + position.x();
                if let Some(p) = pixels.1.get_mut(index) {
                    *p = [r, g, b];
                }
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))
        .map_err(exr_error)?;
    let size = image.layer_data.size;
    Ok(EquirectImage { width: size.width() as u32, height: size.height() as u32, rgb: image.layer_data.channel_data.pixels.1 })
}

fn check_size(path: &Path, width: u64, height: u64) -> Result<(), EnvMapError> {
    if width == 0 || height == 0 {
        return Err(EnvMapError::ZeroSize { path: path.to_path_buf(), width, height });
    }
    if width.saturating_mul(height) > MAX_PIXELS {
        return Err(EnvMapError::TooLarge { path: path.to_path_buf(), width, height });
    }
    Ok(())
}

/// Size limits and the refusal of NaN / infinite pixels, for every format.
fn check_pixels(path: &Path, image: &EquirectImage) -> Result<(), EnvMapError> {
    check_size(path, u64::from(image.width), u64::from(image.height))?;
    let width = image.width as usize;
    if let Some(index) = image.rgb.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(EnvMapError::NonFinite {
            path: path.to_path_buf(),
            col: (index % width) as u32,
            row: (index / width) as u32,
            value: image.rgb[index],
        });
    }
    Ok(())
}

/// World direction of texture coordinates (u, v) ∈ [0,1]²: θ = π·v from +Y,
/// φ = 2π(u − 0.5), direction (sin θ sin φ, cos θ, −sin θ cos φ).
pub fn equirect_direction(u: f64, v: f64) -> DVec3 {
    let (sin_theta, cos_theta) = (PI * v).sin_cos();
    let (sin_phi, cos_phi) = (2.0 * PI * (u - 0.5)).sin_cos();
    DVec3::new(sin_theta * sin_phi, cos_theta, -sin_theta * cos_phi)
}

/// Texture coordinates (u, v) of a unit world direction; inverse of
/// [`equirect_direction`] (u ∈ [0, 1), v ∈ [0, 1]; at the poles u is 0.5).
pub fn equirect_uv(dir: DVec3) -> (f64, f64) {
    let v = dir.y.clamp(-1.0, 1.0).acos() / PI;
    let phi = dir.x.atan2(-dir.z); // −π..π, 0 toward −Z
    let u = (phi / (2.0 * PI) + 0.5).rem_euclid(1.0);
    (u, v)
}

/// Rows per parallel work item. Fixed, so sums are formed in the same order
/// whatever the thread count (same input ⇒ same bits).
const ROWS_PER_BLOCK: usize = 8;

/// Projects an equirect image onto SH: `L_i = ∫ L(ω) y_i(ω) dω` per RGB
/// channel, each pixel weighted by its exact solid angle
/// `(cos θ0 − cos θ1) · 2π/W` (θ0, θ1 its row's edges) and sampled at its
/// centre direction. Accumulates in f64, parallel over blocks of rows,
/// deterministic. Returns `order²` RGB coefficients.
///
/// Precondition: `rgb.len() == width·height`; a shorter buffer projects only
/// its complete rows, an empty image gives zeros. Non-finite pixels
/// propagate (images from [`load_equirect`] have none).
pub fn project_equirect(image: &EquirectImage, order: usize) -> Vec<[f32; 3]> {
    let n = coeff_count(order);
    let (width, height) = (image.width as usize, image.height as usize);
    if width == 0 || height == 0 {
        return vec![[0.0; 3]; n];
    }
    // Longitudes are the same in every row: tabulate sin φ, cos φ once.
    let longitudes: Vec<(f64, f64)> = (0..width).map(|col| (2.0 * PI * ((col as f64 + 0.5) / width as f64 - 0.5)).sin_cos()).collect();
    let rows: Vec<&[[f32; 3]]> = image.rgb.chunks_exact(width).take(height).collect();
    let block_sums: Vec<Vec<[f64; 3]>> = rows
        .par_chunks(ROWS_PER_BLOCK)
        .enumerate()
        .map(|(block, block_rows)| {
            let mut acc = vec![[0.0_f64; 3]; n];
            let mut y = vec![0.0_f64; n];
            for (k, pixels) in block_rows.iter().enumerate() {
                let row = block * ROWS_PER_BLOCK + k;
                let theta0 = PI * row as f64 / height as f64;
                let theta1 = PI * (row + 1) as f64 / height as f64;
                let solid_angle = (theta0.cos() - theta1.cos()) * 2.0 * PI / width as f64;
                let (sin_theta, cos_theta) = (PI * (row as f64 + 0.5) / height as f64).sin_cos();
                for (pixel, &(sin_phi, cos_phi)) in pixels.iter().zip(&longitudes) {
                    let dir = DVec3::new(sin_theta * sin_phi, cos_theta, -sin_theta * cos_phi);
                    eval_basis_f64(order, dir, &mut y);
                    let radiance = pixel.map(|c| f64::from(c) * solid_angle);
                    for (a, &yi) in acc.iter_mut().zip(&y) {
                        for c in 0..3 {
                            a[c] += radiance[c] * yi;
                        }
                    }
                }
            }
            acc
        })
        .collect();
    let total = block_sums.into_iter().fold(vec![[0.0_f64; 3]; n], add_rows);
    total.into_iter().map(|c| c.map(|v| v as f32)).collect()
}

#[cfg(test)]
#[path = "envmap_tests.rs"]
mod tests;
