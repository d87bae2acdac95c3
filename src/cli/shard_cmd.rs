//! `prtbake bake MESH --shard K/N [--round R --layer PREV.prtl] -o PART.prtp`
//! and `prtbake sun INPUT --shard K/N -o PART.prtp`: one shard's part of a
//! sharded bake, merged by `prtbake merge` (docs/scale.md).
//!
//! A shard loads the mesh exactly as a whole bake does and writes its part
//! (and in round 0 its hit records) through `files::Staged`, so a failed or
//! interrupted shard leaves nothing, and a re-run writes the same bytes.

use std::path::{Path, PathBuf};

use anyhow::Context;
use serde_json::json;

use super::bake_cmd::{check_windows, load_for_bake, BakeConfig};
use super::sun_cmd::{
    check_texel_request, day_steps, encode_sun_output, load_sun_input, new_atlas_source_name, sun_meta, sun_surfaces, texel_points,
    texel_sun_meta, texel_sun_plan, SunConfig,
};
use super::Output;
use crate::atlas::Atlas;
use crate::bake::texels::TexelTransferPlan;
use crate::bake::{SunStats, TexelSunStats};
use crate::bundle::bundle_meta;
use crate::bundle::{self, Bundle, SunSeries, SunStep};
use crate::shards::{self, FileKind, Shard, ShardRun, Stage, SunKey, TexelKey, TransferKey};
use crate::sky;
use crate::trace::{BuildQuality, Scene};

/// `--texel-levels` in a shard: the atlas whose charts the pilot sized,
/// and the choice. A run with a BVH (the pilot stage, round 0) runs the
/// pilot as a whole bake does, each shard the same; later rounds trace
/// nothing and repack by the levels round 0 kept with their hit records.
#[allow(clippy::too_many_arguments)]
fn density_atlas(
    mesh: &crate::mesh::Mesh,
    config: &BakeConfig,
    scene: &Scene,
    surfaces: &crate::bake::Surfaces,
    request: &super::bake_cmd::TexelRequest,
    levels: &crate::bake::texel_density::DensityRequest,
    files: &shards::run::RoundFiles,
    run: &ShardRun,
) -> anyhow::Result<(Atlas, shards::ChartLevels)> {
    let input = config.input.display();
    super::bake_cmd::check_density_atlas(mesh, request.unwrap, &config.input)?;
    match files.chart_levels() {
        None => {
            let (atlas, report) = crate::bake::texel_density::transfer_density_atlas(
                mesh,
                scene,
                surfaces,
                &config.params,
                request.size,
                request.points,
                levels,
            )
            .with_context(|| format!("{input}: --texel-levels"))?;
            Ok((atlas, shards::ChartLevels { levels: report.chart_levels.clone(), meta: report.meta().to_string() }))
        }
        Some(None) => anyhow::bail!(
            "{}: shard {}'s hit records hold no chart levels: its round 0 was not baked with --texel-levels",
            run.hits_path(&config.output).display(),
            run.shard
        ),
        Some(Some(kept)) => {
            let atlas = crate::bake::texel_density::atlas_at_levels(mesh, request.size, levels, &kept.levels)
                .with_context(|| format!("{input}: --texel-levels, the levels kept in {}", run.hits_path(&config.output).display()))?;
            Ok((atlas, kept.clone()))
        }
    }
}

/// Extensions of a part, a hit-record file and a merged layer.
pub const PART_FORMAT: &[&str] = &["prtp"];
pub const HITS_FORMAT: &[&str] = &["prth"];
pub const LAYER_FORMAT: &[&str] = &["prtl"];
pub const PILOT_FORMAT: &[&str] = &["prta"];

