//! What prtbake promises about files (docs/safety.md), run as a careless or
//! hostile user would: outputs never destroy inputs or special files, all of
//! a command's outputs land together, interrupts leave nothing behind, reads
//! are bounded, and bad arguments get a clear error (exit 2), never a panic.

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::util::{prtbake, shared_data, Scratch};

/// A closed tetrahedron (four triangles facing out).
const TETRA: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Exit 2, no panic, and stderr contains every needle.
fn assert_refused(o: &Output, needles: &[&str]) {
    let e = stderr(o);
    assert_eq!(o.status.code(), Some(2), "expected exit 2: {e}");
    assert!(!e.contains("panicked"), "panicked: {e}");
    for needle in needles {
        assert!(e.contains(needle), "stderr lacks {needle:?}: {e}");
    }
}

fn assert_ok(o: &Output) {
    assert!(o.status.success(), "failed: {}", stderr(o));
}

/// Files in `dir` whose name says they are temporaries.
fn temporaries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir).unwrap().flatten().map(|e| e.file_name().to_string_lossy().into_owned()).filter(|n| n.contains(".tmp")).collect()
}

fn tetra(dir: &Scratch, name: &str) -> PathBuf {
    let path = dir.path(name);
    std::fs::write(&path, TETRA).unwrap();
    path
}

fn bake_quick(mesh: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["bake", s(mesh), "-o", s(out), "--rays", "4", "--order", "2", "--quiet"];
    args.extend(extra);
    prtbake(&args)
}

/// Item 1: an output that is an input (by any name) is refused and the input
/// is untouched; `sun B.prtb -o B.prtb` stays the one in-place update.
#[test]
fn outputs_never_overwrite_inputs() {
    let dir = Scratch::new("safety-inputs");
    let obj = tetra(&dir, "in.obj");
    let before = std::fs::read(&obj).unwrap();
    assert_refused(&bake_quick(&obj, &obj, &[]), &["in.obj", "is the input"]);
    assert_refused(&prtbake(&["sun", s(&obj), "-o", s(&obj)]), &["is the input"]);
    assert_refused(&prtbake(&["clean", s(&obj), "-o", s(&obj)]), &["is the input"]);
    assert_eq!(std::fs::read(&obj).unwrap(), before);

    let bundle = dir.path("b.prtb");
    assert_ok(&bake_quick(&obj, &bundle, &[]));
    let bundle_bytes = std::fs::read(&bundle).unwrap();
    // The same file through another spelling, and through a hard link.
    let dotted = dir.0.join(".").join("b.prtb");
    assert_refused(&prtbake(&["export", s(&bundle), "-o", s(&dotted)]), &["is the input"]);
    let hard = dir.path("hard.glb");
    std::fs::hard_link(&bundle, &hard).unwrap();
    assert_refused(&prtbake(&["export", s(&bundle), "-o", s(&hard)]), &["hard.glb", "is the input"]);
    assert_eq!(std::fs::read(&bundle).unwrap(), bundle_bytes);
    // Not in place with --refine: it replaces the bundle's mesh and transfer.
    assert_refused(&prtbake(&["sun", s(&bundle), "-o", s(&bundle), "--steps", "4", "--refine", "0.1", "--quiet"]), &["is the input"]);
    assert_eq!(std::fs::read(&bundle).unwrap(), bundle_bytes);
    // The documented in-place update.
    assert_ok(&prtbake(&["sun", s(&bundle), "-o", s(&bundle), "--steps", "4", "--quiet"]));
    assert_ne!(std::fs::read(&bundle).unwrap(), bundle_bytes);

    // The clean report may not be the cleaned mesh.
    let c = dir.path("c.obj");
    assert_refused(&prtbake(&["clean", s(&obj), "-o", s(&c), "--report", s(&c)]), &["named twice"]);
    assert!(!c.exists());
}

