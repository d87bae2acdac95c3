//! The LCD panel's final gather (seed 000 §3.1, §4.3; docs/panel.md):
//! the panel is a grid of texels; per texel an eye ray gives the viewing
//! direction, reflected rays are drawn from the panel's BRDF ([`crate::brdf`])
//! and, for the sun disk, toward the sun (multiple importance sampling), and
//! each reflected ray takes its radiance from the PRT-lit interior or, through
//! the windows, from the full-resolution environment.
//!
//! - `layout`: which triangles are the panel, and texels laid over them (UVs, or a planar projection);
//! - `environment`: the light outside the car (map, Preetham sky + sun disk, overcast, SH), turned by the car's yaw;
//! - `interior`: radiance of what a reflected ray meets (PRT at the hit, glass layers, the sun's direct light);
//! - `gather`: the estimator, progressive (`PanelGather::refine`), deterministic at any thread count;
//! - `readability`: luminance, contrast ratio and the statistics of a panel image;
//! - `glare`: the morning time and car heading at which the sun glares most on the panel;
//! - `images`: the EXR of reflected radiance and the PNG of the contrast ratio with its legend.

pub mod environment;
pub mod gather;
pub mod glare;
pub mod images;
pub mod interior;
pub mod layout;
pub mod readability;
#[cfg(test)]
mod tests;

pub use environment::{Environment, Light, Sun, SUN_ANGULAR_RADIUS_DEG};
pub use gather::{GatherOptions, PanelGather, TexelResult};
pub use interior::{Arrival, Interior, SideShares, MAX_GLASS_LAYERS};
pub use layout::{select_panel, Mapping, PanelLayout};
pub use readability::{contrast_ratio, luminance, Display, Readability};

use std::path::PathBuf;

/// Why a panel cannot be gathered. Messages name the file when there is one.
#[derive(Debug, thiserror::Error)]
pub enum PanelError {
    #[error("{}: no material or group matches the panel pattern {pattern:?} (materials: {available})", .path.display())]
    NoPanel { path: PathBuf, pattern: String, available: String },
    #[error("invalid --panel pattern {pattern:?}: {message}")]
    BadPattern { pattern: String, message: String },
    #[error("{}: the panel ({triangles} triangles) has no area", .path.display())]
    NoArea { path: PathBuf, triangles: usize },
    #[error("{}: the panel's triangles face both ways (their normals cancel); clean the mesh or pick one side", .path.display())]
    NoFacing { path: PathBuf },
    #[error("{}: the eye {eye:?} is behind the panel (panel centre {centre:?}, facing {normal:?})", .path.display())]
    EyeBehind { path: PathBuf, eye: [f32; 3], centre: [f32; 3], normal: [f32; 3] },
    #[error("{}: no texel lands on the panel ({width}x{height} texels by {mapping})", .path.display())]
    NoTexels { path: PathBuf, width: u32, height: u32, mapping: &'static str },
    #[error("{}: the bundle has no transfer: bake it first", .path.display())]
    NoTransfer { path: PathBuf },
    #[error("{}: the transfer has {channels} channels (1 or 3 are shaded)", .path.display())]
    BadChannels { path: PathBuf, channels: u32 },
    #[error("texels {width}x{height}: each side must be 1..=4096")]
    BadTexels { width: u32, height: u32 },
    #[error(
        "{}: {non_finite} of {values} reflected radiance values are not finite (the light, {light}, overflows single precision): no readability can be computed",
        .path.display()
    )]
    NonFinite { path: PathBuf, non_finite: usize, values: usize, light: String },
}

/// Refuses a gather whose results overflowed (a light far past any real
/// one): statistics over NaN or infinity would read as "readable".
pub fn check_finite(results: &[Option<TexelResult>], path: &std::path::Path, light: &str) -> Result<(), PanelError> {
    let values: Vec<f32> = results.iter().flatten().flat_map(|t| t.radiance.into_iter().chain([t.luminance_error])).collect();
    let non_finite = values.iter().filter(|v| !v.is_finite()).count();
    if non_finite > 0 {
        return Err(PanelError::NonFinite { path: path.to_path_buf(), non_finite, values: values.len(), light: light.to_string() });
    }
    Ok(())
}
