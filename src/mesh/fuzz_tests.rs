//! Mutation fuzzing of the OBJ and glTF/GLB loaders, deterministic and fast
//! enough for the normal suite: every case must return `Ok` with a mesh that
//! passes [`Mesh::validate`], or an error; a panic fails the test (nothing
//! here catches unwinds).

use std::path::Path;

use super::*;

/// xorshift64*: a small deterministic generator (no dependency needed).
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

/// Tokens that reach the loaders' edge cases: huge, negative and zero indices,
/// non-finite numbers, statements, separators.
const TOKENS: &[&str] = &[
    "0",
    "-1",
    "-9999999",
    "4294967295",
    "4294967296",
    "18446744073709551615",
    "1e30",
    "-1e38",
    "nan",
    "inf",
    "1e-45",
    "3",
    "/",
    "//",
    " ",
    "\n",
    "\\\n",
    "f ",
    "v ",
    "vt ",
    "vn ",
    "l ",
    "p ",
    "o x\n",
    "g \n",
    "usemtl a\n",
    "mtllib none.mtl\n",
    "#",
    "\u{feff}",
    "\r",
    ",",
    "\"",
    "{",
    "}",
    "[",
    "]",
    "null",
    "true",
    "-0",
    "2147483648",
    "65535",
    "5126",
    "5125",
    "5123",
    "5121",
    "34963",
];

/// One random edit of `input`.
fn mutate(input: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut out = input.to_vec();
    // Half the cases one edit (most still load), half several.
    let edits = if rng.below(2) == 0 { 1 } else { 2 + rng.below(4) };
    for _ in 0..edits {
        let at = rng.below(out.len() + 1);
        match rng.below(7) {
            0 if !out.is_empty() => {
                let i = at.min(out.len() - 1);
                out[i] ^= 1 << rng.below(8);
            }
            1 if !out.is_empty() => {
                let i = at.min(out.len() - 1);
                out[i] = rng.next() as u8;
            }
            2 => out.truncate(at),
            3 => {
                let token = TOKENS[rng.below(TOKENS.len())];
                out.splice(at..at, token.bytes());
            }
            4 if !out.is_empty() => {
                // Replace the number at `at` (if any) with a token.
                let i = at.min(out.len() - 1);
                let start = (0..=i).rev().take_while(|&k| out[k].is_ascii_digit() || out[k] == b'-' || out[k] == b'.').last().unwrap_or(i);
                let end = (i..out.len()).take_while(|&k| out[k].is_ascii_digit() || out[k] == b'.').last().map_or(i, |k| k + 1);
                let token = TOKENS[rng.below(17)];
                out.splice(start..end.max(start), token.bytes());
            }
            5 if !out.is_empty() => {
                // Duplicate a span (repeated statements, repeated chunks).
                let start = at.min(out.len() - 1);
                let end = (start + 1 + rng.below(64)).min(out.len());
                let span: Vec<u8> = out[start..end].to_vec();
                let to = rng.below(out.len() + 1);
                out.splice(to..to, span);
            }
            _ => {
                // Delete a span.
                let end = (at + 1 + rng.below(16)).min(out.len());
                out.drain(at.min(end)..end);
            }
        }
    }
    out
}

fn check(outcome: Result<Mesh, MeshError>, case: usize, kind: &str) -> bool {
    match outcome {
        Ok(mesh) => {
            if let Err(e) = mesh.validate() {
                panic!("{kind} case {case}: loaded an invalid mesh: {e}");
            }
            true
        }
        Err(e) => {
            let text = e.to_string();
            assert!(text.contains("fuzz."), "{kind} case {case}: the error does not name the file: {text}");
            false
        }
    }
}

const OBJ_SEED: &str = "# fuzz seed\nmtllib none.mtl\no box\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nvt 0 0\nvt 1 0\nvt 1 1\n\
vn 0 0 1\nvn 0 1 0\nusemtl red\nf 1/1/1 2/2/1 3/3/1\nf 1//1 3//1 4//1\ng side\nf -5 -4 -1\nf 1 2 3 4 5\nl 1 2 3\np 4\n";

fn seed_glb() -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("seed.glb");
    let mut mesh = obj::load_obj(Path::new("seed.obj"), OBJ_SEED.as_bytes(), UpAxis::Y, &mut Vec::new(), &mut Vec::new()).unwrap();
    mesh.materials[0].role = MaterialRole::Window;
    mesh.materials[0].transmittance = 0.7;
    write_glb(&path, &mesh).unwrap();
    std::fs::read(&path).unwrap()
}

/// A .gltf with an embedded buffer, a node hierarchy and every index type path.
const GLTF_SEED: &str = r#"{"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],
"nodes":[{"children":[1],"scale":[2,2,2]},{"mesh":0,"translation":[1,0,0]}],
"meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1,"mode":4}]}],
"buffers":[{"uri":"data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAIAAAA=","byteLength":44}],
"bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":36},{"buffer":0,"byteOffset":36,"byteLength":6}],
"accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]},
{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}]}"#;

#[test]
fn seeds_load() {
    let mut warnings = Vec::new();
    let obj = obj::load_obj(Path::new("fuzz.obj"), OBJ_SEED.as_bytes(), UpAxis::Y, &mut warnings, &mut Vec::new()).unwrap();
    assert!(obj.triangle_count() >= 6);
    let glb = gltf_load::load_gltf(Path::new("fuzz.glb"), &seed_glb(), &mut warnings, &mut Vec::new()).unwrap();
    assert_eq!(glb.triangle_count(), obj.triangle_count());
    let gltf = gltf_load::load_gltf(Path::new("fuzz.gltf"), GLTF_SEED.as_bytes(), &mut warnings, &mut Vec::new()).unwrap();
    assert_eq!(gltf.triangle_count(), 1);
}

/// 30,000 mutated inputs (10,000 per seed): every one loads a valid mesh or is
/// refused with the file named; a share of them must still load, or the
/// mutations would only be testing the first parse error.
#[test]
fn mutated_meshes_load_or_fail_cleanly() {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let glb = seed_glb();
    let dir = std::path::PathBuf::from("/nonexistent-fuzz-dir");
    let (mut loaded, mut cases) = ([0usize; 3], 0);
    for case in 0..10_000 {
        let mut warnings = Vec::new();
        let bytes = mutate(OBJ_SEED.as_bytes(), &mut rng);
        let up = if case % 2 == 0 { UpAxis::Y } else { UpAxis::Z };
        loaded[0] += check(obj::load_obj(&dir.join("fuzz.obj"), &bytes, up, &mut warnings, &mut Vec::new()), case, "obj") as usize;
        let bytes = mutate(&glb, &mut rng);
        loaded[1] += check(gltf_load::load_gltf(&dir.join("fuzz.glb"), &bytes, &mut warnings, &mut Vec::new()), case, "glb") as usize;
        let bytes = mutate(GLTF_SEED.as_bytes(), &mut rng);
        loaded[2] += check(gltf_load::load_gltf(&dir.join("fuzz.gltf"), &bytes, &mut warnings, &mut Vec::new()), case, "gltf") as usize;
        cases += 3;
    }
    eprintln!("{cases} mutated meshes: loaded obj {} / glb {} / gltf {} of 10000 each", loaded[0], loaded[1], loaded[2]);
    assert!(cases >= 30_000);
    assert!(loaded.iter().all(|&n| n >= 200), "too few mutants load: {loaded:?}");
}
