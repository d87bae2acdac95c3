//! `prtbake bake MESH -o OUT.prtb`: load, (clean), bake transfer, write a bundle.

use std::path::PathBuf;

use anyhow::Context;
use serde_json::json;

use crate::bake::{self, BakeParams, TransferResult};
use crate::bundle::budget;
use crate::bundle::{bundle_meta, encode_transfer_bundle, storage_meta, Quantization, StorageRequest};
use crate::files::Staged;
use crate::mesh::{Mesh, UpAxis};

use super::Output;

/// A checked `bake` configuration.
#[derive(Clone, Debug)]
pub struct BakeConfig {
    pub input: PathBuf,
    pub output: PathBuf,
    pub up: UpAxis,
    pub params: BakeParams,
    pub window_patterns: Vec<String>,
    /// `--one-sided`: materials or groups whose back reflects nothing.
    pub one_sided_patterns: Vec<String>,
    pub threads: usize,
    pub json: bool,
    /// Clean the mesh first with these parameters (`--clean`).
    pub clean: Option<crate::clean::CleanParams>,
    /// How the transfer is stored (`--quantize`, `--max-error`).
    pub storage: StorageRequest,
    /// Store only triangles visible from this box (`--view-box`).
    pub view_box: Option<(bake::cull::ViewBox, bake::cull::CullParams)>,
    /// Replace a read-only output (`--force`).
    pub force: bool,
    /// Bake one shard's part of one round instead of the bundle (`--shard`).
    pub shard: Option<crate::shards::ShardRun>,
    /// Refine the mesh where its light changes (`--refine`, `--max-vertices`).
    pub refine: Option<RefineRequest>,
    /// Texel mode: transfer per texel of an atlas too (`--texel-size`).
    pub texels: Option<TexelRequest>,
}

/// `--texel-size L --texel-points N [--unwrap] [--texel-levels K]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TexelRequest {
    /// The texel size; with `density`, the finest a chart may have.
    pub size: f32,
    pub points: u32,
    /// Unwrap a new atlas even where the mesh has its own (`TEXCOORD_1`).
    pub unwrap: bool,
    /// Texel size per chart, picked by a pilot within a budget (`--texel-levels`, `--max-error`).
    pub density: Option<bake::texel_density::DensityRequest>,
    /// Rays per vertex sample point (`--vertex-rays`; `None`: the texels' `--rays`).
    pub vertex_rays: Option<u32>,
    /// Extra texel points where bounce 0 finds noise, per base point (`--texel-adaptive`).
    pub adaptive: f32,
}

/// What the user asked of adaptive refinement ([`crate::refine`]); the
/// defaults depend on the mesh, so they are resolved once it is loaded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefineRequest {
    pub error: Option<f64>,
    pub max_vertices: Option<usize>,
    pub min_edge: Option<f32>,
    /// Standard errors a transfer difference must exceed (`--refine-noise`).
    pub noise_sigmas: Option<f64>,
}

impl RefineRequest {
    /// The refinement's parameters for `mesh`.
    pub fn params(&self, mesh: &Mesh) -> crate::refine::RefineParams {
        let params = crate::refine::RefineParams::for_mesh(mesh, self.error, self.max_vertices, self.min_edge);
        crate::refine::RefineParams { noise_sigmas: self.noise_sigmas.unwrap_or(params.noise_sigmas), ..params }
    }
}

/// Runs a bake end to end and prints its stats line (or JSON). A shard's
/// run (`config.shard`) is [`super::shard_cmd::run_transfer`]'s.
pub fn run(config: &BakeConfig) -> anyhow::Result<()> {
    anyhow::ensure!(config.shard.is_none(), "a shard's run is shard_cmd::run_transfer's");
    let outputs = [Output::new(&config.output, BUNDLE_FORMAT)];
    super::check_outputs(&[&config.input], &outputs, config.force)?;
    super::check_threads(config.threads)?;
    let loaded = load_for_bake(config, &outputs)?;
    let mut staged = Staged::new();
    let mut report = bake_to_bundle(&loaded.mesh, config, loaded.meta, &mut staged)?;
    staged.commit().with_context(|| format!("cannot write {}", config.output.display()))?;
    report.load_seconds = loaded.load_seconds;
    report.clean_seconds = loaded.clean_seconds;
    print_report(&report, config.json)
}