/// Item 1: a `.mtl` beside the output that prtbake did not write (here the
/// input's own library, with texture lines) is not replaced without --force;
/// nor is the material library the input's OBJ read.
#[test]
fn clean_keeps_material_libraries_it_did_not_write() {
    let dir = Scratch::new("safety-mtl");
    let obj = dir.path("spider.obj");
    std::fs::write(&obj, format!("mtllib spider.mtl\nusemtl fur\n{TETRA}")).unwrap();
    let mtl = dir.path("spider.mtl");
    let library = "newmtl fur\nKd 0.5 0.4 0.3\nKa 0.1 0.1 0.1\nmap_Kd fur.jpg\n";
    std::fs::write(&mtl, library).unwrap();
    // Writing spider.glb is fine; an OBJ named after the library would replace it.
    let other = dir.path("elsewhere").join("spider.obj");
    std::fs::create_dir(other.parent().unwrap()).unwrap();
    assert_ok(&prtbake(&["clean", s(&obj), "-o", s(&other), "--quiet"]));
    let sibling = dir.path("sub.obj");
    std::fs::write(dir.path("sub.mtl"), "newmtl mine\n").unwrap();
    assert_refused(&prtbake(&["clean", s(&obj), "-o", s(&sibling)]), &["sub.mtl", "not written by prtbake", "--force"]);
    assert_eq!(std::fs::read_to_string(dir.path("sub.mtl")).unwrap(), "newmtl mine\n");
    assert!(!sibling.exists(), "nothing lands when one output is refused");
    // An OBJ whose mtllib names another file: the output's .mtl may not be that input.
    let reads_shared = dir.path("a.obj");
    std::fs::write(&reads_shared, format!("mtllib out.mtl\n{TETRA}")).unwrap();
    std::fs::write(dir.path("out.mtl"), "# written by prtbake\nnewmtl x\nKd 1 0 0\n").unwrap();
    assert_refused(&prtbake(&["clean", s(&reads_shared), "-o", s(&dir.path("out.obj"))]), &["out.mtl", "is the input"]);
    assert_eq!(std::fs::read_to_string(&mtl).unwrap(), library);
    // --force replaces a foreign .mtl; a second run replaces prtbake's own.
    assert_ok(&prtbake(&["clean", s(&obj), "-o", s(&sibling), "--force", "--quiet"]));
    assert_ok(&prtbake(&["clean", s(&obj), "-o", s(&sibling), "--quiet"]));
    assert!(std::fs::read_to_string(dir.path("sub.mtl")).unwrap().starts_with("# written by prtbake"));
}

/// Item 1: the extension names what is written.
#[test]
fn output_extensions_name_the_format() {
    let dir = Scratch::new("safety-ext");
    let obj = tetra(&dir, "t.obj");
    assert_refused(&bake_quick(&obj, &dir.path("out.txt"), &[]), &["out.txt", "expected .prtb"]);
    let bundle = dir.path("t.prtb");
    assert_ok(&bake_quick(&obj, &bundle, &[]));
    assert_refused(&prtbake(&["export", s(&bundle), "-o", s(&dir.path("out.obj"))]), &["expected .glb"]);
    assert_refused(&prtbake(&["clean", s(&obj), "-o", s(&dir.path("c.stl"))]), &["expected .obj or .glb"]);
    assert_refused(&prtbake(&["clean", s(&obj), "-o", s(&dir.path("c.glb")), "--report", s(&dir.path("r.txt"))]), &["expected .json"]);
    assert!(std::fs::read_dir(&dir.0).unwrap().count() == 2, "refused runs wrote nothing");
}

