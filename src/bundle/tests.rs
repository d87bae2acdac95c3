//! Whole-bundle tests: round trips, determinism, golden bytes, and hostile input
//! (truncation at every length, bit flips, bumped versions, forged counts, forged
//! values). The fuzz test, built on the helpers here, is `fuzz_tests.rs`.

use glam::{Vec2, Vec3};

use super::container::write_container;
use super::*;
use crate::mesh::{Material, MaterialRole, Mesh};

/// xorshift64*: deterministic test randomness without a dependency.
pub(super) struct Rng(pub(super) u64);
impl Rng {
    pub(super) fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    pub(super) fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
    pub(super) fn signed(&mut self) -> f32 {
        self.unit() * 2.0 - 1.0
    }
    pub(super) fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// A random mesh with every optional attribute.
pub(super) fn random_mesh(rng: &mut Rng, vertices: usize, triangles: usize) -> Mesh {
    let v3 = |rng: &mut Rng| Vec3::new(rng.signed(), rng.signed(), rng.signed());
    Mesh {
        positions: (0..vertices).map(|_| v3(rng) * 10.0).collect(),
        normals: (0..vertices).map(|_| v3(rng).normalize_or(Vec3::Y)).collect(),
        uvs: (0..vertices).map(|_| Vec2::new(rng.unit(), rng.unit())).collect(),
        // Not drawn from `rng`, so the other values stay those the tests name.
        lightmap_uvs: (0..vertices).map(|v| Vec2::new((v % 7) as f32 / 7.0, (v % 5) as f32 / 5.0)).collect(),
        colors: (0..vertices).map(|_| [rng.unit(), rng.unit(), rng.unit()]).collect(),
        indices: (0..3 * triangles).map(|_| rng.below(vertices) as u32).collect(),
        tri_material: (0..triangles).map(|_| rng.below(2) as u16).collect(),
        tri_group: (0..triangles).map(|_| rng.below(3) as u32).collect(),
        materials: vec![
            Material::opaque("stone", 0.6),
            Material { name: "glass ü".into(), albedo: [0.1, 0.2, 0.3], role: MaterialRole::Window, transmittance: 0.8 },
        ],
        groups: vec!["cella".into(), "".into(), "frieze".into()],
    }
}

pub(super) fn random_transfer(rng: &mut Rng, vertices: usize, quantization: Quantization) -> Transfer {
    let (order, channels) = (3u32, 3u32);
    let n = vertices * (channels * order * order) as usize;
    let layer = |rng: &mut Rng, kind| TransferLayer { kind, data: (0..n).map(|_| rng.signed() * 0.9).collect() };
    Transfer {
        order,
        channels,
        quantization,
        layers: vec![layer(rng, LayerKind::Bounce(0)), layer(rng, LayerKind::Total)],
        // Side shares (SIDE) in every random bundle: round trips and the fuzzer read them.
        front_share: (0..vertices).map(|v| ((v * 37) % 256) as f32 / 255.0).collect(),
    }
}

pub(super) fn random_sun(rng: &mut Rng, vertices: usize, step_count: usize) -> SunSeries {
    let sky_order = 3;
    let steps = (0..step_count)
        .map(|k| SunStep {
            unix_time_utc: 1_782_000_000.0 + 420.0 * k as f64,
            direction: Vec3::new(rng.signed(), rng.unit(), rng.signed()).normalize_or(Vec3::Y).to_array(),
            elevation_deg: rng.unit() * 90.0,
            azimuth_deg: rng.unit() * 360.0,
            sun_rgb: [rng.unit() * 900.0, rng.unit() * 900.0, rng.unit() * 900.0],
            night: k % 17 == 0,
            sky_sh: (0..sky_order * sky_order).map(|_| [rng.signed(), rng.signed(), rng.signed()]).collect(),
        })
        .collect();
    let bits: Vec<bool> = (0..vertices * step_count).map(|_| rng.next() & 1 == 1).collect();
    let (words_per_vertex, masks) = SunSeries::pack(step_count, vertices, |v, k| bits[v * step_count + k]);
    SunSeries::per_vertex(sky_order as u32, steps, words_per_vertex, masks)
}

fn random_bundle(seed: u64, vertices: usize, triangles: usize, quantization: Quantization) -> Bundle {
    let mut rng = Rng(seed);
    let meta = serde_json::json!({
        "tool": "prtbake 0.1.0", "seed": seed, "params": {"order": 3, "bounces": 1, "samples": 256},
        "conventions": {"sh_index": "l(l+1)+m", "up": "+Y"}, "stats": {"max_error": 0.25}
    });
    Bundle {
        meta,
        mesh: random_mesh(&mut rng, vertices, triangles),
        transfer: Some(random_transfer(&mut rng, vertices, quantization)),
        sun: Some(random_sun(&mut rng, vertices, 92)),
        texels: None,
    }
}

/// The smallest bundle: one triangle, META `{}`, no transfer or sun, every section raw.
pub(super) fn tiny_bundle() -> Bundle {
    Bundle {
        meta: serde_json::json!({}),
        mesh: Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            normals: vec![Vec3::Z; 3],
            indices: vec![0, 1, 2],
            tri_material: vec![0],
            tri_group: vec![0],
            materials: vec![Material::opaque("m", 0.5)],
            groups: vec!["g".into()],
            ..Mesh::default()
        },
        transfer: None,
        sun: None,
        texels: None,
    }
}

