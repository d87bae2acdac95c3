//! The baker: per-vertex SH transfer (and, in `sun`, shadow masks) traced on
//! the CPU. `bake` does no I/O: it receives a mesh and parameters and returns
//! arrays and statistics.

pub mod cull;
pub mod denoise;
pub(crate) mod enclosure;
pub(crate) mod gather;
pub(crate) mod noise;
pub mod progress;
pub(crate) mod receivers;
pub(crate) mod side_share;
pub mod sun;
pub mod surfaces;
pub mod texel_density;
pub(crate) mod texel_lookup;
pub mod texel_sun;
pub mod texels;
pub mod transfer;
pub(crate) mod twins;
mod window_light;

pub use crate::sampling::DirectionPattern;
pub use sun::{bake_sun_masks, LoopOrder, SunMasks, SunParams, SunStats};
pub use surfaces::Surfaces;
pub use texel_sun::{bake_texel_sun_masks, TexelSunMasks, TexelSunPlan, TexelSunRange, TexelSunStats};
pub use transfer::{bake_transfer, bake_transfer_receivers, NothingToBake};

use crate::sh;
use crate::trace::{Batching, BuildQuality, Scene, SceneError};

/// Which light reaches a point.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Under an open sky: rays that escape the scene bring light; one-sided cosine.
    Open,
    /// Inside a cabin: only rays whose first hit is a window bring light; two-sided cosine |n·ω|.
    Window,
}

/// Where rays are shot from.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase", tag = "kind")]
pub enum Sampling {
    /// Stratified points inside each triangle, about `samples_per_vertex` × vertex count
    /// in all, spread by area, in rotation triples (at least one triple, at most
    /// `max_per_triangle` points, per triangle).
    Interior { samples_per_vertex: f32, max_per_triangle: u32 },
    /// The vertices themselves (leaks shadows where triangles overlap; for comparison).
    Vertex,
}

impl Sampling {
    /// The default interior sampling: two samples per vertex on average.
    pub const fn interior() -> Sampling {
        Sampling::Interior { samples_per_vertex: 2.0, max_per_triangle: 256 }
    }
}

/// How many colour channels the transfer keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Channels {
    /// One when every material is grey, three otherwise.
    Auto,
    One,
    Three,
}

/// Parameters of a transfer bake. A bundle's META `params` reads back
/// into them (`sun BUNDLE --refine` re-bakes the transfer it holds); the
/// fields that are not part of the bake take their defaults.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BakeParams {
    /// SH order n: bands l < n, n² coefficients.
    pub order: usize,
    /// Rays per sample point (≤ 65,536, the Sobol limit per seed).
    pub rays: u32,
    /// Seed of every random stream.
    pub seed: u32,
    /// Seed of the sample positions inside triangles, when it should differ
    /// from `seed` (`None`: `seed`). A study can then vary the rays and keep
    /// the points (examples/ray_scaling.rs separates the two error sources).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub point_seed: Option<u32>,
    pub mode: Mode,
    pub sampling: Sampling,
    /// Interreflection bounces after the direct one (0 = shadowed transfer only).
    pub bounces: u32,
    pub channels: Channels,
    /// Keep each bounce's transfer, not only the total.
    pub store_bounces: bool,
    /// Adaptive allocation (interior sampling): bounce 0 adds about this
    /// many times the base layout's points where its own points measure the
    /// most noise (`bake::adaptive`); 0 = off.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub adaptive: f32,
    pub pattern: DirectionPattern,
    /// Window mode: bounce 0 also traces `rays` directions aimed at the glass
    /// (a pane picked by area, a direction uniform over its solid angle) and
    /// combines them with the cosine rays by multiple importance sampling
    /// (`window_light`): unbiased, and never worse than the cosine rays
    /// alone at the same traced rays on the closed-form window scenes
    /// (tests/estimator.rs); far better where the glass is small or far.
    pub window_sampling: bool,
    /// Window mode: keep the light through glass that reaches a sample point
    /// from a side outside the enclosure. Off (the default), a side of a
    /// point from which more of bounce 0's cosine rays escape to the sky
    /// without meeting glass than meet opaque surfaces is outside
    /// (`bake::enclosure`), and its light through glass is dropped: the
    /// outer face of a wall no longer glows from a pane in front of it and
    /// carries the glow into the room through shared vertices. On, for
    /// window scenes with no enclosure (a pane over an open plane), where
    /// every side sees the open sky, and for a car body with gaps, which
    /// make sides inside the cabin look outside.
    pub keep_outside_sides: bool,
    /// A sample is inside geometry when most of its probe rays hit back faces
    /// closer than this fraction of the scene diagonal.
    pub inside_distance: f32,
    /// Open mode with bounces: a diffuse surface reflects on the side light
    /// reaches it from, back faces included (`bake::twins`), unless its
    /// material is one-sided (`--one-sided`). Off, a ray that meets a back
    /// face brings nothing back (bakes recorded before this field existed).
    #[serde(default)]
    pub two_sided: bool,
    /// Bounces ≥ 1 read the previous bounce at a hit from a fit to the hit
    /// triangle's own points (`bake::transfer::fit`) instead of its corner
    /// vertices' one-ring means; off by default (`--gather-fit`).
    #[serde(default, skip_serializing_if = "is_false")]
    pub gather_fit: bool,
    /// Strength of the noise-guided filter run over the baked vertices
    /// (`bake::denoise`; a neighbour differing by k standard errors keeps
    /// e^(−1/2) of its weight); 0 = off.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub denoise: f32,
    /// No progress line on stderr (not part of the bake: never stored).
    #[serde(skip, default = "quiet_by_default")]
    pub quiet: bool,
    /// Largest cache of bounce 0's hits (8 bytes a ray) kept for the later
    /// bounces to gather from; beyond it they re-trace the same rays (about
    /// 3–4× slower on the Ferrari) and gather through the same 16-bit
    /// barycentrics, so the bytes are the same either way (not part of the
    /// bake: never stored).
    #[serde(skip, default = "default_hit_cache_bytes")]
    pub hit_cache_bytes: u64,
}

