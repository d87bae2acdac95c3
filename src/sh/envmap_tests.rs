//! Tests of env map loading and projection (kept apart: envmap.rs stays short).

use std::path::PathBuf;

use glam::{DVec3, Mat3};

use super::*;
use crate::sh::{eval_basis_f64, project_function, EnvMapError, ShRotation};

/// Midpoint sampling of smooth band-≤3 functions on a 512×256 grid with exact
/// row solid angles: error O(1/H²) ≈ 1e-5; 1e-3 is the brief's bound.
const PROJECTION_TOL: f32 = 1e-3;
/// RGBE keeps 8 mantissa bits; decoding at the bucket midpoint is within
/// half a bucket: relative 1/256 of the largest channel (1/128 for margin).
const RGBE_REL_TOL: f32 = 1.0 / 128.0;

fn temp_path(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("prtbake_sh_{}_{name}", std::process::id()))
}

/// An image whose pixel (col, row) holds `f` of its centre direction.
fn image_from_fn(width: u32, height: u32, f: impl Fn(DVec3) -> [f32; 3]) -> EquirectImage {
    let mut rgb = Vec::with_capacity((width * height) as usize);
    for row in 0..height {
        for col in 0..width {
            let u = (f64::from(col) + 0.5) / f64::from(width);
            let v = (f64::from(row) + 0.5) / f64::from(height);
            rgb.push(f(equirect_direction(u, v)));
        }
    }
    EquirectImage { width, height, rgb }
}

#[test]
fn direction_conventions_hold() {
    let centre = equirect_direction(0.5, 0.5);
    assert!((centre - DVec3::NEG_Z).length() < 1e-12, "image centre looks toward −Z");
    assert!((equirect_direction(0.75, 0.5) - DVec3::X).length() < 1e-12, "u = 0.75 looks toward +X");
    assert!((equirect_direction(0.25, 0.5) - DVec3::NEG_X).length() < 1e-12);
    assert!((equirect_direction(0.3, 0.0) - DVec3::Y).length() < 1e-12, "top row is +Y");
    for k in 0..50 {
        let (u, v) = ((k as f64 * 0.137).fract(), 0.01 + 0.98 * (k as f64 * 0.291).fract());
        let (u2, v2) = equirect_uv(equirect_direction(u, v));
        assert!((u - u2).abs() < 1e-12 && (v - v2).abs() < 1e-12, "({u}, {v}) → ({u2}, {v2})");
    }
}

#[test]
fn projecting_basis_function_images_gives_unit_vectors() {
    let order = 4;
    let mut worst = 0.0_f32;
    for j in 0..coeff_count(order) {
        let image = image_from_fn(512, 256, |d| {
            let mut y = [0.0; 16];
            eval_basis_f64(order, d, &mut y);
            [y[j] as f32, 0.5 * y[j] as f32, 0.0]
        });
        let coeffs = project_equirect(&image, order);
        for (i, c) in coeffs.iter().enumerate() {
            let e = if i == j { 1.0 } else { 0.0 };
            worst = worst.max((c[0] - e).abs()).max((c[1] - 0.5 * e).abs()).max(c[2].abs());
        }
    }
    eprintln!("y_j image (512×256) projects to e_j within {worst:.2e}");
    assert!(worst < PROJECTION_TOL);
}

/// A constant map: DC is exact (row solid angles sum to 4π exactly), and the
/// other coefficients vanish up to the midpoint error in θ of each row,
/// Σ (Δθ²/24)·|d²y/dθ²|·dω ≈ 2e-4 per unit radiance at H = 128 (measured
/// 1.98e-4; it falls as 1/H²). Bound 5e-4 per unit radiance.
#[test]
fn constant_map_projects_to_dc_only() {
    const OFF_DC_TOL: f32 = 5e-4;
    let c = 2.5_f32;
    let image = EquirectImage { width: 256, height: 128, rgb: vec![[c, 0.0, 1.0]; 256 * 128] };
    let coeffs = project_equirect(&image, 5);
    let expected = c * (4.0 * std::f32::consts::PI).sqrt(); // c·4π·y_00
    assert!((coeffs[0][0] - expected).abs() < 1e-6 * expected);
    let worst = coeffs[1..].iter().flatten().fold(0.0_f32, |m, v| m.max(v.abs()));
    eprintln!("constant 256×128 map: L_00 = {} (exact {expected}), max |off-DC| = {worst:.2e} for c = {c}", coeffs[0][0]);
    assert!(worst < OFF_DC_TOL * c);
    assert_eq!(project_equirect(&EquirectImage { width: 0, height: 0, rgb: vec![] }, 3), vec![[0.0; 3]; 9]);
}

