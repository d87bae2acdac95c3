//! `prtbake chart --quick`: the sweep runs from nothing, writes the CSV with
//! its columns and an SVG, and its equal-time summary.

use crate::util::{prtbake, Scratch};

#[test]
fn quick_chart_writes_csv_svg_and_summary() {
    let dir = Scratch::new("chart");
    let out = dir.path("out");
    let o = prtbake(&["chart", "--quick", "-o", out.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "chart failed: {}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let csv = std::fs::read_to_string(out.join("speed-accuracy.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next().unwrap(), prtbake::chart::CSV_HEADER);
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len() as u64, summary["bakes"].as_u64().unwrap());
    let mut scenes: Vec<&str> = rows.iter().map(|r| r[0]).collect();
    scenes.dedup();
    assert_eq!(scenes, ["unoccluded-sphere", "plane-under-sphere", "covered-floor", "integrating-sphere", "cabin"]);
    for r in &rows {
        assert_eq!(r.len(), 10, "{r:?}");
        let seconds: f64 = r[7].parse().unwrap();
        let error: f64 = r[8].parse().unwrap();
        assert!(seconds > 0.0 && error.is_finite() && error > 0.0, "{r:?}");
    }
    for scene in &scenes {
        assert!(rows.iter().any(|r| r[0] == *scene && r[9] == "true"), "{scene} has no Pareto point");
    }
    // Vertex sampling leaks on the covered floor whatever the ray count; interior sampling does not.
    let error_of = |setting: &str, rays: &str| -> f64 {
        rows.iter().find(|r| r[0] == "covered-floor" && r[1] == setting && r[6] == rays).unwrap()[8].parse().unwrap()
    };
    assert!(error_of("sobol vertex order 2 bounces 0", "64") > 3.0 * error_of("sobol interior order 2 bounces 0", "64"));
    let svg = std::fs::read_to_string(out.join("speed-accuracy.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("Pareto front") && svg.contains("covered-floor"));
    assert!(out.join("speed-accuracy-summary.json").exists());
    assert!(out.join("cabin-reference-quick.prtb").exists(), "the cabin reference is cached");
}

/// `chart --real --quick`: the coarse cabin against its two-seed reference.
/// The reference is baked once and cached; a cached bundle baked with other
/// parameters is not trusted but re-baked; errors fall with rays and stay
/// above the reference's own floor.
#[test]
fn quick_real_chart_scores_against_a_cached_two_seed_reference() {
    let dir = Scratch::new("chart-real");
    let out = dir.path("out");
    let args = ["chart", "--real", "--quick", "--threads", "2", "-o", out.to_str().unwrap(), "--json"];
    let first = prtbake(&args);
    assert!(first.status.success(), "chart --real failed: {}", String::from_utf8_lossy(&first.stderr));
    assert_eq!(String::from_utf8_lossy(&first.stderr).matches("baking the cabin reference").count(), 2);
    let summary: serde_json::Value = serde_json::from_slice(&first.stdout).unwrap();
    let scene = &summary["scenes"][0];
    assert_eq!(scene["scene"], "cabin");
    let lit = scene["lit_vertices"].as_u64().unwrap();
    assert!(lit > 0 && lit <= scene["vertices"].as_u64().unwrap());
    let floor = scene["reference"]["seed_difference_dc"].as_f64().unwrap();
    assert!(floor > 0.0 && floor < 0.03, "the reference's seeds differ by {floor}");
    let csv = std::fs::read_to_string(out.join("real-scenes.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next().unwrap(), prtbake::chart::real::CSV_HEADER);
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 4, "{csv}");
    let error = |setting: &str| -> Vec<f64> { rows.iter().filter(|r| r[1] == setting).map(|r| r[7].parse().unwrap()).collect() };
    for setting in ["uniform", "adaptive 1"] {
        let e = error(setting);
        // 4× the rays: the noise halves; the reference's floor (≈ floor/2) keeps it from quite halving.
        assert!(e[1] < 0.6 * e[0] && e[1] > 0.5 * floor, "{setting}: {e:?}");
    }
    assert!(out.join("real-scenes.svg").exists() && out.join("real-scenes-summary.json").exists());

    // Cached: the second run bakes no reference and scores the same (the bake
    // is deterministic, and re-tracing instead of caching hits changes no byte).
    let mut no_cache = args.to_vec();
    no_cache.extend(["--hit-cache-mib", "0"]);
    let again = prtbake(&no_cache);
    assert!(again.status.success());
    assert!(!String::from_utf8_lossy(&again.stderr).contains("baking"), "{}", String::from_utf8_lossy(&again.stderr));
    let second: serde_json::Value = serde_json::from_slice(&again.stdout).unwrap();
    assert_eq!(second["scenes"][0]["reference"]["seed_difference_dc"], scene["reference"]["seed_difference_dc"]);
    // Every row the same but its wall time and traced rays: without the
    // cache the 3 later bounces trace their rays again.
    let deterministic_fields = |rows: &serde_json::Value| -> Vec<serde_json::Value> {
        rows.as_array()
            .unwrap()
            .iter()
            .map(|r| {
                let mut r = r.clone();
                r.as_object_mut().unwrap().remove("seconds");
                r.as_object_mut().unwrap().remove("rays_traced");
                r
            })
            .collect()
    };
    assert_eq!(deterministic_fields(&second["rows"]), deterministic_fields(&summary["rows"]));
    for (retraced, cached) in second["rows"].as_array().unwrap().iter().zip(summary["rows"].as_array().unwrap()) {
        assert!(retraced["rays_traced"].as_u64() > cached["rays_traced"].as_u64(), "{retraced} {cached}");
    }

    // A bundle of the same mesh baked with other parameters is re-baked, not trusted.
    let s12 = out.join("cabin-reference-s12.prtb");
    std::fs::copy(out.join("cabin-reference-s11.prtb"), &s12).unwrap();
    let stale = prtbake(&args);
    assert!(stale.status.success());
    let stderr = String::from_utf8_lossy(&stale.stderr);
    assert!(stderr.contains("seed 12") && !stderr.contains("seed 11"), "{stderr}");
    let third: serde_json::Value = serde_json::from_slice(&stale.stdout).unwrap();
    assert_eq!(third["scenes"][0]["reference"]["seed_difference_dc"], scene["reference"]["seed_difference_dc"]);

    // A file the chart did not write is never replaced: refused, left as it was.
    let foreign = b"not a bundle: a user's file that happens to have the name";
    std::fs::write(&s12, foreign).unwrap();
    let refused = prtbake(&args);
    assert_eq!(refused.status.code(), Some(2), "{}", String::from_utf8_lossy(&refused.stderr));
    assert!(String::from_utf8_lossy(&refused.stderr).contains("cabin-reference-s12.prtb: exists and is not a reference"));
    assert_eq!(std::fs::read(&s12).unwrap(), foreign);
}

/// The chart's outputs are checked before the sweep, as every command's are:
/// a directory where the SVG goes, or a read-only CSV, stops it at once and
/// leaves the CSV as it was; `-o FILE` says the output is a folder.
#[test]
fn chart_outputs_are_checked_before_the_sweep() {
    let dir = Scratch::new("chart-outputs");
    let out = dir.path("out");
    std::fs::create_dir_all(out.join("speed-accuracy.svg")).unwrap();
    let csv = out.join("speed-accuracy.csv");
    std::fs::write(&csv, "mine\n").unwrap();
    let mut permissions = std::fs::metadata(&csv).unwrap().permissions();
    permissions.set_readonly(true);
    std::fs::set_permissions(&csv, permissions).unwrap();
    let o = prtbake(&["chart", "--quick", "-o", out.to_str().unwrap()]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("speed-accuracy.csv") && e.contains("read-only"), "{e}");
    std::fs::remove_dir(out.join("speed-accuracy.svg")).unwrap();
    std::fs::create_dir(out.join("speed-accuracy-summary.json")).unwrap();
    let o = prtbake(&["chart", "--quick", "-o", out.to_str().unwrap(), "--force"]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("speed-accuracy-summary.json: is a directory"), "{e}");
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), "mine\n");
    assert!(!out.join("cabin-reference-quick.prtb").exists(), "refused before the sweep");
    let file = dir.path("file.txt");
    std::fs::write(&file, "x").unwrap();
    let o = prtbake(&["chart", "--quick", "-o", file.to_str().unwrap()]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.code() == Some(2) && e.contains("file.txt: is not a folder"), "{e}");
}