/// Item 2: links are followed (the link stays, its target is replaced);
/// devices, FIFOs and directories are refused; read-only files need --force.
#[cfg(unix)]
#[test]
fn special_outputs_are_refused_and_links_followed() {
    let dir = Scratch::new("safety-special");
    let obj = tetra(&dir, "t.obj");
    let target = dir.path("real.prtb");
    std::fs::write(&target, "old").unwrap();
    let link = dir.path("link.prtb");
    std::os::unix::fs::symlink("real.prtb", &link).unwrap();
    assert_ok(&bake_quick(&obj, &link, &[]));
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink(), "the link was replaced");
    assert_ne!(std::fs::read(&target).unwrap(), b"old");

    assert_refused(&bake_quick(&obj, Path::new("/dev/null"), &[]), &["/dev/null", "character device"]);
    {
        use std::os::unix::fs::FileTypeExt;
        assert!(std::fs::metadata("/dev/null").unwrap().file_type().is_char_device(), "/dev/null was replaced");
    }
    let fifo = dir.path("pipe.prtb");
    let name = std::ffi::CString::new(s(&fifo)).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(name.as_ptr(), 0o644) }, 0);
    assert_refused(&bake_quick(&obj, &fifo, &[]), &["pipe.prtb", "a FIFO"]);
    let sub = dir.path("sub.prtb");
    std::fs::create_dir(&sub).unwrap();
    assert_refused(&bake_quick(&obj, &sub, &[]), &["is a directory"]);
    assert_refused(&bake_quick(&obj, Path::new(&format!("{}/", sub.display())), &[]), &["is a directory"]);
    assert_refused(&bake_quick(&obj, &dir.path("nodir/x.prtb"), &[]), &["nodir does not exist"]);

    let read_only = dir.path("ro.prtb");
    std::fs::write(&read_only, "keep").unwrap();
    let mut permissions = std::fs::metadata(&read_only).unwrap().permissions();
    permissions.set_readonly(true);
    std::fs::set_permissions(&read_only, permissions).unwrap();
    assert_refused(&bake_quick(&obj, &read_only, &[]), &["read-only", "--force"]);
    assert_eq!(std::fs::read(&read_only).unwrap(), b"keep");
    assert_ok(&bake_quick(&obj, &read_only, &["--force"]));
    assert!(temporaries(&dir.0).is_empty());
}

/// Item 3: clean's outputs land together or not at all.
#[test]
fn clean_outputs_land_together() {
    let dir = Scratch::new("safety-together");
    let obj = tetra(&dir, "t.obj");
    let c = dir.path("c.obj");
    assert_refused(&prtbake(&["clean", s(&obj), "-o", s(&c), "--report", s(&dir.path("nodir/r.json"))]), &["nodir does not exist"]);
    assert!(!c.exists() && !dir.path("c.mtl").exists(), "a refused clean wrote part of its outputs");
    assert_ok(&prtbake(&["clean", s(&obj), "-o", s(&c), "--report", s(&dir.path("r.json")), "--quiet"]));
    assert!(c.exists() && dir.path("c.mtl").exists() && dir.path("r.json").exists());
    assert!(temporaries(&dir.0).is_empty());
    // A name the folder cannot hold is refused before any work: the mesh and
    // its .mtl that would have landed first are untouched.
    let (obj_before, mtl_before) = (std::fs::read(&c).unwrap(), std::fs::read(dir.path("c.mtl")).unwrap());
    let long_report = dir.path(&format!("{}.json", "r".repeat(251)));
    let o = prtbake(&["clean", s(&obj), "-o", s(&c), "--report", s(&long_report), "--max-edge", "0.3", "--quiet"]);
    assert_refused(&o, &["256 bytes", "more than the 255"]);
    assert!(std::fs::read(&c).unwrap() == obj_before && std::fs::read(dir.path("c.mtl")).unwrap() == mtl_before);
    let long_bundle = dir.path(&format!("{}.prtb", "b".repeat(251)));
    let o = bake_quick(&obj, &long_bundle, &["--rays", "65536"]);
    assert_refused(&o, &["256 bytes"]);
    assert!(temporaries(&dir.0).is_empty());
}

