//! The interactive viewer: a winit window, a wgpu surface, keys and mouse.
//!
//! Keys (also printed by `H`, documented in docs/viewer.md): mouse left drag
//! orbit, right drag look around, wheel dolly; `W A S D` fly, `Q E` down/up;
//! `Space` play/pause the time lapse; `← →` (or `, .`) step; `+ −` exposure ±½
//! stop; `[ ]` turn the car ∓15° under the sky, `R` auto-turn; `T` all light, `B`
//! (or `0`) direct, `I` indirect, `0–9` bounce N; `U` sun term; `P` the panel's gathered texture; `M` tone
//! operator; `C` print the camera as `--camera`; `H` help; `Esc` quit.

use std::collections::HashSet;
use std::sync::Arc;
use std::time::Instant;

use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{Key, KeyCode, NamedKey, PhysicalKey};
use winit::window::{Window, WindowId};

use super::camera::{Camera, CameraControl};
use super::gpu::{Gpu, Renderer};
use super::layers::LayerSelection;
use super::panel::{PanelRequest, PanelSource};
use super::panel_worker::PanelWorker;
use super::scene::PreparedScene;
use super::{lighting, LightingSource, ViewError, ViewState};
use crate::bundle::Bundle;

/// Seconds per time-lapse step when playing (92 steps ≈ 30 s, as in seed 001 §6).
const STEP_SECONDS: f32 = 0.33;
/// Car auto-turn speed under the sky, degrees per second.
const TURN_DEG_PER_S: f32 = 20.0;

/// The key help printed by `H` and at start.
pub const HELP: &str = "\
mouse: left drag orbit, right drag look, wheel dolly | W A S D fly, Q E down/up
Space play/pause time lapse | <- -> (or , .) step | + - exposure 1/2 stop
[ ] turn the car under the sky, R auto-turn | T all light, B (or 0) direct, I indirect, 0-9 bounce N
U sun term | P panel texture | M tone operator (photographic/Drago/linear) | C print camera | H help | Esc quit";

struct Surface {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    gpu: Gpu,
    renderer: Renderer,
}

struct App {
    bundle: Bundle,
    scene: PreparedScene,
    state: ViewState,
    control: CameraControl,
    tz_minutes: i32,
    surface: Option<Surface>,
    error: Option<ViewError>,
    last_frame: Instant,
    step_clock: f32,
    playing: bool,
    auto_turn: bool,
    keys: HashSet<KeyCode>,
    drag: Option<MouseButton>,
    cursor: Option<(f64, f64)>,
    frame_times: Vec<f32>,
    first_frame: bool,
    panel: Option<PanelState>,
}

/// The panel's progressive gather as the window sees it.
struct PanelState {
    worker: PanelWorker,
    /// The texture is drawn (`P` toggles).
    on: bool,
    /// The last request sent (`None` after a toggle: send one), the samples per
    /// texel of the texture shown, and the requests sent so far (never reused, so a
    /// late texture of an older request is never shown).
    sent: Option<PanelRequest>,
    samples: u32,
    generation: u64,
}

/// Opens a window on `bundle` and runs until it is closed.
/// With `panel`, the LCD panel shows its final gather, refined on worker threads.
pub fn run_window(
    bundle: Bundle,
    scene: PreparedScene,
    state: ViewState,
    camera: Camera,
    tz_minutes: i32,
    panel: Option<PanelSource>,
) -> Result<(), ViewError> {
    let event_loop = EventLoop::new().map_err(|e| {
        ViewError::Window(format!("cannot open the window system: {e} (without a display, render headlessly with --screenshot OUT.png)"))
    })?;
    let bounds = scene.bounds;
    let playing = state.step.is_some() && bundle.sun.is_some();
    let panel = match panel {
        Some(source) => Some(PanelState {
            worker: PanelWorker::start(source, 0).map_err(ViewError::Invalid)?,
            on: true,
            sent: None,
            samples: 0,
            generation: 0,
        }),
        None => None,
    };
    let mut app = App {
        bundle,
        scene,
        state,
        control: CameraControl::new(camera, bounds),
        tz_minutes,
        surface: None,
        error: None,
        last_frame: Instant::now(),
        step_clock: 0.0,
        playing,
        auto_turn: false,
        keys: HashSet::new(),
        drag: None,
        cursor: None,
        frame_times: Vec::new(),
        first_frame: true,
        panel,
    };
    eprintln!("{HELP}");
    event_loop.run_app(&mut app).map_err(|e| ViewError::Window(e.to_string()))?;
    app.error.map_or(Ok(()), Err)
}

