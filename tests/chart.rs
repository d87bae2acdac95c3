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
