//! Sun-shadow bitmasks for a day's time lapse (Callieri et al. 2006, the
//! Parthenon demo, seed 001 §4–§5; DESIGN.md "Sun masks").
//!
//! For each time step k with the sun toward unit `s_k`, vertex v gets bit k
//! set when
//! 1. the step is a day step (the caller passes `None` for night steps),
//! 2. open mode: `n_v · s_k > 0` with `n_v` the vertex (shading) normal;
//!    window mode skips this test (it is two-sided, like its transfer), and
//! 3. the sun reaches the surface around v: of the interior samples of v's
//!    adjacent triangles (the same points the transfer bake uses), weighted
//!    as the transfer weights them (hat value for v times the area a sample
//!    stands for), a strict majority see the sun.
//!
//! A sample sees the sun when (open mode) its interpolated shading normal
//! faces the sun and a ray toward `s_k`, from the sample pushed off its
//! surface by [`Scene::offset_origin`] (relative to scene scale), escapes; in
//! window mode, when the first thing the ray hits is a window.
//!
//! Why samples and a vote rather than one ray from the vertex: a vertex
//! slightly covered by an overlapping triangle would be dark at every step,
//! and a vertex on a crease would start its ray on the wrong side of a
//! neighbour. The vote decides from the surface around the vertex, so one
//! bad neighbour cannot flip it. Vertices with no sample (only window or
//! degenerate triangles around them) get 0.
//!
//! Bits pack into u32 words, step k in word k/32, bit k%32
//! ([`crate::bundle::SunSeries::masks`]). Every sample's bits depend on that
//! sample alone and each vertex's vote sums in a fixed order, so the masks do
//! not depend on the thread count.

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use super::enclosure::{side_is_outside, Sides, SIDE_PROBE_RAYS};
use super::progress::Progress;
use super::receivers::{point_weights, Adjacency, Receivers};
use super::surfaces::Surfaces;
use super::transfer::{interior_layout, sampled_triangles, triangle_area, triangle_sample, InteriorLayout};
use super::{BakeError, DirectionPattern, Mode};
use crate::mesh::Mesh;
use crate::trace::scene::Scene;

/// Largest step count (1,024 steps = 32 words per vertex), as [`crate::sky::MAX_STEPS`].
pub const MAX_SUN_STEPS: usize = crate::sky::MAX_STEPS;

/// Triangles per parallel tracing task.
const TRIANGLES_PER_TASK: usize = 256;
/// Vertices per parallel voting task.
const VERTICES_PER_TASK: usize = 4096;

/// Which loop runs outside when tracing a task's points.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum LoopOrder {
    /// For each step, every point of the task: consecutive rays share a
    /// direction and start close together (coherent).
    StepOuter,
    /// For each point, every step.
    PointOuter,
}

/// Parameters of a sun-mask bake.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct SunParams {
    /// Open (escape = lit, one-sided) or window (first hit a window = lit, two-sided).
    pub mode: Mode,
    /// Interior samples per vertex on average (spread by area in rotation triples, ≥ 3 per triangle).
    pub samples_per_vertex: f32,
    /// At most this many samples per triangle.
    pub max_per_triangle: u32,
    /// Seed of the sample placement (the transfer bake's `seed` gives the same points).
    pub seed: u32,
    /// Window mode: a sample also sees the sun through glass from a side of
    /// its face outside the enclosure (`enclosure`; off by default: such a
    /// side, probed with 32 rays the first time the sun reaches it through
    /// glass, stays dark, as the transfer bake's does).
    pub keep_outside_sides: bool,
    /// Loop nesting while tracing (the masks are the same either way; not stored).
    #[serde(skip)]
    pub loop_order: LoopOrder,
    /// Test the triangle that blocked the previous ray first ([`Scene::occluded_cached`];
    /// open mode; the masks are the same either way; not stored).
    #[serde(skip)]
    pub shadow_cache: bool,
    /// Step-outer, open mode: trace each step's rays in packets of nearby
    /// points ([`Scene::occluded_parallel`], which keeps the shadow cache;
    /// the masks are the same either way; not stored).
    #[serde(skip)]
    pub packets: bool,
    /// No progress line on stderr (never stored).
    #[serde(skip)]
    pub quiet: bool,
}

impl Default for SunParams {
    fn default() -> Self {
        SunParams {
            mode: Mode::Open,
            samples_per_vertex: 2.0,
            max_per_triangle: 256,
            seed: 1,
            keep_outside_sides: false,
            loop_order: LoopOrder::StepOuter,
            shadow_cache: true,
            packets: true,
            quiet: true,
        }
    }
}

impl SunParams {
    /// Checks ranges; called by [`bake_sun_masks`].
    pub fn check(&self) -> Result<(), BakeError> {
        if !(self.samples_per_vertex > 0.0 && self.samples_per_vertex.is_finite()) || self.max_per_triangle == 0 {
            return Err(BakeError::Params("sun masks need a positive sample density".into()));
        }
        Ok(())
    }
}

/// What a sun-mask bake measured.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct SunStats {
    pub triangles: u64,
    pub vertices: u64,
    /// Interior sample points.
    pub points: u64,
    pub steps: u64,
    /// Steps with the sun above the horizon.
    pub day_steps: u64,
    /// Vertices no sample reached: their bits are 0.
    pub vertices_without_samples: u64,
    /// Lit vertices per step.
    pub lit_vertices: Vec<u64>,
    /// Rays traced (points facing away from the sun, and night steps, trace none).
    pub rays: u64,
    pub seconds: f64,
    pub rays_per_second: f64,
}

/// Baked masks in the layout of [`crate::bundle::SunSeries::masks`].
#[derive(Clone, Debug, PartialEq)]
pub struct SunMasks {
    /// `ceil(steps / 32)`.
    pub words_per_vertex: u32,
    /// Vertex-major words: vertex v, step k is bit `k % 32` of word `v · words_per_vertex + k / 32`.
    pub masks: Vec<u32>,
    pub stats: SunStats,
}

impl SunMasks {
    /// Whether `vertex` is lit at `step`.
    pub fn bit(&self, vertex: usize, step: usize) -> bool {
        let w = self.words_per_vertex as usize;
        (self.masks[vertex * w + step / 32] >> (step % 32)) & 1 == 1
    }
}

