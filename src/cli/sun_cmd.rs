//! `prtbake sun MESH_OR_BUNDLE -o OUT.prtb`: a day's sun masks and per-step
//! sun and sky (seed 001, the Parthenon time lapse).
//!
//! Given a bundle, its mesh is reused vertex for vertex and every other
//! section (transfer included) is copied byte for byte; given a mesh file, a
//! new bundle holds the mesh and the sun sections (no transfer). With
//! `--refine` the mesh changes, so a bundle's transfer is baked again on the
//! refined mesh as its META says (`bundle::recipe`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use glam::Vec3;
use serde_json::json;

use crate::bake::{self, Mode, SunMasks, SunParams, SunStats, Surfaces};
use crate::bundle::{self, Bundle, SunSeries, SunStep};
use crate::files::read::read_head;
use crate::files::{read_limited, Limit};
use crate::mesh::UpAxis;
use crate::trace::{BuildQuality, Scene};

use super::bake_cmd::BUNDLE_FORMAT;
use super::Output;
use crate::sky::{self, LocalDate, Site, SkyFrame, StepSpec};

/// Where the sun's directions come from.
#[derive(Clone, Debug)]
pub enum SunSource {
    /// NREL SPA at `site` over a time line.
    Solar {
        site: Site,
        date: LocalDate,
        /// Minutes east of UTC.
        tz_minutes: i32,
        /// Local minutes after midnight of `date`.
        from_min: f64,
        to_min: f64,
        steps: StepSpec,
    },
    /// A CSV of directions (`x,y,z` per line, toward the sun).
    Directions(PathBuf),
}

/// A checked `sun` configuration.
#[derive(Clone, Debug)]
pub struct SunConfig {
    /// A mesh file (.obj, .gltf, .glb) or a bundle (.prtb, recognised by its magic).
    pub input: PathBuf,
    pub output: PathBuf,
    /// Up axis of an OBJ input; `--north` and `--directions` are read in the input's own axes.
    pub up: UpAxis,
    pub source: SunSource,
    /// Geographic north in the input's axes; `None` = −Z for +Y up, +Y for +Z up.
    pub north: Option<Vec3>,
    pub turbidity: f64,
    pub sky_order: usize,
    pub params: SunParams,
    pub window_patterns: Vec<String>,
    pub threads: usize,
    pub json: bool,
    /// Replace a read-only output (`--force`).
    pub force: bool,
    /// Trace one shard's samples into a part instead of the bundle (`--shard`).
    pub shard: Option<crate::shards::Shard>,
    /// Refine the mesh where the sun's light changes (`--refine`, `--max-vertices`); a bundle's
    /// transfer is then baked again on the refined mesh (`bundle::recipe`).
    pub refine: Option<super::bake_cmd::RefineRequest>,
    /// Sun bits per texel too: of a new atlas at this size (`--texel-size`)
    /// for a mesh or a vertex bundle, or beside a bundle's texel transfer as
    /// the sun's own atlas; without it a texel bundle's atlas is used.
    pub texel_size: Option<f32>,
    /// Points per texel (`--texel-points`); default: the texel bundle's
    /// transfer bake's, else [`bake::texels::POINTS_PER_TEXEL`].
    pub texel_points: Option<u32>,
    /// Also store each texel's lit share per step in 4 bits (`--texel-fractions`, section TSUF).
    pub texel_fractions: bool,
    /// Unwrap a new atlas even where the mesh has its own (`--unwrap`; `TEXCOORD_1`).
    pub unwrap: bool,
    /// A new atlas's texel size per chart, picked by a pilot within a budget
    /// (`--texel-levels`, `--max-error`); `texel_size` is then the finest.
    pub texel_density: Option<bake::texel_density::DensityRequest>,
}

/// What `sun` reports.
pub struct SunReport {
    pub output: PathBuf,
    pub masks: SunMasks,
    /// Texel mode: the texels' bits and the atlas's seconds (0 when the bundle had it).
    pub texel_masks: Option<(bake::TexelSunMasks, f64)>,
    /// `--texel-levels`: the pilot and each chart's texel size.
    pub texel_density: Option<bake::texel_density::DensityReport>,
    pub steps: Vec<SunStep>,
    pub input_was_bundle: bool,
    pub sky_seconds: f64,
    pub build_seconds: f64,
    /// Encoding and writing the bundle (and re-baking its transfer after `--refine`).
    pub write_seconds: f64,
    /// `--refine` on a bundle with transfer: the transfer was baked again on the refined mesh.
    pub transfer_rebaked: bool,
    pub bundle_bytes: u64,
    /// What adaptive refinement did (`--refine`).
    pub refine: Option<crate::refine::RefineReport>,
}

