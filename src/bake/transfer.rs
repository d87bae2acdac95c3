//! Per-vertex SH transfer, bounce by bounce (DESIGN.md "Transfer"; seed 000 §4.1, eq. 6).
//!
//! Bounce 0:  t_i⁽⁰⁾(x) = 1/π ∫ y_i(ω) V(x,ω) c(n,ω) dω
//! Bounce b:  t_i⁽ᵇ⁾(x) = 1/π ∫ ρ(h) t_i⁽ᵇ⁻¹⁾(h) [h opaque] c(n,ω) dω
//!
//! Open mode: c = max(n·ω,0), V = 1 when the ray escapes. Window mode: c = |n·ω|,
//! V = τ when the first hit is a window, except on a side of the point outside
//! the enclosure ([`Sides`], docs/conventions.md). Directions are drawn with
//! pdf ∝ c, so each ray's weight is a constant: 1/N (hemisphere) or 2/N (sphere).
//!
//! Points: stratified samples inside each triangle (seed 000 §4.1.1) whose
//! results go to the triangle's vertices by barycentric weight times the area
//! each sample stands for ([`sample_weights`]): a vertex's value estimates the
//! hat-weighted mean of the transfer over its one-ring (docs/conventions.md),
//! whatever the sample density. Or the vertices
//! themselves (`Sampling::Vertex`, kept for comparison: it leaks shadows where
//! triangles overlap). Accumulation runs in fixed item order, so the bytes do
//! not depend on the thread count.

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use super::adaptive::{add_noise_in_quadrature, Moments, VertexDc};
use super::enclosure::Sides;
use super::gather::{decode_hit, encode_hit, Gather, RowBuffer, NO_HIT};
use super::progress::Progress;
use super::surfaces::Surfaces;
use super::twins::{Twins, NO_TWIN};
use super::window_light::WindowLights;
use super::{BakeError, BakeParams, BakeStats, Mode, Sampling, TransferResult};
use crate::mesh::Mesh;
use crate::sampling::{cosine_hemisphere, cosine_sphere, hash_seed, sample_2d, square_to_triangle};
use crate::sh;
use crate::trace::scene::{Batching, RayQuery, Scene};

/// What a vertex's transfer means, recorded in every bundle's META
/// (`conventions.vertex_transfer`): bundles before it (no such key) averaged
/// samples by barycentric weight alone, with one centroid sample on small
/// triangles, so their values depended on the sample density.
pub const VERTEX_ESTIMATOR: &str =
    "estimator 2: hat-weighted mean of the transfer over the vertex's one-ring, parts inside geometry excluded (docs/conventions.md)";

/// Stream tags that keep the random streams of different uses apart.
const TAG_POSITION: u32 = 0x5053_0001;
const TAG_DIRECTION: u32 = 0x5053_0002;

/// Items (triangles or vertices) per parallel task, and per sequential merge.
const ITEMS_PER_TASK: usize = 32;
const ITEMS_PER_MERGE: usize = 8192;

/// Rays of each point first traced with closest hit to decide whether the point lies inside geometry.
const INSIDE_PROBE_RAYS: u32 = 32;
/// Default largest hit cache kept in memory (bytes, [`BakeParams::hit_cache_bytes`]);
/// beyond it later bounces re-trace their rays.
pub const HIT_CACHE_BUDGET_BYTES: u64 = 6 << 30;

/// A hit cache budget for this machine: half the memory available now
/// (Linux `MemAvailable`), or [`HIT_CACHE_BUDGET_BYTES`] where that is
/// unknown. The bytes of a bake never depend on it, only its speed.
pub fn available_hit_cache_bytes() -> u64 {
    // The host's free memory, and a container's limit where one is set
    // (cgroup v2, then v1): /proc/meminfo shows the host's even inside one.
    let read = |path: &str| std::fs::read_to_string(path).ok();
    let available = read("/proc/meminfo").and_then(|info| {
        let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
        line.split_whitespace().nth(1)?.parse::<u64>().ok().map(|kib| kib.saturating_mul(1024))
    });
    let container = ["/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"]
        .iter()
        .find_map(|path| read(path)?.trim().parse::<u64>().ok());
    match (available, container) {
        (None, None) => HIT_CACHE_BUDGET_BYTES,
        (a, c) => a.unwrap_or(u64::MAX).min(c.unwrap_or(u64::MAX)) / 2,
    }
}

/// A task's reusable buffers for one point's rays.
#[derive(Default)]
struct Scratch {
    /// SH basis of one direction.
    basis: Vec<f32>,
    /// The rays of the batch being traced, and their answers.
    queries: Vec<RayQuery>,
    hits: Vec<Option<crate::trace::Hit>>,
    occluded: Vec<bool>,
    /// Per window-light query: the window triangle aimed at and the light pdf of its direction.
    targets: Vec<(u32, f64)>,
    /// Window mode, bounce 0: the light through glass of each side of the
    /// point (front, back of its face), kept apart until [`Sides`] decides.
    side_light: [Vec<f32>; 2],
}

/// One point rays leave from.
#[derive(Clone, Copy)]
struct Point {
    position: Vec3,
    /// Shading normal: the cosine is taken against it.
    normal: Vec3,
    /// Geometric normal: origins are pushed along it.
    face_normal: Vec3,
    /// Seed of this point's direction stream.
    seed: u32,
}

/// The work items of a bake and how their points map to vertices. Their
/// order is the order every sum runs in, whole bake or shards.
pub(crate) enum Items {
    /// Triangles with `counts[k]` samples each; `first_sample[k]` is the
    /// global index of the first. An item holds the triangle's samples
    /// `first_index[k]..first_index[k] + counts[k]` (empty: from 0) of
    /// `weight_count[k]` in all (empty: `counts[k]`), which sets each
    /// sample's weight: a triangle can be split over two items when
    /// adaptive allocation (`bake::adaptive`) adds samples to it.
    Interior {
        triangles: Vec<u32>,
        counts: Vec<u32>,
        first_sample: Vec<u32>,
        first_index: Vec<u32>,
        weight_count: Vec<u32>,
    },
    Vertex {
        vertices: Vec<u32>,
    },
}

impl Items {
    /// Adaptive allocation's layout: the interior `base` items with `extra[k]`
    /// more samples each, one item of `n + e` points per triangle (samples
    /// 0..n + e of its Sobol sequence, each weighing area / (n + e)), point
    /// indices in item order.
    pub(crate) fn unified(base: &Items, extra: &[u32]) -> Items {
        let Items::Interior { triangles, counts, .. } = base else { unreachable!("adaptive allocation needs interior sampling") };
        let counts: Vec<u32> = counts.iter().zip(extra).map(|(&n, &e)| n + e).collect();
        let mut first_sample = Vec::with_capacity(counts.len());
        let mut next = 0u32;
        for &c in &counts {
            first_sample.push(next);
            // Saturates past u32: `check_point_count` refuses such a bake.
            next = next.saturating_add(c);
        }
        Items::Interior { triangles: triangles.clone(), counts, first_sample, first_index: Vec::new(), weight_count: Vec::new() }
    }

    /// The extra points of the `base` items in `range` as items of their own,
    /// one per item with `extra[k] > 0`: samples `n..n + e` of `n + e`, at
    /// their places in the `unified` layout.
    pub(crate) fn extras(base: &Items, extra: &[u32], unified: &Items, range: std::ops::Range<usize>) -> Items {
        let (Items::Interior { triangles, counts, .. }, Items::Interior { first_sample: unified_first, .. }) = (base, unified) else {
            unreachable!("adaptive allocation needs interior sampling")
        };
        let with_extra: Vec<usize> = range.filter(|&k| extra[k] > 0).collect();
        Items::Interior {
            triangles: with_extra.iter().map(|&k| triangles[k]).collect(),
            counts: with_extra.iter().map(|&k| extra[k]).collect(),
            first_sample: with_extra.iter().map(|&k| unified_first[k] + counts[k]).collect(),
            first_index: with_extra.iter().map(|&k| counts[k]).collect(),
            weight_count: with_extra.iter().map(|&k| counts[k] + extra[k]).collect(),
        }
    }

