//! `chart --real`: accuracy per second on the meshes users judge by (the
//! Ferrari in window mode, the grey-white room open through its openings,
//! the demo cabin), each against its own converged reference.
//!
//! **Reference.** The per-vertex mean of bakes with independent seeds (11,
//! 12, …; two for the cabin, six for the Ferrari and eight for the room, whose single
//! bakes are noisier) at many more points and rays than any swept bake,
//! cached in the output folder as ordinary bundles
//! (`<scene>-reference-s<seed>.prtb`; a bundle baked by `prtbake bake` with
//! the same mesh and parameters is used as it is; a stale one is re-baked
//! only over a file this chart wrote, and any other file of that name is
//! refused, never replaced). Its convergence is reported, not assumed: the
//! relative RMS DC difference of two independent half references (the mean
//! of the odd-numbered seeds against the mean of the even-numbered ones).
//! The whole mean's own noise is about half of it, so errors near that
//! floor are overstated by it.
//!
//! **Error** (total: sample positions, rays and bounces together), over the
//! vertices the reference lights (DC > 0):
//! - `dc_error`: relative RMS of DC, `sqrt(Σ (b − r)² / Σ r²)`, the figure of
//!   the error `--max-error` and the docs quote;
//! - `shaded_error`: the worst over [`budget::reference_lightings`] of the
//!   relative RMS of shaded radiance, the definition `--max-error` budgets
//!   storage with (there against the bake itself);
//! - `black_lit`: lit vertices the bake leaves at DC 0; `black_visible`,
//!   those of them whose reference DC is at least [`VISIBLE_FRACTION`] of
//!   the lit mean (the rest carry next to no light: under 10⁻⁶ of the
//!   mean on the Ferrari, where no display shows them).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;

use super::scenes::Size;
use crate::bake::{bake_mesh, BakeParams, Channels, Mode};
use crate::bundle::budget::{self, Lighting};
use crate::mesh::Mesh;
use crate::sh;

/// The first reference seed; a scene's reference uses this and the next
/// `reference_seed_count - 1` (the swept bakes use the default seed, 1).
pub const FIRST_REFERENCE_SEED: u32 = 11;

/// A black lit vertex counts as visible when its reference DC is at least
/// this fraction of the lit vertices' mean: 10 stops below it, about what an
/// 8-bit sRGB display still tells from black at an exposure that shows the mean.
pub const VISIBLE_FRACTION: f64 = 1e-3;

/// Errors the summary reports the time to reach.
pub const TARGETS: [f64; 3] = [0.10, 0.05, 0.02];

/// A real scene ready to sweep.
pub struct RealScene {
    pub name: &'static str,
    /// The file the mesh was read from (`None`: generated).
    pub source: Option<PathBuf>,
    pub mesh: Mesh,
    pub window_patterns: Vec<String>,
    /// Mode, order, bounces, channels; rays = the CLI default for the scene.
    pub base: BakeParams,
    /// Rays and adaptive factor of the reference bakes.
    pub reference_rays: u32,
    pub reference_adaptive: f32,
    /// Reference bakes (an even number: two independent halves).
    pub reference_seed_count: u32,
}

impl RealScene {
    /// The seeds of the reference bakes.
    pub fn reference_seeds(&self) -> Vec<u32> {
        (FIRST_REFERENCE_SEED..FIRST_REFERENCE_SEED + self.reference_seed_count).collect()
    }

    fn reference_params(&self, seed: u32) -> BakeParams {
        BakeParams { rays: self.reference_rays, adaptive: self.reference_adaptive, seed, ..self.base }
    }