/// A small bundle with every section, regular enough that zstd shrinks each one:
/// the content of [`GOLDEN_1_0_ZSTD`].
pub(super) fn small_regular_bundle() -> Bundle {
    let corners: Vec<Vec3> = (0..8).map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32)).collect();
    let quads = [[0u32, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    let indices: Vec<u32> = quads.iter().flat_map(|q| [q[0], q[1], q[2], q[0], q[2], q[3]]).collect();
    let mesh = Mesh {
        normals: corners.iter().map(|p| (*p - Vec3::splat(0.5)).normalize()).collect(),
        positions: corners,
        indices,
        tri_material: vec![0; 12],
        tri_group: vec![0; 12],
        materials: vec![Material::opaque("stone", 0.5)],
        groups: vec!["box".into()],
        ..Mesh::default()
    };
    let transfer = Transfer {
        order: 2,
        channels: 1,
        quantization: Quantization::F16,
        layers: vec![TransferLayer { kind: LayerKind::Total, data: (0..32).map(|i| [0.5, 0.25, 0.0, -0.25][i % 4]).collect() }],
        front_share: Vec::new(),
    };
    let step = |k: usize| SunStep {
        unix_time_utc: 1_782_000_000.0 + 3600.0 * k as f64,
        direction: [0.0, 1.0, 0.0],
        elevation_deg: 90.0,
        azimuth_deg: 0.0,
        sun_rgb: [1000.0, 900.0, 800.0],
        night: false,
        sky_sh: vec![[0.5, 0.5, 0.75]],
    };
    let (words_per_vertex, masks) = SunSeries::pack(2, 8, |v, k| (v + k) % 2 == 0);
    Bundle {
        meta: serde_json::json!({"tool": "prtbake golden", "note": "aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa"}),
        mesh,
        transfer: Some(transfer),
        sun: Some(SunSeries {
            sky_order: 1,
            steps: vec![step(0), step(1)],
            words_per_vertex,
            masks,
            texel_masks: Vec::new(),
            texel_fractions: Vec::new(),
            texel_atlas: None,
        }),
        texels: None,
    }
}

/// [`small_regular_bundle`] as a format 1.0 writer (before the stored-bytes CRC)
/// wrote it with the default options: every section zstd, table word 36 zero.
/// Kept as bytes so that 1.0 files stay readable whatever the writer does now.
const GOLDEN_1_0_ZSTD: &str = "
    50525442 0d0a1a0a 01000000 06000000 78020000 00000000 00000000 cfd62f9a
    4d455441 01000000 10010000 00000000 34000000 00000000 65000000 00000000
    64a9e921 00000000 4d455348 01000000 48010000 00000000 7b000000 00000000
    a4010000 00000000 616c4e29 00000000 4d41544c 01000000 c8010000 00000000
    2e000000 00000000 30000000 00000000 0f6d4515 00000000 58464552 01000000
    f8010000 00000000 1f000000 00000000 58000000 00000000 958b9c4f 00000000
    53554e4d 01000000 18020000 00000000 1e000000 00000000 30000000 00000000
    90f81a44 00000000 53554e44 01000000 38020000 00000000 3c000000 00000000
    78000000 00000000 c23c4952 00000000 28b52ffd 20655d01 0044027b 226e6f74
    65223a22 61222c22 746f6f6c 223a2270 72746261 6b652067 6f6c6465 6e227d01
    00960012 00000000 28b52ffd 60a4008d 03001403 08000000 0c00803f 803f803f
    803f3acd 13bf3f3f 02000000 03010000 00040000 00050000 00070601 00040602
    04060107 071da0a0 304b6b07 70023997 1e81908b e8747107 ee4f7cf5 aceeda3d
    ec2ef777 4f3cd6fd defa0a99 38768409 4bf5bf6e 20988dff cebad24f 3bc296ca
    4d3b1900 00000000 28b52ffd 20302d01 00e80100 00000100 3f803f05 00000073
    746f6e65 00000003 00000062 6f780002 00bb2d0a 50040000 28b52ffd 2058b500
    00600200 00000138 00340000 00b40300 5d390634 d8705a00 28b52ffd 2030ad00
    00580200 00000100 00000800 0203002b 212f0b60 00090000 28b52ffd 20789d01
    00f00200 00000100 60ca8dda 41803fb4 427a4400 00614400 00484400 3f40e4cd
    0800d8ea 7065b11d 6e334707 03af0cec 32fa0245 00000000";

fn unhex(text: &str) -> Vec<u8> {
    let digits: Vec<u8> = text.bytes().filter(u8::is_ascii_hexdigit).collect();
    digits.chunks(2).map(|p| u8::from_str_radix(std::str::from_utf8(p).unwrap(), 16).unwrap()).collect()
}

pub(super) fn small_zstd_bytes() -> Vec<u8> {
    encode_bundle(&small_regular_bundle()).unwrap()
}

fn tiny_bytes() -> Vec<u8> {
    encode_bundle_with(&tiny_bundle(), EncodeOptions { compression: Compression::None }).unwrap()
}

fn small_bytes() -> Vec<u8> {
    encode_bundle(&random_bundle(7, 12, 10, Quantization::F32)).unwrap()
}

fn half_ulp(v: f32) -> f64 {
    let a = v.abs();
    ((f32::from_bits(a.to_bits() + 1) - a) as f64) / 2.0
}

// ---------------------------------------------------------------- round trips

#[test]
fn f32_round_trip_is_bit_exact() {
    let bundle = random_bundle(1, 200, 300, Quantization::F32);
    let bytes = encode_bundle(&bundle).unwrap();
    let back = decode_bundle(&bytes).unwrap();
    assert_eq!(back, bundle);
    let tags: Vec<String> = list_sections(&bytes).unwrap().iter().map(|s| s.tag_name()).collect();
    assert_eq!(tags, ["META", "MESH", "MATL", "XFER", "SIDE", "SUNM", "SUND"]);
    let sun = back.sun.unwrap();
    assert_eq!(sun.words_per_vertex, 3); // 92 steps
}

/// Asserts the documented per-value bound for `q` on every transfer value and
/// that everything else in the bundle is exact.
fn assert_lossy_round_trip(q: Quantization) -> (f64, usize) {
    let bundle = random_bundle(2, 150, 200, q);
    let back = decode_bundle(&encode_bundle(&bundle).unwrap()).unwrap();
    assert_eq!((&back.meta, &back.mesh, &back.sun), (&bundle.meta, &bundle.mesh, &bundle.sun));
    let (t, u) = (bundle.transfer.as_ref().unwrap(), back.transfer.as_ref().unwrap());
    assert_eq!((u.order, u.channels, u.quantization), (t.order, t.channels, q));
    let stride = t.values_per_vertex() as usize;
    let mut worst = 0.0f64;
    for (a, b) in t.layers.iter().zip(&u.layers) {
        assert_eq!(a.kind, b.kind);
        assert_eq!(a.data.len(), b.data.len());
        for (orig, got) in a.data.chunks(stride).zip(b.data.chunks(stride)) {
            let scale = i16_scale(orig) as f64;
            for (&v, &w) in orig.iter().zip(got) {
                let err = (v as f64 - w as f64).abs();
                let bound = match q {
                    Quantization::F16 => (v.abs() as f64 * 2f64.powi(-11)).max(2f64.powi(-25)),
                    _ => scale / 2.0 + half_ulp(w),
                };
                assert!(err <= bound, "{q:?}: v={v} got={w} err={err} bound={bound}");
                worst = worst.max(err);
            }
        }
        let (max_abs, _) = quantization_error(&a.data, t.channels, t.order, q);
        assert_eq!(max_abs, a.data.iter().zip(&b.data).map(|(v, w)| (*v as f64 - *w as f64).abs()).fold(0.0, f64::max));
    }
    (worst, encode_bundle(&bundle).unwrap().len())
}

#[test]
fn f16_round_trip_is_within_relative_bound() {
    let (worst, _) = assert_lossy_round_trip(Quantization::F16);
    assert!(worst > 0.0 && worst <= 0.9 * 2f64.powi(-11));
}

#[test]
fn i16_round_trip_is_within_half_a_step() {
    let (worst, _) = assert_lossy_round_trip(Quantization::I16PerVertexScale);
    assert!(worst > 0.0 && worst <= 0.9 / 32767.0 / 2.0 + 1e-7);
}

#[test]
fn decoded_f16_bundle_reencodes_to_the_same_bytes() {
    let bytes = encode_bundle(&random_bundle(3, 40, 50, Quantization::F16)).unwrap();
    assert_eq!(encode_bundle(&decode_bundle(&bytes).unwrap()).unwrap(), bytes);
}

#[test]
fn encoding_is_deterministic() {
    let bundle = random_bundle(4, 100, 120, Quantization::I16PerVertexScale);
    let first = encode_bundle(&bundle).unwrap();
    assert_eq!(encode_bundle(&bundle.clone()).unwrap(), first);
    assert_eq!(encode_bundle_with(&bundle, EncodeOptions::default()).unwrap(), first);
}

#[test]
fn sun_bits_pack_and_read_back() {
    let bits = |v: usize, k: usize| (v * 31 + k * 7) % 5 == 0;
    let (words_per_vertex, masks) = SunSeries::pack(92, 10, bits);
    assert_eq!((words_per_vertex, masks.len()), (3, 30));
    let mut sun = random_sun(&mut Rng(9), 10, 92);
    sun.masks = masks;
    for v in 0..10 {
        for k in 0..92 {
            assert_eq!(sun.bit(v, k), bits(v, k), "v={v} k={k}");
        }
        assert_eq!(sun.masks[v * 3 + 2] >> 28, 0, "steps 92..96 must be zero");
    }
    assert!(!sun.bit(10, 0) && !sun.bit(0, 92) && !sun.bit(usize::MAX, usize::MAX));
}

#[test]
fn write_then_read_file_round_trips_and_errors_name_the_path() {
    let dir = std::env::temp_dir().join(format!("prtb-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("scene.prtb");
    let bundle = random_bundle(5, 20, 20, Quantization::F32);
    write_bundle(&path, &bundle).unwrap();
    assert_eq!(read_bundle(&path).unwrap(), bundle);
    let leftovers: Vec<_> = std::fs::read_dir(&dir).unwrap().filter_map(|e| e.ok()).filter(|e| e.file_name() != "scene.prtb").collect();
    assert!(leftovers.is_empty(), "temporary file left behind");

    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..100]).unwrap();
    let err = read_bundle(&path).unwrap_err();
    assert!(matches!(err.kind(), BundleError::Truncated { .. }));
    assert!(err.to_string().contains("scene.prtb") && err.to_string().contains("truncated"), "{err}");
    let missing = read_bundle(&dir.join("absent.prtb")).unwrap_err();
    assert!(missing.to_string().contains("absent.prtb"));
    std::fs::remove_dir_all(&dir).unwrap();
}

// ---------------------------------------------------------------- golden bytes

/// The worked example of docs/bundle-format.md, byte for byte (32-bit words as
/// they appear in the file, little-endian): header; table (META, MESH, MATL);
/// META `{}` + pad; MESH counts, positions, normals, indices, material + pad,
/// group; MATL counts, material, group name "g"; file padding. Every section is
/// raw, so each entry's stored-bytes CRC equals its raw CRC.
const GOLDEN: &str = "
    50525442 0d0a1a0a 01000100 03000000 38010000 00000000 00000000 9570fc75
    4d455441 00000000 98000000 00000000 02000000 00000000 02000000 00000000 43bfa6a3 43bfa6a3
    4d455348 00000000 a0000000 00000000 68000000 00000000 68000000 00000000 a0c289a0 a0c289a0
    4d41544c 00000000 08010000 00000000 2c000000 00000000 2c000000 00000000 5f6254b3 5f6254b3
    7b7d0000 00000000
    03000000 01000000 00000000
    00000000 00000000 00000000  0000803f 00000000 00000000  00000000 0000803f 00000000
    00000000 00000000 0000803f  00000000 00000000 0000803f  00000000 00000000 0000803f
    00000000 01000000 02000000
    00000000
    00000000
    01000000 01000000
    00000000 0000003f 0000003f 0000003f 0000803f 01000000 6d000000
    01000000 67000000
    00000000";

/// The same file as the 1.0 writer wrote it: minor 0, word 36 of each entry
/// reserved (zero), and so another header CRC.
const GOLDEN_1_0: &str = "
    50525442 0d0a1a0a 01000000 03000000 38010000 00000000 00000000 95764dad
    4d455441 00000000 98000000 00000000 02000000 00000000 02000000 00000000 43bfa6a3 00000000
    4d455348 00000000 a0000000 00000000 68000000 00000000 68000000 00000000 a0c289a0 00000000
    4d41544c 00000000 08010000 00000000 2c000000 00000000 2c000000 00000000 5f6254b3 00000000
    7b7d0000 00000000
    03000000 01000000 00000000
    00000000 00000000 00000000  0000803f 00000000 00000000  00000000 0000803f 00000000
    00000000 00000000 0000803f  00000000 00000000 0000803f  00000000 00000000 0000803f
    00000000 01000000 02000000
    00000000
    00000000
    01000000 01000000
    00000000 0000003f 0000003f 0000003f 0000803f 01000000 6d000000
    01000000 67000000
    00000000";

fn hex(bytes: &[u8]) -> String {
    bytes.chunks(4).map(|w| w.iter().map(|b| format!("{b:02x}")).collect::<String>()).collect::<Vec<_>>().join(" ")
}

#[test]
fn golden_tiny_bundle_bytes() {
    let bytes = tiny_bytes();
    let expected: String = GOLDEN.split_whitespace().collect::<Vec<_>>().join(" ");
    assert_eq!(hex(&bytes), expected, "\nactual:\n{}", hex(&bytes));
    assert_eq!(decode_bundle(&bytes).unwrap(), tiny_bundle());
}

/// 1.0 files, raw and zstd, still read: no stored-bytes CRC to check, word 36 reserved.
#[test]
fn format_1_0_bundles_still_read() {
    let raw = unhex(GOLDEN_1_0);
    assert_eq!(decode_bundle(&raw).unwrap(), tiny_bundle());
    let zstd = unhex(GOLDEN_1_0_ZSTD);
    assert!(list_sections(&zstd).unwrap().iter().all(|s| s.codec == Codec::Zstd as u32 && s.stored_crc32.is_none()));
    assert_eq!(decode_bundle(&zstd).unwrap(), small_regular_bundle());
    // Re-encoding writes the current minor with a stored-bytes CRC on every section.
    let again = encode_bundle(&decode_bundle(&zstd).unwrap()).unwrap();
    assert_eq!(u16::from_le_bytes([again[10], again[11]]), FORMAT_MINOR);
    assert!(list_sections(&again).unwrap().iter().all(|s| s.stored_crc32.is_some()));
}

/// In a 1.0 file a flip inside a zstd frame header can decode to the same raw
/// bytes, and nothing covers the stored bytes: such flips are accepted, but
/// never with changed content (the raw CRC sees to that). 1.1 refuses them all.
#[test]
fn bit_flips_of_a_1_0_zstd_bundle_are_refused_or_harmless() {
    let bytes = unhex(GOLDEN_1_0_ZSTD);
    let original = decode_bundle(&bytes).unwrap();
    let mut accepted = 0;
    for bit in 0..bytes.len() * 8 {
        if let Ok(decoded) = decode_bundle(&flip_bit(&bytes, bit)) {
            assert_eq!(decoded, original, "flip of bit {bit} silently changed the content");
            accepted += 1;
        }
    }
    // docs/bundle-format.md (Compatibility) quotes this count.
    // 27 before the window cap (rule 7) refused the flips that enlarge a frame's window.
    assert_eq!(accepted, 22, "the 1.0 weakness this test documents");
}

// ---------------------------------------------------------------- hostile input

#[test]
fn every_truncation_is_refused() {
    for bytes in [tiny_bytes(), small_bytes()] {
        for len in 0..bytes.len() {
            let result = decode_bundle(&bytes[..len]);
            assert!(result.is_err(), "prefix of {len} bytes decoded");
            if len < HEADER_LEN {
                assert!(matches!(result, Err(BundleError::Truncated { .. })), "len {len}: {result:?}");
            }
        }
        assert!(decode_bundle(&bytes).is_ok());
    }
}

fn flip_bit(bytes: &[u8], bit: usize) -> Vec<u8> {
    let mut flipped = bytes.to_vec();
    flipped[bit / 8] ^= 1 << (bit % 8);
    flipped
}

/// Every single-bit flip of `bytes` is refused with an error (a panic fails the test).
fn assert_every_bit_flip_is_refused(bytes: &[u8]) {
    for bit in 0..bytes.len() * 8 {
        assert!(decode_bundle(&flip_bit(bytes, bit)).is_err(), "flip of bit {bit} (byte {}) went unnoticed", bit / 8);
    }
}

#[test]
fn every_bit_flip_of_the_raw_tiny_bundle_is_refused() {
    assert_every_bit_flip_is_refused(&tiny_bytes());
}

/// The case 1.0 missed: flips in zstd frame headers that decode to the same bytes.
#[test]
fn every_bit_flip_of_a_zstd_bundle_is_refused() {
    let bytes = small_zstd_bytes();
    assert!(list_sections(&bytes).unwrap().iter().all(|s| s.codec == Codec::Zstd as u32), "every section must be zstd");
    assert_every_bit_flip_is_refused(&bytes);
}

#[test]
fn random_bit_flips_of_a_larger_zstd_bundle_are_refused() {
    let bytes = small_bytes();
    let mut rng = Rng(0xf11b_5eed);
    for _ in 0..2000 {
        let bit = rng.below(bytes.len() * 8);
        assert!(decode_bundle(&flip_bit(&bytes, bit)).is_err(), "flip of bit {bit} went unnoticed");
    }
}

/// A stored-bytes CRC mismatch is named as such, before any decompression.
#[test]
fn corrupted_stored_bytes_are_named() {
    let mut bytes = small_zstd_bytes();
    let mesh = list_sections(&bytes).unwrap().into_iter().find(|s| s.tag == *b"MESH").unwrap();
    bytes[mesh.offset as usize + 5] ^= 0x10; // inside the zstd frame header
    let err = decode_bundle(&bytes).unwrap_err();
    assert!(matches!(err, BundleError::StoredChecksum { tag: Tag(t), .. } if &t == b"MESH"), "{err}");
}

fn set_u16(bytes: &mut [u8], at: usize, v: u16) {
    bytes[at..at + 2].copy_from_slice(&v.to_le_bytes());
}
pub(super) fn set_u32(bytes: &mut [u8], at: usize, v: u32) {
    bytes[at..at + 4].copy_from_slice(&v.to_le_bytes());
}
pub(super) fn get_u32(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())
}
pub(super) fn get_u64(bytes: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap())
}