/// Runs `sun` end to end and prints its report. A shard's run
/// (`config.shard`) is [`super::shard_cmd::run_sun`]'s.
pub fn run(config: &SunConfig) -> anyhow::Result<()> {
    anyhow::ensure!(config.shard.is_none(), "a shard's run is shard_cmd::run_sun's");
    let report = sun_to_bundle(config)?;
    print_report(&report, config.json)
}

/// A bundle by its magic, or by its `.prtb` name (so that a damaged one is
/// reported as a bad bundle, not as an unknown mesh format).
fn is_bundle(path: &Path) -> anyhow::Result<bool> {
    let head = read_head(path, Limit::Bundle, 8).with_context(|| format!("cannot read {}", path.display()))?;
    Ok(head == bundle::MAGIC || path.extension().is_some_and(|e| e.eq_ignore_ascii_case("prtb")))
}

fn is_obj(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj"))
}

/// A sun bake's input, loaded: the mesh in the bake's +Y-up world, the
/// input bundle's bytes and metadata when it was one, and the sky frame.
pub struct SunInput {
    pub mesh: crate::mesh::Mesh,
    /// The input bundle and its META, when the input was a bundle.
    pub original: Option<(Vec<u8>, serde_json::Value)>,
    /// The input bundle holds a transfer section.
    pub had_transfer: bool,
    pub frame: SkyFrame,
    /// The axes `--north` and `--directions` are read in.
    pub file_up: UpAxis,
    /// The input's file name, as META `source` records it.
    pub source_name: Option<String>,
    /// The light the input bundle was baked for (its transfer's, else its
    /// earlier sun masks'): window mode and patterns.
    pub recorded_windows: Option<(Mode, Vec<String>)>,
    /// A texel bundle's atlas and covered texels, when the sun bits go on
    /// it (`None` with [`SunInput::sun_atlas_of_its_own`]).
    pub atlas: Option<(crate::atlas::Atlas, Vec<u32>)>,
    /// With [`SunInput::sun_atlas_of_its_own`]: the transfer's atlas, whose
    /// charts the sun's repacks when the texel sizes allow.
    pub charts_from: Option<crate::atlas::Atlas>,
}

impl SunInput {
    /// `--texel-size` on a bundle with texel transfer: the sun bits get an
    /// atlas of their own (TSAT) at that size, beside the transfer's.
    pub fn sun_atlas_of_its_own(&self) -> bool {
        self.charts_from.is_some()
    }

    pub fn was_bundle(&self) -> bool {
        self.original.is_some()
    }
}

/// Loads and checks the input (`outputs`' extensions: `formats`); a bundle
/// may be its own output only when `in_place` (the documented update).
pub fn load_sun_input(config: &SunConfig, formats: &[&str], in_place: bool) -> anyhow::Result<SunInput> {
    let quiet = config.params.quiet;
    let input = &config.input;
    super::check_threads(config.threads)?;
    let input_was_bundle = is_bundle(input)?;
    // `sun B.prtb -o B.prtb` is the documented in-place update; every other
    // overlap of an output with an input is refused.
    let outputs = [Output { may_be_input: input_was_bundle && in_place, ..Output::new(&config.output, formats) }];
    super::check_outputs(&[input], &outputs, config.force)?;
    if let SunSource::Directions(csv) = &config.source {
        super::check_outputs(&[csv], &[Output::new(&config.output, formats)], config.force)?;
    }
    // The bake's world is +Y up; user vectors come in the input's axes.
    let file_up = if input_was_bundle {
        if config.up == UpAxis::Z {
            anyhow::bail!("{}: a bundle's mesh is already +Y up; --up z applies to OBJ files only", input.display());
        }
        UpAxis::Y
    } else if is_obj(input) {
        config.up
    } else {
        UpAxis::Y
    };
    let (mesh, original, had_transfer, atlas, charts_from) = if input_was_bundle {
        let bytes = bundle::read_bundle_bytes(input).map_err(|e| match e {
            bundle::BundleError::Io { source, .. } => anyhow::Error::new(source).context(format!("cannot read {}", input.display())),
            bundle::BundleError::InFile { source, .. } => anyhow::anyhow!("{}: not a valid bundle: {source}", input.display()),
            other => other.into(),
        })?;
        let b = bundle::decode_bundle(&bytes).with_context(|| format!("{}: not a valid bundle", input.display()))?;
        let own = config.texel_size.is_some() && b.texels.as_ref().is_some_and(|t| t.transfer.is_some());
        let (atlas, charts_from) = match b.texels {
            Some(t) if own => (None, Some(t.atlas)),
            t => (t.map(|t| (t.atlas, t.texels)), None),
        };
        (b.mesh, Some((bytes, b.meta)), b.transfer.is_some(), atlas, charts_from)
    } else {
        // The new bundle says which glass was a window, as a transfer bake's does.
        let mesh = super::load_mesh(input, config.up, quiet, &outputs, config.force)?;
        (Surfaces::with_window_roles(&mesh, &config.window_patterns)?, None, false, None, None)
    };
    let recorded_windows = original.as_ref().and_then(|(_, meta)| recorded_windows(meta, had_transfer));
    let up = Vec3::Y;
    let north = match config.north {
        Some(n) => {
            let n = file_up.to_y_up(n);
            if !(n - up * n.dot(up)).is_finite() || (n - up * n.dot(up)).length() < 1e-6 {
                let n = config.north.unwrap_or_default();
                anyhow::bail!("--north {},{},{} must be finite and not parallel to up", n.x, n.y, n.z);
            }
            n
        }
        None => sky::default_north(up),
    };
    let frame = SkyFrame { north, up, turbidity: config.turbidity, sky_order: config.sky_order };
    let source_name = input.file_name().map(|n| n.to_string_lossy().to_string());
    Ok(SunInput { mesh, original, had_transfer, frame, file_up, source_name, recorded_windows, atlas, charts_from })
}