#[test]
fn projection_is_deterministic_across_thread_counts() {
    let image = image_from_fn(128, 64, |d| [(3.0 * d.x).exp() as f32, d.y as f32, 1.0]);
    let run =
        |threads| rayon::ThreadPoolBuilder::new().num_threads(threads).build().map(|pool| pool.install(|| project_equirect(&image, 6)));
    let (one, two) = (run(1), run(2));
    assert!(one.is_ok());
    assert_eq!(one.ok(), two.ok());
}

/// DESIGN oracle: rotation commutes with projection. f = exp(2 ω·a) is
/// smooth, so 40-node quadrature is accurate to ~1e-12 and the truncation
/// at order 6 commutes with rotation exactly; f32 rotation leaves ~1e-6.
#[test]
fn rotation_commutes_with_projection() {
    let order = 6;
    let a = DVec3::new(0.3, -0.8, 0.5).normalize();
    let r = Mat3::from_axis_angle(glam::Vec3::new(1.0, 1.0, 0.0).normalize(), 1.2);
    let rt = r.transpose().as_dmat3();
    let f = |d: DVec3| [(2.0 * d.dot(a)).exp(); 3];
    let original = project_function(order, 40, f);
    let rotated_function = project_function(order, 40, |d| f(rt * d));
    let mut rotated_coeffs = vec![[0.0; 3]; coeff_count(order)];
    ShRotation::new(order, r).apply_rgb(&original, &mut rotated_coeffs);
    for (x, y) in rotated_function.iter().zip(&rotated_coeffs) {
        assert!((x[0] - y[0]).abs() < 1e-4 * original[0][0], "{x:?} vs {y:?}");
    }
}

#[test]
fn exr_round_trip_float_and_half() {
    let (w, h) = (64usize, 32usize);
    let value = |x: usize, y: usize| (x as f32 / 8.0, y as f32 / 4.0, 0.25);
    let float_path = temp_path("float.exr");
    assert!(exr::prelude::write_rgba_file(&float_path, w, h, |x, y| {
        let (r, g, b) = value(x, y);
        (r, g, b, 1.0_f32)
    })
    .is_ok());
    let image = load_equirect(&float_path);
    let _ = std::fs::remove_file(&float_path);
    let image = image.unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((image.width, image.height), (w as u32, h as u32));
    for (i, p) in image.rgb.iter().enumerate() {
        let (r, g, b) = value(i % w, i / w);
        assert_eq!(*p, [r, g, b], "pixel {i}: row 0 is the first row written");
    }
    let coeffs = project_equirect(&image, 3);
    assert!(coeffs.iter().flatten().all(|c| c.is_finite()) && coeffs[0][2] > 0.0);

    // Half-float RGB without alpha, ZIP compression.
    use exr::prelude::*;
    let half_path = temp_path("half.EXR");
    let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
        let (r, g, b) = value(x, y);
        (f16::from_f32(r), f16::from_f32(g), f16::from_f32(b))
    });
    let encoding = Encoding { compression: Compression::ZIP16, ..Encoding::default() };
    assert!(Image::from_encoded_channels((w, h), encoding, channels).write().to_file(&half_path).is_ok());
    let image = load_equirect(&half_path);
    let _ = std::fs::remove_file(&half_path);
    let image = image.unwrap_or_else(|e| panic!("{e}"));
    for (i, p) in image.rgb.iter().enumerate() {
        let (r, g, b) = value(i % w, i / w);
        assert_eq!(*p, [r, g, b], "these values are exact in f16");
    }
}

#[test]
fn exr_errors_are_typed_and_name_the_file() {
    use exr::prelude::*;
    // Luminance only: no RGB.
    let y_path = temp_path("luminance.exr");
    let channels = AnyChannels::sort(SmallVec::from_vec(vec![AnyChannel::new("Y", FlatSamples::F32(vec![0.5; 16]))]));
    assert!(Image::from_channels((4, 4), channels).write().to_file(&y_path).is_ok());
    let result = load_equirect(&y_path);
    let _ = std::fs::remove_file(&y_path);
    match result {
        Err(e @ EnvMapError::NoRgbChannels { .. }) => assert!(e.to_string().contains("luminance.exr") && e.to_string().contains('Y')),
        other => panic!("expected NoRgbChannels, got {other:?}"),
    }
    // NaN pixel.
    let nan_path = temp_path("nan.exr");
    assert!(
        write_rgb_file(&nan_path, 4, 4, |x, y| if (x, y) == (2, 1) { (f32::NAN, 0.0, 0.0) } else { (1.0_f32, 1.0_f32, 1.0_f32) }).is_ok()
    );
    let result = load_equirect(&nan_path);
    let _ = std::fs::remove_file(&nan_path);
    assert!(matches!(result, Err(EnvMapError::NonFinite { col: 2, row: 1, .. })), "{result:?}");
    // Garbage, and the magic followed by garbage.
    let garbage_path = temp_path("garbage.exr");
    assert!(std::fs::write(&garbage_path, b"this is not an image at all").is_ok());
    assert!(matches!(load_equirect(&garbage_path), Err(EnvMapError::NotExr { .. })));
    let mut bytes = vec![0x76, 0x2f, 0x31, 0x01];
    bytes.extend((0..500u32).map(|i| (i * 7 + 3) as u8));
    assert!(std::fs::write(&garbage_path, &bytes).is_ok());
    let result = load_equirect(&garbage_path);
    let _ = std::fs::remove_file(&garbage_path);
    assert!(matches!(result, Err(EnvMapError::Exr { .. })), "{result:?}");
    // Missing file, unknown extension.
    let missing = temp_path("does_not_exist.exr");
    match load_equirect(&missing) {
        Err(e @ EnvMapError::NotFound { .. }) => assert!(e.to_string().contains("does_not_exist.exr")),
        other => panic!("expected NotFound, got {other:?}"),
    }
    let png_path = temp_path("map.png");
    assert!(std::fs::write(&png_path, b"\x89PNG").is_ok());
    let result = load_equirect(&png_path);
    let _ = std::fs::remove_file(&png_path);
    assert!(matches!(result, Err(EnvMapError::UnknownExtension { .. })));
}