fn quiet_by_default() -> bool {
    true
}

fn default_hit_cache_bytes() -> u64 {
    transfer::HIT_CACHE_BUDGET_BYTES
}

impl Default for BakeParams {
    fn default() -> Self {
        BakeParams {
            order: 3,
            rays: 256,
            seed: 1,
            point_seed: None,
            mode: Mode::Open,
            sampling: Sampling::interior(),
            bounces: 0,
            channels: Channels::Auto,
            store_bounces: false,
            adaptive: 0.0,
            pattern: DirectionPattern::Sobol,
            window_sampling: false,
            keep_outside_sides: false,
            inside_distance: 0.05,
            two_sided: true,
            gather_fit: false,
            denoise: 0.0,
            quiet: true,
            hit_cache_bytes: transfer::HIT_CACHE_BUDGET_BYTES,
        }
    }
}

impl BakeParams {
    /// Checks ranges; called by [`bake_transfer`].
    pub fn check(&self) -> Result<(), BakeError> {
        if self.order == 0 || self.order > sh::MAX_ORDER {
            return Err(BakeError::Params(format!("order {} is outside 1..={}", self.order, sh::MAX_ORDER)));
        }
        if self.rays == 0 || self.rays > crate::sampling::MAX_RAYS_PER_POINT {
            return Err(BakeError::Params(format!("rays per sample {} is outside 1..={}", self.rays, crate::sampling::MAX_RAYS_PER_POINT)));
        }
        if !(0.0..=16.0).contains(&self.adaptive) {
            return Err(BakeError::Params(format!(
                "adaptive allocation {} is outside 0..=16 (extra points per base point)",
                self.adaptive
            )));
        }
        if self.adaptive > 0.0 && self.sampling == Sampling::Vertex {
            // It adds points inside triangles; vertex sampling has one point per vertex.
            return Err(BakeError::Params("adaptive allocation adds interior samples: it needs --sampling interior".into()));
        }
        if self.gather_fit && self.sampling == Sampling::Vertex {
            return Err(BakeError::Params("--gather-fit fits the points inside each triangle: it needs --sampling interior".into()));
        }
        if !(0.0..=16.0).contains(&self.denoise) {
            return Err(BakeError::Params(format!("denoise strength {} is outside 0..=16 (0 = off)", self.denoise)));
        }
        if self.denoise > 0.0 && self.sampling == Sampling::Vertex {
            return Err(BakeError::Params("--denoise is guided by the noise interior points measure: it needs --sampling interior".into()));
        }
        if self.bounces > 16 {
            return Err(BakeError::Params(format!("{} bounces is more than 16", self.bounces)));
        }
        if let Sampling::Interior { samples_per_vertex, max_per_triangle } = self.sampling {
            if !(samples_per_vertex > 0.0 && samples_per_vertex.is_finite()) || max_per_triangle == 0 {
                return Err(BakeError::Params("interior sampling needs a positive sample density".into()));
            }
        }
        Ok(())
    }

