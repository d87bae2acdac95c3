//! A bundle assembled from a bake: the transfer layers as stored (order,
//! channels and quantization from the storage choice), and the metadata every
//! bundle records (tool, parameters, deterministic stats, conventions). Only
//! deterministic values go in, so equal inputs give equal bytes.

use serde_json::json;

use super::{Bundle, LayerKind, Quantization, Transfer, TransferLayer};
use crate::bake::{self, BakeParams, TransferResult};
use crate::bundle::budget;
use crate::mesh::Mesh;

/// The conventions every bundle's metadata records.
pub fn conventions() -> serde_json::Value {
    json!({
        "sh": "real orthonormal SH without the Condon-Shortley phase; index i = l(l+1)+m; order n = bands l < n; polar axis +Z",
        "world": "right-handed, +Y up, metres as in the source file",
        "transfer": "per unit albedo of the receiver: L_out = albedo * sum_i L_i t_i, L_i = integral of L(w) y_i(w) dw",
        "layout": "vertex-major [vertex][channel][coeff]",
        "vertex_transfer": crate::bake::transfer::VERTEX_ESTIMATOR,
        "sun_masks": "step k of vertex v: bit k%32 of word v*words_per_vertex + k/32",
    })
}

/// Assembles a bundle from a bake. Only deterministic values go into it
/// (no timings), so equal inputs give equal bytes.
pub fn make_bundle(mesh: &Mesh, result: &TransferResult, params: &BakeParams, extra_meta: serde_json::Value) -> Bundle {
    make_bundle_stored(mesh, result, params, extra_meta, None)
}

/// [`make_bundle`] storing the transfer as `choice` says (order and channels
/// reduced, quantization set) and recording the choice and its measured
/// error under META `storage`. `None` stores the bake as it is, in f32.
pub fn make_bundle_stored(
    mesh: &Mesh,
    result: &TransferResult,
    params: &BakeParams,
    extra_meta: serde_json::Value,
    choice: Option<&budget::Choice>,
) -> Bundle {
    let storage = choice.map(|c| c.chosen.storage).unwrap_or(budget::Storage {
        order: result.order,
        channels: result.channels,
        quantization: Quantization::F32,
    });
    let stored = |data: &[f32]| budget::reduce(data, result.order, result.channels, &storage);
    let mut layers = vec![TransferLayer { kind: LayerKind::Total, data: stored(&result.total) }];
    for (b, layer) in result.bounces.iter().enumerate() {
        layers.push(TransferLayer { kind: LayerKind::Bounce(b as u32), data: stored(layer) });
    }
    let s = &result.stats;
    let mut meta = json!({
        "tool": "prtbake",
        "version": env!("CARGO_PKG_VERSION"),
        "command": "bake",
        "params": params,
        "stats": {
            "triangles": s.triangles, "vertices": s.vertices, "window_triangles": s.window_triangles,
            "points": s.points, "points_rejected": s.points_rejected,
            "vertices_without_samples": s.vertices_without_samples,
            "rays_per_bounce": s.rays_per_bounce, "rays": s.rays,
        },
        "conventions": conventions(),
    });
    if s.points_added > 0 {
        meta["stats"]["points_added"] = json!(s.points_added);
    }
    if s.back_sides > 0 {
        meta["stats"]["back_sides"] = json!(s.back_sides);
    }
    if let (Some(m), serde_json::Value::Object(extra)) = (meta.as_object_mut(), extra_meta) {
        m.extend(extra);
    }
    if let Some(c) = choice {
        meta["storage"] = storage_meta(c, result);
    }
    Bundle {
        meta,
        mesh: mesh.clone(),
        transfer: Some(Transfer {
            order: storage.order as u32,
            channels: storage.channels as u32,
            quantization: storage.quantization,
            layers,
        }),
        sun: None,
        texels: None,
    }
}