/// Recomputes the raw CRCs of raw-codec sections, the stored-bytes CRCs (minor ≥ 1)
/// and the header CRC, so that a forged file reaches the section decoders instead
/// of failing on a checksum.
fn reseal(bytes: &mut [u8]) {
    let count = get_u32(bytes, 12) as usize;
    let has_stored_crc = u16::from_le_bytes([bytes[10], bytes[11]]) >= STORED_CRC_SINCE_MINOR;
    for i in 0..count {
        let entry = HEADER_LEN + i * ENTRY_LEN;
        let (at, len) = (get_u64(bytes, entry + 8) as usize, get_u64(bytes, entry + 16) as usize);
        let crc = crc32fast::hash(&bytes[at..at + len]);
        if get_u32(bytes, entry + 4) == 0 {
            set_u32(bytes, entry + 32, crc);
        }
        if has_stored_crc {
            set_u32(bytes, entry + 36, crc);
        }
    }
    let crc = header_crc(bytes);
    set_u32(bytes, 28, crc);
}

/// CRC-32 of the header's first 28 bytes and the section table.
pub(super) fn header_crc(bytes: &[u8]) -> u32 {
    let count = get_u32(bytes, 12) as usize;
    let mut h = crc32fast::Hasher::new();
    h.update(&bytes[..28]);
    h.update(&bytes[HEADER_LEN..HEADER_LEN + count * ENTRY_LEN]);
    h.finalize()
}

#[test]
fn bumped_major_version_is_refused_by_name() {
    let mut bytes = tiny_bytes();
    set_u16(&mut bytes, 8, 2);
    let err = decode_bundle(&bytes).unwrap_err();
    assert!(matches!(err, BundleError::UnsupportedVersion { major: 2, minor: FORMAT_MINOR, .. }));
    assert!(err.to_string().contains(&format!("version 2.{FORMAT_MINOR}")), "{err}");
    reseal(&mut bytes); // a well-formed v2 header is refused all the same
    assert!(matches!(decode_bundle(&bytes), Err(BundleError::UnsupportedVersion { major: 2, .. })));
}

#[test]
fn bad_magic_is_not_a_bundle() {
    for input in [&b"solid cube\nfacet normal 0 0 1\n endfacet\nendsolid\n"[..], b"X", b"glTF\x02\0\0\0"] {
        let err = decode_bundle(input).unwrap_err();
        assert!(err.to_string().contains("not a prtbake bundle"), "{err}");
    }
    let mut bytes = tiny_bytes();
    bytes[0] = b'Q';
    assert!(matches!(decode_bundle(&bytes), Err(BundleError::NotABundle { .. })));
    assert!(matches!(decode_bundle(&[]), Err(BundleError::Truncated { .. })));
    assert!(matches!(decode_bundle(b"PRTB"), Err(BundleError::Truncated { .. })));
}