/// A mesh loaded for baking, and what its bundle's metadata says about it.
pub struct LoadedMesh {
    pub mesh: Mesh,
    /// `source` (the file name) and, with `--clean`, the clean report.
    pub meta: serde_json::Value,
    pub load_seconds: f64,
    pub clean_seconds: Option<f64>,
}

/// Loads `config.input` (refusing `outputs` that are files the loader read)
/// and cleans it with `--clean`: the one way whole bakes and shards get their mesh.
pub fn load_for_bake(config: &BakeConfig, outputs: &[Output]) -> anyhow::Result<LoadedMesh> {
    let load_start = std::time::Instant::now();
    let mut mesh = super::load_mesh(&config.input, config.up, config.params.quiet, outputs, config.force)?;
    let load_seconds = load_start.elapsed().as_secs_f64();
    let clean_start = std::time::Instant::now();
    let mut meta = json!({ "source": config.input.file_name().map(|n| n.to_string_lossy().to_string()) });
    if let Some(params) = &config.clean {
        let (cleaned, report, _) = super::clean_cmd::clean_loaded(&mesh, params, &config.input)?;
        if !config.params.quiet {
            eprintln!("clean: {}", report.summary());
        }
        meta["clean"] = serde_json::to_value(&report)?;
        mesh = cleaned;
    }
    let clean_seconds = config.clean.is_some().then(|| clean_start.elapsed().as_secs_f64());
    // The bundle says which glass was a window (the viewer, the panel,
    // `inspect`): marked once here, so whole bakes, shards and their merge
    // all store the same material section.
    let mesh = bake::Surfaces::with_window_roles(&mesh, &config.window_patterns)?;
    Ok(LoadedMesh { mesh, meta, load_seconds, clean_seconds })
}

/// The surfaces of `mesh` as a bake of `config` sees them.
pub fn surfaces_of(mesh: &Mesh, config: &BakeConfig) -> Result<bake::Surfaces, bake::surfaces::PatternError> {
    bake::Surfaces::resolve(mesh, &config.window_patterns)?.with_one_sided(mesh, &config.one_sided_patterns)
}

/// Refuses window mode without a window.
pub fn check_windows(config: &BakeConfig, surfaces: &bake::Surfaces) -> anyhow::Result<()> {
    if config.params.mode == bake::Mode::Window && surfaces.window_triangle_count() == 0 {
        anyhow::bail!(
            "{}: window mode, but no triangle is a window (no material role, and --window {:?} matched no material or group name)",
            config.input.display(),
            config.window_patterns
        );
    }
    Ok(())
}

/// Says on stderr when `--max-error` cannot be met by any storage: the
/// bake's own estimated noise is over the budget (it is stored in the
/// least bytes that add at most 1% to that noise).
pub fn warn_over_budget(choice: Option<&budget::Choice>, output: &std::path::Path) {
    warn_noise_over_budget(choice, output, "the bake's", "more rays or --adaptive lower the noise");
}

/// Texel mode: warns when the texels' own noise is over `--max-error`.
pub fn warn_texels_over_budget(on_texels: Option<&budget::Choice>, output: &std::path::Path) {
    warn_noise_over_budget(on_texels, output, "the texels'", "more rays or --texel-points lower it");
}

fn warn_noise_over_budget(choice: Option<&budget::Choice>, output: &std::path::Path, whose: &str, remedy: &str) {
    let Some(c) = choice else { return };
    if let (false, Some(budget), Some(noise)) = (c.within_budget(), c.budget, c.noise_error) {
        let kept = &c.chosen.storage;
        eprintln!(
            "warning: {}: {whose} own estimated noise is {:.2}% (worst sky), over --max-error {:.2}%: no storage meets it; stored as {} \
             (order {}, {} channel(s)), total {:.2}%, at most {}% over the noise; {remedy}",
            output.display(),
            100.0 * noise,
            100.0 * budget,
            kept.quantization.name(),
            kept.order,
            kept.channels,
            100.0 * c.chosen.total_error.unwrap_or(noise),
            100.0 * budget::OVER_BUDGET_SLACK
        );
    }
}

