//! One shard of a round: the same plan, pass and sums as a whole bake, over
//! the shard's items (no I/O: the caller reads and writes the files).

use std::path::Path;
use std::time::Instant;

use glam::Vec3;

use super::files::{
    HitFile, Identity, LayerFile, PilotFile, SunPart, TexelHits, TexelLayer, TexelRoundPart, TexelSunPart, TransferPart, VertexRows,
};
use super::key::{SunKey, TransferKey};
use super::merge::identity_difference;
use super::{split_by_cost, MeshId, Shard, ShardError};
use crate::bake::gather::RowBuffer;
use crate::bake::noise::{Moments, VertexDc};
use crate::bake::progress::Progress;
use crate::bake::sun::SunPlan;
use crate::bake::texels::TexelTransferPlan;
use crate::bake::transfer::{adaptive_range, run_range, trace_tasks, HitRecords, HitSlots, Plan, RangeSums, SourceRows};
use crate::bake::{BakeError, Surfaces, TexelSunPlan};
use crate::mesh::Mesh;
use crate::trace::Scene;

/// What a transfer shard of round b ≥ 1 reads: its own hit records (from
/// round 0) and the merged layer of round b − 1, with their paths for errors.
pub struct RoundInput<'a> {
    pub hits_path: &'a Path,
    pub hits: HitFile,
    pub layer_path: &'a Path,
    pub layer: LayerFile,
    /// The layer file's CRC (its identity in the part).
    pub layer_crc: u32,
}

/// What a transfer shard writes: its part, and in round 0 of a bake with
/// bounces its hit records.
pub struct RoundOutput {
    pub part: TransferPart,
    pub hits: Option<HitFile>,
    pub seconds: f64,
}

/// What an adaptive bake's shards read in every round: the merged pilot
/// (where the extra points go), its path for errors and its CRC.
pub struct PilotInput<'a> {
    pub path: &'a Path,
    pub pilot: PilotFile,
    pub crc: u32,
}

/// Which pass a transfer shard runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Adaptive allocation's pilot: bounce 0 at the base points only, whose
    /// merge decides where the extra points go.
    Pilot,
    /// Round b = bounce b (with adaptive allocation: over the base and extra points).
    Round(u32),
}

