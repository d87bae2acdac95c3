//! Merges: first the checks that the parts belong together (one bake, one
//! round, every shard exactly once, item ranges end to end), then the sums
//! in shard order, which is item order, so each vertex's f32 sum runs as in
//! a whole bake; then the normalisation a whole bake runs.

use std::path::{Path, PathBuf};

use super::codec::FileKind;
use super::files::{Identity, LayerFile, PilotFile, SunPart, TexelLayer, TexelPilotRows, TransferPart};
use super::key::{first_difference, SunKey, TransferKey};
use super::ShardError;
use crate::bake::noise::{add_noise_in_quadrature, Moments, VertexDc};
use crate::bake::side_share::{add_back_dc, front_shares};
use crate::bake::transfer::{add_layer, add_row, normalise_rows, normalised_layer, split_sides};
use crate::bake::{BakeStats, TexelSunRange, TransferResult};

/// What two identities differ in, as "rays 32 here, 64 in" (the caller names
/// the other file), or `None` when they are the same bake.
pub(crate) fn identity_difference(here: &Identity, there: &Identity, kind: FileKind) -> Option<String> {
    if here.mesh != there.mesh {
        return Some(format!("baked from another mesh ({}) than ({}) in", here.mesh, there.mesh));
    }
    if here.shards != there.shards {
        return Some(format!("is one of {} shards, not of {} as in", here.shards, there.shards));
    }
    if (here.plan_vertices, here.plan_triangles) != (there.plan_vertices, there.plan_triangles) {
        return Some(format!(
            "baked {} vertices and {} triangles with their back sides, not {} and {} as in",
            here.plan_vertices, here.plan_triangles, there.plan_vertices, there.plan_triangles
        ));
    }
    if here.key == there.key {
        return None;
    }
    let fields = |key: &[u8]| match kind {
        FileKind::SunPart => SunKey::decode(key).map(|k| k.fields()),
        _ => TransferKey::decode(key).map(|k| k.fields()),
    };
    match (fields(&here.key), fields(&there.key)) {
        (Ok(a), Ok(b)) => first_difference(&a, &b).or_else(|| Some("other parameters here than in".into())),
        _ => Some("an unreadable parameter block here, unlike".into()),
    }
}

/// Shard indices as "2, 5-7".
fn list_indices(indices: impl IntoIterator<Item = u32>) -> String {
    let mut out: Vec<String> = Vec::new();
    let mut run: Option<(u32, u32)> = None;
    let flush = |run: (u32, u32), out: &mut Vec<String>| {
        out.push(if run.0 == run.1 { run.0.to_string() } else { format!("{}-{}", run.0, run.1) });
    };
    for i in indices {
        run = match run {
            Some((a, b)) if b + 1 == i => Some((a, i)),
            Some(r) => {
                flush(r, &mut out);
                Some((i, i))
            }
            None => Some((i, i)),
        };
    }
    if let Some(r) = run {
        flush(r, &mut out);
    }
    if out.is_empty() {
        "none".into()
    } else {
        out.join(", ")
    }
}

/// The header fields of a part the checks compare.
struct PartHead<'a> {
    path: &'a Path,
    identity: &'a Identity,
    shard: u32,
    /// Transfer rounds; sun parts are all round 0.
    round: u32,
    /// A part of adaptive allocation's pilot stage (before round 0).
    pilot: bool,
    items: std::ops::Range<u32>,
    item_count: u32,
    points: std::ops::Range<u64>,
    point_count: u64,
}

