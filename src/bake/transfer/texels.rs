//! Transfer per texel of a lightmap atlas (texel mode): each covered texel
//! is a receiver whose value is the mean of the transfer over its footprint
//! (the parts of its triangles inside its square), parts inside geometry
//! left out. Its points lie in that footprint, so a 3 cm slat shadow on a
//! 4 m triangle is resolved at the texel size, not the triangle's.
//!
//! The texel pass runs inside the vertex bake, bounce by bounce
//! ([`super::layers`]): bounce b of a texel traces its points' rays and
//! reads, at each hit, bounce b − 1 of the vertex bake (the same gather as a
//! vertex point, [`crate::bake::gather`]). Direct light and shadows are
//! resolved per texel; the interreflected light arriving at a texel is the
//! vertex bake's, which varies slowly.
//!
//! Points: `points_per_texel` per texel, shared among its footprint's
//! triangles by area (at least one each); within a triangle's part, a Sobol
//! point in the clipped polygon (a fan of triangles, picked by area). A
//! point's seed is the texel's and its index there, so the bytes do not
//! depend on the thread count.

use std::ops::Range;
use std::sync::Arc;

use glam::{DVec2, Vec2};
use rayon::prelude::*;

use super::normalise::{SourceRows, TexelRows};
use super::plan::Plan;
use super::run::{HitRecords, Pass, Point, Scratch, WaitingPoints};
use crate::atlas::coverage::{clip_to_texel, polygon_area, Coverage};
use crate::atlas::Atlas;
use crate::bake::enclosure::Sides;
use crate::bake::gather::RowBuffer;
use crate::bake::noise::{add_noise_in_quadrature, Moments, VertexDc};
use crate::bake::texel_lookup::TexelLookup;
use crate::bake::BakeParams;
use crate::sampling::{hash_seed, sample_2d, square_to_triangle, DirectionPattern};

const TAG_TEXEL_POSITION: u32 = 0x5054_0001;
const TAG_TEXEL_DIRECTION: u32 = 0x5054_0002;
/// Texels per parallel task.
const TEXELS_PER_TASK: usize = 64;

/// A texel's sample point: its triangle, barycentrics, and the footprint
/// area it stands for (in texels²).
#[derive(Clone, Copy, Debug)]
pub(crate) struct TexelPoint {
    pub(crate) triangle: u32,
    pub(crate) bary: [f32; 3],
    pub(crate) weight: f32,
}

/// Every covered texel's points (compressed rows in coverage order).
pub(crate) struct TexelPoints {
    pub(crate) start: Vec<u32>,
    pub(crate) points: Vec<TexelPoint>,
    /// Per texel, the index its first point here has among all of the
    /// texel's points (its direction seed counts from it); empty: 0.
    pub(crate) first_index: Vec<u32>,
}

impl TexelPoints {
    pub(crate) fn new(atlas: &Atlas, coverage: &Coverage, points_per_texel: u32, pattern: DirectionPattern, seed: u32) -> TexelPoints {
        let per_texel: Vec<Vec<TexelPoint>> =
            (0..coverage.len()).into_par_iter().map(|i| texel_points(atlas, coverage, i, points_per_texel, pattern, seed, 0..1)).collect();
        TexelPoints::from_rows(per_texel, Vec::new())
    }

    /// The extra points of texels whose points grow `factors[i]` times
    /// (`--texel-adaptive`): each footprint part's samples past the base
    /// ones, weighted as a share of the grown texel's.
    pub(crate) fn extra(
        atlas: &Atlas,
        coverage: &Coverage,
        points_per_texel: u32,
        pattern: DirectionPattern,
        seed: u32,
        factors: &[u32],
        base: &TexelPoints,
    ) -> TexelPoints {
        let per_texel: Vec<Vec<TexelPoint>> = (0..coverage.len())
            .into_par_iter()
            .map(|i| match factors[i] {
                0 | 1 => Vec::new(),
                k => texel_points(atlas, coverage, i, points_per_texel, pattern, seed, 1..k),
            })
            .collect();
        let first_index = base.start.windows(2).map(|w| w[1] - w[0]).collect();
        TexelPoints::from_rows(per_texel, first_index)
    }

    fn from_rows(rows: Vec<Vec<TexelPoint>>, first_index: Vec<u32>) -> TexelPoints {
        let mut start = Vec::with_capacity(rows.len() + 1);
        let mut points = Vec::new();
        start.push(0u32);
        for p in rows {
            points.extend(p);
            start.push(points.len() as u32);
        }
        TexelPoints { start, points, first_index }
    }

    pub(crate) fn len(&self) -> usize {
        self.points.len()
    }