/// Bakes shard `shard`'s items of transfer stage `stage`: the pilot of an
/// adaptive bake, or round b (the bounce): round 0 traces, later rounds
/// gather from `input`; an adaptive bake's rounds read its merged `pilot`.
/// `quiet` silences the progress line.
///
/// Errors: bad parameters, a round past the bounces, inputs missing or
/// present against the round, and inputs from another bake, shard or round
/// (named with their path).
///
/// In texel mode (`key.texels`, with the plan of the atlas it describes),
/// every round also traces the shard's range of covered texels, balanced
/// apart by their points; the pilot stage samples the texels' base points
/// only with `--texel-adaptive`, which places their extra points by it.
#[allow(clippy::too_many_arguments)]
pub fn bake_transfer_shard(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    key: &TransferKey,
    texels: Option<&mut TexelTransferPlan>,
    quiet: bool,
    shard: Shard,
    stage: Stage,
    input: Option<RoundInput>,
    pilot: Option<PilotInput>,
) -> Result<RoundOutput, ShardError> {
    let started = Instant::now();
    // Texel mode: the vertices take their own rays (`--vertex-rays`), the texels the key's.
    let vertex_rays = key.texels.as_ref().map_or(key.params.rays, |t| t.vertex_rays);
    let params = crate::bake::BakeParams { quiet, rays: vertex_rays, ..key.params };
    let adaptive = params.adaptive > 0.0 && matches!(params.sampling, crate::bake::Sampling::Interior { .. });
    // `--texel-adaptive` places texel points by the pilot stage as well.
    let texel_adaptive = key.texels.as_ref().is_some_and(|t| t.adaptive > 0.0);
    let round = match stage {
        Stage::Pilot => 0,
        Stage::Round(r) => r,
    };
    match (stage, adaptive || texel_adaptive, &pilot) {
        (Stage::Pilot, false, _) => {
            return Err(BakeError::Params(
                "the pilot stage is adaptive allocation's, and this bake has --adaptive 0 and no --texel-adaptive".into(),
            )
            .into())
        }
        (Stage::Pilot, true, Some(p)) => {
            return Err(ShardError::mismatch(p.path, "is a merged pilot, which the pilot stage makes: give it to rounds 0 and later"))
        }
        (Stage::Round(r), true, None) => {
            return Err(BakeError::Params(format!(
                "round {r} of an adaptive bake needs the merged pilot (--pilot): its stage decides where the extra points go"
            ))
            .into())
        }
        (Stage::Round(_), false, Some(p)) => {
            return Err(ShardError::mismatch(
                p.path,
                "is a merged pilot, but this bake has --adaptive 0 (and no --texel-adaptive) and needs none",
            ))
        }
        _ => {}
    }
    if round > params.bounces {
        return Err(BakeError::Params(format!(
            "round {round} of a bake of {} bounce(s): rounds run 0..={}",
            params.bounces, params.bounces
        ))
        .into());
    }
    if (round == 0) != input.is_none() {
        return Err(BakeError::Params(format!(
            "round {round} needs {}",
            if round == 0 { "no inputs" } else { "its hit records and the previous round's layer" }
        ))
        .into());
    }
    if key.texels.as_ref().map(|t| t.covered_texels as usize) != texels.as_ref().map(|p| p.texels().len()) {
        return Err(BakeError::Params("the texel plan is not the one the key describes".into()).into());
    }
    let mut plan = Plan::new(mesh, scene, surfaces, &params, None)?;
    let identity = Identity {
        mesh: MeshId::of(mesh),
        plan_vertices: plan.mesh.vertex_count() as u64,
        plan_triangles: plan.mesh.triangle_count() as u64,
        shards: shard.count,
        key: key.encode(),
    };
    // Rounds of an adaptive bake run over the unified layout the pilot decides.
    let mut base_items = None;
    let mut pilot_crc = 0;
    if let (Stage::Round(_), Some(p)) = (stage, &pilot) {
        if let Some(d) = identity_difference(&p.pilot.identity, &identity, super::FileKind::Pilot) {
            return Err(ShardError::mismatch(p.path, format!("{d} this bake's mesh and arguments: this pilot is another bake's")));
        }
        if adaptive {
            let moments: Vec<Moments> = p.pilot.moments.iter().map(|&m| Moments::from_array(m)).collect();
            let dc = VertexDc { weights: &p.pilot.weights, dc_sums: p.pilot.dc_sums.clone(), moments: &moments };
            let extra = plan.extra_counts(&dc);
            base_items = Some((plan.unify(&extra)?, extra));
        }
        pilot_crc = p.crc;
    }
    // Shards split the items by their cost in points × rays: the pilot stage
    // the base points, every round of an adaptive bake the points the pilot
    // decided (base and extra), so the rounds' shards stay balanced.
    let costs: Vec<u64> = plan.items.points_per_item().iter().map(|&p| p as u64 * params.rays as u64).collect();
    let range = split_by_cost(&costs, shard.count)[shard.index as usize].clone();
    let points = plan.items.first_point(range.start) as u64..plan.items.first_point(range.end) as u64;
    let mut rejected = vec![false; plan.items.point_count() as usize];
    let mut source = SourceRows::empty();
    if let Some(input) = &input {
        check_inputs(input, &identity, shard, round, range.start as u32..range.end as u32, points.clone(), &plan)?;
        for local in 0..points.end - points.start {
            rejected[(points.start + local) as usize] = input.hits.is_rejected(local);
        }
        source.rows = RowBuffer::zeroed(input.layer.source.len());
        source.rows.as_mut_slice().copy_from_slice(&input.layer.source);
        source.channels = input.layer.source_channels as usize;
        source.sides = input.layer.source_sides;
    }
    // Texel mode: the shard's covered texels, and in later rounds what
    // their points found inside geometry and the texels' previous bounce,
    // which vertices and texels alike gather at hits on atlas triangles.
    // The pilot stage traces the texels' base points only where extra
    // points are to be placed by them; every round grows the texels by the
    // merged pilot first, so its shards split the grown texels by cost.
    let texels = texels.filter(|_| stage != Stage::Pilot || texel_adaptive);
    let mut texels = match (texels, stage, &pilot) {
        (Some(texel_plan), Stage::Round(_), Some(p)) if texel_adaptive => {
            let Some(rows) = &p.pilot.texels else {
                return Err(ShardError::mismatch(p.path, "holds no texels, and this bake places texel points by them (--texel-adaptive)"));
            };
            texel_plan
                .grow(&plan.mesh, &rows.weights, &rows.dc_sums, &rows.moments, &params)
                .map_err(|e| ShardError::mismatch(p.path, e.to_string()))?;
            Some(texel_plan)
        }
        (texel_plan, ..) => texel_plan,
    }
    .map(|texel_plan| {
        let costs = texel_plan.state.costs();
        let range = split_by_cost(&costs, shard.count)[shard.index as usize].clone();
        (texel_plan, range)
    });
    if let (Some((texel_plan, range)), Some(input)) = (&mut texels, &input) {
        let points = texel_plan.state.point_range(range.clone());
        let (hits, layer) = check_texel_inputs(input, range.clone(), points.clone(), texel_plan.texels().len(), key.params.rays)?;
        for local in 0..points.end - points.start {
            texel_plan.state.rejected[(points.start + local) as usize] = hits.is_rejected(local);
        }
        source.texels = Some(texel_plan.state.source_from_merged(&layer.weights, &layer.source, layer.source_sides));
    }
    let record = stage == Stage::Round(0) && params.bounces > 0;
    let label = match stage {
        Stage::Pilot => format!("shard {shard}, pilot"),
        Stage::Round(r) => format!("shard {shard}, round {r}/{}", params.bounces),
    };
    // A pilot stage that only texels read (`--adaptive 0 --texel-adaptive`)
    // traces no vertex points: nothing reads their pilot rows.
    let vertices_traced = stage != Stage::Pilot || adaptive;
    let vertex_rays = if vertices_traced { (points.end - points.start) * params.rays as u64 } else { 0 };
    let progress = Progress::start(label, vertex_rays, params.quiet);
    let first_items = plan.items.first_items(&plan.receivers());
    let sums = match (&base_items, round) {
        // Adaptive round 0: the base points again (the same bits as the
        // pilot's), then the extras, combined item by item as a whole bake does.
        (Some((base, extra)), 0) => {
            let base_pass = plan.pass(0, &source, &[], None, record).with_items(base);
            let mut hits = HitSlots::new(&base_pass, range.clone());
            let tasks = trace_tasks(&base_pass, range.clone(), &mut hits, &progress);
            adaptive_range(&plan, base, extra, range.clone(), tasks, hits.records, Some(&first_items), &source, record, &progress)
        }
        _ if !vertices_traced => RangeSums::empty(&plan.pass(round, &source, &rejected, None, record)),
        _ => {
            let cached = input.as_ref().map(|i| HitRecords { records: &i.hits.records, first_point: points.start });
            let pass = plan.pass(round, &source, &rejected, cached, record);
            run_range(&pass, range.clone(), Some(&first_items), &progress)
        }
    };
    drop(progress);
    let (texel_part, texel_hits) = match texels {
        Some((texel_plan, range)) => {
            let (part, hits) = trace_texels(texel_plan, range, &plan, &source, round, record, input.as_ref(), shard)?;
            (Some(part), hits)
        }
        None => (None, None),
    };

    let stride = plan.pass_channels(round) * plan.coeffs;
    let tracks_noise = !sums.moments.is_empty();
    let mut opened = VertexRows::default();
    for (v, &first) in first_items.iter().enumerate() {
        if range.contains(&(first as usize)) {
            opened.vertices.push(v as u32);
            opened.rows.extend_from_slice(&sums.sums[v * stride..(v + 1) * stride]);
            if round == 0 {
                opened.weights.push(sums.weights[v]);
            }
            if tracks_noise {
                opened.moments.push(sums.moments[v].to_array());
            }
        }
    }
    let items = range.start as u32..range.end as u32;
    let hits = record.then(|| {
        let count = points.end - points.start;
        let mut bits = vec![0u32; count.div_ceil(32) as usize];
        for &global in &sums.rejected {
            let local = global as u64 - points.start;
            bits[(local / 32) as usize] |= 1 << (local % 32);
        }
        HitFile {
            identity: identity.clone(),
            shard: shard.index,
            items: items.clone(),
            points: points.clone(),
            rays: params.rays,
            rejected: bits,
            records: sums.hits,
            texels: texel_hits,
        }
    });
    let part = TransferPart {
        identity,
        shard: shard.index,
        round,
        items,
        item_count: plan.items.len() as u32,
        points,
        point_count: plan.items.point_count(),
        window_triangles: plan.base_stats().window_triangles,
        // Round 0 names the pilot it allocated by (0 without one).
        layer_crc: input.as_ref().map_or(pilot_crc, |i| i.layer_crc),
        pass_channels: plan.pass_channels(round) as u32,
        channels: plan.channels as u32,
        coeffs: plan.coeffs as u32,
        rays: sums.rays,
        traced: sums.traced,
        rejected: sums.rejected.len() as u64,
        // What bounce 0 met through glass, as a whole bake reports it.
        glass_light: if stage == Stage::Round(0) { sums.glass_dc } else { [0.0; 2] },
        opened,
        tracks_noise,
        pilot: stage == Stage::Pilot,
        late: VertexRows {
            vertices: sums.late.receivers,
            rows: sums.late.rows,
            weights: sums.late.weights,
            moments: sums.late.moments.iter().map(|m| m.to_array()).collect(),
        },
        texels: texel_part,
        frame: Vec::new(),
    };
    Ok(RoundOutput { part, hits, seconds: started.elapsed().as_secs_f64() })
}