/// Checks that `heads` are every shard of one bake exactly once, their
/// items end to end; returns their indices in shard order.
fn check_together(heads: &[PartHead], kind: FileKind) -> Result<Vec<usize>, ShardError> {
    let first = heads.first().ok_or(ShardError::NoParts)?;
    let count = first.identity.shards;
    let mut by_shard: Vec<Option<usize>> = vec![None; count as usize];
    for (i, head) in heads.iter().enumerate() {
        if let Some(d) = identity_difference(head.identity, first.identity, kind) {
            return Err(ShardError::mismatch(
                head.path,
                format!("{d} {}: parts of one merge must come from one bake", first.path.display()),
            ));
        }
        if (head.round, head.pilot) != (first.round, first.pilot) {
            let stage = |h: &PartHead| if h.pilot { "the pilot stage".to_string() } else { format!("round {}", h.round) };
            return Err(ShardError::mismatch(
                head.path,
                format!(
                    "is a part of {}, but {} of {}: merge one stage or round at a time",
                    stage(head),
                    first.path.display(),
                    stage(first)
                ),
            ));
        }
        match by_shard[head.shard as usize] {
            Some(other) => {
                return Err(ShardError::Duplicate {
                    path: head.path.to_path_buf(),
                    other: heads[other].path.to_path_buf(),
                    index: head.shard,
                    count,
                })
            }
            None => by_shard[head.shard as usize] = Some(i),
        }
    }
    let missing: Vec<u32> = (0..count).filter(|&k| by_shard[k as usize].is_none()).collect();
    if !missing.is_empty() {
        let given = (0..count).filter(|&k| by_shard[k as usize].is_some());
        return Err(ShardError::Missing { count, missing: list_indices(missing), given: list_indices(given) });
    }
    let order: Vec<usize> = by_shard.into_iter().flatten().collect();
    let (mut item, mut point) = (0u32, 0u64);
    for &i in &order {
        let h = &heads[i];
        if h.item_count != first.item_count || h.point_count != first.point_count || h.items.start != item || h.points.start != point {
            return Err(ShardError::mismatch(
                h.path,
                format!(
                    "covers items {:?} of {} (points {:?} of {}), which does not follow on from the shards before it: \
                     the parts disagree on the bake's items",
                    h.items, h.item_count, h.points, h.point_count
                ),
            ));
        }
        (item, point) = (h.items.end, h.points.end);
    }
    let last = &heads[*order.last().unwrap_or(&0)];
    if item != first.item_count || point != first.point_count {
        return Err(ShardError::mismatch(
            last.path,
            format!("ends at item {item} of {}: the parts do not cover the bake", first.item_count),
        ));
    }
    Ok(order)
}

/// What a transfer merge gives: the next round's layer, or after the last
/// round the result and the frame its bundle is made from.
pub enum TransferMerge {
    /// The pilot stage of an adaptive bake: what every round allocates by.
    Pilot(PilotFile),
    Layer(LayerFile),
    Final {
        result: TransferResult,
        key: TransferKey,
        frame: Vec<u8>,
        /// Texel mode: every covered texel's rounds merged (no source rows).
        texels: Option<TexelLayer>,
    },
}

