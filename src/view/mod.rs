//! The viewer: relights a bundle on the GPU (wgpu) at the cost of one dot
//! product per vertex, in a window (winit) or headlessly into a PNG.
//!
//! Shading, per vertex as in seeds 000 (§4.2) and 001 (§4):
//!
//! ```text
//! E(v)        = Σ_i L_i · t_i(v)                           (SH lighting · transfer)
//!             + bit(v, k) · max(n·s, 0) · sun_rgb / π       (time-lapse step k only)
//! radiance(x) = albedo(x) · E                               (fragment, per triangle's material)
//! ```
//!
//! then exposure `2^stops` and a tone operator: the photographic one (key from
//! the absolute adaptation luminance, filmic curve; the default), Drago's
//! adaptive logarithmic mapping (seed 000 §5), both driven by a low-resolution
//! log-average luminance with temporal adaptation, or gamma alone (seed 001). Transfer is per unit albedo
//! (docs/conventions.md), the sun irradiance is in the sky module's units, so
//! `albedo/π · E` is radiance in the same units as the sky's. The sun's cosine
//! is taken on the side of the surface the eye sees (the normal turned toward
//! the eye): a single-layer wall lit on its outer face is dark from inside.
//!
//! Per frame only the lighting's SH vector (and the step) changes: the env map
//! is projected once and rotated with [`crate::sh::ShRotation`]; a time-lapse
//! step brings its own sky SH. The viewer reads only the bundle and the map.
//!
//! Behind the geometry the backdrop pass draws the env map itself (full
//! resolution) or the Preetham sky, turned like the lighting; window glass
//! lets τ of it through ([`backdrop`]).
//!
//! - [`scene`]: bundle → GPU-ready arrays (vertices split by material, layer sums).
//! - [`lighting`]: env map / sky / step → SH vectors; the car's turn.
//! - [`backdrop`]: env map / sky behind the geometry, and its CPU reference.
//! - [`camera`]: look-at camera, orbit and fly controls.
//! - [`tonemap`]: tone-mapping parameters and their CPU reference.
//! - [`reference`]: the shading formula on the CPU (tests compare the GPU with it).
//! - `gpu`: device, buffers, pipelines, one frame's passes (shading.wgsl, panel.wgsl, backdrop.wgsl, luminance.wgsl, tonemap.wgsl).
//! - [`panel`]: the LCD panel's final-gathered texture (texel coordinates, texture, the gather's passes).
//! - [`panel_worker`]: that gather on a worker thread for the window (restarts when the eye or the light changes).
//! - [`headless`]: offscreen frame → RGBA8 → PNG, frame timing.
//! - [`window`]: the interactive winit app.

pub mod backdrop;
pub mod camera;
mod gpu;
pub mod headless;
pub mod layers;
pub mod lighting;
pub mod panel;
pub mod panel_worker;
pub mod reference;
pub mod scene;
pub mod tonemap;
pub mod window;

pub use backdrop::{Backdrop, SkyBackdrop};
pub use camera::Camera;
pub use gpu::{Gpu, GpuMemory, Renderer};
pub use headless::{render_image, render_linear, time_frames, FrameTiming, Image, LinearImage};
pub use layers::LayerSelection;
pub use scene::PreparedScene;
pub use tonemap::{ToneMap, ToneOperator};

use std::path::PathBuf;

/// Errors of the viewer.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// No GPU adapter at all (not even a software one). Tests skip on this.
    #[error("no GPU adapter found (for a software one install Mesa's Vulkan driver, e.g. apt-get install mesa-vulkan-drivers)")]
    NoAdapter,
    #[error("cannot open the GPU device: {0}")]
    Device(String),
    #[error("GPU error: {0}")]
    Gpu(String),
    #[error("{0}")]
    Invalid(String),
    #[error("cannot write {path}: {message}")]
    Write { path: PathBuf, message: String },
    #[error(transparent)]
    EnvMap(#[from] crate::sh::EnvMapError),
    #[error("window: {0}")]
    Window(String),
}

