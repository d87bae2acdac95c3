//! Running a range of items for one bounce: each point's rays traced (or
//! gathered from bounce 0's hit records) in parallel tasks, and their sums
//! added to the vertices in item order.

use glam::Vec3;
use rayon::prelude::*;

use super::items::*;
use super::normalise::*;
use crate::bake::enclosure::Sides;
use crate::bake::gather::{back_side, decode_hit, encode_hit, hit_back, Gather, BACK_SIDE, HIT_BACK, NO_HIT};
use crate::bake::noise::Moments;
use crate::bake::progress::Progress;
use crate::bake::receivers::{point_weights, Receivers};
use crate::bake::surfaces::Surfaces;
use crate::bake::twins::{Twins, NO_TWIN};
use crate::bake::window_light::WindowLights;
use crate::bake::{BakeParams, Mode};
use crate::mesh::Mesh;
use crate::sampling::{cosine_hemisphere, cosine_sphere, hash_seed, sample_2d};
use crate::sh;
use crate::trace::scene::{RayQuery, Scene};

pub(crate) const TAG_DIRECTION: u32 = 0x5053_0002;

/// Items (triangles or vertices) per parallel task, and per sequential merge.
pub(crate) const ITEMS_PER_TASK: usize = 32;

pub(crate) const ITEMS_PER_MERGE: usize = 8192;

/// Rays of each point first traced with closest hit to decide whether the point lies inside geometry.
pub(crate) const INSIDE_PROBE_RAYS: u32 = 32;

/// A task's reusable buffers for one point's rays.
#[derive(Default)]
pub(crate) struct Scratch {
    /// SH basis of one direction.
    pub(crate) basis: Vec<f32>,
    /// The rays of the batch being traced, and their answers.
    pub(crate) queries: Vec<RayQuery>,
    pub(crate) hits: Vec<Option<crate::trace::Hit>>,
    pub(crate) occluded: Vec<bool>,
    /// Per window-light query: the window triangle aimed at and the light pdf of its direction.
    pub(crate) targets: Vec<(u32, f64)>,
    /// Window mode, bounce 0: the light through glass of each side of the
    /// point (front, back of its face), kept apart until [`Sides`] decides.
    pub(crate) side_light: [Vec<f32>; 2],
}

/// What tracing one point gave besides its estimate.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Traced {
    /// Rays traced through the BVH.
    pub(crate) rays: u64,
    /// The point lies inside geometry (bounce 0 with the check; its estimate is then meaningless).
    pub(crate) inside: bool,
    /// The part of the estimate's DC (mean over channels) that arrived
    /// through the back of the point's face (window mode, else 0).
    pub(crate) back_dc: f32,
    /// Window mode, bounce 0: the DC (first channel) of the light through
    /// glass the point's sides kept, and that of sides found outside the
    /// enclosure, dropped ([`Sides::outside`]); set by [`Pass::keep_sides`].
    pub(crate) glass_dc: [f32; 2],
    /// Window mode, bounce 0: what the point's rays met on each side, for
    /// the verdict [`Pass::keep_sides`] takes (pooled over the point's item).
    pub(crate) sides: Sides,
}

/// One point rays leave from.
#[derive(Clone, Copy)]
pub(crate) struct Point {
    pub(crate) position: Vec3,
    /// Shading normal: the cosine is taken against it.
    pub(crate) normal: Vec3,
    /// Geometric normal: origins are pushed along it.
    pub(crate) face_normal: Vec3,
    /// Seed of this point's direction stream.
    pub(crate) seed: u32,
}