/// Radiance's float2rgbe: shared exponent from the largest channel.
fn float_to_rgbe(p: [f32; 3]) -> [u8; 4] {
    let max = p.iter().cloned().fold(0.0_f32, f32::max);
    if max < 1e-32 {
        return [0; 4];
    }
    let exponent = max.log2().floor() as i32 + 1; // max = m·2^e, m ∈ [0.5, 1)
    let scale = 256.0 / 2f32.powi(exponent);
    [(p[0] * scale) as u8, (p[1] * scale) as u8, (p[2] * scale) as u8, (exponent + 128) as u8]
}

/// A tiny RGBE writer: header, then flat or new-style RLE scanlines.
fn encode_hdr(width: usize, height: usize, pixels: &[[f32; 3]], rle: bool, bottom_up: bool) -> Vec<u8> {
    let y_axis = if bottom_up { "+Y" } else { "-Y" };
    let mut out = format!("#?RADIANCE\nFORMAT=32-bit_rle_rgbe\nEXPOSURE=1.0\n\n{y_axis} {height} +X {width}\n").into_bytes();
    let rows: Vec<&[[f32; 3]]> = pixels.chunks(width).collect();
    let ordered: Vec<&[[f32; 3]]> = if bottom_up { rows.into_iter().rev().collect() } else { rows };
    for row in ordered {
        let rgbe: Vec<[u8; 4]> = row.iter().map(|&p| float_to_rgbe(p)).collect();
        if !rle {
            out.extend(rgbe.iter().flatten());
            continue;
        }
        out.extend([2, 2, (width >> 8) as u8, (width & 0xff) as u8]);
        for channel in 0..4 {
            let plane: Vec<u8> = rgbe.iter().map(|p| p[channel]).collect();
            let mut x = 0;
            while x < plane.len() {
                // A run of equal bytes, or a literal of up to 128.
                let run = plane[x..].iter().take(127).take_while(|&&b| b == plane[x]).count();
                if run >= 3 {
                    out.extend([128 + run as u8, plane[x]]);
                    x += run;
                } else {
                    let len = (plane.len() - x).min(128);
                    out.push(len as u8);
                    out.extend(&plane[x..x + len]);
                    x += len;
                }
            }
        }
    }
    out
}

#[test]
fn hdr_round_trip_flat_rle_and_bottom_up() {
    let (w, h) = (40usize, 20usize);
    // Runs of equal pixels (left half) and varied ones (right half).
    let pixels: Vec<[f32; 3]> =
        (0..w * h).map(|i| if i % w < 20 { [3.0, 3.0, 0.5] } else { [(i as f32 * 0.37).sin().abs() * 100.0, 0.01, 1.0] }).collect();
    for (rle, bottom_up) in [(false, false), (true, false), (true, true)] {
        let path = temp_path(&format!("rt_{rle}_{bottom_up}.hdr"));
        assert!(std::fs::write(&path, encode_hdr(w, h, &pixels, rle, bottom_up)).is_ok());
        let image = load_equirect(&path);
        let _ = std::fs::remove_file(&path);
        let image = image.unwrap_or_else(|e| panic!("rle={rle}: {e}"));
        assert_eq!((image.width, image.height), (w as u32, h as u32));
        for (got, want) in image.rgb.iter().zip(&pixels) {
            let max = want.iter().cloned().fold(0.0_f32, f32::max);
            for c in 0..3 {
                assert!((got[c] - want[c]).abs() <= RGBE_REL_TOL * max, "rle={rle} bottom_up={bottom_up}: {got:?} vs {want:?}");
            }
        }
    }
}