/// Merges every part of one transfer round. Rounds ≥ 1 also take the layer
/// their parts gathered from (`path`, layer, CRC), whose weights normalise
/// them and whose total they add to.
pub fn merge_transfer(parts: &[(PathBuf, TransferPart)], layer: Option<(&Path, LayerFile, u32)>) -> Result<TransferMerge, ShardError> {
    let heads: Vec<PartHead> = parts
        .iter()
        .map(|(path, p)| PartHead {
            path,
            identity: &p.identity,
            shard: p.shard,
            round: p.round,
            pilot: p.pilot,
            items: p.items.clone(),
            item_count: p.item_count,
            points: p.points.clone(),
            point_count: p.point_count,
        })
        .collect();
    let order = check_together(&heads, FileKind::TransferPart)?;
    let first = &heads[0];
    let (first_path, reference) = (&parts[0].0, &parts[0].1);
    for (path, p) in parts {
        if (p.channels, p.coeffs, p.pass_channels, p.window_triangles)
            != (reference.channels, reference.coeffs, reference.pass_channels, reference.window_triangles)
        {
            return Err(ShardError::mismatch(path, format!("holds rows of another size than {}", first_path.display())));
        }
    }
    for (path, p) in parts {
        if p.pilot != reference.pilot {
            return Err(ShardError::mismatch(path, format!("mixes the pilot stage and round 0 with {}", first_path.display())));
        }
        // Round 0 of an adaptive bake names the pilot it allocated by.
        if p.round == 0 && p.layer_crc != reference.layer_crc {
            return Err(ShardError::mismatch(
                path,
                format!(
                    "allocated its points by another merged pilot than {} (every shard of round 0 needs the same --pilot)",
                    first_path.display()
                ),
            ));
        }
    }
    let key = TransferKey::decode(&first.identity.key).map_err(|e| ShardError::malformed(first_path, format!("parameter block: {e}")))?;
    let params = &key.params;
    let round = reference.round;
    if reference.coeffs as usize != crate::sh::coeff_count(params.order) {
        return Err(ShardError::mismatch(
            first_path,
            format!("holds {} coefficients, but order {} has {}", reference.coeffs, params.order, crate::sh::coeff_count(params.order)),
        ));
    }
    if round > params.bounces {
        return Err(ShardError::mismatch(first_path, format!("is round {round} of a bake of {} bounce(s)", params.bounces)));
    }
    let (mut previous, layer_path) = match (round, layer) {
        (0, None) => (None, first_path.as_path()),
        (0, Some((path, ..))) => {
            return Err(ShardError::mismatch(path, "round 0 parts gather from no layer: merge them without --layer"));
        }
        (_, None) => {
            return Err(ShardError::mismatch(
                first_path,
                format!("round {round} parts gathered from the merged layer of round {}: give it with --layer", round - 1),
            ));
        }
        (_, Some((path, layer, crc))) => {
            check_layer(path, &layer, crc, reference, parts)?;
            (Some(layer), path)
        }
    };

    // The sums, in shard order: each vertex's opening shard's row, then the
    // later shards' contributions in item order.
    // The plan's rows: the mesh's vertices, then its back sides'.
    let vertex_count = first.identity.plan_vertices as usize;
    let (pass_channels, channels, coeffs) = (reference.pass_channels as usize, reference.channels as usize, reference.coeffs as usize);
    let stride = pass_channels * coeffs;
    // The vertex count comes from the parts' identity: allocate without aborting when it lies.
    let mut sums = zeroed(vertex_count * stride, first_path)?;
    let mut weights = match &previous {
        Some(layer) => layer.weights.clone(),
        None => zeroed(vertex_count, first_path)?,
    };
    // Interior sampling: each vertex's DC moments, added as the sums are.
    let tracks_noise = reference.tracks_noise;
    if let Some((path, _)) = parts.iter().find(|(_, p)| p.tracks_noise != reference.tracks_noise) {
        return Err(ShardError::mismatch(path, format!("carries noise moments, and {} does not (or the reverse)", first_path.display())));
    }
    let mut moments = vec![Moments::default(); if tracks_noise { vertex_count } else { 0 }];
    let mut opened = vec![false; vertex_count];
    for &i in &order {
        let (path, part) = &parts[i];
        for (j, &v) in part.opened.vertices.iter().enumerate() {
            let v = v as usize;
            if std::mem::replace(&mut opened[v], true) {
                return Err(ShardError::mismatch(path, format!("opens vertex {v}, which an earlier part opened too")));
            }
            sums[v * stride..(v + 1) * stride].copy_from_slice(&part.opened.rows[j * stride..(j + 1) * stride]);
            if round == 0 {
                weights[v] = part.opened.weights[j];
            }
            if tracks_noise {
                moments[v] = Moments::from_array(part.opened.moments[j]);
            }
        }
        for (j, &v) in part.late.vertices.iter().enumerate() {
            let v = v as usize;
            if !opened[v] {
                return Err(ShardError::mismatch(path, format!("adds to vertex {v}, which no earlier part opened")));
            }
            add_row(&mut sums[v * stride..(v + 1) * stride], &part.late.rows[j * stride..(j + 1) * stride]);
            if round == 0 {
                weights[v] += part.late.weights[j];
            }
            if tracks_noise {
                moments[v].merge(&Moments::from_array(part.late.moments[j]));
            }
        }
    }
    if reference.pilot {
        if !tracks_noise {
            return Err(ShardError::mismatch(first_path, "is a pilot part without the moments the allocation needs"));
        }
        let dc_sums = sums.iter().step_by(stride).copied().collect();
        let moments = moments.iter().map(|m| m.to_array()).collect();
        let texels = pilot_texels(parts, &order, key.texels.as_ref().is_some_and(|t| t.adaptive > 0.0))?;
        return Ok(TransferMerge::Pilot(PilotFile {
            identity: first.identity.clone(),
            points: reference.point_count,
            weights,
            dc_sums,
            moments,
            texels,
        }));
    }
    let texels = merge_texel_round(parts, &order, &key, reference, previous.as_mut().map(|p| (p.texels.take(), layer_path)))?;
    // As a whole bake computes it: the rounds so far, in quadrature.
    let mut noise = previous.as_ref().map_or_else(Vec::new, |layer| layer.noise.clone());
    let mut back_dc = previous.as_ref().map_or_else(Vec::new, |layer| layer.back_dc.clone());
    if tracks_noise {
        add_noise_in_quadrature(&mut noise, &VertexDc::new(&weights, &sums, stride, &moments).standard_errors());
        add_back_dc(&mut back_dc, &weights, &moments);
    }

    let layer = normalised_layer(&sums, &weights, pass_channels, channels, coeffs);
    let (mut total, mut layers, mut rays_per_bounce, points_rejected, rays_traced, glass_light) = match previous {
        Some(p) => (p.total, p.layers, p.rays_per_bounce, p.points_rejected, p.rays_traced, p.glass_light),
        None => {
            let glass_light =
                order.iter().fold([0.0f64; 2], |sum, &i| [sum[0] + parts[i].1.glass_light[0], sum[1] + parts[i].1.glass_light[1]]);
            let rejected = parts.iter().map(|(_, p)| p.rejected).sum();
            (vec![0.0f32; vertex_count * channels * coeffs], Vec::new(), Vec::new(), rejected, 0, glass_light)
        }
    };
    add_layer(&mut total, &layer);
    rays_per_bounce.push(parts.iter().map(|(_, p)| p.rays).sum());
    let rays_traced = rays_traced + parts.iter().map(|(_, p)| p.traced).sum::<u64>();
    if params.store_bounces {
        layers.push(layer);
    }
    if round < params.bounces {
        let mut source = vec![0.0f32; vertex_count * stride];
        normalise_rows(&mut source, &sums, &weights, stride);
        // Window mode: split by side, as a whole bake splits the rows its next bounce gathers.
        let source_sides = params.mode == crate::bake::Mode::Window && tracks_noise;
        if source_sides {
            source = split_sides(&source, &weights, &moments, pass_channels, coeffs).as_slice().to_vec();
        }
        return Ok(TransferMerge::Layer(LayerFile {
            identity: first.identity.clone(),
            round,
            channels: channels as u32,
            coeffs: coeffs as u32,
            source_channels: pass_channels as u32,
            window_triangles: reference.window_triangles,
            points: reference.point_count,
            points_rejected,
            rays_traced,
            glass_light,
            rays_per_bounce,
            weights,
            noise,
            back_dc,
            source_sides,
            source,
            total,
            layers,
            texels,
        }));
    }
    let frame_part = &parts[order[0]];
    if frame_part.1.frame.is_empty() {
        return Err(ShardError::mismatch(&frame_part.0, "is shard 0 of the last round but carries no bundle frame (mesh and metadata)"));
    }
    // The result is the mesh's vertices; the back sides' rows served the gathers only.
    let mesh_vertices = first.identity.mesh.vertices as usize;
    let stride = channels * coeffs;
    total.truncate(mesh_vertices * stride);
    layers.iter_mut().for_each(|l| l.truncate(mesh_vertices * stride));
    noise.truncate(mesh_vertices);
    back_dc.truncate(mesh_vertices);
    let front_share = front_shares(params.mode, &back_dc, &total, channels, coeffs);
    let stats = BakeStats {
        triangles: first.identity.mesh.triangles,
        vertices: mesh_vertices as u64,
        back_sides: first.identity.plan_triangles - first.identity.mesh.triangles,
        window_triangles: reference.window_triangles,
        points: reference.point_count,
        points_rejected,
        vertices_without_samples: weights[..mesh_vertices.min(weights.len())].iter().filter(|&&w| w <= 0.0).count() as u64,
        rays: rays_per_bounce.iter().sum(),
        // Rounds ≥ 1 gather from each shard's hit records; they trace nothing.
        rays_gathered: rays_per_bounce.iter().skip(1).sum(),
        rays_per_bounce,
        rays_traced,
        outside_light_share: crate::bake::outside_light_share(glass_light),
        ..BakeStats::default()
    };
    let result = TransferResult { order: params.order, channels, total, bounces: layers, noise, back: Vec::new(), front_share, stats };
    let texels = texels.map(|t| TexelLayer { source: Vec::new(), ..t });
    Ok(TransferMerge::Final { result, frame: frame_part.1.frame.clone(), key, texels })
}