/// Shared read-only state of a pass.
pub(crate) struct Pass<'a> {
    pub(crate) bounce: u32,
    /// The plan's mesh (twins included); rays are traced in `scene`, built on the mesh's own triangles.
    pub(crate) mesh: &'a Mesh,
    /// What the points add to.
    pub(crate) receivers: Receivers<'a>,
    pub(crate) scene: &'a Scene,
    pub(crate) surfaces: &'a Surfaces,
    pub(crate) twins: &'a Twins,
    pub(crate) params: &'a BakeParams,
    pub(crate) items: &'a Items,
    pub(crate) coeffs: usize,
    /// Channels of this pass's output (1 for bounce 0, whose transfer is colourless).
    pub(crate) channels: usize,
    /// What bounces ≥ 1 gather from: the previous bounce at hits.
    pub(crate) gather: Option<Gather<'a>>,
    pub(crate) rejected: &'a [bool],
    pub(crate) reject_distance: f32,
    /// Bounce 0 records every ray's hit here (when bounces follow and it fits
    /// the budget); bounces ≥ 1 then gather from it instead of re-tracing:
    /// the rays are the same, only the values at their ends change.
    pub(crate) hit_cache: Option<HitRecords<'a>>,
    pub(crate) record_hits: bool,
    /// Interior sampling: keep each item corner's [`Moments`] of this
    /// bounce's point DC (the noise estimate adds every bounce's).
    pub(crate) track_noise: bool,
    /// Window triangles to sample directly for bounce 0 (window mode).
    pub(crate) windows: Option<&'a WindowLights>,
    /// Window mode's bounce 0 over adaptive allocation's extra points: per
    /// item, what its triangle's base points met, pooled into the extras' verdict.
    pub(crate) base_sides: Option<&'a [Sides]>,
}

/// What one task returns: per item and corner, weighted coefficient sums and weights.
pub(crate) struct TaskOutput {
    pub(crate) sums: Vec<f32>,
    pub(crate) weights: Vec<f32>,
    /// Global indices of the points found inside geometry.
    pub(crate) rejected: Vec<u32>,
    /// Rays evaluated (traced or gathered from the cache).
    pub(crate) rays: u64,
    /// Rays actually traced through the BVH.
    pub(crate) traced: u64,
    /// Hit records of this task's points, in point order (bounce 0 with caching).
    pub(crate) hits: Vec<u64>,
    /// Per item and corner, the moments of the points' DC (when the pass
    /// tracks noise, else empty).
    pub(crate) moments: Vec<Moments>,
    /// Summed [`Traced::glass_dc`] of the task's points: kept, dropped.
    pub(crate) glass_dc: [f64; 2],
    /// Window mode's bounce 0 on interior items: per item, what its points
    /// met on each side, pooled (see [`Pass::keep_sides`]); else empty.
    pub(crate) sides: Vec<Sides>,
}

/// Bounce 0's hit records of the points from `first_point` on (a whole
/// bake's, or one shard's).
#[derive(Clone, Copy)]
pub(crate) struct HitRecords<'a> {
    pub(crate) records: &'a [u64],
    pub(crate) first_point: u64,
}

/// Contributions of a range of items to receivers whose first item lies
/// before the range, in item and corner order: added after the earlier
/// ranges' sums, they keep each receiver's sum order that of a whole bake.
#[derive(Default)]
pub(crate) struct LateSums {
    pub(crate) receivers: Vec<u32>,
    /// One row per entry of `receivers`.
    pub(crate) rows: Vec<f32>,
    /// One weight per entry (bounce 0), else empty.
    pub(crate) weights: Vec<f32>,
    /// One [`Moments`] per entry when the pass tracks noise, else empty.
    pub(crate) moments: Vec<Moments>,
}