/// A sample point of the bake.
#[derive(Clone, Copy)]
pub(crate) struct Point {
    pub(crate) position: Vec3,
    /// Interpolated shading normal (the facing test, open mode).
    pub(crate) normal: Vec3,
    /// Geometric normal (the origin offset).
    pub(crate) face_normal: Vec3,
}

impl Point {
    /// The point at barycentrics `b` of triangle `t`.
    pub(crate) fn on_triangle(mesh: &Mesh, scene: &Scene, t: usize, b: [f32; 3]) -> Point {
        let [pa, pb, pc] = mesh.triangle_positions(t);
        let [na, nb, nc] = mesh.triangle(t).map(|i| mesh.normals[i as usize]);
        let face_normal = scene.face_normal(t as u32);
        Point {
            position: pa * b[0] + pb * b[1] + pc * b[2],
            normal: (na * b[0] + nb * b[1] + nc * b[2]).normalize_or(face_normal),
            face_normal,
        }
    }
}

/// Bakes a sun bit per vertex and step.
///
/// `suns[k]` is the unit direction toward the sun at step k in the world
/// frame, or `None` when the sun is below the horizon (all bits of that step
/// are 0). Runs on the current rayon pool; no I/O.
///
/// Errors: bad parameters, a step count outside `1..=1024`, a day
/// direction that is not finite and non-zero, or a mesh on which no
/// triangle receives light ([`super::NothingToBake`]).
pub fn bake_sun_masks(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    suns: &[Option<Vec3>],
    params: &SunParams,
) -> Result<SunMasks, BakeError> {
    let started = Instant::now();
    let plan = SunPlan::new(mesh, surfaces, suns, params)?;
    let (sample_bits, rays) = plan.trace_items(scene, surfaces, 0..plan.layout.triangles.len());
    plan.masks_from_bits(&sample_bits, rays, started)
}

/// [`bake_sun_masks`], and per vertex the steps whose vote was split
/// ([`SunPlan::vote_all`]): where adaptive refinement (`crate::refine`)
/// finds shadow edges that pass between a vertex's samples.
pub(crate) fn bake_sun_masks_split(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    suns: &[Option<Vec3>],
    params: &SunParams,
) -> Result<(SunMasks, Vec<u32>), BakeError> {
    let started = Instant::now();
    let plan = SunPlan::new(mesh, surfaces, suns, params)?;
    let (sample_bits, rays) = plan.trace_items(scene, surfaces, 0..plan.layout.triangles.len());
    plan.vote_all(&sample_bits, rays, started)
}

/// What a partial sun re-bake keeps: earlier masks and split votes (one
/// row per vertex of the new mesh) and the vertices whose rows stay.
pub(crate) struct SunKept<'a> {
    pub(crate) vertices: &'a [bool],
    pub(crate) masks: &'a SunMasks,
    pub(crate) split_votes: &'a [u32],
}

/// Re-bakes the sun masks of the vertices not kept (adaptive refinement,
/// `crate::refine`): traces only the samples of the triangles flagged in
/// `receivers` (which must hold every triangle around those vertices) and
/// keeps the others' words.
pub(crate) fn bake_sun_masks_update(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    suns: &[Option<Vec3>],
    params: &SunParams,
    receivers: &[bool],
    kept: &SunKept,
) -> Result<(SunMasks, Vec<u32>), BakeError> {
    let started = Instant::now();
    let plan = SunPlan::new(mesh, surfaces, suns, params)?;
    let items = &plan.layout.triangles;
    let mut runs: Vec<std::ops::Range<usize>> = Vec::new();
    for item in (0..items.len()).filter(|&i| receivers[items[i] as usize]) {
        match runs.last_mut() {
            Some(run) if run.end == item => run.end += 1,
            _ => runs.push(item..item + 1),
        }
    }
    let (traced, rays) = plan.trace_item_runs(scene, surfaces, &runs);
    let mut sample_bits = vec![0u32; plan.layout.sample_count() as usize * plan.words];
    if let Some(first) = runs.first() {
        let base = plan.layout.first_sample[first.start] as usize * plan.words;
        sample_bits[base..base + traced.len()].copy_from_slice(&traced);
    }
    let (mut masks, mut split) = plan.vote_all(&sample_bits, rays, started)?;
    let words = plan.words;
    for v in (0..mesh.vertex_count()).filter(|&v| kept.vertices[v]) {
        masks.masks[v * words..(v + 1) * words].copy_from_slice(&kept.masks.masks[v * words..(v + 1) * words]);
        split[v * words..(v + 1) * words].copy_from_slice(&kept.split_votes[v * words..(v + 1) * words]);
    }
    let mut sampled = vec![false; mesh.vertex_count()];
    for &t in items {
        mesh.triangle(t as usize).iter().for_each(|&v| sampled[v as usize] = true);
    }
    masks.stats.vertices_without_samples = sampled.iter().filter(|&&s| !s).count() as u64;
    masks.stats.lit_vertices =
        (0..suns.len()).map(|k| masks.masks.chunks_exact(words).filter(|w| (w[k / 32] >> (k % 32)) & 1 == 1).count() as u64).collect();
    Ok((masks, split))
}

/// The masks of a sharded sun bake from its shards' sample bits put end to
/// end (`shards::merge_sun_parts`): the vote a whole bake runs, with
/// the stats of a bake that traced `rays`.
pub fn sun_masks_from_bits(
    mesh: &Mesh,
    surfaces: &Surfaces,
    suns: &[Option<Vec3>],
    params: &SunParams,
    sample_bits: &[u32],
    rays: u64,
) -> Result<SunMasks, BakeError> {
    SunPlan::new(mesh, surfaces, suns, params)?.masks_from_bits(sample_bits, rays, Instant::now())
}

/// The day's directions made unit, after checking the step count (1 to
/// [`MAX_SUN_STEPS`]) and that each day direction is finite and non-zero.
pub(crate) fn checked_suns(suns: &[Option<Vec3>]) -> Result<Vec<Option<Vec3>>, BakeError> {
    if suns.is_empty() || suns.len() > MAX_SUN_STEPS {
        return Err(BakeError::Params(format!("{} sun steps, allowed 1..={MAX_SUN_STEPS}", suns.len())));
    }
    suns.iter()
        .enumerate()
        .map(|(k, s)| match s {
            None => Ok(None),
            Some(d) => d
                .try_normalize()
                .map(Some)
                .ok_or_else(|| BakeError::Params(format!("sun direction of step {k} is {d:?}, not a usable direction"))),
        })
        .collect()
}