    /// The swept settings: (label, rays, adaptive factor). Today's default
    /// (uniform points) at 1/8 … 1 of the scene's default rays, `--adaptive 1`
    /// at half those (the same traced rays per base point), and (full sweep)
    /// `--adaptive 0.25` at the same rays (a quarter more points, for the
    /// Ferrari's 5%-at-today's-time target).
    fn settings(&self, size: Size) -> Vec<(&'static str, u32, f32)> {
        let r = self.base.rays;
        let fractions: &[u32] = if size == Size::Quick { &[8, 2] } else { &[8, 4, 2, 1] };
        let mut out: Vec<(&'static str, u32, f32)> = fractions.iter().map(|&f| ("uniform", r / f, 0.0)).collect();
        out.extend(fractions.iter().map(|&f| ("adaptive 1", (r / f / 2).max(1), 1.0)));
        if size == Size::Full {
            out.extend(fractions.iter().map(|&f| ("adaptive 0.25", r / f, 0.25)));
        }
        out
    }
}

/// Order 3, 3 bounces, one channel.
fn base(mode: Mode, rays: u32, hit_cache_bytes: u64) -> BakeParams {
    BakeParams { order: 3, bounces: 3, channels: Channels::One, mode, rays, quiet: true, hit_cache_bytes, ..BakeParams::default() }
}

/// The Ferrari, the room and the cabin. The first two are read from `data`
/// (the layout of ../shared/data: `car-ferrari458/ferrari_nodraco.glb`,
/// `room-grey-white/grey_white_room_flat.obj`) and skipped with a notice on
/// stderr when absent; the cabin is generated. `Size::Quick` is the cabin
/// alone at a coarse tessellation (seconds, for tests). Every bake keeps up
/// to `hit_cache_bytes` of bounce 0's hits for the later bounces.
pub fn scenes(data: &Path, size: Size, hit_cache_bytes: u64) -> anyhow::Result<Vec<RealScene>> {
    let cad = crate::clean::CleanParams::cad();
    let cabin_detail = if size == Size::Quick { 4.0 } else { crate::fixtures::cabin::DEMO_DETAIL };
    let (raw, _) = crate::fixtures::cabin::generate_cabin(cabin_detail);
    let (cabin, _) = crate::clean::clean_mesh(&raw, &cad)?;
    let cabin = RealScene {
        name: "cabin",
        source: None,
        mesh: cabin,
        window_patterns: Vec::new(),
        base: base(Mode::Window, 192, hit_cache_bytes),
        reference_rays: if size == Size::Quick { 256 } else { 512 },
        reference_adaptive: 3.0,
        reference_seed_count: 2,
    };
    if size == Size::Quick {
        return Ok(vec![cabin]);
    }
    let mut out = Vec::new();
    let load = |relative: &str| -> anyhow::Result<Option<(Mesh, PathBuf)>> {
        let path = data.join(relative);
        if !path.is_file() {
            eprintln!("chart --real: {} not found, scene skipped", path.display());
            return Ok(None);
        }
        let loaded = crate::mesh::load_mesh(&path, &crate::mesh::LoadOptions::default())
            .with_context(|| format!("chart --real: cannot load the scene {relative}"))?;
        Ok(Some((loaded.mesh, path)))
    };
    if let Some((mesh, path)) = load("car-ferrari458/ferrari_nodraco.glb")? {
        out.push(RealScene {
            name: "ferrari",
            source: Some(path),
            mesh,
            window_patterns: vec!["Glass_Gray".into()],
            base: base(Mode::Window, 256, hit_cache_bytes),
            reference_rays: 128,
            reference_adaptive: 8.0,
            // Two seeds differ by 1.7%: three per half for ≤ 1%.
            reference_seed_count: 6,
        });
    }
    if let Some((raw, path)) = load("room-grey-white/grey_white_room_flat.obj")? {
        let (mesh, _) = crate::clean::clean_mesh(&raw, &cad).with_context(|| format!("{}: cannot clean", path.display()))?;
        out.push(RealScene {
            name: "room",
            source: Some(path),
            mesh,
            window_patterns: Vec::new(),
            base: base(Mode::Open, 256, hit_cache_bytes),
            reference_rays: 256,
            reference_adaptive: 8.0,
            // Two seeds differ by 1.8%, halves of three by 1.03%: four per half for ≤ 1%.
            reference_seed_count: 8,
        });
    }
    out.push(cabin);
    Ok(out)
}

/// A scene's converged reference.
pub struct RealReference {
    /// Mean of the seeds' total transfer, `[vertex][coeff]` (one channel).
    pub transfer: Vec<f32>,
    pub order: usize,
    /// Vertices the reference lights (DC > 0).
    pub lit: Vec<usize>,
    /// Relative RMS DC difference of the two half references (odd- and
    /// even-numbered seeds' means) over `lit`.
    pub seed_difference: f64,
    pub seeds: Vec<u32>,
    /// Wall seconds spent baking references in this run (0 when all were cached).
    pub baked_seconds: f64,
}

/// The bundle at `path` when it holds a bake of `mesh` with `params`.
fn cached_transfer(path: &Path, mesh: &Mesh, params: &BakeParams) -> Option<Vec<f32>> {
    let bundle = crate::bundle::read_bundle(path).ok()?;
    let same_params = bundle.meta.get("params") == serde_json::to_value(params).ok().as_ref();
    let same_mesh = bundle.mesh.positions == mesh.positions && bundle.mesh.indices == mesh.indices;
    let transfer = bundle.transfer.filter(|t| t.order as usize == params.order && t.channels == 1)?;
    (same_params && same_mesh).then(|| transfer.total())
}

/// Refuses to replace a file at `path` that is not a reference this chart
/// wrote (a user's bundle of other parameters, or anything else): the
/// cache must not cost anyone a bake.
fn check_replaceable(path: &Path) -> anyhow::Result<()> {
    if !path.exists() {
        return Ok(());
    }
    let ours = crate::bundle::read_bundle(path).is_ok_and(|b| b.meta.get("chart_reference").is_some());
    anyhow::ensure!(
        ours,
        "{}: exists and is not a reference `chart --real` wrote, nor a bake of this mesh with the reference's parameters; move it, or choose another -o",
        path.display()
    );
    Ok(())
}

/// Reads the scene's reference bakes from `cache_dir`, baking (and writing)
/// those that are missing or stale (only over files this chart wrote).
/// Progress on stderr.
pub fn reference(scene: &RealScene, cache_dir: &Path) -> anyhow::Result<RealReference> {
    let mut seeds = Vec::new();
    let mut baked_seconds = 0.0;
    let all_seeds = scene.reference_seeds();
    for &seed in &all_seeds {
        let params = scene.reference_params(seed);
        let path = cache_dir.join(format!("{}-reference-s{seed}.prtb", scene.name));
        let transfer = match cached_transfer(&path, &scene.mesh, &params) {
            Some(t) => t,
            None => {
                check_replaceable(&path)?;
                eprintln!(
                    "chart --real: baking the {} reference, seed {seed} ({} rays, --adaptive {}, {} bounces, hit cache up to {:.1} GiB: --hit-cache-mib) into {}",
                    scene.name,
                    params.rays,
                    params.adaptive,
                    params.bounces,
                    params.hit_cache_bytes as f64 / (1u64 << 30) as f64,
                    path.display()
                );
                let started = Instant::now();
                let (result, _, _) = bake_mesh(&scene.mesh, &params, &scene.window_patterns)?;
                baked_seconds += started.elapsed().as_secs_f64();
                let meta = serde_json::json!({
                    "source": scene.name,
                    "window_patterns": scene.window_patterns,
                    "chart_reference": format!("{} seed {seed}", scene.name),
                });
                crate::bundle::write_bundle(&path, &crate::bundle::make_bundle(&scene.mesh, &result, &params, meta))?;
                result.total
            }
        };
        seeds.push(transfer);
    }
    let order = scene.base.order;
    let n = sh::coeff_count(order);
    let half = |parity: usize| mean_of(&seeds.iter().skip(parity).step_by(2).map(|t| t.as_slice()).collect::<Vec<_>>());
    let (odd, even) = (half(0), half(1));
    let transfer = mean_of(&seeds.iter().map(|t| t.as_slice()).collect::<Vec<_>>());
    let lit: Vec<usize> = (0..transfer.len() / n).filter(|&v| transfer[v * n] > 0.0).collect();
    let dc = |t: &[f32]| lit.iter().map(|&v| t[v * n] as f64).collect::<Vec<f64>>();
    let seed_difference = relative_rms(&dc(&odd), &dc(&even));
    Ok(RealReference { transfer, order, lit, seed_difference, seeds: all_seeds, baked_seconds })
}

/// The per-value mean of equally long transfers (summed in f64, in order).
fn mean_of(transfers: &[&[f32]]) -> Vec<f32> {
    let count = transfers.len().max(1) as f64;
    (0..transfers.first().map_or(0, |t| t.len())).map(|i| (transfers.iter().map(|t| f64::from(t[i])).sum::<f64>() / count) as f32).collect()
}

/// `sqrt(Σ (b − r)² / Σ r²)`.
fn relative_rms(reference: &[f64], other: &[f64]) -> f64 {
    let num: f64 = reference.iter().zip(other).map(|(r, b)| (b - r).powi(2)).sum();
    let den: f64 = reference.iter().map(|r| r * r).sum();
    (num / den).sqrt()
}

/// Errors of one bake's total transfer against the reference.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Score {
    pub dc_error: f64,
    pub shaded_error: f64,
    pub black_lit: usize,
    /// Black lit vertices whose reference DC is at least [`VISIBLE_FRACTION`]
    /// of the lit mean.
    pub black_visible: usize,
    /// The brightest black lit vertex's reference DC over the lit vertices'
    /// mean reference DC (0 with none black): how much light the black ones miss.
    pub brightest_black: f64,
    /// The bake's own estimate of its DC noise, `sqrt(Σ σ² / Σ r²)` over the
    /// lit vertices (σ: `TransferResult::noise`, every bounce's in quadrature;
    /// NaN when the bake measured none), beside `dc_error` to show how far
    /// the estimate can be trusted.
    pub noise_estimate: f64,
}