    /// Each texel's base points then its extras, as one set; `order` maps
    /// each point of it to its place in `self` (< len) or in `extra`.
    fn joined(&self, extra: &TexelPoints) -> (TexelPoints, Vec<u32>) {
        let base_len = self.len() as u32;
        let mut start = Vec::with_capacity(self.start.len());
        let mut points = Vec::with_capacity(self.len() + extra.len());
        let mut order = Vec::with_capacity(self.len() + extra.len());
        start.push(0u32);
        for t in 0..self.start.len() - 1 {
            for p in self.start[t]..self.start[t + 1] {
                points.push(self.points[p as usize]);
                order.push(p);
            }
            for p in extra.start[t]..extra.start[t + 1] {
                points.push(extra.points[p as usize]);
                order.push(base_len + p);
            }
            start.push(points.len() as u32);
        }
        (TexelPoints { start, points, first_index: Vec::new() }, order)
    }
}

/// Covered texel `i`'s points: per footprint part of `c` base points (its
/// share of `points_per_texel` by area, at least one), samples
/// `multiples.start · c .. multiples.end · c` of the part's Sobol stream,
/// each standing for the part's area over `multiples.end · c`.
fn texel_points(
    atlas: &Atlas,
    coverage: &Coverage,
    i: usize,
    points_per_texel: u32,
    pattern: DirectionPattern,
    seed: u32,
    multiples: Range<u32>,
) -> Vec<TexelPoint> {
    let entries = coverage.start[i] as usize..coverage.start[i + 1] as usize;
    let texel = coverage.texels[i];
    let (x, y) = (texel % atlas.width, texel / atlas.width);
    let total: f32 = coverage.area[entries.clone()].iter().sum();
    let mut points = Vec::new();
    for e in entries {
        let t = coverage.triangle[e];
        let uv = atlas.triangle_uv(t as usize);
        let fan = Fan::of(&clip_to_texel(uv, x, y));
        let count = ((points_per_texel as f32 * coverage.area[e] / total).round() as u32).max(1);
        let weight = coverage.area[e] / (count * multiples.end) as f32;
        let stream = hash_seed(&[seed, TAG_TEXEL_POSITION, texel, t]);
        for k in count * multiples.start..count * multiples.end {
            let (u, v) = sample_2d(pattern, k, 0, stream);
            let p = fan.point(u, v);
            let bary = barycentric(uv, p);
            points.push(TexelPoint { triangle: t, bary, weight });
        }
    }
    points
}

/// A convex polygon as the fan of triangles from its first corner, each
/// with its area: built once per footprint part, sampled per point.
struct Fan {
    first: DVec2,
    triangles: Vec<(f64, [DVec2; 3])>,
    area: f64,
}

impl Fan {
    fn of(polygon: &[DVec2]) -> Fan {
        let triangles: Vec<(f64, [DVec2; 3])> = (1..polygon.len().saturating_sub(1))
            .map(|k| {
                let tri = [polygon[0], polygon[k], polygon[k + 1]];
                (polygon_area(&tri), tri)
            })
            .collect();
        let area = triangles.iter().map(|f| f.0).sum();
        Fan { first: polygon.first().copied().unwrap_or_default(), triangles, area }
    }

    /// The point at `(u, v)` of the unit square mapped into the polygon:
    /// `u` picks a triangle by area and is rescaled within it.
    fn point(&self, u: f32, v: f32) -> DVec2 {
        if self.triangles.is_empty() || self.area <= 0.0 {
            return self.first;
        }
        let mut target = u as f64 * self.area;
        let last = self.triangles.len() - 1;
        for (k, (area, tri)) in self.triangles.iter().enumerate() {
            if target <= *area || k == last {
                let u = (target / area.max(f64::MIN_POSITIVE)).clamp(0.0, 1.0) as f32;
                let b = square_to_triangle(u, v);
                return tri[0] * b[0] as f64 + tri[1] * b[1] as f64 + tri[2] * b[2] as f64;
            }
            target -= area;
        }
        self.first
    }
}

/// Barycentric coordinates of `p` in the atlas triangle `uv` (clamped into it).
fn barycentric(uv: [Vec2; 3], p: DVec2) -> [f32; 3] {
    let [a, b, c] = uv.map(|q| q.as_dvec2());
    let det = (b - a).perp_dot(c - a);
    if det == 0.0 {
        return [1.0 / 3.0; 3];
    }
    let l1 = (p - a).perp_dot(c - a) / det;
    let l2 = (b - a).perp_dot(p - a) / det;
    let w = [1.0 - l1 - l2, l1, l2].map(|x| x.max(0.0));
    let s: f64 = w.iter().sum();
    w.map(|x| (x / s) as f32)
}