/// Two OBJ names that differ only in bytes that are not UTF-8 must not share
/// one `.mtl`: such a name cannot be written in the OBJ's `mtllib` line, so it
/// is refused before any work.
#[cfg(unix)]
#[test]
fn obj_names_that_are_not_utf8_are_refused() {
    use std::os::unix::ffi::OsStrExt;
    let dir = Scratch::new("safety-mtl-names");
    let obj = tetra(&dir, "t.obj");
    for byte in [0xffu8, 0xfe] {
        let bytes = [b'o', b'u', b't', byte, b'.', b'o', b'b', b'j'];
        let out = dir.0.join(std::ffi::OsStr::from_bytes(&bytes));
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_prtbake")).arg("clean").arg(&obj).arg("-o").arg(&out).output().unwrap();
        assert_refused(&o, &["must be UTF-8"]);
        assert!(!out.exists());
    }
    assert_eq!(std::fs::read_dir(&dir.0).unwrap().count(), 1, "only the input is there");
    // The .mtl beside a name is that name's, byte for byte.
    let a = prtbake::mesh::mtl_path_for(&dir.0.join(std::ffi::OsStr::from_bytes(b"out\xff.obj")));
    let b = prtbake::mesh::mtl_path_for(&dir.0.join(std::ffi::OsStr::from_bytes(b"out\xfe.obj")));
    assert_ne!(a, b);
}

/// Item 4: Ctrl-C or SIGTERM during a bake exits 130/143 at once, says
/// nothing was written, and leaves no temporary; a 255-byte output name fits.
#[cfg(unix)]
#[test]
fn interrupts_leave_nothing_behind() {
    let dir = Scratch::new("safety-interrupt");
    // A mesh big enough that the bake runs for seconds.
    let mut text = String::new();
    let n = 120;
    for j in 0..=n {
        for i in 0..=n {
            text.push_str(&format!("v {} 0 {}\n", i as f32 / n as f32, j as f32 / n as f32));
        }
    }
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i + 1;
            text.push_str(&format!("f {a} {} {}\nf {} {} {}\n", a + n + 1, a + 1, a + 1, a + n + 1, a + n + 2));
        }
    }
    let obj = dir.path("grid.obj");
    std::fs::write(&obj, text).unwrap();
    for (signal, code) in [(libc::SIGINT, 130), (libc::SIGTERM, 143)] {
        let out = dir.path("slow.prtb");
        let child = std::process::Command::new(env!("CARGO_BIN_EXE_prtbake"))
            .args(["bake", s(&obj), "-o", s(&out), "--rays", "65536", "--quiet"])
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(700));
        // SAFETY: signalling our own child.
        unsafe { libc::kill(child.id() as i32, signal) };
        let o = child.wait_with_output().unwrap();
        assert_eq!(o.status.code(), Some(code), "{}", stderr(&o));
        assert!(stderr(&o).contains("no output of this run was written"), "{}", stderr(&o));
        assert!(!out.exists());
        assert!(temporaries(&dir.0).is_empty(), "{:?}", temporaries(&dir.0));
    }
    let long = dir.path(&format!("{}.prtb", "n".repeat(250)));
    assert_ok(&prtbake(&["bake", s(&obj), "-o", s(&long), "--rays", "1", "--quiet"]));
}

/// Item 6: a file name that is not UTF-8 is printed lossily, not a panic.
#[cfg(unix)]
#[test]
fn inspect_survives_a_non_utf8_name() {
    use std::os::unix::ffi::OsStrExt;
    let dir = Scratch::new("safety-utf8");
    let obj = tetra(&dir, "t.obj");
    let odd = dir.0.join(std::ffi::OsStr::from_bytes(b"b\xff.prtb"));
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_prtbake"))
        .arg("bake")
        .arg(&obj)
        .arg("-o")
        .arg(&odd)
        .args(["--rays", "4", "--json"])
        .output()
        .unwrap();
    assert_ok(&o);
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_prtbake")).arg("inspect").arg(&odd).arg("--json").output().unwrap();
    assert_ok(&o);
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(doc["file"].as_str().unwrap().ends_with("b\u{fffd}.prtb"), "{}", doc["file"]);
}