impl Score {
    /// One line of the figures, for progress and reports.
    pub fn summary(&self) -> String {
        format!(
            "DC error {:.4} (noise estimate {:.4})  shaded {:.4}  black lit {}, visible {} (brightest {:.3} of the mean)",
            self.dc_error, self.noise_estimate, self.shaded_error, self.black_lit, self.black_visible, self.brightest_black
        )
    }
}

/// Scores a one-channel transfer of the reference's order and vertex count,
/// with its per-vertex DC standard errors `noise` (empty when not measured).
pub fn score(transfer: &[f32], noise: &[f32], reference: &RealReference, lightings: &[Lighting]) -> Score {
    let n = sh::coeff_count(reference.order);
    let pick = |t: &[f32]| {
        let mut out = Vec::with_capacity(reference.lit.len() * n);
        reference.lit.iter().for_each(|&v| out.extend_from_slice(&t[v * n..][..n]));
        out
    };
    let (baked, exact) = (pick(transfer), pick(&reference.transfer));
    let dc = |t: &[f32]| t.iter().step_by(n).map(|&x| x as f64).collect::<Vec<f64>>();
    let (baked_dc, exact_dc) = (dc(&baked), dc(&exact));
    let shaded_error = lightings
        .iter()
        .map(|l| budget::relative_rms(&budget::shade(&exact, reference.order, 1, &l.sh), &budget::shade(&baked, reference.order, 1, &l.sh)))
        .fold(0.0, f64::max);
    let lit_mean = exact_dc.iter().sum::<f64>() / exact_dc.len().max(1) as f64;
    let brightest_black = baked_dc.iter().zip(&exact_dc).filter(|(&b, _)| b == 0.0).map(|(_, &r)| r).fold(0.0, f64::max) / lit_mean;
    let noise_estimate = if noise.len() * n == transfer.len() {
        let spread: f64 = reference.lit.iter().map(|&v| f64::from(noise[v]).powi(2)).sum();
        (spread / exact_dc.iter().map(|r| r * r).sum::<f64>()).sqrt()
    } else {
        f64::NAN
    };
    Score {
        dc_error: relative_rms(&exact_dc, &baked_dc),
        shaded_error,
        black_lit: baked_dc.iter().filter(|&&d| d == 0.0).count(),
        black_visible: baked_dc.iter().zip(&exact_dc).filter(|(&b, &r)| b == 0.0 && r >= VISIBLE_FRACTION * lit_mean).count(),
        brightest_black,
        noise_estimate,
    }
}