#[test]
fn hdr_bad_bytes_give_errors_never_panics() {
    let (w, h) = (16usize, 4usize);
    let pixels = vec![[1.0, 2.0, 3.0]; w * h];
    let full = encode_hdr(w, h, &pixels, true, false);
    let path = temp_path("trunc.hdr");
    // Every truncation of a valid file is an error (the last one is the file itself).
    for len in 0..full.len() {
        assert!(std::fs::write(&path, &full[..len]).is_ok());
        assert!(load_equirect(&path).is_err(), "truncated at {len} of {}", full.len());
    }
    let bad_inputs: [&[u8]; 8] = [
        b"#?RADIANCE\n\n-Y 4000000000 +X 0\n",
        b"#?RADIANCE\n\n-Y 1 +X 100000000\n",
        b"not a radiance file",
        b"#?RADIANCE\nFORMAT=32-bit_rle_xyze\n\n-Y 1 +X 1\n\x80\x80\x80\x80",
        b"#?RADIANCE\n\n+X 1 -Y 1\n\x80\x80\x80\x80",
        b"#?RADIANCE\n\n-Y 0 +X 1\n",
        b"#?RADIANCE\n\n-Y 99999 +X 99999\n",
        b"#?RADIANCE\n\n-Y 1 +X 8\n\x02\x02\x00\x09garbage",
    ];
    for bytes in bad_inputs {
        assert!(std::fs::write(&path, bytes).is_ok());
        let result = load_equirect(&path);
        assert!(matches!(result, Err(EnvMapError::BadHdr { .. } | EnvMapError::ZeroSize { .. })), "{result:?}");
    }
    let _ = std::fs::remove_file(&path);
}

#[test]
fn real_sunset_exr_projects_to_finite_coefficients() {
    let path = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/hdri-cc0/sunset.exr"));
    if !path.exists() {
        eprintln!("skipping real_sunset_exr_projects_to_finite_coefficients: {} is absent", path.display());
        return;
    }
    let image = load_equirect(&path).unwrap_or_else(|e| panic!("{e}"));
    let coeffs = project_equirect(&image, 4);
    assert!(coeffs.iter().flatten().all(|c| c.is_finite()));
    assert!(coeffs[0].iter().all(|&c| c > 0.0));
    eprintln!("sunset.exr {}×{}: L_00 = {:?}, L_1m = {:?}", image.width, image.height, coeffs[0], &coeffs[1..4]);
}

#[test]
fn projection_of_analytic_sky_matches_image_projection() {
    // The same smooth function through both projectors agrees: checks the
    // equirect direction mapping against the SH frame.
    let order = 4;
    let f = |d: DVec3| [(1.0 + d.y).powi(2) + 0.5 * d.x, 1.0 + d.z, 0.0];
    let from_image = project_equirect(&image_from_fn(512, 256, |d| f(d).map(|v| v as f32)), order);
    let analytic = project_function(order, 16, f);
    for (a, b) in from_image.iter().zip(&analytic) {
        assert!((a[0] - b[0]).abs() < PROJECTION_TOL && (a[1] - b[1]).abs() < PROJECTION_TOL, "{a:?} vs {b:?}");
    }
}

/// An EXR or a Radiance HDR larger than the image its header describes can
/// take (a valid map extended to a sparse 3 GiB) is refused after its
/// header, naming the file, its size and the image's; the maps themselves load.
#[test]
fn maps_larger_than_their_headers_allow_are_refused_after_the_header() {
    use crate::files::read::bytes_read;
    let big = 3u64 << 30;
    let exr = temp_path("grown.exr");
    assert!(exr::prelude::write_rgb_file(&exr, 64, 32, |x, _| (x as f32, 1.0_f32, 0.5_f32)).is_ok());
    let hdr = temp_path("grown.hdr");
    assert!(std::fs::write(&hdr, encode_hdr(40, 20, &vec![[1.0, 2.0, 3.0]; 800], true, false)).is_ok());
    for (path, size) in [(&exr, "64×32"), (&hdr, "40×20")] {
        let len = std::fs::metadata(path).unwrap().len();
        bytes_read::take();
        assert!(load_equirect(path).is_ok());
        assert!(bytes_read::take() >= len);
        std::fs::OpenOptions::new().write(true).open(path).unwrap().set_len(big).unwrap();
        let result = load_equirect(path);
        let read = bytes_read::take();
        let _ = std::fs::remove_file(path);
        let message = match result {
            Err(e @ EnvMapError::Oversized { .. }) => e.to_string(),
            other => panic!("{}: expected Oversized, got {other:?}", path.display()),
        };
        assert!(
            message.contains(&path.display().to_string()) && message.contains(&format!("is {big} bytes")) && message.contains(size),
            "{message}"
        );
        assert!(read <= 64 << 10, "{}: {read} bytes read to refuse it", path.display());
    }
}
