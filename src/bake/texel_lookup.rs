//! Where a hit point lies in the texel atlas: the bilinear texels a bounce
//! reads the previous bounce from in texel mode. Reading texels instead of
//! the hit triangle's corner vertices (one-ring means) takes the gather's
//! bias down with the texel size rather than with the mesh: near a corner,
//! where light falls off faster than linearly across a big triangle, the
//! hit reads the light within a texel of it.
//!
//! A read uses only texels of the hit triangle's chart that hold light
//! (kept points); charts are packed [`crate::atlas::PADDING`] texels apart,
//! so the four texels around any point of a chart are its own or empty.

use glam::Vec2;

use crate::atlas::{Atlas, NO_CHART};

/// A texel with no receiver (uncovered, or every point inside geometry).
const NONE: u32 = u32::MAX;

/// Per mesh triangle its atlas corners and chart; per texel of the atlas
/// its receiver (an index into the covered texels) or [`NONE`].
pub(crate) struct TexelLookup {
    corner_uv: Vec<[Vec2; 3]>,
    triangle_chart: Vec<u32>,
    width: u32,
    height: u32,
    receiver: Vec<u32>,
    receiver_chart: Vec<u32>,
}

impl TexelLookup {
    /// `texels`: the covered texels (`y · width + x`), each with its chart;
    /// every one readable until [`TexelLookup::drop_empty`].
    pub(crate) fn new(atlas: &Atlas, texels: &[u32], chart: &[u32]) -> TexelLookup {
        let mut receiver = vec![NONE; atlas.width as usize * atlas.height as usize];
        for (i, &texel) in texels.iter().enumerate() {
            receiver[texel as usize] = i as u32;
        }
        TexelLookup {
            corner_uv: (0..atlas.triangle_count()).map(|t| atlas.triangle_uv(t)).collect(),
            triangle_chart: atlas.triangle_chart.clone(),
            width: atlas.width,
            height: atlas.height,
            receiver,
            receiver_chart: chart.to_vec(),
        }
    }

    /// A lookup over no atlas: every read misses.
    #[cfg(test)]
    pub(crate) fn empty() -> TexelLookup {
        TexelLookup {
            corner_uv: Vec::new(),
            triangle_chart: Vec::new(),
            width: 0,
            height: 0,
            receiver: Vec::new(),
            receiver_chart: Vec::new(),
        }
    }

    /// Texels whose points all fell inside geometry hold no light: reads skip them.
    pub(crate) fn drop_empty(&mut self, texels: &[u32], weights: &[f32]) {
        for (&texel, &weight) in texels.iter().zip(weights) {
            if weight <= 0.0 {
                self.receiver[texel as usize] = NONE;
            }
        }
    }

    /// Asks for what [`TexelLookup::bilinear`] reads first of `triangle`.
    #[inline(always)]
    pub(crate) fn prefetch(&self, triangle: usize) {
        if triangle < self.corner_uv.len() {
            crate::trace::bvh8::prefetch_bytes(self.corner_uv.as_ptr().wrapping_add(triangle), 24);
            crate::trace::bvh8::prefetch_bytes(self.triangle_chart.as_ptr().wrapping_add(triangle), 4);
        }
    }

    /// The texels to read at barycentrics `(u, v)` of mesh triangle
    /// `triangle`, with weights summing to 1: bilinear over the four texel
    /// centres around the point, those without light or of another chart
    /// left out. `None` for a triangle outside the atlas (a twin, or one
    /// xatlas left out) or when no texel around the point holds light.
    #[inline]
    pub(crate) fn bilinear(&self, triangle: usize, u: f32, v: f32) -> Option<([u32; 4], [f32; 4])> {
        let chart = *self.triangle_chart.get(triangle)?;
        if chart == NO_CHART {
            return None;
        }
        let [a, b, c] = self.corner_uv[triangle];
        let p = a * (1.0 - u - v) + b * u + c * v - Vec2::splat(0.5);
        let (x0, y0) = (p.x.floor(), p.y.floor());
        let (fx, fy) = (p.x - x0, p.y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let mut ids = [NONE; 4];
        let mut weights = [0.0f32; 4];
        let mut total = 0.0f32;
        for (k, (dx, dy, w)) in
            [(0, 0, (1.0 - fx) * (1.0 - fy)), (1, 0, fx * (1.0 - fy)), (0, 1, (1.0 - fx) * fy), (1, 1, fx * fy)].into_iter().enumerate()
        {
            let (x, y) = (x0 + dx, y0 + dy);
            if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 || w <= 0.0 {
                continue;
            }
            let r = self.receiver[(y * self.width as i64 + x) as usize];
            if r != NONE && self.receiver_chart[r as usize] == chart {
                ids[k] = r;
                weights[k] = w;
                total += w;
            }
        }
        if total <= 0.0 {
            return None;
        }
        weights.iter_mut().for_each(|w| *w /= total);
        Some((ids, weights))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One triangle over a 4 × 4 atlas, texels holding light everywhere but (2, 1).
    fn lookup() -> TexelLookup {
        let atlas = Atlas {
            width: 4,
            height: 4,
            texel_size: 1.0,
            uv: vec![Vec2::new(0.0, 0.0), Vec2::new(4.0, 0.0), Vec2::new(0.0, 4.0)],
            source_vertex: vec![0, 1, 2],
            indices: vec![0, 1, 2],
            triangle_chart: vec![0],
            chart_count: 1,
        };
        let texels: Vec<u32> = (0..16).collect();
        let weights: Vec<f32> = texels.iter().map(|&t| if t == 6 { 0.0 } else { 1.0 }).collect();
        let mut lookup = TexelLookup::new(&atlas, &texels, &[0; 16]);
        lookup.drop_empty(&texels, &weights);
        lookup
    }

    /// Barycentrics of the atlas point (x, y) on the test triangle.
    fn at(x: f32, y: f32) -> (f32, f32) {
        (x / 4.0, y / 4.0)
    }

    #[test]
    fn a_texel_centre_reads_that_texel_alone() {
        let (u, v) = at(1.5, 2.5);
        let (ids, w) = lookup().bilinear(0, u, v).unwrap();
        let read: Vec<(u32, f32)> = ids.iter().zip(w).filter(|(_, w)| *w > 0.0).map(|(&i, w)| (i, w)).collect();
        assert_eq!(read, vec![(2 * 4 + 1, 1.0)]);
    }

    #[test]
    fn between_centres_the_weights_are_bilinear_and_skip_dark_texels() {
        let l = lookup();
        // Between the centres of (0,0), (1,0), (0,1), (1,1): a quarter each.
        let (u, v) = at(1.0, 1.0);
        let (ids, w) = l.bilinear(0, u, v).unwrap();
        assert_eq!(ids, [0, 1, 4, 5]);
        assert!(w.iter().all(|&w| (w - 0.25).abs() < 1e-6), "{w:?}");
        // Around (2, 1), which holds no light: the other three share its weight.
        let (u, v) = at(2.0, 1.0);
        let (ids, w) = l.bilinear(0, u, v).unwrap();
        assert!(!ids.contains(&6), "{ids:?}");
        assert_eq!(ids.iter().filter(|&&i| i == NONE).count(), 1);
        for (&i, &w) in ids.iter().zip(&w) {
            let want = if i == NONE { 0.0 } else { 1.0 / 3.0 };
            assert!((w - want).abs() < 1e-6, "texel {i}: {w}");
        }
    }

    #[test]
    fn triangles_outside_the_atlas_read_nothing() {
        let l = lookup();
        assert!(l.bilinear(1, 0.2, 0.2).is_none(), "a twin's index is past the atlas");
    }
}