/// One swept bake of a real scene.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RealRow {
    pub scene: String,
    pub setting: String,
    pub rays: u32,
    pub adaptive: f32,
    pub seconds: f64,
    pub points: u64,
    pub rays_traced: u64,
    #[serde(flatten)]
    pub score: Score,
}

/// The CSV header, in column order.
pub const CSV_HEADER: &str =
    "scene,setting,rays,adaptive,seconds,points,rays_traced,dc_error,shaded_error,black_lit,brightest_black,noise_estimate,black_visible";

pub fn to_csv(rows: &[RealRow]) -> String {
    let mut s = String::from(CSV_HEADER);
    s.push('\n');
    for r in rows {
        s += &format!(
            "{},{},{},{},{:.3},{},{},{:.6},{:.6},{},{:.6},{:.6},{}\n",
            r.scene,
            r.setting,
            r.rays,
            r.adaptive,
            r.seconds,
            r.points,
            r.rays_traced,
            r.score.dc_error,
            r.score.shaded_error,
            r.score.black_lit,
            r.score.brightest_black,
            r.score.noise_estimate,
            r.score.black_visible
        );
    }
    s
}

/// A scene's reference and its swept bakes.
pub struct SceneSweep {
    pub name: &'static str,
    pub vertices: usize,
    pub reference: RealReference,
    pub reference_params: BakeParams,
    pub rows: Vec<RealRow>,
}

