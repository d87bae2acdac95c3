//! `prtbake demo`: the README's main job. Generates the demo cabin
//! (src/fixtures/cabin.rs) with its injected defects, cleans it inline, bakes it in window mode and writes
//! `cabin.prtb` and `summary.json` into the output folder, with the LCD panel's
//! images under a low sun and an overcast sky (`demo_panel`, docs/panel.md).

use std::path::Path;

use anyhow::Context;
use serde_json::json;

use super::bake_cmd::{bake_to_bundle, BakeConfig};
use super::{Outcome, Output};
use crate::bake::{BakeParams, Mode};
use crate::files::Staged;
use crate::fixtures::cabin;
use crate::mesh::UpAxis;

/// Demo settings: chosen so the bake finishes in well under two minutes on
/// two cores and the cabin reads right: soft window light, seat shadows,
/// coloured interreflection, and no visible mottling on the roof. 192 rays
/// per point: the per-vertex estimator puts at least three points on every
/// triangle (873,645 points on the cleaned cabin, 5.2 per vertex), so a
/// vertex averages ~1,000 ray evaluations, about what 512 rays on the
/// centroid estimator's ~291k points gave (~900), at the same cost; 512 rays now would
/// take 71 s and 3.7 GB of hit cache. Three bounces cost little (bounces ≥ 1 gather
/// from bounce 0's cached hits) and matter: on the cabin, 1 bounce leaves an
/// 18% shaded-radiance error against 3.7% for 3 (docs/speed-accuracy.md).
pub fn demo_params(quiet: bool) -> BakeParams {
    BakeParams { order: 3, rays: 192, bounces: 3, mode: Mode::Window, quiet, ..BakeParams::default() }
}

pub use crate::fixtures::cabin::DEMO_DETAIL;

pub fn run(output_dir: &Path, threads: usize, as_json: bool, quiet: bool) -> anyhow::Result<Outcome> {
    super::check_threads(threads)?;
    std::fs::create_dir_all(output_dir).with_context(|| format!("cannot create {}", output_dir.display()))?;
    let bundle_path = output_dir.join("cabin.prtb");
    let summary_path = output_dir.join("summary.json");
    let panel_paths = super::demo_panel::paths(output_dir);
    let mut outputs = vec![Output::new(&bundle_path, &["prtb"]), Output::new(&summary_path, &["json"])];
    for (_, exr, png) in &panel_paths {
        outputs.push(Output::new(exr, &["exr"]));
        outputs.push(Output::new(png, &["png"]));
    }
    super::check_outputs(&[], &outputs, false)?;
    let started = std::time::Instant::now();
    let (mesh, defects) = cabin::generate_cabin(DEMO_DETAIL);
    if !quiet {
        eprintln!("demo cabin: {} triangles, {} vertices, injected defects {:?}", mesh.triangle_count(), mesh.vertex_count(), defects);
    }
    let (mesh, clean_report) = crate::clean::clean_mesh(&mesh, &crate::clean::CleanParams::cad())?;
    if !quiet {
        eprintln!("clean: {}", clean_report.summary());
    }
    let config = BakeConfig {
        texels: None,
        refine: None,
        input: "demo-cabin (generated)".into(),
        output: bundle_path,
        up: UpAxis::Y,
        params: demo_params(quiet || as_json),
        window_patterns: Vec::new(),
        one_sided_patterns: Vec::new(),
        threads,
        json: as_json,
        clean: None,
        storage: Default::default(),
        view_box: None,
        force: false,
        shard: None,
    };
    let mut staged = Staged::new();
    let meta = json!({ "source": "demo cabin", "defects_injected": defects, "clean": clean_report });
    let report = bake_to_bundle(&mesh, &config, meta, &mut staged)?;
    let panel_started = std::time::Instant::now();
    let panel = super::with_threads(threads, || super::demo_panel::run(&mesh, &report, &panel_paths, quiet || as_json, &mut staged))??;
    let panel_seconds = panel_started.elapsed().as_secs_f64();
    let s = &report.result.stats;
    let summary = json!({
        "bundle": super::json_path(&report.output),
        "triangles": s.triangles,
        "vertices": s.vertices,
        "window_triangles": s.window_triangles,
        "defects_injected": defects,
        "clean": clean_report,
        "params": config.params,
        "rays": s.rays,
        "points_rejected": s.points_rejected,
        "bake_seconds": s.seconds,
        "rays_traced": s.rays_traced,
        "rays_gathered": s.rays_gathered,
        "rays_per_second": s.rays_per_second,
        "total_seconds": started.elapsed().as_secs_f64(),
        "bundle_bytes": report.bundle_bytes,
        "panel": panel,
        "panel_seconds": panel_seconds,
    });
    staged
        .stage_bytes(&summary_path, serde_json::to_string_pretty(&summary)?.as_bytes())
        .with_context(|| format!("cannot write {}", summary_path.display()))?;
    staged.commit().with_context(|| format!("cannot write into {}", output_dir.display()))?;
    if as_json {
        super::print_json(&summary)?;
    } else {
        super::bake_cmd::print_report(&report, false)?;
        println!("summary: {}", summary_path.display());
    }
    Ok(Outcome::Ok)
}
