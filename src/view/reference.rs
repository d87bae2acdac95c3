//! The viewer's shading formula on the CPU, the oracle the GPU images are
//! compared with (tests) and the formula other engines implement (docs/viewer.md).

use super::scene::PreparedScene;
use crate::bundle::SunSeries;

/// Irradiance-like vertex term `E(v) = k · Σ_i L_i t_i(v) + bit · cos · sun_rgb / π`
/// (before albedo), for bundle vertex `v` seen from the side of unit normal
/// `normal` (the vertex normal turned toward the eye), on the front of its
/// triangle when `seen_front` (the side the winding faces, as the bake
/// tells sides).
///
/// `lighting` is truncated or zero-padded to the transfer order. `sun` is the
/// series and the step, when the sun term is on. The cosine is `max(n·s, 0)`:
/// the side the eye sees is lit only when it faces the sun. `k` is the seen
/// side's share of the transfer ([`crate::bake::side_share::seen_side_share`]).
pub fn vertex_light(
    scene: &PreparedScene,
    lighting: &[[f32; 3]],
    sun: Option<(&SunSeries, usize)>,
    v: usize,
    normal: [f32; 3],
    seen_front: bool,
) -> [f32; 3] {
    let n2 = (scene.order * scene.order) as usize;
    let channels = scene.channels as usize;
    let base = v * channels * n2;
    let mut light = [0.0f32; 3];
    for i in 0..n2 {
        let l = lighting.get(i).copied().unwrap_or([0.0; 3]);
        for c in 0..3 {
            let channel = if channels == 3 { c } else { 0 };
            light[c] += scene.transfer[base + channel * n2 + i] * l[c];
        }
    }
    let k = crate::bake::side_share::seen_side_share(scene.front_share.get(v).copied(), seen_front);
    light.iter_mut().for_each(|l| *l *= k);
    if let Some((series, step)) = sun {
        if let Some(s) = series.steps.get(step) {
            if series.bit(v, step) {
                let cosine = normal[0] * s.direction[0] + normal[1] * s.direction[1] + normal[2] * s.direction[2];
                let cosine = cosine.max(0.0);
                for (l, rgb) in light.iter_mut().zip(s.sun_rgb) {
                    *l += cosine * rgb / std::f32::consts::PI;
                }
            }
        }
    }
    light
}

/// Outgoing radiance `albedo · E`.
pub fn radiance(albedo: [f32; 3], light: [f32; 3]) -> [f32; 3] {
    [albedo[0] * light[0], albedo[1] * light[1], albedo[2] * light[2]]
}
