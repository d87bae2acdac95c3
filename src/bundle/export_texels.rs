//! Texel mode in a GLB export (docs/viewer.md, "Texel bundles"): the mesh
//! split along the atlas's seams (one vertex per atlas vertex, its atlas
//! position as `TEXCOORD_1`), the texel transfer as 16-bit RGBA PNGs, the
//! texel sun bits (and sunlit fractions, when stored) as 8-bit RGBA PNGs and
//! a coverage mask, all the atlas's
//! size, row `y` of an image being the texels `y · width + x`.
//!
//! Why 16-bit PNG with an affine map per channel: glTF core takes PNG and
//! JPEG only, transfer values are signed, and 16 bits over each channel's
//! own range keep the rounding under 1/131,070 of that range. The images are
//! dilated one texel past their coverage so that bilinear filtering at a
//! chart's border reads the chart's own light, not the empty atlas around it.

use glam::Vec2;
use serde_json::{json, Value};

use super::types::{SunSeries, TexelLayers};
use crate::atlas::Atlas;
use crate::mesh::{EmbeddedImage, Mesh};

/// The mesh with one vertex per atlas vertex: attributes copied from the
/// vertex it comes from, `lightmap_uvs` the atlas position over the atlas
/// size (in [0, 1], v down as glTF's), triangles in the mesh's order.
pub(super) fn atlas_mesh(mesh: &Mesh, atlas: &Atlas) -> Mesh {
    let size = Vec2::new(atlas.width as f32, atlas.height as f32);
    Mesh {
        lightmap_uvs: atlas.uv.iter().map(|&uv| uv / size).collect(),
        indices: atlas.indices.clone(),
        tri_material: mesh.tri_material.clone(),
        tri_group: mesh.tri_group.clone(),
        materials: mesh.materials.clone(),
        groups: mesh.groups.clone(),
        ..mesh.gather_vertices(&atlas.source_vertex)
    }
}

/// The mesh split along two atlases' seams (the transfer's and the sun's
/// own): one vertex per pair of atlas vertices, in first use over the
/// triangles' corners, `lightmap_uvs` the first atlas's position as in
/// [`atlas_mesh`]. Also each written vertex's bundle vertex and its
/// position in the sun's atlas over that atlas's size.
pub(super) fn two_atlas_mesh(mesh: &Mesh, atlas: &Atlas, sun_atlas: &Atlas) -> (Mesh, Vec<u32>, Vec<Vec2>) {
    let mut pairs: std::collections::HashMap<(u32, u32), u32> = std::collections::HashMap::new();
    let mut first_atlas = Vec::new();
    let mut sun_uv = Vec::new();
    let mut indices = Vec::with_capacity(atlas.indices.len());
    let (size, sun_size) = (Vec2::new(atlas.width as f32, atlas.height as f32), Vec2::new(sun_atlas.width as f32, sun_atlas.height as f32));
    for (&a, &s) in atlas.indices.iter().zip(&sun_atlas.indices) {
        let index = *pairs.entry((a, s)).or_insert_with(|| {
            first_atlas.push(a);
            sun_uv.push(sun_atlas.uv[s as usize] / sun_size);
            first_atlas.len() as u32 - 1
        });
        indices.push(index);
    }
    let source: Vec<u32> = first_atlas.iter().map(|&a| atlas.source_vertex[a as usize]).collect();
    let split = Mesh {
        lightmap_uvs: first_atlas.iter().map(|&a| atlas.uv[a as usize] / size).collect(),
        indices,
        tri_material: mesh.tri_material.clone(),
        tri_group: mesh.tri_group.clone(),
        materials: mesh.materials.clone(),
        groups: mesh.groups.clone(),
        ..mesh.gather_vertices(&source)
    };
    (split, source, sun_uv)
}

/// Where each texel of the atlas reads its values: its own covered row, or
/// for an empty texel next to covered ones the first of its eight
/// neighbours that is covered (left to right, top to bottom); `None` elsewhere.
fn dilated_rows(width: u32, height: u32, covered: &[u32]) -> Vec<Option<u32>> {
    let (w, h) = (width as i64, height as i64);
    let mut own = vec![None; (width as usize) * (height as usize)];
    for (row, &texel) in covered.iter().enumerate() {
        own[texel as usize] = Some(row as u32);
    }
    (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| {
            own[(y * w + x) as usize].or_else(|| {
                (-1..=1)
                    .flat_map(|dy| (-1..=1).map(move |dx| (x + dx, y + dy)))
                    .filter(|&(nx, ny)| (0..w).contains(&nx) && (0..h).contains(&ny))
                    .find_map(|(nx, ny)| own[(ny * w + nx) as usize])
            })
        })
        .collect()
}

