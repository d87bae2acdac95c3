//! Export a bake for engines other than ours: the bundle's mesh as GLB with
//! its transfer coefficients and sun masks as application-specific vertex
//! attributes (`_PRT_…`). The layout is documented in docs/viewer.md
//! ("Export for other engines").
//!
//! - `_PRT_TRANSFER_k`, k = 0 … ⌈S/4⌉−1: VEC4 of FLOAT, values 4k … 4k+3 of the
//!   vertex's S = channels · order² transfer values in bundle order
//!   `[channel][coeff]` (coefficient index `l(l+1)+m`); the last one is zero-padded.
//! - `_PRT_SUN_k`, k = 0 … words_per_vertex−1: VEC4 of UNSIGNED_BYTE, the four
//!   little-endian bytes of sun-mask word k: step `32k + 8j + b` is bit b of byte j.
//! - Document `extras.prtbake`: order, channels, layer, attribute counts, and per
//!   step the sun direction, irradiance, time, night flag and sky SH.
//! - A texel bundle: the mesh split along the atlas's seams with `TEXCOORD_1`,
//!   and its texels as PNG textures named by `extras.prtbake.texels`
//!   ([`super::export_texels`]); per-vertex attributes follow their vertices.

use std::path::Path;

use serde_json::{json, Value};

use super::export_texels::{atlas_mesh, texel_images, two_atlas_mesh};
use super::values::check_bundle;
use super::{Bundle, LayerKind, Transfer};
use crate::mesh::{write_glb_with, AttributeValues, CustomAttribute, GlbAdditions, MeshError};

/// Name of the format version written into `extras.prtbake.format`.
pub const GLTF_EXPORT_FORMAT: &str = "prtbake-gltf-1";
/// Prefix of the transfer attributes (`_PRT_TRANSFER_0`, …).
pub const TRANSFER_ATTRIBUTE_PREFIX: &str = "_PRT_TRANSFER_";
/// Window mode: each vertex's front-side share (section SIDE), one float.
pub const FRONT_SHARE_ATTRIBUTE: &str = "_PRT_FRONT_SHARE";
/// Prefix of the sun-mask attributes (`_PRT_SUN_0`, …).
pub const SUN_ATTRIBUTE_PREFIX: &str = "_PRT_SUN_";

/// What [`export_glb`] wrote.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct GltfExportReport {
    pub vertices: usize,
    pub triangles: usize,
    /// Number of `_PRT_TRANSFER_k` attributes (0 without transfer).
    pub transfer_attributes: usize,
    /// Number of `_PRT_SUN_k` attributes (0 without sun masks).
    pub sun_attributes: usize,
    /// Which layer the transfer attributes hold: `total` or `bounce N`.
    pub layer: String,
    /// Texel bundles: the PNG textures written (coverage, transfer, sun bits); 0 otherwise.
    pub texel_textures: usize,
    /// The sun's bits on an atlas of their own, whose position is `TEXCOORD_2`.
    pub sun_atlas: bool,
}

/// The transfer attributes of `values` (S per vertex), 4 floats each, zero-padded.
pub fn transfer_attributes(values: &[f32], per_vertex: usize, vertex_count: usize) -> Vec<CustomAttribute> {
    let count = per_vertex.div_ceil(4);
    (0..count)
        .map(|k| {
            let mut data = Vec::with_capacity(4 * vertex_count);
            for v in 0..vertex_count {
                for j in 4 * k..4 * k + 4 {
                    data.push(if j < per_vertex { values[v * per_vertex + j] } else { 0.0 });
                }
            }
            CustomAttribute { semantic: format!("{TRANSFER_ATTRIBUTE_PREFIX}{k}"), values: AttributeValues::F32 { components: 4, data } }
        })
        .collect()
}

/// The values of `layer` (`None`: the total); `None` when it is not stored.
fn layer_values(transfer: &Transfer, layer: Option<LayerKind>) -> Option<Vec<f32>> {
    match layer {
        None | Some(LayerKind::Total) => Some(transfer.total()),
        Some(kind) => transfer.layer(kind).map(|l| l.data.clone()),
    }
}

