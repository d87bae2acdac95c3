//! prtbake: precomputed radiance transfer, baked offline.
//!
//! Pipeline: [`mesh`] loads → [`clean`] repairs → [`bake`] traces transfer
//! and sun masks → [`bundle`] stores → `view` relights. [`verify`] checks
//! bakes against closed forms; [`cli`] is the command-line glue. See
//! ARCHITECTURE.md.

pub mod atlas;
pub mod bake;
pub mod brdf;
pub mod bundle;
pub mod chart;
pub mod clean;
pub mod cli;
pub mod colour;
pub(crate) mod disjoint;
pub mod files;
pub mod fixtures;
pub mod mesh;
pub mod panel;
pub mod refine;
pub mod sampling;
pub mod sh;
pub mod shards;
pub mod sky;
pub mod trace;
pub mod verify;
#[cfg(feature = "viewer")]
pub mod view;
