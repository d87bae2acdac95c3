//! A texel bundle's sky light read at a point of a triangle as the viewer
//! reads it (`view/lightmap.wgsl`): the bilinear mean over the four texels
//! around the point that hold light (charts are packed 2 texels apart, so
//! the four never mix two charts), else the texel under the point. The
//! panel's gather reads the interior this way, so a texel bundle's panel
//! sees the texels' light, not the vertices'.

use glam::Vec2;

use super::{Atlas, NO_CHART};

/// Per texel of an atlas, its irradiance `Σ_i L_i t_i` (RGB) and whether it
/// holds light; per triangle, its corners in the atlas.
#[derive(Clone, Debug)]
pub struct LightmapLight {
    width: u32,
    height: u32,
    /// The whole image, row by row: irradiance, or `None` where no light is held.
    image: Vec<Option<[f32; 3]>>,
    corners: Vec<[Vec2; 3]>,
    /// Per triangle: whether it lies in a chart (else it has no texel).
    charted: Vec<bool>,
}

impl LightmapLight {
    /// The light of `atlas`'s covered `texels` (ids `y * width + x`): each
    /// one's `irradiance`, held where `holds` (a texel whose points all lay
    /// inside geometry holds none).
    pub fn new(atlas: &Atlas, texels: &[u32], irradiance: &[[f32; 3]], holds: &[bool]) -> LightmapLight {
        let mut image = vec![None; atlas.width as usize * atlas.height as usize];
        for ((&texel, e), &h) in texels.iter().zip(irradiance).zip(holds) {
            if h {
                if let Some(slot) = image.get_mut(texel as usize) {
                    *slot = Some(*e);
                }
            }
        }
        LightmapLight {
            width: atlas.width,
            height: atlas.height,
            image,
            corners: (0..atlas.triangle_count()).map(|t| atlas.triangle_uv(t)).collect(),
            charted: atlas.triangle_chart.iter().map(|&c| c != NO_CHART).collect(),
        }
    }

    /// The irradiance at barycentrics `(u, v)` of `triangle` (weights
    /// `1 − u − v, u, v` on its corners); `None` for a triangle in no chart.
    pub fn at(&self, triangle: usize, u: f32, v: f32) -> Option<[f32; 3]> {
        if !*self.charted.get(triangle)? {
            return None;
        }
        let [a, b, c] = self.corners[triangle];
        Some(self.sample(a * (1.0 - u - v) + b * u + c * v))
    }

    /// The irradiance at atlas position `p` (texels; texel (x, y) covers
    /// [x, x+1) × [y, y+1)): bilinear over the four nearest texel centres
    /// that hold light, else the texel under `p` (zero when it holds none).
    pub fn sample(&self, p: Vec2) -> [f32; 3] {
        let max = (self.width as i64 - 1, self.height as i64 - 1);
        let texel = |x: i64, y: i64| self.image[(y.clamp(0, max.1) * self.width as i64 + x.clamp(0, max.0)) as usize];
        let q = p - Vec2::splat(0.5);
        let (corner, f) = (q.floor(), q - q.floor());
        let (mut sum, mut weight) = ([0.0f32; 3], 0.0f32);
        for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            let w = if dx == 1 { f.x } else { 1.0 - f.x } * if dy == 1 { f.y } else { 1.0 - f.y };
            if let Some(e) = texel(corner.x as i64 + dx, corner.y as i64 + dy) {
                (0..3).for_each(|k| sum[k] += w * e[k]);
                weight += w;
            }
        }
        if weight > 1e-6 {
            return sum.map(|s| s / weight);
        }
        texel(p.x.floor() as i64, p.y.floor() as i64).unwrap_or([0.0; 3])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4 × 2 atlas with one triangle: texel (1, 0) holds 1, (2, 0) holds
    /// 3, (1, 1) holds nothing, the rest are not covered.
    fn light() -> LightmapLight {
        let atlas = Atlas {
            width: 4,
            height: 2,
            texel_size: 0.1,
            uv: vec![Vec2::new(1.0, 0.0), Vec2::new(3.0, 0.0), Vec2::new(1.0, 2.0)],
            source_vertex: vec![0, 1, 2],
            indices: vec![0, 1, 2],
            triangle_chart: vec![0],
            chart_count: 1,
        };
        LightmapLight::new(&atlas, &[1, 2, 5], &[[1.0; 3], [3.0; 3], [9.0; 3]], &[true, true, false])
    }

    /// The viewer's rule: a texel centre reads its texel, halfway between two
    /// holding texels their mean, a texel holding nothing is left out of the
    /// weights, and where no neighbour holds light the texel under the point.
    #[test]
    fn reads_bilinearly_over_the_texels_that_hold_light() {
        let l = light();
        assert_eq!(l.sample(Vec2::new(1.5, 0.5)), [1.0; 3]);
        assert_eq!(l.sample(Vec2::new(2.0, 0.5)), [2.0; 3]);
        assert_eq!(l.sample(Vec2::new(2.25, 0.5)), [2.5; 3]);
        // Toward the empty texel (1, 1): only (1, 0) and (2, 0) weigh.
        assert_eq!(l.sample(Vec2::new(1.5, 1.0)), [1.0; 3]);
        // No covered texel around: the uncovered texel under the point reads zero.
        assert_eq!(l.sample(Vec2::new(3.9, 1.9)), [0.0; 3]);
        // Barycentrics: the triangle's corner 1 is at (3, 0), between (2, 0) and nothing.
        assert_eq!(l.at(0, 0.0, 0.0), Some(l.sample(Vec2::new(1.0, 0.0))));
        assert_eq!(l.at(0, 0.5, 0.0), Some([2.0; 3]));
        assert_eq!(l.at(1, 0.0, 0.0), None, "a triangle past the atlas");
    }
}