/// One bounce of the texel pass over a range of texels (a shard's, or all):
/// per texel, the weighted sums of its points'
/// results (`pass.channels × pass.coeffs` each) and their weights; bounce 0
/// marks the points inside geometry in `rejected`, later bounces skip them.
/// With a hit cache, bounce 0 returns one hit record per ray of every point
/// in point order, and later bounces gather from them instead of tracing.
pub(crate) struct TexelSums {
    pub(crate) sums: Vec<f32>,
    pub(crate) weights: Vec<f32>,
    /// Per texel, its points' DC moments (the noise estimate).
    pub(crate) moments: Vec<Moments>,
    pub(crate) rays: u64,
    pub(crate) traced: u64,
    pub(crate) hits: Vec<u64>,
    /// Window mode's bounce 0: per texel, what its points met on each side,
    /// pooled into their enclosure verdict; else empty.
    pub(crate) sides: Vec<Sides>,
}

/// Traces (or gathers) the points of the covered texels `texels`.
/// `base_sides` (per texel of the range): what the texel's points traced
/// before met, pooled into these points' enclosure verdict (grown texels' extras).
pub(crate) fn run_texel_pass(
    pass: &Pass,
    points: &TexelPoints,
    texel_ids: &[u32],
    texels: Range<usize>,
    rejected: &mut [bool],
    base_sides: Option<&[Sides]>,
    progress: &crate::bake::progress::Progress,
) -> TexelSums {
    let bounce = pass.bounce;
    let stride = pass.channels * pass.coeffs;
    let first = texels.start;
    let texels = texels.len();
    type Task = (Vec<f32>, Vec<f32>, Vec<Moments>, Vec<u32>, u64, u64, Vec<u64>, Vec<Sides>);
    let tasks: Vec<Task> = (0..texels.div_ceil(TEXELS_PER_TASK))
        .into_par_iter()
        .map(|task| {
            let range = first + task * TEXELS_PER_TASK..first + ((task + 1) * TEXELS_PER_TASK).min(texels);
            let mut sums = vec![0.0f32; range.len() * stride];
            let mut weights = vec![0.0f32; range.len()];
            let mut moments = vec![Moments::default(); range.len()];
            let mut inside = Vec::new();
            let (mut rays, mut traced) = (0u64, 0u64);
            let mut result = vec![0.0f32; stride];
            let mut scratch = Scratch { basis: vec![0.0f32; pass.coeffs], ..Scratch::default() };
            let mut hits = Vec::with_capacity(pass.record_count((points.start[range.end] - points.start[range.start]) as usize));
            // Window mode's bounce 0: a texel's points wait, each side's light
            // apart, for the enclosure verdict pooled over the texel's points.
            let pool = pass.splits_sides(bounce);
            let mut waiting = WaitingPoints::new();
            let mut sides = Vec::new();
            // Adds a point's estimate, with its weight, to texel `local`.
            let mut add = |local: usize, weight: f32, back_dc: f32, result: &[f32]| {
                weights[local] += weight;
                moments[local].add(weight, result[0], back_dc);
                sums[local * stride..(local + 1) * stride].iter_mut().zip(result).for_each(|(s, r)| *s += weight * r);
            };
            for (local, texel) in range.clone().enumerate() {
                let first_index = points.first_index.get(texel).copied().unwrap_or(0);
                waiting.start(base_sides.map_or(Sides::default(), |base| base[texel - first]));
                for (k, p) in (points.start[texel]..points.start[texel + 1]).enumerate() {
                    if bounce > 0 && rejected[p as usize] {
                        continue;
                    }
                    result.fill(0.0);
                    let tp = points.points[p as usize];
                    if let Some(back_dc) = pass.gather_cached(p as u64, &mut result) {
                        rays += pass.params.rays as u64;
                        add(local, tp.weight, back_dc, &result);
                        continue;
                    }
                    let [ia, ib, ic] = pass.mesh.triangle(tp.triangle as usize);
                    let [pa, pb, pc] = pass.mesh.triangle_positions(tp.triangle as usize);
                    let [na, nb, nc] = [ia, ib, ic].map(|i| pass.mesh.normals[i as usize]);
                    let face_normal = pass.face_normal(tp.triangle);
                    let b = tp.bary;
                    let point = Point {
                        position: pa * b[0] + pb * b[1] + pc * b[2],
                        normal: (na * b[0] + nb * b[1] + nc * b[2]).normalize_or(face_normal),
                        face_normal,
                        seed: hash_seed(&[pass.params.seed, TAG_TEXEL_DIRECTION, texel_ids[texel], first_index + k as u32]),
                    };
                    result.fill(0.0);
                    let point_traced = pass.trace_point(&point, bounce, bounce == 0, &mut result, &mut scratch, &mut hits);
                    rays += pass.params.rays as u64;
                    traced += point_traced.rays;
                    if point_traced.inside {
                        inside.push(p);
                        continue;
                    }
                    if pool {
                        waiting.hold(tp.weight, point_traced, &scratch.side_light);
                        continue;
                    }
                    add(local, tp.weight, point_traced.back_dc, &result);
                }
                if pool {
                    waiting.release(pass, &mut result, |weight, traced, result| add(local, weight, traced.back_dc, result));
                    sides.push(waiting.sides);
                }
            }
            progress.add(rays);
            (sums, weights, moments, inside, rays, traced, hits, sides)
        })
        .collect();
    let mut out = TexelSums {
        sums: Vec::with_capacity(texels * stride),
        weights: Vec::with_capacity(texels),
        moments: Vec::with_capacity(texels),
        rays: 0,
        traced: 0,
        hits: Vec::new(),
        sides: Vec::new(),
    };
    for (sums, weights, moments, inside, rays, traced, hits, sides) in tasks {
        out.sides.extend(sides);
        out.sums.extend(sums);
        out.weights.extend(weights);
        out.moments.extend(moments);
        inside.into_iter().for_each(|p| rejected[p as usize] = true);
        out.rays += rays;
        out.traced += traced;
        out.hits.extend(hits);
    }
    out
}

