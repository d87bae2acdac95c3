//! `prtbake panel`: the LCD panel's reflected light by final gather, and
//! whether the driver can read it (docs/panel.md). Writes the reflected
//! radiance (EXR) and the contrast-ratio map with its legend (PNG), prints
//! statistics (`--json` on stdout), progress on stderr.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use glam::Vec3;
use serde_json::json;

use super::Output;
use crate::bake::Surfaces;
use crate::brdf::{EnergyReport, PanelBrdf};
use crate::bundle::Bundle;
use crate::files::Staged;
use crate::panel::{
    interior, layout, select_panel, Display, Environment, GatherOptions, Interior, PanelError, PanelGather, PanelLayout, Readability,
    TexelResult,
};
use crate::sky::{LocalDate, Site};
use crate::trace::{BuildQuality, Scene};

/// The light outside.
#[derive(Clone, Debug)]
pub enum PanelLight {
    /// An equirect map (`--env`) under a car turned by `yaw_deg`.
    Map { path: PathBuf, yaw_deg: f32 },
    /// The Preetham sky and sun at a local time and place (`--sky`).
    Sky { date: LocalDate, minutes: u32, tz_minutes: i32, site: Site, turbidity: f64, yaw_deg: f32 },
    /// The CIE overcast sky of a horizontal illuminance (`--overcast`).
    Overcast { lux: f64 },
}

/// What to gather, how, and where to write it.
#[derive(Clone, Debug)]
pub struct PanelConfig {
    pub bundle: PathBuf,
    /// Glob on material or group names; `None` = materials with the panel role.
    pub panel: Option<String>,
    pub eye: Vec3,
    pub light: PanelLight,
    /// A measured BRDF file; `None` = the anti-glare coating.
    pub brdf: Option<PathBuf>,
    /// Texels; `None` = 256 along the long side, square texels.
    pub texels: Option<(u32, u32)>,
    pub samples: u32,
    pub seed: u32,
    pub display: Display,
    pub threshold: f32,
    /// Reflected radiance (.exr) and contrast ratio (.png).
    pub output: PathBuf,
    pub contrast: PathBuf,
    pub threads: usize,
    pub json: bool,
    pub quiet: bool,
    pub force: bool,
}

/// The contrast PNG beside `output`: `OUT.exr` → `OUT.cr.png`.
pub fn contrast_path(output: &Path) -> PathBuf {
    output.with_extension("cr.png")
}

/// A finished gather and its statistics.
pub struct PanelRun {
    pub layout: PanelLayout,
    pub results: Vec<Option<TexelResult>>,
    pub readability: Readability,
    /// Gather rays (BRDF and sun-disk draws) and every query traced for them
    /// (continuations through glass, shadow rays toward the sun).
    pub rays: u64,
    pub queries: u64,
    /// The whole run, and the gather alone (no BVH build, no images).
    pub seconds: f64,
    pub gather_seconds: f64,
    pub environment: String,
    pub brdf: String,
    /// Where the interior's PRT light is read at a hit: "texels" (a texel bundle) or "vertices".
    pub interior_light: &'static str,
}

/// The environment of `light` (the map is read here; errors name it).
pub fn environment(light: &PanelLight) -> anyhow::Result<Environment> {
    Ok(match light {
        PanelLight::Map { path, yaw_deg } => Environment::map(crate::sh::load_equirect(path)?, *yaw_deg),
        PanelLight::Sky { date, minutes, tz_minutes, site, turbidity, yaw_deg } => {
            let time = crate::sky::unix_time(*date, f64::from(*minutes), *tz_minutes);
            let position = crate::sky::solar_position(site, time, crate::sky::DEFAULT_DELTA_T_S);
            let sun = crate::sky::sun_direction(&position, crate::sky::default_north(Vec3::Y), Vec3::Y);
            Environment::clear_sky(sun, *turbidity, *yaw_deg).with_context(|| {
                format!("the sun is below the horizon at that time (elevation {:.1}°): no sky to light the panel", position.elevation_deg)
            })?
        }
        PanelLight::Overcast { lux } => Environment::overcast(*lux),
    })
}

