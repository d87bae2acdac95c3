//! Sun-shadow bits per texel of a lightmap atlas (texel mode's `sun`): one
//! bit per covered texel and time step, where a vertex's bit cannot draw a
//! 3 cm slat shadow on a 4 m wall.
//!
//! A texel's bit at step k is set when a strict majority of its points,
//! each weighted by the footprint area it stands for, see the sun: the
//! texel's own points of the transfer bake (`bake::transfer::texels`, the
//! same seed gives the same points), each tested as a vertex's sample is
//! ([`super::sun::SunTest`]: open mode, facing by the point's shading normal
//! and a ray that escapes; window mode, a first hit on glass from a side
//! inside the enclosure). So the shadow edge is placed within the texel
//! whose footprint it crosses. Points on window triangles are not traced
//! (glass is drawn by its own pass).
//!
//! As the vertices' bits, a texel's bits depend on its points alone and its
//! vote sums in point order: the bits do not depend on the thread count.

use std::ops::Range;
use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use super::progress::Progress;
use super::sun::{checked_suns, Point, SunParams, SunScratch, SunTest};
use super::transfer::texels::TexelPoints;
use super::{BakeError, DirectionPattern, Surfaces};
use crate::atlas::coverage::Coverage;
use crate::atlas::density::ChartDetail;
use crate::atlas::Atlas;
use crate::mesh::Mesh;
use crate::trace::scene::Scene;

/// Texels per parallel task: a task's rays start close together in the
/// atlas, and its shadow cache serves them all.
const TEXELS_PER_TASK: usize = 256;

/// What a texel sun bake measured.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct TexelSunStats {
    /// Covered texels, and the points traced for them (window triangles' left out).
    pub texels: u64,
    pub points: u64,
    pub points_per_texel: u32,
    /// Lit texels per step.
    pub lit_texels: Vec<u64>,
    pub rays: u64,
    pub seconds: f64,
}

/// Sun bits per covered texel, in the layout of the vertices' masks.
#[derive(Clone, Debug, PartialEq)]
pub struct TexelSunMasks {
    /// The covered texels (`y * width + x`, ascending), one row of words each.
    pub texels: Vec<u32>,
    /// `ceil(steps / 32)`.
    pub words_per_texel: u32,
    /// Texel-major words: texel i, step k is bit `k % 32` of word `i · words_per_texel + k / 32`.
    pub masks: Vec<u32>,
    /// The share of each texel's footprint whose points see the sun, in
    /// sixteenths of 15 (0 = none, 15 = all): texel-major, `ceil(steps / 8)`
    /// words a texel, step k in bits `4 (k % 8)` of word `k / 8`.
    pub fractions: Vec<u32>,
    pub stats: TexelSunStats,
}

/// Largest value of a texel's sun fraction (4 bits: 0..=15).
pub const FRACTION_MAX: u32 = 15;

/// Words of 4-bit fractions per texel for `steps` steps.
pub fn fraction_words(steps: usize) -> usize {
    steps.div_ceil(8)
}

impl TexelSunMasks {
    /// Whether covered texel `i` (an index into `texels`) is lit at `step`.
    pub fn bit(&self, i: usize, step: usize) -> bool {
        let w = self.words_per_texel as usize;
        (self.masks[i * w + step / 32] >> (step % 32)) & 1 == 1
    }

    /// The lit share of covered texel `i` at `step`, 0..=1 in steps of 1/15.
    pub fn fraction(&self, i: usize, step: usize) -> f32 {
        let w = self.fractions.len() / self.texels.len().max(1);
        ((self.fractions[i * w + step / 8] >> (4 * (step % 8))) & 0xF) as f32 / FRACTION_MAX as f32
    }
}

/// A pilot texel sun bake's measure of each chart for
/// [`crate::atlas::density`]: the squared error of one value per texel is,
/// at each step, the variance of the lit indicator over the texel's
/// footprint, `f (1 − f)` for a lit share `f` (0 where the texel is wholly
/// lit or dark); the value is the lit share (the indicator squared).
/// `masks` are of `atlas`, over `steps` steps.
pub fn sun_chart_detail(masks: &TexelSunMasks, atlas: &Atlas, steps: usize) -> ChartDetail {
    let coverage = Coverage::of(atlas);
    ChartDetail::from_texels(atlas, &coverage, |i| {
        let Ok(k) = masks.texels.binary_search(&coverage.texels[i]) else { return (0.0, 0.0) };
        (0..steps).map(|s| f64::from(masks.fraction(k, s))).fold((0.0, 0.0), |(e, v), f| (e + f * (1.0 - f), v + f))
    })
}