/// The points per texel of a texel sun bake: `--texel-points`, else the
/// texel bundle's transfer bake's when the bits go on its atlas (its
/// points, so the same seed votes on the same points), else the default.
pub fn texel_points(config: &SunConfig, input: &SunInput) -> u32 {
    let recorded = input.original.as_ref().filter(|_| !input.sun_atlas_of_its_own());
    let recorded = recorded.and_then(|(_, meta)| meta.pointer("/texels/points_per_texel")?.as_u64());
    config.texel_points.or(recorded.and_then(|p| u32::try_from(p).ok())).unwrap_or(bake::texels::POINTS_PER_TEXEL)
}

/// The mode and `--window` patterns a bundle's META records: its transfer
/// bake's when it has one, else its sun bake's.
fn recorded_windows(meta: &serde_json::Value, had_transfer: bool) -> Option<(Mode, Vec<String>)> {
    let from = if had_transfer { meta } else { meta.get("sun")? };
    let mode: Mode = serde_json::from_value(from.pointer("/params/mode")?.clone()).ok()?;
    Some((mode, crate::bundle::window_patterns_in(from)))
}

/// `config` with the window setup of the input bundle: a `sun` given
/// neither `--window` nor `--window-mode` lights the bundle as its bake did
/// (masks of another light than the transfer's would be silently wrong); a
/// different setup is refused.
pub fn with_bundle_windows(config: &SunConfig, input: &SunInput) -> anyhow::Result<SunConfig> {
    let Some((mode, patterns)) = &input.recorded_windows else { return Ok(config.clone()) };
    let asked_nothing = config.params.mode == Mode::Open && config.window_patterns.is_empty();
    if asked_nothing {
        if *mode == Mode::Window && !config.params.quiet {
            eprintln!("sun: window mode with --window {patterns:?}, as {} was baked", config.input.display());
        }
        let mut adopted = config.clone();
        adopted.params.mode = *mode;
        adopted.window_patterns = patterns.clone();
        return Ok(adopted);
    }
    if config.params.mode != *mode || config.window_patterns != *patterns {
        let describe = |mode: Mode, patterns: &[String]| match mode {
            Mode::Open => "open mode".to_string(),
            Mode::Window => format!("window mode with --window {patterns:?}"),
        };
        anyhow::bail!(
            "{}: baked in {}, but this sun bake asks for {}: the masks would light the scene differently from the bundle's transfer; give the same --window patterns, or none to use the bundle's",
            config.input.display(),
            describe(*mode, patterns),
            describe(config.params.mode, &config.window_patterns)
        );
    }
    Ok(config.clone())
}

