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
            front_share: result.front_share.iter().map(|&share| super::sections::quantize_share(share)).collect(),
        }),
        sun: None,
        texels: None,
    }
}

/// Texel mode with fewer rays per vertex point than per texel point
/// (`bake --vertex-rays`): META `texels.vertex_rays` says so; nothing when
/// they are the same.
pub fn note_vertex_rays(bundle: &mut Bundle, vertex_rays: u32, rays: u32) {
    if vertex_rays != rays {
        bundle.meta["texels"]["vertex_rays"] = json!(vertex_rays);
    }
}

/// Texel mode: adds the atlas and each covered texel's transfer to a bundle
/// [`make_bundle_stored`] made, stored as the vertices are (`choices`, from
/// [`StorageRequest::choose_with_texels`]: the vertices' choice and the
/// texels' measure of it, recorded as META `texels.storage`), and META
/// `texels` saying what they are. `atlas_source` names where the atlas came
/// from (`xatlas` or `TEXCOORD_1`). The one way whole bakes and merged
/// shards store texels.
pub fn add_texel_transfer(
    bundle: &mut Bundle,
    texels: bake::texels::TexelTransfer,
    result: &TransferResult,
    choices: Option<&(budget::Choice, budget::Choice)>,
    atlas_source: &str,
    points_per_texel: u32,
) {
    bundle.meta["texels"] = json!({
        "texel_size": texels.atlas.texel_size,
        "atlas": atlas_source,
        "points_per_texel": points_per_texel,
        "covered": texels.texels.len(),
        "points": texels.points,
        "points_rejected": texels.points_rejected,
        "rays": texels.rays,
        "meaning": "mean of the transfer over the texel's footprint on its triangles, parts inside geometry left out; bounces ≥ 1 (of vertices and texels) read the previous bounce at a hit bilinearly from the texels of the hit's chart, from the hit triangle's vertices on back sides",
    });
    if texels.points_added > 0 {
        bundle.meta["texels"]["points_added"] = json!(texels.points_added);
    }
    if let Some((_, on_texels)) = choices {
        bundle.meta["texels"]["storage"] = storage_meta(on_texels, result);
    }
    let storage = choices
        .map_or(budget::Storage { order: result.order, channels: result.channels, quantization: Quantization::F32 }, |(on_vertices, _)| {
            on_vertices.chosen.storage
        });
    let stored = |data: Vec<f32>| budget::reduce(&data, result.order, result.channels, &storage);
    let front_share = texels.front_share.iter().map(|&share| super::sections::quantize_share(share)).collect();
    let mut layers = vec![TransferLayer { kind: LayerKind::Total, data: stored(texels.total) }];
    layers.extend(
        texels.bounces.into_iter().enumerate().map(|(b, data)| TransferLayer { kind: LayerKind::Bounce(b as u32), data: stored(data) }),
    );
    bundle.texels = Some(super::TexelLayers {
        texels: texels.texels,
        transfer: Some(Transfer {
            order: storage.order as u32,
            channels: storage.channels as u32,
            quantization: storage.quantization,
            layers,
            front_share,
        }),
        atlas: texels.atlas,
    });
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
        let (order, channels) = (result.order, result.channels);
        let lightings = budget::reference_lightings(order);
        let storages = self.storages(order, channels);
        Some(self.choose_among(&result.total, &result.noise, order, channels, &storages, &lightings).0)
    }

    /// Texel mode: one storage for the vertices and the texels (the viewer
    /// reads both at one order and channel count), the smallest whose error
    /// the budget holds on each (or, on one whose noise alone is over it,
    /// that adds at most [`budget::OVER_BUDGET_SLACK`] to its noise), the
    /// texels measured with their own noise. Returns the vertices' choice
    /// and the texels' measure of it; `None` when both are stored as baked.
    pub fn choose_with_texels(
        &self,
        result: &TransferResult,
        texels: &bake::texels::TexelTransfer,
    ) -> Option<(budget::Choice, budget::Choice)> {
        if *self == StorageRequest::default() {
            return None;
        }
        let (order, channels) = (result.order, result.channels);
        let lightings = budget::reference_lightings(order);
        let storages = self.storages(order, channels);
        let (on_texels, texel_noise) = self.choose_among(&texels.total, &texels.noise, order, channels, &storages, &lightings);
        let limit = on_texels.limit();
        let fitting: Vec<budget::Storage> =
            on_texels.measured.iter().filter(|c| c.total_error.unwrap_or(c.shaded_error) <= limit).map(|c| c.storage).collect();
        let (on_vertices, _) = self.choose_among(&result.total, &result.noise, order, channels, &fitting, &lightings);
        // The vertices' choice is one the texels measured, or the bake as it is.
        let chosen = on_vertices.chosen.storage;
        let texel_chosen = match on_texels.measured.iter().find(|c| c.storage == chosen) {
            Some(c) => c.clone(),
            None => budget::measure(&texels.total, order, channels, &chosen, &lightings, texel_noise.as_deref()),
        };
        Some((on_vertices, budget::Choice { chosen: texel_chosen, ..on_texels }))
    }

    /// The storages to try: every quantization asked (all with `--quantize
    /// auto`), and with a budget every smaller order and channel count too.
    fn storages(&self, order: usize, channels: usize) -> Vec<budget::Storage> {
        let all = [Quantization::F16, Quantization::F16Tinted, Quantization::I16PerVertexScale, Quantization::F32];
        let quantizations: Vec<Quantization> = match self.quantize {
            Some(q) => vec![q],
            None => all.to_vec(),
        };
        match self.max_error {
            Some(_) => budget::candidates(order, channels, &quantizations),
            None => quantizations.iter().map(|&q| budget::Storage { order, channels, quantization: q }).collect(),
        }
    }

    /// The smallest of `storages` within the budget for the rows `total`,
    /// and the rows' noise per lighting when the budget counts it.
    fn choose_among(
        &self,
        total: &[f32],
        noise: &[f32],
        order: usize,
        channels: usize,
        storages: &[budget::Storage],
        lightings: &[budget::Lighting],
    ) -> (budget::Choice, Option<Vec<f64>>) {
        let limit = match (self.max_error, self.quantize) {
            (Some(e), _) => e,
            (None, None) => AUTO_QUANTIZE_BUDGET,
            // A fixed quantization without a budget: always taken, but measured.
            (None, Some(_)) => f64::INFINITY,
        };
        // --max-error counts the total error, the bake's own noise included
        // (the definition `chart --real` measures); `--quantize auto` alone
        // bounds what quantization loses.
        let noise = match self.max_error {
            Some(_) => budget::noise_errors(total, order, channels, noise, lightings),
            None => None,
        };
        let mut choice = budget::choose_within_total(total, order, channels, storages, limit, lightings, noise.as_deref());
        if limit.is_infinite() {
            choice.budget = None;
        }
        (choice, noise)
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
