//! Sharded bakes (docs/scale.md): shards run as separate processes in any
//! order and at any thread count, merged round by round, give the bundle a
//! single process writes, byte for byte; merges name missing, repeated and
//! foreign parts.

use std::path::{Path, PathBuf};

use crate::util::{prtbake, Scratch};

/// The demo cabin at low detail (11,738 triangles and 6,746 vertices once
/// cleaned; 12,186 sample points, 34 of them inside geometry), with its
/// injected defects (`bake --clean` repairs them in every process), as GLB.
pub fn write_cabin(dir: &Scratch) -> PathBuf {
    let (mesh, _) = prtbake::fixtures::cabin::generate_cabin(10.0);
    let path = dir.path("cabin.glb");
    prtbake::mesh::write_glb(&path, &mesh).unwrap();
    path
}

/// Window light, three bounces, colour, each bounce stored, cleaned inline:
/// every piece of a bake's bundle that a merge has to reproduce.
/// Adaptive allocation (bake's default) gives the shards a pilot stage.
const BAKE_ARGS: &[&str] = &["--window", "glass", "--bounces", "3", "--rays", "12", "--seed", "5", "--store-bounces", "--clean", "--quiet"];

fn run(args: &[&str]) -> String {
    let out = prtbake(args);
    assert!(out.status.success(), "prtbake {}: {}", args.join(" "), String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Runs `prtbake args` expecting exit 2, and returns its stderr.
fn refused(args: &[&str]) -> String {
    let out = prtbake(args);
    assert_eq!(out.status.code(), Some(2), "prtbake {} should fail: {}", args.join(" "), String::from_utf8_lossy(&out.stdout));
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A fixed shuffle of 0..n (the shards' run order and the parts' merge order).
fn shuffled(n: u32, salt: u32) -> Vec<u32> {
    let mut order: Vec<u32> = (0..n).collect();
    let mut state = 0x9e37_79b9u32 ^ salt.wrapping_mul(0x85eb_ca6b);
    for i in (1..order.len()).rev() {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        order.swap(i, state as usize % (i + 1));
    }
    order
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `merge INPUTS… -o OUT`.
fn merge<'a>(inputs: &[&'a Path], out: &'a Path) -> Vec<&'a str> {
    let mut a = vec!["merge", "-o", s(out)];
    a.extend(inputs.iter().map(|p| s(p)));
    a
}

/// Runs every round of a sharded transfer bake of `mesh` into `dir`, as a
/// scheduler would (shards in shuffled order, 1 or 2 threads), and returns
/// the merged bundle. `part(round, k)` names each part.
fn sharded_bake(dir: &Path, mesh: &Path, args: &[&str], bounces: u32, n: u32) -> PathBuf {
    let part = |round: u32, k: u32| dir.join(format!("r{round}-{k}.prtp"));
    let layer = |round: u32| dir.join(format!("r{round}.prtl"));
    let bundle = dir.join("merged.prtb");
    // Adaptive allocation (unless --adaptive 0): the pilot stage, merged into the pilot every round reads.
    let pilot = dir.join("pilot.prta");
    let adaptive = !args.windows(2).any(|w| w == ["--adaptive", "0"]) || args.contains(&"--texel-adaptive");
    if adaptive {
        let pilot_part = |k: u32| dir.join(format!("pilot-{k}.prtp"));
        for k in shuffled(n, 50) {
            let (shard, threads) = (format!("{k}/{n}"), (1 + k % 2).to_string());
            let part = pilot_part(k);
            let mut a = vec!["bake", s(mesh), "-o", s(&part), "--shard", &shard, "--round", "pilot", "--threads", &threads];
            a.extend(args);
            run(&a);
        }
        let parts: Vec<PathBuf> = shuffled(n, 51).into_iter().map(pilot_part).collect();
        let mut a = vec!["merge", "-o", s(&pilot)];
        a.extend(parts.iter().map(|p| s(p)));
        run(&a);
    }
    for round in 0..=bounces {
        for k in shuffled(n, round) {
            let (shard, round_text, threads) = (format!("{k}/{n}"), round.to_string(), (1 + k % 2).to_string());
            let previous = layer(round.saturating_sub(1));
            let part = part(round, k);
            let mut a = vec!["bake", s(mesh), "-o", s(&part), "--shard", &shard, "--round", &round_text, "--threads", &threads];
            if round > 0 {
                a.extend(["--layer", s(&previous)]);
            }
            if adaptive {
                a.extend(["--pilot", s(&pilot)]);
            }
            a.extend(args);
            run(&a);
        }
        let parts: Vec<PathBuf> = shuffled(n, round + 100).into_iter().map(|k| part(round, k)).collect();
        let out = if round == bounces { bundle.clone() } else { layer(round) };
        let previous = layer(round.saturating_sub(1));
        let mut a = vec!["merge", "-o", s(&out)];
        a.extend(parts.iter().map(|p| s(p)));
        if round > 0 {
            a.extend(["--layer", s(&previous)]);
        }
        run(&a);
    }
    bundle
}

#[test]
fn sharded_transfer_merges_into_the_single_process_bundle() {
    let dir = Scratch::new("shards-transfer");
    let mesh = write_cabin(&dir);
    let single = dir.path("single.prtb");
    let mut a = vec!["bake", s(&mesh), "-o", s(&single), "--threads", "2"];
    a.extend(BAKE_ARGS);
    run(&a);
    let expected = std::fs::read(&single).unwrap();
    for n in [1u32, 2, 3, 7] {
        let work = dir.path(&format!("n{n}"));
        std::fs::create_dir(&work).unwrap();
        let merged = sharded_bake(&work, &mesh, BAKE_ARGS, 3, n);
        assert!(std::fs::read(&merged).unwrap() == expected, "{n} shards: the merged bundle differs from the single-process bake");
    }
    // --max-error budgets the total error, the bake's noise included: the
    // parts carry the noise's moments, so the merge chooses the same storage.
    let budgeted: Vec<&str> = BAKE_ARGS.iter().copied().chain(["--max-error", "0.3"]).collect();
    let single = dir.path("single-budget.prtb");
    let mut a = vec!["bake", s(&mesh), "-o", s(&single), "--threads", "2"];
    a.extend(&budgeted);
    run(&a);
    let storage = prtbake::bundle::read_bundle(&single).unwrap().meta["storage"].clone();
    assert!(storage["noise_error"].as_f64().is_some_and(|n| n > 0.0), "{storage}");
    let work = dir.path("budget");
    std::fs::create_dir(&work).unwrap();
    let merged = sharded_bake(&work, &mesh, &budgeted, 3, 3);
    assert!(std::fs::read(&merged).unwrap() == std::fs::read(&single).unwrap(), "3 shards with --max-error: the merged bundle differs");
    // Uniform points (--adaptive 0): no pilot stage, the same promise.
    let uniform: Vec<&str> = BAKE_ARGS.iter().copied().chain(["--adaptive", "0"]).collect();
    let single = dir.path("single-uniform.prtb");
    let mut a = vec!["bake", s(&mesh), "-o", s(&single), "--threads", "2"];
    a.extend(&uniform);
    run(&a);
    let work = dir.path("uniform");
    std::fs::create_dir(&work).unwrap();
    let merged = sharded_bake(&work, &mesh, &uniform, 3, 2);
    assert!(std::fs::read(&merged).unwrap() == std::fs::read(&single).unwrap(), "2 uniform shards: the merged bundle differs");
    // Adaptive rounds need the pilot, and every round 0 shard the same one.
    let lone = dir.path("lone.prtp");
    let mut a = vec!["bake", s(&mesh), "-o", s(&lone), "--shard", "0/3", "--round", "0"];
    a.extend(BAKE_ARGS);
    let e = refused(&a);
    assert!(e.contains("needs --pilot"), "{e}");
    assert!(!lone.exists());
    let mut a = vec!["bake", s(&mesh), "-o", s(&lone), "--shard", "0/3", "--round", "pilot"];
    a.extend(&uniform);
    let e = refused(&a);
    assert!(e.contains("--adaptive 0"), "{e}");
}

#[test]
fn sharded_sun_merges_into_the_single_process_bundle() {
    let dir = Scratch::new("shards-sun");
    let mesh = write_cabin(&dir);
    let args = ["--window", "glass", "--steps", "24", "--seed", "3", "--quiet"];
    let single = dir.path("single.prtb");
    let mut a = vec!["sun", s(&mesh), "-o", s(&single)];
    a.extend(args);
    run(&a);
    let expected = std::fs::read(&single).unwrap();
    for n in [1u32, 2, 3, 7] {
        let part = |k: u32| dir.path(&format!("sun-{n}-{k}.prtp"));
        for k in shuffled(n, 7) {
            let (shard, threads) = (format!("{k}/{n}"), (1 + k % 2).to_string());
            let p = part(k);
            let mut a = vec!["sun", s(&mesh), "-o", s(&p), "--shard", &shard, "--threads", &threads];
            a.extend(args);
            run(&a);
        }
        let merged = dir.path(&format!("sun-{n}.prtb"));
        let parts: Vec<PathBuf> = shuffled(n, 8).into_iter().map(part).collect();
        let mut a = vec!["merge", "-o", s(&merged)];
        a.extend(parts.iter().map(|p| s(p)));
        run(&a);
        assert!(std::fs::read(&merged).unwrap() == expected, "{n} sun shards: the merged bundle differs from the single-process one");
    }
    // A part of another day, or another seed, is named; so is a missing one.
    let foreign = dir.path("sun-foreign.prtp");
    let mut a = vec!["sun", s(&mesh), "-o", s(&foreign), "--shard", "1/3"];
    a.extend(args);
    a.extend(["--turbidity", "4"]);
    run(&a);
    let parts = [dir.path("sun-3-0.prtp"), foreign.clone(), dir.path("sun-3-2.prtp")];
    let e = refused(&merge(&[&parts[0], &parts[1], &parts[2]], &dir.path("x.prtb")));
    assert!(e.contains(&format!("{}: day and sky", foreign.display())), "{e}");
    let e = refused(&merge(&[&parts[0], &parts[2]], &dir.path("x.prtb")));
    assert!(e.contains("missing part(s) of 3 shards: 1 (given: 0, 2)"), "{e}");
    let e = refused(&merge(&[&parts[0], &dir.path("sun-2-1.prtp"), &parts[2]], &dir.path("x.prtb")));
    assert!(e.contains("sun-2-1.prtp: is one of 2 shards, not of 3"), "{e}");
}

/// Texel mode's sun through shards, for each way a texel sun bake starts:
/// a mesh given a new atlas (with the texels' lit shares), a per-vertex
/// bundle given one, a texel bundle with its own, and a texel bundle whose
/// sun gets an atlas of its own (TSAT, its charts repacked). The single process
/// writes the same bundle at 1 and 2 threads, and 1, 2 and 3 shards (run
/// in shuffled order at 1 or 2 threads) merge into it byte for byte; a part
/// of other texel settings is named.
#[test]
fn sharded_texel_sun_merges_into_the_single_process_bundle() {
    let dir = Scratch::new("shards-texel-sun");
    let mesh = write_cabin(&dir);
    let vertex_bundle = dir.path("vertices.prtb");
    run(&["bake", s(&mesh), "-o", s(&vertex_bundle), "--window", "glass", "--rays", "4", "--bounces", "1", "--quiet"]);
    let texel_bundle = dir.path("texels.prtb");
    run(&[
        "bake",
        s(&mesh),
        "-o",
        s(&texel_bundle),
        "--window",
        "glass",
        "--rays",
        "4",
        "--bounces",
        "1",
        "--texel-size",
        "0.08",
        "--quiet",
    ]);
    let common = ["--window", "glass", "--steps", "12", "--seed", "3", "--quiet"];
    let cases: [(&str, &Path, &[&str], &str); 5] = [
        ("mesh", &mesh, &["--texel-size", "0.06", "--texel-fractions"], "\"TSUN\""),
        // A texel size per chart: every shard runs the pilot and sizes the same charts.
        ("levels", &mesh, &["--texel-size", "0.04", "--texel-levels", "2", "--max-error", "0.05"], "\"TSUN\""),
        ("vertex-bundle", &vertex_bundle, &["--texel-size", "0.06"], "\"TSUN\""),
        ("texel-bundle", &texel_bundle, &["--texel-fractions"], "\"TSUN\""),
        ("sun-atlas", &texel_bundle, &["--texel-size", "0.04", "--texel-fractions"], "\"TSAB\""),
    ];
    for (name, input, texel_args, section) in cases {
        let sun = |out: &Path, extra: &[&str]| {
            let mut a = vec!["sun", s(input), "-o", s(out)];
            a.extend(common);
            a.extend(texel_args);
            a.extend(extra);
            run(&a)
        };
        let single = dir.path(&format!("{name}.prtb"));
        sun(&single, &["--threads", "2"]);
        let expected = std::fs::read(&single).unwrap();
        let one_thread = dir.path(&format!("{name}-1.prtb"));
        sun(&one_thread, &["--threads", "1"]);
        assert!(std::fs::read(&one_thread).unwrap() == expected, "{name}: the bundle differs between 1 and 2 threads");
        let inspect = run(&["inspect", s(&single), "--json"]);
        assert!(inspect.contains(section), "{name}: no texel sun section {section} in {inspect}");
        for n in [1u32, 2, 3] {
            let part = |k: u32| dir.path(&format!("{name}-{n}-{k}.prtp"));
            for k in shuffled(n, 11) {
                let (shard, threads) = (format!("{k}/{n}"), (1 + k % 2).to_string());
                let stdout = sun(&part(k), &["--shard", &shard, "--threads", &threads]);
                assert!(stdout.contains("; texels "), "{name}: shard {shard} traced no texels: {stdout}");
            }
            let merged = dir.path(&format!("{name}-{n}.prtb"));
            let parts: Vec<PathBuf> = shuffled(n, 12).into_iter().map(part).collect();
            let mut a = vec!["merge", "-o", s(&merged)];
            a.extend(parts.iter().map(|p| s(p)));
            run(&a);
            assert!(
                std::fs::read(&merged).unwrap() == expected,
                "{name}, {n} shards: the merged bundle differs from the single-process one"
            );
        }
    }
    // Other points per texel, or no texels at all, in one part: named.
    let foreign = dir.path("foreign.prtp");
    let mut a =
        vec!["sun", s(&mesh), "-o", s(&foreign), "--shard", "1/2", "--texel-size", "0.06", "--texel-fractions", "--texel-points", "8"];
    a.extend(common);
    run(&a);
    let e = refused(&merge(&[&dir.path("mesh-2-0.prtp"), &foreign], &dir.path("x.prtb")));
    assert!(e.contains("foreign.prtp: texel mode 0.06 m texels, 8 points each here, 0.06 m texels, 4 points each in"), "{e}");
    let mut a = vec!["sun", s(&mesh), "-o", s(&foreign), "--shard", "1/2"];
    a.extend(common);
    run(&a);
    let e = refused(&merge(&[&dir.path("mesh-2-0.prtp"), &foreign], &dir.path("x.prtb")));
    assert!(e.contains("foreign.prtp: texel mode off here"), "{e}");
    assert!(!dir.path("x.prtb").exists());
}

/// Texel transfer through shards, with the denoiser the merge runs after
/// the last round and the storage `--max-error` chooses: each shard traces its range of covered texels beside
/// its items, and 1 and 3 shards (shuffled, at 1 or 2 threads) merge into
/// the single process's bundle, itself the same at 1 and 2 threads. So
/// does a per-vertex bake with `--denoise`. A part of other texel settings,
/// and a layer without texels, are named.
#[test]
fn sharded_texel_transfer_merges_into_the_single_process_bundle() {
    let dir = Scratch::new("shards-texel-transfer");
    let mesh = write_cabin(&dir);
    let texel_args: &[&str] = &[
        "--window",
        "glass",
        "--bounces",
        "2",
        "--rays",
        "12",
        "--seed",
        "5",
        "--store-bounces",
        "--clean",
        "--quiet",
        "--max-error",
        "0.5",
        "--texel-size",
        "0.05",
        "--texel-points",
        "2",
        "--denoise",
        "1",
    ];
    let single = |name: &str, args: &[&str], threads: &str| {
        let out = dir.path(name);
        let mut a = vec!["bake", s(&mesh), "-o", s(&out), "--threads", threads];
        a.extend(args);
        run(&a);
        std::fs::read(&out).unwrap()
    };
    let expected = single("single.prtb", texel_args, "2");
    assert!(expected == single("single-1.prtb", texel_args, "1"), "the single-process texel bundle differs between 1 and 2 threads");
    let b = prtbake::bundle::read_bundle(&dir.path("single.prtb")).unwrap();
    let texels = b.texels.as_ref().expect("a texel bundle");
    assert!(texels.texels.len() > 10_000 && texels.transfer.as_ref().unwrap().layers.len() == 4, "{} texels", texels.texels.len());
    // The budget chose one storage for vertices and texels, measured on both.
    assert!(b.meta["texels"]["storage"]["within_budget"] == true && b.meta["storage"]["within_budget"] == true, "{}", b.meta);
    for n in [1u32, 3] {
        let work = dir.path(&format!("texels-n{n}"));
        std::fs::create_dir(&work).unwrap();
        let merged = sharded_bake(&work, &mesh, texel_args, 2, n);
        assert!(std::fs::read(&merged).unwrap() == expected, "{n} shards: the merged texel bundle differs from the single-process bake");
    }
    // The vertices with fewer rays than the texels (`--vertex-rays`): the
    // texels are those of the bake above; shards merge into the same bytes.
    let few: Vec<&str> = texel_args.iter().copied().chain(["--vertex-rays", "4"]).collect();
    let expected_few = single("few.prtb", &few, "2");
    let f = prtbake::bundle::read_bundle(&dir.path("few.prtb")).unwrap();
    assert_eq!(f.meta["texels"]["vertex_rays"], 4, "{}", f.meta);
    let shown = run(&["inspect", s(&dir.path("few.prtb"))]);
    assert!(shown.contains("vertices baked with 4 rays a point"), "{shown}");
    // A third of the vertices' rays (adaptive allocation places its extra points by what they found).
    let vertex_rays = |m: &serde_json::Value| m["stats"]["rays_per_bounce"][0].as_u64().unwrap() as f64;
    assert!((3.0 * vertex_rays(&f.meta) / vertex_rays(&b.meta) - 1.0).abs() < 0.01, "{} vs {}", f.meta["stats"], b.meta["stats"]);
    let work = dir.path("texels-few");
    std::fs::create_dir(&work).unwrap();
    let merged = sharded_bake(&work, &mesh, &few, 2, 2);
    assert!(std::fs::read(&merged).unwrap() == expected_few, "2 shards with --vertex-rays 4: the merged texel bundle differs");
    // Extra texel points (`--texel-adaptive`) placed by the pilot stage's
    // merged texels, with the vertices' adaptive allocation and without it.
    for (name, extra) in [("grown", &["--texel-adaptive", "1"][..]), ("grown-only", &["--texel-adaptive", "0.5", "--adaptive", "0"][..])] {
        let args: Vec<&str> = texel_args.iter().copied().chain(extra.iter().copied()).collect();
        let expected = single(&format!("{name}.prtb"), &args, "2");
        let g = prtbake::bundle::read_bundle(&dir.path(&format!("{name}.prtb"))).unwrap();
        assert!(g.meta["texels"]["points_added"].as_u64() > Some(0), "{name}: {}", g.meta["texels"]);
        let work = dir.path(&format!("texels-{name}"));
        std::fs::create_dir(&work).unwrap();
        let merged = sharded_bake(&work, &mesh, &args, 2, 2);
        assert!(std::fs::read(&merged).unwrap() == expected, "{name}, 2 shards: the merged texel bundle differs");
        // The pilot stage traces the vertices' points only when their own
        // allocation reads them; the texels' always.
        let probe = work.join("probe.prtp");
        let mut a = vec!["bake", s(&mesh), "-o", s(&probe), "--shard", "0/2", "--round", "pilot", "--json"];
        a.extend(&args);
        let shown: serde_json::Value = serde_json::from_str(&run(&a)).unwrap();
        assert_eq!(shown["rays"].as_u64() == Some(0), name == "grown-only", "{name}: {shown}");
        assert!(shown["texels"]["rays"].as_u64() > Some(0), "{name}: {shown}");
    }
    // A texel size per chart (`--texel-levels`): every shard's round 0 (and
    // pilot stage) runs the pilot, later rounds repack the atlas by the
    // levels kept with their hit records; the merge carries META `texels.density`.
    let levels: Vec<&str> = texel_args.iter().map(|&a| if a == "0.5" { "0.05" } else { a }).chain(["--texel-levels", "2"]).collect();
    let expected_levels = single("levels.prtb", &levels, "2");
    let l = prtbake::bundle::read_bundle(&dir.path("levels.prtb")).unwrap();
    let per_level = &l.meta["texels"]["density"]["charts_per_level"];
    assert!(per_level[0].as_u64() > Some(0) && per_level[1].as_u64() > Some(0), "both sizes in use: {}", l.meta["texels"]);
    let work = dir.path("texels-levels");
    std::fs::create_dir(&work).unwrap();
    let merged = sharded_bake(&work, &mesh, &levels, 2, 2);
    assert!(std::fs::read(&merged).unwrap() == expected_levels, "2 shards with --texel-levels: the merged texel bundle differs");
    // Round 1 given hit records of a bake without the levels: named.
    let (x, r0, pilot, few_dir) = (work.join("x.prtp"), work.join("r0.prtl"), work.join("pilot.prta"), dir.path("texels-few"));
    let mut a = vec!["bake", s(&mesh), "-o", s(&x), "--shard", "0/2", "--round", "1"];
    a.extend(["--layer", s(&r0), "--pilot", s(&pilot), "--shard-dir", s(&few_dir)]);
    a.extend(&levels);
    let e = refused(&a);
    assert!(e.contains("hits-0-of-2.prth: shard 0/2's hit records hold no chart levels"), "{e}");
    // Per vertex, denoised by the merge.
    let vertex_args: Vec<&str> = texel_args[..texel_args.len() - 6].iter().copied().chain(["--denoise", "1"]).collect();
    let expected = single("vertex.prtb", &vertex_args, "2");
    let work = dir.path("vertex");
    std::fs::create_dir(&work).unwrap();
    let merged = sharded_bake(&work, &mesh, &vertex_args, 2, 2);
    assert!(std::fs::read(&merged).unwrap() == expected, "2 denoised vertex shards: the merged bundle differs");
    // Shard 2 of 3's pilot with 3 points per texel, beside the others' 2.
    let work = dir.path("texels-n3");
    let odd = work.join("odd.prtp");
    let points_3: Vec<&str> =
        texel_args.iter().copied().take(texel_args.len() - 4).chain(["--texel-points", "3", "--denoise", "1"]).collect();
    let mut a = vec!["bake", s(&mesh), "-o", s(&odd), "--shard", "2/3", "--round", "pilot"];
    a.extend(&points_3);
    run(&a);
    let (p0, p1) = (work.join("pilot-0.prtp"), work.join("pilot-1.prtp"));
    let e = refused(&merge(&[&p0, &p1, &odd], &dir.path("x.prta")));
    assert!(e.contains("odd.prtp") && e.contains("texel mode 0.05 m texels, 3 points each here, 0.05 m texels, 2 points each in"), "{e}");
    // Round 1 of a texel bake given the pilot, layer and hit records of a per-vertex bake.
    let vertex = dir.path("vertex");
    let (layer, pilot) = (vertex.join("r0.prtl"), vertex.join("pilot.prta"));
    let mut a = vec!["bake", s(&mesh), "-o", s(&odd), "--shard", "0/2", "--round", "1", "--layer", s(&layer), "--pilot", s(&pilot)];
    a.extend(["--shard-dir", s(&vertex)]);
    a.extend(texel_args);
    let e = refused(&a);
    assert!(e.contains("texel mode off here, 0.05 m texels, 2 points each in") && e.contains("another bake's"), "{e}");
}

/// A re-run shard writes the same bytes; a merge refuses a missing, a
/// repeated and a foreign part, naming it, and writes nothing.
#[test]
fn shards_are_idempotent_and_merges_name_bad_parts() {
    let dir = Scratch::new("shards-errors");
    let mesh = write_cabin(&dir);
    let args = ["--window", "glass", "--bounces", "1", "--rays", "8", "--adaptive", "0", "--quiet"];
    let bake = |shard: &str, round: &str, out: &Path, extra: &[&str]| {
        let mut a = vec!["bake", s(&mesh), "-o", s(out), "--shard", shard, "--round", round];
        a.extend(args);
        a.extend(extra);
        run(&a);
    };
    let parts: Vec<PathBuf> = (0..3).map(|k| dir.path(&format!("r0-{k}.prtp"))).collect();
    for (k, p) in parts.iter().enumerate() {
        bake(&format!("{k}/3"), "0", p, &[]);
    }
    // Idempotent: the same shard again, at another thread count, gives the same part and hit records.
    let (part_1, hits_1) = (std::fs::read(&parts[1]).unwrap(), std::fs::read(dir.path("hits-1-of-3.prth")).unwrap());
    let again = dir.path("again").join("r0-1.prtp");
    std::fs::create_dir(again.parent().unwrap()).unwrap();
    bake("1/3", "0", &again, &["--threads", "1"]);
    assert!(std::fs::read(&again).unwrap() == part_1, "a re-run shard wrote another part");
    assert!(std::fs::read(dir.path("again").join("hits-1-of-3.prth")).unwrap() == hits_1, "a re-run shard wrote other hit records");

    let layer = dir.path("r0.prtl");
    let e = refused(&merge(&[&parts[0], &parts[2]], &layer));
    assert!(e.contains("missing part(s) of 3 shards: 1 (given: 0, 2)"), "{e}");
    let e = refused(&merge(&[&parts[0], &parts[1], &parts[2], &again], &layer));
    assert!(e.contains(&format!("{}: shard 1/3 is given twice (also as {})", again.display(), parts[1].display())), "{e}");
    let foreign = dir.path("seed9-1.prtp");
    bake("1/3", "0", &foreign, &["--seed", "9", "--shard-dir", s(&dir.path("again"))]);
    let e = refused(&merge(&[&parts[0], &foreign, &parts[2]], &layer));
    assert!(e.contains(&format!("{}: seed 9 here, 1 in {}", foreign.display(), parts[0].display())), "{e}");
    let other_n = dir.path("of2-1.prtp");
    bake("1/2", "0", &other_n, &["--shard-dir", s(&dir.path("again"))]);
    let e = refused(&merge(&[&parts[0], &other_n, &parts[2]], &layer));
    assert!(e.contains(&format!("{}: is one of 2 shards, not of 3", other_n.display())), "{e}");
    assert!(!layer.exists(), "a refused merge wrote its output");

    // Round 1 needs the layer its parts gathered from, and refuses another bake's hit records.
    run(&merge(&[&parts[2], &parts[0], &parts[1]], &layer));
    let r1 = dir.path("r1-0.prtp");
    let e = refused(&[
        "bake",
        s(&mesh),
        "-o",
        s(&r1),
        "--shard",
        "0/3",
        "--round",
        "1",
        "--window",
        "glass",
        "--bounces",
        "1",
        "--rays",
        "8",
        "--adaptive",
        "0",
    ]);
    assert!(e.contains("--round 1 needs --layer"), "{e}");
    let mut a = vec!["bake", s(&mesh), "-o", s(&r1), "--shard", "1/3", "--round", "1", "--layer", s(&layer), "--shard-dir"];
    a.push(s(&dir.0));
    a.extend(["--window", "glass", "--bounces", "1", "--rays", "16", "--adaptive", "0", "--quiet"]);
    let e = refused(&a);
    assert!(e.contains("hits-1-of-3.prth: rays 8 here, 16 in this bake's"), "{e}");
    let x = dir.path("x.prtb");
    let mut a = merge(&[&parts[0], &parts[1], &parts[2]], &x);
    a.extend(["--layer", s(&layer)]);
    let e = refused(&a);
    assert!(e.contains("round 0 parts gather from no layer"), "{e}");
    let e = refused(&["merge", s(&layer), "-o", s(&dir.path("x.prtb"))]);
    assert!(e.contains("is a merged layer, not a part"), "{e}");
}

/// A closed box (12 triangles, one wall made of the material `pane`, not
/// glass in the file), a seat block inside (`seat_leather`) and a ground
/// triangle last whose area dwarfs the rest: most of the bake's cost sits in
/// the last item, so several shards get no item at all.
pub fn write_box_with_pane(dir: &Scratch) -> PathBuf {
    let obj = dir.path("pane-box.obj");
    let mut text = String::from("mtllib pane-box.mtl\n");
    let corners = |x0: f32, y0: f32, z0: f32, x1: f32, y1: f32, z1: f32| -> Vec<[f32; 3]> {
        (0..8).map(|i| [if i & 1 == 0 { x0 } else { x1 }, if i & 2 == 0 { y0 } else { y1 }, if i & 4 == 0 { z0 } else { z1 }]).collect()
    };
    // Faces of a box as quads of corner indices, wound outward.
    let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    let mut base = 1;
    for (name, (lo, hi), pane_face) in
        [("wall", ([0.0, 0.0, 0.0], [2.0, 1.5, 3.0]), Some(5usize)), ("seat_leather", ([0.6, 0.0, 1.0], [1.4, 0.5, 1.8]), None)]
    {
        for c in corners(lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]) {
            text += &format!("v {} {} {}\n", c[0], c[1], c[2]);
        }
        text += &format!("o {name}\n");
        for (f, q) in quads.iter().enumerate() {
            let material = if Some(f) == pane_face { "pane" } else { name };
            let [a, b, c, d] = q.map(|i| i + base);
            text += &format!("usemtl {material}\nf {a} {b} {c}\nf {a} {c} {d}\n");
        }
        base += 8;
    }
    text += "o ground\nv -40 -0.01 -40\nv 40 -0.01 -40\nv 0 -0.01 40\nusemtl ground\n";
    text += &format!("f {} {} {}\n", base, base + 2, base + 1);
    std::fs::write(&obj, text).unwrap();
    let mtl =
        "newmtl wall\nKd 0.7 0.7 0.7\nnewmtl pane\nKd 0.5 0.5 0.5\nnewmtl seat_leather\nKd 0.4 0.2 0.1\nnewmtl ground\nKd 0.3 0.3 0.3\n";
    std::fs::write(dir.path("pane-box.mtl"), mtl).unwrap();
    obj
}

/// `--window` that makes a window of a material the file does not mark
/// (and `PATTERN=TAU` that sets its transmittance) changes the bundle's
/// material section; every shard count, past the item count too (empty
/// shards), merges into the single-process bytes.
#[test]
fn merges_keep_the_window_roles_and_shards_may_be_empty() {
    let dir = Scratch::new("shards-roles");
    let mesh = write_box_with_pane(&dir);
    for window in ["pane", "pane=0.5"] {
        for adaptive in ["0.25", "0"] {
            let args = ["--window", window, "--bounces", "1", "--rays", "8", "--seed", "2", "--adaptive", adaptive, "--quiet"];
            let single = dir.path("single.prtb");
            let mut a = vec!["bake", s(&mesh), "-o", s(&single), "--force"];
            a.extend(args);
            run(&a);
            let expected = std::fs::read(&single).unwrap();
            let bundle = prtbake::bundle::decode_bundle(&expected).unwrap();
            let pane = bundle.mesh.materials.iter().find(|m| m.name == "pane").unwrap();
            assert_eq!(pane.role, prtbake::mesh::MaterialRole::Window, "the single bake marks the window");
            assert_eq!(pane.transmittance, if window == "pane" { 1.0 } else { 0.5 });
            let counts: Vec<u32> = if adaptive == "0" { vec![5, 40] } else { (1..=7).chain([40]).collect() };
            for n in counts {
                let work = dir.path(&format!("{window}-{adaptive}-{n}"));
                std::fs::create_dir(&work).unwrap();
                let merged = sharded_bake(&work, &mesh, &args, 1, n);
                assert!(
                    std::fs::read(&merged).unwrap() == expected,
                    "--window {window} --adaptive {adaptive}, {n} shards: the merged bundle differs from the single-process bake"
                );
            }
        }
    }
}

/// The light through glass that the enclosure rule dropped
/// (`stats.outside_light_share`) is carried by the shard parts and layers:
/// the last merge reports what the single-process bake reports. The
/// window-halo room (`verify::shapes::room_with_pane_outside_opening`): the
/// front wall's outer side sees the pane and the sky, so some is dropped.
#[test]
fn merges_report_the_light_through_glass_dropped() {
    let dir = Scratch::new("shards-glass-light");
    let mesh = dir.path("halo-room.obj");
    prtbake::mesh::write_obj(&mesh, &prtbake::verify::shapes::room_with_pane_outside_opening().0).unwrap();
    let args = ["--window", "glass", "--bounces", "1", "--rays", "16", "--seed", "3", "--adaptive", "0", "--quiet"];
    let json = |out: &str| -> f64 {
        let doc: serde_json::Value = serde_json::from_str(out).unwrap();
        doc["stats"]["outside_light_share"].as_f64().or_else(|| doc["outside_light_share"].as_f64()).unwrap()
    };
    let single = dir.path("single.prtb");
    let mut a = vec!["bake", s(&mesh), "-o", s(&single), "--json"];
    a.extend(args);
    let whole = json(&run(&a));
    assert!(whole > 0.01 && whole < 0.99, "the fixture drops some light through glass, not all: {whole}");
    let work = dir.path("sharded");
    std::fs::create_dir(&work).unwrap();
    let merged = sharded_bake(&work, &mesh, &args, 1, 3);
    assert!(std::fs::read(&merged).unwrap() == std::fs::read(&single).unwrap(), "the merged bundle differs");
    // The last merge again, asking for JSON; its text line too.
    let parts: Vec<PathBuf> = (0..3).map(|k| work.join(format!("r1-{k}.prtp"))).collect();
    let (again, layer) = (work.join("again.prtb"), work.join("r0.prtl"));
    let mut a = merge(&parts.iter().map(|p| p.as_path()).collect::<Vec<_>>(), &again);
    a.extend(["--layer", s(&layer)]);
    let text = run(&a);
    a.push("--json");
    a.push("--force");
    let sharded = json(&run(&a));
    assert!((sharded - whole).abs() <= 1e-12 * whole, "merged {sharded} against the single bake's {whole}");
    assert!(text.contains(&format!("window light: {:.1}%", 100.0 * whole)), "{text}");
}

/// A pilot part among round-0 parts is named as the other stage, and a
/// truncated part as truncated (not by the garbage where its length was).
#[test]
fn merges_name_a_part_of_another_stage_and_a_truncated_part() {
    let dir = Scratch::new("shards-stages");
    let mesh = write_box_with_pane(&dir);
    let args = ["--window", "pane", "--bounces", "1", "--rays", "4", "--quiet"];
    let work = dir.path("w");
    std::fs::create_dir(&work).unwrap();
    sharded_bake(&work, &mesh, &args, 1, 2);
    let (pilot_0, r0_1) = (work.join("pilot-0.prtp"), work.join("r0-1.prtp"));
    let e = refused(&merge(&[&r0_1, &pilot_0], &dir.path("x.prtl")));
    assert!(e.contains(&format!("{}: is a part of the pilot stage, but {} of round 0", pilot_0.display(), r0_1.display())), "{e}");
    let bytes = std::fs::read(work.join("r0-0.prtp")).unwrap();
    let cut = dir.path("cut.prtp");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let e = refused(&merge(&[&cut, &r0_1], &dir.path("x.prtl")));
    assert!(e.contains(&format!("{}: is {} bytes and does not end in its own length", cut.display(), bytes.len() / 2)), "{e}");
}
