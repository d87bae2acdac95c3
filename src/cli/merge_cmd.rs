//! `prtbake merge PARTS… [--layer PREV.prtl] -o OUT`: joins every part of one
//! round of a sharded bake into the next round's layer (`.prtl`) or, after
//! the last round, the bundle (`.prtb`) a single process writes, byte for
//! byte (docs/scale.md). Parts may come in any order; a missing, repeated
//! or foreign part is named in the error (exit 2).

use std::path::{Path, PathBuf};

use anyhow::Context;
use serde_json::json;

use super::sun_cmd::sun_stats_meta;
use super::Output;
use crate::bake::Surfaces;
use crate::bundle;
use crate::bundle::StorageRequest;
use crate::files::Staged;
use crate::shards::run::{decode, read_shard_file};
use crate::shards::{self, FileKind, LayerFile, MeshId, ShardError, SunPart, TransferMerge, TransferPart};

/// A checked `merge` configuration.
#[derive(Clone, Debug)]
pub struct MergeConfig {
    pub parts: Vec<PathBuf>,
    pub output: PathBuf,
    /// Rounds ≥ 1: the layer the parts gathered from.
    pub layer: Option<PathBuf>,
    pub threads: usize,
    pub json: bool,
    pub force: bool,
}

/// Outputs a merge may write: the next round's layer or the bundle.
const MERGE_FORMATS: &[&str] = &["prtl", "prtb", "prta"];

/// Reads the parts, merges them and writes the layer or bundle.
pub fn run(config: &MergeConfig) -> anyhow::Result<()> {
    super::check_threads(config.threads)?;
    let mut inputs: Vec<&Path> = config.parts.iter().map(PathBuf::as_path).collect();
    inputs.extend(config.layer.as_deref());
    super::check_outputs(&inputs, &[Output::new(&config.output, MERGE_FORMATS)], config.force)?;
    let mut transfer: Vec<(PathBuf, TransferPart)> = Vec::new();
    let mut sun: Vec<(PathBuf, SunPart)> = Vec::new();
    for path in &config.parts {
        let bytes = read_shard_file(path)?;
        match FileKind::of(&bytes) {
            Ok(FileKind::TransferPart) => transfer.push((path.clone(), decode(path, &bytes, TransferPart::decode)?)),
            Ok(FileKind::SunPart) => sun.push((path.clone(), decode(path, &bytes, SunPart::decode)?)),
            Ok(other) => {
                return Err(ShardError::Malformed {
                    path: path.clone(),
                    problem: format!(
                        "is {}, not a part: merge takes the parts of one round (and the previous layer with --layer)",
                        other.name()
                    ),
                }
                .into())
            }
            Err(problem) => return Err(ShardError::Malformed { path: path.clone(), problem }.into()),
        }
    }
    if let (Some((t, _)), Some((s, _))) = (transfer.first(), sun.first()) {
        return Err(ShardError::Mismatch {
            path: s.clone(),
            problem: format!("is a sun part, but {} is a transfer part: merge one bake at a time", t.display()),
        }
        .into());
    }
    if sun.is_empty() {
        merge_transfer(config, &transfer)
    } else {
        merge_sun(config, &sun)
    }
}

fn has_extension(path: &Path, extension: &str) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case(extension))
}

