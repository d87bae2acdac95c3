//! Deterministic argument fuzzing of the commands whose numbers a user or a
//! script types: `panel` (eye, texels, samples, light, display, threshold,
//! turns) and the sharded-bake launchers' plan (`bake --plan-shards N` with
//! the arguments the launchers pass through). Every case exits 0 or 2, never
//! panics, and a success keeps its promises (finite statistics, a plan that
//! reads N as a decimal number). Cases are drawn from fixed seeds, so a
//! failure names a replayable case.

use std::path::Path;

use crate::util::{prtbake, write_scene_obj, Scratch};

/// xorshift64*.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn pick<'a>(&mut self, options: &[&'a str]) -> &'a str {
        options[(self.next() % options.len() as u64) as usize]
    }
    fn chance(&mut self, percent: u64) -> bool {
        self.next() % 100 < percent
    }
}

const NUMBERS: &[&str] = &["0", "1", "-1", "2.5", "1e39", "-1e39", "nan", "inf", "-inf", "1e-45", "4294967296", "08", "x", "", "3,4"];

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Exit 0 or 2, no panic; returns whether it succeeded.
fn exits_cleanly(args: &[String], case: usize) -> (bool, String) {
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = prtbake(&refs);
    let (out, err) = (String::from_utf8_lossy(&o.stdout).into_owned(), String::from_utf8_lossy(&o.stderr).into_owned());
    assert!(!err.contains("panicked"), "case {case}: prtbake {}: panicked: {err}", args.join(" "));
    match o.status.code() {
        Some(0) => (true, out),
        Some(2) => {
            assert!(err.contains("error"), "case {case}: exit 2 without an error message: {err}");
            (false, out)
        }
        code => panic!("case {case}: prtbake {}: exit {code:?}: {err}", args.join(" ")),
    }
}

#[test]
fn panel_arguments_exit_cleanly() {
    let dir = Scratch::new("fuzz-panel");
    let obj = dir.path("scene.obj");
    write_scene_obj(&obj);
    let bundle = dir.path("scene.prtb");
    let o = prtbake(&["bake", s(&obj), "-o", s(&bundle), "--rays", "8", "--quiet"]);
    assert!(o.status.success());
    let not_a_map = dir.path("map.exr");
    std::fs::write(&not_a_map, "not an image").unwrap();
    let mut rng = Rng(0x9a2e1_f00d);
    let mut successes = 0;
    for case in 0..150 {
        let out = dir.path(&format!("p{case}.exr"));
        let mut args: Vec<String> = vec![
            "panel".into(),
            s(&bundle).into(),
            "--panel".into(),
            if rng.chance(90) { "grey" } else { rng.pick(&["[", "nav*"]) }.into(),
        ];
        let coordinate =
            |rng: &mut Rng| if rng.chance(95) { ["1", "2", "3", "0.5", "-0.2"][rng.next() as usize % 5] } else { rng.pick(NUMBERS) };
        let (x, y, z) = (coordinate(&mut rng), coordinate(&mut rng).trim_start_matches('-').to_string(), coordinate(&mut rng));
        args.push(format!("--eye={x},{y},{z}"));
        match rng.next() % 4 {
            0 => args.extend([
                "--overcast".into(),
                "--lux".into(),
                rng.pick(&["10000", "1e39", "50000", "0", "-5", "nan", "3e38", "120"]).into(),
            ]),
            1 if rng.chance(30) => {
                args.extend(["--env".into(), if rng.chance(50) { s(&not_a_map).into() } else { s(&dir.path("missing.exr")).into() }])
            }
            2 => args.extend(["--sky".into(), "--time".into(), rng.pick(&["12:00", "25:00", "x", "10:00", "14:30", "23:59"]).into()]),
            _ => args.push("--overcast".into()),
        }
        if rng.chance(30) {
            args.extend(["--texels".into(), rng.pick(&["4x3", "0x2", "1x1", "5000x1", "axb", "8X8", "4x"]).into()]);
        } else {
            args.extend(["--texels".into(), "6x4".into()]);
        }
        args.extend(["--samples".into(), if rng.chance(85) { "4" } else { rng.pick(NUMBERS) }.into()]);
        for flag in ["--display-white", "--display-black", "--threshold", "--yaw"] {
            if rng.chance(12) {
                args.extend([flag.into(), rng.pick(NUMBERS).into()]);
            }
        }
        args.extend(["-o".into(), s(&out).into(), "--json".into()]);
        let (ok, stdout) = exits_cleanly(&args, case);
        if ok {
            successes += 1;
            let doc: serde_json::Value = serde_json::from_str(&stdout).unwrap();
            for key in ["min_contrast_ratio", "median_contrast_ratio", "mean_reflected_luminance", "max_reflected_luminance"] {
                let v = doc["readability"][key].as_f64();
                assert!(v.is_some_and(f64::is_finite), "case {case}: {key} = {:?} ({})", doc["readability"][key], args.join(" "));
            }
            assert!(out.exists() && out.with_extension("cr.png").exists());
        } else {
            assert!(!out.exists(), "case {case}: a refused panel wrote its image");
        }
    }
    println!("panel: 150 argument cases, {successes} succeeded, the rest refused with exit 2");
    assert!(successes > 30, "the generator should also make valid cases");
}

#[test]
fn launcher_plans_read_numbers_as_prtbake_does() {
    let dir = Scratch::new("fuzz-plan");
    let obj = dir.path("scene.obj");
    write_scene_obj(&obj);
    let out = dir.path("out.prtb");
    let mut rng = Rng(0x1a0c_4e55);
    let mut planned = 0;
    for case in 0..200 {
        let n = if rng.chance(60) { rng.pick(&["1", "2", "08", "010", "64"]) } else { rng.pick(NUMBERS) };
        let mut args: Vec<String> = vec!["bake".into(), s(&obj).into(), "-o".into(), s(&out).into()];
        for flag in ["--bounces", "--rays", "--adaptive", "--threads", "--order", "--seed"] {
            if rng.chance(40) {
                args.extend([flag.into(), if rng.chance(50) { rng.pick(&["0", "1", "3", "010", "08"]) } else { rng.pick(NUMBERS) }.into()]);
            }
        }
        if rng.chance(20) {
            args.extend(["--sampling".into(), rng.pick(&["vertex", "interior", "x"]).into()]);
        }
        args.extend(["--plan-shards".into(), n.into()]);
        let (ok, stdout) = exits_cleanly(&args, case);
        if !ok {
            continue;
        }
        planned += 1;
        let value = |key: &str| stdout.lines().find_map(|l| l.strip_prefix(&format!("{key}="))).map(str::to_string);
        assert_eq!(value("shards").unwrap().parse::<u64>().unwrap(), n.parse::<u64>().unwrap(), "case {case}: {}", args.join(" "));
        let bounces_arg = args.windows(2).rev().find(|w| w[0] == "--bounces").map_or("0".to_string(), |w| w[1].clone());
        assert_eq!(value("bounces").unwrap().parse::<u64>().unwrap(), bounces_arg.parse::<u64>().unwrap(), "case {case}");
        assert!(matches!(value("pilot").as_deref(), Some("0" | "1")) && matches!(value("threads_given").as_deref(), Some("0" | "1")));
        assert!(!out.exists(), "case {case}: a plan bakes nothing");
    }
    println!("plans: 200 argument cases, {planned} planned, the rest refused with exit 2");
    assert!(planned > 20);
}