/// What a bake reports on stdout.
pub struct BakeReport {
    pub output: PathBuf,
    pub result: TransferResult,
    pub build_seconds: f64,
    pub bundle_bytes: u64,
    pub window_names: Vec<String>,
    /// Open mode: every ray that leaves the scene counts, glass is opaque.
    pub open_mode: bool,
    pub load_seconds: f64,
    pub clean_seconds: Option<f64>,
    pub write_seconds: f64,
    /// The measured storage choice, when not stored as baked.
    pub storage: Option<budget::Choice>,
    /// What view-box culling removed.
    pub cull: Option<bake::cull::CullReport>,
    /// What adaptive refinement did.
    pub refine: Option<crate::refine::RefineReport>,
    /// Texel mode: the atlas and the texel passes.
    pub texels: Option<TexelReport>,
}

/// What texel mode adds to a bake's report (the vertices' own figures stay
/// in the result's stats).
#[derive(Clone, Debug, serde::Serialize)]
pub struct TexelReport {
    pub texel_size: f32,
    /// Whose atlas: "TEXCOORD_1" (the mesh's own) or "xatlas" (unwrapped).
    pub atlas: &'static str,
    pub width: u32,
    pub height: u32,
    pub charts: u32,
    pub covered: usize,
    pub points: u64,
    /// Of `points`, those `--texel-adaptive` added.
    pub points_added: u64,
    pub points_rejected: u64,
    pub rays: u64,
    pub rays_traced: u64,
    pub atlas_seconds: f64,
    pub seconds_per_bounce: Vec<f64>,
    /// The texels' measure of the storage chosen for vertices and texels (META `texels.storage`).
    pub storage: Option<serde_json::Value>,
    /// `--texel-levels`: the pilot and each chart's texel size (META `texels.density`).
    pub density: Option<bake::texel_density::DensityReport>,
}

/// Extensions of a bundle output.
pub const BUNDLE_FORMAT: &[&str] = &["prtb"];

/// Bakes `mesh` and stages the bundle named in `config` among the command's
/// outputs (it lands when the caller commits them); `extra_meta` is merged
/// into the metadata.
pub fn bake_to_bundle(mesh: &Mesh, config: &BakeConfig, extra_meta: serde_json::Value, staged: &mut Staged) -> anyhow::Result<BakeReport> {
    if let Some(request) = config.texels {
        return bake_texels_to_bundle(mesh, config, request, extra_meta, staged);
    }
    let (result, surfaces, build_seconds, cull, refined) =
        super::with_threads(config.threads, || bake_maybe_refined(mesh, config))?.with_context(|| config.input.display().to_string())?;
    check_windows(config, &surfaces)?;
    let write_start = std::time::Instant::now();
    let mut extra_meta = bundle_meta(extra_meta, &config.window_patterns, &config.one_sided_patterns, &surfaces);
    let (mesh, refine) = match refined {
        Some((refined_mesh, report)) => {
            extra_meta["refine"] = report.meta();
            (std::borrow::Cow::Owned(refined_mesh), Some(report))
        }
        None => (std::borrow::Cow::Borrowed(mesh), None),
    };
    let mesh: &Mesh = &mesh;
    let (stored_mesh, result) = match &cull {
        Some((visible, report)) => {
            if !config.params.quiet {
                eprintln!(
                    "view-box culling: {} of {} triangles removed ({} kept), {} of {} vertices kept, {} rays",
                    report.triangles_removed,
                    report.triangles_before,
                    report.triangles_kept,
                    report.vertices_kept,
                    report.vertices_before,
                    report.rays
                );
            }
            extra_meta["cull"] = serde_json::to_value(report)?;
            let (kept, map) = bake::cull::compact(mesh, visible);
            let stride = result.channels * crate::sh::coeff_count(result.order);
            let move_layer = |d: &[f32]| bake::cull::compact_vertex_data(d, stride, &map, kept.vertex_count());
            let compacted = TransferResult {
                total: move_layer(&result.total),
                bounces: result.bounces.iter().map(|l| move_layer(l)).collect(),
                back: Vec::new(),
                noise: if result.noise.is_empty() {
                    Vec::new()
                } else {
                    bake::cull::compact_vertex_data(&result.noise, 1, &map, kept.vertex_count())
                },
                front_share: if result.front_share.is_empty() {
                    Vec::new()
                } else {
                    bake::cull::compact_vertex_data(&result.front_share, 1, &map, kept.vertex_count())
                },
                ..result
            };
            (std::borrow::Cow::Owned(kept), compacted)
        }
        None => (std::borrow::Cow::Borrowed(mesh), result),
    };
    // The storage choice measures its candidates on the bake's threads.
    let (encoded, choice) =
        super::with_threads(config.threads, || encode_transfer_bundle(&stored_mesh, &result, &config.params, extra_meta, &config.storage))?
            .with_context(|| format!("{}: cannot encode the bundle", config.output.display()))?;
    warn_over_budget(choice.as_ref(), &config.output);
    staged.stage_bytes(&config.output, &encoded).with_context(|| format!("cannot write {}", config.output.display()))?;
    let bundle_bytes = encoded.len() as u64;
    Ok(BakeReport {
        output: config.output.clone(),
        result,
        build_seconds,
        bundle_bytes,
        window_names: surfaces.window_names,
        open_mode: config.params.mode == bake::Mode::Open,
        load_seconds: 0.0,
        clean_seconds: None,
        write_seconds: write_start.elapsed().as_secs_f64(),
        storage: choice,
        cull: cull.map(|c| c.1),
        refine,
        texels: None,
    })
}