/// Says on stderr when no vertex is lit at any step: a site, date, north or
/// up axis that keeps the sun out of the scene gives all-dark masks.
pub fn warn_if_never_lit(output: &Path, mode: Mode, window_patterns: &[String], stats: &SunStats) {
    if stats.vertices == 0 || stats.lit_vertices.iter().any(|&n| n > 0) {
        return;
    }
    let why = if stats.day_steps == 0 {
        "the sun is below the horizon at every step (check --date, --from/--to and --tz)".to_string()
    } else if mode == Mode::Window {
        format!(
            "the sun never reaches a surface through the windows ({window_patterns:?}) in {} daytime steps: check --north (the direction of geographic north in the file's axes; default -Z, or +Y with --up z) and --up, which turn the sun's path around the scene",
            stats.day_steps
        )
    } else {
        format!(
            "no surface faces the sun unshadowed in {} daytime steps: check --north (default -Z, or +Y with --up z) and --up",
            stats.day_steps
        )
    };
    eprintln!("warning: {}: no vertex is lit at any step; {why}", output.display());
}

/// The day: sun position, colour and sky per step.
pub fn day_steps(config: &SunConfig, input: &SunInput) -> anyhow::Result<Vec<SunStep>> {
    Ok(match &config.source {
        SunSource::Solar { site, date, tz_minutes, from_min, to_min, steps } => {
            let timeline = sky::timeline(*date, *tz_minutes, *from_min, *to_min, *steps).context("bad time line")?;
            sky::day_steps(site, &timeline, sky::DEFAULT_DELTA_T_S, &input.frame)
        }
        SunSource::Directions(path) => {
            let bytes = read_limited(path, Limit::Text).with_context(|| format!("cannot read {}", path.display()))?;
            let text = String::from_utf8(bytes).map_err(|e| anyhow::anyhow!("{}: not UTF-8 text ({e})", path.display()))?;
            let directions = sky::parse_directions(&text, bake::sun::MAX_SUN_STEPS)
                .map_err(|e| anyhow::anyhow!("{}:{}: {}", path.display(), e.line, e.message))?;
            let world: Vec<Vec3> = directions.into_iter().map(|d| input.file_up.to_y_up(d)).collect();
            sky::steps_from_directions(&world, &input.frame)
        }
    })
}

/// The surfaces of `mesh`; window mode needs a window.
pub fn sun_surfaces(config: &SunConfig, mesh: &crate::mesh::Mesh) -> anyhow::Result<Surfaces> {
    let surfaces = Surfaces::resolve(mesh, &config.window_patterns)?;
    if config.params.mode == Mode::Window && surfaces.window_triangle_count() == 0 {
        anyhow::bail!(
            "{}: window mode, but no triangle is a window (no material role, and --window {:?} matched no material or group name)",
            config.input.display(),
            config.window_patterns
        );
    }
    Ok(surfaces)
}

/// The output bundle's bytes: the input bundle with the sun sections added
/// (every other section copied byte for byte) or a new bundle of the mesh.
pub fn encode_sun_output(input: &SunInput, sun_meta: serde_json::Value, series: &SunSeries, output: &Path) -> anyhow::Result<Vec<u8>> {
    let texels =
        input.atlas.as_ref().map(|(atlas, texels)| bundle::TexelLayers { atlas: atlas.clone(), texels: texels.clone(), transfer: None });
    let encoded = match &input.original {
        Some((bytes, meta)) => {
            let mut meta = meta.clone();
            if let Some(m) = meta.as_object_mut() {
                m.insert("sun".into(), sun_meta);
            } else {
                meta = json!({ "previous_meta": meta, "sun": sun_meta });
            }
            let atlas = input.atlas.as_ref().map(|(atlas, texels)| (atlas, &texels[..]));
            bundle::encode_with_sun_on(bytes, &meta, series, atlas)
        }
        None => {
            let meta = json!({
                "tool": "prtbake",
                "version": env!("CARGO_PKG_VERSION"),
                "command": "sun",
                "source": input.source_name,
                "sun": sun_meta,
                "conventions": crate::bundle::conventions(),
            });
            bundle::encode_bundle(&Bundle { meta, mesh: input.mesh.clone(), transfer: None, sun: Some(series.clone()), texels })
        }
    };
    encoded.with_context(|| format!("cannot encode {}", output.display()))
}

