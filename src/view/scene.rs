//! Bundle → the flat arrays the GPU draws: vertices split by material (so the
//! fragment stage knows each triangle's albedo while the SH dot product stays
//! per bundle vertex), u32 indices, the selected transfer layers summed, masks.

use std::collections::HashMap;

use super::layers::LayerSelection;
use crate::bundle::{Bundle, SunSeries};

/// One GPU vertex: 40 bytes, `source` indexes the bundle's per-vertex data.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpuVertex {
    pub position: [f32; 3],
    pub normal: [f32; 3],
    /// Albedo of the material of the triangles using this copy, clamped to 0..1
    /// as the bake does; for glass copies (τ, τ, τ), the glass transmittance.
    pub albedo: [f32; 3],
    /// Bundle vertex whose transfer and sun bits this copy uses.
    pub source: u32,
}

/// Size of [`GpuVertex`] in the vertex buffer.
pub const GPU_VERTEX_BYTES: usize = 40;

impl GpuVertex {
    /// Little-endian bytes in the vertex-buffer layout.
    pub fn write_to(&self, out: &mut Vec<u8>) {
        for x in self.position.iter().chain(&self.normal).chain(&self.albedo) {
            out.extend_from_slice(&x.to_le_bytes());
        }
        out.extend_from_slice(&self.source.to_le_bytes());
    }
}

/// How a run of triangles is drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DrawKind {
    /// PRT-shaded, opaque.
    Opaque,
    /// Window glass: transmits τ of what is behind it (the env, or the car
    /// body seen through it), adds nothing.
    Glass { transmittance: f32 },
    /// The LCD panel ([`super::panel`]): PRT-shaded, plus its final-gathered
    /// texture when one is set ([`PanelDraws::texture`]), else as `Opaque`.
    Panel,
}

/// The panel's part of a prepared scene.
#[derive(Clone, Debug)]
pub struct PanelDraws {
    /// Texture coordinate of every GPU vertex ([0,1]² over the panel's texel
    /// grid; zero for vertices of other draws, which do not read it).
    pub texcoords: Vec<[f32; 2]>,
    /// The gathered radiance drawn on the panel; `None` draws it PRT-shaded only.
    pub texture: Option<super::panel::PanelTexture>,
}

/// A contiguous range of [`PreparedScene::indices`] with one material and one
/// way of drawing: the renderer picks each draw's pipeline by its kind (the
/// LCD panel's final-gathered texture is drawn by its own).
#[derive(Clone, Debug, PartialEq)]
pub struct MaterialDraw {
    /// Index into the bundle mesh's materials.
    pub material: u32,
    pub kind: DrawKind,
    /// Range of `indices` (multiples of 3).
    pub indices: std::ops::Range<u32>,
}

/// The bundle in the form the renderer uploads.
#[derive(Clone, Debug)]
pub struct PreparedScene {
    pub vertices: Vec<GpuVertex>,
    /// Triangles over `vertices`, u32, counter-clockwise (drawn two-sided),
    /// grouped by [`MaterialDraw`] (bundle triangle order within a draw).
    pub indices: Vec<u32>,
    /// The draws, opaque ones first.
    pub draws: Vec<MaterialDraw>,
    /// SH order n of the transfer.
    pub order: u32,
    /// 1 or 3.
    pub channels: u32,
    /// Selected transfer, `[bundle vertex][channel][coeff]`.
    pub transfer: Vec<f32>,
    /// Window mode: per bundle vertex, the share of its light that reached
    /// its front side (section SIDE); the side the eye sees is drawn with
    /// its share of the transfer. Empty: both sides show all of it.
    pub front_share: Vec<f32>,
    /// The bundle's sun masks (empty without a sun series) and words per vertex.
    pub masks: Vec<u32>,
    pub words_per_vertex: u32,
    /// Bounds of the drawn geometry.
    pub bounds: (glam::Vec3, glam::Vec3),
    /// The equirect map drawn behind the geometry ([`super::backdrop::Backdrop::EnvMap`]),
    /// uploaded once at full resolution; `None` for a sky or no backdrop.
    pub environment: Option<crate::sh::EquirectImage>,
    /// The panel's texture coordinates and texture, when the scene has a panel.
    pub panel: Option<PanelDraws>,
    /// Texel mode: opaque draws read their light from the bundle's texels.
    pub lightmap: Option<LightmapScene>,
}