/// Writes `bundle` as GLB at `path` with `_PRT_…` attributes.
///
/// `layer`: which transfer layer to write; `None` writes the total (the `Total`
/// layer, or the sum of the stored bounces). Errors when the layer is absent,
/// when a value is out of its range (NaN, albedo above 1, …: glTF has no NaN, and
/// JSON would get `null`), or when the mesh cannot be written (see [`write_glb_with`]).
pub fn export_glb(path: &Path, bundle: &Bundle, layer: Option<LayerKind>) -> Result<GltfExportReport, MeshError> {
    let invalid = |message: String| MeshError::InvalidForWrite { path: path.to_path_buf(), message };
    // Decoded bundles passed these checks already; bundles built in memory did not.
    check_bundle(bundle).map_err(|e| invalid(e.to_string()))?;
    // A texel bundle's vertices are split along the atlas's seams (and the
    // sun's own atlas's, with one): each written vertex carries the values of
    // the bundle vertex it copies.
    let own_sun_atlas = bundle.sun.as_ref().and_then(|s| s.texel_atlas.as_ref());
    let (split, split_source, sun_texcoords) = match (&bundle.texels, own_sun_atlas) {
        (Some(t), Some(own)) => {
            let (mesh, source, sun_uv) = two_atlas_mesh(&bundle.mesh, &t.atlas, &own.atlas);
            (Some(mesh), Some(source), Some(sun_uv))
        }
        (Some(t), None) => (Some(atlas_mesh(&bundle.mesh, &t.atlas)), Some(t.atlas.source_vertex.clone()), None),
        (None, _) => (None, None, None),
    };
    let mesh = split.as_ref().unwrap_or(&bundle.mesh);
    let vertex_count = mesh.vertex_count();
    let source: Vec<usize> = match split_source {
        Some(source) => source.iter().map(|&v| v as usize).collect(),
        None => (0..vertex_count).collect(),
    };
    let requested = match layer {
        Some(LayerKind::Bounce(b)) => format!("bounce {b}"),
        _ => "total".to_string(),
    };
    let mut attributes = Vec::new();
    let mut layer_name = "none".to_string();
    let mut transfer_meta = Value::Null;
    if let Some(t) = &bundle.transfer {
        let per_vertex = t.values_per_vertex() as usize;
        let values =
            layer_values(t, layer).ok_or_else(|| invalid(format!("the bundle stores no {requested} layer (bake with --store-bounces)")))?;
        layer_name = requested.clone();
        if let Some(j) = values.iter().position(|v| !v.is_finite()) {
            let vertex = j / per_vertex.max(1);
            return Err(invalid(format!("transfer {layer_name} value {j} (vertex {vertex}) is {}: the bounces sum past f32", values[j])));
        }
        let values: Vec<f32> = source.iter().flat_map(|&v| values[v * per_vertex..(v + 1) * per_vertex].iter().copied()).collect();
        attributes.extend(transfer_attributes(&values, per_vertex, vertex_count));
        transfer_meta = json!({
            "order": t.order, "channels": t.channels, "values_per_vertex": per_vertex, "layer": layer_name,
            "attributes": per_vertex.div_ceil(4), "prefix": TRANSFER_ATTRIBUTE_PREFIX,
        });
        if !t.front_share.is_empty() {
            let data = source.iter().map(|&v| t.front_share[v]).collect();
            attributes
                .push(CustomAttribute { semantic: FRONT_SHARE_ATTRIBUTE.into(), values: AttributeValues::F32 { components: 1, data } });
            transfer_meta["front_share"] = json!({
                "attribute": FRONT_SHARE_ATTRIBUTE,
                "meaning": "share of the vertex's light that reached the front of its face (the side its winding faces); draw the back side with 1 - share",
            });
        }
    } else if layer.is_some() {
        return Err(invalid("the bundle has no transfer".into()));
    }
    let transfer_count = attributes.iter().filter(|a| a.semantic.starts_with(TRANSFER_ATTRIBUTE_PREFIX)).count();

    let mut sun_meta = Value::Null;
    if let Some(sun) = &bundle.sun {
        let words = sun.words_per_vertex as usize;
        for k in 0..words {
            let data = source.iter().map(|&v| sun.masks[v * words + k].to_le_bytes()).collect();
            attributes.push(CustomAttribute { semantic: format!("{SUN_ATTRIBUTE_PREFIX}{k}"), values: AttributeValues::U8x4(data) });
        }
        let steps: Vec<Value> = sun
            .steps
            .iter()
            .map(|s| {
                json!({
                    "unix_time_utc": s.unix_time_utc, "direction": s.direction, "elevation_deg": s.elevation_deg,
                    "azimuth_deg": s.azimuth_deg, "sun_rgb": s.sun_rgb, "night": s.night, "sky_sh": s.sky_sh,
                })
            })
            .collect();
        sun_meta = json!({
            "steps": steps, "sky_order": sun.sky_order, "words_per_vertex": words, "attributes": words, "prefix": SUN_ATTRIBUTE_PREFIX,
        });
    }
    let sun_count = attributes.iter().filter(|a| a.semantic.starts_with(SUN_ATTRIBUTE_PREFIX)).count();
    let mut images = Vec::new();
    let mut texel_meta = Value::Null;
    if let Some(t) = &bundle.texels {
        let values = match &t.transfer {
            None => None,
            Some(x) => Some(layer_values(x, layer).ok_or_else(|| invalid(format!("the texels store no {requested} layer")))?),
        };
        let per_texel = t.transfer.as_ref().map_or(0, |x| x.values_per_vertex() as usize);
        let transfer = values.as_deref().map(|v| (v, per_texel, requested.as_str()));
        let (written, meta) = texel_images(t, transfer, bundle.sun.as_ref()).map_err(|e| invalid(format!("texel images: {e}")))?;
        images = written;
        texel_meta = meta;
    }
    let extras = json!({ "prtbake": {
        "format": GLTF_EXPORT_FORMAT,
        "transfer": transfer_meta,
        "sun": sun_meta,
        "texels": texel_meta,
        "shading": "radiance = albedo * (sum_i L_i t_i + bit * max(n.s, 0) * sun_rgb / pi); L_i = integral of L(w) y_i(w) dw",
        "conventions": bundle.meta.get("conventions").cloned().unwrap_or(Value::Null),
    }});
    let second_lightmap_uvs = sun_texcoords.unwrap_or_default();
    write_glb_with(
        path,
        mesh,
        GlbAdditions { attributes: &attributes, extras: Some(extras), images: &images, second_lightmap_uvs: &second_lightmap_uvs },
    )?;
    Ok(GltfExportReport {
        vertices: vertex_count,
        triangles: mesh.triangle_count(),
        transfer_attributes: transfer_count,
        sun_attributes: sun_count,
        layer: layer_name,
        texel_textures: images.len(),
        sun_atlas: !second_lightmap_uvs.is_empty(),
    })
}