    pub(crate) fn len(&self) -> usize {
        match self {
            Items::Interior { triangles, .. } => triangles.len(),
            Items::Vertex { vertices } => vertices.len(),
        }
    }
    fn corners(&self) -> usize {
        match self {
            Items::Interior { .. } => 3,
            Items::Vertex { .. } => 1,
        }
    }
    /// Global index of the first point of `item` (`len()`: the point count).
    pub(crate) fn first_point(&self, item: usize) -> usize {
        match self {
            Items::Interior { first_sample, .. } => match first_sample.get(item) {
                Some(&first) => first as usize,
                None => self.point_count() as usize,
            },
            Items::Vertex { .. } => item,
        }
    }
    pub(crate) fn point_count(&self) -> u64 {
        match self {
            Items::Interior { counts, .. } => counts.iter().map(|&c| c as u64).sum(),
            Items::Vertex { vertices } => vertices.len() as u64,
        }
    }
    /// Sample points of each item, in item order (what a shard's share is measured in).
    pub(crate) fn points_per_item(&self) -> Vec<u32> {
        match self {
            Items::Interior { counts, .. } => counts.clone(),
            Items::Vertex { vertices } => vec![1; vertices.len()],
        }
    }
    /// The vertices item `item`'s corners add to (a vertex item: itself, thrice).
    fn corner_vertices(&self, mesh: &Mesh, item: usize) -> [u32; 3] {
        match self {
            Items::Interior { triangles, .. } => mesh.triangle(triangles[item] as usize),
            Items::Vertex { vertices } => [vertices[item]; 3],
        }
    }
    /// The first item that adds to each vertex (`u32::MAX`: none): a range
    /// of items holds a vertex's first sums exactly when it holds this item.
    pub(crate) fn first_items(&self, mesh: &Mesh) -> Vec<u32> {
        let mut first = vec![u32::MAX; mesh.vertex_count()];
        for item in 0..self.len() {
            for &v in &self.corner_vertices(mesh, item)[..self.corners()] {
                let slot = &mut first[v as usize];
                *slot = (*slot).min(item as u32);
            }
        }
        first
    }
}

/// Shared read-only state of a pass.
pub(crate) struct Pass<'a> {
    bounce: u32,
    /// The plan's mesh (twins included); rays are traced in `scene`, built on the mesh's own triangles.
    mesh: &'a Mesh,
    scene: &'a Scene,
    surfaces: &'a Surfaces,
    twins: &'a Twins,
    params: &'a BakeParams,
    items: &'a Items,
    coeffs: usize,
    /// Channels of this pass's output (1 for bounce 0, whose transfer is colourless).
    channels: usize,
    /// What bounces ≥ 1 gather from: the previous bounce at hits.
    gather: Option<Gather<'a>>,
    rejected: &'a [bool],
    reject_distance: f32,
    /// Bounce 0 records every ray's hit here (when bounces follow and it fits
    /// the budget); bounces ≥ 1 then gather from it instead of re-tracing:
    /// the rays are the same, only the values at their ends change.
    hit_cache: Option<HitRecords<'a>>,
    record_hits: bool,
    /// Interior sampling: keep each item corner's [`Moments`] of this
    /// bounce's point DC (the noise estimate adds every bounce's).
    track_noise: bool,
    /// Window triangles to sample directly for bounce 0 (window mode).
    windows: Option<&'a WindowLights>,
}

/// What one task returns: per item and corner, weighted coefficient sums and weights.
pub(crate) struct TaskOutput {
    sums: Vec<f32>,
    weights: Vec<f32>,
    /// Global indices of the points found inside geometry.
    rejected: Vec<u32>,
    /// Rays evaluated (traced or gathered from the cache).
    rays: u64,
    /// Rays actually traced through the BVH.
    traced: u64,
    /// Hit records of this task's points, in point order (bounce 0 with caching).
    hits: Vec<u64>,
    /// Per item and corner, the moments of the points' DC (when the pass
    /// tracks noise, else empty).
    moments: Vec<Moments>,
}

/// Bounce 0's hit records of the points from `first_point` on (a whole
/// bake's, or one shard's).
#[derive(Clone, Copy)]
pub(crate) struct HitRecords<'a> {
    pub(crate) records: &'a [u64],
    pub(crate) first_point: u64,
}

/// The previous bounce per vertex in line-aligned rows, what the next
/// bounce gathers from. After bounce 0 it is colourless (one row serves
/// every channel, a third of the bytes of its widened copy).
pub(crate) struct SourceRows {
    pub(crate) rows: RowBuffer,
    /// 1 after bounce 0, else the bake's channels.
    pub(crate) channels: usize,
}

impl SourceRows {
    pub(crate) fn empty() -> SourceRows {
        SourceRows { rows: RowBuffer::zeroed(0), channels: 1 }
    }
}

/// What every pass of a bake shares: the items, sizes, the albedo bounces
/// reflect with and the window lights. A whole bake and each of its shards
/// (`bake::shards`) build it the same way, so they see the same items.
pub(crate) struct Plan<'a> {
    /// The mesh the bake's receivers lie on: the scene's mesh, with the
    /// twins of its back sides appended when it has any (`bake::twins`).
    pub(crate) mesh: std::borrow::Cow<'a, Mesh>,
    scene: &'a Scene,
    surfaces: std::borrow::Cow<'a, Surfaces>,
    /// Which triangles have a back side of their own, and where.
    pub(crate) twins: Twins,
    pub(crate) params: &'a BakeParams,
    pub(crate) items: Items,
    pub(crate) coeffs: usize,
    /// Channels of the result (bounce 0 is traced colourless, then widened).
    pub(crate) channels: usize,
    /// Albedo at hit points, per channel count.
    bounce_albedo: Vec<[f32; 3]>,
    windows: Option<WindowLights>,
}

impl<'a> Plan<'a> {
    /// Checks the parameters and lists the items (`receivers`: see [`bake_transfer_receivers`]).
    pub(crate) fn new(
        mesh: &'a Mesh,
        scene: &'a Scene,
        surfaces: &'a Surfaces,
        params: &'a BakeParams,
        receivers: Option<&[bool]>,
    ) -> Result<Plan<'a>, BakeError> {
        params.check()?;
        if receivers.is_some_and(|r| r.len() != mesh.triangle_count()) {
            return Err(BakeError::Params("receiver flags do not match the triangle count".into()));
        }
        let sampled = sampled_triangles(mesh, surfaces)?;
        let (items, aug) = build_items_with_twins(mesh, surfaces, sampled, params, receivers);
        check_point_count(items.point_count())?;
        let (mesh, surfaces, twins) = match aug {
            Some((m, s, t)) => (std::borrow::Cow::Owned(m), std::borrow::Cow::Owned(s), t),
            None => (std::borrow::Cow::Borrowed(mesh), std::borrow::Cow::Borrowed(surfaces), Twins::none(mesh)),
        };
        let channels = params.channel_count(&surfaces);
        let bounce_albedo: Vec<[f32; 3]> =
            if channels == 1 { surfaces.albedo.iter().map(|a| [(a[0] + a[1] + a[2]) / 3.0; 3]).collect() } else { surfaces.albedo.clone() };
        let windows = if params.mode == Mode::Window && params.window_sampling { WindowLights::new(&mesh, &surfaces) } else { None };
        Ok(Plan { mesh, scene, surfaces, twins, params, items, coeffs: sh::coeff_count(params.order), channels, bounce_albedo, windows })
    }

    /// The counts every bake of this plan reports, before any ray.
    pub(crate) fn base_stats(&self) -> BakeStats {
        BakeStats {
            triangles: self.twins.triangles as u64,
            vertices: self.twins.vertices as u64,
            back_sides: self.twins.source_triangle.len() as u64,
            window_triangles: self.surfaces.window_triangle_count() as u64,
            points: self.items.point_count(),
            batching: self.scene.batching(),
            ..BakeStats::default()
        }
    }

    /// Channels bounce `bounce` is traced in: bounce 0's transfer is colourless.
    pub(crate) fn pass_channels(&self, bounce: u32) -> usize {
        if bounce == 0 {
            1
        } else {
            self.channels
        }
    }

    /// A pass of `bounce`: bounces ≥ 1 gather from `source` (at `cached`
    /// hits, or at re-traced ones); bounce 0 records its hits when `record_hits`.
    pub(crate) fn pass<'p>(
        &'p self,
        bounce: u32,
        source: &'p SourceRows,
        rejected: &'p [bool],
        cached: Option<HitRecords<'p>>,
        record_hits: bool,
    ) -> Pass<'p> {
        let gather = (bounce > 0).then(|| {
            Gather::new(&self.mesh.indices, &self.bounce_albedo, source.rows.as_slice(), self.coeffs, source.channels, self.channels)
        });
        Pass {
            bounce,
            mesh: &self.mesh,
            scene: self.scene,
            surfaces: &self.surfaces,
            twins: &self.twins,
            params: self.params,
            items: &self.items,
            coeffs: self.coeffs,
            channels: self.pass_channels(bounce),
            gather,
            rejected,
            reject_distance: self.params.inside_distance * self.scene.diagonal,
            hit_cache: if bounce > 0 { cached } else { None },
            record_hits: bounce == 0 && record_hits,
            track_noise: self.items.corners() == 3,
            windows: self.windows.as_ref(),
        }
    }
}

/// Contributions of a range of items to vertices whose first item lies
/// before the range, in item and corner order: added after the earlier
/// ranges' sums, they keep each vertex's sum order that of a whole bake.
#[derive(Default)]
pub(crate) struct LateSums {
    pub(crate) vertices: Vec<u32>,
    /// One row per entry of `vertices`.
    pub(crate) rows: Vec<f32>,
    /// One weight per entry (bounce 0), else empty.
    pub(crate) weights: Vec<f32>,
    /// One [`Moments`] per entry when the pass tracks noise, else empty.
    pub(crate) moments: Vec<Moments>,
}