/// What a sun bake's tracing and voting share: the checked day and where
/// the samples go. A whole bake and each of its shards (`shards`)
/// build it the same way.
pub(crate) struct SunPlan<'a> {
    mesh: &'a Mesh,
    params: &'a SunParams,
    /// Unit directions toward the sun, `None` at night.
    suns: Vec<Option<Vec3>>,
    pub(crate) layout: InteriorLayout,
    /// Mask words per sample and per vertex.
    pub(crate) words: usize,
}

impl<'a> SunPlan<'a> {
    /// Checks the parameters and the day (see [`bake_sun_masks`]) and places the samples.
    pub(crate) fn new(mesh: &'a Mesh, surfaces: &Surfaces, suns: &[Option<Vec3>], params: &'a SunParams) -> Result<SunPlan<'a>, BakeError> {
        params.check()?;
        let suns = checked_suns(suns)?;
        let layout = interior_layout(mesh, sampled_triangles(mesh, surfaces)?, params.samples_per_vertex, params.max_per_triangle);
        super::transfer::check_point_count(layout.sample_count())?;
        Ok(SunPlan { mesh, params, words: suns.len().div_ceil(32), suns, layout })
    }

    fn day_steps(&self) -> u64 {
        self.suns.iter().filter(|s| s.is_some()).count() as u64
    }

    /// Sample points of each layout item, in item order (what a shard's share is measured in).
    pub(crate) fn points_per_item(&self) -> &[u32] {
        &self.layout.counts
    }

    /// Traces the samples of the layout items in `range` toward every day
    /// step: `words` bits per sample, in sample order, each task writing its
    /// own slice. Returns the bits and the rays traced.
    pub(crate) fn trace_items(&self, scene: &Scene, surfaces: &Surfaces, range: std::ops::Range<usize>) -> (Vec<u32>, u64) {
        self.trace_item_runs(scene, surfaces, std::slice::from_ref(&range))
    }

    /// [`SunPlan::trace_items`] over ascending, disjoint runs of items: the
    /// bits of the samples from the first run's first item to the last
    /// run's end, zero for the items between runs (not traced).
    pub(crate) fn trace_item_runs(&self, scene: &Scene, surfaces: &Surfaces, runs: &[std::ops::Range<usize>]) -> (Vec<u32>, u64) {
        let layout = &self.layout;
        let words = self.words;
        let day_steps = self.day_steps();
        let first_point = |item: usize| layout.first_sample.get(item).map_or(layout.sample_count() as usize, |&f| f as usize);
        let (base, end) = match (runs.first(), runs.last()) {
            (Some(first), Some(last)) => (first_point(first.start), first_point(last.end)),
            _ => (0, 0),
        };
        let mut sample_bits = vec![0u32; (end - base) * words];
        let glass = Glass::for_sun(self.mesh, surfaces, self.params);
        let test = SunTest { scene, surfaces, params: self.params, glass: glass.as_ref() };
        let tracer = Tracer { mesh: self.mesh, test, layout, suns: &self.suns, words };
        let points: u64 = runs.iter().flat_map(|r| &layout.counts[r.clone()]).map(|&c| c as u64).sum();
        let progress = Progress::start("sun".into(), points * day_steps, self.params.quiet);
        let mut tasks = Vec::new();
        let mut rest: &mut [u32] = &mut sample_bits;
        let mut rest_start = base;
        for range in runs {
            for start in range.clone().step_by(TRIANGLES_PER_TASK) {
                let end = (start + TRIANGLES_PER_TASK).min(range.end);
                let (_, tail) = rest.split_at_mut((first_point(start) - rest_start) * words);
                let (mine, others) = tail.split_at_mut((first_point(end) - first_point(start)) * words);
                rest = others;
                rest_start = first_point(end);
                tasks.push((start, end, mine));
            }
        }
        let rays: u64 = tasks
            .into_par_iter()
            .map(|(start, end, out)| {
                let rays = tracer.trace_task(start, end, out);
                progress.add(layout.counts[start..end].iter().map(|&c| c as u64).sum::<u64>() * day_steps);
                rays
            })
            .sum();
        drop(progress);
        (sample_bits, rays)
    }

    /// The masks from every sample's bits (all items' samples, in sample
    /// order: a whole bake's, or its shards' put end to end), with the
    /// stats of a bake that traced `rays` and started at `started`.
    pub(crate) fn masks_from_bits(&self, sample_bits: &[u32], rays: u64, started: Instant) -> Result<SunMasks, BakeError> {
        Ok(self.vote_all(sample_bits, rays, started)?.0)
    }

    /// [`SunPlan::masks_from_bits`], and per vertex (same layout) the steps
    /// whose vote was split: some samples around the vertex saw the sun and
    /// some did not (a shadow edge crosses its one-ring), facing vertices only.
    pub(crate) fn vote_all(&self, sample_bits: &[u32], rays: u64, started: Instant) -> Result<(SunMasks, Vec<u32>), BakeError> {
        let (words, mesh, params) = (self.words, self.mesh, self.params);
        let point_count = self.layout.sample_count() as usize;
        if sample_bits.len() != point_count * words {
            return Err(BakeError::Params(format!(
                "{} sample words, but {point_count} samples of {words} word(s) are baked",
                sample_bits.len()
            )));
        }
        // Vote: each receiver sums its samples' weights in adjacency order.
        let receivers = Receivers::vertices(mesh);
        let adjacency = Adjacency::build(&receivers, &self.layout.triangles);
        let weights = self.sample_weights();
        let vertex_count = receivers.count();
        let mut masks = vec![0u32; vertex_count * words];
        let mut split = vec![0u32; vertex_count * words];
        let without: u64 = masks
            .par_chunks_mut(VERTICES_PER_TASK * words)
            .zip(split.par_chunks_mut(VERTICES_PER_TASK * words))
            .enumerate()
            .map(|(chunk, (out, split_out))| {
                let first = chunk * VERTICES_PER_TASK;
                let mut lit_weight = vec![0.0f32; self.suns.len()];
                let mut without = 0u64;
                for (local, (vertex_words, split_words)) in out.chunks_exact_mut(words).zip(split_out.chunks_exact_mut(words)).enumerate() {
                    let v = first + local;
                    let total = self.vote(v, &adjacency, &weights, sample_bits, &mut lit_weight);
                    if total <= 0.0 {
                        without += 1;
                        continue;
                    }
                    let normal = receivers.normal(v);
                    for (k, sun) in self.suns.iter().enumerate() {
                        let Some(s) = sun else { continue };
                        let facing = params.mode == Mode::Window || normal.dot(*s) > 0.0;
                        if facing && 2.0 * lit_weight[k] > total {
                            vertex_words[k / 32] |= 1 << (k % 32);
                        }
                        if facing && lit_weight[k] > 0.0 && lit_weight[k] < total {
                            split_words[k / 32] |= 1 << (k % 32);
                        }
                    }
                }
                without
            })
            .sum();

        let lit_vertices =
            (0..self.suns.len()).map(|k| masks.chunks_exact(words).filter(|w| (w[k / 32] >> (k % 32)) & 1 == 1).count() as u64).collect();
        let seconds = started.elapsed().as_secs_f64();
        let stats = SunStats {
            triangles: mesh.triangle_count() as u64,
            vertices: vertex_count as u64,
            points: point_count as u64,
            steps: self.suns.len() as u64,
            day_steps: self.day_steps(),
            vertices_without_samples: without,
            lit_vertices,
            rays,
            seconds,
            rays_per_second: rays as f64 / seconds.max(1e-9),
        };
        Ok((SunMasks { words_per_vertex: words as u32, masks, stats }, split))
    }

    /// Barycentrics of sample `s` of layout item `item`.
    #[inline]
    fn barycentrics(&self, item: usize, s: u32) -> [f32; 3] {
        sample_barycentrics(self.mesh, self.params, &self.layout, item, s)
    }

    /// Each sample's weights toward its triangle's three corners, in sample order.
    fn sample_weights(&self) -> Vec<[f32; 3]> {
        let layout = &self.layout;
        (0..layout.triangles.len())
            .into_par_iter()
            .flat_map_iter(|item| {
                let (count, area) = (layout.counts[item], triangle_area(self.mesh, layout.triangles[item]));
                (0..count).map(move |s| point_weights(self.barycentrics(item, s), area, count))
            })
            .collect()
    }

    /// Sums, for vertex `v`, the weight of its samples that see the sun at
    /// each step into `lit_weight` (overwritten); returns the total weight.
    /// The weights are the transfer's (hat value times the area a sample
    /// stands for), so the vote estimates whether the sunlit part of the
    /// hat-weighted one-ring is a majority, whatever the sample counts.
    fn vote(&self, v: usize, adjacency: &Adjacency, weights: &[[f32; 3]], sample_bits: &[u32], lit_weight: &mut [f32]) -> f32 {
        lit_weight.fill(0.0);
        let mut total = 0.0f32;
        for &(item, corner) in adjacency.of(v) {
            let item = item as usize;
            let first = self.layout.first_sample[item] as usize;
            for s in 0..self.layout.counts[item] {
                let w = weights[first + s as usize][corner as usize];
                total += w;
                let bits = &sample_bits[(first + s as usize) * self.words..][..self.words];
                for (word_index, &word) in bits.iter().enumerate() {
                    let mut word = word;
                    while word != 0 {
                        let bit = word.trailing_zeros() as usize;
                        lit_weight[word_index * 32 + bit] += w;
                        word &= word - 1;
                    }
                }
            }
        }
        total
    }
}

