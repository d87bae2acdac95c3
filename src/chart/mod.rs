//! Speed against accuracy: sweeps the bake's settings (rays per sample,
//! direction pattern, sampling, SH order, bounces) on scenes whose right
//! answer is known and records, per bake, seconds and error.
//!
//! **Error** is the one `--max-error` budgets (see [`crate::bundle::budget`]): the
//! worst relative RMS of shaded radiance per unit albedo over 12 clear skies,
//! against the exact transfer (analytic scenes) or a high-sample reference
//! bake (the covered floor's leak-free twin, the demo cabin). Truncated SH
//! orders count what they drop. Seconds are the wall time of the bake (BVH
//! build included) on the current thread pool.
//!
//! - `scenes`: the scenes, their references and how a bake is scored;
//! - `real`: `--real`, the Ferrari, the room and the cabin against their
//!   own converged references (total error, not ray noise alone);
//! - `pareto`: the Pareto front and equal-time comparisons;
//! - `plot`: the SVG (plotters).

pub mod pareto;
pub mod plot;
pub mod real;
pub mod scenes;

use crate::bake::{DirectionPattern, Sampling};

/// One bake of the sweep.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Row {
    pub scene: String,
    /// The curve this point belongs to (every setting but the ray count).
    pub setting: String,
    pub pattern: String,
    pub sampling: String,
    pub order: usize,
    pub bounces: u32,
    pub rays: u32,
    pub seconds: f64,
    pub error: f64,
    /// On the scene's Pareto front (no other point is both faster and more accurate).
    pub pareto: bool,
}

/// Names used in settings and the CSV.
pub fn pattern_name(p: DirectionPattern) -> &'static str {
    match p {
        DirectionPattern::Sobol => "sobol",
        DirectionPattern::Random => "random",
    }
}

pub fn sampling_name(s: Sampling) -> &'static str {
    match s {
        Sampling::Interior { .. } => "interior",
        Sampling::Vertex => "vertex",
    }
}

/// The CSV header, in column order.
pub const CSV_HEADER: &str = "scene,setting,pattern,sampling,order,bounces,rays,seconds,error,pareto";

/// The rows as CSV (header first).
pub fn to_csv(rows: &[Row]) -> String {
    let mut s = String::from(CSV_HEADER);
    s.push('\n');
    for r in rows {
        s += &format!(
            "{},{},{},{},{},{},{},{:.6},{:.6e},{}\n",
            r.scene, r.setting, r.pattern, r.sampling, r.order, r.bounces, r.rays, r.seconds, r.error, r.pareto
        );
    }
    s
}