/// One bounce's sums over a range of items (a whole bake is one range).
pub(crate) struct RangeSums {
    /// `[vertex][channel][coeff]` for every vertex; filled for the vertices
    /// whose first item is in the range (all of them in a whole bake).
    pub(crate) sums: Vec<f32>,
    /// Bounce 0: each vertex's summed sample weight ([`sample_weights`]), as `sums`.
    pub(crate) weights: Vec<f32>,
    /// Bounce 0 (interior sampling): each vertex's [`Moments`] of its
    /// points' DC, as `weights` but for the vertices `late` holds.
    pub(crate) moments: Vec<Moments>,
    pub(crate) late: LateSums,
    /// Global indices of the points found inside geometry (bounce 0).
    pub(crate) rejected: Vec<u32>,
    pub(crate) rays: u64,
    pub(crate) traced: u64,
    /// Bounce 0's hit records of the range's points, in point order, when recorded.
    pub(crate) hits: Vec<u64>,
}

/// Adds `row` to `target`, element by element: the one place per-item sums
/// meet, so whole bakes and merged shards add in the same order.
#[inline]
pub(crate) fn add_row(target: &mut [f32], row: &[f32]) {
    target.iter_mut().zip(row).for_each(|(t, s)| *t += s);
}

/// (a) and (b): evaluates every point of the items in `range` for `pass`'s
/// bounce, in tasks of [`ITEMS_PER_TASK`] items, and adds each item's corner
/// sums to its vertices in item order. `first_items` (see
/// [`Items::first_items`]) is given for a range that is not the whole bake:
/// contributions to vertices first touched before it go to
/// [`RangeSums::late`] instead.
pub(crate) fn run_range(pass: &Pass, range: std::ops::Range<usize>, first_items: Option<&[u32]>, progress: &Progress) -> RangeSums {
    let mut out = RangeSums::empty(pass);
    let mut hits = HitSlots::new(pass, range.clone());
    for merge_start in range.clone().step_by(ITEMS_PER_MERGE) {
        let merge_end = (merge_start + ITEMS_PER_MERGE).min(range.end);
        let outputs = trace_tasks(pass, merge_start..merge_end, &mut hits, progress);
        // In item order: the only place results meet, so the sum order is fixed.
        for (task_start, task) in outputs {
            out.add_task(pass, task_start, &task, first_items.map(|f| (f, range.start)));
        }
    }
    out.hits = hits.records;
    out
}

/// Bounce 0's hit records of a range of items (one per point and ray, when
/// the pass records them), and the part no task has filled yet.
pub(crate) struct HitSlots {
    pub(crate) records: Vec<u64>,
    /// Index in `records` of the first unfilled slot.
    filled: usize,
}

impl HitSlots {
    pub(crate) fn new(pass: &Pass, range: std::ops::Range<usize>) -> HitSlots {
        let points = pass.items.first_point(range.end) - pass.items.first_point(range.start);
        HitSlots { records: vec![0; pass.record_count(points)], filled: 0 }
    }
}

/// Evaluates every point of the items in `range` for `pass`'s bounce, in
/// parallel tasks of [`ITEMS_PER_TASK`] items; returns each task's first item
/// and output, in item order. Each task copies its points' hit records to
/// their place in `hits`, so the 8 bytes a ray of fresh pages fault in on
/// every thread, not in the merge.
pub(crate) fn trace_tasks(
    pass: &Pass,
    range: std::ops::Range<usize>,
    hits: &mut HitSlots,
    progress: &Progress,
) -> Vec<(usize, TaskOutput)> {
    let mut unfilled = &mut hits.records[hits.filled..];
    let tasks: Vec<(usize, &mut [u64])> = range
        .clone()
        .step_by(ITEMS_PER_TASK)
        .map(|task_start| {
            let task_end = (task_start + ITEMS_PER_TASK).min(range.end);
            let points = pass.items.first_point(task_end) - pass.items.first_point(task_start);
            let (task_hits, rest) = std::mem::take(&mut unfilled).split_at_mut(pass.record_count(points));
            unfilled = rest;
            hits.filled += task_hits.len();
            (task_start, task_hits)
        })
        .collect();
    tasks
        .into_par_iter()
        .map(|(task_start, task_hits)| {
            let mut out = pass.run_task(task_start, (task_start + ITEMS_PER_TASK).min(range.end));
            task_hits.copy_from_slice(&out.hits);
            // Freed now, not after the merge: a merge's records would otherwise be held twice.
            out.hits = Vec::new();
            progress.add(out.rays);
            (task_start, out)
        })
        .collect()
}

impl RangeSums {
    fn empty(pass: &Pass) -> RangeSums {
        let vertex_count = pass.mesh.vertex_count();
        RangeSums {
            sums: vec![0.0; vertex_count * pass.channels * pass.coeffs],
            weights: vec![0.0; vertex_count],
            moments: if pass.track_noise { vec![Moments::default(); vertex_count] } else { Vec::new() },
            late: LateSums::default(),
            rejected: Vec::new(),
            rays: 0,
            traced: 0,
            hits: Vec::new(),
        }
    }

    /// Adds one task's item sums, in item and corner order. `late_before`:
    /// vertices whose first item is before this item index go to `late`.
    fn add_task(&mut self, pass: &Pass, task_start: usize, task: &TaskOutput, late_before: Option<(&[u32], usize)>) {
        self.rays += task.rays;
        self.traced += task.traced;
        self.rejected.extend_from_slice(&task.rejected);
        let corners = pass.items.corners();
        let stride = pass.channels * pass.coeffs;
        let with_weights = pass.bounce == 0;
        for (local, corner_sums) in task.sums.chunks_exact(corners * stride).enumerate() {
            let vertices = pass.items.corner_vertices(pass.mesh, task_start + local);
            for (corner, sums) in corner_sums.chunks_exact(stride).enumerate() {
                let v = vertices[corner] as usize;
                let weight = task.weights[local * corners + corner];
                if late_before.is_some_and(|(first, start)| (first[v] as usize) < start) {
                    self.late.vertices.push(v as u32);
                    self.late.rows.extend_from_slice(sums);
                    if with_weights {
                        self.late.weights.push(weight);
                    }
                    if let (false, Some(moments)) = (self.moments.is_empty(), task.moments.get(local * corners + corner)) {
                        self.late.moments.push(*moments);
                    }
                    continue;
                }
                if with_weights {
                    self.weights[v] += weight;
                }
                if let (Some(total), Some(moments)) = (self.moments.get_mut(v), task.moments.get(local * corners + corner)) {
                    total.merge(moments);
                }
                add_row(&mut self.sums[v * stride..(v + 1) * stride], sums);
            }
        }
    }
}

/// (c) A bounce's layer: each vertex's sums over its weight, bounce 0
/// widened to all `channels`; zero where a vertex has no weight.
pub(crate) fn normalised_layer(sums: &[f32], weights: &[f32], pass_channels: usize, channels: usize, coeffs: usize) -> Vec<f32> {
    let stride = pass_channels * coeffs;
    let mut layer = vec![0.0f32; weights.len() * channels * coeffs];
    layer.par_chunks_mut(channels * coeffs).zip(sums.par_chunks(stride).zip(weights.par_iter())).for_each(|(dst, (src, &w))| {
        if w > 0.0 {
            for (c, dst) in dst.chunks_exact_mut(coeffs).enumerate() {
                let source_channel = if pass_channels == 1 { 0 } else { c };
                dst.iter_mut().zip(&src[source_channel * coeffs..][..coeffs]).for_each(|(d, s)| *d = s / w);
            }
        }
    });
    layer
}

/// (c) The next bounce's gather rows: the same quotients as
/// [`normalised_layer`], unwidened, into `source` (reusing its buffer).
pub(crate) fn normalise_source_into(source: &mut SourceRows, sums: &[f32], weights: &[f32], pass_channels: usize, coeffs: usize) {
    let stride = pass_channels * coeffs;
    if source.rows.len() != weights.len() * stride {
        source.rows = RowBuffer::zeroed(weights.len() * stride);
    }
    source.channels = pass_channels;
    normalise_rows(source.rows.as_mut_slice(), sums, weights, stride);
}

/// The next bounce's gather rows from a widened layer (its first
/// `pass_channels` channels: bounce 0's are copies of one).
fn source_from_layer(source: &mut SourceRows, layer: &[f32], pass_channels: usize, channels: usize, coeffs: usize) {
    let stride = pass_channels * coeffs;
    let vertices = layer.len() / (channels * coeffs).max(1);
    if source.rows.len() != vertices * stride {
        source.rows = RowBuffer::zeroed(vertices * stride);
    }
    source.channels = pass_channels;
    source
        .rows
        .as_mut_slice()
        .par_chunks_mut(stride)
        .zip(layer.par_chunks(channels * coeffs))
        .for_each(|(dst, src)| dst.copy_from_slice(&src[..stride]));
}