/// Bakes a sun bit per covered texel of `atlas` (unwrapped from `mesh`) and
/// step, from `points_per_texel` points per texel placed with `pattern` and
/// `params.seed` (the transfer bake's points when they are the same).
/// `suns` as [`super::bake_sun_masks`] takes them.
pub fn bake_texel_sun_masks(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    atlas: &Atlas,
    points_per_texel: u32,
    pattern: DirectionPattern,
    suns: &[Option<Vec3>],
    params: &SunParams,
) -> Result<TexelSunMasks, BakeError> {
    let started = Instant::now();
    let plan = TexelSunPlan::new(mesh, atlas, points_per_texel, pattern, suns, params)?;
    let traced = plan.trace(mesh, scene, surfaces, 0..plan.texel_count());
    Ok(plan.finish(traced, started.elapsed().as_secs_f64()))
}

/// Lit texels at each of `steps` steps, from texel-major masks.
pub fn lit_counts(masks: &[u32], steps: usize) -> Vec<u64> {
    let words = steps.div_ceil(32);
    (0..steps).map(|k| masks.chunks_exact(words).filter(|w| (w[k / 32] >> (k % 32)) & 1 == 1).count() as u64).collect()
}

/// A texel sun bake made ready: the covered texels and their points, the
/// same in every process that makes it from the same mesh, atlas and seed,
/// so shards can each trace a range of texels ([`TexelSunPlan::trace`]).
pub struct TexelSunPlan {
    coverage: Coverage,
    points: TexelPoints,
    points_per_texel: u32,
    suns: Vec<Option<Vec3>>,
    params: SunParams,
}

/// A range of texels traced (or every shard's ranges joined): their rows of
/// [`TexelSunMasks::masks`] and [`TexelSunMasks::fractions`], the points
/// traced and the rays.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TexelSunRange {
    pub masks: Vec<u32>,
    pub fractions: Vec<u32>,
    pub points: u64,
    pub rays: u64,
}

impl TexelSunPlan {
    pub fn new(
        mesh: &Mesh,
        atlas: &Atlas,
        points_per_texel: u32,
        pattern: DirectionPattern,
        suns: &[Option<Vec3>],
        params: &SunParams,
    ) -> Result<TexelSunPlan, BakeError> {
        params.check()?;
        let suns = checked_suns(suns)?;
        super::texels::check_texel_inputs(mesh, atlas, points_per_texel)?;
        let coverage = Coverage::of(atlas);
        let points = TexelPoints::new(atlas, &coverage, points_per_texel, pattern, params.seed);
        Ok(TexelSunPlan { coverage, points, points_per_texel, suns, params: *params })
    }

    /// The covered texels (`y * width + x`, ascending).
    pub fn texels(&self) -> &[u32] {
        &self.coverage.texels
    }

    pub fn texel_count(&self) -> usize {
        self.coverage.len()
    }

    /// Mask words per texel (`ceil(steps / 32)`) and fraction words per texel.
    pub fn words(&self) -> (usize, usize) {
        (self.suns.len().div_ceil(32), fraction_words(self.suns.len()))
    }

    /// What tracing each texel costs: its points times the day's steps.
    pub fn costs(&self) -> Vec<u64> {
        let day_steps = self.suns.iter().filter(|s| s.is_some()).count() as u64;
        self.points.start.windows(2).map(|w| (w[1] - w[0]) as u64 * day_steps).collect()
    }