/// The texel transfer a sharded texel bake stores: the merged rounds of
/// every covered texel, on the atlas and texels shard 0's frame carries,
/// which must be the atlas the key names.
pub fn merged_texel_transfer(
    merged: TexelLayer,
    frame: crate::bundle::TexelLayers,
    key: &super::TexelKey,
    params: &crate::bake::BakeParams,
) -> Result<crate::bake::texels::TexelTransfer, String> {
    if super::atlas_crc(&frame.atlas) != key.atlas_crc || frame.texels.len() != merged.texel_count as usize {
        return Err(format!(
            "its bundle frame holds another atlas ({} covered texels, CRC-32 {:08x}) than the parts baked ({}, {:08x})",
            frame.texels.len(),
            super::atlas_crc(&frame.atlas),
            merged.texel_count,
            key.atlas_crc
        ));
    }
    let coeffs = crate::sh::coeff_count(params.order);
    let channels = merged.total.len() / (merged.texel_count as usize * coeffs).max(1);
    let front_share = front_shares(params.mode, &merged.back_dc, &merged.total, channels, coeffs);
    Ok(crate::bake::texels::TexelTransfer {
        atlas: frame.atlas,
        texels: frame.texels,
        total: merged.total,
        bounces: merged.layers,
        covered_area: merged.weights,
        noise: merged.noise,
        front_share,
        points: merged.points,
        points_added: 0,
        points_rejected: merged.points_rejected,
        rays: merged.rays,
        rays_traced: merged.rays_traced,
        seconds_per_bounce: Vec::new(),
    })
}