/// One round over a shard's covered texels `range`: the texels' pass of a
/// whole bake ([`crate::bake::texels`]), gathering from `source`; round 0
/// of a bake with bounces records the texel points' hits.
#[allow(clippy::too_many_arguments)]
fn trace_texels(
    texel_plan: &mut TexelTransferPlan,
    range: std::ops::Range<usize>,
    plan: &Plan,
    source: &SourceRows,
    round: u32,
    record: bool,
    input: Option<&RoundInput>,
    shard: Shard,
) -> Result<(TexelRoundPart, Option<TexelHits>), ShardError> {
    let growth = texel_plan.growth.take().filter(|_| round == 0);
    let state = &mut texel_plan.state;
    let params = &state.params(plan);
    let points = state.point_range(range.clone());
    let cached = input.and_then(|i| i.hits.texels.as_ref()).map(|h| HitRecords { records: &h.records, first_point: points.start });
    let mut pass = plan.pass(round, source, &[], cached, record);
    pass.params = params;
    let label = format!("shard {shard}, texels, round {round}/{}", params.bounces);
    let progress = Progress::start(label, (points.end - points.start) * params.rays as u64, params.quiet);
    // Round 0 of grown texels: the base points and the extras, combined as a whole bake does.
    let sums = match growth {
        Some(growth) => state.trace_grown(&pass, &growth, range.clone(), None, &progress),
        None => state.trace_range(&pass, range.clone(), &progress),
    };
    drop(progress);
    let rejected: Vec<bool> = state.rejected[points.start as usize..points.end as usize].to_vec();
    let part = TexelRoundPart {
        texels: range.start as u32..range.end as u32,
        texel_count: state.texels.len() as u32,
        points: points.clone(),
        point_count: state.points.len() as u64,
        rays: sums.rays,
        traced: sums.traced,
        rejected: if round == 0 { rejected.iter().filter(|&&r| r).count() as u64 } else { 0 },
        sums: sums.sums,
        weights: if round == 0 { sums.weights } else { Vec::new() },
        moments: sums.moments.iter().map(|m| m.to_array()).collect(),
    };
    let hits = record.then(|| {
        let mut bits = vec![0u32; rejected.len().div_ceil(32)];
        for (local, _) in rejected.iter().enumerate().filter(|(_, &r)| r) {
            bits[local / 32] |= 1 << (local % 32);
        }
        TexelHits { texels: part.texels.clone(), points, rays: params.rays, rejected: bits, records: sums.hits, density: None }
    });
    Ok((part, hits))
}