/// Checks the texel flags against the input: fractions need texels, and a
/// texel bundle's atlas is the one its sun bits must match.
pub fn check_texel_request(config: &SunConfig, input: &SunInput) -> anyhow::Result<()> {
    if config.texel_fractions && config.texel_size.is_none() && input.atlas.is_none() {
        anyhow::bail!("--texel-fractions: the sun is baked per vertex here; give --texel-size L, or a bundle with an atlas");
    }
    if config.texel_density.is_some() {
        if config.texel_size.is_none() {
            anyhow::bail!("--texel-levels: the sun is baked per vertex here; give --texel-size L (the finest texel)");
        }
        if input.atlas.is_none() {
            super::bake_cmd::check_density_atlas(&input.mesh, config.unwrap, &config.input)?;
        }
    }
    if let (Some(size), Some((atlas, _))) = (config.texel_size, &input.atlas) {
        anyhow::bail!(
            "{}: --texel-size {size}, but the bundle has an atlas ({} m texels) with sun bits only, whose texels the new bits must match; leave --texel-size out",
            config.input.display(),
            atlas.texel_size
        );
    }
    Ok(())
}

/// The atlas of a texel sun bake, with the seconds unwrapping took: a texel
/// bundle's own (0 s), else a new one at `--texel-size` (beside texel
/// transfer, its charts repacked when its size is theirs over 1, 2, 4 or
/// 8); none per vertex.
/// The atlas of the sun's texels with its seconds: [`sun_atlas`], or with
/// `--texel-levels` the one its pilot sizes per chart, and its report. A
/// whole bake and every shard (each with its own pilot) call this alike.
pub fn sun_texel_atlas(
    config: &SunConfig,
    input: &SunInput,
    scene: &Scene,
    surfaces: &bake::Surfaces,
    suns: &[Option<glam::Vec3>],
) -> anyhow::Result<Option<(crate::atlas::Atlas, f64, Option<bake::texel_density::DensityReport>)>> {
    Ok(match (&input.atlas, config.texel_size, &config.texel_density) {
        (None, Some(finest), Some(density)) => {
            let started = Instant::now();
            let (atlas, report) = bake::texel_density::sun_density_atlas(
                &input.mesh,
                scene,
                surfaces,
                suns,
                &config.params,
                finest,
                density,
                input.charts_from.as_ref(),
            )
            .with_context(|| format!("{}: --texel-levels", config.input.display()))?;
            Some((atlas, started.elapsed().as_secs_f64(), Some(report)))
        }
        _ => sun_atlas(config, input)?.map(|(atlas, seconds)| (atlas, seconds, None)),
    })
}

pub fn sun_atlas(config: &SunConfig, input: &SunInput) -> anyhow::Result<Option<(crate::atlas::Atlas, f64)>> {
    let started = Instant::now();
    Ok(match (&input.atlas, config.texel_size) {
        (Some((atlas, _)), _) => Some((atlas.clone(), 0.0)),
        (None, Some(size)) => {
            let atlas = match input.charts_from.as_ref().and_then(|a| a.with_texel_size(size)) {
                Some(repacked) => repacked,
                None => crate::atlas::Atlas::for_mesh(&input.mesh, size, config.unwrap),
            };
            let atlas = atlas.with_context(|| config.input.display().to_string())?;
            Some((atlas, started.elapsed().as_secs_f64()))
        }
        (None, None) => None,
    })
}

/// Whose a new atlas is: the mesh's own lightmap UVs, xatlas's unwrap, or
/// (the sun's own atlas beside texel transfer) the transfer's charts repacked.
pub fn new_atlas_source_name(config: &SunConfig, input: &SunInput) -> &'static str {
    let pilot_or_size = match (&config.texel_density, config.texel_size) {
        (Some(density), Some(finest)) => Some(density.pilot_size(finest)),
        (_, size) => size,
    };
    let base = input.charts_from.as_ref();
    if base.zip(pilot_or_size).is_some_and(|(base, size)| base.repack_level(size).is_some()) {
        return "the texel transfer's charts, repacked";
    }
    super::bake_cmd::atlas_source_name(&input.mesh, config.unwrap)
}

/// The texels and points of a texel sun bake over `atlas`; a texel
/// bundle's list of covered texels must be the atlas's.
pub fn texel_sun_plan(
    config: &SunConfig,
    input: &SunInput,
    atlas: &crate::atlas::Atlas,
    points_per_texel: u32,
    suns: &[Option<Vec3>],
) -> anyhow::Result<bake::TexelSunPlan> {
    let pattern = bake::DirectionPattern::Sobol;
    let plan = bake::TexelSunPlan::new(&input.mesh, atlas, points_per_texel, pattern, suns, &config.params)
        .with_context(|| config.input.display().to_string())?;
    if let Some((_, covered)) = &input.atlas {
        anyhow::ensure!(
            covered == plan.texels(),
            "{}: the atlas lists {} covered texels, but its triangles overlap {}: a damaged atlas",
            config.input.display(),
            covered.len(),
            plan.texel_count()
        );
    }
    Ok(plan)
}

