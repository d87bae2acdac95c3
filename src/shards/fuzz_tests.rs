//! A deterministic fuzz test of the shard files and their merge, in the
//! normal suite: the parts, pilots, layers and hit records of a real small
//! sharded bake (window mode, adaptive, one bounce, and a sun bake), mutated
//! field by field and resealed (length and CRC-32 recomputed, so the checks
//! of the fields themselves are what is exercised), decoded, and whatever
//! decodes merged with the untouched parts of its round. For each case:
//! - decoding and merging return `Ok` or `Err`; a panic fails the test;
//! - no single allocation exceeds a small multiple of the input (a forged
//!   count is checked against the bytes before it is trusted);
//! - a merge that accepts a mutated part says which part when it refuses.
//!
//! Random corruption without resealing is refused by the CRC; every flipped
//! bit and truncation is covered by `codec` and `files` tests.

use std::path::{Path, PathBuf};

use super::*;
use crate::bake::{BakeParams, Mode, SunParams, Surfaces};
use crate::bundle::fuzz_tests::{largest_allocation, reset_largest_allocation};
use crate::trace::{BuildQuality, Scene};
use crate::verify::shapes;

/// xorshift64*: replayable from its seed.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Recomputes the trailer (length, CRC-32) of a mutated file.
fn reseal(bytes: &mut [u8]) {
    let n = bytes.len();
    bytes[n - 12..n - 4].copy_from_slice(&(n as u64).to_le_bytes());
    let crc = crc32fast::hash(&bytes[..n - 4]);
    bytes[n - 4..].copy_from_slice(&crc.to_le_bytes());
}

/// One mutation of the body (between the 16-byte header and the 12-byte
/// trailer): a flipped bit, an overwritten byte, or an aligned 4- or 8-byte
/// field set to an extreme (0, 1, all ones, a power of two, a float edge).
fn mutate(rng: &mut Rng, bytes: &[u8]) -> Vec<u8> {
    let mut out = bytes.to_vec();
    let body = 16..bytes.len() - 12;
    if body.is_empty() {
        return out;
    }
    for _ in 0..1 + rng.below(3) {
        let at = body.start + rng.below(body.len());
        match rng.below(4) {
            0 => out[at] ^= 1 << rng.below(8),
            1 => out[at] = rng.next() as u8,
            _ => {
                let width = if rng.below(2) == 0 { 4 } else { 8 };
                let at = body.start + (at - body.start) / width * width;
                if at + width > body.end {
                    continue;
                }
                let extremes: [u64; 8] =
                    [0, 1, u64::MAX, 1 << 31, 1 << 40, f32::NAN.to_bits() as u64, f32::INFINITY.to_bits() as u64, 0x7fff_ffff];
                let v = extremes[rng.below(extremes.len())].to_le_bytes();
                out[at..at + width].copy_from_slice(&v[..width]);
            }
        }
    }
    reseal(&mut out);
    out
}

/// A window-mode adaptive bake of a small integrating sphere, sharded in two:
/// its pilot parts, round-0 parts and hits, the merged layer and round-1 parts.
struct Round {
    pilot_parts: Vec<Vec<u8>>,
    pilot: Vec<u8>,
    round0: Vec<Vec<u8>>,
    hits: Vec<Vec<u8>>,
    layer: Vec<u8>,
    round1: Vec<Vec<u8>>,
    sun: Vec<Vec<u8>>,
}

fn bytes_of(write: impl FnOnce(&mut Vec<u8>) -> std::io::Result<u32>) -> Vec<u8> {
    let mut out = Vec::new();
    write(&mut out).unwrap();
    out
}

