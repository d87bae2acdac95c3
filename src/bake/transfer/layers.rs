//! Every bounce of a bake over its plan, bounce 0 to B, into the result.

use std::time::Instant;

use super::items::*;
use super::normalise::*;
use super::plan::*;
use super::run::*;
use crate::bake::noise::{add_noise_in_quadrature, VertexDc};
use crate::bake::progress::Progress;
use crate::bake::side_share::{add_back_dc, front_shares};
use crate::bake::surfaces::Surfaces;
use crate::bake::twins::Twins;
use crate::bake::{BakeError, BakeParams, TransferResult};
use crate::mesh::Mesh;
use crate::trace::scene::{Batching, Scene};

/// What a partial re-bake keeps (adaptive refinement, `crate::refine`):
/// every bounce's full layer from an earlier bake of the same surface, and
/// the vertices whose values stay.
pub(crate) struct Kept<'a> {
    /// One widened layer per bounce 0..=B, `[vertex][channel][coeff]`.
    pub(crate) layers: &'a [Vec<f32>],
    /// The same of the back sides ([`TransferResult::back`]; empty without).
    pub(crate) back: &'a [Vec<f32>],
    pub(crate) vertices: &'a [bool],
}

pub(crate) fn bake_layers(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    params: &BakeParams,
    receivers: Option<&[bool]>,
    kept: Option<&Kept>,
) -> Result<TransferResult, BakeError> {
    bake_layers_with_texels(mesh, scene, surfaces, params, receivers, kept, None)
}