/// `--texel-adaptive`: the pilot parts' texel ranges joined in shard order
/// (end to end over the covered texels) into the merged pilot's per-texel
/// weights, DC sums and moments; `None` when the bake places no texel points.
fn pilot_texels(parts: &[(PathBuf, TransferPart)], order: &[usize], adaptive: bool) -> Result<Option<TexelPilotRows>, ShardError> {
    if !adaptive {
        return Ok(None);
    }
    let mut rows = TexelPilotRows { weights: Vec::new(), dc_sums: Vec::new(), moments: Vec::new() };
    let mut next = 0u32;
    let mut count = 0u32;
    for &i in order {
        let (path, part) = &parts[i];
        let Some(t) = &part.texels else {
            return Err(ShardError::mismatch(path, "is a pilot part without the texels --texel-adaptive places points by"));
        };
        let n = t.texels.len();
        if t.texels.start != next || t.weights.len() != n || t.moments.len() != n || (n > 0 && t.sums.len() % n != 0) {
            return Err(ShardError::mismatch(path, format!("holds texels {}..{} where {next} was next", t.texels.start, t.texels.end)));
        }
        let stride = if n > 0 { t.sums.len() / n } else { 1 };
        rows.weights.extend_from_slice(&t.weights);
        rows.dc_sums.extend(t.sums.iter().step_by(stride.max(1)));
        rows.moments.extend_from_slice(&t.moments);
        (next, count) = (t.texels.end, t.texel_count);
    }
    if next != count {
        return Err(ShardError::mismatch(&parts[order[0]].0, format!("the pilot parts hold texels 0..{next} of {count}")));
    }
    Ok(Some(rows))
}

/// Texel mode: joins the parts' texel ranges (in shard order, end to end
/// over the covered texels) and runs the round's normalisation a whole
/// bake runs on its texels; `previous` is the texels of the layer the
/// parts gathered from (rounds ≥ 1), with its path.
fn merge_texel_round(
    parts: &[(PathBuf, TransferPart)],
    order: &[usize],
    key: &TransferKey,
    reference: &TransferPart,
    previous: Option<(Option<TexelLayer>, &Path)>,
) -> Result<Option<TexelLayer>, ShardError> {
    let first_path = &parts[order[0]].0;
    let Some(texel_key) = &key.texels else {
        if let Some((path, _)) = parts.iter().find(|(_, p)| p.texels.is_some()) {
            return Err(ShardError::mismatch(path, "holds texel rows, but its key has no texel mode"));
        }
        if let Some((Some(_), path)) = previous {
            return Err(ShardError::mismatch(path, "holds texel rows, but the parts' key has no texel mode"));
        }
        return Ok(None);
    };
    if reference.pilot {
        return Ok(None);
    }
    let params = &key.params;
    let round = reference.round;
    let (pass_channels, channels, coeffs) = (reference.pass_channels as usize, reference.channels as usize, reference.coeffs as usize);
    let stride = pass_channels * coeffs;
    let covered = texel_key.covered_texels;
    let mut sums = Vec::new();
    let (mut weights, mut moments) = (Vec::new(), Vec::new());
    let (mut next, mut next_point, mut point_count) = (0u32, 0u64, None);
    let (mut rays, mut traced, mut rejected) = (0u64, 0u64, 0u64);
    for &i in order {
        let (path, part) = &parts[i];
        let t = part.texels.as_ref().ok_or_else(|| ShardError::mismatch(path, "holds no texel rows, but its key is texel mode's"))?;
        if t.texel_count != covered || *point_count.get_or_insert(t.point_count) != t.point_count {
            return Err(ShardError::mismatch(
                path,
                format!("holds {} covered texels of {} points, not the key's {covered} of the other parts'", t.texel_count, t.point_count),
            ));
        }
        if t.texels.start != next || t.points.start != next_point {
            return Err(ShardError::mismatch(path, format!("holds texels {:?}, but the shards before it end at texel {next}", t.texels)));
        }
        (next, next_point) = (t.texels.end, t.points.end);
        sums.extend_from_slice(&t.sums);
        weights.extend_from_slice(&t.weights);
        moments.extend(t.moments.iter().map(|&m| Moments::from_array(m)));
        (rays, traced, rejected) = (rays + t.rays, traced + t.traced, rejected + t.rejected);
    }
    if next != covered || Some(next_point) != point_count {
        let (path, _) = &parts[order[order.len() - 1]];
        return Err(ShardError::mismatch(path, format!("ends at texel {next}: the parts do not cover the {covered} covered texels")));
    }
    let previous = match previous {
        None => None,
        Some((None, path)) => return Err(ShardError::mismatch(path, "holds no texel rows, but the parts are texel mode's")),
        Some((Some(layer), path)) if layer.texel_count != covered => {
            return Err(ShardError::mismatch(path, format!("holds {} covered texels, the parts {covered}", layer.texel_count)))
        }
        Some((Some(layer), _)) => Some(layer),
    };
    // As a whole bake's texel pass: bounce 0's weights normalise every bounce.
    let mut merged = match previous {
        Some(layer) => TexelLayer { rays: layer.rays + rays, rays_traced: layer.rays_traced + traced, ..layer },
        None => TexelLayer {
            texel_count: covered,
            points: point_count.unwrap_or(0),
            points_rejected: rejected,
            rays,
            rays_traced: traced,
            weights,
            noise: Vec::new(),
            back_dc: Vec::new(),
            source_sides: false,
            source: Vec::new(),
            total: zeroed(covered as usize * channels * coeffs, first_path)?,
            layers: Vec::new(),
        },
    };
    let sigma = VertexDc::new(&merged.weights, &sums, stride, &moments).standard_errors();
    add_noise_in_quadrature(&mut merged.noise, &sigma);
    add_back_dc(&mut merged.back_dc, &merged.weights, &moments);
    let layer = normalised_layer(&sums, &merged.weights, pass_channels, channels, coeffs);
    add_layer(&mut merged.total, &layer);
    if params.store_bounces {
        merged.layers.push(layer);
    }
    merged.source = vec![0.0f32; if round < params.bounces { covered as usize * stride } else { 0 }];
    if round < params.bounces {
        normalise_rows(&mut merged.source, &sums, &merged.weights, stride);
        merged.source_sides = params.mode == crate::bake::Mode::Window;
        if merged.source_sides {
            merged.source = split_sides(&merged.source, &merged.weights, &moments, pass_channels, coeffs).as_slice().to_vec();
        }
    }
    Ok(Some(merged))
}

