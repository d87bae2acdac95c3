//! `prtbake chart [-o DIR]`: the speed-accuracy sweep (src/chart), written as
//! `speed-accuracy.csv`, `speed-accuracy.svg` and `speed-accuracy-summary.json`
//! (equal-time comparisons), with the cabin reference bake cached in DIR.
//! `--real`: the real scenes instead (src/chart/real.rs), written as
//! `real-scenes.csv`, `real-scenes.svg` and `real-scenes-summary.json`, with
//! their reference bakes cached in DIR.

use std::path::{Path, PathBuf};

use anyhow::Context;
use serde_json::json;

use super::Output;
use crate::chart::{self, pareto, scenes::Size};
use crate::files::Staged;

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

/// The folder `dir` (made if missing) and its three outputs `<stem>.csv`,
/// `<stem>.svg`, `<stem>-summary.json`, checked before the sweep as every
/// command's outputs are.
fn prepare_outputs(dir: &Path, stem: &str, force: bool) -> anyhow::Result<[PathBuf; 3]> {
    if dir.exists() && !dir.is_dir() {
        anyhow::bail!("{}: is not a folder: chart -o names the folder its outputs and cached references go in", dir.display());
    }
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let paths = [dir.join(format!("{stem}.csv")), dir.join(format!("{stem}.svg")), dir.join(format!("{stem}-summary.json"))];
    let outputs = [Output::new(&paths[0], &["csv"]), Output::new(&paths[1], &["svg"]), Output::new(&paths[2], &["json"])];
    super::check_outputs(&[], &outputs, force)?;
    Ok(paths)
}