/// A texel bake in progress: its receivers and points, what bounce 0 found
/// inside geometry, and the layers so far.
pub(crate) struct TexelState {
    pub(crate) texels: Vec<u32>,
    pub(crate) points: TexelPoints,
    pub(crate) rejected: Vec<bool>,
    pub(crate) weights: Vec<f32>,
    pub(crate) total: Vec<f32>,
    pub(crate) bounces: Vec<Vec<f32>>,
    /// Per texel, the standard error of its DC (channel 0), bounces added in quadrature.
    pub(crate) noise: Vec<f32>,
    /// Per texel, the DC that came through the back of its face (`bake::side_share`).
    pub(crate) back_dc: Vec<f32>,
    /// Per texel, its chart (that of its first triangle).
    pub(crate) chart: Vec<u32>,
    pub(crate) width: u32,
    /// Rays per texel point (`BakeParams::rays`; the vertices' plan may take fewer).
    pub(crate) rays_per_point: u32,
    /// `--texel-adaptive`: extra points, as a share of the base points,
    /// placed after bounce 0's base pass ([`super::texel_adaptive`]).
    pub(crate) adaptive: f32,
    /// Of `points`, those adaptive allocation added.
    pub(crate) points_added: u64,
    /// The atlas and its coverage, kept while extra points are still to be placed.
    footprints: Option<Box<(Atlas, Coverage)>>,
    points_per_texel: u32,
    pub(crate) rays: u64,
    pub(crate) traced: u64,
    /// Wall seconds of each bounce's texel pass.
    pub(crate) seconds: Vec<f64>,
    /// Bounce 0's hit records, one per ray of every point (empty: later
    /// bounces re-trace), as the vertices' hit cache.
    hits: Vec<u64>,
    /// Where hits read the texels; texels without light are dropped from it after bounce 0.
    lookup: Arc<TexelLookup>,
    /// The last bounce per texel, unwidened: what the next bounce gathers
    /// (split by side when `next_sides`).
    next: Option<RowBuffer>,
    next_sides: bool,
}

/// Grown texels (`--texel-adaptive`) until bounce 0 has traced them: the
/// base points as first placed, the extras, each texel's factor, and where
/// each point of the joined set came from (< base length: a base point).
pub(crate) struct Growth {
    base: TexelPoints,
    extra: TexelPoints,
    factors: Vec<u32>,
    order: Vec<u32>,
}

impl TexelState {
    /// The texels of `atlas` (`coverage`) with `points_per_texel` points of
    /// `params.rays` rays each, and `adaptive` × as many more where bounce
    /// 0 finds the most noise.
    pub(crate) fn new(atlas: &Atlas, coverage: &Coverage, points_per_texel: u32, adaptive: f32, params: &BakeParams) -> TexelState {
        let points = TexelPoints::new(atlas, coverage, points_per_texel, params.pattern, params.seed);
        let chart = texel_charts(atlas, coverage);
        TexelState {
            lookup: Arc::new(TexelLookup::new(atlas, &coverage.texels, &chart)),
            next: None,
            next_sides: false,
            seconds: Vec::new(),
            hits: Vec::new(),
            texels: coverage.texels.clone(),
            rejected: vec![false; points.len()],
            points,
            weights: Vec::new(),
            total: Vec::new(),
            bounces: Vec::new(),
            noise: Vec::new(),
            back_dc: Vec::new(),
            chart,
            width: atlas.width,
            rays_per_point: params.rays,
            adaptive,
            points_added: 0,
            footprints: (adaptive > 0.0).then(|| Box::new((atlas.clone(), coverage.clone()))),
            points_per_texel,
            rays: 0,
            traced: 0,
        }
    }

    /// The parameters of the texels' passes: the plan's, with the texels' rays per point.
    pub(crate) fn params(&self, plan: &Plan) -> BakeParams {
        BakeParams { rays: self.rays_per_point, ..*plan.params }
    }

