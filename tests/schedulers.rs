//! The scheduler scripts (docs/scale.md "On Slurm", "On Kubernetes") drive
//! a sharded bake to the single-process bytes: scripts/slurm/submit.sh and
//! submit-sun.sh against a stand-in `sbatch` that runs each job at once and
//! refuses a job whose dependency has not succeeded, and the Kubernetes
//! manifests parsed, checked and their pods' commands run in apply order.
//! (A real Slurm: scripts/slurm/smoke-test.sh.)

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::shards::write_cabin;
use crate::util::{prtbake, Scratch};

const REPO: &str = env!("CARGO_MANIFEST_DIR");
/// Adaptive allocation (bake's default): the launchers add the pilot stage.
const BAKE_ARGS: &[&str] = &["--window", "glass", "--bounces", "2", "--rays", "8", "--seed", "5", "--store-bounces", "--clean"];
const SUN_ARGS: &[&str] = &["--window", "glass", "--steps", "24", "--seed", "3"];

/// `sbatch` for the test: numbers jobs from 100, appends "id dependency array"
/// to $FAKE_SLURM/jobs, fails unless an afterok dependency exists and
/// succeeded, runs an array's tasks last index first, prints the id.
const FAKE_SBATCH: &str = r#"#!/usr/bin/env bash
set -euo pipefail
id=$(cat "$FAKE_SLURM/next" 2>/dev/null || echo 100)
echo $((id + 1)) >"$FAKE_SLURM/next"
array= dep=
while [ $# -gt 0 ]; do
    case $1 in
        --array=*) array=${1#--array=} ;;
        --dependency=afterok:*) dep=${1#--dependency=afterok:} ;;
        --*) ;;
        *) break ;;
    esac
    shift
done
[ -z "$dep" ] || [ -f "$FAKE_SLURM/ok-$dep" ] || { echo "sbatch: dependency $dep not satisfied" >&2; exit 1; }
echo "$id ${dep:-none} ${array:-none}" >>"$FAKE_SLURM/jobs"
script=$1
shift
if [ -n "$array" ]; then
    for k in $(seq "${array#*-}" -1 "${array%-*}"); do
        SLURM_JOB_ID=$id SLURM_ARRAY_TASK_ID=$k bash "$script" "$@" >>"$FAKE_SLURM/log" 2>&1
    done
else
    SLURM_JOB_ID=$id bash "$script" "$@" >>"$FAKE_SLURM/log" 2>&1
fi
touch "$FAKE_SLURM/ok-$id"
echo "$id;fake"
"#;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Runs prtbake `args` and returns the bytes of `out`.
fn bake_alone(args: &[&str], out: &Path) -> Vec<u8> {
    let o = prtbake(args);
    assert!(o.status.success(), "prtbake {}: {}", args.join(" "), String::from_utf8_lossy(&o.stderr));
    std::fs::read(out).unwrap()
}

/// Runs a script of the repository with the fake Slurm first on PATH; returns (exit code, stdout, stderr).
fn script(dir: &Scratch, name: &str, args: &[&str], env: &[(&str, &str)]) -> (Option<i32>, String, String) {
    let path = format!("{}:{}", s(&dir.path("bin")), std::env::var("PATH").unwrap_or_default());
    let o = Command::new(Path::new(REPO).join(name))
        .args(args)
        .env("PATH", path)
        .env("FAKE_SLURM", dir.path("slurm"))
        .env("PRTBAKE", env!("CARGO_BIN_EXE_prtbake"))
        .envs(env.iter().copied())
        .output()
        .unwrap();
    (o.status.code(), String::from_utf8_lossy(&o.stdout).trim().to_owned(), String::from_utf8_lossy(&o.stderr).into_owned())
}

/// Runs a script with `operands` then `args`, expecting success; returns its stdout.
fn script_ok(dir: &Scratch, name: &str, operands: &[&str], args: &[&str], env: &[(&str, &str)]) -> String {
    let (code, out, e) = script(dir, name, &[operands, args].concat(), env);
    assert_eq!(code, Some(0), "{name}: {e}");
    out
}