impl App {
    fn open(&mut self, event_loop: &ActiveEventLoop) -> Result<Surface, ViewError> {
        let attributes =
            Window::default_attributes().with_title("prtbake view").with_inner_size(winit::dpi::LogicalSize::new(1280.0, 720.0));
        let window = Arc::new(event_loop.create_window(attributes).map_err(|e| ViewError::Window(e.to_string()))?);
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle());
        let surface = instance.create_surface(window.clone()).map_err(|e| ViewError::Window(e.to_string()))?;
        let options = wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: Some(&surface),
            ..Default::default()
        };
        let adapter = pollster::block_on(instance.request_adapter(&options)).map_err(|_| ViewError::NoAdapter)?;
        let gpu = Gpu::with_adapter(instance, adapter)?;
        eprintln!("adapter: {}", gpu.adapter_name());
        let size = window.inner_size();
        let mut config = surface
            .get_default_config(&gpu.adapter, size.width.max(1), size.height.max(1))
            .ok_or_else(|| ViewError::Window("the surface does not work with this adapter".into()))?;
        // Prefer a non-sRGB format: the tone-mapping shader applies the display gamma itself.
        let capabilities = surface.get_capabilities(&gpu.adapter);
        if let Some(&format) = capabilities.formats.iter().find(|f| !f.is_srgb()) {
            config.format = format;
        }
        surface.configure(&gpu.device, &config);
        let renderer = Renderer::new(&gpu, &self.scene, config.format, config.width, config.height)?;
        Ok(Surface { window, surface, config, gpu, renderer })
    }

    fn stored_bounces(&self) -> Vec<u32> {
        self.bundle.transfer.as_ref().map(|t| t.stored_bounces()).unwrap_or_default()
    }

    /// Applies a new layer selection: sums the layers on the CPU and uploads them.
    fn set_layers(&mut self, layers: LayerSelection) {
        let stored = self.stored_bounces();
        let layers = match layers {
            LayerSelection::Bounces(mut list) => {
                list.sort_unstable();
                list.dedup();
                if list == stored {
                    LayerSelection::Total
                } else {
                    LayerSelection::Bounces(list)
                }
            }
            total => total,
        };
        if let (Some(transfer), Some(s)) = (&self.bundle.transfer, &self.surface) {
            if let Err(e) = s.renderer.set_transfer(&s.gpu, &layers.combine(transfer)) {
                eprintln!("error: {e}");
                return;
            }
        }
        eprintln!("layers: {}", layers.describe());
        self.state.layers = layers;
    }

    fn toggle_bounces(&mut self, which: &[u32]) {
        let stored = self.stored_bounces();
        if stored.is_empty() {
            eprintln!("the bundle stores no separate bounces (bake with --store-bounces); only the total is available");
            return;
        }
        let mut current = match &self.state.layers {
            LayerSelection::Total => stored.clone(),
            LayerSelection::Bounces(list) => list.clone(),
        };
        let which: Vec<u32> = which.iter().copied().filter(|b| stored.contains(b)).collect();
        if which.is_empty() {
            eprintln!("bounce not stored (stored: {stored:?})");
            return;
        }
        if which.iter().any(|b| current.contains(b)) {
            current.retain(|b| !which.contains(b));
        } else {
            current.extend(&which);
        }
        self.set_layers(LayerSelection::Bounces(current));
    }

    fn step_by(&mut self, delta: i64) {
        let Some(count) = self.bundle.sun.as_ref().map(|s| s.step_count() as i64).filter(|&n| n > 0) else {
            eprintln!("the bundle has no time lapse");
            return;
        };
        let current = self.state.step.unwrap_or(0) as i64;
        self.state.step = Some((current + delta).rem_euclid(count) as usize);
    }

    /// The car can turn under an env map or the default sky, not under a time
    /// lapse (its sun masks are baked for the car as it stands).
    fn can_turn(&self) -> bool {
        !matches!(self.state.source, LightingSource::StepSky { .. })
    }

    /// Turns the car by `degrees` about +Y (counter-clockwise from above).
    fn turn(&mut self, degrees: f32) {
        if self.can_turn() {
            self.state.car_rotation_deg[0] = (self.state.car_rotation_deg[0] + degrees) % 360.0;
        } else {
            eprintln!("the time lapse's sun masks are baked for the car as it stands: it cannot turn (view with --env to turn it)");
        }
    }

    fn on_key(&mut self, event_loop: &ActiveEventLoop, key: &Key) {
        match key.as_ref() {
            Key::Named(NamedKey::Escape) => event_loop.exit(),
            Key::Named(NamedKey::Space) if self.bundle.sun.is_some() => {
                self.playing = !self.playing;
                if self.state.step.is_none() {
                    self.state.step = Some(0);
                }
            }
            Key::Named(NamedKey::ArrowRight) | Key::Character(".") => {
                self.playing = false;
                self.step_by(1);
            }
            Key::Named(NamedKey::ArrowLeft) | Key::Character(",") => {
                self.playing = false;
                self.step_by(-1);
            }
            Key::Character("+") | Key::Character("=") => self.state.tonemap.exposure_stops += 0.5,
            Key::Character("-") | Key::Character("_") => self.state.tonemap.exposure_stops -= 0.5,
            Key::Character("[") => self.turn(-15.0),
            Key::Character("]") => self.turn(15.0),
            Key::Character(c) => match c.to_ascii_lowercase().as_str() {
                "r" if self.can_turn() => self.auto_turn = !self.auto_turn,
                "r" => self.turn(0.0),
                "t" => self.set_layers(LayerSelection::Total),
                "b" => self.toggle_bounces(&[0]),
                "i" => {
                    let indirect: Vec<u32> = self.stored_bounces().into_iter().filter(|&b| b > 0).collect();
                    self.toggle_bounces(&indirect);
                }
                "u" => self.state.sun_on = !self.state.sun_on,
                "p" => self.toggle_panel(),
                "m" => {
                    self.state.tonemap.operator = self.state.tonemap.operator.next();
                    eprintln!("tone operator: {:?}", self.state.tonemap.operator);
                    self.first_frame = true;
                }
                "c" => println!("--camera {}", self.control.camera.to_arg()),
                "h" => eprintln!("{HELP}"),
                digit if digit.len() == 1 && digit.as_bytes()[0].is_ascii_digit() => {
                    self.toggle_bounces(&[(digit.as_bytes()[0] - b'0') as u32]);
                }
                _ => {}
            },
            _ => {}
        }
    }

    fn toggle_panel(&mut self) {
        let Some(panel) = &mut self.panel else {
            eprintln!("no panel (no material has the panel role; name it with --panel PATTERN)");
            return;
        };
        panel.on = !panel.on;
        panel.sent = None;
        if let (false, Some(s)) = (panel.on, &mut self.surface) {
            s.renderer.set_panel_texture(&s.gpu, None);
        }
        eprintln!("panel texture: {}", if panel.on { "on" } else { "off" });
    }

    /// Restarts the gather when the eye or the light changed; shows the newest texture.
    fn update_panel(&mut self, settings: &super::FrameSettings) {
        let (Some(panel), Some(s)) = (&mut self.panel, &mut self.surface) else { return };
        if !panel.on {
            return;
        }
        let request = PanelRequest::new(self.control.camera.eye, settings, &self.state.layers, panel.generation + 1);
        if panel.sent.as_ref().is_none_or(|sent| !sent.same_gather(&request)) {
            panel.generation = request.generation;
            panel.worker.request(request.clone());
            panel.sent = Some(request);
        }
        if let Some(texture) = panel.worker.latest(panel.generation) {
            panel.samples = texture.samples;
            s.renderer.set_panel_texture(&s.gpu, Some(&texture));
        }
    }

    fn status(&self) -> String {
        let step = match (&self.bundle.sun, self.state.step) {
            (Some(sun), Some(k)) => format!(
                " | step {k}/{} {}{}{}",
                sun.step_count(),
                lighting::step_local_time(sun, k, self.tz_minutes),
                if self.playing { " playing" } else { "" },
                if self.state.sun_on { "" } else { " sun off" }
            ),
            _ => String::new(),
        };
        let ms = if self.frame_times.is_empty() { 0.0 } else { self.frame_times.iter().sum::<f32>() / self.frame_times.len() as f32 * 1e3 };
        let panel = match &self.panel {
            Some(p) if p.on => format!(" | panel {} spp", p.samples),
            _ => String::new(),
        };
        format!(
            "prtbake view | {:?} {:+.1} EV | {} | car yaw {:.0}°{step}{panel} | {ms:.1} ms",
            self.state.tonemap.operator,
            self.state.tonemap.exposure_stops,
            self.state.layers.describe(),
            self.state.car_rotation_deg[0]
        )
    }

    fn redraw(&mut self) {
        let now = Instant::now();
        let dt = (now - self.last_frame).as_secs_f32().min(0.25);
        self.last_frame = now;
        self.frame_times.push(dt);
        if self.frame_times.len() > 30 {
            self.frame_times.remove(0);
        }
        // Advance the time lapse, the environment and the fly camera.
        if self.playing {
            self.step_clock += dt;
            while self.step_clock >= STEP_SECONDS {
                self.step_clock -= STEP_SECONDS;
                self.step_by(1);
            }
        }
        if self.auto_turn {
            self.turn(TURN_DEG_PER_S * dt);
        }
        let axis = |plus: KeyCode, minus: KeyCode| self.keys.contains(&plus) as i32 as f32 - self.keys.contains(&minus) as i32 as f32;
        let (forward, right, up) =
            (axis(KeyCode::KeyW, KeyCode::KeyS), axis(KeyCode::KeyD, KeyCode::KeyA), axis(KeyCode::KeyE, KeyCode::KeyQ));
        if forward != 0.0 || right != 0.0 || up != 0.0 {
            self.control.fly(forward, right, up, dt);
        }
        let order = self.scene.order as usize;
        let settings = self.state.frame_settings(self.bundle.sun.as_ref(), order);
        self.update_panel(&settings);
        let title = self.status();
        let reset = std::mem::replace(&mut self.first_frame, false);
        let Some(s) = &mut self.surface else { return };
        let frame = match s.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                s.surface.configure(&s.gpu.device, &s.config);
                s.window.request_redraw();
                return;
            }
            _ => {
                s.window.request_redraw();
                return;
            }
        };
        let view = frame.texture.create_view(&Default::default());
        s.renderer.render(&s.gpu, &view, &self.control.camera, &settings, self.bundle.sun.as_ref(), dt, reset);
        s.gpu.queue.present(frame);
        s.window.set_title(&title);
        s.window.request_redraw();
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.surface.is_some() {
            return;
        }
        match self.open(event_loop) {
            Ok(s) => {
                s.window.request_redraw();
                self.surface = Some(s);
            }
            Err(e) => {
                self.error = Some(e);
                event_loop.exit();
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                if let Some(s) = &mut self.surface {
                    s.config.width = size.width.max(1);
                    s.config.height = size.height.max(1);
                    s.surface.configure(&s.gpu.device, &s.config);
                    s.renderer.resize(&s.gpu, s.config.width, s.config.height);
                }
            }
            WindowEvent::KeyboardInput { event, .. } => {
                let code = match event.physical_key {
                    PhysicalKey::Code(code) => Some(code),
                    PhysicalKey::Unidentified(_) => None,
                };
                match event.state {
                    ElementState::Pressed => {
                        if let Some(code) = code {
                            self.keys.insert(code);
                        }
                        if !event.repeat || matches!(event.logical_key.as_ref(), Key::Character("[" | "]" | "+" | "=" | "-")) {
                            self.on_key(event_loop, &event.logical_key);
                        }
                    }
                    ElementState::Released => {
                        if let Some(code) = code {
                            self.keys.remove(&code);
                        }
                    }
                }
            }
            WindowEvent::MouseInput { state, button, .. } => {
                self.drag = (state == ElementState::Pressed).then_some(button);
            }
            WindowEvent::CursorMoved { position, .. } => {
                if let (Some((x, y)), Some(button)) = (self.cursor, self.drag) {
                    let (dx, dy) = ((position.x - x) as f32 * 0.005, (position.y - y) as f32 * 0.005);
                    match button {
                        MouseButton::Left => self.control.orbit(-dx, dy),
                        MouseButton::Right => self.control.look(-dx, dy),
                        _ => {}
                    }
                }
                self.cursor = Some((position.x, position.y));
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let lines = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                };
                self.control.dolly(lines * 0.1);
            }
            WindowEvent::RedrawRequested => self.redraw(),
            _ => {}
        }
    }
}