/// Runs the sweep on `threads` threads (0 = all) and writes the outputs into `dir`.
pub fn run(dir: &Path, quick: bool, threads: usize, as_json: bool, force: bool) -> anyhow::Result<super::Outcome> {
    let paths = prepare_outputs(dir, "speed-accuracy", force)?;
    let size = if quick { Size::Quick } else { Size::Full };
    let started = std::time::Instant::now();
    let rows = super::with_threads(threads, || chart::scenes::sweep(size, dir))??;
    let comparisons: Vec<pareto::Comparison> = COMPARISONS.iter().map(|(s, a, b)| pareto::compare(&rows, s, a, b)).collect();
    let front: Vec<_> = rows.iter().filter(|r| r.pareto).collect();
    let extra = json!({ "equal_time": comparisons, "pareto_front": front });
    let (csv_path, svg_path, summary) = write_outputs(&paths, &chart::to_csv(&rows), &rows, rows.len(), started, quick, extra)?;
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

/// `chart --real`: the real scenes found in `data` (and the generated cabin)
/// against their converged references, cached in `dir`; every bake keeps up
/// to `hit_cache_bytes` of bounce 0's hits.
pub fn run_real(
    dir: &Path,
    data: &Path,
    hit_cache_bytes: u64,
    quick: bool,
    threads: usize,
    as_json: bool,
    force: bool,
) -> anyhow::Result<super::Outcome> {
    use crate::chart::real::{self, Reach};
    let paths = prepare_outputs(dir, "real-scenes", force)?;
    let size = if quick { Size::Quick } else { Size::Full };
    let started = std::time::Instant::now();
    let sweeps = super::with_threads(threads, || -> anyhow::Result<Vec<real::SceneSweep>> {
        let scenes = real::scenes(data, size, hit_cache_bytes)?;
        real::sweep(&scenes, size, dir)
    })??;
    let rows: Vec<real::RealRow> = sweeps.iter().flat_map(|s| s.rows.iter().cloned()).collect();
    // The SVG plots DC error (the targets' figure) against seconds, one curve per setting.
    let plotted: Vec<chart::Row> = sweeps
        .iter()
        .flat_map(|s| {
            let params = &s.reference_params;
            s.rows.iter().map(|r| chart::Row {
                scene: r.scene.clone(),
                setting: r.setting.clone(),
                pattern: "sobol".into(),
                sampling: "interior".into(),
                order: params.order,
                bounces: params.bounces,
                rays: r.rays,
                seconds: r.seconds,
                error: r.score.dc_error,
                pareto: false,
            })
        })
        .collect();
    let scenes: Vec<serde_json::Value> = sweeps
        .iter()
        .map(|s| {
            let mut settings: Vec<&str> = Vec::new();
            s.rows.iter().for_each(|r| if !settings.contains(&r.setting.as_str()) { settings.push(&r.setting) });
            let reach: Vec<serde_json::Value> = settings
                .iter()
                .map(|setting| {
                    let mut curve: Vec<(f64, f64)> =
                        s.rows.iter().filter(|r| r.setting == *setting).map(|r| (r.seconds, r.score.dc_error)).collect();
                    curve.sort_by(|a, b| a.0.total_cmp(&b.0));
                    let times: Vec<(f64, Reach)> = real::TARGETS.iter().map(|&t| (t, real::time_to_reach(&curve, t))).collect();
                    json!({ "setting": setting, "dc_error_reached": times.iter().map(|(t, r)| json!({ "target": t, "seconds": r })).collect::<Vec<_>>() })
                })
                .collect();
            json!({
                "scene": s.name,
                "vertices": s.vertices,
                "lit_vertices": s.reference.lit.len(),
                "reference": {
                    "params": s.reference_params,
                    "seeds": s.reference.seeds,
                    "seed_difference_dc": s.reference.seed_difference,
                    "baked_seconds": s.reference.baked_seconds,
                },
                "time_to_reach": reach,
            })
        })
        .collect();
    let extra = json!({ "scenes": scenes, "rows": rows });
    let (csv_path, svg_path, summary) = write_outputs(&paths, &real::to_csv(&rows), &plotted, rows.len(), started, quick, extra)?;
    if as_json {
        super::print_json(&summary)?;
    } else {
        println!("{} bakes in {:.1}s: {}, {}", rows.len(), started.elapsed().as_secs_f64(), csv_path.display(), svg_path.display());
        for s in &sweeps {
            println!("  {}: {} lit vertices; reference halves differ by {:.4}", s.name, s.reference.lit.len(), s.reference.seed_difference);
            for r in &s.rows {
                println!("    {:<10} {:>4} rays {:>8.2}s  {}", r.setting, r.rays, r.seconds, r.score.summary());
            }
        }
    }
    Ok(super::Outcome::Ok)
}

/// Writes `paths` (the CSV, the SVG of `plotted`, its Pareto fronts marked
/// here, and the summary: the common fields plus `extra`'s), all landing
/// together; returns the first two paths and the summary.
fn write_outputs(
    paths: &[PathBuf; 3],
    csv: &str,
    plotted: &[chart::Row],
    bakes: usize,
    started: std::time::Instant,
    quick: bool,
    extra: serde_json::Value,
) -> anyhow::Result<(PathBuf, PathBuf, serde_json::Value)> {
    let [csv_path, svg_path, summary_path] = paths;
    let mut plotted = plotted.to_vec();
    pareto::mark_fronts(&mut plotted);
    let svg = chart::plot::render_svg(&plotted).map_err(anyhow::Error::msg).context("cannot draw the chart")?;
    let mut summary = json!({
        "csv": super::json_path(csv_path),
        "svg": super::json_path(svg_path),
        "bakes": bakes,
        "sweep_seconds": started.elapsed().as_secs_f64(),
        "quick": quick,
    });
    if let (Some(fields), serde_json::Value::Object(more)) = (summary.as_object_mut(), extra) {
        fields.extend(more);
    }
    let mut staged = Staged::new();
    for (path, bytes) in
        [(csv_path, csv.as_bytes().to_vec()), (svg_path, svg.into_bytes()), (summary_path, serde_json::to_vec_pretty(&summary)?)]
    {
        staged.stage_bytes(path, &bytes).with_context(|| format!("cannot write {}", path.display()))?;
    }
    staged.commit().with_context(|| format!("cannot write {}", csv_path.display()))?;
    Ok((csv_path.clone(), svg_path.clone(), summary))
}