    /// Channels the result will have for these surfaces.
    pub fn channel_count(&self, surfaces: &Surfaces) -> usize {
        match self.channels {
            Channels::One => 1,
            Channels::Three => 3,
            Channels::Auto => {
                if surfaces.all_grey() {
                    1
                } else {
                    3
                }
            }
        }
    }
}

/// Errors of the baker.
#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    #[error("bad bake parameters: {0}")]
    Params(String),
    #[error(transparent)]
    Pattern(#[from] surfaces::PatternError),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    NothingToBake(#[from] NothingToBake),
}

/// What a bake measured.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct BakeStats {
    pub triangles: u64,
    pub vertices: u64,
    pub window_triangles: u64,
    /// Sample points (interior samples or vertices).
    pub points: u64,
    /// Interior samples rejected as lying inside geometry.
    pub points_rejected: u64,
    /// Window mode: of the light through glass that bounce 0's sample points
    /// met (DC summed over points), the share on sides the enclosure rule
    /// found outside and dropped (`BakeParams::keep_outside_sides` keeps
    /// it: the share is then 0). Right for a room's outer walls; on a car
    /// body with gaps it is light the cabin should keep.
    pub outside_light_share: f64,
    /// Of `points`, those adaptive allocation added after bounce 0 (`BakeParams::adaptive`).
    pub points_added: u64,
    /// Vertices no sample reached (only on window or degenerate triangles): their transfer is zero.
    pub vertices_without_samples: u64,
    /// Triangles whose back side reflects light with sample points of its own
    /// (open mode with bounces, `bake::twins`); their points are in `points`.
    pub back_sides: u64,
    /// Rays evaluated per bounce (bounces ≥ 1 reuse bounce 0's hits when they fit in memory).
    pub rays_per_bounce: Vec<u64>,
    pub seconds_per_bounce: Vec<f64>,
    /// Rays evaluated in all bounces.
    pub rays: u64,
    /// Rays actually traced through the BVH (probe rays included).
    pub rays_traced: u64,
    /// Evaluations of bounces ≥ 1 answered from bounce 0's hit records
    /// (gathered, not traced); 0 when the bounces re-traced their rays.
    pub rays_gathered: u64,
    pub seconds: f64,
    /// Traced rays per second: `rays_traced / seconds`, comparable with a
    /// raw ray rate (gathered evaluations are not rays and are not counted).
    pub rays_per_second: f64,
    /// All evaluations per second (`rays / seconds`, gathered ones included).
    pub evaluations_per_second: f64,
    /// How the scene ran its batches of rays (measured when it was built).
    pub batching: Batching,
}

/// [`BakeStats::outside_light_share`] of the DC through glass that bounce
/// 0's points met on sides kept and on sides dropped.
pub fn outside_light_share([kept, dropped]: [f64; 2]) -> f64 {
    if kept + dropped > 0.0 {
        dropped / (kept + dropped)
    } else {
        0.0
    }
}

/// A baked transfer: per vertex `[channel][coeff]`, vertex-major.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferResult {
    pub order: usize,
    pub channels: usize,
    /// Sum of all bounces.
    pub total: Vec<f32>,
    /// Each bounce (0 = direct) when `store_bounces`, else empty.
    pub bounces: Vec<Vec<f32>>,
    /// Per vertex, the standard error of its DC estimate (channel 0): each
    /// bounce's from its points' spread (`bake::noise::Moments`), the
    /// bounces added in quadrature (`noise::add_noise_in_quadrature`);
    /// empty when not measured (vertex sampling). Not stored in bundles.
    pub noise: Vec<f32>,
    /// The back sides' layers (`bake::twins`), bounce by bounce, one row per
    /// vertex (zero where a vertex has no back side of its own), when
    /// `store_bounces` and the bake had back sides: what a partial re-bake
    /// keeps (`crate::refine`). Not stored in bundles.
    pub back: Vec<Vec<f32>>,
    /// Window mode with interior sampling: per vertex, the share of its
    /// light that reached it through the front of its face
    /// (`bake::side_share`); empty otherwise (open mode: all of it).
    pub front_share: Vec<f32>,
    pub stats: BakeStats,
}