/// Bakes one shard's part of one transfer round and prints what it wrote:
/// the arguments checked, the mesh loaded as a whole bake loads it, then
/// [`ShardRun`]'s library calls (inputs, bake, write).
pub fn run_transfer(config: &BakeConfig, run: &ShardRun) -> anyhow::Result<()> {
    let (shard, round, bounces) = (run.shard, run.round, config.params.bounces);
    run.check(bounces, has_pilot_stage(config))?;
    if config.view_box.is_some() {
        anyhow::bail!("--view-box with --shard: sharded bakes store every triangle (bake the view box in one process)");
    }
    let hits_path = run.hits_path(&config.output);
    let mut outputs = vec![Output::new(&config.output, PART_FORMAT)];
    if run.writes_hits(bounces) {
        outputs.push(Output::new(&hits_path, HITS_FORMAT));
    }
    let read = run.inputs(&config.output);
    let mut inputs: Vec<&Path> = vec![&config.input];
    inputs.extend(read.iter().map(PathBuf::as_path));
    super::check_outputs(&inputs, &outputs, config.force)?;
    super::check_threads(config.threads)?;
    let loaded = load_for_bake(config, &outputs)?;
    // The inputs of later rounds are read (and checked) before any ray.
    let files = run.read_inputs(&config.output)?;
    let mut key = TransferKey {
        params: config.params,
        window_patterns: config.window_patterns.clone(),
        one_sided_patterns: config.one_sided_patterns.clone(),
        quantize: config.storage.quantize,
        max_error: config.storage.max_error,
        texels: None,
    };
    let mesh = &loaded.mesh;
    let input = config.input.display().to_string();
    let (mut output, surfaces, build_seconds, atlas, density) = super::with_threads(config.threads, || -> anyhow::Result<_> {
        let surfaces = super::bake_cmd::surfaces_of(mesh, config)?;
        check_windows(config, &surfaces)?;
        let scene = run.scene(mesh).with_context(|| input.clone())?;
        // Texel mode: every shard unwraps the same atlas and makes the same texel points.
        let mut density: Option<shards::ChartLevels> = None;
        let mut texels = match &config.texels {
            Some(request) => {
                let atlas = match &request.density {
                    None => Atlas::for_mesh(mesh, request.size, request.unwrap).with_context(|| format!("{input}: --texel-size"))?,
                    Some(levels) => {
                        let (atlas, chosen) = density_atlas(mesh, config, &scene, &surfaces, request, levels, &files, run)?;
                        density = Some(chosen);
                        atlas
                    }
                };
                let plan = TexelTransferPlan::new(mesh, &atlas, request.points, request.adaptive, &config.params)
                    .with_context(|| input.clone())?;
                key.texels = Some(TexelKey {
                    texel_size: atlas.texel_size,
                    points_per_texel: request.points,
                    fractions: false,
                    covered_texels: plan.texels().len() as u32,
                    atlas_crc: shards::atlas_crc(&atlas),
                    vertex_rays: request.vertex_rays.unwrap_or(config.params.rays),
                    adaptive: request.adaptive,
                });
                Some((atlas, plan))
            }
            None => None,
        };
        let plan = texels.as_mut().map(|(_, plan)| plan);
        let mut output = run.bake(mesh, &scene, &surfaces, &key, plan, config.params.quiet, files, &config.output)?;
        // Round 0 keeps the pilot's choice with this shard's hit records, for its later rounds.
        if let Some(texel_hits) = output.hits.as_mut().and_then(|h| h.texels.as_mut()) {
            texel_hits.density = density.clone();
        }
        Ok((output, surfaces, scene.build_time.as_secs_f64(), texels, density))
    })??;
    if run.stage() == Stage::Round(bounces) && shard.index == 0 {
        // The last merge makes the bundle from this: the mesh and the metadata a whole bake records.
        let mut meta = bundle_meta(loaded.meta, &config.window_patterns, &config.one_sided_patterns, &surfaces);
        let texels = match (atlas, &config.texels) {
            (Some((atlas, plan)), Some(request)) => {
                // The atlas and its covered texels; the merge puts in their transfer (zeros here) and META `texels`.
                meta["texels"] = json!({ "atlas": super::bake_cmd::atlas_source_name(mesh, request.unwrap) });
                if plan.points_added() > 0 {
                    meta["texels"]["points_added"] = json!(plan.points_added());
                }
                if let Some(d) = &density {
                    meta["texels"]["density"] = serde_json::from_str(&d.meta).context("the density META")?;
                }
                let zeros = vec![0.0; plan.texels().len() * output.part.channels as usize * output.part.coeffs as usize];
                let layers = vec![bundle::TransferLayer { kind: bundle::LayerKind::Total, data: zeros }];
                let transfer = bundle::Transfer {
                    order: config.params.order as u32,
                    channels: output.part.channels,
                    quantization: bundle::Quantization::F32,
                    layers,
                    front_share: Vec::new(),
                };
                Some(bundle::TexelLayers { atlas, texels: plan.texels().to_vec(), transfer: Some(transfer) })
            }
            _ => None,
        };
        let frame = Bundle { meta, mesh: loaded.mesh, transfer: None, sun: None, texels };
        output.part.frame = bundle::encode_bundle(&frame).context("cannot encode the bundle frame")?;
    }
    run.write(&output, &config.output)?;
    let part = &output.part;

    let size = |p: &Path| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
    let hits_written = output.hits.is_some().then_some(hits_path.as_path());
    if config.json {
        return super::print_json(&json!({
            "output": super::json_path(&config.output),
            "part_bytes": size(&config.output),
            "hits": hits_written.map(super::json_path),
            "hits_bytes": hits_written.map(size),
            "shard": shard.to_string(),
            "round": if run.pilot_stage { json!("pilot") } else { json!(round) },
            "bounces": bounces,
            "items": [part.items.start, part.items.end],
            "item_count": part.item_count,
            "points": [part.points.start, part.points.end],
            "opened_vertices": part.opened.len(),
            "late_contributions": part.late.len(),
            "texels": part.texels.as_ref().map(|t| json!({
                "range": [t.texels.start, t.texels.end],
                "covered": t.texel_count,
                "points": [t.points.start, t.points.end],
                "rays": t.rays,
                "rays_traced": t.traced,
            })),
            "rays": part.rays,
            "rays_traced": part.traced,
            "bvh_build_seconds": build_seconds,
            "seconds": output.seconds,
            "peak_memory_bytes": crate::bake::peak_memory_bytes(),
        }));
    }
    let what = if run.pilot_stage { "pilot".to_string() } else { format!("round {round}/{bounces}") };
    let texels = part
        .texels
        .as_ref()
        .map(|t| {
            format!(
                "; texels {}..{} of {}, {} points, {} rays",
                t.texels.start,
                t.texels.end,
                t.texel_count,
                t.points.end - t.points.start,
                t.rays
            )
        })
        .unwrap_or_default();
    println!(
        "shard {shard}, {what}: items {}..{} of {}, {} points, {} rays{texels} in {:.2}s; wrote {} ({} bytes){}",
        part.items.start,
        part.items.end,
        part.item_count,
        part.points.end - part.points.start,
        part.rays,
        output.seconds,
        config.output.display(),
        size(&config.output),
        hits_written.map(|p| format!(" and {} ({} bytes)", p.display(), size(p))).unwrap_or_default()
    );
    Ok(())
}