/// Sweeps each scene against its reference (cached in `cache_dir`).
pub fn sweep(scenes: &[RealScene], size: Size, cache_dir: &Path) -> anyhow::Result<Vec<SceneSweep>> {
    let mut out = Vec::new();
    for scene in scenes {
        let reference = reference(scene, cache_dir)?;
        eprintln!(
            "chart --real: {} reference: {} of {} vertices lit, its halves differ by {:.4} (DC relative RMS)",
            scene.name,
            reference.lit.len(),
            scene.mesh.vertex_count(),
            reference.seed_difference
        );
        let lightings = budget::reference_lightings(reference.order);
        // One untimed bake first, so the first timed point does not pay for cold caches.
        bake_mesh(&scene.mesh, &BakeParams { rays: 4, bounces: 0, ..scene.base }, &scene.window_patterns)?;
        let mut rows = Vec::new();
        for (setting, rays, adaptive) in scene.settings(size) {
            let params = BakeParams { rays, adaptive, ..scene.base };
            let started = Instant::now();
            let (result, _, _) = bake_mesh(&scene.mesh, &params, &scene.window_patterns)?;
            let seconds = started.elapsed().as_secs_f64();
            let score = score(&result.total, &result.noise, &reference, &lightings);
            eprintln!("chart --real: {:<8} {:<10} {:>4} rays {:>8.2}s  {}", scene.name, setting, rays, seconds, score.summary());
            rows.push(RealRow {
                scene: scene.name.into(),
                setting: setting.into(),
                rays,
                adaptive,
                seconds,
                points: result.stats.points,
                rays_traced: result.stats.rays_traced,
                score,
            });
        }
        out.push(SceneSweep {
            name: scene.name,
            vertices: scene.mesh.vertex_count(),
            reference_params: scene.reference_params(FIRST_REFERENCE_SEED),
            reference,
            rows,
        });
    }
    Ok(out)
}

/// When a setting's curve (points in increasing time) first reaches `target`:
/// `Reached(seconds)` interpolated log–log between the bracketing bakes,
/// `AtFirst(seconds)` when its cheapest bake is already below (the time is an
/// upper bound), `NotReached` within the sweep.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Reach {
    Reached(f64),
    AtFirst(f64),
    NotReached,
}