impl TransferResult {
    /// Coefficients of vertex `v`, channel `c`.
    pub fn coefficients(&self, v: usize, c: usize) -> &[f32] {
        let n = sh::coeff_count(self.order);
        &self.total[(v * self.channels + c) * n..][..n]
    }
}

/// Peak resident memory of this process in bytes (Linux `VmHWM`), if known.
pub fn peak_memory_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// What the baker needs of a mesh: finite coordinates (NaN or infinity would
/// poison the BVH build; loaders refuse them too, but meshes built in code
/// reach here directly), indices in range, one normal per vertex, one material
/// in range per triangle. UVs and colours are not read.
pub fn check_mesh(mesh: &crate::mesh::Mesh) -> Result<(), BakeError> {
    let bad = |m: String| Err(BakeError::Params(format!("invalid mesh: {m}")));
    if let Some(v) = mesh.positions.iter().position(|p| !p.is_finite()) {
        return bad(format!("vertex {v} has a non-finite coordinate {}", mesh.positions[v]));
    }
    if mesh.indices.len() % 3 != 0 || mesh.normals.len() != mesh.positions.len() {
        return bad(format!("{} indices, {} normals for {} vertices", mesh.indices.len(), mesh.normals.len(), mesh.positions.len()));
    }
    if let Some(i) = mesh.indices.iter().position(|&i| i as usize >= mesh.positions.len()) {
        return bad(format!("index {i} is {} but there are {} vertices", mesh.indices[i], mesh.positions.len()));
    }
    let triangles = mesh.triangle_count();
    // Hit records name a triangle in 30 bits (and twins double the count in open mode).
    if triangles as u64 >= gather::MAX_RECORD_TRIANGLES / 2 {
        return bad(format!("{triangles} triangles: a bake takes fewer than {}", gather::MAX_RECORD_TRIANGLES / 2));
    }
    if mesh.tri_material.len() != triangles || mesh.tri_material.iter().any(|&m| m as usize >= mesh.materials.len()) {
        return bad("a triangle has no material or one out of range".into());
    }
    if mesh.tri_group.len() != triangles || mesh.tri_group.iter().any(|&g| g as usize >= mesh.groups.len()) {
        return bad("a triangle has no group or one out of range".into());
    }
    Ok(())
}

/// Builds the scene and surfaces for `mesh` and bakes its transfer: the one
/// path `prtbake bake`, `verify` and the tests share.
pub fn bake_mesh(
    mesh: &crate::mesh::Mesh,
    params: &BakeParams,
    window_patterns: &[String],
) -> Result<(TransferResult, Surfaces, f64), BakeError> {
    bake_mesh_with(mesh, params, window_patterns, &[])
}

/// [`bake_mesh`] with the materials or groups matching `one_sided_patterns`
/// one-sided (their back reflects nothing in bounces; `Surfaces::with_one_sided`).
pub fn bake_mesh_with(
    mesh: &crate::mesh::Mesh,
    params: &BakeParams,
    window_patterns: &[String],
    one_sided_patterns: &[String],
) -> Result<(TransferResult, Surfaces, f64), BakeError> {
    params.check()?;
    check_mesh(mesh)?;
    let surfaces = Surfaces::resolve(mesh, window_patterns)?.with_one_sided(mesh, one_sided_patterns)?;
    let scene = Scene::build(mesh, BuildQuality::Sah)?;
    let build_seconds = scene.build_time.as_secs_f64();
    let result = bake_transfer(mesh, &scene, &surfaces, params)?;
    Ok((result, surfaces, build_seconds))
}

fn is_false(x: &bool) -> bool {
    !*x
}

fn is_zero(x: &f32) -> bool {
    *x == 0.0
}