/// `dst` = each vertex's row of `sums` over its weight, zero where it has none.
pub(crate) fn normalise_rows(dst: &mut [f32], sums: &[f32], weights: &[f32], stride: usize) {
    dst.par_chunks_mut(stride).zip(sums.par_chunks(stride).zip(weights.par_iter())).for_each(|(dst, (src, &w))| {
        dst.iter_mut().zip(src).for_each(|(d, s)| *d = if w > 0.0 { s / w } else { 0.0 });
    });
}

/// Adds a bounce's layer to the running total (bounce order, as a whole bake).
pub(crate) fn add_layer(total: &mut [f32], layer: &[f32]) {
    total.iter_mut().zip(layer).for_each(|(t, l)| *t += l);
}

/// Bakes transfer for every vertex. Runs on the current rayon pool.
pub fn bake_transfer(mesh: &Mesh, scene: &Scene, surfaces: &Surfaces, params: &BakeParams) -> Result<TransferResult, BakeError> {
    bake_transfer_receivers(mesh, scene, surfaces, params, None)
}

/// [`bake_transfer`] with rays shot only from the triangles flagged in
/// `receivers` (one flag per triangle; `None` = all), while every triangle
/// still occludes: the view-box culling of seed 001 §5 ("precomputing shadows
/// we use the whole dataset"). A kept triangle gets exactly the samples and
/// rays it gets in a full bake (the sample density is that of the full mesh);
/// vertices touching no receiver get zero. Bounces ≥ 1 gather from hit
/// triangles' previous bounce, which is zero on non-receivers: pass `None`
/// when bounces follow, or accept that light.
///
/// Precondition: `receivers`, if given, has one entry per triangle.
///
/// Errors: bad parameters, or a mesh on which no triangle receives light
/// (each a window or of zero area: [`NothingToBake`]), whose bake would
/// store only zeros.
pub fn bake_transfer_receivers(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    params: &BakeParams,
    receivers: Option<&[bool]>,
) -> Result<TransferResult, BakeError> {
    bake_layers(mesh, scene, surfaces, params, receivers, None)
}

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

/// Re-bakes the vertices not in `kept.vertices` from the triangles flagged
/// in `receivers` (which must hold every triangle around those vertices),
/// and keeps the others' values. Bounces ≥ 1 gather from the merged
/// previous bounce, so a re-baked vertex sees its neighbours' light whether
/// they were re-baked or kept. Returns every bounce's layer (as with
/// `store_bounces`) and the total.
pub(crate) fn bake_transfer_update(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    params: &BakeParams,
    receivers: &[bool],
    kept: &Kept,
) -> Result<TransferResult, BakeError> {
    let params = BakeParams { store_bounces: true, ..*params };
    bake_layers(mesh, scene, surfaces, &params, Some(receivers), Some(kept))
}

fn bake_layers(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    params: &BakeParams,
    receivers: Option<&[bool]>,
    kept: Option<&Kept>,
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
    let mut source = SourceRows::empty();
    let mut layers: Vec<Vec<f32>> = Vec::new();
    let mut back_layers: Vec<Vec<f32>> = Vec::new();
    // The mesh's own vertices; the plan's rows past them are its back sides'.
    let vertex_count = mesh.vertex_count();
    let stride = channels * coeffs;
    let mut total = vec![0.0f32; vertex_count * stride];
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
        }
        for index in sums.rejected {
            rejected[index as usize] = true;
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
            None if bounce < params.bounces => normalise_source_into(&mut source, &sums.sums, &vertex_weight, pass_channels, coeffs),
            None => {}
        }
        add_layer(&mut total, &layer[..vertex_count * stride]);
        stats.rays_per_bounce.push(sums.rays);
        stats.rays_traced += sums.traced;
        stats.seconds_per_bounce.push(phase_start.elapsed().as_secs_f64());
        if params.store_bounces {
            if !plan.twins.is_empty() {
                back_layers.push(back_rows(&layer, &plan.twins, stride));
            }
            layer.truncate(vertex_count * stride);
            layers.push(layer);
        }
    }
    noise.truncate(vertex_count);

    stats.points_rejected = rejected.iter().filter(|&&r| r).count() as u64;
    let re_baked = |v: usize| kept.is_none_or(|k| !k.vertices[v]);
    stats.vertices_without_samples =
        vertex_weight[..vertex_count].iter().enumerate().filter(|&(v, &w)| w <= 0.0 && re_baked(v)).count() as u64;
    stats.rays = stats.rays_per_bounce.iter().sum();
    stats.seconds = started.elapsed().as_secs_f64();
    stats.rays_gathered = if use_cache { stats.rays_per_bounce.iter().skip(1).sum() } else { 0 };
    stats.rays_per_second = stats.rays_traced as f64 / stats.seconds.max(1e-9);
    stats.evaluations_per_second = stats.rays as f64 / stats.seconds.max(1e-9);
    Ok(TransferResult { order: params.order, channels, total, bounces: layers, noise, back: back_layers, stats })
}