/// Gathers the panel of `bundle` (read from `path`, named in errors).
#[allow(clippy::too_many_arguments)] // the gather's inputs, each checked by the caller
pub fn gather_panel(
    bundle: &Bundle,
    path: &Path,
    pattern: Option<&str>,
    eye: Vec3,
    env: &Environment,
    brdf: &PanelBrdf,
    texels: Option<(u32, u32)>,
    samples: u32,
    seed: u32,
    display: Display,
    threshold: f32,
    quiet: bool,
) -> anyhow::Result<PanelRun> {
    let started = Instant::now();
    let transfer = bundle.transfer.as_ref().ok_or_else(|| PanelError::NoTransfer { path: path.to_path_buf() })?;
    if transfer.channels != 1 && transfer.channels != 3 {
        return Err(PanelError::BadChannels { path: path.to_path_buf(), channels: transfer.channels }.into());
    }
    let mesh = &bundle.mesh;
    let triangles = select_panel(mesh, pattern, path)?;
    let (width, height) = texels.unwrap_or_else(|| layout::default_texels(mesh, &triangles, 256));
    let layout = PanelLayout::new(mesh, &triangles, width, height, path)?;
    if (eye - layout.centre).dot(layout.front) <= 0.0 {
        return Err(PanelError::EyeBehind {
            path: path.to_path_buf(),
            eye: eye.to_array(),
            centre: layout.centre.to_array(),
            normal: layout.front.to_array(),
        }
        .into());
    }
    let surfaces = Surfaces::resolve(mesh, &bundle.window_patterns())?;
    let scene = Scene::build(mesh, BuildQuality::Sah)?;
    let order = transfer.order as usize;
    let light = interior::vertex_light(&transfer.total(), order, transfer.channels as usize, &env.sh_lighting(order));
    let two_sided = bundle.is_window_mode();
    // A texel bundle: the interior's light where the viewer takes it, from the texels.
    let texel_light = bundle.texels.as_ref().and_then(|t| {
        let transfer = t.transfer.as_ref()?;
        let order = transfer.order as usize;
        Some(interior::texel_light(&t.atlas, &t.texels, &transfer.total(), order, transfer.channels as usize, &env.sh_lighting(order)))
    });
    let interior_light = if texel_light.is_some() { "texels" } else { "vertices" };
    let side_shares =
        crate::panel::SideShares::of(transfer, bundle.texels.as_ref().and_then(|t| Some((&t.atlas, &t.texels[..], t.transfer.as_ref()?))));
    let interior = Interior { scene: &scene, mesh, surfaces: &surfaces, vertex_light: light, two_sided, texel_light, side_shares };
    let mut gather = PanelGather::new(&interior, env, brdf, &layout, eye, GatherOptions { seed, ..GatherOptions::default() });
    if !quiet {
        eprintln!(
            "panel: {} triangles, {}x{} texels ({} on the panel, {} mapping), {} samples per texel; {}; the interior's light from its {interior_light}",
            triangles.len(),
            width,
            height,
            layout.covered(),
            layout.mapping.name(),
            samples,
            env.describe()
        );
    }
    let pass = samples.div_ceil(8).max(1);
    let gather_started = Instant::now();
    while gather.samples() < samples {
        gather.refine(pass.min(samples - gather.samples()));
        if !quiet {
            eprint!("\rgather: {}/{} samples per texel", gather.samples(), samples);
        }
    }
    if !quiet {
        eprintln!();
    }
    let gather_seconds = gather_started.elapsed().as_secs_f64();
    let results = gather.results();
    crate::panel::check_finite(&results, path, &env.describe())?;
    let (rays, queries) = (gather.rays(), gather.queries());
    let readability = Readability::of(&results, display, threshold).ok_or_else(|| PanelError::NoTexels {
        path: path.to_path_buf(),
        width,
        height,
        mapping: layout.mapping.name(),
    })?;
    drop(gather);
    Ok(PanelRun {
        layout,
        results,
        readability,
        rays,
        queries,
        seconds: started.elapsed().as_secs_f64(),
        gather_seconds,
        environment: env.describe(),
        brdf: String::new(),
        interior_light,
    })
}

/// Stages the EXR and the PNG of `run`.
pub fn stage_images(run: &PanelRun, exr: &Path, png: &Path, display: Display, staged: &mut Staged) -> anyhow::Result<()> {
    let (w, h) = (run.layout.width, run.layout.height);
    let exr_bytes = crate::panel::images::radiance_exr(&run.results, w, h).with_context(|| format!("cannot encode {}", exr.display()))?;
    let png_bytes =
        crate::panel::images::contrast_png(&run.results, w, h, display).with_context(|| format!("cannot encode {}", png.display()))?;
    staged.stage_bytes(exr, &exr_bytes).with_context(|| format!("cannot write {}", exr.display()))?;
    staged.stage_bytes(png, &png_bytes).with_context(|| format!("cannot write {}", png.display()))?;
    Ok(())
}