/// Barycentrics of sample `s` of layout item `item`: the transfer bake's points.
#[inline]
fn sample_barycentrics(mesh: &Mesh, params: &SunParams, layout: &InteriorLayout, item: usize, s: u32) -> [f32; 3] {
    let t = layout.triangles[item];
    triangle_sample(DirectionPattern::Sobol, params.seed, t, mesh.triangle(t as usize), s)
}

/// Shared read-only state of the tracing pass.
struct Tracer<'a> {
    mesh: &'a Mesh,
    test: SunTest<'a>,
    layout: &'a InteriorLayout,
    suns: &'a [Option<Vec3>],
    words: usize,
}

impl Tracer<'_> {
    /// Barycentrics of sample `s` of layout item `item`.
    #[inline]
    fn barycentrics(&self, item: usize, s: u32) -> [f32; 3] {
        sample_barycentrics(self.mesh, self.test.params, self.layout, item, s)
    }

    /// Traces the samples of layout items `start..end` at every day step into
    /// `out` (`words` per sample, in sample order). Returns the rays traced.
    fn trace_task(&self, start: usize, end: usize, out: &mut [u32]) -> u64 {
        // Place the task's points once.
        let mut points = Vec::with_capacity(out.len() / self.words.max(1));
        for item in start..end {
            let t = self.layout.triangles[item] as usize;
            for s in 0..self.layout.counts[item] {
                points.push(Point::on_triangle(self.mesh, self.test.scene, t, self.barycentrics(item, s)));
            }
        }
        let words = self.words;
        let mut rays = 0u64;
        // Window mode: whether each side of each point is outside, once probed.
        let mut sides = vec![[None; 2]; points.len()];
        // One shadow-cache entry per task: the leaf that blocked the previous ray.
        let mut hint = u32::MAX;
        match self.test.params.loop_order {
            LoopOrder::StepOuter => {
                let mut scratch = SunScratch::new(points.len());
                let mut lit = vec![false; points.len()];
                for (k, sun) in self.suns.iter().enumerate() {
                    let Some(s) = *sun else { continue };
                    rays += self.test.sees_sun_each(&points, s, &mut sides, &mut scratch, &mut lit);
                    for (p, _) in lit.iter().enumerate().filter(|(_, &l)| l) {
                        out[p * words + k / 32] |= 1 << (k % 32);
                    }
                }
            }
            LoopOrder::PointOuter => {
                for (p, point) in points.iter().enumerate() {
                    for (k, sun) in self.suns.iter().enumerate() {
                        let Some(s) = *sun else { continue };
                        let (lit, traced) = self.test.sees_sun(point, s, &mut hint, &mut sides[p]);
                        rays += traced as u64;
                        if lit {
                            out[p * words + k / 32] |= 1 << (k % 32);
                        }
                    }
                }
            }
        }
        rays
    }
}

/// The test of one point against one sun direction, shared by the
/// vertices' samples and the texels' (`bake::texel_sun`).
#[derive(Clone, Copy)]
pub(crate) struct SunTest<'a> {
    pub(crate) scene: &'a Scene,
    pub(crate) surfaces: &'a Surfaces,
    pub(crate) params: &'a SunParams,
    /// Window mode with packets: the glass as a scene of its own ([`Glass`]).
    pub(crate) glass: Option<&'a Glass>,
}