/// Item 7 and 14: thread counts, viewpoints and negative numbers are range-checked.
#[test]
fn numeric_arguments_are_range_checked() {
    let dir = Scratch::new("safety-args");
    let obj = tetra(&dir, "t.obj");
    let out = dir.path("o.prtb");
    for threads in ["100000", "1025"] {
        assert_refused(&bake_quick(&obj, &out, &["--threads", threads]), &["--threads", "at most"]);
        assert_refused(&prtbake(&["sun", s(&obj), "-o", s(&out), "--threads", threads]), &["--threads", "at most"]);
    }
    assert_refused(&prtbake(&["verify", "--threads", "100000"]), &["--threads"]);
    assert_refused(&bake_quick(&obj, &out, &["--view-box", "0,0,0,1,1,1", "--view-points", "100000000"]), &["--view-points"]);
    assert_refused(&prtbake(&["bake", s(&obj), "-o", s(&out), "--rays", "-1"]), &["invalid value '-1'", "--rays"]);
    assert_refused(&prtbake(&["sun", s(&obj), "-o", s(&out), "--steps", "-3"]), &["invalid value '-3'"]);
    assert!(!out.exists());
}

/// Item 9: inputs are read only from regular files and within their limits;
/// a bundle's magic is checked before its body is read.
#[cfg(unix)]
#[test]
fn reads_are_bounded() {
    let dir = Scratch::new("safety-reads");
    let out = dir.path("o.prtb");
    // A glTF buffer naming /dev/zero.
    let gltf = dir.path("zero.gltf");
    std::fs::write(&gltf, r#"{"asset":{"version":"2.0"},"buffers":[{"uri":"/dev/zero","byteLength":36}]}"#).unwrap();
    assert_refused(&bake_quick(&gltf, &out, &[]), &["zero.gltf", "/dev/zero", "character device"]);
    // An mtllib naming /dev/zero: a warning, the bake goes on with grey.
    let obj = dir.path("m.obj");
    std::fs::write(&obj, format!("mtllib /dev/zero\n{TETRA}")).unwrap();
    let o = prtbake(&["bake", s(&obj), "-o", s(&out), "--rays", "4"]);
    assert_ok(&o);
    assert!(stderr(&o).contains("character device"), "{}", stderr(&o));
    // --directions /dev/zero.
    let t = tetra(&dir, "t.obj");
    assert_refused(&prtbake(&["sun", s(&t), "-o", s(&out), "--directions", "/dev/zero"]), &["/dev/zero", "character device"]);
    // A FIFO as the mesh: refused at once rather than blocking.
    let fifo = dir.path("in.obj");
    let name = std::ffi::CString::new(s(&fifo)).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(name.as_ptr(), 0o644) }, 0);
    assert_refused(&bake_quick(&fifo, &out, &[]), &["in.obj", "a FIFO"]);
    // A 3 GiB sparse file that is not a bundle: refused after its first bytes.
    let big = dir.path("big.prtb");
    let f = std::fs::File::create(&big).unwrap();
    f.set_len(3 << 30).unwrap();
    assert_refused(&prtbake(&["inspect", s(&big)]), &["big.prtb", "not a prtbake bundle"]);
}