/// [`bake_layers`], and with `texels` the texel pass of each bounce
/// ([`super::texels`]), run after the vertices' pass. Bounces ≥ 1 of both
/// then read the previous bounce at a hit from the texels around it
/// ([`crate::bake::texel_lookup`]), and from the hit triangle's vertices
/// only where no texel holds it (back sides, triangles outside the atlas).
pub(crate) fn bake_layers_with_texels(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    params: &BakeParams,
    receivers: Option<&[bool]>,
    kept: Option<&Kept>,
    mut texels: Option<&mut super::texels::TexelState>,
) -> Result<TransferResult, BakeError> {
    let started = Instant::now();
    let mut plan = Plan::new(mesh, scene, surfaces, params, receivers)?;
    let (coeffs, channels) = (plan.coeffs, plan.channels);
    let adaptive = params.adaptive > 0.0 && matches!(plan.items, Items::Interior { .. });
    // With adaptive allocation bounce 0 adds up to `adaptive` × the base points.
    let planned_points = (plan.items.point_count() as f64 * (1.0 + if adaptive { f64::from(params.adaptive) } else { 0.0 })) as u64;
    let mut stats = plan.base_stats();
    let cache_bytes = planned_points * params.rays as u64 * 8;
    let use_cache = params.bounces > 0 && cache_bytes <= params.hit_cache_bytes;
    if !params.quiet {
        if params.bounces > 0 && !use_cache {
            eprintln!(
                "hit cache: {:.1} GiB needed, {:.1} GiB allowed (--hit-cache-mib): the {} later bounce(s) re-trace their rays (same bytes, slower)",
                cache_bytes as f64 / (1u64 << 30) as f64,
                params.hit_cache_bytes as f64 / (1u64 << 30) as f64,
                params.bounces
            );
        }
        let Batching { closest_hit, occlusion } = scene.batching();
        eprintln!("rays: closest hit {closest_hit}, occlusion {occlusion} (the faster on this scene's probe rays)");
    }
    let mut rejected = vec![false; plan.items.point_count() as usize];
    let mut hit_cache: Vec<u64> = Vec::new();
    let mut vertex_weight: Vec<f32> = Vec::new();
    let mut noise: Vec<f32> = Vec::new();
    // Per receiver, the DC that came through the back of its face (window mode).
    let mut back_dc: Vec<f32> = Vec::new();
    let mut source = SourceRows::empty();
    let mut layers: Vec<Vec<f32>> = Vec::new();
    let mut back_layers: Vec<Vec<f32>> = Vec::new();
    let mut fit: Option<super::fit::FitMatrices> = None;
    // The mesh's own vertices; the plan's rows past them are its back sides'.
    let vertex_count = mesh.vertex_count();
    let stride = channels * coeffs;
    let mut total = vec![0.0f32; vertex_count * stride];
    // The texel passes' seconds: their own phases, not the vertices'.
    let mut texel_seconds = 0.0f64;
    for bounce in 0..=params.bounces {
        let phase_start = Instant::now();
        let points = if bounce == 0 { planned_points } else { plan.items.point_count() };
        let progress = Progress::start(format!("bounce {}/{}", bounce, params.bounces), points * params.rays as u64, params.quiet);
        let sums = if bounce == 0 && adaptive {
            let sums = adaptive_first_bounce(&mut plan, &source, use_cache, &progress)?;
            rejected.resize(plan.items.point_count() as usize, false);
            stats.points_added = plan.items.point_count() - stats.points;
            stats.points = plan.items.point_count();
            sums
        } else {
            let cached = use_cache.then_some(HitRecords { records: &hit_cache, first_point: 0 });
            let pass = plan.pass(bounce, &source, &rejected, cached, use_cache);
            run_range(&pass, 0..plan.items.len(), None, &progress)
        };
        drop(progress);
        // The texels' pass of this bounce: it gathers what `source` still
        // holds, bounce − 1, as the vertices' pass did.
        let bounce_texel_seconds = match texels.as_deref_mut() {
            Some(texels) => texels.run_bounce(&plan, &source, bounce, if use_cache { cache_bytes } else { 0 }),
            None => 0.0,
        };
        texel_seconds += bounce_texel_seconds;
        let pass_channels = plan.pass_channels(bounce);
        if bounce == 0 {
            vertex_weight = sums.weights;
            if use_cache {
                hit_cache = sums.hits;
            }
        }
        if !sums.moments.is_empty() {
            let sigma = VertexDc::new(&vertex_weight, &sums.sums, pass_channels * coeffs, &sums.moments).standard_errors();
            add_noise_in_quadrature(&mut noise, &sigma);
            add_back_dc(&mut back_dc, &vertex_weight, &sums.moments);
        }
        for index in sums.rejected {
            rejected[index as usize] = true;
        }
        if bounce == 0 {
            stats.outside_light_share = crate::bake::outside_light_share(sums.glass_dc);
        }
        let mut layer = normalised_layer(&sums.sums, &vertex_weight, pass_channels, channels, coeffs);
        match kept {
            Some(kept) => {
                let previous = &kept.layers[bounce as usize];
                for v in (0..vertex_count).filter(|&v| kept.vertices[v]) {
                    layer[v * stride..(v + 1) * stride].copy_from_slice(&previous[v * stride..(v + 1) * stride]);
                }
                // A kept vertex keeps its back side too.
                let previous_back = kept.back.get(bounce as usize);
                for (k, &source) in plan.twins.source_vertex.iter().enumerate() {
                    if kept.vertices[source as usize] {
                        let row = &mut layer[(vertex_count + k) * stride..(vertex_count + k + 1) * stride];
                        match previous_back {
                            Some(back) => row.copy_from_slice(&back[source as usize * stride..(source as usize + 1) * stride]),
                            None => row.fill(0.0),
                        }
                    }
                }
                if bounce < params.bounces {
                    source_from_layer(&mut source, &layer, pass_channels, channels, coeffs);
                }
            }
            None if bounce < params.bounces => {
                normalise_source_into(&mut source, &sums.sums, &vertex_weight, pass_channels, coeffs);
                if params.mode == crate::bake::Mode::Window && !sums.moments.is_empty() && sums.item_sums.is_empty() {
                    // The next bounce reads the light of the side of a face its ray meets.
                    source.rows = split_sides(source.rows.as_slice(), &vertex_weight, &sums.moments, pass_channels, coeffs);
                    source.sides = true;
                }
                if !sums.item_sums.is_empty() {
                    // The next bounce reads each hit triangle's own fit (`--gather-fit`).
                    let fit = fit.get_or_insert_with(|| super::fit::fit_matrices(&plan.mesh, &plan.items, params, &rejected));
                    let stride = pass_channels * coeffs;
                    let mut rows = crate::bake::gather::RowBuffer::zeroed(3 * plan.mesh.triangle_count() * stride);
                    let vertex_rows = source.rows.as_slice();
                    source.corner_indices = super::fit::fill_corner_table(
                        rows.as_mut_slice(),
                        &plan.mesh,
                        &plan.items,
                        fit,
                        &sums.item_sums,
                        vertex_rows,
                        stride,
                    );
                    source.rows = rows;
                }
            }
            None => {}
        }
        if let Some(texels) = texels.as_deref_mut() {
            // The next bounce, of vertices and texels alike, reads hits on
            // atlas triangles from this bounce's texels.
            source.texels = texels.take_source();
        }
        add_layer(&mut total, &layer[..vertex_count * stride]);
        stats.rays_per_bounce.push(sums.rays);
        stats.rays_traced += sums.traced;
        stats.seconds_per_bounce.push(phase_start.elapsed().as_secs_f64() - bounce_texel_seconds);
        if params.store_bounces {
            if !plan.twins.is_empty() {
                back_layers.push(back_rows(&layer, &plan.twins, stride));
            }
            layer.truncate(vertex_count * stride);
            layers.push(layer);
        }
    }
    noise.truncate(vertex_count);
    back_dc.truncate(vertex_count);
    // The share of the light as baked: the denoiser smooths values, not sides.
    let front_share = front_shares(params.mode, &back_dc, &total, channels, coeffs);
    if params.denoise > 0.0 && kept.is_none() {
        crate::bake::denoise::denoise(mesh, &mut total, &mut layers, &mut noise, stride, params.denoise);
    }

    stats.points_rejected = rejected.iter().filter(|&&r| r).count() as u64;
    let re_baked = |v: usize| kept.is_none_or(|k| !k.vertices[v]);
    stats.vertices_without_samples =
        vertex_weight[..vertex_count].iter().enumerate().filter(|&(v, &w)| w <= 0.0 && re_baked(v)).count() as u64;
    stats.rays = stats.rays_per_bounce.iter().sum();
    stats.seconds = started.elapsed().as_secs_f64();
    stats.rays_gathered = if use_cache { stats.rays_per_bounce.iter().skip(1).sum() } else { 0 };
    // The vertices' rates, over the vertices' own time.
    let vertex_seconds = (stats.seconds - texel_seconds).max(1e-9);
    stats.rays_per_second = stats.rays_traced as f64 / vertex_seconds;
    stats.evaluations_per_second = stats.rays as f64 / vertex_seconds;
    Ok(TransferResult { order: params.order, channels, total, bounces: layers, noise, back: back_layers, front_share, stats })
}