/// `len` zeros, or an error naming `path` when they cannot be allocated.
fn zeroed(len: usize, path: &Path) -> Result<Vec<f32>, ShardError> {
    let mut v = Vec::new();
    v.try_reserve_exact(len)
        .map_err(|_| ShardError::mismatch(path, format!("claims a mesh whose sums ({len} floats) do not fit in memory")))?;
    v.resize(len, 0.0);
    Ok(v)
}

/// The layer given to a merge must be the one every part gathered from.
fn check_layer(
    path: &Path,
    layer: &LayerFile,
    crc: u32,
    reference: &TransferPart,
    parts: &[(PathBuf, TransferPart)],
) -> Result<(), ShardError> {
    if let Some(d) = identity_difference(&layer.identity, &reference.identity, FileKind::Layer) {
        return Err(ShardError::mismatch(path, format!("{d} {}: this layer is another bake's", parts[0].0.display())));
    }
    if layer.round + 1 != reference.round {
        return Err(ShardError::mismatch(
            path,
            format!(
                "is the layer of round {}, but the parts are round {}: give the layer of round {}",
                layer.round,
                reference.round,
                reference.round - 1
            ),
        ));
    }
    let source_channels = if layer.round == 0 { 1 } else { reference.channels };
    if (layer.channels, layer.coeffs, layer.source_channels) != (reference.channels, reference.coeffs, source_channels) {
        return Err(ShardError::mismatch(path, format!("holds rows of another size than {}", parts[0].0.display())));
    }
    if let Some((part_path, _)) = parts.iter().find(|(_, p)| p.layer_crc != crc) {
        return Err(ShardError::mismatch(
            part_path,
            format!("gathered from another layer file than {} (CRC-32 {crc:08x}): re-run this shard with that layer", path.display()),
        ));
    }
    Ok(())
}

/// Every sun part of one bake put together: all samples' bits in sample
/// order, the rays traced, and shard 0's frame.
pub struct MergedSun {
    pub key: SunKey,
    pub identity: Identity,
    pub bits: Vec<u32>,
    pub rays: u64,
    pub frame: Vec<u8>,
    /// Texel mode: every covered texel's rows, joined in texel order.
    pub texels: Option<TexelSunRange>,
}