#[test]
fn slurm_submit_chains_rounds_and_sun_into_the_single_process_bundles() {
    let dir = Scratch::new("schedulers-slurm");
    let mesh = write_cabin(&dir);
    for sub in ["bin", "slurm"] {
        std::fs::create_dir(dir.path(sub)).unwrap();
    }
    let sbatch = dir.path("bin/sbatch");
    std::fs::write(&sbatch, FAKE_SBATCH).unwrap();
    std::fs::set_permissions(&sbatch, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();

    let single = dir.path("single.prtb");
    let expected = bake_alone(&[&["bake", s(&mesh), "-o", s(&single), "--quiet"], BAKE_ARGS].concat(), &single);
    let bundle = dir.path("slurm.prtb");
    let last = script_ok(&dir, "scripts/slurm/submit.sh", &[s(&mesh), s(&bundle), "3"], BAKE_ARGS, &[("CPUS", "2")]);
    assert!(std::fs::read(&bundle).unwrap() == expected, "3 Slurm shards: the merged bundle differs from the single-process bake");

    // The pilot stage, then three rounds: each an array of 3 after the previous merge, each merge after its array.
    let jobs = std::fs::read_to_string(dir.path("slurm/jobs")).unwrap();
    let chain: Vec<String> = (100..108)
        .map(|id| format!("{id} {} {}", if id == 100 { "none".into() } else { (id - 1).to_string() }, ["0-2", "none"][id as usize % 2]))
        .collect();
    assert_eq!(jobs.lines().collect::<Vec<_>>(), chain);
    assert_eq!(last, "107");
    assert!(dir.path("slurm.shards/pilot.prta").exists(), "the pilot stage's merge");

    // Sun masks on the bundle, after the bake's last merge (AFTER).
    let single_sun = dir.path("single-sun.prtb");
    let expected = bake_alone(&[&["sun", s(&single), "-o", s(&single_sun), "--quiet"], SUN_ARGS].concat(), &single_sun);
    let sun = dir.path("slurm-sun.prtb");
    let last = script_ok(&dir, "scripts/slurm/submit-sun.sh", &[s(&bundle), s(&sun), "4"], SUN_ARGS, &[("AFTER", "107")]);
    assert_eq!(last, "109");
    assert!(std::fs::read(&sun).unwrap() == expected, "4 Slurm sun shards: the merged bundle differs from the single-process one");

    // Threads are the jobs' cores (CPUS), not a bake argument; N must be a count.
    let (code, _, e) = script(&dir, "scripts/slurm/submit.sh", &[s(&mesh), s(&bundle), "3", "--threads", "2"], &[]);
    assert!(code == Some(2) && e.contains("give CPUS=T, not --threads"), "{e}");
    let (code, _, e) = script(&dir, "scripts/slurm/submit.sh", &[s(&mesh), s(&bundle), "three"], &[]);
    assert!(code == Some(2) && e.contains("'three'") && e.contains("--plan-shards"), "{e}");
}

/// The launchers read the bake's numbers as prtbake does, through `bake
/// --plan-shards`: `--bounces 010` is ten bounces (bash alone read it as
/// octal 8, left rounds 0–8 and no bundle, and exited 0), `N=08` is eight
/// shards (a bash error before); shards-local.sh exits 0 only with the bundle.
#[test]
fn launchers_read_numbers_as_prtbake_does() {
    let dir = Scratch::new("schedulers-numbers");
    let mesh = crate::shards::write_box_with_pane(&dir);
    for sub in ["bin", "slurm"] {
        std::fs::create_dir(dir.path(sub)).unwrap();
    }
    let sbatch = dir.path("bin/sbatch");
    std::fs::write(&sbatch, FAKE_SBATCH).unwrap();
    std::fs::set_permissions(&sbatch, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    let args = ["--window", "pane", "--rays", "4", "--bounces", "010", "--quiet"];
    let single = dir.path("single.prtb");
    let expected =
        bake_alone(&["bake", s(&mesh), "-o", s(&single), "--window", "pane", "--rays", "4", "--bounces", "10", "--quiet"], &single);
    let local = dir.path("local.prtb");
    let (code, _, e) = script(&dir, "scripts/shards-local.sh", &[&[s(&mesh), s(&local), "08"], &args[..]].concat(), &[("JOBS", "2")]);
    assert_eq!(code, Some(0), "{e}");
    assert!(std::fs::read(&local).unwrap() == expected, "shards-local.sh, --bounces 010 on 08 shards: not the 10-bounce bundle");
    assert!(dir.path("local.shards/r10").is_dir() && dir.path("local.shards/r9.prtl").exists(), "rounds 0..=10");
    let slurm = dir.path("slurm.prtb");
    let last = script_ok(&dir, "scripts/slurm/submit.sh", &[s(&mesh), s(&slurm), "08"], &args, &[]);
    assert!(std::fs::read(&slurm).unwrap() == expected, "submit.sh, --bounces 010 on 08 shards: not the 10-bounce bundle");
    // A pilot and 11 rounds, each an array of 8 and a merge.
    assert_eq!(last, (100 + 2 * 12 - 1).to_string());
    let jobs = std::fs::read_to_string(dir.path("slurm/jobs")).unwrap();
    assert_eq!(jobs.lines().filter(|l| l.ends_with(" 0-7")).count(), 12, "{jobs}");
    // Kubernetes: the same plan, and Job names past 63 characters refused before any manifest.
    let planner = ("PLANNER", env!("CARGO_BIN_EXE_prtbake"));
    let manifests = dir.path("k8s");
    let env = [planner, ("DIR", s(&manifests))];
    script_ok(&dir, "scripts/kubernetes/manifests.sh", &[s(&mesh), s(&dir.path("k.prtb")), "08"], &args, &env);
    assert_eq!(std::fs::read_dir(&manifests).unwrap().count(), 2 * 12, "a pilot and 11 rounds, each with its merge");
    let long = "x".repeat(60);
    let env = [planner, ("DIR", s(&manifests)), ("NAME", &long)];
    let (code, _, e) =
        script(&dir, "scripts/kubernetes/manifests.sh", &[&[s(&mesh), s(&dir.path("k.prtb")), "2"], &args[..]].concat(), &env);
    assert!(code == Some(2) && e.contains("over Kubernetes' 63"), "{e}");
    // A bad number stops every launcher with prtbake's message, before any job.
    let (code, _, e) = script(&dir, "scripts/shards-local.sh", &[s(&mesh), s(&dir.path("bad.prtb")), "2", "--bounces", "x"], &[]);
    assert!(code == Some(2) && e.contains("--bounces"), "{e}");
    assert!(!dir.path("bad.shards").exists());
}

/// Python 3 with PyYAML, or a skip notice.
fn python_yaml() -> bool {
    let ok = Command::new("python3").args(["-c", "import yaml"]).output().is_ok_and(|o| o.status.success());
    if !ok {
        eprintln!("SKIP: python3 with PyYAML is absent (the Kubernetes manifests are not checked)");
    }
    ok
}

#[test]
fn kubernetes_manifests_run_in_order_into_the_single_process_bundle() {
    if !python_yaml() {
        return;
    }
    let dir = Scratch::new("schedulers-k8s");
    let mesh = write_cabin(&dir);
    let single = dir.path("single.prtb");
    let expected = bake_alone(&[&["bake", s(&mesh), "-o", s(&single), "--quiet"], BAKE_ARGS].concat(), &single);
    let manifests = dir.path("manifests");
    let bundle = dir.path("out/k8s.prtb");
    std::fs::create_dir(dir.path("out")).unwrap();
    let env = [("DIR", s(&manifests)), ("MOUNT", s(&dir.0)), ("PRTBAKE", env!("CARGO_BIN_EXE_prtbake"))];
    script_ok(&dir, "scripts/kubernetes/manifests.sh", &[s(&mesh), s(&bundle), "3"], BAKE_ARGS, &env);
    let names: Vec<String> = std::fs::read_dir(&manifests).unwrap().map(|f| f.unwrap().file_name().into_string().unwrap()).collect();
    assert_eq!(names.len(), 8, "{names:?}: the pilot, 3 rounds and 4 merges");

    // The pods' commands in apply order, as the cluster would run them.
    let check = Path::new(REPO).join("scripts/kubernetes/check.py");
    let o = Command::new("python3").arg(&check).arg(&manifests).arg("--commands").output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let commands: Vec<Vec<String>> = String::from_utf8(o.stdout).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(commands.len(), 4 * (3 + 1), "the pilot and 3 rounds, of 3 pods and a merge each");
    for c in &commands {
        let o = Command::new(&c[0]).args(&c[1..]).output().unwrap();
        assert!(o.status.success(), "{c:?}: {}", String::from_utf8_lossy(&o.stderr));
    }
    assert!(std::fs::read(&bundle).unwrap() == expected, "the pods' bundle differs from the single-process bake");

    // An Indexed Job whose completions disagree with its shard count is named.
    let round1: PathBuf = manifests.join("04-r1.yaml");
    let text =
        std::fs::read_to_string(&round1).unwrap().replace("completions: 3", "completions: 2").replace("parallelism: 3", "parallelism: 2");
    std::fs::write(&round1, text).unwrap();
    let o = Command::new("python3").arg(&check).arg(&manifests).output().unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("04-r1.yaml: an Indexed Job of 2 completions must run --shard $(JOB_COMPLETION_INDEX)/2"), "{e}");
}