/// Window mode's glass as a scene of its own. A point sees the sun through
/// a window when the first glass along its ray lets light through and
/// nothing opaque lies nearer: the first glass here (one closest hit on a
/// small tree), then an occlusion test of the whole scene short of it,
/// which packets answer ([`Scene::occluded_parallel_each`]).
pub(crate) struct Glass {
    scene: Scene,
    /// Glass-scene triangle → mesh triangle.
    mesh_triangle: Vec<u32>,
}

impl Glass {
    /// The glass of `mesh` (its window triangles), when the sun test would
    /// take packets through it (window mode, step-outer with the shadow
    /// cache and packets on); `None` otherwise or without glass.
    pub(crate) fn for_sun(mesh: &Mesh, surfaces: &Surfaces, params: &SunParams) -> Option<Glass> {
        if params.mode != Mode::Window || !params.packets || !params.shadow_cache {
            return None;
        }
        let triangles: Vec<u32> =
            (0..mesh.triangle_count() as u32).filter(|&t| surfaces.window_transmittance[t as usize].is_some()).collect();
        if triangles.is_empty() {
            return None;
        }
        let glass = Mesh {
            positions: mesh.positions.clone(),
            normals: mesh.normals.clone(),
            uvs: Vec::new(),
            lightmap_uvs: Vec::new(),
            colors: Vec::new(),
            indices: triangles.iter().flat_map(|&t| mesh.triangle(t as usize)).collect(),
            tri_material: triangles.iter().map(|&t| mesh.tri_material[t as usize]).collect(),
            tri_group: triangles.iter().map(|&t| mesh.tri_group[t as usize]).collect(),
            materials: mesh.materials.clone(),
            groups: mesh.groups.clone(),
        };
        let scene = Scene::build(&glass, crate::trace::BuildQuality::Sah).ok()?;
        Some(Glass { scene, mesh_triangle: triangles })
    }
}

/// The shadow cache and buffers of [`SunTest::sees_sun_each`], kept from
/// step to step over one set of points.
pub(crate) struct SunScratch {
    /// Per point, the leaf triangle that last blocked its ray (`u32::MAX` = none).
    point_hints: Vec<u32>,
    /// The leaf that blocked the previous ray (one ray at a time), or the
    /// last blocker found (packets: the hint of points that have none).
    lone_hint: u32,
    facing: Vec<u32>,
    origins: Vec<Vec3>,
    hints: Vec<u32>,
    blocked: Vec<bool>,
    /// Window mode: each ray's reach, short of its first glass.
    reach: Vec<f32>,
}

impl SunScratch {
    pub(crate) fn new(points: usize) -> SunScratch {
        SunScratch {
            point_hints: vec![u32::MAX; points],
            lone_hint: u32::MAX,
            facing: Vec::new(),
            origins: Vec::new(),
            hints: Vec::new(),
            blocked: Vec::new(),
            reach: Vec::new(),
        }
    }
}

