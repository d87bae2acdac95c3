//! Scores bakes of `chart --real`'s scenes against its cached references,
//! outside the chart's own sweep (docs/speed-accuracy.md):
//!
//! ```sh
//! real_score DATA CACHE SCENE export OUT.obj        # the scene's mesh as the chart bakes it
//! real_score DATA CACHE SCENE score BUNDLE.prtb…    # bundles of that mesh (any prtbake version)
//! real_score DATA CACHE SCENE bake RAYS:ADAPTIVE[:ws][:seed=N]…
//! real_score DATA CACHE SCENE split HIGH SETTING…   # error by bounce against a bake at HIGH
//! ```
//!
//! DATA is ../shared/data, CACHE the chart's output folder holding
//! `<scene>-reference-s<seed>.prtb` (baked there first when missing), SCENE
//! `ferrari`, `room` or `cabin`. `score` reads a bundle whose vertices are the
//! scene's, in its order or (another loader's) matched by exact position.
//! `bake` bakes in process with the chart's parameters (order 3, 3 bounces,
//! one channel) at the given rays and `--adaptive`, `ws` adding
//! `--window-sampling`, and says of the black lit vertices how many of the
//! reference's seeds light them. `split` bakes HIGH (a setting as for
//! `bake`, far more rays) keeping each bounce, then each SETTING, and says
//! how far each one's bounce 0 and its later bounces together lie from
//! HIGH's, relative to HIGH's total over the reference's lit vertices: where
//! a setting's error comes from (HIGH's own noise included; give HIGH
//! another seed, `…:seed=7`, or the shared rays hide part of the error).
use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

use anyhow::{bail, ensure, Context};
use prtbake::bake::{bake_mesh, BakeParams, TransferResult};
use prtbake::chart::real::{self, RealReference, RealScene, Score};
use prtbake::chart::scenes::Size;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    ensure!(
        args.len() >= 4,
        "usage: real_score DATA CACHE SCENE export OUT.obj | score BUNDLE… | bake RAYS:ADAPTIVE[:ws][:seed=N]… | split HIGH SETTING…"
    );
    let (data, cache, name, command) = (Path::new(&args[0]), Path::new(&args[1]), args[2].as_str(), args[3].as_str());
    let scenes = real::scenes(data, Size::Full, 14_000 << 20)?;
    let scene = scenes.iter().find(|s| s.name == name).with_context(|| format!("no scene {name} (ferrari, room, cabin)"))?;
    if command == "export" {
        let out = Path::new(args.get(4).context("export needs OUT.obj")?);
        // Never over the scene's own file (the room is an OBJ too).
        let inputs: Vec<&Path> = scene.source.iter().map(|p| p.as_path()).collect();
        prtbake::files::check_outputs(&inputs, &[prtbake::files::Output::new(out, &["obj"])], false)?;
        prtbake::mesh::write_obj(out, &scene.mesh)?;
        return Ok(());
    }
    let reference = real::reference(scene, cache)?;
    let lightings = prtbake::bundle::budget::reference_lightings(reference.order);
    let n = prtbake::sh::coeff_count(reference.order);
    let print = |label: &str, s: &Score| println!("{name} {label}: {}", s.summary());
    match command {
        "score" => {
            for path in &args[4..] {
                let transfer = bundle_transfer(Path::new(path), scene, n)?;
                print(path, &real::score(&transfer, &[], &reference, &lightings));
            }
        }
        "bake" => {
            let seed_dc = seed_dcs(cache, scene, &reference, n)?;
            // One untimed bake first, as the chart does, for warm caches.
            bake_mesh(&scene.mesh, &BakeParams { rays: 4, bounces: 0, ..scene.base }, &scene.window_patterns)?;
            for setting in &args[4..] {
                let params = parse_setting(setting, &scene.base)?;
                let started = Instant::now();
                let (result, _, _) = bake_mesh(&scene.mesh, &params, &scene.window_patterns)?;
                let seconds = started.elapsed().as_secs_f64();
                print(
                    &format!("{setting} {seconds:.2} s, {} points, {} rays traced", result.stats.points, result.stats.rays_traced),
                    &real::score(&result.total, &result.noise, &reference, &lightings),
                );
                let mut by_seeds = vec![0usize; seed_dc.len() + 1];
                for &v in reference.lit.iter().filter(|&&v| result.total[v * n] == 0.0) {
                    by_seeds[seed_dc.iter().filter(|dc| dc[v] > 0.0).count()] += 1;
                }
                println!("  black lit vertices by how many of the {} reference seeds light them (0 … all): {by_seeds:?}", seed_dc.len());
            }
        }
        "split" => {
            ensure!(args.len() >= 6, "split needs HIGH and at least one SETTING");
            let keep_bounces =
                |setting: &str| Ok::<_, anyhow::Error>(BakeParams { store_bounces: true, ..parse_setting(setting, &scene.base)? });
            let (high, _, _) = bake_mesh(&scene.mesh, &keep_bounces(&args[4])?, &scene.window_patterns)?;
            let split = BounceSplit::new(&high, &reference.lit, n);
            println!("{name} {}: bounce 0 holds {:.3} of the lit vertices' summed DC", args[4], split.direct_share());
            for setting in &args[5..] {
                let started = Instant::now();
                let (result, _, _) = bake_mesh(&scene.mesh, &keep_bounces(setting)?, &scene.window_patterns)?;
                let seconds = started.elapsed().as_secs_f64();
                let [total, direct, indirect] = split.errors(&result);
                println!("{name} {setting} {seconds:.2} s: DC error against {}: total {total:.4}, bounce 0 {direct:.4}, bounces 1+ {indirect:.4}", args[4]);
            }
        }
        other => bail!("unknown command {other:?}: export, score, bake or split"),
    }
    Ok(())
}