fn merge_transfer(config: &MergeConfig, parts: &[(PathBuf, TransferPart)]) -> anyhow::Result<()> {
    let layer = match &config.layer {
        Some(path) => {
            let bytes = read_shard_file(path)?;
            let (layer, crc): (LayerFile, u32) = decode(path, &bytes, LayerFile::decode)?;
            Some((path.as_path(), layer, crc))
        }
        None => None,
    };
    let merged = super::with_threads(config.threads, || shards::merge_transfer(parts, layer))??;
    let output = &config.output;
    let round = parts.first().map_or(0, |(_, p)| p.round);
    let mut staged = Staged::new();
    let summary = match merged {
        TransferMerge::Pilot(pilot) => {
            if !has_extension(output, "prta") {
                anyhow::bail!(
                    "{}: these are pilot parts (--round pilot): their merge is the pilot every round reads with --pilot; name the output .prta",
                    output.display()
                );
            }
            if config.layer.is_some() {
                anyhow::bail!("--layer: the pilot stage gathers from no layer");
            }
            staged.stage(output, |w| pilot.write_to(w).map(drop)).with_context(|| format!("cannot write {}", output.display()))?;
            json!({ "kind": "pilot", "vertices": pilot.identity.mesh.vertices, "base_points": pilot.points })
        }
        TransferMerge::Layer(layer) => {
            if !has_extension(output, "prtl") {
                anyhow::bail!(
                    "{}: round {round} is not the last: its merge is the layer round {} gathers from; name the output .prtl",
                    output.display(),
                    round + 1
                );
            }
            staged.stage(output, |w| layer.write_to(w).map(drop)).with_context(|| format!("cannot write {}", output.display()))?;
            json!({ "kind": "layer", "round": round, "vertices": layer.identity.mesh.vertices })
        }
        TransferMerge::Final { result, key, frame, texels } => {
            if !has_extension(output, "prtb") {
                anyhow::bail!("{}: round {round} is the last: its merge is the bundle; name the output .prtb", output.display());
            }
            let frame_path = &parts.iter().find(|(_, p)| p.shard == 0).map_or(&parts[0].0, |(path, _)| path);
            let b = bundle::decode_bundle(&frame).map_err(|e| ShardError::Malformed {
                path: frame_path.to_path_buf(),
                problem: format!("its bundle frame (the mesh and metadata) does not decode: {e}"),
            })?;
            if MeshId::of(&b.mesh) != parts[0].1.identity.mesh {
                return Err(ShardError::Mismatch {
                    path: frame_path.to_path_buf(),
                    problem: "its bundle frame holds another mesh than the one the parts baked".into(),
                }
                .into());
            }
            // Adaptive allocation's extra points, counted as a whole bake counts them.
            let mut result = result;
            if key.params.adaptive > 0.0 {
                let surfaces =
                    crate::bake::Surfaces::resolve(&b.mesh, &key.window_patterns)?.with_one_sided(&b.mesh, &key.one_sided_patterns)?;
                let base = crate::bake::transfer::base_point_count(&b.mesh, &surfaces, &key.params)?;
                result.stats.points_added = result.stats.points.saturating_sub(base);
            }
            let frame_error = |problem: String| ShardError::Malformed { path: frame_path.to_path_buf(), problem };
            let mut b = b;
            let texels = match (texels, b.texels.take(), &key.texels) {
                (None, None, None) => None,
                (Some(merged), Some(frame_texels), Some(texel_key)) => {
                    Some(shards::merged_texel_transfer(merged, frame_texels, texel_key, &key.params).map_err(frame_error)?)
                }
                _ => return Err(frame_error("its bundle frame's atlas does not go with the parts' texel mode".into()).into()),
            };
            let atlas_source = b.meta.pointer("/texels/atlas").and_then(|a| a.as_str()).unwrap_or("xatlas").to_string();
            let density = b.meta.pointer("/texels/density").cloned();
            let points_added = b.meta.pointer("/texels/points_added").and_then(|p| p.as_u64()).unwrap_or(0);
            let encoded = super::with_threads(config.threads, || -> anyhow::Result<_> {
                let mut texels = texels;
                // `--denoise`: the filters a whole bake runs after its last bounce, vertices and texels.
                let k = key.params.denoise;
                if k > 0.0 {
                    let stride = result.channels * crate::sh::coeff_count(result.order);
                    crate::bake::denoise::denoise(&b.mesh, &mut result.total, &mut result.bounces, &mut result.noise, stride, k);
                    if let Some(t) = &mut texels {
                        crate::bake::texels::denoise_texel_transfer(t, stride, k).map_err(|e| frame_error(e.to_string()))?;
                    }
                }
                let storage = StorageRequest { quantize: key.quantize, max_error: key.max_error };
                let (bundle, choice) = match texels {
                    None => {
                        let choice = storage.choose(&result);
                        (bundle::make_bundle_stored(&b.mesh, &result, &key.params, b.meta, choice.as_ref()), choice)
                    }
                    Some(t) => {
                        // One storage for vertices and texels, within the budget on each, as a whole bake.
                        let choices = storage.choose_with_texels(&result, &t);
                        let mut bundle = bundle::make_bundle_stored(&b.mesh, &result, &key.params, b.meta, choices.as_ref().map(|c| &c.0));
                        let points = key.texels.as_ref().map_or(0, |t| t.points_per_texel);
                        let t = crate::bake::texels::TexelTransfer { points_added, ..t };
                        bundle::add_texel_transfer(&mut bundle, t, &result, choices.as_ref(), &atlas_source, points);
                        if let Some(density) = &density {
                            bundle.meta["texels"]["density"] = density.clone();
                        }
                        let vertex_rays = key.texels.as_ref().map_or(key.params.rays, |t| t.vertex_rays);
                        bundle::note_vertex_rays(&mut bundle, vertex_rays, key.params.rays);
                        if let Some(adaptive) = key.texels.as_ref().map(|t| t.adaptive).filter(|&a| a > 0.0) {
                            bundle.meta["texels"]["adaptive"] = serde_json::json!(adaptive);
                        }
                        super::bake_cmd::warn_texels_over_budget(choices.as_ref().map(|c| &c.1), output);
                        (bundle, choices.map(|c| c.0))
                    }
                };
                let encoded = bundle::encode_bundle(&bundle).with_context(|| format!("{}: cannot encode the bundle", output.display()))?;
                Ok((encoded, choice))
            })??;
            let (encoded, choice) = encoded;
            super::bake_cmd::warn_over_budget(choice.as_ref(), output);
            staged.stage_bytes(output, &encoded).with_context(|| format!("cannot write {}", output.display()))?;
            let s = &result.stats;
            json!({
                "kind": "bundle", "round": round, "vertices": s.vertices, "triangles": s.triangles, "points": s.points,
                "points_rejected": s.points_rejected, "rays": s.rays, "order": result.order, "channels": result.channels,
                "outside_light_share": s.outside_light_share,
                "storage": choice.as_ref().map(|c| crate::bundle::storage_meta(c, &result)),
            })
        }
    };
    staged.commit().with_context(|| format!("cannot write {}", output.display()))?;
    report(config, parts.len(), summary)
}

