//! A bake's plan: its items, sizes and the passes over them, shared by a
//! whole bake and its shards; adaptive allocation's unified layout.

use super::items::*;
use super::normalise::*;
use super::run::*;
use crate::bake::enclosure::Sides;
use crate::bake::gather::Gather;
use crate::bake::noise::VertexDc;
use crate::bake::progress::Progress;
use crate::bake::receivers::Receivers;
use crate::bake::surfaces::Surfaces;
use crate::bake::twins::Twins;
use crate::bake::window_light::WindowLights;
use crate::bake::{BakeError, BakeParams, BakeStats, Mode, Sampling};
use crate::mesh::Mesh;
use crate::sh;
use crate::trace::scene::Scene;

/// What every pass of a bake shares: the items, sizes, the albedo bounces
/// reflect with and the window lights. A whole bake and each of its shards
/// (`shards`) build it the same way, so they see the same items.
pub(crate) struct Plan<'a> {
    /// The mesh the bake's receivers lie on: the scene's mesh, with the
    /// twins of its back sides appended when it has any (`bake::twins`).
    pub(crate) mesh: std::borrow::Cow<'a, Mesh>,
    pub(crate) scene: &'a Scene,
    pub(crate) surfaces: std::borrow::Cow<'a, Surfaces>,
    /// Which triangles have a back side of their own, and where.
    pub(crate) twins: Twins,
    pub(crate) params: &'a BakeParams,
    pub(crate) items: Items,
    pub(crate) coeffs: usize,
    /// Channels of the result (bounce 0 is traced colourless, then widened).
    pub(crate) channels: usize,
    /// Albedo at hit points, per channel count.
    pub(crate) bounce_albedo: Vec<[f32; 3]>,
    pub(crate) windows: Option<WindowLights>,
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
            let corners = if source.corner_indices.is_empty() { self.receivers().hit_table() } else { &source.corner_indices };
            let gather = Gather::new(corners, &self.bounce_albedo, source.rows.as_slice(), self.coeffs, source.channels, self.channels);
            let stride = source.channels * self.coeffs;
            let texel_back_offset = source.texels.as_ref().map_or(0, |t| t.back_offset(stride));
            let gather = gather.with_sides(source.back_offset(stride), texel_back_offset);
            match &source.texels {
                Some(texels) => gather.with_texels(&texels.lookup, texels.rows.as_slice()),
                None => gather,
            }
        });
        Pass {
            bounce,
            mesh: &self.mesh,
            receivers: self.receivers(),
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
            base_sides: None,
        }
    }
}

impl Plan<'_> {
    /// What the bake's points add to: the vertices of the plan's mesh.
    pub(crate) fn receivers(&self) -> Receivers<'_> {
        Receivers::vertices(&self.mesh)
    }

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
    // Window mode: an extra item's enclosure verdict pools its triangle's
    // base points too (the base tasks' counts, per item in item order).
    let base_sides: Option<Vec<Sides>> = pass.splits_sides(0).then(|| {
        let per_item = base_tasks.iter().flat_map(|(start, task)| task.sides.iter().enumerate().map(move |(local, s)| (start + local, *s)));
        per_item.filter(|&(k, _)| extra[k] > 0).map(|(_, s)| s).collect()
    });
    let extra_tasks = {
        let extra_pass = Pass { items: &extra_items, base_sides: base_sides.as_deref(), ..plan.pass(0, source, &[], None, record_hits) };
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
        out.add_counts(task);
    }
    out.rejected.sort_unstable();
    out.hits = records;
    out
}