/// META `sun.texels` of a texel sun bake (no timings); `new_atlas_source`
/// names where an atlas made for this bake came from.
pub fn texel_sun_meta(
    atlas: &crate::atlas::Atlas,
    stats: &bake::TexelSunStats,
    fractions: bool,
    new_atlas_source: Option<&str>,
) -> serde_json::Value {
    let mut meta = json!({
        "texel_size": atlas.texel_size,
        "points_per_texel": stats.points_per_texel,
        "fractions": fractions,
        "covered": stats.texels,
        "points": stats.points,
        "rays": stats.rays,
        "lit_texels": stats.lit_texels,
        "bit_rule": "lit iff a strict majority of the texel's points (its footprint on its triangles, each weighted by the area it stands for; window triangles' left out) see the sun, each tested as a vertex's sample",
    });
    if let Some(source) = new_atlas_source {
        meta["atlas"] = json!(source);
    }
    meta
}

/// Loads the input, computes the day, bakes the masks and writes the bundle.
pub fn sun_to_bundle(config: &SunConfig) -> anyhow::Result<SunReport> {
    // In place only without `--refine`: refining replaces the bundle's mesh
    // and transfer, which the input alone can give back.
    let mut input = load_sun_input(config, BUNDLE_FORMAT, config.refine.is_none())?;
    let config = &with_bundle_windows(config, &input)?;
    // Refining a bundle's mesh re-bakes its transfer on the new vertices:
    // read how before any work, so a bundle that cannot be re-baked stops here.
    if config.refine.is_some() {
        // Its texels (transfer or sun bits) belong to the mesh refinement replaces, and only the vertices could be re-baked.
        if input.atlas.is_some() || input.sun_atlas_of_its_own() {
            anyhow::bail!(
                "{}: the bundle holds texels (texel mode): --refine replaces its mesh, whose atlas and texels would be lost; \
                 run sun on it without --refine, or refine the mesh and bake texels again",
                config.input.display()
            );
        }
    }
    if config.refine.is_some() && config.texel_size.is_some() {
        anyhow::bail!("--texel-size with --refine: texels already resolve the sun where vertices cannot; refine or bake texels");
    }
    check_texel_request(config, &input)?;
    let recipe = match (&config.refine, &input.original) {
        (Some(_), Some((_, meta))) if input.had_transfer => {
            Some(crate::bundle::recipe::TransferRecipe::from_meta(&config.input, meta, config.params.quiet)?)
        }
        _ => None,
    };
    let points_per_texel = texel_points(config, &input);
    let (steps, build_seconds, sky_seconds, masks, refined, texel_masks) =
        super::with_threads(config.threads, || -> anyhow::Result<_> {
            let sky_start = Instant::now();
            let steps = day_steps(config, &input)?;
            let sky_seconds = sky_start.elapsed().as_secs_f64();
            let surfaces = sun_surfaces(config, &input.mesh)?;
            let in_input = || config.input.display().to_string();
            let suns = sky::day_directions(&steps);
            if let Some(request) = &config.refine {
                let params = request.params(&input.mesh);
                let (mesh, masks, report) =
                    crate::refine::refine_sun(input.mesh.clone(), &config.window_patterns, &suns, &config.params, &params)
                        .with_context(in_input)?;
                return Ok((steps, 0.0, sky_seconds, masks, Some((mesh, report)), None));
            }
            let scene = Scene::build(&input.mesh, BuildQuality::Sah).with_context(in_input)?;
            let masks = bake::bake_sun_masks(&input.mesh, &scene, &surfaces, &suns, &config.params).with_context(in_input)?;
            let atlas = sun_texel_atlas(config, &input, &scene, &surfaces, &suns)?;
            let texel_masks = match atlas {
                None => None,
                Some((atlas, atlas_seconds, density)) => {
                    let started = Instant::now();
                    let plan = texel_sun_plan(config, &input, &atlas, points_per_texel, &suns)?;
                    let traced = plan.trace(&input.mesh, &scene, &surfaces, 0..plan.texel_count());
                    let seconds = started.elapsed().as_secs_f64();
                    let texel_masks = plan.finish(traced, seconds);
                    Some((texel_masks, atlas, atlas_seconds, density))
                }
            };
            Ok((steps, scene.build_time.as_secs_f64(), sky_seconds, masks, None, texel_masks))
        })??;
    // Whose atlas a new one is: the mesh's own (TEXCOORD_1) or xatlas's.
    let mut new_atlas_source = None;
    let mut own_atlas = None;
    if let Some((masks, atlas, _, _)) = &texel_masks {
        if input.atlas.is_none() {
            new_atlas_source = Some(new_atlas_source_name(config, &input));
            let atlas = bundle::TexelAtlas { atlas: atlas.clone(), texels: masks.texels.clone() };
            if input.sun_atlas_of_its_own() {
                own_atlas = Some(atlas);
            } else {
                input.atlas = Some((atlas.atlas, atlas.texels));
            }
        }
    }
    let texel_density = texel_masks.as_ref().and_then(|(_, _, _, density)| density.clone());
    let texel_masks = texel_masks.map(|(masks, _, seconds, _)| (masks, seconds));
    warn_if_never_lit(&config.output, config.params.mode, &config.window_patterns, &masks.stats);
    let refine = refined.map(|(mesh, report)| {
        input.mesh = mesh;
        report
    });

    let series = SunSeries {
        sky_order: config.sky_order as u32,
        steps: steps.clone(),
        words_per_vertex: masks.words_per_vertex,
        masks: masks.masks.clone(),
        texel_masks: texel_masks.as_ref().map(|(t, _)| t.masks.clone()).unwrap_or_default(),
        texel_fractions: texel_masks.as_ref().filter(|_| config.texel_fractions).map(|(t, _)| t.fractions.clone()).unwrap_or_default(),
        texel_atlas: own_atlas,
    };
    let mut sun_meta = sun_meta(config, &input.frame, &masks.stats, input.was_bundle());
    let sun_texel_atlas = series.texel_atlas.as_ref().map(|own| &own.atlas).or(input.atlas.as_ref().map(|(atlas, _)| atlas));
    if let (Some((t, _)), Some(atlas)) = (&texel_masks, sun_texel_atlas) {
        sun_meta["texels"] = texel_sun_meta(atlas, &t.stats, config.texel_fractions, new_atlas_source);
        if series.texel_atlas.is_some() {
            // TSAT: the sun's texels are not the texel transfer's.
            sun_meta["texels"]["own_atlas"] = json!(true);
        }
        if let Some(density) = &texel_density {
            sun_meta["texels"]["density"] = density.meta();
        }
    }
    if let Some(r) = &refine {
        sun_meta["refine"] = r.meta();
    }
    let output = &config.output;
    let write_start = Instant::now();
    let encoded = match (&refine, &input.original) {
        // The mesh changed: the bundle is made anew (the transfer re-baked on it, if it had one).
        (Some(_), Some((_, meta))) => {
            let in_input = || config.input.display().to_string();
            let mut out = match &recipe {
                Some(recipe) => super::with_threads(config.threads, || recipe.bake(&input.mesh))?.with_context(in_input)?,
                None => Bundle { meta: meta.clone(), mesh: input.mesh.clone(), transfer: None, sun: None, texels: None },
            };
            out.meta["sun"] = sun_meta;
            out.sun = Some(series.clone());
            bundle::encode_bundle(&out).with_context(|| format!("cannot encode {}", output.display()))?
        }
        _ => encode_sun_output(&input, sun_meta, &series, output)?,
    };
    crate::files::write_atomic(output, &encoded).with_context(|| format!("cannot write {}", output.display()))?;
    let bundle_bytes = encoded.len() as u64;
    Ok(SunReport {
        output: output.clone(),
        masks,
        texel_masks,
        texel_density,
        steps,
        input_was_bundle: input.was_bundle(),
        sky_seconds,
        build_seconds,
        write_seconds: write_start.elapsed().as_secs_f64(),
        transfer_rebaked: recipe.is_some(),
        bundle_bytes,
        refine,
    })
}

