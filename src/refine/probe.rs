//! Values of a per-vertex bake at points on the surface, for comparing
//! bakes of different refinements of one surface (a vertex-by-vertex
//! difference cannot: their vertices differ). Points are spread uniformly
//! by area; each is found on a mesh by a short ray along its face normal,
//! and the mesh's rows are interpolated there as the viewer's Gouraud
//! shading does.

use glam::Vec3;
use rayon::prelude::*;

use crate::bake::{SunMasks, Surfaces};
use crate::mesh::Mesh;
use crate::trace::Scene;

/// A point on a surface and its face normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    pub position: Vec3,
    pub normal: Vec3,
}

/// Where a point lies on a mesh: a triangle and barycentrics of its corners.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Located {
    pub triangle: u32,
    pub barycentrics: [f32; 3],
}

/// `count` points uniform by area over the triangles of `mesh` for which
/// `keep` holds, from a fixed stream keyed by `seed`.
pub fn surface_points(mesh: &Mesh, count: usize, seed: u64, keep: impl Fn(usize) -> bool) -> Vec<SurfacePoint> {
    let mut cumulative = Vec::with_capacity(mesh.triangle_count());
    let mut total = 0.0f64;
    for t in 0..mesh.triangle_count() {
        if keep(t) {
            total += mesh.triangle_area(t);
        }
        cumulative.push(total);
    }
    if total <= 0.0 {
        return Vec::new();
    }
    let mut state = seed ^ 0x9E37_79B9_7F4A_7C15;
    let mut uniform = move || {
        // splitmix64: a fixed, well-mixed stream.
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..count)
        .map(|_| {
            let target = uniform() * total;
            let t = cumulative.partition_point(|&c| c <= target).min(mesh.triangle_count() - 1);
            let (mut u, mut v) = (uniform() as f32, uniform() as f32);
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let [a, b, c] = mesh.triangle_positions(t);
            SurfacePoint { position: a + (b - a) * u + (c - a) * v, normal: (b - a).cross(c - a).normalize_or_zero() }
        })
        .collect()
}

/// Finds each point on the mesh `scene` was built from: the
/// nearest surface along its normal within `reach` either way; `None` when
/// there is none.
pub fn locate(scene: &Scene, points: &[SurfacePoint], reach: f32) -> Vec<Option<Located>> {
    points
        .par_iter()
        .map(|p| {
            let down = scene.closest_hit(p.position + p.normal * reach, -p.normal, 2.0 * reach);
            let hit = down.or_else(|| scene.closest_hit(p.position - p.normal * reach, p.normal, 2.0 * reach))?;
            Some(Located { triangle: hit.triangle, barycentrics: [1.0 - hit.u - hit.v, hit.u, hit.v] })
        })
        .collect()
}

/// `rows` (`stride` values per vertex of `mesh`) interpolated at each
/// located point; zeros where a point was not found.
pub fn interpolate(mesh: &Mesh, rows: &[f32], stride: usize, located: &[Option<Located>]) -> Vec<f32> {
    let mut out = vec![0.0f32; located.len() * stride];
    out.par_chunks_mut(stride.max(1)).zip(located.par_iter()).for_each(|(dst, l)| {
        if let Some(l) = l {
            for (corner, &v) in mesh.triangle(l.triangle as usize).iter().enumerate() {
                let w = l.barycentrics[corner];
                dst.iter_mut().zip(&rows[v as usize * stride..][..stride]).for_each(|(d, r)| *d += w * r);
            }
        }
    });
    out
}

/// The sun masks as the viewer draws them: each step's bit, interpolated
/// at each located point (`[point][step]`, in 0..=1).
pub fn interpolate_masks(mesh: &Mesh, masks: &SunMasks, steps: usize, located: &[Option<Located>]) -> Vec<f32> {
    let bits: Vec<f32> = (0..mesh.vertex_count()).flat_map(|v| (0..steps).map(move |k| if masks.bit(v, k) { 1.0 } else { 0.0 })).collect();
    interpolate(mesh, &bits, steps, located)
}

/// The per-point reference of sun masks: 1 where a ray from the point
/// toward `sun` escapes (open mode), its face turned toward the sun.
pub fn reference_sun(scene: &Scene, points: &[SurfacePoint], sun: Vec3) -> Vec<f32> {
    points
        .par_iter()
        .map(|p| {
            let facing = p.normal.dot(sun) > 0.0;
            let lit = facing && !scene.occluded(scene.offset_origin(p.position, p.normal, sun), sun, f32::INFINITY);
            if lit {
                1.0
            } else {
                0.0
            }
        })
        .collect()
}

/// The per-point reference of window-mode sun masks: 1 where the first hit
/// from the point toward `sun` is glass and, unless `keep_outside_sides`,
/// the side of the point the ray leaves from is not outside the enclosure
/// (`outside[p][side]`, from [`outside_sides`]): the rule the bake applies
/// (docs/conventions.md), so the reference draws the same light.
pub fn reference_sun_window(scene: &Scene, surfaces: &Surfaces, points: &[SurfacePoint], outside: &[[bool; 2]], sun: Vec3) -> Vec<f32> {
    points
        .par_iter()
        .zip(outside.par_iter())
        .map(|(p, outside)| {
            let side = crate::bake::enclosure::Sides::of(p.normal, sun);
            let through_glass = scene
                .closest_hit(scene.offset_origin(p.position, p.normal, sun), sun, f32::INFINITY)
                .is_some_and(|h| surfaces.window_transmittance[h.triangle as usize].is_some_and(|tau| tau > 0.0));
            if through_glass && !outside[side] {
                1.0
            } else {
                0.0
            }
        })
        .collect()
}

/// Each point's two sides (front, back of its face): outside the enclosure
/// by the bake's own probe (`bake::enclosure::side_is_outside`); all
/// `false` when `keep_outside_sides`.
pub fn outside_sides(scene: &Scene, surfaces: &Surfaces, points: &[SurfacePoint], keep_outside_sides: bool) -> Vec<[bool; 2]> {
    points
        .par_iter()
        .map(|p| {
            if keep_outside_sides {
                return [false; 2];
            }
            [0, 1].map(|side| crate::bake::enclosure::side_is_outside(scene, surfaces, p.position, p.normal, side))
        })
        .collect()
}
