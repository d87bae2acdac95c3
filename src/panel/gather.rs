//! The per-texel estimator (seed 000 §4.3), progressive.
//!
//! For texel point `p` with normal `n` and eye direction `wo`, the reflected
//! radiance `L_r = ∫ f(wi, wo) L(wi) cos θi dωi` splits as `L = L_rest + L_sun`
//! (the sun disk). `L_rest` is estimated by drawing `wi` from the BRDF alone;
//! the sun disk, a 6.8e-5 sr source that BRDF draws rarely hit, by two
//! strategies combined with the power heuristic (Veach 1997): the BRDF draw,
//! weighted `p_b² / (p_b² + p_s²)` when it lands in the disk, and a direction
//! uniform over the disk (`p_s = 1/Ω`), weighted `p_s² / (p_b² + p_s²)`. Each
//! strategy alone is unbiased for its part, so the sum is.
//!
//! Sample `k` of texel `i` uses Owen-scrambled Sobol point `k` of the stream
//! seeded by `(seed, i)` (four dimensions: the BRDF's two, the disk's two), so
//! a texel's value does not depend on the thread count or on how the samples
//! were split between [`PanelGather::refine`] calls; per-texel sums are f64 in
//! sample order.

use glam::Vec3;
use rayon::prelude::*;

use super::environment::Environment;
use super::interior::Interior;
use super::layout::{PanelLayout, NO_TRIANGLE};
use crate::brdf::Brdf;
use crate::sampling::{hash_seed, sample_2d, tangent_frame, DirectionPattern};
use crate::trace::RayQuery;

/// The most samples a texel can take (one Sobol stream: 2^16 points).
pub const MAX_SAMPLES: u32 = crate::sampling::MAX_RAYS_PER_POINT;

/// Choices of the estimator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GatherOptions {
    pub seed: u32,
    /// Sample the sun disk as well as the BRDF (MIS). Off only to measure what it saves.
    pub sun_sampling: bool,
    /// Owen-scrambled Sobol (the default) or independent uniform numbers (to compare convergence).
    pub pattern: DirectionPattern,
}

impl Default for GatherOptions {
    fn default() -> Self {
        GatherOptions { seed: 1, sun_sampling: true, pattern: DirectionPattern::Sobol }
    }
}

/// Running sums of one texel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Sums {
    total: [f64; 3],
    /// The part that came through windows.
    window: [f64; 3],
    /// The part that came straight from the sky or the sun (through windows or not).
    sky: [f64; 3],
    /// Σ of each sample's luminance squared (for the standard error).
    luminance_sq: f64,
    rays: u64,
    /// Queries traced: gather rays, their continuations through glass and
    /// the shadow rays toward the sun from lit interior hits.
    queries: u64,
}

/// A texel's estimate after the samples taken so far.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TexelResult {
    /// Mean reflected radiance, RGB.
    pub radiance: [f32; 3],
    /// The part of it that came through windows.
    pub through_windows: [f32; 3],
    /// The part of it that came straight from the sky or the sun (through
    /// windows or, in open mode, not); the rest the interior reflected.
    pub from_sky: [f32; 3],
    /// Standard error of the mean luminance (Rec. 709 weights), from the sample variance.
    pub luminance_error: f32,
}

/// A panel being gathered: the scene, the light, the BRDF, the texels, the eye, and the sums so far.
pub struct PanelGather<'a> {
    interior: &'a Interior<'a>,
    env: &'a Environment,
    brdf: &'a dyn Brdf,
    layout: &'a PanelLayout,
    eye: Vec3,
    options: GatherOptions,
    sums: Vec<Sums>,
    samples: u32,
}