/// Where a texel bake's atlas comes from: the mesh's own lightmap
/// coordinates (`TEXCOORD_1`) unless it has none or `--unwrap` asks for a new one.
pub fn atlas_source_name(mesh: &Mesh, unwrap: bool) -> &'static str {
    if mesh.lightmap_uvs.is_empty() || unwrap {
        "xatlas"
    } else {
        "TEXCOORD_1"
    }
}

/// `--texel-levels` sizes the charts of an atlas it unwraps: refused on a
/// mesh's own lightmap atlas (TEXCOORD_1, kept as authored) without `--unwrap`.
pub fn check_density_atlas(mesh: &Mesh, unwrap: bool, input: &std::path::Path) -> anyhow::Result<()> {
    if atlas_source_name(mesh, unwrap) != "xatlas" {
        anyhow::bail!(
            "{}: --texel-levels: the mesh has its own lightmap atlas (TEXCOORD_1), kept as authored; give --unwrap to unwrap one whose charts get their own texel sizes",
            input.display()
        );
    }
    Ok(())
}

/// Texel mode: unwraps the atlas, bakes vertices and texels together, and
/// stages the bundle with its ATLS and TXFR sections (texels at the
/// vertices' quantization, at the baked order and channels).
fn bake_texels_to_bundle(
    mesh: &Mesh,
    config: &BakeConfig,
    request: TexelRequest,
    extra_meta: serde_json::Value,
    staged: &mut Staged,
) -> anyhow::Result<BakeReport> {
    let input = config.input.display().to_string();
    if request.density.is_some() {
        check_density_atlas(mesh, request.unwrap, &config.input)?;
    }
    let baked = super::with_threads(config.threads, || -> anyhow::Result<_> {
        let surfaces = surfaces_of(mesh, config).with_context(|| input.clone())?;
        let scene = crate::trace::Scene::build(mesh, crate::trace::BuildQuality::Sah).with_context(|| input.clone())?;
        let clock = std::time::Instant::now();
        let (atlas, density) = match &request.density {
            None => {
                let atlas =
                    crate::atlas::Atlas::for_mesh(mesh, request.size, request.unwrap).with_context(|| format!("{input}: --texel-size"))?;
                (atlas, None)
            }
            Some(density) => {
                let (atlas, report) = bake::texel_density::transfer_density_atlas(
                    mesh,
                    &scene,
                    &surfaces,
                    &config.params,
                    request.size,
                    request.points,
                    density,
                )
                .with_context(|| format!("{input}: --texel-levels"))?;
                (atlas, Some(report))
            }
        };
        let atlas_seconds = clock.elapsed().as_secs_f64();
        let vertex_rays = request.vertex_rays.unwrap_or(config.params.rays);
        let sampling = bake::texels::TexelSampling { points: request.points, vertex_rays, adaptive: request.adaptive };
        let (result, texels) =
            bake::texels::bake_texels_for(mesh, &scene, &surfaces, &config.params, atlas, sampling, None).with_context(|| input.clone())?;
        Ok((result, texels, surfaces, scene.build_time.as_secs_f64(), atlas_seconds, density))
    })??;
    let (result, texels, surfaces, build_seconds, atlas_seconds, density) = baked;
    let atlas_source = atlas_source_name(mesh, request.unwrap);
    let texel_report = TexelReport {
        texel_size: texels.atlas.texel_size,
        atlas: atlas_source,
        width: texels.atlas.width,
        height: texels.atlas.height,
        charts: texels.atlas.chart_count,
        covered: texels.texels.len(),
        points: texels.points,
        points_added: texels.points_added,
        points_rejected: texels.points_rejected,
        rays: texels.rays,
        rays_traced: texels.rays_traced,
        atlas_seconds,
        seconds_per_bounce: texels.seconds_per_bounce.clone(),
        storage: None,
        density,
    };
    check_windows(config, &surfaces)?;
    let write_start = std::time::Instant::now();
    let meta = bundle_meta(extra_meta, &config.window_patterns, &config.one_sided_patterns, &surfaces);
    // One storage for vertices and texels, within the budget on each.
    let choices = super::with_threads(config.threads, || config.storage.choose_with_texels(&result, &texels))?;
    let mut texel_report = texel_report;
    texel_report.storage = choices.as_ref().map(|(_, on_texels)| storage_meta(on_texels, &result));
    let mut bundle = crate::bundle::make_bundle_stored(mesh, &result, &config.params, meta, choices.as_ref().map(|c| &c.0));
    crate::bundle::add_texel_transfer(&mut bundle, texels, &result, choices.as_ref(), atlas_source, request.points);
    if let Some(density) = &texel_report.density {
        bundle.meta["texels"]["density"] = density.meta();
    }
    crate::bundle::note_vertex_rays(&mut bundle, request.vertex_rays.unwrap_or(config.params.rays), config.params.rays);
    if request.adaptive > 0.0 {
        bundle.meta["texels"]["adaptive"] = serde_json::json!(request.adaptive);
    }
    let encoded =
        crate::bundle::encode_bundle(&bundle).with_context(|| format!("{}: cannot encode the bundle", config.output.display()))?;
    warn_over_budget(choices.as_ref().map(|c| &c.0), &config.output);
    warn_texels_over_budget(choices.as_ref().map(|c| &c.1), &config.output);
    let choice = choices.map(|c| c.0);
    staged.stage_bytes(&config.output, &encoded).with_context(|| format!("cannot write {}", config.output.display()))?;
    Ok(BakeReport {
        output: config.output.clone(),
        result,
        build_seconds,
        bundle_bytes: encoded.len() as u64,
        window_names: surfaces.window_names,
        open_mode: config.params.mode == bake::Mode::Open,
        load_seconds: 0.0,
        clean_seconds: None,
        write_seconds: write_start.elapsed().as_secs_f64(),
        storage: choice,
        cull: None,
        refine: None,
        texels: Some(texel_report),
    })
}