/// A texel round's inputs: this shard's texel hit records and the merged
/// texels of the round before, for `covered` texels.
fn check_texel_inputs<'a>(
    input: &'a RoundInput,
    range: std::ops::Range<usize>,
    points: std::ops::Range<u64>,
    covered: usize,
    rays: u32,
) -> Result<(&'a TexelHits, &'a TexelLayer), ShardError> {
    let hits =
        input.hits.texels.as_ref().ok_or_else(|| {
            ShardError::mismatch(input.hits_path, "holds no texel hit records, but this bake is texel mode's (--texel-size)")
        })?;
    if hits.texels != (range.start as u32..range.end as u32) || hits.points != points {
        return Err(ShardError::mismatch(
            input.hits_path,
            format!("holds the hit records of texels {:?}, but this shard traces texels {range:?}", hits.texels),
        ));
    }
    if hits.rays != rays {
        return Err(ShardError::mismatch(
            input.hits_path,
            format!("holds {} rays per texel point, but this bake traces {rays}", hits.rays),
        ));
    }
    let layer = input
        .layer
        .texels
        .as_ref()
        .ok_or_else(|| ShardError::mismatch(input.layer_path, "holds no texel rows, but this bake is texel mode's (--texel-size)"))?;
    if layer.texel_count as usize != covered {
        return Err(ShardError::mismatch(
            input.layer_path,
            format!("holds {} covered texels, but this atlas covers {covered}", layer.texel_count),
        ));
    }
    Ok((hits, layer))
}