/// `bake`/`sun --plan-shards N`: the arguments checked as prtbake reads them,
/// and the plan a launcher needs, one `key=value` per line: the shard count,
/// for a transfer bake its bounces (rounds 0..=B) and whether it has a pilot
/// stage, and whether `--threads` was given.
/// Whether a sharded transfer bake has the pilot stage: adaptive allocation
/// of the vertices' points (interior sampling) or of the texels'.
pub fn has_pilot_stage(config: &BakeConfig) -> bool {
    let p = &config.params;
    let vertices = p.adaptive > 0.0 && matches!(p.sampling, crate::bake::Sampling::Interior { .. });
    vertices || config.texels.as_ref().is_some_and(|t| t.adaptive > 0.0)
}

/// `--plan-shards N`: the plan a scheduler script reads (`scripts/shard-args.sh`);
/// `bake` is `(bounces, whether it has the pilot stage)`, `None` for `sun`.
pub fn print_plan(shards: u32, output: &Path, bake: Option<(u32, bool)>, threads_given: bool) -> anyhow::Result<()> {
    if shards == 0 {
        anyhow::bail!("--plan-shards 0: a sharded bake has at least one shard");
    }
    if !output.extension().is_some_and(|e| e.eq_ignore_ascii_case("prtb")) {
        anyhow::bail!("{}: a sharded bake's output is the merged bundle; name it .prtb", output.display());
    }
    println!("shards={shards}");
    if let Some((bounces, pilot)) = bake {
        println!("bounces={bounces}");
        println!("pilot={}", u8::from(pilot));
    }
    println!("threads_given={}", u8::from(threads_given));
    Ok(())
}

/// The stats a sun part's frame carries until the merge counts them: only the step count is known.
fn placeholder_stats(steps: &[SunStep]) -> SunStats {
    SunStats { steps: steps.len() as u64, ..SunStats::default() }
}