type CulledBake = (TransferResult, bake::Surfaces, f64, Option<(Vec<bool>, bake::cull::CullReport)>);
type RefinedBake =
    (TransferResult, bake::Surfaces, f64, Option<(Vec<bool>, bake::cull::CullReport)>, Option<(Mesh, crate::refine::RefineReport)>);

/// Bakes `mesh`, refined first with `--refine`/`--max-vertices` (the
/// result then belongs to the refined mesh, returned with the report).
fn bake_maybe_refined(mesh: &Mesh, config: &BakeConfig) -> Result<RefinedBake, bake::BakeError> {
    let Some(request) = &config.refine else {
        let (r, s, b, c) = bake_maybe_culled(mesh, config)?;
        return Ok((r, s, b, c, None));
    };
    let (refined, result, surfaces, report) = crate::refine::refine_transfer(
        mesh.clone(),
        &config.params,
        &config.window_patterns,
        &config.one_sided_patterns,
        &request.params(mesh),
    )?;
    // The rounds' BVH builds are inside the refinement's time.
    Ok((result, surfaces, 0.0, None, Some((refined, report))))
}

/// Bakes `mesh`; with a view box, finds the visible triangles first and
/// (without bounces) shoots rays only from them, every triangle still occluding.
fn bake_maybe_culled(mesh: &Mesh, config: &BakeConfig) -> Result<CulledBake, bake::BakeError> {
    let Some((view_box, cull_params)) = &config.view_box else {
        let (r, s, b) = bake::bake_mesh_with(mesh, &config.params, &config.window_patterns, &config.one_sided_patterns)?;
        return Ok((r, s, b, None));
    };
    config.params.check()?;
    let surfaces = surfaces_of(mesh, config)?;
    let scene = crate::trace::Scene::build(mesh, crate::trace::BuildQuality::Sah)?;
    let (visible, report) = bake::cull::visible_triangles(mesh, &scene, &surfaces, view_box, cull_params);
    // Bounces gather from every triangle's previous bounce, so they need the full bake.
    let receivers = (config.params.bounces == 0).then_some(visible.as_slice());
    let result = bake::bake_transfer_receivers(mesh, &scene, &surfaces, &config.params, receivers)?;
    Ok((result, surfaces, scene.build_time.as_secs_f64(), Some((visible, report))))
}