/// Everything a frame needs besides the camera and the geometry.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameSettings {
    /// Lighting radiance SH, RGB per coefficient `L_i = ∫ L(ω) y_i(ω) dω`, index
    /// `l(l+1)+m`, any order: truncated or zero-padded to the transfer's order.
    pub lighting: Vec<[f32; 3]>,
    /// Time-lapse step whose sun term is added; `None` = no sun. Ignored when the
    /// bundle has no sun series or the step is out of range.
    pub sun_step: Option<usize>,
    /// What is drawn behind the geometry and seen through the glass.
    pub backdrop: Backdrop,
    pub tonemap: ToneMap,
}

/// Where the lighting (and the backdrop) comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum LightingSource {
    /// An env map projected once; the map itself ([`PreparedScene::environment`])
    /// is the backdrop. Turned with the car ([`ViewState::car_rotation_deg`]).
    EnvMap(Vec<[f32; 3]>),
    /// The default Preetham sky: its SH (no sun term) and its backdrop. Turned with the car.
    Sky { sh: Vec<[f32; 3]>, backdrop: SkyBackdrop },
    /// A fixed SH vector with a black backdrop (synthetic lighting). Turned with the car.
    Sh(Vec<[f32; 3]>),
    /// The current time-lapse step's sky SH from the bundle, and its Preetham
    /// sky and sun disc as the backdrop (`up`, `turbidity`: META `sun`). Not
    /// turned: the sun masks are baked for the car as it stands.
    StepSky { up: glam::Vec3, turbidity: f32 },
}

/// The interactive state that a frame's settings derive from.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewState {
    pub source: LightingSource,
    /// The car's yaw, pitch, roll under the sky, degrees ([`lighting::car_to_env_rotation`]):
    /// turning the car by R is the environment turning by Rᵀ.
    pub car_rotation_deg: [f32; 3],
    /// Current time-lapse step (`None`: no sun term).
    pub step: Option<usize>,
    /// Sun term on (when a step is selected).
    pub sun_on: bool,
    pub tonemap: ToneMap,
    pub layers: LayerSelection,
}

impl ViewState {
    /// This state's frame settings for a transfer of `order`.
    pub fn frame_settings(&self, sun: Option<&crate::bundle::SunSeries>, order: usize) -> FrameSettings {
        let [yaw, pitch, roll] = self.car_rotation_deg;
        let rotation = lighting::car_to_env_rotation(yaw, pitch, roll);
        let sun_step = if self.sun_on { self.step } else { None };
        let (lighting, backdrop) = match (&self.source, sun) {
            (LightingSource::StepSky { up, turbidity }, Some(series)) => {
                let k = self.step.unwrap_or(0);
                let backdrop = series.steps.get(k).map_or(Backdrop::Black, |s| {
                    Backdrop::Sky(SkyBackdrop {
                        sun: glam::Vec3::from(s.direction),
                        up: *up,
                        turbidity: *turbidity,
                        scale: 1.0,
                        // The disc is drawn when the sun term lights the scene.
                        sun_irradiance: sun_step.map(|_| s.sun_rgb),
                        rotation: glam::Mat3::IDENTITY,
                    })
                });
                (lighting::step_sky_sh(series, k, order), backdrop)
            }
            (LightingSource::StepSky { .. }, None) => (vec![[0.0; 3]; crate::sh::coeff_count(order)], Backdrop::Black),
            (LightingSource::EnvMap(base), _) => (lighting::rotate_sh(base, order, rotation), Backdrop::EnvMap { rotation }),
            (LightingSource::Sky { sh, backdrop }, _) => {
                (lighting::rotate_sh(sh, order, rotation), Backdrop::Sky(SkyBackdrop { rotation, ..*backdrop }))
            }
            (LightingSource::Sh(base), _) => (lighting::rotate_sh(base, order, rotation), Backdrop::Black),
        };
        FrameSettings { lighting, sun_step, backdrop, tonemap: self.tonemap }
    }
}
