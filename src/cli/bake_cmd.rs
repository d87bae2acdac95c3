//! `prtbake bake MESH -o OUT.prtb`: load, (clean), bake transfer, write a bundle.

use std::path::PathBuf;

use anyhow::Context;
use serde_json::json;

use crate::bake::{self, BakeParams, TransferResult};
use crate::bundle::{self, Bundle, LayerKind, Quantization, Transfer, TransferLayer};
use crate::mesh::{Mesh, UpAxis};

/// A checked `bake` configuration.
#[derive(Clone, Debug)]
pub struct BakeConfig {
    pub input: PathBuf,
    pub output: PathBuf,
    pub up: UpAxis,
    pub params: BakeParams,
    pub window_patterns: Vec<String>,
    pub threads: usize,
    pub json: bool,
    /// Clean the mesh first with these parameters (`--clean`).
    pub clean: Option<crate::clean::CleanParams>,
}

/// Runs a bake end to end and prints its stats line (or JSON).
pub fn run(config: &BakeConfig) -> anyhow::Result<()> {
    let load_start = std::time::Instant::now();
    let mut mesh = super::load_mesh(&config.input, config.up, config.params.quiet)?;
    let load_seconds = load_start.elapsed().as_secs_f64();
    let clean_start = std::time::Instant::now();
    let mut meta = json!({ "source": config.input.file_name().map(|n| n.to_string_lossy().to_string()) });
    if let Some(params) = &config.clean {
        let (cleaned, report) = super::clean_cmd::clean_loaded(&mesh, params, &config.input)?;
        if !config.params.quiet {
            eprintln!("clean: {}", report.summary());
        }
        meta["clean"] = serde_json::to_value(&report)?;
        mesh = cleaned;
    }
    let clean_seconds = clean_start.elapsed().as_secs_f64();
    let mut report = bake_to_bundle(&mesh, config, meta)?;
    report.load_seconds = load_seconds;
    report.clean_seconds = config.clean.is_some().then_some(clean_seconds);
    print_report(&report, config.json)
}

/// What a bake reports on stdout.
pub struct BakeReport {
    pub output: PathBuf,
    pub result: TransferResult,
    pub build_seconds: f64,
    pub bundle_bytes: u64,
    pub window_names: Vec<String>,
    pub load_seconds: f64,
    pub clean_seconds: Option<f64>,
    pub write_seconds: f64,
}

/// Bakes `mesh` and writes the bundle named in `config`; `extra_meta` is merged into the metadata.
pub fn bake_to_bundle(mesh: &Mesh, config: &BakeConfig, extra_meta: serde_json::Value) -> anyhow::Result<BakeReport> {
    let (result, surfaces, build_seconds) =
        super::with_threads(config.threads, || bake::bake_mesh(mesh, &config.params, &config.window_patterns))??;
    if config.params.mode == bake::Mode::Window && surfaces.window_triangle_count() == 0 {
        anyhow::bail!(
            "{}: window mode, but no triangle is a window (no material role, and --window {:?} matched no material or group name)",
            config.input.display(),
            config.window_patterns
        );
    }
    let write_start = std::time::Instant::now();
    let mut extra_meta = extra_meta;
    extra_meta["window_patterns"] = json!(config.window_patterns);
    extra_meta["windows"] = json!(surfaces.window_names);
    let bundle = make_bundle(mesh, &result, &config.params, extra_meta);
    bundle::write_bundle(&config.output, &bundle).with_context(|| format!("cannot write {}", config.output.display()))?;
    let bundle_bytes = std::fs::metadata(&config.output).map(|m| m.len()).unwrap_or(0);
    Ok(BakeReport {
        output: config.output.clone(),
        result,
        build_seconds,
        bundle_bytes,
        window_names: surfaces.window_names,
        load_seconds: 0.0,
        clean_seconds: None,
        write_seconds: write_start.elapsed().as_secs_f64(),
    })
}

/// Assembles a bundle from a bake. Only deterministic values go into it
/// (no timings), so equal inputs give equal bytes.
pub fn make_bundle(mesh: &Mesh, result: &TransferResult, params: &BakeParams, extra_meta: serde_json::Value) -> Bundle {
    let mut layers = vec![TransferLayer { kind: LayerKind::Total, data: result.total.clone() }];
    for (b, layer) in result.bounces.iter().enumerate() {
        layers.push(TransferLayer { kind: LayerKind::Bounce(b as u32), data: layer.clone() });
    }
    let s = &result.stats;
    let mut meta = json!({
        "tool": "prtbake",
        "version": env!("CARGO_PKG_VERSION"),
        "command": "bake",
        "params": params,
        "stats": {
            "triangles": s.triangles, "vertices": s.vertices, "window_triangles": s.window_triangles,
            "points": s.points, "points_rejected": s.points_rejected,
            "vertices_without_samples": s.vertices_without_samples,
            "rays_per_bounce": s.rays_per_bounce, "rays": s.rays,
        },
        "conventions": super::conventions(),
    });
    if let (Some(m), serde_json::Value::Object(extra)) = (meta.as_object_mut(), extra_meta) {
        m.extend(extra);
    }
    Bundle {
        meta,
        mesh: mesh.clone(),
        transfer: Some(Transfer {
            order: result.order as u32,
            channels: result.channels as u32,
            quantization: Quantization::F32,
            layers,
        }),
        sun: None,
    }
}

/// Prints the final stats line, or the JSON document with `--json`.
pub fn print_report(report: &BakeReport, as_json: bool) -> anyhow::Result<()> {
    let s = &report.result.stats;
    if as_json {
        return super::print_json(&json!({
            "output": report.output,
            "order": report.result.order,
            "channels": report.result.channels,
            "stats": s,
            "seconds_per_phase": {
                "load": report.load_seconds,
                "clean": report.clean_seconds,
                "bvh_build": report.build_seconds,
                "bounces": s.seconds_per_bounce,
                "write": report.write_seconds,
            },
            "bvh_build_seconds": report.build_seconds,
            "bundle_bytes": report.bundle_bytes,
            "windows": report.window_names,
            "peak_memory_bytes": bake::peak_memory_bytes(),
        }));
    }
    println!(
        "baked {}: {} triangles, {} vertices, {} points ({} rejected), {} rays in {:.2}s ({:.2} Mrays/s), order {}, {} channel(s), {} bytes",
        report.output.display(),
        s.triangles,
        s.vertices,
        s.points,
        s.points_rejected,
        s.rays,
        s.seconds,
        s.rays_per_second / 1e6,
        report.result.order,
        report.result.channels,
        report.bundle_bytes
    );
    Ok(())
}
