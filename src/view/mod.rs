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
//! then exposure `2^stops` and either gamma (seed 001) or Drago's adaptive
//! logarithmic mapping driven by a low-resolution log-average luminance with
//! temporal adaptation (seed 000 §5). Transfer is per unit albedo
//! (docs/conventions.md), the sun irradiance is in the sky module's units, so
//! `albedo/π · E` is radiance in the same units as the sky's. In window-mode
//! bundles the sun cosine is two-sided, `|n·s|`, like the bake's.
//!
//! Per frame only the lighting's SH vector (and the step) changes: the env map
//! is projected once and rotated with [`crate::sh::ShRotation`]; a time-lapse
//! step brings its own sky SH. The viewer reads only the bundle and the map.
//!
//! - [`scene`]: bundle → GPU-ready arrays (vertices split by material, layer sums).
//! - [`lighting`]: env map / sky / step → SH vectors.
//! - [`camera`]: look-at camera, orbit and fly controls.
//! - [`tonemap`]: tone-mapping parameters and their CPU reference.
//! - [`reference`]: the shading formula on the CPU (tests compare the GPU with it).
//! - `gpu`: device, buffers, pipelines, one frame's passes (shading.wgsl, tonemap.wgsl).
//! - [`headless`]: offscreen frame → RGBA8 → PNG, frame timing.
//! - [`window`]: the interactive winit app.

pub mod camera;
mod gpu;
pub mod headless;
pub mod lighting;
pub mod reference;
pub mod scene;
pub mod tonemap;
pub mod window;

pub use camera::Camera;
pub use gpu::{Gpu, GpuMemory, Renderer};
pub use headless::{render_image, time_frames, FrameTiming, Image};
pub use scene::{LayerSelection, PreparedScene};
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
    pub tonemap: ToneMap,
}

/// Where the SH lighting comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum LightingSource {
    /// A fixed SH vector (an env map projected once, or the default sky), rotated by
    /// [`ViewState::rotation_deg`] every frame.
    Sh(Vec<[f32; 3]>),
    /// The current time-lapse step's sky SH from the bundle (not rotated: the
    /// sun masks are baked for the sky as it is).
    StepSky,
}

/// The interactive state that a frame's settings derive from.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewState {
    pub source: LightingSource,
    /// Environment yaw, pitch, roll in degrees ([`lighting::env_rotation`]).
    pub rotation_deg: [f32; 3],
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
        let lighting = match (&self.source, sun) {
            (LightingSource::StepSky, Some(series)) => lighting::step_sky_sh(series, self.step.unwrap_or(0), order),
            (LightingSource::StepSky, None) => vec![[0.0; 3]; crate::sh::coeff_count(order)],
            (LightingSource::Sh(base), _) => {
                let [yaw, pitch, roll] = self.rotation_deg;
                lighting::rotate_sh(base, order, lighting::env_rotation(yaw, pitch, roll))
            }
        };
        FrameSettings { lighting, sun_step: if self.sun_on { self.step } else { None }, tonemap: self.tonemap }
    }
}
