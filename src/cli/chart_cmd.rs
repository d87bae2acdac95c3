//! `prtbake chart [-o DIR]`: the speed-accuracy sweep (src/chart), written as
//! `speed-accuracy.csv`, `speed-accuracy.svg` and `speed-accuracy-summary.json`
//! (equal-time comparisons), with the cabin reference bake cached in DIR.

use std::path::Path;

use anyhow::Context;
use serde_json::json;

use crate::chart::{self, pareto, scenes::Size};

/// Equal-time comparisons the summary reports: (scene, a, b).
const COMPARISONS: &[(&str, &str, &str)] = &[
    ("unoccluded-sphere", "sobol interior order 4 bounces 0", "random interior order 4 bounces 0"),
    ("plane-under-sphere", "sobol interior order 4 bounces 0", "random interior order 4 bounces 0"),
    ("plane-under-sphere", "sobol vertex order 4 bounces 0", "random vertex order 4 bounces 0"),
    ("covered-floor", "sobol interior order 2 bounces 0", "random interior order 2 bounces 0"),
    ("covered-floor", "sobol interior order 2 bounces 0", "sobol vertex order 2 bounces 0"),
    ("covered-floor", "random interior order 2 bounces 0", "random vertex order 2 bounces 0"),
    ("plane-under-sphere", "sobol interior order 4 bounces 0", "sobol vertex order 4 bounces 0"),
    ("integrating-sphere", "sobol interior order 1 bounces 8", "random interior order 1 bounces 8"),
    ("cabin", "sobol interior order 3 bounces 3", "random interior order 3 bounces 3"),
    ("cabin", "sobol interior order 3 bounces 3", "sobol vertex order 3 bounces 3"),
];

/// Runs the sweep on `threads` threads (0 = all) and writes the outputs into `dir`.
pub fn run(dir: &Path, quick: bool, threads: usize, as_json: bool) -> anyhow::Result<super::Outcome> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let size = if quick { Size::Quick } else { Size::Full };
    let started = std::time::Instant::now();
    let rows = super::with_threads(threads, || chart::scenes::sweep(size, dir))??;
    let csv_path = dir.join("speed-accuracy.csv");
    crate::files::write_atomic(&csv_path, chart::to_csv(&rows).as_bytes())
        .with_context(|| format!("cannot write {}", csv_path.display()))?;
    let svg = chart::plot::render_svg(&rows).map_err(anyhow::Error::msg).context("cannot draw the chart")?;
    let svg_path = dir.join("speed-accuracy.svg");
    crate::files::write_atomic(&svg_path, svg.as_bytes()).with_context(|| format!("cannot write {}", svg_path.display()))?;
    let comparisons: Vec<pareto::Comparison> = COMPARISONS.iter().map(|(s, a, b)| pareto::compare(&rows, s, a, b)).collect();
    let front: Vec<_> = rows.iter().filter(|r| r.pareto).collect();
    let summary = json!({
        "csv": super::json_path(&csv_path),
        "svg": super::json_path(&svg_path),
        "bakes": rows.len(),
        "sweep_seconds": started.elapsed().as_secs_f64(),
        "quick": quick,
        "equal_time": comparisons,
        "pareto_front": front,
    });
    let summary_path = dir.join("speed-accuracy-summary.json");
    crate::files::write_atomic(&summary_path, serde_json::to_string_pretty(&summary)?.as_bytes())
        .with_context(|| format!("cannot write {}", summary_path.display()))?;
    if as_json {
        super::print_json(&summary)?;
    } else {
        println!("{} bakes in {:.1}s: {}, {}", rows.len(), started.elapsed().as_secs_f64(), csv_path.display(), svg_path.display());
        for c in &comparisons {
            if let Some(r) = c.geometric_mean_ratio {
                println!(
                    "  {:<19} at equal time, error({}) / error({}) = {:.3} (geometric mean over {} times, {} past b's slowest point)",
                    c.scene,
                    c.a,
                    c.b,
                    r,
                    c.ratios.len(),
                    c.capped
                );
            }
        }
    }
    Ok(super::Outcome::Ok)
}