#[test]
fn trailing_bytes_are_refused() {
    for extra in [1usize, 7, 8, 100] {
        let mut bytes = small_bytes();
        bytes.resize(bytes.len() + extra, 0);
        let err = decode_bundle(&bytes).unwrap_err();
        assert!(matches!(err, BundleError::TrailingBytes { extra: e, .. } if e == extra as u64), "{err}");
    }
}

/// A bundle file of another size than its header's total length is refused
/// after its 32-byte header, and one of the right size whose section table
/// is damaged after its header and table, before any payload is read: a
/// bundle with 3 GiB appended (sparse) costs 32 bytes to refuse.
#[test]
fn file_sizes_are_checked_against_the_header_before_the_body_is_read() {
    use crate::files::read::bytes_read;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("grown.prtb");
    let bytes = small_bytes();
    let table_end = HEADER_LEN as u64 + u64::from(u32::from_le_bytes(bytes[12..16].try_into().unwrap())) * ENTRY_LEN as u64;
    let set_len = |len: u64| std::fs::OpenOptions::new().write(true).open(&path).unwrap().set_len(len).unwrap();
    std::fs::write(&path, &bytes).unwrap();
    bytes_read::take();
    assert_eq!(read_bundle_bytes(&path).unwrap(), bytes);
    assert_eq!(bytes_read::take(), HEADER_LEN as u64 + table_end + bytes.len() as u64);

    let big = 3u64 << 30;
    set_len(big);
    let err = read_bundle_bytes(&path).unwrap_err();
    assert_eq!(bytes_read::take(), HEADER_LEN as u64);
    assert!(matches!(err.kind(), BundleError::TrailingBytes { extra, .. } if *extra == big - bytes.len() as u64), "{err}");
    let message = err.to_string();
    assert!(
        message.contains("grown.prtb") && message.contains("trailing bytes") && message.contains(&format!("the file has {big} bytes")),
        "{message}"
    );

    set_len(bytes.len() as u64 - 8);
    let err = read_bundle_bytes(&path).unwrap_err();
    assert_eq!(bytes_read::take(), HEADER_LEN as u64);
    assert!(matches!(err.kind(), BundleError::Truncated { .. }), "{err}");

    let mut damaged = bytes.clone();
    damaged[HEADER_LEN + ENTRY_LEN + 9] ^= 1;
    std::fs::write(&path, &damaged).unwrap();
    let err = read_bundle_bytes(&path).unwrap_err();
    assert_eq!(bytes_read::take(), HEADER_LEN as u64 + table_end);
    assert!(matches!(err.kind(), BundleError::HeaderChecksum { .. }), "{err}");
}

#[test]
fn unknown_sections_are_skipped_and_later_minors_read() {
    let bundle = tiny_bundle();
    let mut parts = vec![(*b"zNEW", vec![1u8, 2, 3])];
    parts.extend([
        (*b"META", b"{}".to_vec()),
        (*b"MESH", sections_bytes(&bundle, *b"MESH")),
        (*b"MATL", sections_bytes(&bundle, *b"MATL")),
    ]);
    let mut bytes = write_container(&parts, EncodeOptions { compression: Compression::None }).unwrap();
    assert_eq!(decode_bundle(&bytes).unwrap(), bundle);

    // A later minor with a header flag set: read, the flag ignored.
    set_u16(&mut bytes, 10, FORMAT_MINOR + 1);
    set_u32(&mut bytes, 24, 0x8000_0000);
    reseal(&mut bytes);
    assert_eq!(decode_bundle(&bytes).unwrap(), bundle);
    // The stored-bytes CRC (defined in 1.1) is still checked in a later minor.
    set_u32(&mut bytes, HEADER_LEN + 36, 5);
    let mut bad_crc = bytes.clone();
    let crc = header_crc(&bad_crc);
    set_u32(&mut bad_crc, 28, crc);
    assert!(matches!(decode_bundle(&bad_crc), Err(BundleError::StoredChecksum { .. })));
    // The same flag in a file of this reader's minor is corruption.
    set_u16(&mut bytes, 10, FORMAT_MINOR);
    reseal(&mut bytes);
    assert!(matches!(decode_bundle(&bytes), Err(BundleError::Layout(_))));
}

/// In a 1.0 file, word 36 of a table entry is reserved and must be zero.
#[test]
fn nonzero_reserved_word_in_a_1_0_table_is_refused() {
    let mut bytes = unhex(GOLDEN_1_0);
    set_u32(&mut bytes, HEADER_LEN + 36, 5);
    reseal(&mut bytes);
    let err = decode_bundle(&bytes).unwrap_err();
    assert!(matches!(err, BundleError::Layout(_)) && err.to_string().contains("reserved field is 0x5"), "{err}");
}

/// Raw bytes of one section of `bundle`, via the real encoder.
fn sections_bytes(bundle: &Bundle, tag: [u8; 4]) -> Vec<u8> {
    let bytes = encode_bundle_with(bundle, EncodeOptions { compression: Compression::None }).unwrap();
    let info = list_sections(&bytes).unwrap().into_iter().find(|s| s.tag == tag).unwrap();
    bytes[info.offset as usize..(info.offset + info.raw_len) as usize].to_vec()
}

fn decode_parts(parts: &[([u8; 4], Vec<u8>)]) -> Result<Bundle, BundleError> {
    decode_bundle(&write_container(parts, EncodeOptions::default()).unwrap())
}

#[test]
fn forged_counts_are_refused_before_allocation() {
    let bundle = random_bundle(6, 12, 10, Quantization::F32);
    let meta = (*b"META", b"{}".to_vec());
    let mesh = (*b"MESH", sections_bytes(&bundle, *b"MESH"));
    let matl = (*b"MATL", sections_bytes(&bundle, *b"MATL"));
    let detail = |r: Result<Bundle, BundleError>| match r {
        Err(BundleError::Malformed { tag, detail }) => format!("{tag}: {detail}"),
        Err(other) => panic!("expected Malformed, got {other}"),
        Ok(_) => panic!("forged section decoded"),
    };

    // A mesh announcing 4 billion vertices in a few hundred bytes.
    let mut huge = mesh.1.clone();
    set_u32(&mut huge, 0, u32::MAX);
    let msg = detail(decode_parts(&[meta.clone(), (*b"MESH", huge), matl.clone()]));
    assert!(msg.starts_with("MESH: a mesh of 4294967295 vertices"), "{msg}");

    // Materials: u32::MAX names of at least 4 bytes each.
    let mut many = matl.1.clone();
    set_u32(&mut many, 4, u32::MAX);
    let msg = detail(decode_parts(&[meta.clone(), mesh.clone(), (*b"MATL", many)]));
    assert!(msg.starts_with("MATL:") && msg.contains("4294967295 groups"), "{msg}");

    // A name length running past the section.
    let mut long_name = matl.1.clone();
    set_u32(&mut long_name, 8 + 20, 1 << 30);
    assert!(detail(decode_parts(&[meta.clone(), mesh.clone(), (*b"MATL", long_name)])).contains("material name"));

    // Transfer with order 65535 and sun data with 2^32-1 steps.
    let xfer = sections_bytes(&bundle, *b"XFER");
    let mut big_order = xfer.clone();
    set_u32(&mut big_order, 0, 65535);
    let msg = detail(decode_parts(&[meta.clone(), mesh.clone(), matl.clone(), (*b"XFER", big_order)]));
    assert!(msg.starts_with("XFER:"), "{msg}");
    let (sunm, sund) = (sections_bytes(&bundle, *b"SUNM"), sections_bytes(&bundle, *b"SUND"));
    let mut many_steps = sund.clone();
    set_u32(&mut many_steps, 0, u32::MAX);
    let parts = [meta.clone(), mesh.clone(), matl.clone(), (*b"SUNM", sunm.clone()), (*b"SUND", many_steps)];
    assert!(detail(decode_parts(&parts)).starts_with("SUND:"));

    // Mask padding bits (steps 92..95) must be zero.
    let mut dirty = sunm.clone();
    dirty[16 + 8 + 3] |= 0x80; // vertex 0, word 2, bit 31 = step 95
    let parts = [meta.clone(), mesh.clone(), matl.clone(), (*b"SUNM", dirty), (*b"SUND", sund.clone())];
    assert!(detail(decode_parts(&parts)).contains("past step 92"));

    // Mesh indices out of range are caught by Mesh::validate.
    let mut bad_index = mesh.1.clone();
    let at = 12 + 12 * 4 * 13; // after positions, normals, uvs, colours and lightmap uvs (13 floats) of 12 vertices
    set_u32(&mut bad_index, at, 12);
    assert!(detail(decode_parts(&[meta.clone(), (*b"MESH", bad_index), matl.clone()])).contains("out of range"));

    // Masks for another vertex count; SUNM without SUND; a missing MESH.
    let mut other_count = sunm.clone();
    set_u32(&mut other_count, 8, 11);
    let parts = [meta.clone(), mesh.clone(), matl.clone(), (*b"SUNM", other_count), (*b"SUND", sund.clone())];
    assert!(detail(decode_parts(&parts)).contains("the mesh has 12"));
    let parts = [meta.clone(), mesh.clone(), matl.clone(), (*b"SUNM", sunm.clone())];
    assert!(matches!(decode_parts(&parts), Err(BundleError::MissingSection(Tag(t))) if &t == b"SUND"));
    assert!(matches!(decode_parts(&[meta.clone(), matl.clone()]), Err(BundleError::MissingSection(Tag(t))) if &t == b"MESH"));
}