/// Checks and concatenates the parts of a sharded sun bake.
pub fn merge_sun_parts(parts: &[(PathBuf, SunPart)]) -> Result<MergedSun, ShardError> {
    let heads: Vec<PartHead> = parts
        .iter()
        .map(|(path, p)| PartHead {
            path,
            identity: &p.identity,
            shard: p.shard,
            round: 0,
            pilot: false,
            items: p.items.clone(),
            item_count: p.item_count,
            points: p.points.clone(),
            point_count: p.point_count,
        })
        .collect();
    let order = check_together(&heads, FileKind::SunPart)?;
    let (first_path, first) = &parts[order[0]];
    let key = SunKey::decode(&first.identity.key).map_err(|e| ShardError::malformed(first_path, format!("parameter block: {e}")))?;
    let words = key.steps.div_ceil(32);
    if let Some((path, _)) = parts.iter().find(|(_, p)| p.words != words) {
        return Err(ShardError::mismatch(
            path,
            format!("holds {} mask words per point, not the {words} of {} steps", first.words, key.steps),
        ));
    }
    // The vote counts each set bit's step: a bit past the last step would count a step that does not exist.
    let last_word_mask = if key.steps % 32 == 0 { u32::MAX } else { (1u32 << (key.steps % 32)) - 1 };
    for (path, part) in parts {
        if part.bits.chunks_exact(words as usize).any(|point| point[point.len() - 1] & !last_word_mask != 0) {
            return Err(ShardError::mismatch(path, format!("has bits set past the last of its {} steps", key.steps)));
        }
    }
    if first.frame.is_empty() {
        return Err(ShardError::mismatch(first_path, "is shard 0 but carries no bundle frame"));
    }
    let mut bits = Vec::with_capacity(first.point_count as usize * first.words as usize);
    for &i in &order {
        bits.extend_from_slice(&parts[i].1.bits);
    }
    let texels = merge_texel_rows(parts, &order, &key, last_word_mask)?;
    Ok(MergedSun {
        identity: first.identity.clone(),
        bits,
        rays: parts.iter().map(|(_, p)| p.rays).sum(),
        frame: first.frame.clone(),
        texels,
        key,
    })
}