pub fn time_to_reach(curve: &[(f64, f64)], target: f64) -> Reach {
    let Some(&(t0, e0)) = curve.first() else { return Reach::NotReached };
    if e0 <= target {
        return Reach::AtFirst(t0);
    }
    for w in curve.windows(2) {
        let ((ta, ea), (tb, eb)) = (w[0], w[1]);
        if ea > target && eb <= target {
            let f = (ea.ln() - target.ln()) / (ea.ln() - eb.ln());
            return Reach::Reached((ta.ln() + f * (tb.ln() - ta.ln())).exp());
        }
    }
    Reach::NotReached
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_to_reach_interpolates_log_log_and_says_when_it_cannot() {
        // Error ∝ t^-1/2: from (10 s, 0.2) to (40 s, 0.1); 0.1414 is reached at 20 s.
        let curve = [(10.0, 0.2), (40.0, 0.1)];
        match time_to_reach(&curve, 0.2 / 2f64.sqrt()) {
            Reach::Reached(t) => assert!((t - 20.0).abs() < 1e-9, "{t}"),
            other => panic!("{other:?}"),
        }
        assert_eq!(time_to_reach(&curve, 0.3), Reach::AtFirst(10.0));
        assert_eq!(time_to_reach(&curve, 0.05), Reach::NotReached);
        assert_eq!(time_to_reach(&[], 0.05), Reach::NotReached);
        // A curve that rises again past the target is reached at its first crossing.
        assert!(matches!(time_to_reach(&[(1.0, 0.3), (2.0, 0.1), (4.0, 0.2)], 0.15), Reach::Reached(t) if t > 1.0 && t < 2.0));
    }

    #[test]
    fn score_is_zero_for_the_reference_and_counts_black_lit_vertices() {
        let n = sh::coeff_count(2);
        // Three vertices; the middle one is dark in the reference and not scored.
        let transfer = vec![0.3, 0.1, 0.0, 0.05, 0.0, 0.0, 0.0, 0.0, 0.2, -0.1, 0.02, 0.0];
        let lit: Vec<usize> = (0..3).filter(|&v| transfer[v * n] > 0.0).collect();
        assert_eq!(lit, vec![0, 2]);
        let reference =
            RealReference { transfer: transfer.clone(), order: 2, lit, seed_difference: 0.0, seeds: vec![11, 12], baked_seconds: 0.0 };
        let lightings = budget::reference_lightings(2);
        let exact = score(&transfer, &[0.01, 0.0, 0.02], &reference, &lightings);
        assert_eq!(exact.dc_error, 0.0);
        assert_eq!((exact.shaded_error, exact.black_lit, exact.black_visible, exact.brightest_black), (0.0, 0, 0, 0.0));
        // Noise estimate: sqrt((0.01² + 0.02²) / (0.3² + 0.2²)); the unlit vertex's noise is not counted.
        assert!((exact.noise_estimate - (0.0005f64 / 0.13).sqrt()).abs() < 1e-6, "{}", exact.noise_estimate);
        assert!(score(&transfer, &[], &reference, &lightings).noise_estimate.is_nan());
        let mut off = transfer.clone();
        off[4] = 7.0; // the unlit vertex: not scored
        off[2 * n] = 0.0; // a lit vertex turned black
        let s = score(&off, &[], &reference, &lightings);
        assert_eq!((s.black_lit, s.black_visible), (1, 1));
        // The black vertex's reference DC 0.2 over the lit mean 0.25.
        assert!((s.brightest_black - 0.8).abs() < 1e-6, "{}", s.brightest_black);
        // DC error: sqrt(0.2² / (0.3² + 0.2²)).
        assert!((s.dc_error - (0.04f64 / 0.13).sqrt()).abs() < 1e-6, "{}", s.dc_error);
        assert!(s.shaded_error > 0.0);
        // A lit vertex far below 10⁻³ of the mean, left black: counted, not visible.
        let mut dim = transfer.clone();
        dim[2 * n] = 1e-5;
        let dim_reference = RealReference { transfer: dim.clone(), ..reference };
        dim[2 * n] = 0.0;
        let d = score(&dim, &[], &dim_reference, &lightings);
        assert_eq!((d.black_lit, d.black_visible), (1, 0));
    }
}