    /// Bounce `bounce` of the texels, gathering from `source` (bounce − 1)
    /// like the plan's vertex pass. Bounce 0 records its hits when they fit
    /// the hit cache beside the vertices' `vertex_cache_bytes`; later bounces
    /// gather from them (same bytes as re-tracing). Returns its seconds.
    pub(crate) fn run_bounce(&mut self, plan: &Plan, source: &SourceRows, bounce: u32, vertex_cache_bytes: u64) -> f64 {
        let params = &self.params(plan);
        let cache_bytes = self.planned_points() * params.rays as u64 * 8;
        let record = bounce == 0 && params.bounces > 0 && cache_bytes + vertex_cache_bytes <= params.hit_cache_bytes;
        if bounce == 0 && params.bounces > 0 && !record && !params.quiet {
            eprintln!(
                "hit cache: the texels' {:.1} GiB do not fit beside the vertices' (--hit-cache-mib): their later bounces re-trace (same bytes, slower)",
                cache_bytes as f64 / (1u64 << 30) as f64
            );
        }
        let records = std::mem::take(&mut self.hits);
        let cached = (!records.is_empty()).then_some(HitRecords { records: &records, first_point: 0 });
        let mut pass = plan.pass(bounce, source, &[], cached, record);
        pass.params = params;
        self.run(&pass, plan.channels, params.store_bounces);
        if self.hits.is_empty() {
            self.hits = records;
        }
        self.seconds.last().copied().unwrap_or(0.0)
    }

    /// Runs bounce `pass.bounce` over the texels and adds its layer
    /// (widened to `channels`) to the total; keeps it when `store`.
    fn run(&mut self, pass: &Pass, channels: usize, store: bool) {
        let points = if pass.bounce == 0 { self.planned_points() } else { self.points.len() as u64 };
        let label = format!("texels, bounce {}/{}", pass.bounce, pass.params.bounces);
        let clock = std::time::Instant::now();
        let progress = crate::bake::progress::Progress::start(label, points * pass.params.rays as u64, pass.params.quiet);
        let mut sums = run_texel_pass(pass, &self.points, &self.texels, 0..self.texels.len(), &mut self.rejected, None, &progress);
        if pass.bounce == 0 && self.footprints.is_some() {
            let dc_sums = sums.sums.iter().step_by(pass.channels * pass.coeffs).map(|&s| f64::from(s)).collect();
            if let Some(growth) = self.grow(pass.mesh, &sums.weights, dc_sums, &sums.moments, pass.params) {
                let base_rejected = std::mem::replace(&mut self.rejected, vec![false; self.points.len()]);
                sums = self.trace_grown(pass, &growth, 0..self.texels.len(), Some((sums, base_rejected)), &progress);
            }
        }
        drop(progress);
        if !sums.hits.is_empty() {
            self.hits = std::mem::take(&mut sums.hits);
        }
        if pass.bounce == 0 {
            self.weights = sums.weights.clone();
            if let Some(lookup) = Arc::get_mut(&mut self.lookup) {
                lookup.drop_empty(&self.texels, &self.weights);
            }
        }
        if pass.bounce < pass.params.bounces {
            let stride = pass.channels * pass.coeffs;
            let mut rows = RowBuffer::zeroed(self.texels.len() * stride);
            super::normalise::normalise_rows(rows.as_mut_slice(), &sums.sums, &self.weights, stride);
            // Window mode: the next bounce reads the side of a face its ray meets.
            self.next_sides = pass.params.mode == crate::bake::Mode::Window;
            if self.next_sides {
                rows = super::normalise::split_sides(rows.as_slice(), &self.weights, &sums.moments, pass.channels, pass.coeffs);
            }
            self.next = Some(rows);
        }
        let sigma = VertexDc::new(&self.weights, &sums.sums, pass.channels * pass.coeffs, &sums.moments).standard_errors();
        add_noise_in_quadrature(&mut self.noise, &sigma);
        crate::bake::side_share::add_back_dc(&mut self.back_dc, &self.weights, &sums.moments);
        let layer = super::normalise::normalised_layer(&sums.sums, &self.weights, pass.channels, channels, pass.coeffs);
        if self.total.is_empty() {
            self.total = vec![0.0; layer.len()];
        }
        super::normalise::add_layer(&mut self.total, &layer);
        self.rays += sums.rays;
        self.traced += sums.traced;
        if store {
            self.bounces.push(layer);
        }
        self.seconds.push(clock.elapsed().as_secs_f64());
    }
}

impl TexelState {
    /// Points bounce 0 traces at most: the base points and the extras.
    fn planned_points(&self) -> u64 {
        let base = self.points.len() as u64 - self.points_added;
        if self.footprints.is_some() {
            base + (f64::from(self.adaptive) * base as f64) as u64
        } else {
            self.points.len() as u64
        }
    }