/// Joins the parts' texel rows in shard order, after checking that each
/// part has them as the key says, and that their ranges tile the covered
/// texels without gap or overlap.
fn merge_texel_rows(
    parts: &[(PathBuf, SunPart)],
    order: &[usize],
    key: &SunKey,
    last_word_mask: u32,
) -> Result<Option<TexelSunRange>, ShardError> {
    let Some(texel_key) = &key.texels else {
        return match parts.iter().find(|(_, p)| p.texels.is_some()) {
            Some((path, _)) => Err(ShardError::mismatch(path, "holds texel rows, but its key has no texel mode")),
            None => Ok(None),
        };
    };
    let (words, fraction_words) = (key.steps.div_ceil(32), if texel_key.fractions { key.steps.div_ceil(8) } else { 0 });
    let mut merged = TexelSunRange::default();
    let mut next = 0u32;
    for &i in order {
        let (path, part) = &parts[i];
        let t = part.texels.as_ref().ok_or_else(|| ShardError::mismatch(path, "holds no texel rows, but its key is texel mode's"))?;
        if t.texel_count != texel_key.covered_texels || t.words != words || t.fraction_words != fraction_words {
            return Err(ShardError::mismatch(
                path,
                format!(
                    "holds {} covered texels of {} mask and {} fraction words, not the key's {} of {words} and {fraction_words}",
                    t.texel_count, t.words, t.fraction_words, texel_key.covered_texels
                ),
            ));
        }
        if t.texels.start != next {
            return Err(ShardError::mismatch(path, format!("holds texels {:?}, but the shards before it end at texel {next}", t.texels)));
        }
        if t.masks.chunks_exact(words as usize).any(|texel| texel[texel.len() - 1] & !last_word_mask != 0) {
            return Err(ShardError::mismatch(path, format!("has texel bits set past the last of its {} steps", key.steps)));
        }
        next = t.texels.end;
        merged.masks.extend_from_slice(&t.masks);
        merged.fractions.extend_from_slice(&t.fractions);
        merged.points += t.points;
        merged.rays += t.rays;
    }
    if next != texel_key.covered_texels {
        let (path, _) = &parts[order[order.len() - 1]];
        return Err(ShardError::mismatch(path, format!("is the last shard, but its texels end at {next} of {}", texel_key.covered_texels)));
    }
    Ok(Some(merged))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A three-vertex mesh's identity under `key`, in `shards` shards.
    fn identity_of(key: &SunKey, shards: u32) -> crate::shards::Identity {
        let mesh = crate::shards::MeshId { crc: 1, vertices: 3, triangles: 1 };
        crate::shards::Identity { mesh, plan_vertices: 3, plan_triangles: 1, shards, key: key.encode() }
    }

    /// Sun bits past the last step would make the vote count a step that
    /// does not exist: a part with one is refused, not merged.
    #[test]
    fn sun_bits_past_the_last_step_are_refused() {
        let key = SunKey { params: crate::bake::SunParams::default(), window_patterns: Vec::new(), steps: 5, day_crc: 7, texels: None };
        let identity = identity_of(&key, 1);
        let part = |bits: Vec<u32>| SunPart {
            identity: identity.clone(),
            shard: 0,
            items: 0..1,
            item_count: 1,
            points: 0..2,
            point_count: 2,
            words: 1,
            rays: 10,
            bits,
            frame: vec![1],
            texels: None,
        };
        assert!(merge_sun_parts(&[(PathBuf::from("ok.prtp"), part(vec![0b11111, 0b1]))]).is_ok());
        let e = merge_sun_parts(&[(PathBuf::from("bad.prtp"), part(vec![0b1, 0b100000]))]).err().unwrap().to_string();
        assert!(e.contains("bad.prtp: has bits set past the last of its 5 steps"), "{e}");
    }

    /// Texel rows must tile the covered texels in shard order: a gap, an
    /// overlap, a short last shard, a bit past the last step or a part
    /// without texels under a texel key is refused, naming the part.
    #[test]
    fn texel_rows_that_do_not_tile_the_covered_texels_are_refused() {
        use crate::shards::{TexelKey, TexelSunPart};
        let texel_key = TexelKey {
            texel_size: 0.1,
            points_per_texel: 4,
            fractions: false,
            covered_texels: 5,
            atlas_crc: 9,
            vertex_rays: 0,
            adaptive: 0.0,
        };
        let key = SunKey {
            params: crate::bake::SunParams::default(),
            window_patterns: Vec::new(),
            steps: 5,
            day_crc: 7,
            texels: Some(texel_key),
        };
        let identity = identity_of(&key, 2);
        let part = |shard: u32, texels: Option<std::ops::Range<u32>>| {
            let path = PathBuf::from(format!("part-{shard}.prtp"));
            let texels = texels.map(|range| TexelSunPart {
                masks: vec![0b1_0101; range.len()],
                texels: range,
                texel_count: 5,
                words: 1,
                fraction_words: 0,
                points: 8,
                rays: 30,
                fractions: Vec::new(),
            });
            let part = SunPart {
                identity: identity.clone(),
                shard,
                items: shard..shard + 1,
                item_count: 2,
                points: shard as u64..shard as u64 + 1,
                point_count: 2,
                words: 1,
                rays: 10,
                bits: vec![0b1],
                frame: if shard == 0 { vec![1] } else { Vec::new() },
                texels,
            };
            (path, part)
        };
        let merged = merge_sun_parts(&[part(1, Some(2..5)), part(0, Some(0..2))]).unwrap().texels.unwrap();
        assert_eq!((merged.masks.len(), merged.points, merged.rays), (5, 16, 60));
        let refused = |parts: &[(PathBuf, SunPart)]| merge_sun_parts(parts).err().unwrap().to_string();
        let e = refused(&[part(0, Some(0..2)), part(1, Some(3..5))]);
        assert!(e.contains("part-1.prtp: holds texels 3..5, but the shards before it end at texel 2"), "{e}");
        let e = refused(&[part(0, Some(0..3)), part(1, Some(2..5))]);
        assert!(e.contains("part-1.prtp: holds texels 2..5, but the shards before it end at texel 3"), "{e}");
        let e = refused(&[part(0, Some(0..2)), part(1, Some(2..4))]);
        assert!(e.contains("part-1.prtp: is the last shard, but its texels end at 4 of 5"), "{e}");
        let e = refused(&[part(0, Some(0..2)), part(1, None)]);
        assert!(e.contains("part-1.prtp: holds no texel rows"), "{e}");
        let mut late = part(1, Some(2..5));
        late.1.texels.as_mut().unwrap().masks[1] = 0b10_0000;
        let e = refused(&[part(0, Some(0..2)), late]);
        assert!(e.contains("part-1.prtp: has texel bits set past the last of its 5 steps"), "{e}");
    }

    #[test]
    fn index_lists_are_short() {
        assert_eq!(list_indices([2, 5, 6, 7, 9]), "2, 5-7, 9");
        assert_eq!(list_indices([]), "none");
    }
}