#[test]
fn encoder_refuses_bundles_that_would_not_read_back() {
    let good = random_bundle(10, 12, 10, Quantization::F16);
    let refuse = |b: Bundle, needle: &str| {
        let err = encode_bundle(&b).unwrap_err().to_string();
        assert!(err.contains(needle), "{err} (wanted {needle})");
    };
    let mut b = good.clone();
    b.transfer.as_mut().unwrap().layers[0].data.pop();
    refuse(b, "values, expected 12 vertices");
    let mut b = good.clone();
    b.transfer.as_mut().unwrap().layers[1].data[5] = f32::NAN;
    refuse(b, "section XFER: layer 1 value 5 (vertex 0) is NaN");
    let mut b = good.clone();
    b.mesh.normals[1] = Vec3::new(0.0, f32::INFINITY, 0.0);
    refuse(b, "section MESH: vertex 1 normal is inf");
    let mut b = good.clone();
    b.sun.as_mut().unwrap().steps[2].direction = [0.0, 2.0, 0.0];
    refuse(b, "section SUND: step 2 sun direction has length 2, not 1");
    let mut b = good.clone();
    b.transfer.as_mut().unwrap().layers[1].data[5] = 1e6;
    refuse(b, "overflows f16");
    let mut b = good.clone();
    b.transfer.as_mut().unwrap().layers[1].kind = LayerKind::Bounce(0);
    refuse(b, "appears twice");
    let mut b = good.clone();
    b.sun.as_mut().unwrap().masks[2] |= 1 << 31;
    refuse(b, "past step 92");
    let mut b = good.clone();
    b.sun.as_mut().unwrap().steps[3].sky_sh.pop();
    refuse(b, "sky coefficients");
    let mut b = good.clone();
    b.mesh.indices[0] = 99;
    refuse(b, "out of range");
}

#[test]
fn duplicate_and_misplaced_sections_are_refused() {
    let mut dup = tiny_bytes();
    dup[HEADER_LEN + 2 * ENTRY_LEN..][..4].copy_from_slice(b"MESH"); // MATL -> second MESH
    reseal(&mut dup);
    assert!(matches!(decode_bundle(&dup), Err(BundleError::DuplicateSection(Tag(t))) if &t == b"MESH"));

    let mut moved = tiny_bytes();
    set_u32(&mut moved, HEADER_LEN + ENTRY_LEN + 8, 0xa8); // MESH offset 160 -> 168
    reseal(&mut moved);
    let err = decode_bundle(&moved).unwrap_err().to_string();
    assert!(err.contains("section MESH: offset 168 is not the canonical 160"), "{err}");

    let mut padded = tiny_bytes();
    padded[152 + 2] = 1; // META padding
    assert!(matches!(decode_bundle(&padded), Err(BundleError::Layout(_))));
}

/// Adding a sun series to a bundle keeps every other section's bytes (an i16
/// transfer would not survive decode + re-encode bit for bit in general) and
/// replaces an existing series.
#[test]
fn encode_with_sun_keeps_other_sections_verbatim() {
    let mut original = random_bundle(11, 60, 70, Quantization::I16PerVertexScale);
    original.sun = None;
    let bytes = encode_bundle(&original).unwrap();
    let sun = random_sun(&mut Rng(12), 60, 5);
    let meta = serde_json::json!({"sun": {"steps": 5}});
    let with_sun = encode_with_sun(&bytes, &meta, &sun).unwrap();
    let (a, b) = (Container::parse(&bytes).unwrap(), Container::parse(&with_sun).unwrap());
    for tag in [sections::MESH, sections::MATL, sections::XFER] {
        let pa = a.payload(a.find(tag).unwrap()).unwrap();
        let pb = b.payload(b.find(tag).unwrap()).unwrap();
        assert_eq!(pa, pb, "{:?}", Tag(tag));
    }
    let decoded = decode_bundle(&with_sun).unwrap();
    assert_eq!(decoded.sun.as_ref(), Some(&sun));
    assert_eq!(decoded.meta, meta);
    assert_eq!(decoded.transfer, decode_bundle(&bytes).unwrap().transfer);
    // Replacing: a second series takes the first one's place.
    let sun2 = random_sun(&mut Rng(13), 60, 1);
    let again = decode_bundle(&encode_with_sun(&with_sun, &meta, &sun2).unwrap()).unwrap();
    assert_eq!(again.sun, Some(sun2));
    // A series for another vertex count is refused.
    assert!(encode_with_sun(&bytes, &meta, &random_sun(&mut Rng(14), 59, 5)).is_err());
}

/// The extreme step counts, 1 and 1,024, pack and round-trip.
#[test]
fn one_and_1024_steps_round_trip() {
    for steps in [1usize, 1024] {
        let mut b = random_bundle(21, 30, 20, Quantization::F32);
        b.sun = Some(random_sun(&mut Rng(22), 30, steps));
        let sun = b.sun.as_ref().unwrap();
        assert_eq!(sun.words_per_vertex as usize, steps.div_ceil(32));
        let back = decode_bundle(&encode_bundle(&b).unwrap()).unwrap();
        assert_eq!(back.sun, b.sun);
        let s = back.sun.unwrap();
        assert!((0..30).all(|v| (0..steps).all(|k| s.bit(v, k) == sun.bit(v, k))));
    }
}

// ---------------------------------------------------------------- value ranges

/// Raw bytes of every section of `bundle`, as the writer lays them out.
pub(super) fn raw_sections(bundle: &Bundle) -> Vec<([u8; 4], Vec<u8>)> {
    let bytes = encode_bundle_with(bundle, EncodeOptions { compression: Compression::None }).unwrap();
    list_sections(&bytes).unwrap().iter().map(|s| (s.tag, bytes[s.offset as usize..(s.offset + s.raw_len) as usize].to_vec())).collect()
}

/// `bundle` with the bytes of section `tag` at `offset` replaced by `patch`,
/// laid out again by the container writer, so every CRC is valid: only the
/// range checks stand between the forged value and the caller.
fn forged_at(bundle: &Bundle, tag: [u8; 4], offset: usize, patch: &[u8]) -> Vec<u8> {
    let mut parts = raw_sections(bundle);
    let raw = &mut parts.iter_mut().find(|(t, _)| *t == tag).unwrap().1;
    raw[offset..offset + patch.len()].copy_from_slice(patch);
    write_container(&parts, EncodeOptions::default()).unwrap()
}

/// [`forged_at`] at the one place section `tag` holds the bytes `marker`.
fn forged(bundle: &Bundle, tag: [u8; 4], marker: &[u8], patch: &[u8]) -> Vec<u8> {
    let raw = raw_sections(bundle).into_iter().find(|(t, _)| *t == tag).unwrap().1;
    let hits: Vec<usize> = raw.windows(marker.len()).enumerate().filter(|(_, w)| *w == marker).map(|(i, _)| i).collect();
    assert_eq!(hits.len(), 1, "marker {marker:02x?} must occur once in {}", Tag(tag));
    forged_at(bundle, tag, hits[0], patch)
}

/// Decoding `bytes` fails with a `BadValue` in section `tag` whose message is `expected`.
fn assert_bad_value(bytes: &[u8], tag: &[u8; 4], expected: &str) {
    match decode_bundle(bytes) {
        Err(BundleError::BadValue { tag: Tag(t), bad }) => {
            assert_eq!((&t, bad.to_string().as_str()), (tag, expected), "wrong field or section");
        }
        other => panic!("expected section {} to fail with \"{expected}\", got {other:?}", Tag(*tag)),
    }
}

const MARK: f32 = 0.3217;
const NAN: f32 = f32::NAN;
const INF: f32 = f32::INFINITY;

/// A bundle whose `field` holds `MARK` (or a value derived from it), forged to `value`.
fn forged_field(set: impl FnOnce(&mut Bundle) -> f32, tag: [u8; 4], value: f32) -> Vec<u8> {
    let mut b = random_bundle(30, 6, 4, Quantization::F32);
    let stored = set(&mut b);
    forged(&b, tag, &stored.to_le_bytes(), &value.to_le_bytes())
}