/// META `storage`: what was kept, what it measured, against what.
pub fn storage_meta(c: &budget::Choice, result: &TransferResult) -> serde_json::Value {
    let baked = budget::Storage { order: result.order, channels: result.channels, quantization: Quantization::F32 };
    let mut meta = json!({
        "order": c.chosen.storage.order,
        "channels": c.chosen.storage.channels,
        "quantization": c.chosen.storage.quantization.name(),
        "bytes_per_vertex_per_layer": c.chosen.bytes_per_vertex,
        "f32_bytes_per_vertex_per_layer": budget::bytes_per_vertex(&baked),
        "baked_order": result.order,
        "baked_channels": result.channels,
        "max_error": c.budget,
        "shaded_error": c.chosen.shaded_error,
        "quantization_max_abs": c.chosen.quantization_max_abs,
        "error_metric": "worst relative RMS of shaded radiance per unit albedo (sum_i L_i t_i) over vertices and RGB, \
                         against the baked f32 transfer, under 12 clear Preetham skies (elevations 10/35/65 deg, 4 azimuths)",
    });
    // With the bake's noise measured, max_error budgets the total: noise and storage in quadrature.
    if let (Some(noise), Some(total)) = (c.noise_error, c.chosen.total_error) {
        meta["noise_error"] = json!(noise);
        meta["total_error"] = json!(total);
        meta["within_budget"] = json!(c.within_budget());
        meta["total_error_metric"] = json!(
            "per sky sqrt(noise^2 + storage^2), worst over the skies; noise: each vertex's DC standard error, each bounce's \
             from its points' spread, in quadrature, scaled to the sky's shading as a relative error (bias from truncated bounces not counted)"
        );
    }
    meta
}

/// What the user asked about storage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StorageRequest {
    /// A fixed quantization, or `None` for the smallest within the budget.
    pub quantize: Option<Quantization>,
    /// Error budget (relative RMS in shaded radiance, see [`crate::bundle::budget`]):
    /// order, channels and quantization are chosen to fit it.
    pub max_error: Option<f64>,
}

impl Default for StorageRequest {
    /// Store the bake as it is, in f32.
    fn default() -> Self {
        StorageRequest { quantize: Some(Quantization::F32), max_error: None }
    }
}

/// Budget of `--quantize auto` without `--max-error`: quantization only, 0.1% shaded error.
pub const AUTO_QUANTIZE_BUDGET: f64 = 1e-3;

impl StorageRequest {
    /// Chooses and measures the storage of `result` (order and channels only
    /// shrink with a `max_error`). `None` when the bake is stored as it is.
    pub fn choose(&self, result: &TransferResult) -> Option<budget::Choice> {
        if *self == StorageRequest::default() {
            return None;
        }
        let all = [Quantization::F16, Quantization::F16Tinted, Quantization::I16PerVertexScale, Quantization::F32];
        let quantizations: Vec<Quantization> = match self.quantize {
            Some(q) => vec![q],
            None => all.to_vec(),
        };
        let (order, channels) = (result.order, result.channels);
        let storages: Vec<budget::Storage> = match self.max_error {
            Some(_) => budget::candidates(order, channels, &quantizations),
            None => quantizations.iter().map(|&q| budget::Storage { order, channels, quantization: q }).collect(),
        };
        let limit = match (self.max_error, self.quantize) {
            (Some(e), _) => e,
            (None, None) => AUTO_QUANTIZE_BUDGET,
            // A fixed quantization without a budget: always taken, but measured.
            (None, Some(_)) => f64::INFINITY,
        };
        let lightings = budget::reference_lightings(order);
        // --max-error counts the total error, the bake's own noise included
        // (the definition `chart --real` measures); `--quantize auto` alone
        // bounds what quantization loses.
        let noise = match self.max_error {
            Some(_) => budget::noise_errors(&result.total, order, channels, &result.noise, &lightings),
            None => None,
        };
        let mut choice = budget::choose_within_total(&result.total, order, channels, &storages, limit, &lightings, noise.as_deref());
        if limit.is_infinite() {
            choice.budget = None;
        }
        Some(choice)
    }
}

/// The metadata a bundle records beyond the bake: `base` (source, clean)
/// with the window and one-sided patterns and the window materials found.
pub fn bundle_meta(
    base: serde_json::Value,
    window_patterns: &[String],
    one_sided_patterns: &[String],
    surfaces: &bake::Surfaces,
) -> serde_json::Value {
    let mut meta = base;
    meta["window_patterns"] = json!(window_patterns);
    meta["one_sided_patterns"] = json!(one_sided_patterns);
    meta["windows"] = json!(surfaces.window_names);
    meta
}

/// The bundle of a bake: stored as `storage` asks, measured, encoded. The
/// one way whole bakes and merged shards make their bundle.
pub fn encode_transfer_bundle(
    mesh: &Mesh,
    result: &TransferResult,
    params: &BakeParams,
    meta: serde_json::Value,
    storage: &StorageRequest,
) -> Result<(Vec<u8>, Option<budget::Choice>), super::BundleError> {
    let choice = storage.choose(result);
    let bundle = make_bundle_stored(mesh, result, params, meta, choice.as_ref());
    Ok((super::encode_bundle(&bundle)?, choice))
}