/// The sun parameters and deterministic stats recorded in META (no timings).
pub fn sun_meta(config: &SunConfig, frame: &SkyFrame, stats: &SunStats, input_was_bundle: bool) -> serde_json::Value {
    let source = match &config.source {
        SunSource::Solar { site, date, tz_minutes, from_min, to_min, steps } => json!({
            "kind": "spa",
            "site": { "latitude_deg": site.latitude_deg, "longitude_deg": site.longitude_deg, "elevation_m": site.elevation_m },
            "date": format!("{:04}-{:02}-{:02}", date.year, date.month, date.day),
            "tz_minutes": tz_minutes,
            "from_min": from_min,
            "to_min": to_min,
            "step": match steps { StepSpec::Step(m) => json!({"minutes": m}), StepSpec::Count(n) => json!({"count": n}) },
            "delta_t_s": sky::DEFAULT_DELTA_T_S,
        }),
        SunSource::Directions(path) => json!({
            "kind": "directions",
            "file": path.file_name().map(|n| n.to_string_lossy().to_string()),
        }),
    };
    json!({
        "source": source,
        "steps": stats.steps,
        "turbidity": frame.turbidity,
        "sky_order": frame.sky_order,
        "sky_model": "Preetham 1999, projected to SH by Gauss-Legendre quadrature (256 x 512)",
        "north": frame.north.to_array(),
        "up": frame.up.to_array(),
        "input_up": match config.up { UpAxis::Y => "y", UpAxis::Z => "z" },
        "params": config.params,
        "window_patterns": config.window_patterns,
        "added_to_bundle": input_was_bundle,
        "bit_rule": "lit iff day step, n.s > 0 (open mode only), and a strict majority of the interior samples of the adjacent triangles, each weighted by its barycentric coordinate times the area it stands for, see the sun (window mode: the first hit toward the sun is glass, seen from a side of the sample that is not outside the enclosure, unless keep_outside_sides)",
        "stats": sun_stats_meta(stats),
    })
}