#[test]
fn mesh_values_out_of_range_are_refused_by_name() {
    let position = |b: &mut Bundle| {
        b.mesh.positions[3].y = MARK;
        MARK
    };
    assert_bad_value(&forged_field(position, *b"MESH", NAN), b"MESH", "vertex 3 position is NaN");
    let normal = |b: &mut Bundle| {
        b.mesh.normals[3] = Vec3::new(MARK, 0.0, 0.5);
        MARK
    };
    assert_bad_value(&forged_field(normal, *b"MESH", NAN), b"MESH", "vertex 3 normal is NaN");
    let mut b = random_bundle(30, 6, 4, Quantization::F32);
    b.mesh.normals[3] = Vec3::new(MARK, 0.0, MARK);
    let zero = forged(&b, *b"MESH", &[MARK.to_le_bytes(), 0f32.to_le_bytes(), MARK.to_le_bytes()].concat(), &[0u8; 12]);
    assert_bad_value(&zero, b"MESH", "vertex 3 normal is the zero vector (no direction)");
    let uv = |b: &mut Bundle| {
        b.mesh.uvs[2].x = MARK;
        MARK
    };
    assert_bad_value(&forged_field(uv, *b"MESH", INF), b"MESH", "vertex 2 uv is inf");
    let colour = |b: &mut Bundle| {
        b.mesh.colors[4][1] = MARK;
        MARK
    };
    assert_bad_value(&forged_field(colour, *b"MESH", NAN), b"MESH", "vertex 4 colour is NaN");
    assert_bad_value(&forged_field(colour, *b"MESH", -0.5), b"MESH", "vertex 4 colour is -0.5, outside [0, ∞)");
}

#[test]
fn material_values_out_of_range_are_refused_by_name() {
    let albedo = |b: &mut Bundle| {
        b.mesh.materials[1].albedo[2] = MARK;
        MARK
    };
    assert_bad_value(&forged_field(albedo, *b"MATL", NAN), b"MATL", "material 1 albedo is NaN");
    assert_bad_value(&forged_field(albedo, *b"MATL", 1.5), b"MATL", "material 1 albedo is 1.5, outside [0, 1]");
    assert_bad_value(&forged_field(albedo, *b"MATL", -INF), b"MATL", "material 1 albedo is -inf");
    let transmittance = |b: &mut Bundle| {
        b.mesh.materials[1].transmittance = MARK;
        MARK
    };
    assert_bad_value(&forged_field(transmittance, *b"MATL", NAN), b"MATL", "material 1 transmittance is NaN");
    assert_bad_value(&forged_field(transmittance, *b"MATL", -0.25), b"MATL", "material 1 transmittance is -0.25, outside [0, 1]");
}

#[test]
fn sun_values_out_of_range_are_refused_by_name() {
    let mut b = random_bundle(30, 6, 4, Quantization::F32);
    b.sun.as_mut().unwrap().steps[5].unix_time_utc = 1_234_567_890.123;
    let time = forged(&b, *b"SUND", &1_234_567_890.123f64.to_le_bytes(), &f64::NAN.to_le_bytes());
    assert_bad_value(&time, b"SUND", "step 5 time is NaN");

    let direction = |b: &mut Bundle| {
        let d = Vec3::new(MARK, 0.8, 0.5).normalize();
        b.sun.as_mut().unwrap().steps[5].direction = d.to_array();
        d.x
    };
    assert_bad_value(&forged_field(direction, *b"SUND", NAN), b"SUND", "step 5 sun direction is NaN");
    assert_bad_value(&forged_field(direction, *b"SUND", 3.0), b"SUND", "step 5 sun direction has length 3.1457639, not 1");

    let elevation = |b: &mut Bundle| {
        b.sun.as_mut().unwrap().steps[5].elevation_deg = 32.17;
        32.17
    };
    assert_bad_value(&forged_field(elevation, *b"SUND", 91.0), b"SUND", "step 5 elevation is 91, outside [-90, 90] degrees");
    assert_bad_value(&forged_field(elevation, *b"SUND", NAN), b"SUND", "step 5 elevation is NaN");
    let azimuth = |b: &mut Bundle| {
        b.sun.as_mut().unwrap().steps[5].azimuth_deg = 321.7;
        321.7
    };
    assert_bad_value(&forged_field(azimuth, *b"SUND", -1.0), b"SUND", "step 5 azimuth is -1, outside [0, 360] degrees");
    assert_bad_value(&forged_field(azimuth, *b"SUND", INF), b"SUND", "step 5 azimuth is inf");
    let irradiance = |b: &mut Bundle| {
        b.sun.as_mut().unwrap().steps[5].sun_rgb[1] = 321.7;
        321.7
    };
    assert_bad_value(&forged_field(irradiance, *b"SUND", -1.0), b"SUND", "step 5 sun irradiance is -1, outside [0, ∞)");
    assert_bad_value(&forged_field(irradiance, *b"SUND", NAN), b"SUND", "step 5 sun irradiance is NaN");
    let sky = |b: &mut Bundle| {
        b.sun.as_mut().unwrap().steps[5].sky_sh[2][1] = MARK;
        MARK
    };
    assert_bad_value(&forged_field(sky, *b"SUND", NAN), b"SUND", "step 5 sky SH is NaN");
}

#[test]
fn transfer_values_out_of_range_are_refused_by_name() {
    let value = |b: &mut Bundle| {
        b.transfer.as_mut().unwrap().layers[1].data[30] = MARK;
        MARK
    };
    assert_bad_value(&forged_field(value, *b"XFER", NAN), b"XFER", "layer 1 value 30 (vertex 1) is NaN");

    // XFER: 16-byte header, then layer 0: kind and reserved (8 bytes), data.
    let layer0 = 16 + 8;
    let f16 = random_bundle(31, 6, 4, Quantization::F16);
    let nan_f16 = forged_at(&f16, *b"XFER", layer0 + 2 * 3, &0x7e00u16.to_le_bytes());
    assert_bad_value(&nan_f16, b"XFER", "layer 0 value 3 (vertex 0) is NaN");
    let mut tinted = random_bundle(32, 6, 4, Quantization::F16Tinted);
    tinted.transfer.as_mut().unwrap().layers.iter_mut().for_each(|l| l.data.iter_mut().for_each(|v| *v = v.abs() + 0.1));
    let inf_tint = forged_at(&tinted, *b"XFER", layer0, &0x7c00u16.to_le_bytes()); // vertex 0, channel 0 tint
    assert_bad_value(&inf_tint, b"XFER", "layer 0 value 0 (vertex 0) is inf");

    // i16: the V per-vertex scales come first; vertex 1's is at layer0 + 4.
    let i16 = random_bundle(33, 6, 4, Quantization::I16PerVertexScale);
    let scale = |value: f32| forged_at(&i16, *b"XFER", layer0 + 4, &value.to_le_bytes());
    assert_bad_value(&scale(NAN), b"XFER", "layer 0 i16 scale of vertex 1 is NaN");
    assert_bad_value(&scale(-1e-3), b"XFER", "layer 0 i16 scale of vertex 1 is -0.001, outside [0, ∞)");
    assert_bad_value(&scale(0.0), b"XFER", "layer 0 i16 scale of vertex 1 is 0, outside (0, ∞) for a vertex with non-zero codes");
    // A scale large enough that the codes overflow f32.
    assert_bad_value(&scale(f32::MAX), b"XFER", "layer 0 value 27 (vertex 1) is -inf");
}

/// What the writer does with values a loader can hand over: clamps albedo and
/// transmittance into [0, 1] and colours to ≥ 0 (the bake uses albedo and
/// transmittance clamped), replaces a zero normal by the face normal.
#[test]
fn writer_stores_values_in_range() {
    let mut b = tiny_bundle();
    b.mesh.materials[0].albedo = [1.2, 0.5, -0.1];
    b.mesh.materials[0].transmittance = 1.5;
    b.mesh.normals[1] = Vec3::ZERO;
    b.mesh.colors = vec![[-0.5, 0.25, 2.0]; 3];
    let back = decode_bundle(&encode_bundle(&b).unwrap()).unwrap();
    assert_eq!((back.mesh.materials[0].albedo, back.mesh.materials[0].transmittance), ([1.0, 0.5, 0.0], 1.0));
    assert_eq!(back.mesh.normals, vec![Vec3::Z; 3]);
    assert_eq!(back.mesh.colors, vec![[0.0, 0.25, 2.0]; 3]);
}