fn real_files() -> Round {
    let (mut mesh, _) = shapes::integrating_sphere(1, 0.6, 0.7, shapes::Opening::Window);
    mesh.materials[0].albedo = [0.7, 0.5, 0.3];
    let params = BakeParams { rays: 8, bounces: 1, mode: Mode::Window, adaptive: 1.0, quiet: true, ..BakeParams::default() };
    let key =
        TransferKey { params, window_patterns: Vec::new(), one_sided_patterns: Vec::new(), quantize: None, max_error: None, texels: None };
    let surfaces = Surfaces::resolve(&mesh, &[]).unwrap();
    let scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
    let shard = |index| Shard { index, count: 2 };
    let pilot_parts: Vec<TransferPart> = (0..2)
        .map(|k| bake_transfer_shard(&mesh, &scene, &surfaces, &key, None, true, shard(k), Stage::Pilot, None, None).unwrap().part)
        .collect();
    let named = |parts: &[TransferPart]| -> Vec<(PathBuf, TransferPart)> {
        parts.iter().enumerate().map(|(k, p)| (PathBuf::from(format!("part-{k}")), p.clone())).collect()
    };
    let TransferMerge::Pilot(pilot) = merge_transfer(&named(&pilot_parts), None).unwrap() else { panic!("a pilot") };
    let pilot_bytes = bytes_of(|w| pilot.write_to(w));
    let (pilot, pilot_crc) = PilotFile::decode(&pilot_bytes).unwrap();
    let input = |pilot: &PilotFile| Some(PilotInput { path: Path::new("pilot"), pilot: pilot.clone(), crc: pilot_crc });
    let outs: Vec<RoundOutput> = (0..2)
        .map(|k| bake_transfer_shard(&mesh, &scene, &surfaces, &key, None, true, shard(k), Stage::Round(0), None, input(&pilot)).unwrap())
        .collect();
    let round0: Vec<TransferPart> = outs.iter().map(|o| o.part.clone()).collect();
    let hits: Vec<HitFile> = outs.iter().map(|o| o.hits.clone().unwrap()).collect();
    let TransferMerge::Layer(layer) = merge_transfer(&named(&round0), None).unwrap() else { panic!("a layer") };
    let layer_bytes = bytes_of(|w| layer.write_to(w));
    let (layer, layer_crc) = LayerFile::decode(&layer_bytes).unwrap();
    let round1: Vec<TransferPart> = (0..2)
        .map(|k| {
            let round = RoundInput {
                hits_path: Path::new("hits"),
                hits: hits[k as usize].clone(),
                layer_path: Path::new("layer"),
                layer: layer.clone(),
                layer_crc,
            };
            let mut part =
                bake_transfer_shard(&mesh, &scene, &surfaces, &key, None, true, shard(k), Stage::Round(1), Some(round), input(&pilot))
                    .unwrap()
                    .part;
            part.frame = b"not a bundle".to_vec();
            part
        })
        .collect();
    let suns = [Some(glam::Vec3::new(0.3, 1.0, 0.2).normalize()), None, Some(glam::Vec3::new(-0.6, 0.7, 0.1).normalize())];
    let sun_key = SunKey {
        params: SunParams { mode: Mode::Window, quiet: true, ..SunParams::default() },
        window_patterns: Vec::new(),
        steps: 3,
        day_crc: 7,
        texels: None,
    };
    let sun: Vec<Vec<u8>> = (0..2)
        .map(|k| {
            let mut part = bake_sun_shard(&mesh, &scene, &surfaces, &suns, &sun_key, None, shard(k)).unwrap();
            if k == 0 {
                part.frame = b"not a bundle".to_vec();
            }
            part.to_bytes()
        })
        .collect();
    Round {
        pilot_parts: pilot_parts.iter().map(TransferPart::to_bytes).collect(),
        pilot: pilot_bytes,
        round0: round0.iter().map(TransferPart::to_bytes).collect(),
        hits: hits.iter().map(|h| bytes_of(|w| h.write_to(w).map(|_| 0))).collect(),
        layer: layer_bytes,
        round1: round1.iter().map(TransferPart::to_bytes).collect(),
        sun,
    }
}

/// Decodes `bytes` as `kind` and, for a part, merges it with the other
/// untouched part of its stage (and the layer, for round 1). No panic, no
/// outsized allocation; returns whether the merge accepted it.
fn run_case(files: &Round, kind: usize, which: usize, bytes: &[u8], context: &str) -> bool {
    reset_largest_allocation();
    let merged = match kind {
        0 | 1 | 2 => {
            let stage = [&files.pilot_parts, &files.round0, &files.round1][kind];
            let Ok(part) = TransferPart::decode(bytes) else { return false };
            let other = TransferPart::decode(&stage[1 - which]).unwrap();
            let parts = [(PathBuf::from("mutated"), part), (PathBuf::from("other"), other)];
            let layer = (kind == 2).then(|| {
                let (l, crc) = LayerFile::decode(&files.layer).unwrap();
                (Path::new("layer"), l, crc)
            });
            match merge_transfer(&parts, layer) {
                Ok(_) => true,
                Err(e) => {
                    assert!(
                        e.to_string().contains("mutated") || e.to_string().contains("other") || e.to_string().contains("layer"),
                        "{context}: {e}"
                    );
                    false
                }
            }
        }
        3 => PilotFile::decode(bytes).is_ok(),
        4 => HitFile::decode(bytes).is_ok(),
        5 => LayerFile::decode(bytes).is_ok(),
        _ => {
            let Ok(part) = SunPart::decode(bytes) else { return false };
            let other = SunPart::decode(&files.sun[1 - which]).unwrap();
            match merge_sun_parts(&[(PathBuf::from("mutated"), part), (PathBuf::from("other"), other)]) {
                Ok(_) => true,
                Err(e) => {
                    assert!(e.to_string().contains("mutated") || e.to_string().contains("other"), "{context}: {e}");
                    false
                }
            }
        }
    };
    let largest = largest_allocation();
    // Merges build per-vertex rows; a forged count would ask for far more.
    assert!(largest <= 64 * bytes.len() + (1 << 20), "{context}: one allocation of {largest} bytes");
    merged
}

#[test]
fn mutated_shard_files_are_refused_or_merged_without_panic() {
    let files = real_files();
    let mut rng = Rng(0x5eed_0f_5ba2d5);
    let names = ["pilot part", "round-0 part", "round-1 part", "pilot", "hit records", "layer", "sun part"];
    let (mut cases, mut accepted) = (0usize, 0usize);
    for round in 0..3000 {
        for (kind, name) in names.iter().enumerate() {
            let (which, base): (usize, &[u8]) = match kind {
                0 => (round % 2, &files.pilot_parts[round % 2]),
                1 => (round % 2, &files.round0[round % 2]),
                2 => (round % 2, &files.round1[round % 2]),
                3 => (0, &files.pilot),
                4 => (round % 2, &files.hits[round % 2]),
                5 => (0, &files.layer),
                _ => (round % 2, &files.sun[round % 2]),
            };
            let bytes = mutate(&mut rng, base);
            let context = format!("{name} case {round}");
            accepted += usize::from(run_case(&files, kind, which, &bytes, &context));
            cases += 1;
        }
    }
    // The untouched files merge: the harness itself is sound.
    assert!(run_case(&files, 1, 0, &files.round0[0], "untouched round-0 part"));
    assert!(run_case(&files, 6, 1, &files.sun[1], "untouched sun part"));
    println!("shard files: {cases} mutated cases, {accepted} accepted (values changed within their checks)");
}