fn encode_png(width: u32, height: u32, colour: png::ColorType, depth: png::BitDepth, data: &[u8]) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, width, height);
        encoder.set_color(colour);
        encoder.set_depth(depth);
        let mut writer = encoder.write_header().map_err(|e| e.to_string())?;
        writer.write_image_data(data).map_err(|e| e.to_string())?;
    }
    Ok(out)
}

/// The images of a texel bundle and the `extras.prtbake.texels` that
/// names them. `transfer`: the chosen layer's values, `per_texel` a covered
/// texel; `layer` its name. Image (and texture) 0 is the coverage mask.
pub(super) fn texel_images(
    texels: &TexelLayers,
    transfer: Option<(&[f32], usize, &str)>,
    sun: Option<&SunSeries>,
) -> Result<(Vec<EmbeddedImage>, Value), String> {
    let atlas = &texels.atlas;
    let (width, height) = (atlas.width, atlas.height);
    let rows = dilated_rows(width, height, &texels.texels);
    let mut images = Vec::new();

    let mut coverage = vec![0u8; rows.len()];
    for &texel in &texels.texels {
        coverage[texel as usize] = 255;
    }
    let png = encode_png(width, height, png::ColorType::Grayscale, png::BitDepth::Eight, &coverage)?;
    images.push(EmbeddedImage { name: "prtbake_coverage".into(), png, nearest: true });

    let mut transfer_meta = Value::Null;
    if let Some((values, per_texel, layer)) = transfer {
        let (mut offsets, mut scales, mut textures) = (Vec::new(), Vec::new(), Vec::new());
        for k in 0..per_texel.div_ceil(4) {
            let mut offset = [0f32; 4];
            let mut scale = [0f32; 4];
            for c in 0..4 {
                let j = 4 * k + c;
                if j < per_texel {
                    let column = values.iter().skip(j).step_by(per_texel);
                    let (lo, hi) = column.fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
                    if lo.is_finite() {
                        offset[c] = lo;
                        scale[c] = hi - lo;
                    }
                }
            }
            let mut data = Vec::with_capacity(rows.len() * 8);
            for row in &rows {
                for c in 0..4 {
                    let j = 4 * k + c;
                    let q = match row {
                        Some(r) if j < per_texel && scale[c] > 0.0 => {
                            ((values[*r as usize * per_texel + j] - offset[c]) / scale[c] * 65535.0).round().clamp(0.0, 65535.0) as u16
                        }
                        _ => 0,
                    };
                    data.extend_from_slice(&q.to_be_bytes());
                }
            }
            let png = encode_png(width, height, png::ColorType::Rgba, png::BitDepth::Sixteen, &data)?;
            textures.push(images.len());
            images.push(EmbeddedImage { name: format!("prtbake_transfer_{k}"), png, nearest: false });
            offsets.push(offset);
            scales.push(scale);
        }
        transfer_meta = json!({
            "layer": layer, "values_per_texel": per_texel, "textures": textures, "offset": offsets, "scale": scales,
            "decode": "value[4k + c] = offset[k][c] + scale[k][c] * q / 65535, q the 16-bit sample of channel c of texture k",
        });
        // Window mode: each texel's front-side share (TSID), its stored byte.
        if let Some(shares) = texels.transfer.as_ref().map(|t| &t.front_share).filter(|s| s.len() == texels.texels.len()) {
            let data: Vec<u8> = rows.iter().map(|row| row.map_or(255, |r| (shares[r as usize] * 255.0).round() as u8)).collect();
            let png = encode_png(width, height, png::ColorType::Grayscale, png::BitDepth::Eight, &data)?;
            transfer_meta["front_share"] = json!({ "texture": images.len(),
                "decode": "share = q / 255 of the light reached the front of the face (the side its winding faces); draw the back side with 1 - share" });
            images.push(EmbeddedImage { name: "prtbake_front_share".into(), png, nearest: false });
        }
    }

    let mut sun_meta = Value::Null;
    if let Some(sun) = sun.filter(|s| !s.texel_masks.is_empty()) {
        // The sun's own atlas (TSAT) has its own texels, size and coverage.
        let own_rows;
        let (rows, width, height) = match &sun.texel_atlas {
            Some(own) => {
                own_rows = dilated_rows(own.atlas.width, own.atlas.height, &own.texels);
                (&own_rows, own.atlas.width, own.atlas.height)
            }
            None => (&rows, width, height),
        };
        let own_coverage = match &sun.texel_atlas {
            Some(own) => {
                let mut coverage = vec![0u8; rows.len()];
                for &texel in &own.texels {
                    coverage[texel as usize] = 255;
                }
                let png = encode_png(width, height, png::ColorType::Grayscale, png::BitDepth::Eight, &coverage)?;
                images.push(EmbeddedImage { name: "prtbake_sun_coverage".into(), png, nearest: true });
                Some(images.len() - 1)
            }
            None => None,
        };
        let words = sun.words_per_vertex as usize;
        let mut textures = Vec::new();
        for k in 0..words {
            let data: Vec<u8> =
                rows.iter().flat_map(|row| row.map_or([0; 4], |r| sun.texel_masks[r as usize * words + k].to_le_bytes())).collect();
            let png = encode_png(width, height, png::ColorType::Rgba, png::BitDepth::Eight, &data)?;
            textures.push(images.len());
            images.push(EmbeddedImage { name: format!("prtbake_sun_{k}"), png, nearest: true });
        }
        let mut fraction_textures = Vec::new();
        let fraction_words = if sun.texel_fractions.is_empty() { 0 } else { sun.steps.len().div_ceil(8) };
        for k in 0..fraction_words {
            let word = |r: u32| sun.texel_fractions[r as usize * fraction_words + k].to_le_bytes();
            let data: Vec<u8> = rows.iter().flat_map(|row| row.map_or([0; 4], word)).collect();
            let png = encode_png(width, height, png::ColorType::Rgba, png::BitDepth::Eight, &data)?;
            fraction_textures.push(images.len());
            images.push(EmbeddedImage { name: format!("prtbake_sun_fraction_{k}"), png, nearest: true });
        }
        sun_meta = json!({ "words_per_texel": words, "textures": textures,
            "decode": "step 32k + 8j + b is bit b of channel j of texture k (sample with nearest filtering)",
            "fraction_textures": fraction_textures,
            "fraction_decode": "the sunlit share of step 8k + 2j + h is nibble h (low first) of channel j of fraction texture k, over 15; use it instead of the bit where present" });
        if let (Some(own), Some(coverage)) = (&sun.texel_atlas, own_coverage) {
            sun_meta["atlas"] = json!({ "uv": "TEXCOORD_2", "width": width, "height": height, "texel_size": own.atlas.texel_size,
                "covered_texels": own.texels.len(), "coverage_texture": coverage,
                "meaning": "the sun's bits lie on an atlas of their own (finer than the transfer's): sample these textures at the vertex attribute named by uv, in [0, 1] as TEXCOORD_1" });
        }
    }
    let meta = json!({
        "width": width, "height": height, "texel_size": atlas.texel_size, "uv": "TEXCOORD_1", "covered_texels": texels.texels.len(),
        "coverage_texture": 0, "dilated": 1, "transfer": transfer_meta, "sun": sun_meta,
    });
    Ok((images, meta))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dilation_fills_the_ring_around_coverage_from_the_first_covered_neighbour() {
        // 4 × 3 atlas, texels 5 and 6 covered (row 1, x = 1 and 2).
        let rows = dilated_rows(4, 3, &[5, 6]);
        let expect = [Some(0), Some(0), Some(0), Some(1), Some(0), Some(0), Some(1), Some(1), Some(0), Some(0), Some(0), Some(1)];
        assert_eq!(rows, expect);
        // 5 × 1 with texel 0 covered: only x = 1 is next to it.
        assert_eq!(dilated_rows(5, 1, &[0]), [Some(0), Some(0), None, None, None]);
    }
}