/// The JSON statistics of a run.
pub fn run_json(run: &PanelRun, exr: &Path, png: &Path, display: Display, samples: u32) -> serde_json::Value {
    json!({
        "radiance_exr": super::json_path(exr),
        "contrast_png": super::json_path(png),
        "texels": [run.layout.width, run.layout.height],
        "texels_on_panel": run.layout.covered(),
        "mapping": run.layout.mapping.name(),
        "samples_per_texel": samples,
        "environment": run.environment,
        "interior_light": run.interior_light,
        "brdf": run.brdf,
        "display": display,
        "luminance": "Rec. 709: Y = 0.2126 R + 0.7152 G + 0.0722 B",
        "contrast_ratio": "(L_white + L_reflected) / (L_black + L_reflected)",
        "readability": run.readability,
        "rays": run.rays,
        "queries": run.queries,
        "seconds": run.seconds,
        "rays_per_second": run.rays as f64 / run.seconds.max(1e-9),
        "gather_seconds": run.gather_seconds,
        "gather_rays_per_second": run.rays as f64 / run.gather_seconds.max(1e-9),
        "gather_queries_per_second": run.queries as f64 / run.gather_seconds.max(1e-9),
    })
}

pub fn run(config: &PanelConfig) -> anyhow::Result<()> {
    super::check_threads(config.threads)?;
    let mut inputs: Vec<&Path> = vec![&config.bundle];
    if let PanelLight::Map { path, .. } = &config.light {
        inputs.push(path);
    }
    if let Some(brdf) = &config.brdf {
        inputs.push(brdf);
    }
    super::check_outputs(&inputs, &[Output::new(&config.output, &["exr"]), Output::new(&config.contrast, &["png"])], config.force)?;
    if config.samples == 0 || config.samples > crate::panel::gather::MAX_SAMPLES {
        anyhow::bail!("--samples {}: expected 1..={}", config.samples, crate::panel::gather::MAX_SAMPLES);
    }
    // A BRDF file's energy is checked as it is read; the built-in one's by
    // its tests (`brdf::analytic`), not again on every run.
    let brdf_name = config.brdf.as_ref().map_or("antiglare".to_string(), |path| path.display().to_string());
    let brdf = match &config.brdf {
        Some(path) => {
            let brdf = PanelBrdf::load(path)?;
            let report = super::with_threads(config.threads, || EnergyReport::of(&brdf))?;
            if let Some(warning) = report.warning(&brdf_name) {
                eprintln!("warning: {warning}");
            }
            brdf
        }
        None => PanelBrdf::default(),
    };
    let env = environment(&config.light)?;
    let bundle = crate::bundle::read_bundle(&config.bundle)?;
    let quiet = config.quiet || config.json;
    let mut run = super::with_threads(config.threads, || {
        gather_panel(
            &bundle,
            &config.bundle,
            config.panel.as_deref(),
            config.eye,
            &env,
            &brdf,
            config.texels,
            config.samples,
            config.seed,
            config.display,
            config.threshold,
            quiet,
        )
    })??;
    run.brdf = brdf_name;
    let mut staged = Staged::new();
    stage_images(&run, &config.output, &config.contrast, config.display, &mut staged)?;
    staged.commit().context("cannot write the panel images")?;
    let report = run_json(&run, &config.output, &config.contrast, config.display, config.samples);
    if config.json {
        super::print_json(&report)?;
    } else {
        let r = &run.readability;
        println!(
            "contrast ratio: min {}, median {}; {:.1}% of texels below {}:1; reflected luminance mean {}, max {} cd/m²; {:.0}% straight from the sky ({:.0}% through windows), {:.0}% from the interior",
            super::significant(r.min_contrast_ratio.into(), 3),
            super::significant(r.median_contrast_ratio.into(), 3),
            100.0 * r.fraction_below_threshold,
            r.threshold,
            super::significant(r.mean_reflected_luminance.into(), 3),
            super::significant(r.max_reflected_luminance.into(), 3),
            100.0 * r.sky_share,
            100.0 * r.window_share,
            100.0 * r.interior_share
        );
        println!(
            "wrote {} and {} ({:.1} s; gather {:.1} s, {:.2e} rays/s, {:.2e} queries/s)",
            config.output.display(),
            config.contrast.display(),
            run.seconds,
            run.gather_seconds,
            run.rays as f64 / run.gather_seconds.max(1e-9),
            run.queries as f64 / run.gather_seconds.max(1e-9)
        );
    }
    Ok(())
}