/// META `sun.stats`: the deterministic counts of a sun bake.
pub fn sun_stats_meta(s: &SunStats) -> serde_json::Value {
    json!({
        "points": s.points, "day_steps": s.day_steps, "rays": s.rays,
        "vertices_without_samples": s.vertices_without_samples, "lit_vertices": s.lit_vertices,
    })
}

/// Prints the final line, or the JSON document with `--json`.
pub fn print_report(report: &SunReport, as_json: bool) -> anyhow::Result<()> {
    let s = &report.masks.stats;
    if as_json {
        return super::print_json(&json!({
            "output": super::json_path(&report.output),
            "added_to_bundle": report.input_was_bundle,
            "stats": s,
            "texels": report.texel_masks.as_ref().map(|(t, atlas_seconds)| json!({ "stats": t.stats, "atlas_seconds": atlas_seconds, "density": report.texel_density })),
            "sky_seconds": report.sky_seconds,
            "bvh_build_seconds": report.build_seconds,
            "bundle_bytes": report.bundle_bytes,
            "peak_memory_bytes": bake::peak_memory_bytes(),
            "refine": report.refine,
        }));
    }
    if let Some(r) = &report.refine {
        println!("{}", r.summary());
    }
    let mut phases = vec![("sky".to_string(), report.sky_seconds)];
    match &report.refine {
        None => phases.extend([("BVH build".to_string(), report.build_seconds), ("sun rays".to_string(), s.seconds)]),
        Some(r) => phases.extend([
            (format!("{} BVH builds", r.rounds.len()), r.bvh_build_seconds),
            (format!("refinement's sun rays and splits ({} rounds)", r.rounds.len()), (r.seconds - r.bvh_build_seconds).max(0.0)),
        ]),
    }
    let write = if report.transfer_rebaked { "transfer re-baked on the refined mesh, and write" } else { "write" };
    if let Some((t, atlas_seconds)) = &report.texel_masks {
        if *atlas_seconds > 0.0 {
            phases.push(("atlas".to_string(), *atlas_seconds));
        }
        phases.push(("texel sun rays".to_string(), t.stats.seconds));
    }
    phases.push((write.to_string(), report.write_seconds));
    println!(
        "sun {}: {} steps ({} day), {} vertices, {} points, {} rays in {:.2}s ({:.2} Mrays/s), sky {:.2}s, {} bytes",
        report.output.display(),
        s.steps,
        s.day_steps,
        s.vertices,
        s.points,
        s.rays,
        s.seconds,
        s.rays_per_second / 1e6,
        report.sky_seconds,
        report.bundle_bytes
    );
    if let Some((t, _)) = &report.texel_masks {
        let lit: u64 = t.stats.lit_texels.iter().sum();
        println!(
            "texels: {} covered, {} points ({} per texel), {} rays in {:.2}s ({:.2} Mrays/s), {:.1}% of texel-steps lit",
            t.stats.texels,
            t.stats.points,
            t.stats.points_per_texel,
            t.stats.rays,
            t.stats.seconds,
            t.stats.rays as f64 / t.stats.seconds.max(1e-9) / 1e6,
            100.0 * lit as f64 / (t.stats.texels * s.steps).max(1) as f64
        );
        if let Some(d) = &report.texel_density {
            println!("{}", d.summary());
        }
    }
    // Last, as `bake` and `clean` end: where the time went.
    println!("{}", super::phase_line(&phases));
    Ok(())
}