/// A later round's inputs must be this bake's and this shard's: its own hit
/// records, and the layer of the round before.
fn check_inputs(
    input: &RoundInput,
    identity: &Identity,
    shard: Shard,
    round: u32,
    items: std::ops::Range<u32>,
    points: std::ops::Range<u64>,
    plan: &Plan,
) -> Result<(), ShardError> {
    let (hits, layer) = (&input.hits, &input.layer);
    let this_bake = "this bake's mesh and arguments";
    if let Some(d) = identity_difference(&hits.identity, identity, super::FileKind::Hits) {
        return Err(ShardError::mismatch(input.hits_path, format!("{d} {this_bake}: these hit records are another bake's")));
    }
    if hits.shard != shard.index || hits.items != items || hits.points != points {
        return Err(ShardError::mismatch(
            input.hits_path,
            format!(
                "holds shard {}/{}'s hit records (items {:?}), not shard {shard}'s (items {items:?})",
                hits.shard, shard.count, hits.items
            ),
        ));
    }
    if hits.rays != plan.params.rays {
        return Err(ShardError::mismatch(
            input.hits_path,
            format!("holds {} rays per point, but this bake traces {}", hits.rays, plan.params.rays),
        ));
    }
    if let Some(d) = identity_difference(&layer.identity, identity, super::FileKind::Layer) {
        return Err(ShardError::mismatch(input.layer_path, format!("{d} {this_bake}: this layer is another bake's")));
    }
    if layer.round + 1 != round {
        return Err(ShardError::mismatch(
            input.layer_path,
            format!("is the layer of round {}, but round {round} gathers from round {}'s", layer.round, round - 1),
        ));
    }
    let source_channels = plan.pass_channels(round - 1) as u32;
    if layer.channels != plan.channels as u32 || layer.coeffs != plan.coeffs as u32 || layer.source_channels != source_channels {
        return Err(ShardError::mismatch(input.layer_path, "holds rows of another size than this bake's"));
    }
    Ok(())
}

/// Traces shard `shard`'s samples toward every day step of `suns` (see
/// [`crate::bake::bake_sun_masks`]) and, in texel mode, its share of the
/// covered texels; the caller adds the frame to shard 0's part. The key's
/// `quiet` says whether progress is shown.
pub fn bake_sun_shard(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    suns: &[Option<Vec3>],
    key: &SunKey,
    texels: Option<&TexelSunPlan>,
    shard: Shard,
) -> Result<SunPart, ShardError> {
    if key.steps as usize != suns.len() {
        return Err(BakeError::Params(format!("{} sun steps, but the key says {}", suns.len(), key.steps)).into());
    }
    if key.texels.as_ref().map(|t| t.covered_texels as usize) != texels.map(TexelSunPlan::texel_count) {
        return Err(BakeError::Params("the texel plan is not the one the key describes".into()).into());
    }
    let plan = SunPlan::new(mesh, surfaces, suns, &key.params)?;
    let day_steps = suns.iter().filter(|s| s.is_some()).count().max(1) as u64;
    let costs: Vec<u64> = plan.points_per_item().iter().map(|&p| p as u64 * day_steps).collect();
    let range = split_by_cost(&costs, shard.count)[shard.index as usize].clone();
    let first_point = |item: usize| plan.layout.first_sample.get(item).map_or(plan.layout.sample_count(), |&f| f as u64);
    let (bits, rays) = plan.trace_items(scene, surfaces, range.clone());
    // The texels are balanced apart: their points per texel, times the day's steps.
    let texels = texels.map(|texel_plan| {
        let costs = texel_plan.costs();
        let range = split_by_cost(&costs, shard.count)[shard.index as usize].clone();
        let traced = texel_plan.trace(mesh, scene, surfaces, range.clone());
        let fractions = key.texels.as_ref().is_some_and(|t| t.fractions);
        let (words, fraction_words) = texel_plan.words();
        TexelSunPart {
            texels: range.start as u32..range.end as u32,
            texel_count: costs.len() as u32,
            words: words as u32,
            fraction_words: if fractions { fraction_words as u32 } else { 0 },
            points: traced.points,
            rays: traced.rays,
            masks: traced.masks,
            fractions: if fractions { traced.fractions } else { Vec::new() },
        }
    });
    Ok(SunPart {
        identity: Identity {
            mesh: MeshId::of(mesh),
            plan_vertices: mesh.vertex_count() as u64,
            plan_triangles: mesh.triangle_count() as u64,
            shards: shard.count,
            key: key.encode(),
        },
        shard: shard.index,
        items: range.start as u32..range.end as u32,
        item_count: costs.len() as u32,
        points: first_point(range.start)..first_point(range.end),
        point_count: plan.layout.sample_count(),
        words: plan.words as u32,
        rays,
        bits,
        frame: Vec::new(),
        texels,
    })
}