impl SunTest<'_> {
    /// [`SunTest::sees_sun`] of every point toward unit `s`, into `lit`
    /// (same length); returns the rays traced. `sides` holds each point's
    /// verdicts (window mode). Open mode with packets on traces the facing
    /// points' rays as packets of consecutive points (a task's points lie
    /// close together, [`Scene::occluded_parallel`]); each ray's hint is
    /// the triangle that blocked its point at an earlier step, else the
    /// last blocker found in the task. The answers are the same as one ray
    /// at a time.
    pub(crate) fn sees_sun_each(
        &self,
        points: &[Point],
        s: Vec3,
        sides: &mut [[Option<bool>; 2]],
        scratch: &mut SunScratch,
        lit: &mut [bool],
    ) -> u64 {
        assert!(points.len() == lit.len() && points.len() == scratch.point_hints.len(), "one answer and one hint per point");
        if let (Mode::Window, Some(glass)) = (self.params.mode, self.glass) {
            return self.sees_sun_through_glass(glass, points, s, sides, scratch, lit);
        }
        if self.params.mode != Mode::Open || !self.params.packets || !self.params.shadow_cache {
            let mut rays = 0u64;
            for (p, point) in points.iter().enumerate() {
                let (sees, traced) = self.sees_sun(point, s, &mut scratch.lone_hint, &mut sides[p]);
                lit[p] = sees;
                rays += u64::from(traced);
            }
            return rays;
        }
        let SunScratch { point_hints, facing, origins, hints, blocked, lone_hint, .. } = scratch;
        facing.clear();
        origins.clear();
        hints.clear();
        lit.fill(false);
        for (p, point) in points.iter().enumerate().filter(|(_, point)| point.normal.dot(s) > 0.0) {
            facing.push(p as u32);
            origins.push(self.scene.offset_origin(point.position, point.face_normal, s));
            hints.push(if point_hints[p] == u32::MAX { *lone_hint } else { point_hints[p] });
        }
        blocked.resize(origins.len(), false);
        self.scene.occluded_parallel(origins, s, f32::INFINITY, hints, blocked);
        for ((&p, &b), &h) in facing.iter().zip(blocked.iter()).zip(hints.iter()) {
            lit[p as usize] = !b;
            point_hints[p as usize] = h;
            if h != u32::MAX {
                *lone_hint = h;
            }
        }
        facing.len() as u64
    }

    /// [`SunTest::sees_sun_each`] in window mode with packets: per point,
    /// its first glass (`glass`), then the whole scene's occlusion short of
    /// it in packets (each ray its own reach, the shadow cache as in open
    /// mode); the side verdicts as [`SunTest::sees_sun`]. The rays counted
    /// are the lone test's (one per point, and the side probes). A blocker
    /// that is itself glass (the two trees' distances to one pane can differ
    /// by rounding) sends its point to the lone test.
    fn sees_sun_through_glass(
        &self,
        glass: &Glass,
        points: &[Point],
        s: Vec3,
        sides: &mut [[Option<bool>; 2]],
        scratch: &mut SunScratch,
        lit: &mut [bool],
    ) -> u64 {
        let SunScratch { point_hints, facing, origins, hints, blocked, lone_hint, reach } = scratch;
        let tau = &self.surfaces.window_transmittance;
        facing.clear();
        origins.clear();
        hints.clear();
        reach.clear();
        lit.fill(false);
        for (p, point) in points.iter().enumerate() {
            let origin = self.scene.offset_origin(point.position, point.face_normal, s);
            let Some(hit) = glass.scene.closest_hit(origin, s, f32::INFINITY) else { continue };
            if !tau[glass.mesh_triangle[hit.triangle as usize] as usize].is_some_and(|t| t > 0.0) {
                continue;
            }
            facing.push(p as u32);
            origins.push(origin);
            reach.push(hit.t.next_down());
            hints.push(if point_hints[p] == u32::MAX { *lone_hint } else { point_hints[p] });
        }
        blocked.resize(origins.len(), false);
        self.scene.occluded_parallel_each(origins, s, reach, hints, blocked);
        let mut rays = points.len() as u64;
        for (((&p, &b), &h), &origin) in facing.iter().zip(blocked.iter()).zip(hints.iter()).zip(origins.iter()) {
            let (p, point) = (p as usize, &points[p as usize]);
            let by_glass = b && self.scene.mesh_triangle_of_leaf(h).is_some_and(|t| tau[t as usize].is_some());
            if b && !by_glass {
                point_hints[p] = h;
                *lone_hint = h;
            }
            let through = if by_glass { self.first_hit_is_clear_glass(origin, s) } else { !b };
            if !through {
                continue;
            }
            let (inside, probes) = self.side_inside(point, s, &mut sides[p]);
            rays += u64::from(probes);
            lit[p] = inside;
        }
        rays
    }

    /// Whether `point` sees the sun toward unit `s`, and the rays traced.
    /// `sides` holds the point's verdicts on its sides (window mode).
    #[inline]
    pub(crate) fn sees_sun(&self, point: &Point, s: Vec3, hint: &mut u32, sides: &mut [Option<bool>; 2]) -> (bool, u32) {
        match self.params.mode {
            Mode::Open => {
                if point.normal.dot(s) <= 0.0 {
                    return (false, 0);
                }
                let origin = self.scene.offset_origin(point.position, point.face_normal, s);
                let blocked = if self.params.shadow_cache {
                    self.scene.occluded_cached(origin, s, f32::INFINITY, hint)
                } else {
                    self.scene.occluded(origin, s, f32::INFINITY)
                };
                (!blocked, 1)
            }
            Mode::Window => {
                let origin = self.scene.offset_origin(point.position, point.face_normal, s);
                if !self.first_hit_is_clear_glass(origin, s) {
                    return (false, 1);
                }
                let (inside, probes) = self.side_inside(point, s, sides);
                (inside, 1 + probes)
            }
        }
    }

    /// Window mode: whether the first hit from `origin` along `s` is glass
    /// that lets light through (one closest hit).
    #[inline]
    fn first_hit_is_clear_glass(&self, origin: Vec3, s: Vec3) -> bool {
        let tau = &self.surfaces.window_transmittance;
        self.scene.closest_hit(origin, s, f32::INFINITY).is_some_and(|hit| tau[hit.triangle as usize].is_some_and(|t| t > 0.0))
    }

    /// Window mode, a point whose ray toward `s` leaves through glass:
    /// whether its light counts (the side it looks from is inside, or
    /// `--keep-outside-sides`), and the probe rays its side took the first
    /// time it was asked (`sides` keeps the verdicts).
    #[inline]
    fn side_inside(&self, point: &Point, s: Vec3, sides: &mut [Option<bool>; 2]) -> (bool, u32) {
        if self.params.keep_outside_sides {
            return (true, 0);
        }
        let side = Sides::of(point.face_normal, s);
        let probed = sides[side].is_none();
        let outside =
            *sides[side].get_or_insert_with(|| side_is_outside(self.scene, self.surfaces, point.position, point.face_normal, side));
        (!outside, if probed { SIDE_PROBE_RAYS } else { 0 })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Material;
    use crate::trace::{BuildQuality, Scene};

    /// Window mode's packets against its lone test (the first hit is glass)
    /// at a point inside each opaque triangle of `mesh` for eight suns: the
    /// same verdict for every point, but where an opaque surface and the
    /// first glass lie within the scene's tie distance along the ray (the
    /// lone closest hit counts them as one surface and picks by facing and
    /// index; the packets ask whether anything opaque lies before the
    /// glass). Returns the lit point-steps and the ties.
    fn window_packets_against_lone(mesh: &Mesh, window: &str) -> (usize, usize) {
        let surfaces = Surfaces::resolve(mesh, &[window.to_string()]).unwrap();
        let scene = Scene::build(mesh, BuildQuality::Sah).unwrap();
        let params = SunParams { mode: Mode::Window, ..SunParams::default() };
        let glass = Glass::for_sun(mesh, &surfaces, &params).expect("the mesh has glass");
        let packets = SunTest { scene: &scene, surfaces: &surfaces, params: &params, glass: Some(&glass) };
        let lone = SunTest { glass: None, ..packets };
        let points: Vec<Point> = (0..mesh.triangle_count())
            .filter(|&t| surfaces.window_transmittance[t].is_none())
            .map(|t| Point::on_triangle(mesh, &scene, t, [0.5, 0.3, 0.2]))
            .collect();
        let (mut lit, mut ties) = (0usize, 0usize);
        for k in 0..8 {
            let a = k as f32 * 0.8;
            let s = Vec3::new(a.cos(), 0.3 + 0.08 * k as f32, a.sin()).normalize();
            let mut sides = vec![[None; 2]; points.len()];
            let mut scratch = SunScratch::new(points.len());
            let mut answers = vec![false; points.len()];
            let rays = packets.sees_sun_each(&points, s, &mut sides, &mut scratch, &mut answers);
            let mut lone_sides = vec![[None; 2]; points.len()];
            let (mut lone_rays, mut hint, mut step_ties) = (0u64, u32::MAX, 0);
            for (p, point) in points.iter().enumerate() {
                let (sees, traced) = lone.sees_sun(point, s, &mut hint, &mut lone_sides[p]);
                lone_rays += u64::from(traced);
                lit += usize::from(sees);
                if sees != answers[p] {
                    // A tie: the nearest opaque surface (brute force, f64)
                    // within the scene's tie distance of the first glass,
                    // where the lone closest hit counts the two as one
                    // surface and picks by facing and index.
                    let origin = scene.offset_origin(point.position, point.face_normal, s);
                    let t_glass = glass.scene.closest_hit(origin, s, f32::INFINITY).unwrap().t as f64;
                    let (o, d) = (origin.as_dvec3(), s.as_dvec3());
                    let nearest_opaque = (0..mesh.triangle_count())
                        .filter(|&t| surfaces.window_transmittance[t].is_none())
                        .filter_map(|t| {
                            let [a, b, c] = mesh.triangle_positions(t).map(|v| v.as_dvec3());
                            let (e1, e2) = (b - a, c - a);
                            let pv = d.cross(e2);
                            let det = e1.dot(pv);
                            let tv = o - a;
                            let (u, qv) = (tv.dot(pv) / det, tv.cross(e1));
                            let (v, t) = (d.dot(qv) / det, e2.dot(qv) / det);
                            (det != 0.0 && u >= -1e-6 && v >= -1e-6 && u + v <= 1.0 + 1e-6 && t > 0.0).then_some(t)
                        })
                        .fold(f64::INFINITY, f64::min);
                    assert!(
                        (nearest_opaque - t_glass).abs() <= 1.01 * scene.tie_distance as f64,
                        "point {p}, sun {k}: lone {sees}, packets {}: glass at {t_glass}, nearest opaque at {nearest_opaque}, tie {}",
                        answers[p],
                        scene.tie_distance
                    );
                    step_ties += 1;
                }
            }
            if step_ties == 0 {
                assert_eq!(rays, lone_rays, "sun {k}: the rays counted as the lone test counts them");
            }
            ties += step_ties;
        }
        (lit, ties)
    }

    #[test]
    fn window_packets_agree_with_the_lone_first_hit_test() {
        let (mesh, _) = crate::fixtures::cabin::generate_cabin(10.0);
        let (lit, ties) = window_packets_against_lone(&mesh, "glass");
        assert!(lit > 1000 && ties == 0, "{lit} lit point-steps, {ties} ties");
    }

    /// The same on the Ferrari (window `Glass_Gray`), whose glass meets its
    /// frames: ties occur, and every differing verdict is one.
    #[test]
    fn window_packets_agree_with_the_lone_test_on_the_ferrari_but_for_ties() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/car-ferrari458/ferrari_nodraco.glb");
        if !path.exists() {
            eprintln!("skipped: {} is absent", path.display());
            return;
        }
        let mesh = crate::mesh::load_mesh(&path, &crate::mesh::LoadOptions::default()).unwrap().mesh;
        let (lit, ties) = window_packets_against_lone(&mesh, "Glass_Gray");
        eprintln!("Ferrari: {lit} lit point-steps, {ties} ties");
        assert!(lit > 10_000 && ties * 1000 < lit, "{lit} lit point-steps, {ties} ties");
    }

    /// A unit-square grid in the XZ plane at height y, normal ±Y.
    fn floor(n: u32, y: f32, up: bool) -> Mesh {
        let mut b = crate::fixtures::builder::MeshBuilder::new(vec![Material::opaque("grey", 0.5)]);
        let (u, v) = if up { (Vec3::Z, Vec3::X) } else { (Vec3::X, Vec3::Z) };
        b.grid("floor", Vec3::new(-0.5, y, -0.5), u, v, n, n, |_, _| 0);
        b.mesh
    }

    fn bake(mesh: &Mesh, suns: &[Option<Vec3>], mode: Mode) -> SunMasks {
        bake_with(mesh, suns, &SunParams { mode, ..SunParams::default() })
    }

    fn bake_with(mesh: &Mesh, suns: &[Option<Vec3>], params: &SunParams) -> SunMasks {
        let surfaces = Surfaces::resolve(mesh, &[]).unwrap();
        let scene = Scene::build(mesh, BuildQuality::Sah).unwrap();
        bake_sun_masks(mesh, &scene, &surfaces, suns, params).unwrap()
    }

    /// An open floor under a high sun: every vertex lit; sun below the horizon
    /// (None) or behind the surface (n·s ≤ 0): every vertex dark.
    #[test]
    fn open_floor_is_lit_only_by_a_sun_in_front() {
        let mesh = floor(8, 0.0, true);
        assert!(mesh.normals.iter().all(|n| n.y > 0.99));
        let suns = [Some(Vec3::new(0.3, 1.0, 0.2)), None, Some(Vec3::new(0.3, -1.0, 0.0)), Some(Vec3::X)];
        let m = bake(&mesh, &suns, Mode::Open);
        for v in 0..mesh.vertex_count() {
            assert!(m.bit(v, 0));
            assert!(!m.bit(v, 1) && !m.bit(v, 2) && !m.bit(v, 3), "vertex {v}");
        }
        assert_eq!(m.stats.lit_vertices, vec![mesh.vertex_count() as u64, 0, 0, 0]);
        assert_eq!(m.stats.day_steps, 3);
    }

    #[test]
    fn step_counts_outside_1_to_1024_are_refused() {
        let mesh = floor(2, 0.0, true);
        let surfaces = Surfaces::resolve(&mesh, &[]).unwrap();
        let scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
        let p = SunParams::default();
        assert!(bake_sun_masks(&mesh, &scene, &surfaces, &[], &p).is_err());
        assert!(bake_sun_masks(&mesh, &scene, &surfaces, &vec![None; 1025], &p).is_err());
        assert!(bake_sun_masks(&mesh, &scene, &surfaces, &[Some(Vec3::ZERO)], &p).is_err());
        let m = bake_sun_masks(&mesh, &scene, &surfaces, &vec![Some(Vec3::Y); 1024], &p).unwrap();
        assert_eq!(m.words_per_vertex, 32);
        assert!(m.masks.iter().all(|&w| w == u32::MAX));
    }

    /// Window mode: a floor under a window pane, the sun overhead. Vertices
    /// under the pane are lit whichever way the floor faces; vertices whose
    /// ray escapes past the pane are dark (a crack lets no light in).
    #[test]
    fn window_mode_is_two_sided_and_needs_the_window() {
        for up in [true, false] {
            let mut mesh = floor(10, 0.0, up);
            let mut pane = crate::fixtures::builder::MeshBuilder::new(vec![Material {
                role: crate::mesh::MaterialRole::Window,
                ..Material::opaque("glass", 0.0)
            }]);
            pane.grid("pane", Vec3::new(-0.25, 0.5, -0.25), Vec3::Z * 0.5, Vec3::X * 0.5, 2, 2, |_, _| 0);
            crate::verify::shapes::append(&mut mesh, &pane.mesh);
            let floor_vertices = 121;
            // A pane over an open floor: no enclosure, so outside sides are kept.
            let params = SunParams { mode: Mode::Window, keep_outside_sides: true, ..SunParams::default() };
            let m = bake_with(&mesh, &[Some(Vec3::Y)], &params);
            for v in 0..floor_vertices {
                let p = mesh.positions[v];
                let inside = p.x.abs() < 0.2 && p.z.abs() < 0.2;
                let outside = p.x.abs() > 0.3 || p.z.abs() > 0.3;
                if inside {
                    assert!(m.bit(v, 0), "vertex {v} at {p} under the pane (floor up {up})");
                }
                if outside {
                    assert!(!m.bit(v, 0), "vertex {v} at {p} outside the pane (floor up {up})");
                }
            }
        }
    }

    /// The window halo in sun masks: in the closed room of
    /// `room_with_pane_outside_opening`, a low sun in front of the pane
    /// reaches the floor through the opening and, through the pane from
    /// behind, the front wall's outer face. With the enclosure rule no
    /// front-wall vertex is lit (its outer side sees open sky and glass, its
    /// inner side cannot see the sun through the pane); every other vertex
    /// keeps its bit, and the floor has a lit patch.
    #[test]
    fn sun_through_a_pane_does_not_light_the_outer_face_of_its_wall() {
        let (mesh, wall) = crate::verify::shapes::room_with_pane_outside_opening();
        let suns = [Some(Vec3::new(0.1, 0.6, -1.0).normalize()), Some(Vec3::new(-0.2, 0.3, -1.0).normalize())];
        let window = SunParams { mode: Mode::Window, ..SunParams::default() };
        let rule = bake_with(&mesh, &suns, &window);
        let kept = bake_with(&mesh, &suns, &SunParams { keep_outside_sides: true, ..window });
        for k in 0..suns.len() {
            let lit_wall = |m: &SunMasks| wall.clone().filter(|&v| m.bit(v, k)).count();
            assert!(lit_wall(&kept) > 0, "step {k}: the fixture no longer shows the halo");
            assert_eq!(lit_wall(&rule), 0, "step {k}");
            let floor_lit = (0..mesh.vertex_count()).filter(|&v| !wall.contains(&v) && rule.bit(v, k)).count();
            assert!(floor_lit > 0, "step {k}: the sun no longer enters the room");
            for v in (0..mesh.vertex_count()).filter(|v| !wall.contains(v)) {
                assert_eq!(rule.bit(v, k), kept.bit(v, k), "step {k}, vertex {v} at {}", mesh.positions[v]);
            }
            eprintln!("step {k}: front wall lit {} -> 0 vertices, room lit {floor_lit}", lit_wall(&kept));
        }
    }

    /// Sun masks for a floor that is all window or all degenerate are
    /// refused like its transfer bake: no vertex could ever be lit.
    #[test]
    fn masks_where_no_triangle_receives_light_are_refused() {
        let mut glass = floor(2, 0.0, true);
        glass.materials[0].role = crate::mesh::MaterialRole::Window;
        let mut collapsed = floor(2, 0.0, true);
        collapsed.positions.iter_mut().for_each(|p| *p = Vec3::ZERO);
        for (mesh, reason) in [(glass, "every triangle is a window"), (collapsed, "triangles are degenerate (zero area)")] {
            let surfaces = Surfaces::resolve(&mesh, &[]).unwrap();
            let scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
            let refused = bake_sun_masks(&mesh, &scene, &surfaces, &[Some(Vec3::Y)], &SunParams::default()).err().expect("refused");
            assert!(matches!(refused, BakeError::NothingToBake(_)), "{refused:?}");
            assert!(refused.to_string().contains(reason), "{refused}");
        }
    }

    /// Sun masks are scale-free like the transfer: a floor with a cover,
    /// scaled by a power of two to just under the extent limit, gets the
    /// same bits as at unit scale. Past the limit the scene the sun pass
    /// needs is refused.
    #[test]
    fn masks_up_to_the_extent_limit_match_unit_scale_and_larger_scenes_are_refused() {
        let mut mesh = floor(8, 0.0, true);
        let mut cover = floor(2, 0.2, true);
        crate::verify::shapes::transform(&mut cover, 0.4, Vec3::ZERO);
        crate::verify::shapes::append(&mut mesh, &cover);
        let suns: Vec<Option<Vec3>> = (0..12).map(|k| Some(Vec3::new((k as f32 * 0.5).cos(), 0.4 + 0.1 * k as f32, 0.3))).collect();
        let unit = bake(&mesh, &suns, Mode::Open);
        let scale = (2.0f32).powi((crate::trace::MAX_SCENE_EXTENT / mesh.diagonal()).log2().floor() as i32);
        let mut big = mesh.clone();
        crate::verify::shapes::transform(&mut big, scale, Vec3::ZERO);
        assert!(big.diagonal() > crate::trace::MAX_SCENE_EXTENT / 2.0);
        let at_limit = bake(&big, &suns, Mode::Open);
        assert!(unit.masks.iter().any(|&w| w != 0) && unit.masks.iter().any(|&w| w != (1 << 12) - 1));
        assert_eq!(unit.masks, at_limit.masks);
        crate::verify::shapes::transform(&mut big, 1e11, Vec3::ZERO);
        let refused = Scene::build(&big, BuildQuality::Sah).err().expect("refused").to_string();
        assert!(refused.contains("rescale the model"), "{refused}");
    }

    /// A vertex covered by a small overlapping triangle just above it: a ray
    /// from the vertex is blocked, the vote of its surrounding samples is not.
    #[test]
    fn a_slightly_covered_vertex_keeps_its_sun() {
        let mut mesh = floor(4, 0.0, true);
        let centre = mesh.positions.iter().position(|p| p.x.abs() < 1e-6 && p.z.abs() < 1e-6).unwrap();
        let mut cover = floor(1, 2e-3, true);
        crate::verify::shapes::transform(&mut cover, 0.05, Vec3::ZERO);
        crate::verify::shapes::append(&mut mesh, &cover);
        let m = bake(&mesh, &[Some(Vec3::new(0.1, 1.0, 0.0))], Mode::Open);
        assert!(m.bit(centre, 0));
    }
}