/// The back sides' rows of a layer of the plan's mesh, one row per mesh
/// vertex (zero where a vertex has none).
fn back_rows(layer: &[f32], twins: &Twins, stride: usize) -> Vec<f32> {
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
fn adaptive_first_bounce(plan: &mut Plan, source: &SourceRows, record_hits: bool, progress: &Progress) -> Result<RangeSums, BakeError> {
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

impl Plan<'_> {
    /// The extra points per base item that the pilot `pilot` (bounce 0's
    /// base points, every vertex) asks for: about `params.adaptive` × the
    /// base points, in whole rotation triples (`bake::adaptive`).
    pub(crate) fn extra_counts(&self, pilot: &VertexDc) -> Vec<u32> {
        let budget = (self.items.point_count() as f64 * f64::from(self.params.adaptive)) as u64;
        let max_per_triangle = match self.params.sampling {
            Sampling::Interior { max_per_triangle, .. } => max_per_triangle,
            Sampling::Vertex => 0,
        };
        super::adaptive::extra_counts(&self.mesh, &self.items, pilot, budget, max_per_triangle)
    }

    /// Makes the items the unified layout of `extra` and returns the base
    /// layout they replace.
    pub(crate) fn unify(&mut self, extra: &[u32]) -> Result<Items, BakeError> {
        let unified = Items::unified(&self.items, extra);
        check_point_count(unified.point_count())?;
        Ok(std::mem::replace(&mut self.items, unified))
    }
}

/// Bounce 0 of adaptive allocation over the items `range`, `plan.items`
/// being the unified layout: `base_tasks` are the range's base points
/// traced in the `base` layout (weights of `n` points each, hit records
/// `base_hits` in base point order); their sums, weights and moments are
/// scaled to `n + e` points, the extra points are traced (continuing each
/// triangle's Sobol sequence, weights of `n + e`), and each item's two
/// outputs meet before they are added to the vertices in item order
/// (`first_items`: as [`run_range`]). The hit records come back in unified
/// point order, the base ones moved within one buffer grown once. A whole
/// bake and a shard (which traces its base points again) run this alike,
/// so their sums meet in the same order.
#[allow(clippy::too_many_arguments)]
pub(crate) fn adaptive_range(
    plan: &Plan,
    base: &Items,
    extra: &[u32],
    range: std::ops::Range<usize>,
    mut base_tasks: Vec<(usize, TaskOutput)>,
    base_hits: Vec<u64>,
    first_items: Option<&[u32]>,
    source: &SourceRows,
    record_hits: bool,
    progress: &Progress,
) -> RangeSums {
    let Items::Interior { counts, first_sample: base_first, .. } = base else {
        unreachable!("adaptive allocation runs on interior samples")
    };
    let Items::Interior { first_sample: unified_first, .. } = &plan.items else { unreachable!("the unified layout is interior") };
    let pass = plan.pass(0, source, &[], None, record_hits);
    if range.is_empty() {
        // A shard with no items (more shards than the cost can split) adds nothing.
        return RangeSums::empty(&pass);
    }
    let rays = if pass.record_hits { plan.params.rays as usize } else { 0 };
    let stride = plan.coeffs;
    // Base records to their unified places, last item first: every block
    // moves toward the end, past no block not yet moved.
    let (base_start, unified_start) = (base_first[range.start] as usize, unified_first[range.start] as usize);
    let mut records = base_hits;
    records.resize((plan.items.first_point(range.end) - unified_start) * rays, 0);
    for k in range.clone().rev() {
        let from = (base_first[k] as usize - base_start) * rays;
        let to = (unified_first[k] as usize - unified_start) * rays;
        records.copy_within(from..from + counts[k] as usize * rays, to);
    }
    // The extra points, as items of their own (samples n..n + e), traced
    // into their unified slots.
    let extra_items = Items::extras(base, extra, &plan.items, range.clone());
    let extra_tasks = {
        let extra_pass = Pass { items: &extra_items, ..plan.pass(0, source, &[], None, record_hits) };
        trace_tasks_scattered(&extra_pass, &mut records, unified_start, progress)
    };
    // Per item of the range, its extra item's task and place in the task
    // (extra item j is the j-th item with e > 0; tasks hold ITEMS_PER_TASK).
    let mut extra_at: Vec<Option<(usize, usize)>> = vec![None; range.len()];
    for (j, k) in range.clone().filter(|&k| extra[k] > 0).enumerate() {
        extra_at[k - range.start] = Some((j / ITEMS_PER_TASK, j % ITEMS_PER_TASK));
    }
    let mut out = RangeSums::empty(&pass);
    for (start, task) in &mut base_tasks {
        let items = task.weights.len() / 3;
        // Base point indices to unified ones.
        for global in task.rejected.iter_mut() {
            let k = *start + base_first[*start..*start + items].partition_point(|&f| f <= *global) - 1;
            *global = *global - base_first[k] + unified_first[k];
        }
        for local in 0..items {
            let k = *start + local;
            let (n, e) = (counts[k], extra[k]);
            if e == 0 {
                continue;
            }
            let scale = n as f32 / (n + e) as f32;
            let sums = &mut task.sums[local * 3 * stride..(local + 1) * 3 * stride];
            sums.iter_mut().for_each(|s| *s *= scale);
            task.weights[local * 3..(local + 1) * 3].iter_mut().for_each(|w| *w *= scale);
            for m in task.moments[local * 3..(local + 1) * 3].iter_mut() {
                *m = m.scaled(f64::from(scale));
            }
            let Some((t, at)) = extra_at[k - range.start] else { unreachable!("an item with extra points has an extra item") };
            let added = &extra_tasks[t].1;
            add_row(sums, &added.sums[at * 3 * stride..(at + 1) * 3 * stride]);
            for corner in 0..3 {
                task.weights[local * 3 + corner] += added.weights[at * 3 + corner];
                task.moments[local * 3 + corner].merge(&added.moments[at * 3 + corner]);
            }
        }
        out.add_task(&pass, *start, task, first_items.map(|f| (f, range.start)));
    }
    for (_, task) in &extra_tasks {
        out.rays += task.rays;
        out.traced += task.traced;
        out.rejected.extend_from_slice(&task.rejected);
    }
    out.rejected.sort_unstable();
    out.hits = records;
    out
}

/// [`trace_tasks`] for items whose points are not contiguous in the
/// unified layout (the extra items of [`adaptive_range`]): each item's hit
/// records go to its own slot of `records` (which starts at unified point
/// `records_start`).
fn trace_tasks_scattered(pass: &Pass, records: &mut [u64], records_start: usize, progress: &Progress) -> Vec<(usize, TaskOutput)> {
    let rays = pass.record_count(1);
    let Items::Interior { counts, first_sample, .. } = pass.items else { unreachable!("extra items are interior") };
    // Every item's slot, in item order (slots ascend, so one walk splits them off).
    let mut rest = records;
    let mut consumed = 0usize;
    let mut slots: Vec<&mut [u64]> = Vec::with_capacity(counts.len());
    for (&first, &count) in first_sample.iter().zip(counts) {
        let at = (first as usize - records_start) * rays;
        let (_, tail) = std::mem::take(&mut rest).split_at_mut(at - consumed);
        let (slot, tail) = tail.split_at_mut(count as usize * rays);
        slots.push(slot);
        rest = tail;
        consumed = at + count as usize * rays;
    }
    let mut tasks: Vec<(usize, Vec<&mut [u64]>)> = Vec::new();
    for (item, slot) in slots.into_iter().enumerate() {
        if item % ITEMS_PER_TASK == 0 {
            tasks.push((item, Vec::new()));
        }
        if let Some(task) = tasks.last_mut() {
            task.1.push(slot);
        }
    }
    let len = counts.len();
    tasks
        .into_par_iter()
        .map(|(task_start, task_slots)| {
            let mut out = pass.run_task(task_start, (task_start + ITEMS_PER_TASK).min(len));
            let mut hits = out.hits.as_slice();
            for slot in task_slots {
                let (mine, others) = hits.split_at(slot.len());
                slot.copy_from_slice(mine);
                hits = others;
            }
            out.hits = Vec::new();
            progress.add(out.rays);
            (task_start, out)
        })
        .collect()
}

/// Sample points of the base layout of a bake of `mesh` with `params`
/// (before adaptive allocation adds any): a sharded bake's merge reports
/// `BakeStats::points_added` against it, as a whole bake does.
pub fn base_point_count(mesh: &Mesh, surfaces: &Surfaces, params: &BakeParams) -> Result<u64, BakeError> {
    Ok(build_items_with_twins(mesh, surfaces, sampled_triangles(mesh, surfaces)?, params, None).0.point_count())
}

/// The items of a bake: [`build_items`] on the mesh, and in open mode
/// with bounces (two-sided, interior sampling) the twins of the sampled
/// triangles whose back can be lit, appended as items of their own with
/// their triangle's sample count (the density is the mesh's), on the
/// augmented mesh `bake::twins` makes. `None` when there are no twins.
fn build_items_with_twins(
    mesh: &Mesh,
    surfaces: &Surfaces,
    sampled: Vec<u32>,
    params: &BakeParams,
    receivers: Option<&[bool]>,
) -> (Items, Option<(Mesh, Surfaces, Twins)>) {
    let wants_twins = params.two_sided && params.mode == Mode::Open && params.bounces > 0 && params.sampling != Sampling::Vertex;
    let twinned = if wants_twins { super::twins::twinned_triangles(mesh, surfaces, &sampled) } else { Vec::new() };
    let items = build_items(mesh, sampled, params, receivers);
    if !twinned.iter().any(|&t| t) {
        return (items, None);
    }
    let (aug, aug_surfaces, twins) = super::twins::augment(mesh, surfaces, &twinned);
    let Items::Interior { mut triangles, mut counts, mut first_sample, .. } = items else { unreachable!("twins need interior sampling") };
    let count_of: std::collections::HashMap<u32, u32> = triangles.iter().copied().zip(counts.iter().copied()).collect();
    let mut next = counts.iter().fold(0u32, |a, &c| a.saturating_add(c));
    for (k, &source) in twins.source_triangle.iter().enumerate() {
        // A twin receives where its triangle does (view-box culling, partial re-bakes).
        let Some(&count) = count_of.get(&source) else { continue };
        triangles.push((twins.triangles + k) as u32);
        counts.push(count);
        first_sample.push(next);
        next = next.saturating_add(count);
    }
    (
        Items::Interior { triangles, counts, first_sample, first_index: Vec::new(), weight_count: Vec::new() },
        Some((aug, aug_surfaces, twins)),
    )
}

/// Lists the work items: the `sampled` triangles (interior sampling), or
/// their vertices (vertex sampling).
fn build_items(mesh: &Mesh, sampled: Vec<u32>, params: &BakeParams, receivers: Option<&[bool]>) -> Items {
    let receives = |t: u32| receivers.is_none_or(|r| r[t as usize]);
    match params.sampling {
        Sampling::Vertex => {
            let mut used = vec![false; mesh.vertex_count()];
            for &t in sampled.iter().filter(|&&t| receives(t)) {
                for v in mesh.triangle(t as usize) {
                    used[v as usize] = true;
                }
            }
            Items::Vertex { vertices: (0..mesh.vertex_count() as u32).filter(|&v| used[v as usize]).collect() }
        }
        Sampling::Interior { samples_per_vertex, max_per_triangle } => {
            // Density comes from the whole scene, so a culled bake samples its
            // kept triangles exactly as a full bake would.
            let layout = interior_layout(mesh, sampled, samples_per_vertex, max_per_triangle);
            let (triangles, counts): (Vec<u32>, Vec<u32>) =
                layout.triangles.iter().zip(&layout.counts).filter(|(&t, _)| receives(t)).map(|(&t, &c)| (t, c)).unzip();
            let mut first_sample = Vec::with_capacity(counts.len());
            let mut next = 0u32;
            for &c in &counts {
                first_sample.push(next);
                // Saturates past u32: `check_point_count` refuses such a bake.
                next = next.saturating_add(c);
            }
            Items::Interior { triangles, counts, first_sample, first_index: Vec::new(), weight_count: Vec::new() }
        }
    }
}

/// Triangles that receive samples: neither windows nor degenerate. Refuses
/// a mesh with none: its bake would store nothing but zeros.
pub(crate) fn sampled_triangles(mesh: &Mesh, surfaces: &Surfaces) -> Result<Vec<u32>, NothingToBake> {
    let is_window = |t: u32| surfaces.window_transmittance[t as usize].is_some();
    let sampled: Vec<u32> = (0..mesh.triangle_count() as u32).filter(|&t| !is_window(t) && triangle_area(mesh, t) > 0.0).collect();
    if !sampled.is_empty() {
        return Ok(sampled);
    }
    let windows = (0..mesh.triangle_count() as u32).filter(|&t| is_window(t)).count();
    Err(NothingToBake { triangles: mesh.triangle_count(), windows, degenerate: mesh.triangle_count() - windows })
}

/// Why a bake would store nothing: no triangle receives light, because
/// each is a window (light passes through it) or degenerate (zero area).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("nothing to bake: {}", why_nothing_receives(*.triangles, *.windows, *.degenerate))]
pub struct NothingToBake {
    pub triangles: usize,
    pub windows: usize,
    /// Opaque triangles of zero area.
    pub degenerate: usize,
}

/// [`NothingToBake`]'s reason in words, a lone triangle named as such.
fn why_nothing_receives(triangles: usize, windows: usize, degenerate: usize) -> String {
    match (triangles, windows, degenerate) {
        (0, _, _) => "the mesh has no triangles".into(),
        (1, 1, _) => "the only triangle is a window: no surface receives light".into(),
        (1, _, _) => "the only triangle is degenerate (zero area)".into(),
        (n, w, _) if w == n => format!("every triangle is a window ({n} of {n}): no surface receives light"),
        (n, 0, _) => format!("all {n} triangles are degenerate (zero area)"),
        (n, w, d) => {
            let windows = if w == 1 { "is a window" } else { "are windows" };
            let degenerate = if d == 1 { "is degenerate" } else { "are degenerate" };
            format!("no triangle receives light: of {n}, {w} {windows} and {d} {degenerate} (zero area)")
        }
    }
}

/// Where interior samples go: `counts[k]` samples in `triangles[k]`, whose
/// global sample indices start at `first_sample[k]` (a prefix sum).
pub(crate) struct InteriorLayout {
    pub triangles: Vec<u32>,
    pub counts: Vec<u32>,
    pub first_sample: Vec<u32>,
}

impl InteriorLayout {
    /// Total number of samples.
    pub fn sample_count(&self) -> u64 {
        self.counts.iter().map(|&c| c as u64).sum()
    }
}

/// Spreads about `samples_per_vertex × vertex count` samples over `triangles`
/// by area (at least three, at most `max_per_triangle`, per triangle; see
/// [`samples_in_triangle`]). The one placement rule transfer and sun masks share.
pub(crate) fn interior_layout(mesh: &Mesh, triangles: Vec<u32>, samples_per_vertex: f32, max_per_triangle: u32) -> InteriorLayout {
    let total_area: f64 = triangles.iter().map(|&t| triangle_area(mesh, t) as f64).sum();
    let density = samples_per_vertex as f64 * mesh.vertex_count() as f64 / total_area.max(f64::MIN_POSITIVE);
    let counts: Vec<u32> =
        triangles.iter().map(|&t| samples_in_triangle(triangle_area(mesh, t) as f64 * density, max_per_triangle)).collect();
    let mut first_sample = Vec::with_capacity(counts.len());
    let mut next = 0u32;
    for &c in &counts {
        first_sample.push(next);
        // Saturates past u32: `check_point_count` refuses such a bake.
        next = next.saturating_add(c);
    }
    InteriorLayout { triangles, counts, first_sample }
}

/// Sample points are indexed with `u32`: refuses a bake with more.
pub(crate) fn check_point_count(points: u64) -> Result<(), BakeError> {
    if points > u32::MAX as u64 {
        return Err(BakeError::Params(format!(
            "{points} sample points, more than the {} this baker indexes: lower the samples per vertex",
            u32::MAX
        )));
    }
    Ok(())
}

/// Sample count for a triangle that should get `expected` samples: the
/// nearest multiple of three, at least three (one rotation triple, see
/// [`triangle_sample`]) and at most `max` rounded down to a multiple of
/// three (but three when `max` is smaller). The count sets only the noise:
/// each sample is weighted by the area it stands for ([`sample_weights`]),
/// and a whole triple gives each corner exactly a third of that area, so
/// the normalising weights are exact at every density. (A lone uniform
/// point would leave its weight to chance: a ratio estimator's bias and
/// more noise; a lone centroid would estimate the centroid's value.)
fn samples_in_triangle(expected: f64, max: u32) -> u32 {
    let triples = (expected / 3.0).round().max(1.0) as u32;
    3 * triples.min((max / 3).max(1))
}

/// Barycentrics of sample `s` in mesh triangle `t` (vertex indices
/// `corners`) for a bake seeded with `seed`: the same points whatever pass
/// asks (transfer, sun masks).
///
/// The points are laid out on the corners sorted by vertex index, then
/// mapped back: a triangle whose winding is flipped (its corners listed in
/// another order) gets the same points, so window mode stays side-blind.
///
/// Samples come as the three cyclic rotations of one Owen-scrambled Sobol
/// point (each uniform over the triangle). A symmetric set gives each
/// corner the same total barycentric weight (a third of the samples), so the
/// normalising weights are exact, and the mean position each corner receives
/// leans toward no neighbour: smooth transfer is reproduced to second order.
/// Independent points leave a first-order bias (measured: 1.1e-2 in band 1
/// on the 2,562-vertex icosphere, against 1.5e-4 at the vertices).
#[inline]
pub(crate) fn triangle_sample(pattern: super::DirectionPattern, seed: u32, t: u32, corners: [u32; 3], s: u32) -> [f32; 3] {
    let (u1, u2) = sample_2d(pattern, s / 3, 0, hash_seed(&[seed, TAG_POSITION, t]));
    let b = square_to_triangle(u1, u2);
    let sorted = match s % 3 {
        0 => b,
        1 => [b[1], b[2], b[0]],
        _ => [b[2], b[0], b[1]],
    };
    let mut order = [0usize, 1, 2];
    order.sort_unstable_by_key(|&k| corners[k]);
    let mut out = [0.0; 3];
    for (rank, &corner) in order.iter().enumerate() {
        out[corner] = sorted[rank];
    }
    out
}

/// What a sample at barycentrics `b`, one of `count` in a triangle of area
/// `area`, adds to each corner's weight: its hat value there times the area
/// it stands for. Over the samples, Σ w·t / Σ w estimates each vertex's
/// hat-weighted mean of the transfer over its one-ring (docs/conventions.md,
/// "Per-vertex transfer"), whatever the sample counts; the transfer and the
/// sun vote share it.
#[inline]
pub(crate) fn sample_weights(b: [f32; 3], area: f32, count: u32) -> [f32; 3] {
    let share = area / count as f32;
    b.map(|x| x * share)
}

pub(crate) fn triangle_area(mesh: &Mesh, t: u32) -> f32 {
    let [a, b, c] = mesh.triangle_positions(t as usize);
    0.5 * (b - a).cross(c - a).length()
}

impl<'a> Pass<'a> {
    /// The same pass over other items (adaptive allocation's base layout).
    pub(crate) fn with_items(self, items: &'a Items) -> Pass<'a> {
        Pass { items, ..self }
    }
}

impl Pass<'_> {
    /// Traces (or gathers) every point of items `start..end` for this pass's bounce.
    fn run_task(&self, start: usize, end: usize) -> TaskOutput {
        let bounce = self.bounce;
        let corners = self.items.corners();
        let stride = self.channels * self.coeffs;
        let mut out = TaskOutput {
            sums: vec![0.0; (end - start) * corners * stride],
            weights: vec![0.0; (end - start) * corners],
            rejected: Vec::new(),
            rays: 0,
            traced: 0,
            hits: Vec::new(),
            moments: if self.track_noise { vec![Moments::default(); (end - start) * corners] } else { Vec::new() },
        };
        let mut point_result = vec![0.0f32; stride];
        let mut scratch = Scratch { basis: vec![0.0f32; self.coeffs], ..Scratch::default() };
        for item in start..end {
            let local = item - start;
            match self.items {
                Items::Vertex { vertices } => {
                    let v = vertices[item] as usize;
                    point_result.fill(0.0);
                    if !self.gather_cached(item as u64, &mut point_result) {
                        let normal = self.mesh.normals[v];
                        let point = Point {
                            position: self.mesh.positions[v],
                            normal,
                            face_normal: normal,
                            seed: hash_seed(&[self.params.seed, TAG_DIRECTION, v as u32, u32::MAX]),
                        };
                        let traced = self.trace_point(&point, bounce, false, &mut point_result, &mut scratch, &mut out.hits);
                        out.traced += traced.0;
                    }
                    out.rays += self.params.rays as u64;
                    out.weights[local] = 1.0;
                    out.sums[local * stride..(local + 1) * stride].copy_from_slice(&point_result);
                }
                Items::Interior { triangles, counts, first_sample, first_index, weight_count } => {
                    let t = triangles[item];
                    let first_index = first_index.get(item).copied().unwrap_or(0);
                    let weight_count = weight_count.get(item).copied().unwrap_or(counts[item]);
                    let [ia, ib, ic] = self.mesh.triangle(t as usize);
                    let [pa, pb, pc] = self.mesh.triangle_positions(t as usize);
                    let [na, nb, nc] = [ia, ib, ic].map(|i| self.mesh.normals[i as usize]);
                    let face_normal = self.face_normal(t);
                    let area = triangle_area(self.mesh, t);
                    for s in 0..counts[item] {
                        let global = first_sample[item] + s;
                        if bounce > 0 && self.rejected[global as usize] {
                            continue;
                        }
                        let seed = self.params.point_seed.unwrap_or(self.params.seed);
                        let b = triangle_sample(self.params.pattern, seed, t, [ia, ib, ic], first_index + s);
                        point_result.fill(0.0);
                        let (traced, inside) = if self.gather_cached(global as u64, &mut point_result) {
                            (0, false)
                        } else {
                            let point = Point {
                                position: pa * b[0] + pb * b[1] + pc * b[2],
                                normal: (na * b[0] + nb * b[1] + nc * b[2]).normalize_or(face_normal),
                                face_normal,
                                seed: hash_seed(&[self.params.seed, TAG_DIRECTION, t, first_index + s]),
                            };
                            self.trace_point(&point, bounce, bounce == 0, &mut point_result, &mut scratch, &mut out.hits)
                        };
                        out.rays += self.params.rays as u64;
                        out.traced += traced;
                        if inside {
                            out.rejected.push(global);
                            continue;
                        }
                        let dc = point_result[0];
                        for (corner, w) in sample_weights(b, area, weight_count).into_iter().enumerate() {
                            out.weights[local * 3 + corner] += w;
                            if let Some(moments) = out.moments.get_mut(local * 3 + corner) {
                                moments.add(w, dc);
                            }
                            let dst = &mut out.sums[(local * 3 + corner) * stride..][..stride];
                            dst.iter_mut().zip(&point_result).for_each(|(d, r)| *d += w * r);
                        }
                    }
                }
            }
        }
        out
    }

    /// Hit records `points` points leave in bounce 0 (one per ray, when recorded).
    fn record_count(&self, points: usize) -> usize {
        if self.record_hits {
            points * self.params.rays as usize
        } else {
            0
        }
    }

    /// Each ray's weight: directions are drawn ∝ c(n,ω), so 1/N over the
    /// hemisphere (open mode) or 2/N over the sphere (window mode).
    #[inline]
    fn ray_weight(&self) -> f32 {
        (if self.params.mode == Mode::Window { 2.0 } else { 1.0 }) / self.params.rays as f32
    }

    /// Bounces ≥ 1 with a hit cache: adds point `point_index`'s estimate from
    /// its cached hits to `result` and returns true; false when this pass
    /// traces rays instead (then the point's position and seed are needed).
    #[inline]
    fn gather_cached(&self, point_index: u64, result: &mut [f32]) -> bool {
        let (Some(cache), Some(gather)) = (self.hit_cache, &self.gather) else { return false };
        let rays = self.params.rays as usize;
        let local = (point_index - cache.first_point) as usize;
        // This point's records, then the next points' (usually gathered
        // next), which the gather prefetches into.
        gather.point(&cache.records[local * rays..], rays, self.ray_weight(), result);
        true
    }

    /// Traces the rays of one point for `bounce` (those of bounces ≥ 1 when
    /// nothing is cached), adding the estimate to
    /// `result` (`[channel][coeff]`). In bounce 0 with caching, appends one
    /// hit record per ray to `hits`. Returns the rays traced through the BVH
    /// and, when `check_inside`, whether the point lies inside geometry (then
    /// `result` is meaningless).
    fn trace_point(
        &self,
        point: &Point,
        bounce: u32,
        check_inside: bool,
        result: &mut [f32],
        scratch: &mut Scratch,
        hits: &mut Vec<u64>,
    ) -> (u64, bool) {
        let params = self.params;
        let window_mode = params.mode == Mode::Window;
        let ray_count = params.rays;
        let ray_weight = self.ray_weight();
        // The first rays of bounce 0 also decide whether the point lies inside
        // geometry (most of them hit back faces close by): they are traced with
        // closest hit once, and serve both purposes. Always the same
        // INSIDE_PROBE_RAYS directions, even when fewer rays are asked for
        // (those past `ray_count` only probe), so a point's verdict does not
        // depend on `--rays`.
        let probe = if check_inside { INSIDE_PROBE_RAYS } else { 0 };
        // With window sampling, bounce 0's light through the glass is
        // estimated by the cosine rays and as many rays aimed at the glass,
        // combined by MIS (`window_light`).
        let sample_windows = if bounce == 0 { self.windows } else { None };
        // Window mode keeps bounce 0's light of the point's two sides apart,
        // to drop that of a side outside the enclosure (`Sides::outside`).
        let split_sides = window_mode && bounce == 0 && !params.keep_outside_sides;
        let mut sides = Sides::default();
        if split_sides {
            for light in &mut scratch.side_light {
                light.clear();
                light.resize(result.len(), 0.0);
            }
        }
        let cosine_rays = ray_count;
        let mut traced = 0u64;
        // The rays go to the scene a batch at a time (so it can walk several
        // at once): the probe rays first, whose verdict may end the point,
        // then the rest. Results are added in ray order, as one at a time would.
        for batch in [0..probe, probe..cosine_rays] {
            if batch.is_empty() {
                continue;
            }
            scratch.queries.clear();
            for k in batch.clone() {
                let direction = self.direction(point, k);
                let origin = self.scene.offset_origin(point.position, point.face_normal, direction);
                scratch.queries.push(RayQuery { origin, direction, t_max: f32::INFINITY });
            }
            traced += scratch.queries.len() as u64;
            // Bounce 0 in open mode needs only occlusion, unless hits are recorded or probed.
            let closest = bounce > 0 || window_mode || self.record_hits || batch.start < probe;
            if closest {
                scratch.hits.resize(scratch.queries.len(), None);
                self.scene.closest_hits(&scratch.queries, &mut scratch.hits);
            } else {
                scratch.occluded.resize(scratch.queries.len(), false);
                self.scene.occluded_each(&scratch.queries, &mut scratch.occluded);
            }
            let mut inside_hits = 0u32;
            for (i, query) in scratch.queries.iter().enumerate() {
                let probe_only = batch.start + i as u32 >= ray_count;
                if bounce > 0 {
                    if let (Some(hit), Some(gather)) = (scratch.hits[i], &self.gather) {
                        // Through the cache's encoding, so the bytes do not depend on whether the cache fit.
                        let record = self.record_of(&hit);
                        if record != NO_HIT {
                            let (triangle, u, v) = decode_hit(record);
                            gather.add_hit(triangle, u, v, ray_weight, result);
                        }
                    }
                    continue;
                }
                let visibility = if closest {
                    let hit = scratch.hits[i];
                    if batch.start < probe && matches!(hit, Some(h) if h.back_face && h.t < self.reject_distance) {
                        inside_hits += 1;
                    }
                    if probe_only {
                        continue;
                    }
                    if self.record_hits {
                        hits.push(hit.map_or(NO_HIT, |h| self.record_of(&h)));
                    }
                    if split_sides {
                        let side = Sides::of(point.face_normal, query.direction);
                        sides.count(side, self.surfaces, hit.map(|h| h.triangle));
                    }
                    match hit {
                        Some(h) if window_mode => self.surfaces.window_transmittance[h.triangle as usize].unwrap_or(0.0),
                        Some(_) => 0.0,
                        None if window_mode => 0.0,
                        None => 1.0,
                    }
                } else if scratch.occluded[i] {
                    0.0
                } else {
                    1.0
                };
                if visibility > 0.0 {
                    let w = match (sample_windows, scratch.hits.get(i).copied().flatten()) {
                        (Some(windows), Some(hit)) if closest => {
                            let pdf = windows.pdf(point.position, hit.triangle, query.direction, hit.t);
                            visibility * self.window_mis_weight(point, query.direction, pdf)
                        }
                        _ => visibility * ray_weight,
                    };
                    sh::eval_basis(params.order, query.direction, &mut scratch.basis);
                    let target =
                        if split_sides { &mut scratch.side_light[Sides::of(point.face_normal, query.direction)][..] } else { &mut *result };
                    target.iter_mut().zip(scratch.basis.iter()).for_each(|(r, y)| *r += w * y);
                }
            }
            if check_inside && batch.start < probe && self.reject_inside(inside_hits, probe, hits) {
                return (traced, true);
            }
        }
        if let Some(windows) = sample_windows {
            traced += self.add_window_light(point, windows, if split_sides { None } else { Some(&mut *result) }, scratch);
        }
        if split_sides {
            // Only the sides inside the enclosure keep their light through glass.
            for side in 0..2 {
                if !sides.outside(side) {
                    result.iter_mut().zip(&scratch.side_light[side]).for_each(|(r, l)| *r += l);
                }
            }
        }
        (traced, false)
    }

    /// The light through the glass per unit transmittance and SH basis value
    /// that one of bounce 0's rays toward `direction` carries, when the
    /// light strategy's pdf of that direction is `light_pdf`: the balance
    /// heuristic over N cosine rays (pdf |n·ω|/2π over the sphere) and N
    /// rays aimed at the glass, `(|n·ω|/π) / (N |n·ω|/2π + N p_l)`. With
    /// `light_pdf` = 0 it is the cosine rays' own weight, 2/N.
    #[inline]
    fn window_mis_weight(&self, point: &Point, direction: Vec3, light_pdf: f64) -> f32 {
        let n = f64::from(self.params.rays);
        let cosine = f64::from(point.normal.dot(direction).abs());
        let cosine_pdf = cosine / (2.0 * std::f64::consts::PI);
        if cosine_pdf <= 0.0 {
            return 0.0;
        }
        (cosine / std::f64::consts::PI / (n * cosine_pdf + n * light_pdf)) as f32
    }

    /// Bounce 0 in window mode, the light strategy: N directions toward the
    /// glass (`WindowLights::draw`: a pane by area, a direction uniform
    /// over its solid angle); a draw counts when the first hit along it is
    /// the pane drawn, weighted by [`Pass::window_mis_weight`], into `result`,
    /// or when that is `None` into the side's `scratch.side_light`. Returns rays traced.
    fn add_window_light(&self, point: &Point, windows: &WindowLights, mut result: Option<&mut [f32]>, scratch: &mut Scratch) -> u64 {
        scratch.queries.clear();
        scratch.targets.clear();
        for k in 0..self.params.rays {
            let (u_pick, _) = sample_2d(self.params.pattern, k, 2, point.seed);
            let (u1, u2) = sample_2d(self.params.pattern, k, 1, point.seed);
            let Some(draw) = windows.draw(point.position, u_pick, u1, u2) else { continue };
            // A pane touching the point: the offset origin may lie past it.
            if draw.distance <= 16.0 * self.scene.origin_offset {
                continue;
            }
            let origin = self.scene.offset_origin(point.position, point.face_normal, draw.direction);
            let reach = draw.distance * 1.001 + 4.0 * self.scene.tie_distance;
            scratch.queries.push(RayQuery { origin, direction: draw.direction, t_max: reach });
            scratch.targets.push((draw.triangle, draw.pdf));
        }
        scratch.hits.resize(scratch.queries.len(), None);
        self.scene.closest_hits(&scratch.queries, &mut scratch.hits);
        for ((query, &(triangle, pdf)), hit) in scratch.queries.iter().zip(&scratch.targets).zip(&scratch.hits) {
            if !matches!(hit, Some(h) if h.triangle == triangle) {
                continue;
            }
            let tau = self.surfaces.window_transmittance[triangle as usize].unwrap_or(0.0);
            let w = tau * self.window_mis_weight(point, query.direction, pdf);
            sh::eval_basis(self.params.order, query.direction, &mut scratch.basis);
            let target = match result.as_deref_mut() {
                Some(result) => result,
                None => &mut scratch.side_light[Sides::of(point.face_normal, query.direction)][..],
            };
            target.iter_mut().zip(scratch.basis.iter()).for_each(|(r, y)| *r += w * y);
        }
        scratch.queries.len() as u64
    }

    /// Decides, from the `probe` first rays, whether a point lies inside
    /// geometry: more than half of them (three quarters over the whole
    /// sphere, where the back hemisphere of a solid's surface hits its inside
    /// anyway) met a back face closer than `reject_distance`. A rejected
    /// point's recorded hits are replaced by misses.
    fn reject_inside(&self, inside_hits: u32, probe: u32, hits: &mut Vec<u64>) -> bool {
        let threshold = if self.params.mode == Mode::Window { 0.75 } else { 0.5 };
        if inside_hits as f32 <= threshold * probe as f32 {
            return false;
        }
        if self.record_hits {
            hits.truncate(hits.len() - probe.min(self.params.rays) as usize);
            hits.extend(std::iter::repeat_n(NO_HIT, self.params.rays as usize));
        }
        true
    }

    /// What later bounces gather at `hit`: the hit triangle's rows, or in
    /// open mode, on a back face, its twin's (the twin's corners run the
    /// other way: its barycentrics are (v, u)); `NO_HIT` where no light
    /// comes back (a window, a back face without a twin).
    #[inline]
    fn record_of(&self, hit: &crate::trace::Hit) -> u64 {
        if self.surfaces.window_transmittance[hit.triangle as usize].is_some() {
            return NO_HIT;
        }
        if self.params.mode == Mode::Window || !hit.back_face {
            return encode_hit(hit.triangle, hit.u, hit.v);
        }
        match self.twins.twin_of[hit.triangle as usize] {
            NO_TWIN => NO_HIT,
            twin => encode_hit(twin, hit.v, hit.u),
        }
    }

    /// Unit geometric normal of triangle `t` of the plan's mesh (a twin's is its triangle's, negated).
    #[inline]
    fn face_normal(&self, t: u32) -> Vec3 {
        match self.twins.geometry_of(t) {
            (t, false) => self.scene.face_normal(t),
            (source, true) => -self.scene.face_normal(source),
        }
    }

    #[inline]
    fn direction(&self, point: &Point, k: u32) -> Vec3 {
        let (u1, u2) = sample_2d(self.params.pattern, k, 0, point.seed);
        if self.params.mode == Mode::Window {
            cosine_sphere(point.normal, u1, u2)
        } else {
            cosine_hemisphere(point.normal, u1, u2)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::{bake_mesh, BakeError};
    use crate::verify::shapes;

    #[test]
    fn point_counts_past_u32_are_refused_not_wrapped() {
        assert!(super::check_point_count(u32::MAX as u64).is_ok());
        let error = super::check_point_count(u32::MAX as u64 + 1).unwrap_err().to_string();
        assert!(error.contains("4294967296 sample points") && error.contains("samples per vertex"), "{error}");
    }

    /// A plane of 8 triangles whose first `windows` are windows and whose
    /// next `degenerate` ones are collapsed to a point.
    fn plane_with(windows: usize, degenerate: usize) -> (Mesh, Vec<String>) {
        let mut mesh = shapes::plane_grid(2, 1.0);
        mesh.groups = vec!["wall".into(), "glass".into()];
        mesh.tri_group = (0..8).map(|t| u32::from(t < windows)).collect();
        for t in windows..windows + degenerate {
            let [a, b, c] = mesh.triangle(t);
            // A fresh vertex per corner, all at one point: neighbours keep their area.
            for (k, v) in [a, b, c].into_iter().enumerate() {
                mesh.positions.push(mesh.positions[a as usize]);
                mesh.normals.push(mesh.normals[v as usize]);
                mesh.indices[3 * t + k] = mesh.positions.len() as u32 - 1;
            }
        }
        (mesh, vec!["glass".into()])
    }

    /// A bake in which no triangle receives light (every one a window or of
    /// zero area) is refused, saying which; one receiving triangle is enough.
    #[test]
    fn a_bake_where_no_triangle_receives_light_is_refused_with_the_reason() {
        let params = BakeParams { rays: 8, ..BakeParams::default() };
        let vertex = BakeParams { sampling: Sampling::Vertex, ..params };
        for (windows, degenerate, reason) in [
            (8, 0, "nothing to bake: every triangle is a window (8 of 8): no surface receives light"),
            (0, 8, "nothing to bake: all 8 triangles are degenerate (zero area)"),
            (3, 5, "nothing to bake: no triangle receives light: of 8, 3 are windows and 5 are degenerate (zero area)"),
            (7, 1, "of 8, 7 are windows and 1 is degenerate (zero area)"),
        ] {
            let (mesh, patterns) = plane_with(windows, degenerate);
            for params in [params, vertex] {
                let refused = bake_mesh(&mesh, &params, &patterns).err().expect("refused");
                let expected = NothingToBake { triangles: 8, windows, degenerate };
                assert!(matches!(&refused, BakeError::NothingToBake(n) if *n == expected), "{refused:?}");
                assert!(refused.to_string().contains(reason), "{refused}");
            }
        }
        let (mesh, patterns) = plane_with(4, 3);
        let result = bake_mesh(&mesh, &params, &patterns).unwrap().0;
        assert!(result.stats.points > 0 && result.total.iter().any(|&t| t > 0.0));
    }

    #[test]
    fn one_or_no_triangle_is_named_plainly() {
        let message = |triangles, windows, degenerate| NothingToBake { triangles, windows, degenerate }.to_string();
        assert_eq!(message(0, 0, 0), "nothing to bake: the mesh has no triangles");
        assert_eq!(message(1, 1, 0), "nothing to bake: the only triangle is a window: no surface receives light");
        assert_eq!(message(1, 0, 1), "nothing to bake: the only triangle is degenerate (zero area)");
    }
}