/// Share of sample points inside geometry past which a bake says so.
pub const REJECTED_WARNING_SHARE: f64 = 0.1;

/// Says on stderr when many sample points were inside geometry: they are
/// dropped, so the surfaces they stood for are estimated from fewer points
/// (or none: black vertices), and the mesh likely has interpenetrating parts.
pub fn warn_rejected(s: &bake::BakeStats, output: &std::path::Path) {
    if s.points == 0 || (s.points_rejected as f64) < REJECTED_WARNING_SHARE * s.points as f64 {
        return;
    }
    eprintln!(
        "warning: {}: {} of {} sample points ({:.0}%) lie inside geometry and were dropped: the mesh has solids passing through each other or overlapping shells (clean --cut-intersections cuts where surfaces cross; inspect MESH lists its parts); {} vertices got no sample",
        output.display(),
        s.points_rejected,
        s.points,
        100.0 * s.points_rejected as f64 / s.points as f64,
        s.vertices_without_samples
    );
}

/// Share of vertices that see the sky below which an open-mode bake says
/// the scene is closed.
pub const SEALED_WARNING_SHARE: f64 = 0.02;

/// Says on stderr when an open-mode bake lit almost no vertex: the sky
/// reaches nothing inside, which is right for a closed room but is mostly a
/// pane or a door baked as opaque (the dining room with its pane quad: 417
/// of 135,681 vertices lit, a black picture and no word).
pub fn warn_sealed(report: &BakeReport) {
    let r = &report.result;
    let stride = crate::sh::coeff_count(r.order) * r.channels;
    if !report.open_mode || stride == 0 || r.total.is_empty() {
        return;
    }
    let vertices = r.total.len() / stride;
    let lit = r.total.chunks_exact(stride).filter(|v| v[0] > 0.0).count();
    if (lit as f64) >= SEALED_WARNING_SHARE * vertices as f64 {
        return;
    }
    let fix = match report.window_names.is_empty() {
        true => "if light comes in through glass or a pane, bake with --window PATTERN (prtbake inspect MESH lists the materials and which look like glass)".to_string(),
        false => format!("the mesh marks {} as windows, which open mode keeps opaque: --window-mode lets the light in through them", report.window_names.join(", ")),
    };
    eprintln!(
        "warning: {}: only {lit} of {vertices} vertices ({:.1}%) see the sky: in open mode this scene is closed and its inside stays black; {fix}",
        report.output.display(),
        100.0 * lit as f64 / vertices.max(1) as f64
    );
}

/// Where a bake's time went, one line: the phases and their seconds,
/// the largest first named as such.
pub fn time_line(report: &BakeReport) -> String {
    let s = &report.result.stats;
    let mut phases: Vec<(String, f64)> = vec![("load".into(), report.load_seconds)];
    if let Some(c) = report.clean_seconds {
        phases.push(("clean".into(), c));
    }
    match &report.refine {
        None => {
            phases.push(("BVH build".into(), report.build_seconds));
            for (b, seconds) in s.seconds_per_bounce.iter().enumerate() {
                phases.push((if b == 0 { "bounce 0 (traced)".into() } else { format!("bounce {b}") }, *seconds));
            }
        }
        Some(r) => {
            phases.push((format!("{} BVH builds", r.rounds.len()), r.bvh_build_seconds));
            phases.push((format!("refinement's bakes and splits ({} rounds)", r.rounds.len()), (r.seconds - r.bvh_build_seconds).max(0.0)));
        }
    }
    if let Some(t) = &report.texels {
        phases.push(("atlas".into(), t.atlas_seconds));
        for (b, seconds) in t.seconds_per_bounce.iter().enumerate() {
            phases.push((format!("texels, bounce {b}"), *seconds));
        }
    }
    phases.push(("write".into(), report.write_seconds));
    super::phase_line(&phases)
}