/// One bounce's sums over a range of items (a whole bake is one range).
pub(crate) struct RangeSums {
    /// `[receiver][channel][coeff]` for every receiver; filled for the
    /// receivers whose first item is in the range (all of them in a whole bake).
    pub(crate) sums: Vec<f32>,
    /// Bounce 0: each receiver's summed sample weight ([`point_weights`]), as `sums`.
    pub(crate) weights: Vec<f32>,
    /// Bounce 0 (interior sampling): each receiver's [`Moments`] of its
    /// points' DC, as `weights` but for the vertices `late` holds.
    pub(crate) moments: Vec<Moments>,
    pub(crate) late: LateSums,
    /// Global indices of the points found inside geometry (bounce 0).
    pub(crate) rejected: Vec<u32>,
    pub(crate) rays: u64,
    pub(crate) traced: u64,
    /// Summed [`Traced::glass_dc`] of the range's points, in task order: kept, dropped.
    pub(crate) glass_dc: [f64; 2],
    /// Bounce 0's hit records of the range's points, in point order, when recorded.
    pub(crate) hits: Vec<u64>,
    /// `--gather-fit`: each item's three corner sums, `[item][corner][channel][coeff]`.
    pub(crate) item_sums: Vec<f32>,
}

/// (a) and (b): evaluates every point of the items in `range` for `pass`'s
/// bounce, in tasks of [`ITEMS_PER_TASK`] items, and adds each item's corner
/// sums to its receivers in item order. `first_items` (see
/// [`Items::first_items`]) is given for a range that is not the whole bake:
/// contributions to receivers first touched before it go to
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
    pub(crate) filled: usize,
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
    pub(crate) fn empty(pass: &Pass) -> RangeSums {
        let count = pass.receivers.count();
        RangeSums {
            sums: vec![0.0; count * pass.channels * pass.coeffs],
            weights: vec![0.0; count],
            moments: if pass.track_noise { vec![Moments::default(); count] } else { Vec::new() },
            late: LateSums::default(),
            rejected: Vec::new(),
            rays: 0,
            traced: 0,
            glass_dc: [0.0; 2],
            hits: Vec::new(),
            item_sums: match pass.items {
                Items::Interior { .. } if pass.params.gather_fit => vec![0.0; pass.items.len() * 3 * pass.channels * pass.coeffs],
                _ => Vec::new(),
            },
        }
    }

    /// Adds one task's counts (rays, the light through glass kept and
    /// dropped) and its rejected points; not its sums.
    pub(crate) fn add_counts(&mut self, task: &TaskOutput) {
        self.rays += task.rays;
        self.traced += task.traced;
        self.glass_dc[0] += task.glass_dc[0];
        self.glass_dc[1] += task.glass_dc[1];
        self.rejected.extend_from_slice(&task.rejected);
    }

    /// Adds one task's item sums, in item and corner order. `late_before`:
    /// receivers whose first item is before this item index go to `late`.
    pub(crate) fn add_task(&mut self, pass: &Pass, task_start: usize, task: &TaskOutput, late_before: Option<(&[u32], usize)>) {
        self.add_counts(task);
        let corners = pass.items.corners();
        let stride = pass.channels * pass.coeffs;
        let with_weights = pass.bounce == 0;
        for (local, corner_sums) in task.sums.chunks_exact(corners * stride).enumerate() {
            if !self.item_sums.is_empty() {
                self.item_sums[(task_start + local) * corners * stride..][..corners * stride].copy_from_slice(corner_sums);
            }
            let receivers = pass.items.corner_receivers(&pass.receivers, task_start + local);
            for (corner, sums) in corner_sums.chunks_exact(stride).enumerate() {
                let v = receivers[corner] as usize;
                let weight = task.weights[local * corners + corner];
                if late_before.is_some_and(|(first, start)| (first[v] as usize) < start) {
                    self.late.receivers.push(v as u32);
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

/// [`trace_tasks`] for items whose points are not contiguous in the
/// unified layout (the extra items of [`adaptive_range`]): each item's hit
/// records go to its own slot of `records` (which starts at unified point
/// `records_start`).
pub(crate) fn trace_tasks_scattered(
    pass: &Pass,
    records: &mut [u64],
    records_start: usize,
    progress: &Progress,
) -> Vec<(usize, TaskOutput)> {
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

/// Adds one point's estimate `result` to the three corners of item `local`
/// of a task, with the corner weights `weights`, and its glass light to the task's.
#[inline]
fn add_point(out: &mut TaskOutput, local: usize, weights: [f32; 3], traced: &Traced, result: &[f32], stride: usize) {
    out.glass_dc[0] += traced.glass_dc[0] as f64;
    out.glass_dc[1] += traced.glass_dc[1] as f64;
    let dc = result[0];
    for (corner, w) in weights.into_iter().enumerate() {
        out.weights[local * 3 + corner] += w;
        if let Some(moments) = out.moments.get_mut(local * 3 + corner) {
            moments.add(w, dc, traced.back_dc);
        }
        let dst = &mut out.sums[(local * 3 + corner) * stride..][..stride];
        dst.iter_mut().zip(result).for_each(|(d, r)| *d += w * r);
    }
}

/// Window mode's bounce 0: the points of one triangle (or texel), each
/// side's light kept apart, waiting for the enclosure verdict pooled over
/// their rays; `K` is what the caller needs to add a point's estimate.
pub(crate) struct WaitingPoints<K> {
    /// What the points' rays met on each side, with the prior counts they started from.
    pub(crate) sides: Sides,
    points: Vec<(K, Traced)>,
    light: Vec<f32>,
}

impl<K> WaitingPoints<K> {
    pub(crate) fn new() -> WaitingPoints<K> {
        WaitingPoints { sides: Sides::default(), points: Vec::new(), light: Vec::new() }
    }

    /// Starts another triangle or texel, from counts `prior` (its points traced before, if any).
    pub(crate) fn start(&mut self, prior: Sides) {
        self.sides = prior;
        self.points.clear();
        self.light.clear();
    }

    /// Holds a point that [`Pass::trace_point`] just traced: its counts and its sides' light.
    pub(crate) fn hold(&mut self, key: K, traced: Traced, side_light: &[Vec<f32>; 2]) {
        self.sides.add(&traced.sides);
        self.points.push((key, traced));
        self.light.extend_from_slice(&side_light[0]);
        self.light.extend_from_slice(&side_light[1]);
    }

    /// Each held point's estimate under the pooled verdict (`result` is the
    /// buffer it is made in), handed to `add` in the order the points came.
    pub(crate) fn release(&mut self, pass: &Pass, result: &mut [f32], mut add: impl FnMut(K, &Traced, &[f32])) {
        let stride = result.len();
        for (k, (key, mut traced)) in self.points.drain(..).enumerate() {
            let light = &self.light[2 * k * stride..][..2 * stride];
            result.fill(0.0);
            pass.keep_sides(&self.sides, [&light[..stride], &light[stride..]], result, &mut traced);
            add(key, &traced, result);
        }
    }
}

impl<'a> Pass<'a> {
    /// The same pass over other items (adaptive allocation's base layout).
    pub(crate) fn with_items(self, items: &'a Items) -> Pass<'a> {
        Pass { items, ..self }
    }
}

impl Pass<'_> {
    /// Traces (or gathers) every point of items `start..end` for this pass's bounce.
    pub(crate) fn run_task(&self, start: usize, end: usize) -> TaskOutput {
        let bounce = self.bounce;
        let corners = self.items.corners();
        let stride = self.channels * self.coeffs;
        let mut out = TaskOutput {
            sums: vec![0.0; (end - start) * corners * stride],
            weights: vec![0.0; (end - start) * corners],
            rejected: Vec::new(),
            rays: 0,
            traced: 0,
            glass_dc: [0.0; 2],
            sides: Vec::new(),
            hits: Vec::new(),
            moments: if self.track_noise { vec![Moments::default(); (end - start) * corners] } else { Vec::new() },
        };
        let mut point_result = vec![0.0f32; stride];
        let mut scratch = Scratch { basis: vec![0.0f32; self.coeffs], ..Scratch::default() };
        let mut waiting = WaitingPoints::new();
        for item in start..end {
            let local = item - start;
            match self.items {
                Items::Vertex { vertices } => {
                    let v = vertices[item] as usize;
                    point_result.fill(0.0);
                    if self.gather_cached(item as u64, &mut point_result).is_none() {
                        let normal = self.mesh.normals[v];
                        let point = Point {
                            position: self.mesh.positions[v],
                            normal,
                            face_normal: normal,
                            seed: hash_seed(&[self.params.seed, TAG_DIRECTION, v as u32, u32::MAX]),
                        };
                        let mut traced = self.trace_point(&point, bounce, false, &mut point_result, &mut scratch, &mut out.hits);
                        if self.splits_sides(bounce) {
                            let [front, back] = &scratch.side_light;
                            let own = traced.sides;
                            self.keep_sides(&own, [front, back], &mut point_result, &mut traced);
                        }
                        out.traced += traced.rays;
                    }
                    out.rays += self.params.rays as u64;
                    out.weights[local] = 1.0;
                    out.sums[local * stride..(local + 1) * stride].copy_from_slice(&point_result);
                }
                Items::Interior { .. } => {
                    let Some(ItemSamples { triangle: t, count, first_sample, first_index, weight_count }) = self.items.samples(item) else {
                        unreachable!("an interior layout's item")
                    };
                    let [ia, ib, ic] = self.mesh.triangle(t as usize);
                    let [pa, pb, pc] = self.mesh.triangle_positions(t as usize);
                    let [na, nb, nc] = [ia, ib, ic].map(|i| self.mesh.normals[i as usize]);
                    let face_normal = self.face_normal(t);
                    let area = triangle_area(self.mesh, t);
                    // Window mode's bounce 0: the points wait, each side's light
                    // apart, for the enclosure verdict pooled over the triangle's points.
                    let pool = self.splits_sides(bounce);
                    waiting.start(self.base_sides.map_or(Sides::default(), |base| base[item]));
                    for s in 0..count {
                        let global = first_sample + s;
                        if bounce > 0 && self.rejected[global as usize] {
                            continue;
                        }
                        let seed = self.params.point_seed.unwrap_or(self.params.seed);
                        let b = triangle_sample(self.params.pattern, seed, t, [ia, ib, ic], first_index + s);
                        point_result.fill(0.0);
                        let traced = if let Some(back_dc) = self.gather_cached(global as u64, &mut point_result) {
                            Traced { back_dc, ..Traced::default() }
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
                        out.traced += traced.rays;
                        if traced.inside {
                            out.rejected.push(global);
                            continue;
                        }
                        if pool {
                            waiting.hold(b, traced, &scratch.side_light);
                            continue;
                        }
                        add_point(&mut out, local, point_weights(b, area, weight_count), &traced, &point_result, stride);
                    }
                    if pool {
                        waiting.release(self, &mut point_result, |b, traced, result| {
                            add_point(&mut out, local, point_weights(b, area, weight_count), traced, result, stride)
                        });
                        out.sides.push(waiting.sides);
                    }
                }
            }
        }
        out
    }

    /// Hit records `points` points leave in bounce 0 (one per ray, when recorded).
    pub(crate) fn record_count(&self, points: usize) -> usize {
        if self.record_hits {
            points * self.params.rays as usize
        } else {
            0
        }
    }

    /// Each ray's weight: directions are drawn ∝ c(n,ω), so 1/N over the
    /// hemisphere (open mode) or 2/N over the sphere (window mode).
    #[inline]
    pub(crate) fn ray_weight(&self) -> f32 {
        (if self.params.mode == Mode::Window { 2.0 } else { 1.0 }) / self.params.rays as f32
    }

    /// Bounces ≥ 1 with a hit cache: adds point `point_index`'s estimate from
    /// its cached hits to `result` and returns its back-side DC (as
    /// [`Traced::back_dc`]); `None` when this pass traces rays instead (then
    /// the point's position and seed are needed).
    #[inline]
    pub(crate) fn gather_cached(&self, point_index: u64, result: &mut [f32]) -> Option<f32> {
        let (Some(cache), Some(gather)) = (self.hit_cache, &self.gather) else { return None };
        let rays = self.params.rays as usize;
        let local = (point_index - cache.first_point) as usize;
        // This point's records, then the next points' (usually gathered
        // next), which the gather prefetches into.
        let back = gather.point(&cache.records[local * rays..], rays, self.ray_weight(), result);
        Some(back / self.channels as f32)
    }

    /// Traces the rays of one point for `bounce` (those of bounces ≥ 1 when
    /// nothing is cached), adding the estimate to
    /// `result` (`[channel][coeff]`). In bounce 0 with caching, appends one
    /// hit record per ray to `hits` (marked [`BACK_SIDE`] in window mode
    /// where the ray leaves through the back of the face). Returns the rays
    /// traced through the BVH, when `check_inside` whether the point lies
    /// inside geometry (then `result` is meaningless), and the estimate's
    /// back-side DC.
    pub(crate) fn trace_point(
        &self,
        point: &Point,
        bounce: u32,
        check_inside: bool,
        result: &mut [f32],
        scratch: &mut Scratch,
        hits: &mut Vec<u64>,
    ) -> Traced {
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
        // to drop that of a side outside the enclosure (`Sides::outside`)
        // and to tell the back side's share.
        let split_sides = self.splits_sides(bounce);
        // Bounces ≥ 1 in window mode: the DC the back side's rays gather.
        let mut back_dc = 0.0f32;
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
        // A ray that only probes asks for a back face closer than the reject
        // distance: traced no further than twice that (and past any tie
        // there), it finds the same closest hit wherever the verdict reads it.
        let probe_reach = 2.0 * self.reject_distance + 8.0 * self.scene.tie_distance;
        for batch in [0..probe, probe..cosine_rays] {
            if batch.is_empty() {
                continue;
            }
            scratch.queries.clear();
            for k in batch.clone() {
                let direction = self.direction(point, k);
                let origin = self.scene.offset_origin(point.position, point.face_normal, direction);
                let t_max = if k >= ray_count { probe_reach } else { f32::INFINITY };
                scratch.queries.push(RayQuery { origin, direction, t_max });
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
                        let record = self.side_record(self.record_of(&hit), point, query.direction);
                        if record != NO_HIT {
                            let (triangle, u, v) = decode_hit(record);
                            back_dc += back_side(record) * gather.add_hit(triangle, u, v, hit_back(record), ray_weight, result);
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
                        hits.push(hit.map_or(NO_HIT, |h| self.side_record(self.record_of(&h), point, query.direction)));
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
                return Traced { rays: traced, inside: true, ..Traced::default() };
            }
        }
        if let Some(windows) = sample_windows {
            traced += self.add_window_light(point, windows, if split_sides { None } else { Some(&mut *result) }, scratch);
        }
        // Window mode's bounce 0 leaves the two sides' light in `scratch`
        // for `keep_sides`, which adds it to the estimate once the verdict is in.
        Traced { rays: traced, inside: false, back_dc: back_dc / self.channels as f32, glass_dc: [0.0; 2], sides }
    }

    /// Window mode, bounce 0: true when [`Pass::trace_point`] leaves each
    /// side's light apart for [`Pass::keep_sides`].
    #[inline]
    pub(crate) fn splits_sides(&self, bounce: u32) -> bool {
        self.params.mode == Mode::Window && bounce == 0
    }

    /// Adds to `result` the light of the sides (`light`: front, back) that
    /// `verdict` finds inside the enclosure (all with `--keep-outside-sides`),
    /// and sets `traced`'s back-side DC and kept and dropped glass DC.
    pub(crate) fn keep_sides(&self, verdict: &Sides, light: [&[f32]; 2], result: &mut [f32], traced: &mut Traced) {
        let mut back_dc = 0.0;
        traced.glass_dc = [0.0; 2];
        for side in 0..2 {
            if self.params.keep_outside_sides || !verdict.outside(side) {
                result.iter_mut().zip(light[side]).for_each(|(r, l)| *r += l);
                traced.glass_dc[0] += light[side][0];
                if side == 1 {
                    back_dc = light[1][0];
                }
            } else {
                traced.glass_dc[1] += light[side][0];
            }
        }
        traced.back_dc = back_dc / self.channels as f32;
    }

    /// `record` marked [`BACK_SIDE`] when, in window mode, its ray toward
    /// `direction` leaves through the back of the point's face.
    #[inline]
    pub(crate) fn side_record(&self, record: u64, point: &Point, direction: Vec3) -> u64 {
        if record == NO_HIT || self.params.mode != Mode::Window || Sides::of(point.face_normal, direction) == 0 {
            record
        } else {
            record | BACK_SIDE
        }
    }

    /// The light through the glass per unit transmittance and SH basis value
    /// that one of bounce 0's rays toward `direction` carries, when the
    /// light strategy's pdf of that direction is `light_pdf`: the balance
    /// heuristic over N cosine rays (pdf |n·ω|/2π over the sphere) and N
    /// rays aimed at the glass, `(|n·ω|/π) / (N |n·ω|/2π + N p_l)`. With
    /// `light_pdf` = 0 it is the cosine rays' own weight, 2/N.
    #[inline]
    pub(crate) fn window_mis_weight(&self, point: &Point, direction: Vec3, light_pdf: f64) -> f32 {
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
    pub(crate) fn add_window_light(
        &self,
        point: &Point,
        windows: &WindowLights,
        mut result: Option<&mut [f32]>,
        scratch: &mut Scratch,
    ) -> u64 {
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
    pub(crate) fn reject_inside(&self, inside_hits: u32, probe: u32, hits: &mut Vec<u64>) -> bool {
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

    /// What later bounces gather at `hit`: the hit triangle's rows, in
    /// window mode those of the side hit (marked [`HIT_BACK`] on a back
    /// face), or in open mode, on a back face, its twin's (the twin's
    /// corners run the other way: its barycentrics are (v, u)); `NO_HIT`
    /// where no light comes back (a window, a back face without a twin).
    #[inline]
    pub(crate) fn record_of(&self, hit: &crate::trace::Hit) -> u64 {
        if self.surfaces.window_transmittance[hit.triangle as usize].is_some() {
            return NO_HIT;
        }
        if self.params.mode == Mode::Window {
            return encode_hit(hit.triangle, hit.u, hit.v) | if hit.back_face { HIT_BACK } else { 0 };
        }
        if !hit.back_face {
            return encode_hit(hit.triangle, hit.u, hit.v);
        }
        match self.twins.twin_of[hit.triangle as usize] {
            NO_TWIN => NO_HIT,
            twin => encode_hit(twin, hit.v, hit.u),
        }
    }

    /// Unit geometric normal of triangle `t` of the plan's mesh (a twin's is its triangle's, negated).
    #[inline]
    pub(crate) fn face_normal(&self, t: u32) -> Vec3 {
        match self.twins.geometry_of(t) {
            (t, false) => self.scene.face_normal(t),
            (source, true) => -self.scene.face_normal(source),
        }
    }

    #[inline]
    pub(crate) fn direction(&self, point: &Point, k: u32) -> Vec3 {
        let (u1, u2) = sample_2d(self.params.pattern, k, 0, point.seed);
        if self.params.mode == Mode::Window {
            cosine_sphere(point.normal, u1, u2)
        } else {
            cosine_hemisphere(point.normal, u1, u2)
        }
    }
}