    /// `--texel-adaptive`: places the extra points by bounce 0's base sums
    /// per texel (Σ w, Σ w·DC and the DC moments: a whole bake's base pass,
    /// or a sharded bake's merged pilot) and makes the points one set, each
    /// texel's base points then its extras, which later bounces run over as
    /// they are. Returns what bounce 0 needs to trace the grown texels
    /// ([`TexelState::trace_grown`]); `None` when nothing grows.
    pub(crate) fn grow(
        &mut self,
        mesh: &crate::mesh::Mesh,
        weights: &[f32],
        dc_sums: Vec<f64>,
        moments: &[Moments],
        params: &BakeParams,
    ) -> Option<Growth> {
        let footprints = self.footprints.take()?;
        let (atlas, coverage) = &*footprints;
        let neighbours = same_chart_neighbours(&self.texels, self.width, &self.chart);
        let pilot = super::texel_adaptive::TexelPilot {
            weights,
            dc_sums,
            moments,
            counts: self.points.start.windows(2).map(|w| w[1] - w[0]).collect(),
            areas: texel_world_areas(mesh, atlas, coverage),
            neighbours: &neighbours,
        };
        let budget = (f64::from(self.adaptive) * self.points.len() as f64) as u64;
        let factors = super::texel_adaptive::factors(&pilot, budget);
        let extra = TexelPoints::extra(atlas, coverage, self.points_per_texel, params.pattern, params.seed, &factors, &self.points);
        if extra.len() == 0 {
            return None;
        }
        let (mut joined, order) = self.points.joined(&extra);
        // A grown texel's base points stand for its parts' areas over the grown counts, as its extras do.
        let base_len = self.points.len();
        for t in 0..self.texels.len() {
            let row = joined.start[t] as usize..joined.start[t + 1] as usize;
            let extras: Vec<(u32, f32)> = joined.points[row.clone()]
                .iter()
                .zip(&order[row.clone()])
                .filter(|(_, &o)| o as usize >= base_len)
                .map(|(p, _)| (p.triangle, p.weight))
                .collect();
            for (p, &o) in joined.points[row.clone()].iter_mut().zip(&order[row]) {
                if (o as usize) < base_len {
                    if let Some(&(_, w)) = extras.iter().find(|(t, _)| *t == p.triangle) {
                        p.weight = w;
                    }
                }
            }
        }
        self.points_added = extra.len() as u64;
        let base = std::mem::replace(&mut self.points, joined);
        Some(Growth { base, extra, factors, order })
    }

    /// Bounce 0 of grown texels over covered texels `range`: the base points
    /// with their own weights (`base`: already traced over the range, with
    /// the base points' verdicts; else traced here), then the extras; each
    /// texel's base sums scaled by 1 / its factor and its extras added, as
    /// the grown weights would sum them. Sets the joined points' verdicts
    /// of the range and returns their hit records in the joined order.
    pub(crate) fn trace_grown(
        &mut self,
        pass: &Pass,
        growth: &Growth,
        range: Range<usize>,
        base: Option<(TexelSums, Vec<bool>)>,
        progress: &crate::bake::progress::Progress,
    ) -> TexelSums {
        let (mut sums, base_rejected) = base.unwrap_or_else(|| {
            let mut rejected = vec![false; growth.base.len()];
            let sums = run_texel_pass(pass, &growth.base, &self.texels, range.clone(), &mut rejected, None, progress);
            (sums, rejected)
        });
        let mut extra_rejected = vec![false; growth.extra.len()];
        let base_sides = (!sums.sides.is_empty()).then_some(&sums.sides[..]);
        let extra = run_texel_pass(pass, &growth.extra, &self.texels, range.clone(), &mut extra_rejected, base_sides, progress);
        let stride = pass.channels * pass.coeffs;
        for (local, &k) in growth.factors[range.clone()].iter().enumerate() {
            let row = local * stride..(local + 1) * stride;
            if k > 1 {
                let share = 1.0 / k as f32;
                sums.sums[row.clone()].iter_mut().for_each(|s| *s *= share);
                sums.weights[local] *= share;
                sums.moments[local] = sums.moments[local].scaled(1.0 / f64::from(k));
            }
            sums.sums[row.clone()].iter_mut().zip(&extra.sums[row]).for_each(|(s, e)| *s += e);
            sums.weights[local] += extra.weights[local];
            sums.moments[local].merge(&extra.moments[local]);
        }
        sums.rays += extra.rays;
        sums.traced += extra.traced;
        let base_len = growth.base.len();
        let (base_first, extra_first) = (growth.base.start[range.start] as usize, growth.extra.start[range.start] as usize);
        let rays = pass.record_count(1);
        let joined = self.points.start[range.start] as usize..self.points.start[range.end] as usize;
        let mut hits = Vec::with_capacity(joined.len() * rays);
        for j in joined {
            let o = growth.order[j] as usize;
            let (rejected, records) = if o < base_len {
                (base_rejected[o], sums.hits.get((o - base_first) * rays..(o - base_first + 1) * rays))
            } else {
                let e = o - base_len;
                (extra_rejected[e], extra.hits.get((e - extra_first) * rays..(e - extra_first + 1) * rays))
            };
            self.rejected[j] = rejected;
            hits.extend_from_slice(records.unwrap_or_default());
        }
        sums.hits = hits;
        sums
    }