/// Export refuses a bundle built in memory with a value glTF cannot hold, and
/// writes nothing (no `null` in JSON, no NaN in the buffers).
#[test]
fn export_refuses_out_of_range_values() {
    let dir = std::env::temp_dir().join(format!("prtb-export-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("out.glb");
    let mut b = random_bundle(34, 6, 4, Quantization::F32);
    b.mesh.materials[1].albedo[0] = f32::NAN;
    let err = export_glb(&path, &b, None).unwrap_err().to_string();
    assert!(err.contains("section MATL: material 1 albedo is NaN"), "{err}");
    assert!(!path.exists());

    // Finite bounce layers whose sum overflows f32.
    let mut b = random_bundle(34, 6, 4, Quantization::F32);
    let t = b.transfer.as_mut().unwrap();
    t.layers = vec![
        TransferLayer { kind: LayerKind::Bounce(0), data: vec![3e38; 162] },
        TransferLayer { kind: LayerKind::Bounce(1), data: vec![3e38; 162] },
    ];
    let err = export_glb(&path, &b, None).unwrap_err().to_string();
    assert!(err.contains("transfer total value 0 (vertex 0) is inf"), "{err}");
    assert!(!path.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The 1.0 writer did not clamp: a 1.0 file's out-of-range albedo, transmittance,
/// colours and zero normals read as the 1.1 writer would store them; NaN is refused.
#[test]
fn format_1_0_values_are_brought_into_range_but_nan_is_refused() {
    // GOLDEN_1_0: normal 1 at 0xdc, albedo at 0x114, transmittance at 0x120.
    let mut bytes = unhex(GOLDEN_1_0);
    bytes[0x114..0x118].copy_from_slice(&1.25f32.to_le_bytes());
    bytes[0x120..0x124].copy_from_slice(&(-0.5f32).to_le_bytes());
    bytes[0xdc..0xe8].fill(0);
    reseal(&mut bytes);
    let b = decode_bundle(&bytes).unwrap();
    assert_eq!((b.mesh.materials[0].albedo, b.mesh.materials[0].transmittance), ([1.0, 0.5, 0.5], 0.0));
    assert_eq!(b.mesh.normals, vec![Vec3::Z; 3]);
    // Adding a sun series writes the current minor, with the values as decoded.
    let sun = random_sun(&mut Rng(3), 3, 2);
    let with_sun = decode_bundle(&encode_with_sun(&bytes, &serde_json::json!({}), &sun).unwrap()).unwrap();
    assert_eq!((with_sun.mesh, with_sun.sun), (b.mesh, Some(sun)));

    bytes[0x118..0x11c].copy_from_slice(&f32::NAN.to_le_bytes());
    reseal(&mut bytes);
    assert_bad_value(&bytes, b"MATL", "material 0 albedo is NaN");
    // The same out-of-range values in a file of the current minor are refused.
    let mut current = unhex(GOLDEN);
    current[0x114..0x118].copy_from_slice(&1.25f32.to_le_bytes());
    reseal(&mut current);
    assert_bad_value(&current, b"MATL", "material 0 albedo is 1.25, outside [0, 1]");
}

/// A bundle with an atlas and texel transfer (sections ATLS and TXFR).
fn texel_bundle() -> Bundle {
    let mut bundle = random_bundle(7, 12, 10, Quantization::F32);
    bundle.mesh = crate::verify::shapes::plane_grid(3, 1.0);
    bundle.sun = None;
    let coeffs = 4;
    let vertex_values = (0..bundle.mesh.vertex_count() * coeffs).map(|i| (i as f32 * 0.1).sin()).collect();
    bundle.transfer = Some(Transfer {
        order: 2,
        channels: 1,
        quantization: Quantization::F32,
        layers: vec![TransferLayer { kind: LayerKind::Total, data: vertex_values }],
        front_share: Vec::new(),
    });
    let atlas = crate::atlas::Atlas::unwrap(&bundle.mesh, 0.05).unwrap();
    let texels = crate::atlas::coverage::Coverage::of(&atlas).texels;
    let data = (0..texels.len() * coeffs).map(|i| (i as f32 * 0.37).cos()).collect();
    let transfer = Transfer {
        order: 2,
        channels: 1,
        quantization: Quantization::F32,
        layers: vec![TransferLayer { kind: LayerKind::Total, data }],
        front_share: Vec::new(),
    };
    bundle.texels = Some(TexelLayers { atlas, texels, transfer: Some(transfer) });
    bundle
}

/// A small texel bundle whose sun bits lie on an atlas of their own (TSAT,
/// TSAB, TSAF), for the reader's fuzzer.
pub(super) fn sun_atlas_bundle() -> Bundle {
    let mut bundle = texel_bundle();
    bundle.mesh = crate::verify::shapes::plane_grid(1, 1.0);
    let vertex_count = bundle.mesh.vertex_count();
    let transfer = bundle.transfer.as_mut().unwrap();
    transfer.layers[0].data = (0..vertex_count * 4).map(|i| i as f32 * 0.1).collect();
    let atlas = crate::atlas::Atlas::unwrap(&bundle.mesh, 0.25).unwrap();
    let texels = crate::atlas::coverage::Coverage::of(&atlas).texels;
    let mut texel_transfer = transfer.clone();
    texel_transfer.layers[0].data = (0..texels.len() * 4).map(|i| (i as f32 * 0.3).sin()).collect();
    bundle.texels = Some(TexelLayers { atlas, texels, transfer: Some(texel_transfer) });
    let fine = crate::atlas::Atlas::unwrap(&bundle.mesh, 0.125).unwrap();
    let fine_texels = crate::atlas::coverage::Coverage::of(&fine).texels;
    let mut sun = random_sun(&mut Rng(47), vertex_count, 5);
    sun.texel_masks = SunSeries::pack(5, fine_texels.len(), |i, k| (i + k) % 3 == 0).1;
    sun.texel_fractions = (0..fine_texels.len() as u32).map(|i| (i * 0x1111) & 0xF_FFFF).collect();
    sun.texel_atlas = Some(TexelAtlas { atlas: fine, texels: fine_texels });
    bundle.sun = Some(sun);
    bundle
}

#[test]
fn texel_bundles_round_trip_and_refuse_a_broken_atlas() {
    let bundle = texel_bundle();
    let bytes = encode_bundle(&bundle).unwrap();
    assert_eq!(decode_bundle(&bytes).unwrap(), bundle);
    let raw = encode_bundle_with(&bundle, EncodeOptions { compression: Compression::None }).unwrap();
    for len in (0..raw.len()).step_by(97) {
        assert!(decode_bundle(&raw[..len]).is_err(), "prefix of {len} bytes decoded");
    }
    // The sections come as a pair.
    let mesh = &bundle.mesh;
    let t = bundle.texels.as_ref().unwrap();
    let base = || {
        vec![
            (META, sections::encode_meta(&bundle.meta).unwrap()),
            (MESH, sections::encode_mesh(mesh).unwrap()),
            (MATL, sections::encode_materials(&mesh.materials, &mesh.groups).unwrap()),
        ]
    };
    let atlas_raw = sections::encode_atlas(&t.atlas, &t.texels, mesh).unwrap();
    let mut only_atlas = base();
    only_atlas.push((ATLS, atlas_raw.clone()));
    let only_atlas = write_container(&only_atlas, EncodeOptions::default()).unwrap();
    assert!(matches!(decode_bundle(&only_atlas), Err(BundleError::MissingSection(Tag(TXFR)))));
    // An atlas index past the atlas vertices is refused, naming the section.
    let first_index = 32 + t.atlas.uv.len() * 12;
    let mut forged = atlas_raw.clone();
    forged[first_index..first_index + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    let mut parts = base();
    parts.push((ATLS, forged));
    parts.push((TXFR, sections::encode_transfer_of(t.texels.len(), t.transfer.as_ref().unwrap(), TXFR).unwrap()));
    let error = decode_bundle(&write_container(&parts, EncodeOptions::default()).unwrap()).unwrap_err().to_string();
    assert!(error.contains("ATLS") && error.contains("atlas index"), "{error}");
    // A transfer for the wrong number of texels is refused by the encoder.
    let mut short = bundle.clone();
    short.texels.as_mut().unwrap().texels.pop();
    assert!(encode_bundle(&short).is_err());
}

/// Sun bits per texel (section TSUN) round trip beside the vertices' masks,
/// with or without the texels' transfer (a sun-only texel bundle); `sun`
/// on a bundle replaces them; masks for another texel count, masks without
/// an atlas and an atlas with neither transfer nor masks are refused.
#[test]
fn texel_sun_masks_round_trip_with_and_without_texel_transfer() {
    let mut bundle = texel_bundle();
    let covered = bundle.texels.as_ref().unwrap().texels.len();
    let mut rng = Rng(41);
    let mut sun = random_sun(&mut rng, bundle.mesh.vertex_count(), 40);
    let (words, texel_masks) = SunSeries::pack(40, covered, |i, k| (i * 7 + k * 3) % 5 < 2);
    assert_eq!(words, 2);
    assert_eq!(words, sun.words_per_vertex);
    sun.texel_masks = texel_masks;
    // Each texel's lit share in 4 bits (TSUF), 40 steps in 5 words a texel.
    sun.texel_fractions =
        (0..covered * 5).map(|w| if w % 5 == 4 { 0x0000_F00F } else { 0x1234_5678u32.rotate_left(w as u32 % 32) }).collect();
    bundle.sun = Some(sun.clone());
    let bytes = encode_bundle(&bundle).unwrap();
    let decoded = decode_bundle(&bytes).unwrap();
    assert_eq!(decoded, bundle);
    let series = decoded.sun.as_ref().unwrap();
    assert!(series.texel_bit(1, 0) == ((7 % 5) < 2) && !series.texel_bit(1, 40) && !series.texel_bit(covered, 0));
    assert!(list_sections(&bytes).unwrap().iter().any(|s| s.tag_name() == "TSUN"));
    assert!(list_sections(&bytes).unwrap().iter().any(|s| s.tag_name() == "TSUF"));
    assert_eq!(series.texel_sun(0, 1), 7.0 / 15.0);
    // Fractions for another texel count, or without bits, are refused.
    let mut short_fractions = bundle.clone();
    short_fractions.sun.as_mut().unwrap().texel_fractions.pop();
    assert!(encode_bundle(&short_fractions).is_err());
    let mut no_bits = bundle.clone();
    no_bits.sun.as_mut().unwrap().texel_masks.clear();
    assert!(encode_bundle(&no_bits).is_err());
    // Sun-only: ATLS and TSUN without TXFR.
    let mut sun_only = bundle.clone();
    sun_only.transfer = None;
    sun_only.texels.as_mut().unwrap().transfer = None;
    assert_eq!(decode_bundle(&encode_bundle(&sun_only).unwrap()).unwrap(), sun_only);
    // `sun` again on the texel bundle: its masks replaced, the rest kept.
    let mut again = sun.clone();
    again.texel_masks = SunSeries::pack(40, covered, |i, k| (i + k) % 3 == 0).1;
    let replaced = decode_bundle(&encode_with_sun(&bytes, &bundle.meta, &again).unwrap()).unwrap();
    assert_eq!(replaced.sun.as_ref().unwrap().texel_masks, again.texel_masks);
    assert_eq!(replaced.texels, bundle.texels);
    // The wrong texel count, masks without an atlas, an atlas holding nothing.
    let mut short = bundle.clone();
    short.sun.as_mut().unwrap().texel_masks.truncate(words as usize * (covered - 1));
    assert!(encode_bundle(&short).is_err());
    let mut no_atlas = bundle.clone();
    no_atlas.texels = None;
    assert!(encode_bundle(&no_atlas).is_err());
    let mut empty = sun_only.clone();
    empty.sun.as_mut().unwrap().texel_masks.clear();
    assert!(encode_bundle(&empty).is_err());
}

/// The sun's bits on an atlas of their own (TSAT with TSAB and TSAF, finer
/// than the texel transfer's) round trip; `sun` again on such a bundle
/// replaces or drops them; TSAT without TSAB, TSAB without TSAT, either
/// without texel transfer, bits on both atlases, and masks for the
/// transfer's texel count are refused; without the three the rest reads.
#[test]
fn a_sun_atlas_of_its_own_round_trips_beside_the_texel_transfer() {
    let mut bundle = texel_bundle();
    let fine = crate::atlas::Atlas::unwrap(&bundle.mesh, 0.02).unwrap();
    let fine_texels = crate::atlas::coverage::Coverage::of(&fine).texels;
    let covered = bundle.texels.as_ref().unwrap().texels.len();
    assert!(fine_texels.len() > 4 * covered, "{} fine texels against {covered}", fine_texels.len());
    let mut rng = Rng(43);
    let mut sun = random_sun(&mut rng, bundle.mesh.vertex_count(), 12);
    sun.texel_masks = SunSeries::pack(12, fine_texels.len(), |i, k| (i * 5 + k) % 7 < 3).1;
    sun.texel_fractions = (0..fine_texels.len() * 2).map(|w| 0x9abc_def0u32.rotate_left(w as u32 % 32)).collect();
    for (i, w) in sun.texel_fractions.iter_mut().enumerate() {
        if i % 2 == 1 {
            *w &= 0x0000_FFFF; // steps 12..16 do not exist
        }
    }
    sun.texel_atlas = Some(TexelAtlas { atlas: fine.clone(), texels: fine_texels.clone() });
    bundle.sun = Some(sun.clone());
    let bytes = encode_bundle(&bundle).unwrap();
    let decoded = decode_bundle(&bytes).unwrap();
    assert_eq!(decoded, bundle);
    let tags: Vec<String> = list_sections(&bytes).unwrap().iter().map(|s| s.tag_name()).collect();
    let at = |tag: &str| tags.iter().position(|t| t == tag).unwrap();
    assert!(at("ATLS") < at("TXFR") && at("TXFR") < at("TSAT") && at("TSAT") < at("TSAB") && at("TSAB") < at("TSAF"), "{tags:?}");
    assert!(!tags.iter().any(|t| t == "TSUN" || t == "TSUF"), "{tags:?}");
    assert_eq!(decoded.sun.as_ref().unwrap().texel_count(decoded.texels.as_ref()), Some(fine_texels.len()));
    // `sun` again: with its own atlas it is re-encoded alike; on the transfer's atlas TSAT goes.
    assert_eq!(encode_with_sun(&bytes, &bundle.meta, &sun).unwrap(), bytes);
    let mut on_transfer_atlas = sun.clone();
    on_transfer_atlas.texel_atlas = None;
    on_transfer_atlas.texel_fractions.clear();
    on_transfer_atlas.texel_masks = SunSeries::pack(12, covered, |i, k| (i + k) % 2 == 0).1;
    let replaced = encode_with_sun(&bytes, &bundle.meta, &on_transfer_atlas).unwrap();
    assert!(!list_sections(&replaced).unwrap().iter().any(|s| s.tag_name() == "TSAT"));
    let replaced = decode_bundle(&replaced).unwrap();
    assert_eq!((replaced.texels, replaced.sun.unwrap().texel_masks), (bundle.texels.clone(), on_transfer_atlas.texel_masks.clone()));
    // Masks counted on the transfer's texels while TSAT has more: refused.
    let mut wrong_count = bundle.clone();
    wrong_count.sun.as_mut().unwrap().texel_masks = SunSeries::pack(12, covered, |_, _| true).1;
    wrong_count.sun.as_mut().unwrap().texel_fractions.clear();
    assert!(encode_bundle(&wrong_count).is_err());
    // Beside vertex transfer only, the sun's atlas is ATLS: TSAT is refused.
    let mut vertex_transfer = bundle.clone();
    vertex_transfer.texels.as_mut().unwrap().transfer = None;
    assert!(encode_bundle(&vertex_transfer).is_err());
    // On disk: TSAT without TSUN, and TSAT beside an atlas without TXFR.
    let mesh = &bundle.mesh;
    let t = bundle.texels.as_ref().unwrap();
    let head = vec![
        (META, sections::encode_meta(&bundle.meta).unwrap()),
        (MESH, sections::encode_mesh(mesh).unwrap()),
        (MATL, sections::encode_materials(&mesh.materials, &mesh.groups).unwrap()),
        (SUNM, sections::encode_sun_masks(&sun, mesh.vertex_count()).unwrap()),
        (SUND, sections::encode_sun_data(&sun).unwrap()),
        (ATLS, sections::encode_atlas(&t.atlas, &t.texels, mesh).unwrap()),
    ];
    let tsat = (TSAT, sections::encode_atlas(&fine, &fine_texels, mesh).unwrap());
    let tsab = (TSAB, sections::encode_texel_sun_masks(&sun, fine_texels.len(), true).unwrap());
    let txfr = (TXFR, sections::encode_transfer_of(t.texels.len(), t.transfer.as_ref().unwrap(), TXFR).unwrap());
    let mut no_masks = head.clone();
    no_masks.extend([txfr.clone(), tsat.clone()]);
    let no_masks = write_container(&no_masks, EncodeOptions::default()).unwrap();
    assert!(matches!(decode_bundle(&no_masks), Err(BundleError::MissingSection(Tag(TSAB)))));
    let mut no_atlas = head.clone();
    no_atlas.extend([txfr.clone(), tsab.clone()]);
    let no_atlas = write_container(&no_atlas, EncodeOptions::default()).unwrap();
    assert!(matches!(decode_bundle(&no_atlas), Err(BundleError::MissingSection(Tag(TSAT)))));
    let mut no_transfer = head.clone();
    no_transfer.extend([tsat.clone(), tsab.clone()]);
    let no_transfer = write_container(&no_transfer, EncodeOptions::default()).unwrap();
    assert!(matches!(decode_bundle(&no_transfer), Err(BundleError::MissingSection(Tag(TXFR)))));
    let mut both = head.clone();
    let tsun = (TSUN, sections::encode_texel_sun_masks(&on_transfer_atlas, covered, false).unwrap());
    both.extend([txfr.clone(), tsat.clone(), tsab.clone(), tsun]);
    let error = decode_bundle(&write_container(&both, EncodeOptions::default()).unwrap()).unwrap_err().to_string();
    assert!(error.contains("TSAB") && error.contains("both"), "{error}");
    // A reader that knows none of TSAT, TSAB, TSAF skips them: the texel transfer with the sun per vertex.
    let mut older = head.clone();
    older.push(txfr.clone());
    let older = decode_bundle(&write_container(&older, EncodeOptions::default()).unwrap()).unwrap();
    assert!(older.sun.as_ref().unwrap().texel_masks.is_empty() && older.texels == bundle.texels);
    let mut whole = head;
    whole.extend([txfr, tsat, tsab]);
    let whole = decode_bundle(&write_container(&whole, EncodeOptions::default()).unwrap()).unwrap();
    assert_eq!(whole.sun.unwrap().texel_atlas.unwrap().texels, fine_texels);
}