/// Traces one shard's sun samples (and in texel mode its range of texels)
/// into a part and prints what it wrote.
pub fn run_sun(config: &SunConfig, shard: Shard) -> anyhow::Result<()> {
    let mut input = load_sun_input(config, PART_FORMAT, false)?;
    check_texel_request(config, &input)?;
    let config = &super::sun_cmd::with_bundle_windows(config, &input)?;
    let points_per_texel = texel_points(config, &input);
    let started = std::time::Instant::now();
    let (part, steps, atlas, density) = super::with_threads(config.threads, || -> anyhow::Result<_> {
        let steps = day_steps(config, &input)?;
        let suns = sky::day_directions(&steps);
        let surfaces = sun_surfaces(config, &input.mesh)?;
        let scene = Scene::build(&input.mesh, BuildQuality::Sah).with_context(|| config.input.display().to_string())?;
        // `--texel-levels`: every shard runs the pilot and sizes the same charts.
        let (atlas, density) = match super::sun_cmd::sun_texel_atlas(config, &input, &scene, &surfaces, &suns)? {
            Some((atlas, _, density)) => (Some(atlas), density),
            None => (None, None),
        };
        let texel_plan = atlas.as_ref().map(|a| texel_sun_plan(config, &input, a, points_per_texel, &suns)).transpose()?;
        let mut meta = sun_meta(config, &input.frame, &placeholder_stats(&steps), input.was_bundle());
        if let Some(m) = meta.as_object_mut() {
            m.remove("stats");
        }
        let mut key = SunKey::of_day(config.params, config.window_patterns.clone(), &steps, &meta);
        key.texels = atlas.as_ref().zip(texel_plan.as_ref()).map(|(atlas, plan)| TexelKey {
            texel_size: atlas.texel_size,
            points_per_texel,
            fractions: config.texel_fractions,
            covered_texels: plan.texel_count() as u32,
            atlas_crc: shards::atlas_crc(atlas),
            vertex_rays: 0,
            adaptive: 0.0,
        });
        let part = shards::bake_sun_shard(&input.mesh, &scene, &surfaces, &suns, &key, texel_plan.as_ref(), shard)?;
        let atlas = atlas.zip(texel_plan.map(|plan| plan.texels().to_vec()));
        Ok((part, steps, atlas, density))
    })??;
    let mut part = part;
    if shard.index == 0 {
        // The merge fills in the masks and the stats; everything else is the bundle a whole bake writes.
        let words = part.words;
        let texel_words = |per_texel: usize| atlas.as_ref().map_or(0, |(_, texels)| texels.len() * per_texel);
        let mut series = SunSeries {
            sky_order: config.sky_order as u32,
            words_per_vertex: words,
            masks: vec![0; input.mesh.vertex_count() * words as usize],
            texel_masks: vec![0; texel_words(words as usize)],
            texel_fractions: vec![
                0;
                if config.texel_fractions { texel_words(crate::bake::texel_sun::fraction_words(steps.len())) } else { 0 }
            ],
            texel_atlas: None,
            steps,
        };
        let mut meta = sun_meta(config, &input.frame, &placeholder_stats(&series.steps), input.was_bundle());
        if let Some((atlas, texels)) = atlas {
            let new_source = input.atlas.is_none().then(|| new_atlas_source_name(config, &input));
            let stats = TexelSunStats { texels: texels.len() as u64, points_per_texel, ..TexelSunStats::default() };
            meta["texels"] = texel_sun_meta(&atlas, &stats, config.texel_fractions, new_source);
            if let Some(density) = &density {
                meta["texels"]["density"] = density.meta();
            }
            if input.sun_atlas_of_its_own() {
                // TSAT: the sun's texels are not the texel transfer's (as `sun` in one process).
                meta["texels"]["own_atlas"] = json!(true);
                series.texel_atlas = Some(crate::bundle::TexelAtlas { atlas, texels });
            } else {
                input.atlas = Some((atlas, texels));
            }
        }
        part.frame = encode_sun_output(&input, meta, &series, &config.output)?;
    }
    crate::files::write_atomic_with(&config.output, |w| part.write_to(w).map(drop))
        .with_context(|| format!("cannot write {}", config.output.display()))?;
    let bytes = std::fs::metadata(&config.output).map(|m| m.len()).unwrap_or(0);
    let seconds = started.elapsed().as_secs_f64();
    if config.json {
        return super::print_json(&json!({
            "output": super::json_path(&config.output),
            "part_bytes": bytes,
            "kind": FileKind::SunPart.name(),
            "shard": shard.to_string(),
            "items": [part.items.start, part.items.end],
            "item_count": part.item_count,
            "points": [part.points.start, part.points.end],
            "rays": part.rays,
            "texels": part.texels.as_ref().map(|t| json!({
                "range": [t.texels.start, t.texels.end],
                "covered": t.texel_count,
                "points": t.points,
                "rays": t.rays,
            })),
            "seconds": seconds,
        }));
    }
    let texels = part
        .texels
        .as_ref()
        .map(|t| format!("; texels {}..{} of {}, {} points, {} rays", t.texels.start, t.texels.end, t.texel_count, t.points, t.rays))
        .unwrap_or_default();
    println!(
        "sun shard {shard}: items {}..{} of {}, {} points, {} rays{texels} in {seconds:.2}s; wrote {} ({bytes} bytes)",
        part.items.start,
        part.items.end,
        part.item_count,
        part.points.end - part.points.start,
        part.rays,
        config.output.display()
    );
    Ok(())
}