/// A bake kept bounce by bounce, to split another bake's DC error into its
/// bounce 0's and its later bounces' parts.
struct BounceSplit<'a> {
    high: &'a TransferResult,
    lit: &'a [usize],
    n: usize,
    /// Σ over lit vertices of the high bake's total DC².
    norm: f64,
}

impl<'a> BounceSplit<'a> {
    fn new(high: &'a TransferResult, lit: &'a [usize], n: usize) -> Self {
        let norm = lit.iter().map(|&v| (high.total[v * n] as f64).powi(2)).sum();
        BounceSplit { high, lit, n, norm }
    }

    /// DC of vertex `v`: 0 the total, 1 bounce 0, 2 the later bounces.
    fn dc(&self, result: &TransferResult, v: usize, part: usize) -> f64 {
        let at = |layer: &[f32]| layer[v * self.n] as f64;
        match part {
            0 => at(&result.total),
            1 => at(&result.bounces[0]),
            _ => result.bounces[1..].iter().map(|b| at(b)).sum(),
        }
    }

    fn direct_share(&self) -> f64 {
        let sum = |part| self.lit.iter().map(|&v| self.dc(self.high, v, part)).sum::<f64>();
        sum(1) / sum(0)
    }

    /// Relative RMS DC difference from the high bake of the total, bounce 0
    /// and the later bounces, each over the high bake's total.
    fn errors(&self, result: &TransferResult) -> [f64; 3] {
        [0, 1, 2].map(|part| {
            let squared: f64 = self.lit.iter().map(|&v| (self.dc(result, v, part) - self.dc(self.high, v, part)).powi(2)).sum();
            (squared / self.norm).sqrt()
        })
    }
}

/// `RAYS:ADAPTIVE[:ws][:seed=N]` over the scene's base parameters.
fn parse_setting(setting: &str, base: &BakeParams) -> anyhow::Result<BakeParams> {
    let mut parts = setting.split(':');
    let mut params = *base;
    params.rays = parts.next().unwrap_or_default().parse().with_context(|| format!("{setting}: rays"))?;
    params.adaptive = parts.next().context("RAYS:ADAPTIVE")?.parse().with_context(|| format!("{setting}: adaptive"))?;
    for part in parts {
        match part.strip_prefix("seed=") {
            Some(seed) => params.seed = seed.parse().with_context(|| format!("{setting}: seed"))?,
            None if part == "ws" => params.window_sampling = true,
            None => bail!("{setting}: unknown {part:?}"),
        }
    }
    Ok(params)
}

/// A bundle's one-channel total transfer in the scene's vertex order.
fn bundle_transfer(path: &Path, scene: &RealScene, n: usize) -> anyhow::Result<Vec<f32>> {
    let bundle = prtbake::bundle::read_bundle(path)?;
    let transfer = bundle.transfer.with_context(|| format!("{}: no transfer", path.display()))?;
    ensure!(
        transfer.channels == 1 && transfer.order as usize * transfer.order as usize == n,
        "{}: not one channel of the reference's order",
        path.display()
    );
    let total = transfer.total();
    if bundle.mesh.positions == scene.mesh.positions {
        return Ok(total);
    }
    let key = |p: &glam::Vec3| (p.x.to_bits(), p.y.to_bits(), p.z.to_bits());
    let mut at: HashMap<_, usize> = HashMap::new();
    for (i, p) in bundle.mesh.positions.iter().enumerate() {
        at.entry(key(p)).or_insert(i);
    }
    let mut out = vec![0.0f32; scene.mesh.vertex_count() * n];
    for (v, p) in scene.mesh.positions.iter().enumerate() {
        let i = *at.get(&key(p)).with_context(|| format!("{}: no vertex at the scene's vertex {v}", path.display()))?;
        out[v * n..][..n].copy_from_slice(&total[i * n..][..n]);
    }
    Ok(out)
}

/// Each reference seed's DC, in seed order.
fn seed_dcs(cache: &Path, scene: &RealScene, reference: &RealReference, n: usize) -> anyhow::Result<Vec<Vec<f32>>> {
    reference
        .seeds
        .iter()
        .map(|seed| {
            Ok(bundle_transfer(&cache.join(format!("{}-reference-s{seed}.prtb", scene.name)), scene, n)?.into_iter().step_by(n).collect())
        })
        .collect()
}