fn merge_sun(config: &MergeConfig, parts: &[(PathBuf, SunPart)]) -> anyhow::Result<()> {
    let output = &config.output;
    if config.layer.is_some() {
        anyhow::bail!("--layer: sun parts are merged in one round, without a layer");
    }
    if !has_extension(output, "prtb") {
        anyhow::bail!("{}: sun parts merge into a bundle; name the output .prtb", output.display());
    }
    let merged = shards::merge_sun_parts(parts)?;
    let frame_path = parts.iter().find(|(_, p)| p.shard == 0).map_or(&parts[0].0, |(path, _)| path);
    let frame_error = |problem: String| ShardError::Malformed { path: frame_path.clone(), problem };
    let b = bundle::decode_bundle(&merged.frame).map_err(|e| frame_error(format!("its bundle frame does not decode: {e}")))?;
    let mut series = b.sun.ok_or_else(|| frame_error("its bundle frame has no sun sections".into()))?;
    if MeshId::of(&b.mesh) != merged.identity.mesh || series.steps.len() != merged.key.steps as usize {
        return Err(frame_error("its bundle frame holds another mesh or day than the parts baked".into()).into());
    }
    let surfaces = Surfaces::resolve(&b.mesh, &merged.key.window_patterns)?;
    let suns = crate::sky::day_directions(&series.steps);
    let masks = super::with_threads(config.threads, || {
        crate::bake::sun::sun_masks_from_bits(&b.mesh, &surfaces, &suns, &merged.key.params, &merged.bits, merged.rays)
    })??;
    super::sun_cmd::warn_if_never_lit(output, merged.key.params.mode, &merged.key.window_patterns, &masks.stats);
    let mut meta = b.meta;
    let sun_meta =
        meta.get_mut("sun").and_then(|s| s.as_object_mut()).ok_or_else(|| frame_error("its frame's META has no sun object".into()))?;
    sun_meta.insert("stats".into(), sun_stats_meta(&masks.stats));
    series.words_per_vertex = masks.words_per_vertex;
    series.masks = masks.masks;
    if let Some(texels) = merged.texels {
        // The sun's own atlas's texels (TSAT) when it has one, else the bundle's.
        let covered = series.texel_count(b.texels.as_ref()).unwrap_or(0);
        let texel_meta = sun_meta.get_mut("texels").and_then(|t| t.as_object_mut());
        let (Some(texel_meta), true) = (texel_meta, covered * merged.key.steps.div_ceil(32) as usize == texels.masks.len()) else {
            return Err(frame_error("its bundle frame has no atlas or texel sun metadata for the parts' texels".into()).into());
        };
        let lit_texels = crate::bake::texel_sun::lit_counts(&texels.masks, merged.key.steps as usize);
        texel_meta.insert("points".into(), json!(texels.points));
        texel_meta.insert("rays".into(), json!(texels.rays));
        texel_meta.insert("lit_texels".into(), json!(lit_texels));
        series.texel_masks = texels.masks;
        series.texel_fractions = texels.fractions;
    }
    let encoded = bundle::encode_with_sun(&merged.frame, &meta, &series).with_context(|| format!("cannot encode {}", output.display()))?;
    crate::files::write_atomic(output, &encoded).with_context(|| format!("cannot write {}", output.display()))?;
    let s = &masks.stats;
    report(
        config,
        parts.len(),
        json!({ "kind": "sun bundle", "vertices": s.vertices, "points": s.points, "steps": s.steps, "rays": s.rays }),
    )
}

fn report(config: &MergeConfig, parts: usize, summary: serde_json::Value) -> anyhow::Result<()> {
    let bytes = std::fs::metadata(&config.output).map(|m| m.len()).unwrap_or(0);
    if config.json {
        let mut doc = json!({ "output": super::json_path(&config.output), "parts": parts, "bytes": bytes });
        if let (Some(d), serde_json::Value::Object(s)) = (doc.as_object_mut(), summary) {
            d.extend(s);
        }
        return super::print_json(&doc);
    }
    let kind = summary["kind"].as_str().unwrap_or("file");
    let round = summary.get("round").and_then(|r| r.as_u64()).map(|r| format!(" of round {r}")).unwrap_or_default();
    println!("merged {parts} part(s){round} into {} ({kind}, {bytes} bytes)", config.output.display());
    if let Some(share) = summary.get("outside_light_share").and_then(|s| s.as_f64()) {
        super::bake_cmd::print_window_light(share);
    }
    Ok(())
}
