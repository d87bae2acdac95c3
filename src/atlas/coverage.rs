//! Which texels each triangle covers, and by how much: the receivers of
//! texel mode. A texel's samples lie in its footprint on its triangles, and
//! a triangle's point splats to the texels around it, so every texel a
//! triangle overlaps by any area is listed (conservative), with the area of
//! the overlap (the triangle clipped to the texel's square).

use super::{Atlas, NO_CHART};
use glam::{DVec2, Vec2};
use rayon::prelude::*;

/// Texels with their covering triangles (compressed rows, texels ascending,
/// each texel's triangles ascending).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Coverage {
    /// Texel ids `y * width + x`, ascending, each once.
    pub texels: Vec<u32>,
    /// Texel `i`'s entries are `start[i]..start[i + 1]`.
    pub start: Vec<u32>,
    pub triangle: Vec<u32>,
    /// Overlap area in texels² (1 for a texel the triangle covers whole).
    pub area: Vec<f32>,
}

impl Coverage {
    /// The texels of `atlas` that its triangles overlap.
    pub fn of(atlas: &Atlas) -> Coverage {
        let mut entries: Vec<(u32, u32, f32)> = (0..atlas.triangle_count())
            .into_par_iter()
            .filter(|&t| atlas.triangle_chart[t] != NO_CHART)
            .flat_map_iter(|t| triangle_texels(atlas, t).into_iter().map(move |(texel, area)| (texel, t as u32, area)))
            .collect();
        entries.sort_unstable_by_key(|&(texel, t, _)| (texel, t));
        let mut c = Coverage { start: vec![0], ..Coverage::default() };
        for (i, &(texel, t, area)) in entries.iter().enumerate() {
            if c.texels.last() != Some(&texel) {
                if !c.texels.is_empty() {
                    c.start.push(i as u32);
                }
                c.texels.push(texel);
            }
            c.triangle.push(t);
            c.area.push(area);
        }
        if !c.texels.is_empty() {
            c.start.push(entries.len() as u32);
        }
        c
    }

    /// Number of covered texels.
    pub fn len(&self) -> usize {
        self.texels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.texels.is_empty()
    }
}

/// The texels triangle `t` overlaps by a positive area, with the overlap.
fn triangle_texels(atlas: &Atlas, t: usize) -> Vec<(u32, f32)> {
    let uv = atlas.triangle_uv(t);
    let (lo, hi) = (uv[0].min(uv[1]).min(uv[2]), uv[0].max(uv[1]).max(uv[2]));
    let clamp = |v: f32, n: u32| (v.max(0.0) as u32).min(n.saturating_sub(1));
    let (x0, y0) = (clamp(lo.x.floor(), atlas.width), clamp(lo.y.floor(), atlas.height));
    let (x1, y1) = (clamp(hi.x.floor(), atlas.width), clamp(hi.y.floor(), atlas.height));
    let mut out = Vec::new();
    for y in y0..=y1 {
        for x in x0..=x1 {
            let area = polygon_area(&clip_to_texel(uv, x, y));
            if area > 0.0 {
                out.push((y * atlas.width + x, area as f32));
            }
        }
    }
    out
}

/// The triangle clipped to texel `(x, y)`'s square (Sutherland–Hodgman);
/// at most 7 corners, none when they do not overlap.
pub fn clip_to_texel(tri: [Vec2; 3], x: u32, y: u32) -> Vec<DVec2> {
    let mut poly: Vec<DVec2> = tri.iter().map(|p| p.as_dvec2()).collect();
    let (x, y) = (x as f64, y as f64);
    // Each edge of the square as (axis, bound, keep the side above it).
    for (axis, bound, above) in [(0, x, true), (0, x + 1.0, false), (1, y, true), (1, y + 1.0, false)] {
        if poly.is_empty() {
            break;
        }
        let inside = |p: DVec2| if above { p[axis] >= bound } else { p[axis] <= bound };
        let mut next = Vec::with_capacity(poly.len() + 1);
        for i in 0..poly.len() {
            let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
            let (ia, ib) = (inside(a), inside(b));
            if ia {
                next.push(a);
            }
            if ia != ib {
                let s = (bound - a[axis]) / (b[axis] - a[axis]);
                let mut p = a + (b - a) * s;
                p[axis] = bound;
                next.push(p);
            }
        }
        poly = next;
    }
    poly
}

/// Unsigned area of a polygon (shoelace).
pub fn polygon_area(poly: &[DVec2]) -> f64 {
    let n = poly.len();
    if n < 3 {
        return 0.0;
    }
    (0..n).map(|i| poly[i].perp_dot(poly[(i + 1) % n])).sum::<f64>().abs() * 0.5
}