/// The back sides' rows of a layer of the plan's mesh, one row per mesh
/// vertex (zero where a vertex has none).
pub(crate) fn back_rows(layer: &[f32], twins: &Twins, stride: usize) -> Vec<f32> {
    let mut back = vec![0.0f32; twins.vertices * stride];
    for (k, &source) in twins.source_vertex.iter().enumerate() {
        let from = (twins.vertices + k) * stride;
        back[source as usize * stride..][..stride].copy_from_slice(&layer[from..from + stride]);
    }
    back
}

/// Bounce 0 with adaptive allocation (`bake::adaptive`): the base points
/// first, whose moments place about `params.adaptive` × as many extra
/// points; `plan.items` then becomes the unified layout (each triangle one
/// item of `n + e` points, [`Items::unified`]) and [`adaptive_range`]
/// traces the extras and combines them with the base points item by item.
pub(crate) fn adaptive_first_bounce(
    plan: &mut Plan,
    source: &SourceRows,
    record_hits: bool,
    progress: &Progress,
) -> Result<RangeSums, BakeError> {
    let base_len = plan.items.len();
    let (base_tasks, base_hits, extra) = {
        let pass = plan.pass(0, source, &[], None, record_hits);
        let mut hits = HitSlots::new(&pass, 0..base_len);
        let tasks = trace_tasks(&pass, 0..base_len, &mut hits, progress);
        let mut base = RangeSums::empty(&pass);
        for (start, task) in &tasks {
            base.add_task(&pass, *start, task, None);
        }
        let pilot = VertexDc::new(&base.weights, &base.sums, plan.coeffs, &base.moments);
        (tasks, hits.records, plan.extra_counts(&pilot))
    };
    let base_items = plan.unify(&extra)?;
    Ok(adaptive_range(plan, &base_items, &extra, 0..base_len, base_tasks, base_hits, None, source, record_hits, progress))
}