    /// What the next bounce gathers at hits on atlas triangles: this
    /// bounce's texels (once; `None` after the last bounce).
    pub(crate) fn take_source(&mut self) -> Option<TexelRows> {
        let sides = self.next_sides;
        self.next.take().map(|rows| TexelRows { lookup: Arc::clone(&self.lookup), rows, sides })
    }

    /// `--denoise K` over the texels ([`denoise_texels`]).
    pub(crate) fn denoise(&mut self, stride: usize, k: f32) {
        let rows = TexelRowsMut { total: &mut self.total, bounces: &mut self.bounces, noise: &mut self.noise };
        denoise_texels(&self.texels, self.width, &self.chart, &self.weights, rows, stride, k);
    }
}

/// A sharded bake's texels (each shard traces a range of them; see
/// `crate::shards`): the same points, passes and sums as a whole bake's.
impl TexelState {
    /// Each covered texel's cost, its points × rays (shards split the texels by it).
    pub(crate) fn costs(&self) -> Vec<u64> {
        self.points.start.windows(2).map(|w| (w[1] - w[0]) as u64 * self.rays_per_point as u64).collect()
    }

    /// The sample points of covered texels `texels`, as point indices.
    pub(crate) fn point_range(&self, texels: Range<usize>) -> Range<u64> {
        self.points.start[texels.start] as u64..self.points.start[texels.end] as u64
    }

    /// Bounce `pass.bounce` over covered texels `texels`, the sums left
    /// unnormalised for the merge; bounce 0 marks the points inside geometry.
    pub(crate) fn trace_range(&mut self, pass: &Pass, texels: Range<usize>, progress: &crate::bake::progress::Progress) -> TexelSums {
        run_texel_pass(pass, &self.points, &self.texels, texels, &mut self.rejected, None, progress)
    }

    /// What a later round gathers at hits on atlas triangles: the merged
    /// previous bounce (`rows`, normalised), read through the lookup without
    /// the texels bounce 0 left empty (`weights`), as a whole bake reads it.
    pub(crate) fn source_from_merged(&mut self, weights: &[f32], rows: &[f32], sides: bool) -> TexelRows {
        if let Some(lookup) = Arc::get_mut(&mut self.lookup) {
            lookup.drop_empty(&self.texels, weights);
        }
        let mut buffer = RowBuffer::zeroed(rows.len());
        buffer.as_mut_slice().copy_from_slice(rows);
        TexelRows { lookup: Arc::clone(&self.lookup), rows: buffer, sides }
    }
}

/// Each covered texel's footprint in world area: its parts' atlas areas
/// scaled by their triangles' world area over atlas area.
fn texel_world_areas(mesh: &crate::mesh::Mesh, atlas: &Atlas, coverage: &Coverage) -> Vec<f64> {
    let scale: Vec<f64> = (0..atlas.triangle_count())
        .map(|t| {
            let [a, b, c] = mesh.triangle_positions(t);
            let world = 0.5 * f64::from((b - a).cross(c - a).length());
            let uv = atlas.triangle_uv(t).map(|q| q.as_dvec2());
            let texels = polygon_area(&uv);
            if texels > 0.0 {
                world / texels
            } else {
                0.0
            }
        })
        .collect();
    (0..coverage.len())
        .map(|i| {
            (coverage.start[i] as usize..coverage.start[i + 1] as usize)
                .map(|e| f64::from(coverage.area[e]) * scale[coverage.triangle[e] as usize])
                .sum()
        })
        .collect()
}

/// Each covered texel's chart (that of its first triangle).
pub(crate) fn texel_charts(atlas: &Atlas, coverage: &Coverage) -> Vec<u32> {
    (0..coverage.len()).map(|i| atlas.triangle_chart[coverage.triangle[coverage.start[i] as usize] as usize]).collect()
}

/// Each covered texel's covered 8-neighbours in its own chart, as indices
/// into `texels` (ids `y * width + x`, ascending).
pub(crate) fn same_chart_neighbours(texels: &[u32], width: u32, chart: &[u32]) -> Vec<Vec<u32>> {
    let index_of = |id: u32| texels.binary_search(&id).ok();
    texels
        .iter()
        .enumerate()
        .map(|(i, &id)| {
            let (x, y) = ((id % width) as i64, (id / width) as i64);
            [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)]
                .iter()
                .map(|&(dx, dy)| (x + dx, y + dy))
                .filter(|&(u, v)| u >= 0 && v >= 0 && u < width as i64)
                .filter_map(|(u, v)| index_of((v * width as i64 + u) as u32))
                .filter(|&j| chart[j] == chart[i])
                .map(|j| j as u32)
                .collect()
        })
        .collect()
}