/// Review item 10: a file whose header gives (or bounds) its size is
/// checked against the file's size before its body is read. Each input is a
/// valid file extended to a sparse 3 GiB: bundles (`inspect`, `sun`,
/// `export`), a shard part (`merge`), a GLB and a glTF whose buffer declares
/// a byteLength of 10¹⁵ (`bake`), an EXR and a Radiance HDR (`panel --env`).
/// Each is refused with exit 2, the file named and what is wrong said, and
/// the run's peak memory stays under 200 MB (reading the file whole took
/// 3.1 GB).
#[cfg(unix)]
#[test]
fn sizes_are_checked_against_headers_before_reading() {
    const BIG: u64 = 3 << 30;
    const PEAK_MAX: u64 = 200 << 20;
    let dir = Scratch::new("safety-sizes");
    let grow = |from: &Path, name: &str| {
        let to = dir.path(name);
        std::fs::copy(from, &to).unwrap();
        std::fs::OpenOptions::new().write(true).open(&to).unwrap().set_len(BIG).unwrap();
        to
    };
    let mesh = tetra(&dir, "t.obj");
    let bundle = dir.path("t.prtb");
    assert_ok(&bake_quick(&mesh, &bundle, &[]));
    let part = dir.path("t.prtp");
    assert_ok(&bake_quick(&mesh, &part, &["--shard", "0/1", "--adaptive", "0"]));
    let glb = dir.path("t.glb");
    assert_ok(&prtbake(&["export", s(&bundle), "-o", s(&glb)]));
    let exr = dir.path("t.exr");
    exr::prelude::write_rgb_file(&exr, 64, 32, |_, _| (1.0f32, 1.0f32, 1.0f32)).unwrap();
    let hdr = dir.path("t.hdr");
    let mut hdr_bytes = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 2\n".to_vec();
    hdr_bytes.extend([128u8, 128, 128, 129].repeat(4));
    std::fs::write(&hdr, hdr_bytes).unwrap();
    // The small maps light a flat panel (a quad: the tetrahedron faces both ways).
    let quad = dir.path("q.obj");
    std::fs::write(&quad, "v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nf 1 4 3\nf 1 3 2\n").unwrap();
    let quad_bundle = dir.path("q.prtb");
    assert_ok(&bake_quick(&quad, &quad_bundle, &[]));
    for small in [&exr, &hdr] {
        let args =
            ["panel", s(&quad_bundle), "--eye", "0.5,1,0.5", "--env", s(small), "--panel", "default", "--texels", "2x2", "--samples", "1"];
        assert_ok(&prtbake(&[&args[..], &["-o", s(&dir.path("p.exr"))]].concat()));
    }
    let (big_bundle, big_part, big_glb) = (grow(&bundle, "big.prtb"), grow(&part, "big.prtp"), grow(&glb, "big.glb"));
    let (big_exr, big_hdr) = (grow(&exr, "big.exr"), grow(&hdr, "big.hdr"));
    let big_bin = dir.path("big.bin");
    std::fs::File::create(&big_bin).unwrap().set_len(BIG).unwrap();
    let gltf = dir.path("huge.gltf");
    std::fs::write(&gltf, r#"{"asset":{"version":"2.0"},"buffers":[{"uri":"big.bin","byteLength":1000000000000000}]}"#).unwrap();
    let out = dir.path("o.prtb");
    let trailing = format!("{} trailing bytes after the", BIG - std::fs::metadata(&bundle).unwrap().len());
    let panel = |env: &Path| {
        vec![
            "panel".to_string(),
            s(&bundle).into(),
            "--eye".into(),
            "0.2,0.2,0.2".into(),
            "--env".into(),
            s(env).into(),
            "-o".into(),
            s(&dir.path("p.exr")).into(),
        ]
    };
    let cases: Vec<(Vec<String>, Vec<String>)> = vec![
        (vec!["inspect".into(), s(&big_bundle).into()], vec!["big.prtb".into(), trailing.clone()]),
        (vec!["sun".into(), s(&big_bundle).into(), "-o".into(), s(&out).into()], vec!["big.prtb".into(), trailing.clone()]),
        (vec!["export".into(), s(&big_bundle).into(), "-o".into(), s(&dir.path("e.glb")).into()], vec!["big.prtb".into(), trailing]),
        (
            vec!["merge".into(), s(&big_part).into(), "-o".into(), s(&out).into()],
            vec!["big.prtp".into(), format!("is {BIG} bytes and does not end in its own length and CRC-32")],
        ),
        (vec!["bake".into(), s(&big_glb).into(), "-o".into(), s(&out).into()], vec!["big.glb".into(), "bytes past its end".into()]),
        (
            vec!["bake".into(), s(&gltf).into(), "-o".into(), s(&out).into()],
            vec!["huge.gltf".into(), "byteLength 1000000000000000".into(), format!("holds only {BIG} bytes")],
        ),
        (panel(&big_exr), vec!["big.exr".into(), format!("is {BIG} bytes"), "64×32 image".into()]),
        (panel(&big_hdr), vec!["big.hdr".into(), format!("is {BIG} bytes"), "2×2 image".into()]),
    ];
    for (args, needles) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (output, peak) = crate::util::prtbake_peak_memory(&args);
        assert_refused(&output, &needles.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(peak < PEAK_MAX, "prtbake {}: peak memory {} MB", args.join(" "), peak >> 20);
    }
}

/// Item 12: OBJ polylines are not surfaces.
#[test]
fn obj_polylines_are_not_baked() {
    let dir = Scratch::new("safety-lines");
    let obj = dir.path("lines.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nl 1 2 3\nl 2 3 4\nl 1 2\nl 3 4 1 2\nl 1 3\nl 2 4\n").unwrap();
    assert_refused(&bake_quick(&obj, &dir.path("l.prtb"), &[]), &["lines.obj", "no triangles"]);
    let mixed = dir.path("mixed.obj");
    std::fs::write(&mixed, format!("{TETRA}l 1 2 3\n")).unwrap();
    let o = prtbake(&["bake", s(&mixed), "-o", s(&dir.path("m.prtb")), "--rays", "4"]);
    assert_ok(&o);
    assert!(stderr(&o).contains("1 polyline statement(s) (`l`, first at line 9) skipped"), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains(": 4 triangles,"), "{}", String::from_utf8_lossy(&o.stdout));
}

/// Item 14: directions CSVs with a byte-order mark and huge components; OBJ
/// parse errors with their line.
#[test]
fn small_input_rough_edges() {
    let dir = Scratch::new("safety-small");
    let obj = tetra(&dir, "t.obj");
    let csv = dir.path("d.csv");
    std::fs::write(&csv, "\u{feff}0,1,0\n1e30,1e30,1e30\n").unwrap();
    let out = dir.path("s.prtb");
    assert_ok(&prtbake(&["sun", s(&obj), "-o", s(&out), "--directions", s(&csv), "--quiet"]));
    let o = prtbake(&["inspect", s(&out), "--json"]);
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(doc["sun"]["steps"], 2);
    let bad = dir.path("bad.obj");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 1\nf 1 2 3\n").unwrap();
    assert_refused(&bake_quick(&bad, &out, &[]), &["bad.obj", "line 4"]);
}

/// The bad-and-edge corpus through `bake`, `clean` and `inspect`: no panic,
/// exit 0 or 2, and every error names the file.
#[test]
fn bad_and_edge_corpus_through_the_commands() {
    let Some(corpus) = shared_data("bad-and-edge-inputs") else { return };
    let dir = Scratch::new("safety-corpus");
    let mut files = Vec::new();
    let mut pending = vec![corpus];
    while let Some(folder) = pending.pop() {
        for entry in std::fs::read_dir(&folder).unwrap().flatten() {
            let path = entry.path();
            if path.is_dir() {
                pending.push(path);
            } else if matches!(path.extension().and_then(|e| e.to_str()), Some("obj" | "gltf" | "glb")) {
                files.push(path);
            }
        }
    }
    files.sort();
    assert!(files.len() > 50, "only {} corpus files", files.len());
    let (mut ok, mut refused) = (0, 0);
    for file in &files {
        let name = file.file_name().unwrap().to_string_lossy().into_owned();
        let runs = [
            prtbake(&["bake", s(file), "-o", s(&dir.path("c.prtb")), "--rays", "2", "--order", "1", "--quiet"]),
            prtbake(&["clean", s(file), "-o", s(&dir.path("c.glb")), "--quiet"]),
            prtbake(&["inspect", s(file)]),
        ];
        for (command, o) in ["bake", "clean", "inspect"].iter().zip(&runs) {
            let e = stderr(o);
            assert!(!e.contains("panicked"), "{command} {name} panicked: {e}");
            match o.status.code() {
                Some(0) => ok += 1,
                Some(2) => {
                    refused += 1;
                    assert!(e.contains(&name), "{command} {name}: the error does not name the file: {e}");
                }
                other => panic!("{command} {name}: exit {other:?}: {e}"),
            }
        }
    }
    eprintln!("corpus: {} files, {ok} runs succeeded, {refused} refused with the file named", files.len());
    assert!(temporaries(&dir.0).is_empty());
}
