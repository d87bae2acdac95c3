//! `prtbake view BUNDLE`: relight a bundle in a window, or headlessly into a PNG
//! (`--screenshot`), optionally timing frames (`--frames N`). Reads only the
//! bundle and the env map, never the source mesh. Needs the `viewer` feature.

use std::path::PathBuf;

/// A checked-as-typed `view` configuration (semantic checks happen in [`run`]).
#[derive(Clone, Debug)]
pub struct ViewConfig {
    pub bundle: PathBuf,
    /// Equirect env map (.exr / .hdr) for the SH lighting.
    pub env: Option<PathBuf>,
    /// Use the time lapse's sky SH from the bundle.
    pub sky: bool,
    /// Local `HH:MM` of the step to show.
    pub time: Option<String>,
    /// Step index to show.
    pub step: Option<usize>,
    /// UTC offset `+HH:MM` for `--time` (default: the sky module's, Athens at the equinox).
    pub tz: Option<String>,
    pub exposure: f32,
    /// The car's yaw, pitch, roll under the sky in degrees (the environment turns the other way).
    pub car_rotation_deg: [f32; 3],
    /// `photographic`, `drago` or `linear`.
    pub tonemap: String,
    pub gamma: f32,
    /// `total`, `direct`, `indirect` or bounce list `0,1`.
    pub layers: String,
    /// Globs of materials or groups not to draw (glass included).
    pub hide: Vec<String>,
    pub screenshot: Option<PathBuf>,
    /// `WxH`.
    pub size: String,
    /// `EX,EY,EZ,TX,TY,TZ`.
    pub camera: Option<String>,
    pub fov_deg: f32,
    /// Frames to time in headless mode (0 = one frame, no timing).
    pub frames: u32,
    /// Glob on material or group names for the LCD panel; `None` = panel-role materials (if any).
    pub panel: Option<String>,
    /// Texels of the panel texture; `None` = 128 along the long side, square texels.
    pub panel_texels: Option<(u32, u32)>,
    /// Gather passes before the screenshot (0 = no panel texture); `None` = to 256 samples per texel.
    pub panel_passes: Option<u32>,
    pub json: bool,
}

/// Parses `WxH` (each 1..=16384).
pub fn parse_size(text: &str) -> anyhow::Result<(u32, u32)> {
    let parsed = text.split_once(['x', 'X']).and_then(|(w, h)| Some((w.trim().parse::<u32>().ok()?, h.trim().parse::<u32>().ok()?)));
    match parsed {
        Some((w, h)) if (1..=16384).contains(&w) && (1..=16384).contains(&h) => Ok((w, h)),
        _ => anyhow::bail!("--size {text:?}: expected WIDTHxHEIGHT, each 1..=16384, e.g. 1280x720"),
    }
}

#[cfg(not(feature = "viewer"))]
pub fn run(_config: &ViewConfig) -> anyhow::Result<()> {
    anyhow::bail!("this prtbake was built without the `viewer` feature (rebuild with default features)")
}