/// The rows `--denoise` filters in place.
pub(crate) struct TexelRowsMut<'a> {
    pub(crate) total: &'a mut [f32],
    pub(crate) bounces: &'a mut [Vec<f32>],
    pub(crate) noise: &'a mut Vec<f32>,
}

/// `--denoise K` over covered texels `texels` of an atlas `width` wide: the
/// vertices' filter ([`crate::bake::denoise`]) with each texel's 8
/// surrounding texels of its own chart as neighbours and its covered area
/// (`weights`) as its weight.
pub(crate) fn denoise_texels(texels: &[u32], width: u32, chart: &[u32], weights: &[f32], rows: TexelRowsMut, stride: usize, k: f32) {
    let n = texels.len();
    let pairs: Vec<(u32, u32)> = same_chart_neighbours(texels, width, chart)
        .into_iter()
        .enumerate()
        .flat_map(|(i, around)| around.into_iter().map(move |j| (i as u32, j)))
        .collect();
    let neighbours = crate::bake::denoise::Neighbours::from_pairs(n, pairs);
    crate::bake::denoise::filter_receivers(&neighbours, weights, |_, _| true, rows.total, rows.bounces, rows.noise, stride, k);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 24 × 24 texel grid, one channel, DC only: 0.5 plus noise of known σ
    /// left of x = 12 (lit), 0 right of it (a sharp shadow). `charts` gives
    /// each texel's chart.
    fn grid(charts: impl Fn(u32) -> u32) -> (TexelState, Vec<f32>) {
        let (w, sigma) = (24u32, 0.04f32);
        let mut gauss = crate::bake::denoise::tests::gaussian_stream(777);
        let texels: Vec<u32> = (0..w * w).collect();
        let lit = |id: u32| id % w < 12;
        let clean: Vec<f32> = texels.iter().map(|&id| if lit(id) { 0.5 } else { 0.0 }).collect();
        let total = texels.iter().map(|&id| clean[id as usize] + if lit(id) { sigma * gauss() } else { 0.0 }).collect();
        let noise = texels.iter().map(|&id| if lit(id) { sigma } else { 0.0 }).collect();
        let chart = texels.iter().map(|&id| charts(id)).collect();
        let n = texels.len();
        let state = TexelState {
            texels,
            points: TexelPoints { start: vec![0; n + 1], points: Vec::new(), first_index: Vec::new() },
            rejected: Vec::new(),
            weights: vec![1.0; n],
            total,
            bounces: Vec::new(),
            noise,
            back_dc: Vec::new(),
            chart,
            width: w,
            rays_per_point: 1,
            adaptive: 0.0,
            points_added: 0,
            footprints: None,
            points_per_texel: 1,
            rays: 0,
            traced: 0,
            lookup: Arc::new(TexelLookup::empty()),
            next: None,
            next_sides: false,
            seconds: Vec::new(),
            hits: Vec::new(),
        };
        (state, clean)
    }

    /// The texel denoiser lowers the noise on the lit side by more than 2×
    /// and leaves the shadow edge where it is, within one texel: every texel
    /// one or more texels from the edge keeps its side.
    #[test]
    fn the_denoiser_keeps_a_sharp_shadow_edge_within_one_texel() {
        let (mut state, clean) = grid(|_| 0);
        let rms = |values: &[f32]| {
            let far: Vec<usize> = (0..values.len()).filter(|&i| (i as u32 % 24) < 10).collect();
            (far.iter().map(|&i| (values[i] - clean[i]).powi(2)).sum::<f32>() / far.len() as f32).sqrt()
        };
        let before = rms(&state.total);
        state.denoise(1, 2.0);
        let after = rms(&state.total);
        assert!(before > 0.03 && after < before / 2.0, "rms {before} → {after}");
        for (i, &v) in state.total.iter().enumerate() {
            let x = i as u32 % 24;
            if x <= 10 {
                assert!(v > 0.35, "lit texel {i} fell to {v}");
            }
            if x >= 13 {
                assert!(v < 0.05, "shadowed texel {i} rose to {v}");
            }
        }
    }

    /// Texels of two charts are never averaged, however alike their values.
    #[test]
    fn the_denoiser_does_not_cross_charts() {
        let (mut state, _) = grid(|id| u32::from(id / 24 >= 12));
        // Rows 12 on are another chart at a constant 0.3, as noise-free.
        for i in 12 * 24..24 * 24 {
            state.total[i] = 0.3;
            state.noise[i] = 0.0;
        }
        let before: Vec<f32> = state.total[12 * 24..].to_vec();
        state.denoise(1, 100.0);
        // Averaging equal values may round in the last bit; mixing with the first chart (0 to 0.5) would not.
        assert!(state.total[12 * 24..].iter().zip(&before).all(|(a, b)| (a - b).abs() < 1e-6), "the second chart changed");
    }
}