    /// The bits and fractions of covered texels `range`. A texel's bits
    /// depend on its own points alone, so any split of the texels into
    /// ranges gives the same rows.
    pub fn trace(&self, mesh: &Mesh, scene: &Scene, surfaces: &Surfaces, range: Range<usize>) -> TexelSunRange {
        let (words, fwords) = self.words();
        let (suns, points) = (&self.suns, &self.points);
        let day_steps = suns.iter().filter(|s| s.is_some()).count() as u64;
        let glass = super::sun::Glass::for_sun(mesh, surfaces, &self.params);
        let test = SunTest { scene, surfaces, params: &self.params, glass: glass.as_ref() };
        let point_count = (points.start[range.end] - points.start[range.start]) as u64;
        let progress = Progress::start("sun, texels".into(), point_count * day_steps, self.params.quiet);
        let mut masks = vec![0u32; range.len() * words];
        let mut fractions = vec![0u32; range.len() * fwords];
        let (rays, traced_points): (u64, u64) = masks
            .par_chunks_mut(TEXELS_PER_TASK * words)
            .zip(fractions.par_chunks_mut(TEXELS_PER_TASK * fwords))
            .enumerate()
            .map(|(task, (out, fraction_out))| {
                let first = range.start + task * TEXELS_PER_TASK;
                let texels = first..(first + TEXELS_PER_TASK).min(range.end);
                let span = points.start[texels.start] as usize..points.start[texels.end] as usize;
                // The task's points, with the texel each belongs to; window triangles' left out.
                let mut task_points = Vec::with_capacity(span.len());
                let mut owner = Vec::with_capacity(span.len());
                let mut weight = Vec::with_capacity(span.len());
                for texel in texels.clone() {
                    for p in &points.points[points.start[texel] as usize..points.start[texel + 1] as usize] {
                        if surfaces.window_transmittance[p.triangle as usize].is_some() {
                            continue;
                        }
                        task_points.push(Point::on_triangle(mesh, scene, p.triangle as usize, p.bary));
                        owner.push((texel - first) as u32);
                        weight.push(p.weight);
                    }
                }
                let mut total = vec![0.0f32; texels.len()];
                owner.iter().zip(&weight).for_each(|(&o, &w)| total[o as usize] += w);
                let mut sides = vec![[None; 2]; task_points.len()];
                let mut lit = vec![0.0f32; texels.len()];
                let mut rays = 0u64;
                let mut scratch = SunScratch::new(task_points.len());
                let mut sees = vec![false; task_points.len()];
                for (k, sun) in suns.iter().enumerate() {
                    let Some(s) = *sun else { continue };
                    lit.fill(0.0);
                    rays += test.sees_sun_each(&task_points, s, &mut sides, &mut scratch, &mut sees);
                    for (p, _) in sees.iter().enumerate().filter(|(_, &l)| l) {
                        lit[owner[p] as usize] += weight[p];
                    }
                    for (local, (&l, &t)) in lit.iter().zip(&total).enumerate() {
                        if t > 0.0 && 2.0 * l > t {
                            out[local * words + k / 32] |= 1 << (k % 32);
                        }
                        if t > 0.0 {
                            let v = ((l / t).clamp(0.0, 1.0) * FRACTION_MAX as f32).round() as u32;
                            fraction_out[local * fwords + k / 8] |= v << (4 * (k % 8));
                        }
                    }
                }
                progress.add(task_points.len() as u64 * day_steps);
                (rays, task_points.len() as u64)
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        drop(progress);
        TexelSunRange { masks, fractions, points: traced_points, rays }
    }

    /// The masks of every covered texel (ranges joined in order) with their statistics.
    pub fn finish(&self, traced: TexelSunRange, seconds: f64) -> TexelSunMasks {
        let TexelSunRange { masks, fractions, points, rays } = traced;
        let words = self.words().0;
        let lit_texels = lit_counts(&masks, self.suns.len());
        let stats =
            TexelSunStats { texels: self.texel_count() as u64, points, points_per_texel: self.points_per_texel, lit_texels, rays, seconds };
        TexelSunMasks { texels: self.coverage.texels.clone(), words_per_texel: words as u32, masks, fractions, stats }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::Mode;
    use crate::trace::BuildQuality;
    use crate::verify::shapes;
    use glam::Vec2;

    /// A 2 × 2 floor (y = 0) under a 0.5 × 0.5 square roof at height h,
    /// centred over the origin: the roof's shadow for sun `s` is the square
    /// shifted by −h·(s.x, s.z)/s.y.
    fn floor_and_roof(h: f32) -> (Mesh, usize) {
        let mut mesh = shapes::plane_grid(4, 2.0);
        let floor_triangles = mesh.triangle_count();
        let mut roof = shapes::plane_grid(1, 0.5);
        shapes::transform(&mut roof, 1.0, Vec3::new(0.0, h, 0.0));
        shapes::append(&mut mesh, &roof);
        (mesh, floor_triangles)
    }

    /// Texel sun bits against the analytic shadow of a square roof, edges
    /// included: every floor texel whose footprint lies wholly inside the
    /// shadow is dark, wholly outside it lit; a texel the edge crosses is
    /// lit when most of it is (its points' vote), checked where the lit
    /// share is clearly above or below one half; its stored lit share is
    /// the analytic one within what 16 points resolve. The same bits on
    /// one thread and on two, and in packets or one ray at a time.
    #[test]
    fn texel_sun_bits_match_an_analytic_shadow_edges_included() {
        let h = 0.3f32;
        let (mesh, floor_triangles) = floor_and_roof(h);
        let texel = 0.02f32;
        let atlas = Atlas::unwrap(&mesh, texel).unwrap();
        let surfaces = Surfaces::resolve(&mesh, &[]).unwrap();
        let scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
        let suns = [Some(Vec3::new(0.35, 1.0, -0.2).normalize()), Some(Vec3::new(-0.6, 0.8, 0.1).normalize()), None];
        let params = SunParams { mode: Mode::Open, seed: 3, ..SunParams::default() };
        let run = |threads: usize, packets: bool| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let params = SunParams { packets, ..params };
            pool.install(|| bake_texel_sun_masks(&mesh, &scene, &surfaces, &atlas, 16, DirectionPattern::Sobol, &suns, &params).unwrap())
        };
        let (one, two, lone_rays) = (run(1, true), run(2, true), run(2, false));
        assert_eq!(one, TexelSunMasks { stats: TexelSunStats { seconds: one.stats.seconds, ..two.stats.clone() }, ..two.clone() });
        assert_eq!(one, TexelSunMasks { stats: TexelSunStats { seconds: one.stats.seconds, ..lone_rays.stats.clone() }, ..lone_rays });
        let coverage = Coverage::of(&atlas);
        assert_eq!(coverage.texels, one.texels);
        // The world position of an atlas point of floor triangle t.
        let world = |t: usize, p: Vec2| {
            let uv = atlas.triangle_uv(t);
            let det = (uv[1] - uv[0]).perp_dot(uv[2] - uv[0]);
            let l1 = (p - uv[0]).perp_dot(uv[2] - uv[0]) / det;
            let l2 = (uv[1] - uv[0]).perp_dot(p - uv[0]) / det;
            let [a, b, c] = mesh.triangle_positions(t);
            a * (1.0 - l1 - l2) + b * l1 + c * l2
        };
        let (mut inside, mut outside, mut edge) = (0, 0, 0);
        let mut worst_fraction = 0.0f32;
        for (k, sun) in suns.iter().enumerate() {
            let Some(s) = sun else {
                assert_eq!(one.stats.lit_texels[k], 0, "night step {k}");
                continue;
            };
            let shift = Vec2::new(s.x, s.z) * (-h / s.y);
            let shaded = |p: Vec3| {
                let q = Vec2::new(p.x, p.z) - shift;
                q.x.abs() < 0.25 && q.y.abs() < 0.25
            };
            for i in 0..coverage.len() {
                let entries = coverage.start[i] as usize..coverage.start[i + 1] as usize;
                if entries.clone().any(|e| coverage.triangle[e] as usize >= floor_triangles) {
                    continue;
                }
                // The texel's footprint on a 6 × 6 grid of its square, on its triangles.
                let (x, y) = ((coverage.texels[i] % atlas.width) as f32, (coverage.texels[i] / atlas.width) as f32);
                let (mut dark, mut all) = (0.0f32, 0.0f32);
                for e in entries {
                    let t = coverage.triangle[e] as usize;
                    let polygon = crate::atlas::coverage::clip_to_texel(atlas.triangle_uv(t), x as u32, y as u32);
                    for g in 0..36 {
                        let p = Vec2::new(x + (g % 6) as f32 / 6.0 + 1.0 / 12.0, y + (g / 6) as f32 / 6.0 + 1.0 / 12.0);
                        if contains(&polygon, p) {
                            all += 1.0;
                            dark += f32::from(u8::from(shaded(world(t, p))));
                        }
                    }
                }
                if all == 0.0 {
                    continue;
                }
                let lit_share = 1.0 - dark / all;
                let bit = one.bit(i, k);
                // The stored share: its points' vote, within what 16 points and 4 bits resolve.
                let fraction = one.fraction(i, k);
                assert!(bit == (fraction > 0.5) || (fraction - 0.5).abs() < 0.04, "step {k}: bit {bit}, fraction {fraction}");
                worst_fraction = worst_fraction.max((fraction - lit_share).abs());
                if lit_share == 0.0 {
                    inside += 1;
                    assert!(!bit, "step {k}: texel {} wholly in the shadow is lit", coverage.texels[i]);
                } else if lit_share == 1.0 {
                    outside += 1;
                    assert!(bit, "step {k}: texel {} wholly in the sun is dark", coverage.texels[i]);
                } else if !(0.3..=0.7).contains(&lit_share) {
                    edge += 1;
                    assert_eq!(bit, lit_share > 0.5, "step {k}: edge texel {} is {lit_share:.2} lit", coverage.texels[i]);
                }
            }
        }
        eprintln!(
            "texels checked: {inside} in the shadow, {outside} in the sun, {edge} on its edges; fraction off by at most {worst_fraction}"
        );
        assert!(worst_fraction < 0.35, "a texel's stored lit share is {worst_fraction} off the analytic one");
        assert!(inside > 500 && outside > 10_000 && edge > 40, "{inside} / {outside} / {edge}");
    }

    fn contains(polygon: &[glam::DVec2], p: Vec2) -> bool {
        let p = p.as_dvec2();
        let n = polygon.len();
        let sign = |i: usize| (polygon[(i + 1) % n] - polygon[i]).perp_dot(p - polygon[i]);
        n >= 3 && (0..n).all(|i| sign(i) * sign(0) >= 0.0) && sign(0) != 0.0
    }
}