/// Prints the final stats line, or the JSON document with `--json`.
pub fn print_report(report: &BakeReport, as_json: bool) -> anyhow::Result<()> {
    let s = &report.result.stats;
    // Warnings go to stderr with or without --json.
    warn_rejected(s, &report.output);
    warn_sealed(report);
    if as_json {
        return super::print_json(&json!({
            "output": super::json_path(&report.output),
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
            "storage": report.storage.as_ref().map(|c| storage_meta(c, &report.result)),
            "storage_candidates": report.storage.as_ref().map(|c| &c.measured),
            "cull": report.cull,
            "refine": report.refine,
            "texels": report.texels,
        }));
    }
    println!(
        "baked {}: {} triangles, {} vertices, {} points ({}{} rejected), {} rays traced in {:.2}s ({:.2} Mrays/s traced; {} evaluations, {} of them gathered from hit records), order {}, {} channel(s), {} bytes",
        report.output.display(),
        s.triangles,
        s.vertices,
        s.points,
        if s.points_added > 0 { format!("{} added by --adaptive, ", s.points_added) } else { String::new() },
        s.points_rejected,
        s.rays_traced,
        // Texel mode: the vertices' own seconds (the texels' follow on their line).
        s.seconds - report.texels.as_ref().map_or(0.0, |t| t.seconds_per_bounce.iter().sum()),
        s.rays_per_second / 1e6,
        s.rays,
        s.rays_gathered,
        report.result.order,
        report.result.channels,
        report.bundle_bytes
    );
    print_window_light(s.outside_light_share);
    if let Some(r) = &report.refine {
        println!("{}", r.summary());
    }
    if let Some(t) = &report.texels {
        let seconds: f64 = t.seconds_per_bounce.iter().sum();
        println!(
            "texels: {} covered of {} × {} ({} charts of {}, {} per texel), {} points ({}{} inside geometry), {} rays traced in {:.2}s ({:.2} Mrays/s); the vertices' figures above are their own",
            t.covered,
            t.width,
            t.height,
            t.charts,
            t.atlas,
            t.texel_size,
            t.points,
            if t.points_added > 0 { format!("{} added by --texel-adaptive, ", t.points_added) } else { String::new() },
            t.points_rejected,
            t.rays_traced,
            seconds,
            t.rays_traced as f64 / seconds.max(1e-9) / 1e6
        );
        if let Some(d) = &t.density {
            println!("{}", d.summary());
        }
    }
    if s.back_sides > 0 {
        println!(
            "two-sided: {} of {} triangles reflect on their back side too (open surfaces; --one-sided PATTERN turns it off)",
            s.back_sides, s.triangles
        );
    }
    println!("{}", time_line(report));
    if let Some(c) = &report.storage {
        let s = &c.chosen;
        println!(
            "storage: order {}, {} channel(s), {}: {} bytes/vertex per layer (f32 as baked: {}), shaded error {:.3e}{}",
            s.storage.order,
            s.storage.channels,
            s.storage.quantization.name(),
            s.bytes_per_vertex,
            budget::bytes_per_vertex(&budget::Storage {
                order: report.result.order,
                channels: report.result.channels,
                quantization: Quantization::F32
            }),
            s.shaded_error,
            c.budget.map(|b| format!(" (budget {b:.3e})")).unwrap_or_default()
        );
    }
    if let Some(storage) = report.texels.as_ref().and_then(|t| t.storage.as_ref()) {
        let error = |name: &str| storage.get(name).and_then(|e| e.as_f64()).map(|e| format!(", {} {e:.3e}", name.replace('_', " ")));
        println!(
            "texel storage: the same, measured on the texels{}{}{}",
            error("shaded_error").unwrap_or_default(),
            error("noise_error").unwrap_or_default(),
            error("total_error").unwrap_or_default()
        );
    }
    Ok(())
}

/// The line saying how much light through glass the enclosure rule dropped
/// (nothing when it dropped none). Right for a building's outer walls; a car
/// body with gaps makes sides inside the cabin look outside
/// (docs/image-accuracy.md).
pub(super) fn print_window_light(outside_light_share: f64) {
    if outside_light_share > 0.0 {
        println!(
            "window light: {:.1}% of what the sample points met through glass fell on sides outside the enclosure and was dropped (--keep-outside-sides keeps it)",
            100.0 * outside_light_share
        );
    }
}