#[cfg(feature = "viewer")]
pub fn run(config: &ViewConfig) -> anyhow::Result<()> {
    use anyhow::Context;
    use serde_json::json;

    use crate::view::{self, Camera, LayerSelection, LightingSource, ToneMap, ToneOperator, ViewState};

    let path = &config.bundle;
    if let Some(shot) = &config.screenshot {
        let mut inputs = vec![path.as_path()];
        inputs.extend(config.env.as_deref());
        super::check_outputs(&inputs, &[super::Output::new(shot, &["png", "exr"])], false)?;
        if config.frames > 0 && is_exr(shot) {
            anyhow::bail!("--frames times tone-mapped frames: name the screenshot .png");
        }
    }
    let mut bundle = crate::bundle::read_bundle(path).with_context(|| format!("cannot view {}", path.display()))?;
    if bundle.transfer.is_none() {
        if bundle.sun.is_none() {
            anyhow::bail!("{}: the bundle has neither transfer nor sun masks: nothing to shade", path.display());
        }
        // Sun masks alone: albedo × the sun term, no sky light on the surfaces.
        if !config.json {
            eprintln!(
                "{}: sun masks without transfer: surfaces show the direct sun only (bake transfer for the sky's light)",
                path.display()
            );
        }
        bundle.transfer = Some(crate::bundle::Transfer::zero(bundle.mesh.vertex_count()));
    }
    let transfer = bundle.transfer.as_ref().with_context(|| format!("{}: the bundle has no transfer to shade", path.display()))?;
    let order = transfer.order as usize;
    let layers = LayerSelection::parse(&config.layers, &transfer.stored_bounces()).map_err(anyhow::Error::msg)?;
    // The LCD panel (role panel, or --panel), drawn with its final-gathered texture.
    let panel = match view::panel::PanelMapping::find(&bundle.mesh, config.panel.as_deref(), config.panel_texels, path) {
        Ok(panel) => panel,
        Err(e) if config.panel.is_none() => {
            // A panel-role material the gather cannot lay texels over (no area, facing both ways) does not stop the viewer.
            eprintln!("warning: {e}; the panel is drawn without its gathered reflection");
            None
        }
        Err(e) => anyhow::bail!(e),
    };
    // Glass (window role, or `bake --window PATTERN[=TAU]` kept in META) is drawn as glass.
    let mut scene = view::scene::prepare_scene_with_panel(&bundle, &layers, &config.hide, panel.as_ref())
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let size = parse_size(&config.size)?;

    // The time-lapse step, if any.
    let tz_minutes = match &config.tz {
        Some(text) => crate::sky::time::parse_tz(text)?,
        None => crate::sky::time::default_tz_minutes(),
    };
    let wants_time_lapse = config.sky || config.time.is_some() || config.step.is_some();
    // Steps from a list of directions (`sun --directions`) have no time of day.
    let has_clock = bundle.meta.pointer("/sun/source/kind").and_then(|k| k.as_str()) == Some("spa");
    if bundle.sun.is_some() && !has_clock && config.time.is_some() {
        anyhow::bail!(
            "{}: the time lapse's steps come from a list of sun directions, with no time of day: choose one with --step K",
            path.display()
        );
    }
    let step = match (&bundle.sun, config.step, &config.time) {
        (None, _, _) if wants_time_lapse => {
            anyhow::bail!("{}: the bundle has no time lapse (sun masks), so --sky, --time and --step do not apply", path.display())
        }
        (None, _, _) => None,
        (Some(sun), Some(k), _) if k >= sun.step_count() => {
            anyhow::bail!("--step {k}: the bundle has {} steps (0..{})", sun.step_count(), sun.step_count())
        }
        (Some(_), Some(k), _) => Some(k),
        (Some(sun), None, Some(time)) => {
            let step = view::lighting::step_nearest_time(sun, crate::sky::time::parse_hhmm(time)?, tz_minutes);
            if let Some(k) = step {
                let shown = view::lighting::step_local_time(sun, k, tz_minutes);
                if shown != *time && !config.json {
                    eprintln!("--time {time}: the nearest step of the time lapse is {k}, at {shown}");
                }
            }
            step
        }
        (Some(sun), None, None) => (sun.step_count() > 0).then_some(sun.step_count() / 2),
    };
    let source = match &config.env {
        Some(env) => {
            let (image, sh) = view::lighting::env_map(env, order).with_context(|| format!("cannot use {} as lighting", env.display()))?;
            scene.environment = Some(image);
            LightingSource::EnvMap(sh)
        }
        None if bundle.sun.is_some() => {
            let up = bundle.meta.pointer("/sun/up").and_then(|v| serde_json::from_value::<[f32; 3]>(v.clone()).ok());
            let turbidity = bundle.meta.pointer("/sun/turbidity").and_then(|v| v.as_f64());
            LightingSource::StepSky {
                up: up.map_or(glam::Vec3::Y, glam::Vec3::from),
                turbidity: turbidity.unwrap_or(crate::sky::DEFAULT_TURBIDITY) as f32,
            }
        }
        None => {
            let (sh, backdrop) = view::lighting::default_sky(order);
            LightingSource::Sky { sh, backdrop }
        }
    };
    if matches!(source, LightingSource::StepSky { .. }) && config.car_rotation_deg != [0.0; 3] {
        anyhow::bail!(
            "{}: --yaw/--pitch/--roll turn the car under the sky, but the time lapse's sun masks are baked for the car as it stands (light it with --env MAP to turn it)",
            path.display()
        );
    }
    let Some(operator) = ToneOperator::parse(&config.tonemap) else {
        anyhow::bail!("--tonemap {:?}: expected photographic, drago or linear", config.tonemap)
    };
    if !(config.gamma.is_finite() && config.gamma > 0.0 && config.exposure.is_finite()) {
        anyhow::bail!("--gamma must be positive and --exposure finite");
    }
    let state = ViewState {
        source,
        car_rotation_deg: config.car_rotation_deg,
        step,
        sun_on: step.is_some(),
        tonemap: ToneMap { operator, exposure_stops: config.exposure, gamma: config.gamma, ..ToneMap::default() },
        layers,
    };
    let mut camera = match &config.camera {
        Some(text) => {
            let (eye, target) = Camera::parse_eye_target(text).map_err(anyhow::Error::msg)?;
            Camera::look_at(eye, target, scene.bounds)
        }
        None => Camera::fit(scene.bounds),
    };
    if !(config.fov_deg > 1.0 && config.fov_deg < 179.0) {
        anyhow::bail!("--fov {}: expected 1..179 degrees", config.fov_deg);
    }
    camera.fov_y_deg = config.fov_deg;

    let Some(screenshot) = &config.screenshot else {
        let panel_source = match &panel {
            Some(mapping) => {
                eprintln!("panel: building the ray-tracing scene for the gather");
                Some(view::panel::PanelSource::new(&bundle, mapping, scene.environment.clone()).map_err(anyhow::Error::msg)?)
            }
            None => None,
        };
        return view::window::run_window(bundle, scene, state, camera, tz_minutes, panel_source).map_err(Into::into);
    };
    quiet_headless_vulkan();
    let gpu = view::Gpu::headless()?;
    let settings = state.frame_settings(bundle.sun.as_ref(), order);
    let (width, height) = size;
    let passes = config.panel_passes.unwrap_or_else(|| view::panel::passes_for(view::panel::INTERACTIVE_SAMPLES));
    if panel.is_none() && config.panel_passes.is_some_and(|p| p > 0) && !config.json {
        eprintln!("--panel-passes: the bundle has no panel (no material has the panel role; name it with --panel GLOB)");
    }
    let panel_report = match (&panel, &mut scene.panel) {
        (Some(mapping), Some(draws)) if passes > 0 => {
            let started = std::time::Instant::now();
            let mut source = view::panel::PanelSource::new(&bundle, mapping, scene.environment.clone()).map_err(anyhow::Error::msg)?;
            let request = view::panel::PanelRequest::new(camera.eye, &settings, &state.layers, 0);
            let texture = source.texture(&request, passes);
            let report = json!({
                "texels": [texture.width, texture.height], "texels_on_panel": mapping.layout.covered(), "mapping": mapping.layout.mapping.name(),
                "centre": mapping.layout.centre.to_array(), "front": mapping.layout.front.to_array(),
                "passes": passes, "samples_per_texel": texture.samples, "eye": camera.eye.to_array(), "seconds": started.elapsed().as_secs_f64(),
            });
            if !config.json {
                eprintln!(
                    "panel: {}x{} texels, {passes} passes ({} samples per texel) from the eye {:?} in {:.2} s",
                    texture.width,
                    texture.height,
                    texture.samples,
                    camera.eye.to_array(),
                    started.elapsed().as_secs_f64()
                );
            }
            draws.texture = Some(texture);
            Some(report)
        }
        _ => None,
    };
    let step_time = match (&bundle.sun, step) {
        (Some(sun), Some(k)) if has_clock => Some(view::lighting::step_local_time(sun, k, tz_minutes)),
        _ => None,
    };
    if is_exr(screenshot) {
        // Linear radiance before tone mapping, for comparison with a path tracer.
        let image = view::render_linear(&gpu, &scene, bundle.sun.as_ref(), &camera, &settings, width, height)?;
        let bytes = image.encode_exr().map_err(|e| anyhow::anyhow!("cannot encode {}: {e}", screenshot.display()))?;
        crate::files::write_atomic(screenshot, &bytes).with_context(|| format!("cannot write {}", screenshot.display()))?;
        if config.json {
            return super::print_json(&json!({
                "screenshot": super::json_path(screenshot), "width": width, "height": height, "adapter": gpu.adapter_name(),
                "linear": true, "step": step, "step_local_time": step_time, "camera": camera.to_arg(), "panel": panel_report,
            }));
        }
        println!("wrote {} ({width}x{height}, linear radiance, {})", screenshot.display(), gpu.adapter_name());
        return Ok(());
    }
    let (image, timing) = if config.frames > 0 {
        let (image, timing) = view::time_frames(&gpu, &scene, bundle.sun.as_ref(), &camera, &settings, width, height, config.frames)?;
        (image, Some(timing))
    } else {
        (view::render_image(&gpu, &scene, bundle.sun.as_ref(), &camera, &settings, width, height)?, None)
    };
    image.write_png(screenshot)?;
    if config.json {
        return super::print_json(&json!({
            "screenshot": super::json_path(screenshot), "width": width, "height": height, "adapter": gpu.adapter_name(),
            "step": step, "step_local_time": step_time, "camera": camera.to_arg(), "timing": timing, "panel": panel_report,
        }));
    }
    println!("wrote {} ({width}x{height}, {})", screenshot.display(), gpu.adapter_name());
    if let Some(t) = timing {
        println!(
            "frame time: mean {:.2} ms, min {:.2} ms over {} frames; {} triangles, {} GPU vertices; GPU buffers {} bytes (transfer {}), targets {} bytes",
            t.mean_ms, t.min_ms, t.frames, t.triangles, t.gpu_vertices, t.memory.buffers, t.memory.transfer, t.memory.targets
        );
    }
    Ok(())
}

#[cfg(feature = "viewer")]
fn is_exr(path: &std::path::Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr"))
}

/// Without a session, Mesa's Vulkan loader prints "XDG_RUNTIME_DIR is invalid
/// or not set" (twice) while probing window systems a headless frame never
/// uses. Point it at a private folder first (only when unset; the viewer's own
/// threads are not started yet, so changing the environment is safe here).
#[cfg(all(feature = "viewer", unix))]
fn quiet_headless_vulkan() {
    use std::os::unix::fs::PermissionsExt;
    if std::env::var_os("XDG_RUNTIME_DIR").is_some() {
        return;
    }
    // SAFETY: getuid has no preconditions.
    let dir = std::env::temp_dir().join(format!("prtbake-runtime-{}", unsafe { libc::getuid() }));
    if std::fs::create_dir_all(&dir).is_ok() && std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700)).is_ok() {
        std::env::set_var("XDG_RUNTIME_DIR", &dir);
    }
}

#[cfg(all(feature = "viewer", not(unix)))]
fn quiet_headless_vulkan() {}