/// A texel-mode bundle's light for the opaque draws: per GPU vertex its
/// atlas position (texels), and the selected transfer per covered texel.
#[derive(Clone, Debug)]
pub struct LightmapScene {
    pub width: u32,
    pub height: u32,
    /// Per GPU vertex, its position in the atlas in texels, then in the
    /// sun's own atlas (zero without one, and for glass copies).
    pub texcoords: Vec<[f32; 4]>,
    /// Covered texel ids (`y * width + x`), and whether each holds light
    /// (a texel whose points all lay inside geometry does not).
    pub texels: Vec<u32>,
    pub valid: Vec<bool>,
    /// The selected layers summed, `[texel][channel][coeff]`; empty when
    /// the bundle has texel sun bits only (the sky light is then per vertex).
    pub transfer: Vec<f32>,
    /// Per covered texel, the front side's share of its light (section
    /// TSID), as [`PreparedScene::front_share`]; empty without.
    pub front_share: Vec<f32>,
    /// The bundle's time lapse when it has sun bits per texel (its
    /// per-vertex masks left out: the vertex buffers carry them); `None`:
    /// the sun stays per vertex.
    pub texel_sun: Option<SunSeries>,
    /// The sun's bits on an atlas of their own (section TSAT): its size
    /// and covered texels; the bits of `texel_sun` are its texels'.
    pub sun_atlas: Option<SunAtlasTexels>,
}

/// The sun's own atlas as the viewer reads it.
#[derive(Clone, Debug)]
pub struct SunAtlasTexels {
    pub width: u32,
    pub height: u32,
    /// Covered texel ids (`y * width + x`), in the order of the sun's bits.
    pub texels: Vec<u32>,
}

impl LightmapScene {
    /// Whether the texels carry their own sun bits (else the sun is per vertex).
    pub fn has_sun_bits(&self) -> bool {
        self.texel_sun.is_some()
    }

    /// Whether the texels carry the sky light (else it is per vertex).
    pub fn has_sky(&self) -> bool {
        !self.transfer.is_empty()
    }

    /// Whether the texels carry their front-side shares.
    pub fn has_side_shares(&self) -> bool {
        self.has_sky() && self.front_share.len() == self.texels.len()
    }

    /// Each texel's front share over the whole texture (1 off the covered texels).
    pub fn side_share_image(&self) -> Vec<f32> {
        let mut image = vec![1.0f32; self.width as usize * self.height as usize];
        for (&texel, &share) in self.texels.iter().zip(&self.front_share) {
            image[texel as usize] = share;
        }
        image
    }

    /// The sun's own atlas at `sun_step`: 1 + each covered texel's sunlit
    /// share, 0 off its texels (the fragment shader reads it bilinearly
    /// over its covered texels); empty without a sun atlas.
    pub fn own_atlas_sun(&self, sun_step: Option<usize>) -> Vec<f32> {
        let (Some(own), Some(series)) = (&self.sun_atlas, &self.texel_sun) else {
            return Vec::new();
        };
        let mut image = vec![0.0f32; own.width as usize * own.height as usize];
        for (i, &texel) in own.texels.iter().enumerate() {
            image[texel as usize] = 1.0 + sun_step.map_or(0.0, |k| series.texel_sun(i, k));
        }
        image
    }

    /// Irradiance per texel of the whole texture for `lighting` (the SH dot
    /// product the vertex shader does per vertex), RGBA; the fragment shader
    /// reads it bilinearly. A is 0 where the texel holds no light, else 1,
    /// plus its sunlit share at `sun_step` when it has sun bits on this
    /// atlas (its stored fraction, else its bit).
    pub fn irradiance(&self, order: u32, channels: u32, lighting: &[[f32; 3]], sun_step: Option<usize>) -> Vec<[f32; 4]> {
        let n2 = (order * order) as usize;
        let stride = n2 * channels as usize;
        let mut image = vec![[0.0f32; 4]; self.width as usize * self.height as usize];
        for (i, &texel) in self.texels.iter().enumerate() {
            if !self.valid[i] {
                continue;
            }
            let mut e = [0.0f32; 3];
            if let Some(row) = self.transfer.get(i * stride..(i + 1) * stride) {
                for (k, l) in lighting.iter().take(n2).enumerate() {
                    for c in 0..3 {
                        let t = if channels == 3 { row[c * n2 + k] } else { row[k] };
                        e[c] += t * l[c];
                    }
                }
            }
            let lit = match (&self.texel_sun, sun_step) {
                (Some(series), Some(k)) if self.sun_atlas.is_none() => series.texel_sun(i, k),
                _ => 0.0,
            };
            image[texel as usize] = [e[0], e[1], e[2], 1.0 + lit];
        }
        image
    }
}

/// Prepares `bundle` for drawing.
///
/// Windows (the window role, or the bake's `--window` patterns from META, by
/// material or group name, with their transmittance) are drawn as glass.
/// Triangles whose material or group name matches a glob of `hide` are not
/// drawn. Errors when the bundle has no transfer, a pattern is malformed, or
/// the selected layers are absent.
pub fn prepare_scene(bundle: &Bundle, layers: &LayerSelection, hide: &[String]) -> Result<PreparedScene, String> {
    prepare_scene_with_panel(bundle, layers, hide, None)
}