impl<'a> PanelGather<'a> {
    /// A gather with no samples yet.
    pub fn new(
        interior: &'a Interior<'a>,
        env: &'a Environment,
        brdf: &'a dyn Brdf,
        layout: &'a PanelLayout,
        eye: Vec3,
        options: GatherOptions,
    ) -> PanelGather<'a> {
        PanelGather { interior, env, brdf, layout, eye, options, sums: vec![Sums::default(); layout.texel_count()], samples: 0 }
    }

    /// Adds `passes` samples to every texel (fewer when [`MAX_SAMPLES`] would be passed);
    /// returns the number added. Rows run in parallel; the result does not depend on the thread count.
    pub fn refine(&mut self, passes: u32) -> u32 {
        let passes = passes.min(MAX_SAMPLES - self.samples);
        let range = self.samples..self.samples + passes;
        let width = self.layout.width as usize;
        let mut sums = std::mem::take(&mut self.sums);
        let this = &*self;
        sums.par_chunks_mut(width).enumerate().for_each(|(row, row_sums)| {
            for (col, s) in row_sums.iter_mut().enumerate() {
                let texel = row * width + col;
                if this.layout.triangle[texel] != NO_TRIANGLE {
                    this.add_samples(texel, range.clone(), s);
                }
            }
        });
        self.sums = sums;
        self.samples += passes;
        passes
    }

    /// Samples per texel so far.
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// Gather rays traced so far: the BRDF draws and the sun-disk draws (not
    /// their continuations through glass, nor the shadow rays from interior hits).
    pub fn rays(&self) -> u64 {
        self.sums.iter().map(|s| s.rays).sum()
    }

    /// Queries the gather traced so far: its rays, their continuations
    /// through glass and the shadow rays toward the sun from interior hits.
    pub fn queries(&self) -> u64 {
        self.sums.iter().map(|s| s.queries).sum()
    }

    /// The layout gathered over.
    pub fn layout(&self) -> &PanelLayout {
        self.layout
    }

    /// Texel `i`'s estimate; `None` for a texel off the panel or before any sample.
    pub fn texel(&self, i: usize) -> Option<TexelResult> {
        if self.layout.triangle[i] == NO_TRIANGLE || self.samples == 0 {
            return None;
        }
        let s = &self.sums[i];
        let n = f64::from(self.samples);
        let mean = s.total.map(|x| x / n);
        let y = crate::colour::luminance_f64(mean);
        let variance = (s.luminance_sq / n - y * y).max(0.0) * n / (n - 1.0).max(1.0);
        Some(TexelResult {
            radiance: mean.map(|x| x as f32),
            through_windows: s.window.map(|x| (x / n) as f32),
            from_sky: s.sky.map(|x| (x / n) as f32),
            luminance_error: (variance / n).sqrt() as f32,
        })
    }

    /// Every texel's estimate, row-major (`None` off the panel).
    pub fn results(&self) -> Vec<Option<TexelResult>> {
        (0..self.sums.len()).map(|i| self.texel(i)).collect()
    }

    /// The first rays of texel `texel`'s BRDF draws for samples `range`, as
    /// the gather traces them (for measuring the tracer on the gather's own
    /// rays); empty for a texel off the panel or not facing the eye.
    pub fn first_rays(&self, texel: usize, range: std::ops::Range<u32>) -> Vec<RayQuery> {
        if self.layout.triangle[texel] == NO_TRIANGLE {
            return Vec::new();
        }
        self.texel_draws(texel, range).map_or_else(Vec::new, |d| d.first_rays)
    }

    /// Texel `texel`'s frame, its samples' random numbers and BRDF draws,
    /// and the first ray of each draw; `None` when the eye sees the texel
    /// edge-on or from behind (nothing reflects toward it).
    fn texel_draws(&self, texel: usize, range: std::ops::Range<u32>) -> Option<TexelDraws> {
        let p = self.layout.point[texel];
        let n = self.layout.normal[texel];
        let face = self.interior.scene.face_normal(self.layout.triangle[texel]);
        let wo = (self.eye - p).try_normalize()?;
        let (t, b) = tangent_frame(n);
        let frame = Frame { t, b, n };
        let wo_local = frame.to_local(wo);
        if wo_local.z <= 0.0 {
            return None;
        }
        let seed = hash_seed(&[self.options.seed, texel as u32, 0x7a6e_1c0d]);
        let draw = |k: u32| match self.options.pattern {
            DirectionPattern::Sobol => sobol_burley::sample_4d(k, 0, seed),
            DirectionPattern::Random => {
                let (a, b) = (sample_2d(DirectionPattern::Random, k, 0, seed), sample_2d(DirectionPattern::Random, k, 1, seed));
                [a.0, a.1, b.0, b.1]
            }
        };
        let draws: Vec<[f32; 4]> = range.map(draw).collect();
        let brdf_samples: Vec<_> = draws.iter().map(|u| self.brdf.sample(wo_local, [u[0], u[1]])).collect();
        let first_rays = brdf_samples.iter().flatten().map(|sample| self.interior.first_ray(p, face, frame.to_world(sample.wi))).collect();
        Some(TexelDraws { p, face, frame, wo_local, draws, brdf_samples, first_rays })
    }

    fn add_samples(&self, texel: usize, range: std::ops::Range<u32>, sums: &mut Sums) {
        let Some(TexelDraws { p, face, frame, wo_local, draws, brdf_samples, first_rays }) = self.texel_draws(texel, range) else {
            return;
        };
        let sun = self.env.sun.as_ref();
        let sun_radiance = sun.map(|s| s.radiance());
        let sun_pdf = sun.map_or(0.0, |s| (1.0 / s.solid_angle()) as f32);
        // The BRDF's directions of every sample first, their first rays
        // traced as one batch (the scene's batch mode: interleaved where
        // the tree waits on memory), the same hits as one at a time.
        let mut first_hits = vec![None; first_rays.len()];
        self.interior.scene.closest_hits(&first_rays, &mut first_hits);
        let mut first = first_rays.iter().zip(first_hits);
        for (u, brdf_sample) in draws.into_iter().zip(brdf_samples) {
            let mut value = [0.0f32; 3];
            let mut through_window = [0.0f32; 3];
            let mut from_sky = [0.0f32; 3];
            let mut add = |w: [f32; 3], light: [f32; 3], window: bool, sky: bool| {
                for c in 0..3 {
                    value[c] += w[c] * light[c];
                    if window {
                        through_window[c] += w[c] * light[c];
                    }
                    if sky {
                        from_sky[c] += w[c] * light[c];
                    }
                }
            };
            // Strategy 1: a direction from the BRDF.
            if let Some(sample) = brdf_sample {
                let (ray, hit) = first.next().expect("one first ray per BRDF sample");
                let wi = ray.direction;
                let f = self.brdf.eval(sample.wi, wo_local);
                let weight = f.map(|f| f * sample.wi.z / sample.pdf);
                let arrival = self.interior.trace_from(self.env, ray, hit);
                sums.rays += 1;
                sums.queries += u64::from(arrival.queries);
                add(weight, arrival.radiance, arrival.through_window, arrival.sky_transmittance > 0.0);
                if let (Some(sun), Some(l_sun)) = (sun, sun_radiance) {
                    if arrival.sky_transmittance > 0.0 && sun.contains(wi) {
                        let mis = if self.options.sun_sampling { power_heuristic(sample.pdf, sun_pdf) } else { 1.0 };
                        add(weight, l_sun.map(|l| l * arrival.sky_transmittance * mis), arrival.through_window, true);
                    }
                }
            }
            // Strategy 2: a direction within the sun disk.
            if let (Some(sun), Some(l_sun), true) = (sun, sun_radiance, self.options.sun_sampling) {
                let wi = sun.sample([u[2], u[3]]);
                let wi_local = frame.to_local(wi);
                if wi_local.z > 0.0 {
                    let f = self.brdf.eval(wi_local, wo_local);
                    if f.iter().any(|&x| x > 0.0) {
                        let (tau, window, queries) = self.interior.sun_arrival(sun, p, face, wi);
                        sums.rays += 1;
                        sums.queries += u64::from(queries);
                        if tau > 0.0 {
                            let mis = power_heuristic(sun_pdf, self.brdf.pdf(wo_local, wi_local));
                            let weight = f.map(|f| f * wi_local.z / sun_pdf * mis * tau);
                            add(weight, l_sun, window, true);
                        }
                    }
                }
            }
            for c in 0..3 {
                sums.total[c] += f64::from(value[c]);
                sums.window[c] += f64::from(through_window[c]);
                sums.sky[c] += f64::from(from_sky[c]);
            }
            let y = crate::colour::luminance_f64(value.map(f64::from));
            sums.luminance_sq += y * y;
        }
    }
}

/// A texel's tangent frame: tangent, bitangent, normal.
struct Frame {
    t: Vec3,
    b: Vec3,
    n: Vec3,
}

impl Frame {
    fn to_local(&self, d: Vec3) -> Vec3 {
        Vec3::new(d.dot(self.t), d.dot(self.b), d.dot(self.n))
    }

    fn to_world(&self, d: Vec3) -> Vec3 {
        (self.t * d.x + self.b * d.y + self.n * d.z).normalize()
    }
}

/// What [`PanelGather::texel_draws`] prepares for a texel's samples.
struct TexelDraws {
    p: Vec3,
    face: Vec3,
    frame: Frame,
    wo_local: Vec3,
    draws: Vec<[f32; 4]>,
    brdf_samples: Vec<Option<crate::brdf::BrdfSample>>,
    first_rays: Vec<RayQuery>,
}

/// Veach's power heuristic (β = 2) for the strategy with density `a` against `b`.
fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (f64::from(a).powi(2), f64::from(b).powi(2));
    if a2 + b2 > 0.0 {
        (a2 / (a2 + b2)) as f32
    } else {
        0.0
    }
}