/// [`prepare_scene`], with the triangles of `panel` (those not drawn as glass)
/// in draws of kind [`DrawKind::Panel`] whose vertices carry their texture
/// coordinates; no texture yet ([`PanelDraws::texture`] is `None`).
pub fn prepare_scene_with_panel(
    bundle: &Bundle,
    layers: &LayerSelection,
    hide: &[String],
    panel: Option<&super::panel::PanelMapping>,
) -> Result<PreparedScene, String> {
    let transfer = bundle.transfer.as_ref().ok_or("the bundle has no transfer to shade (bake it first)")?;
    if transfer.channels != 1 && transfer.channels != 3 {
        return Err(format!("{} transfer channels: the viewer shades 1 (grey) or 3 (RGB)", transfer.channels));
    }
    if transfer.order as usize > crate::sh::MAX_ORDER {
        return Err(format!("transfer order {} is above {}", transfer.order, crate::sh::MAX_ORDER));
    }
    if let LayerSelection::Bounces(list) = layers {
        let stored = transfer.stored_bounces();
        if let Some(b) = list.iter().find(|b| !stored.contains(b)) {
            return Err(format!("bounce {b} is not stored in the bundle (stored: {stored:?})"));
        }
    }
    let patterns = hide
        .iter()
        .map(|p| glob::Pattern::new(p).map_err(|e| format!("invalid --hide pattern {p:?}: {e}")))
        .collect::<Result<Vec<_>, _>>()?;
    let mesh = &bundle.mesh;
    let surfaces = crate::bake::Surfaces::resolve(mesh, &bundle.window_patterns()).map_err(|e| format!("META window_patterns: {e}"))?;
    let hidden_material: Vec<bool> = mesh.materials.iter().map(|m| patterns.iter().any(|p| p.matches(&m.name))).collect();
    let hidden_group: Vec<bool> = mesh.groups.iter().map(|g| patterns.iter().any(|p| p.matches(g))).collect();
    let mut is_panel = vec![false; mesh.triangle_count()];
    for &t in panel.map_or(&[][..], |p| &p.triangles) {
        is_panel[t as usize] = true;
    }

    // Each drawn triangle's draw: (material, kind), numbered in first-use order.
    let mut draw_keys: Vec<(u32, DrawKind)> = Vec::new();
    let mut triangles_of_draw: Vec<Vec<u32>> = Vec::new();
    for t in 0..mesh.triangle_count() {
        let material = u32::from(mesh.tri_material[t]);
        if hidden_material[material as usize] || hidden_group[mesh.tri_group[t] as usize] {
            continue;
        }
        let kind = match surfaces.window_transmittance[t] {
            Some(transmittance) => DrawKind::Glass { transmittance },
            None if is_panel[t] => DrawKind::Panel,
            None => DrawKind::Opaque,
        };
        let draw = match draw_keys.iter().position(|&key| key == (material, kind)) {
            Some(d) => d,
            None => {
                draw_keys.push((material, kind));
                triangles_of_draw.push(Vec::new());
                draw_keys.len() - 1
            }
        };
        triangles_of_draw[draw].push(t as u32);
    }
    // Opaque draws first (the backdrop and the glass are drawn after them).
    let mut order: Vec<usize> = (0..draw_keys.len()).collect();
    order.sort_by_key(|&d| matches!(draw_keys[d].1, DrawKind::Glass { .. }));

    // One GPU vertex per (bundle vertex, draw) pair in first-use order; in
    // texel mode per (atlas vertex, draw), since a chart seam splits a vertex.
    // With the sun on an atlas of its own, per (atlas vertex, its atlas vertex, draw).
    let atlas = bundle.texels.as_ref().map(|t| &t.atlas);
    let sun_atlas = bundle.sun.as_ref().and_then(|s| s.texel_atlas.as_ref()).map(|own| &own.atlas);
    let mut atlas_uv: Vec<[f32; 4]> = Vec::new();
    let mut copies: HashMap<(u32, u32, usize), u32> = HashMap::new();
    let mut vertices = Vec::new();
    let mut texcoords = Vec::new();
    let mut indices = Vec::with_capacity(mesh.indices.len());
    let mut draws = Vec::with_capacity(order.len());
    let (mut lo, mut hi) = (glam::Vec3::splat(f32::INFINITY), glam::Vec3::splat(f32::NEG_INFINITY));
    for d in order {
        let (material, kind) = draw_keys[d];
        // Glass copies carry (τ, τ, τ) where opaque ones carry the albedo.
        let colour = match kind {
            DrawKind::Opaque | DrawKind::Panel => mesh.materials[material as usize].albedo.map(|a| a.clamp(0.0, 1.0)),
            DrawKind::Glass { transmittance } => [transmittance; 3],
        };
        let first = indices.len() as u32;
        for &t in &triangles_of_draw[d] {
            for (corner, v) in mesh.triangle(t as usize).into_iter().enumerate() {
                let atlas_vertex = atlas.map(|a| a.indices[3 * t as usize + corner]);
                let sun_atlas_vertex = sun_atlas.map_or(0, |a| a.indices[3 * t as usize + corner]);
                let key = (atlas_vertex.unwrap_or(v), sun_atlas_vertex, d);
                let index = *copies.entry(key).or_insert_with(|| {
                    if let Some(a) = atlas {
                        let uv = a.uv[atlas_vertex.unwrap_or(0) as usize];
                        let sun_uv = sun_atlas.map_or(glam::Vec2::ZERO, |s| s.uv[sun_atlas_vertex as usize]);
                        let glass = matches!(kind, DrawKind::Glass { .. });
                        atlas_uv.push(if glass { [0.0; 4] } else { [uv.x, uv.y, sun_uv.x, sun_uv.y] });
                    }
                    let position = mesh.positions[v as usize];
                    lo = lo.min(position);
                    hi = hi.max(position);
                    vertices.push(GpuVertex {
                        position: position.to_array(),
                        normal: mesh.normals[v as usize].to_array(),
                        albedo: colour,
                        source: v,
                    });
                    if let (Some(mapping), DrawKind::Panel) = (panel, kind) {
                        texcoords.resize(vertices.len() - 1, [0.0; 2]);
                        texcoords.push(mapping.texcoord(mesh, v));
                    }
                    vertices.len() as u32 - 1
                });
                indices.push(index);
            }
        }
        draws.push(MaterialDraw { material, kind, indices: first..indices.len() as u32 });
    }
    if indices.is_empty() {
        (lo, hi) = mesh.bounds();
    }
    let panel = panel.map(|_| {
        texcoords.resize(vertices.len(), [0.0; 2]);
        PanelDraws { texcoords, texture: None }
    });
    let lightmap = match &bundle.texels {
        Some(t) => {
            let stride = (transfer.order * transfer.order * transfer.channels) as usize;
            let texel_front_share = t.transfer.as_ref().map_or_else(Vec::new, |tt| tt.front_share.clone());
            let (texel_transfer, valid) = match &t.transfer {
                Some(tt) => {
                    if tt.order != transfer.order || tt.channels != transfer.channels {
                        return Err(format!(
                            "the texels' transfer (order {}, {} channels) differs from the vertices' (order {}, {})",
                            tt.order, tt.channels, transfer.order, transfer.channels
                        ));
                    }
                    let texel_transfer = layers.combine(tt);
                    let valid = texel_transfer.chunks_exact(stride.max(1)).map(|row| row.iter().any(|&x| x != 0.0)).collect();
                    (texel_transfer, valid)
                }
                // Sun bits alone (`sun --texel-size` on a mesh or a vertex bundle): the sky light stays per vertex.
                None => (Vec::new(), vec![true; t.texels.len()]),
            };
            let texel_sun = bundle.sun.as_ref().filter(|s| !s.texel_masks.is_empty()).map(|s| SunSeries {
                sky_order: s.sky_order,
                steps: s.steps.clone(),
                words_per_vertex: s.words_per_vertex,
                masks: Vec::new(),
                texel_masks: s.texel_masks.clone(),
                texel_fractions: s.texel_fractions.clone(),
                texel_atlas: None,
            });
            let sun_atlas = bundle.sun.as_ref().and_then(|s| s.texel_atlas.as_ref()).map(|own| SunAtlasTexels {
                width: own.atlas.width,
                height: own.atlas.height,
                texels: own.texels.clone(),
            });
            Some(LightmapScene {
                width: t.atlas.width,
                height: t.atlas.height,
                texcoords: atlas_uv,
                texels: t.texels.clone(),
                valid,
                transfer: texel_transfer,
                front_share: texel_front_share,
                texel_sun,
                sun_atlas,
            })
        }
        None => None,
    };
    let (masks, words_per_vertex) = match &bundle.sun {
        Some(SunSeries { masks, words_per_vertex, .. }) => (masks.clone(), *words_per_vertex),
        None => (Vec::new(), 0),
    };
    Ok(PreparedScene {
        vertices,
        indices,
        draws,
        order: transfer.order,
        channels: transfer.channels,
        transfer: layers.combine(transfer),
        front_share: transfer.front_share.clone(),
        masks,
        words_per_vertex,
        bounds: (lo, hi),
        environment: None,
        panel,
        lightmap,
    })
}
