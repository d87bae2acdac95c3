//! Edge errors: how much the baked light differs between an edge's two
//! vertices (the module doc of [`super`] defines both).

use glam::Vec3;
use rayon::prelude::*;

use super::EdgeError;
use crate::bake::{Mode, SunMasks, TransferResult};
use crate::bundle::budget;
use crate::mesh::Mesh;

/// Rec. 709 luminance weights.
const LUMINANCE: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// The skies transfer errors are measured under, and each one's
/// area-weighted mean shaded luminance over a mesh: the unit of error.
#[derive(Clone, Debug)]
pub struct MeanShading {
    skies: Vec<Vec<[f32; 3]>>,
    means: Vec<f64>,
}

impl MeanShading {
    /// The reference skies' mean shading of `mesh` baked as `result`.
    pub fn of(mesh: &Mesh, result: &TransferResult) -> MeanShading {
        let skies: Vec<Vec<[f32; 3]>> = budget::reference_lightings(result.order).into_iter().map(|l| l.sh).collect();
        let area = vertex_areas(mesh);
        let total_area: f64 = area.iter().sum();
        let means = skies
            .iter()
            .map(|sky| {
                let y = luminances(result, sky);
                let mean = y.iter().zip(&area).map(|(y, a)| y * a).sum::<f64>() / total_area.max(f64::MIN_POSITIVE);
                // A scene that is black under a sky measures in absolute units.
                if mean > 0.0 {
                    mean
                } else {
                    1.0
                }
            })
            .collect();
        MeanShading { skies, means }
    }
}

/// Shaded luminance per vertex under `sky`.
fn luminances(result: &TransferResult, sky: &[[f32; 3]]) -> Vec<f64> {
    layer_luminances(&result.total, result, sky)
}

/// Shaded luminance per vertex of `layer` (laid out as `result`'s) under `sky`.
fn layer_luminances(layer: &[f32], result: &TransferResult, sky: &[[f32; 3]]) -> Vec<f64> {
    budget::shade(layer, result.order, result.channels, sky).iter().map(|rgb| (0..3).map(|c| LUMINANCE[c] * rgb[c]).sum()).collect()
}

/// A third of the area of the triangles around each vertex.
fn vertex_areas(mesh: &Mesh) -> Vec<f64> {
    let mut area = vec![0.0f64; mesh.vertex_count()];
    for t in 0..mesh.triangle_count() {
        let third = mesh.triangle_area(t) / 3.0;
        for v in mesh.triangle(t) {
            area[v as usize] += third;
        }
    }
    area
}

/// Every edge of `mesh` once (vertex pairs, smaller first), in order of first use.
fn edges(mesh: &Mesh) -> Vec<[u32; 2]> {
    let mut all: Vec<[u32; 2]> = (0..mesh.triangle_count())
        .flat_map(|t| {
            let v = mesh.triangle(t);
            [0, 1, 2].map(|c| [v[c].min(v[(c + 1) % 3]), v[c].max(v[(c + 1) % 3])])
        })
        .filter(|[a, b]| a != b)
        .collect();
    all.sort_unstable();
    all.dedup();
    all
}

/// Each edge's transfer error: the largest luminance difference between its
/// vertices over the skies, less `noise_sigmas` standard errors of that
/// difference ([`shading_noise`]; nothing less than zero), over the larger
/// of the two vertices' mean and that sky's mean shading of the scene.
pub fn transfer_edge_errors(mesh: &Mesh, result: &TransferResult, mean: &MeanShading, noise_sigmas: f64) -> Vec<EdgeError> {
    let shaded: Vec<Vec<f64>> = mean.skies.iter().map(|sky| luminances(result, sky)).collect();
    let noise: Vec<Vec<f64>> = if noise_sigmas > 0.0 { shading_noise(result, &mean.skies) } else { Vec::new() };
    edges(mesh)
        .into_par_iter()
        .map(|[a, b]| {
            let (a, b) = (a as usize, b as usize);
            let error = shaded
                .iter()
                .zip(&mean.means)
                .enumerate()
                .map(|(sky, (y, &m))| {
                    let (ya, yb) = (y[a], y[b]);
                    let deep = match noise.get(sky) {
                        Some(n) => noise_sigmas * n[a].hypot(n[b]),
                        None => 0.0,
                    };
                    // Relative where the edge is brighter than the scene's
                    // mean (as a tone-mapped view shows it), against the mean
                    // in the dark, so noise in the dark does not count as light.
                    ((ya - yb).abs() - deep).max(0.0) / m.max(0.5 * (ya + yb))
                })
                .fold(0.0, f64::max);
            EdgeError { edge: [a as u32, b as u32], error }
        })
        .collect()
}

/// Per sky, each vertex's standard error of shaded luminance: its DC
/// standard error over every bounce (`TransferResult::noise`) scaled by the
/// vertex's shading per unit of DC, i.e. the same relative noise as its DC.
/// Empty rows (zeros) when the bake measured no noise (vertex sampling).
fn shading_noise(result: &TransferResult, skies: &[Vec<[f32; 3]>]) -> Vec<Vec<f64>> {
    let vertex_count = result.total.len() / (result.channels * crate::sh::coeff_count(result.order)).max(1);
    if result.noise.len() != vertex_count {
        return skies.iter().map(|_| vec![0.0; vertex_count]).collect();
    }
    let total = &result.total;
    let stride = result.channels * crate::sh::coeff_count(result.order);
    skies
        .iter()
        .map(|sky| {
            layer_luminances(total, result, sky)
                .iter()
                .enumerate()
                .map(|(v, &y)| {
                    let dc = f64::from(total[v * stride]);
                    if dc > 0.0 {
                        f64::from(result.noise[v]) * y.abs() / dc
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect()
}

/// Each edge's sun error: the difference of direct sun (`bit × cos`)
/// between its vertices, averaged over the day steps (an edge a shadow
/// crosses for a tenth of the day at cos 0.5 has error 0.05); a vertex
/// whose vote was split at a step (`split_votes`, the masks' layout)
/// counts its full `cos` there.
pub fn sun_edge_errors(mesh: &Mesh, masks: &SunMasks, split_votes: &[u32], suns: &[Option<Vec3>], mode: Mode) -> Vec<EdgeError> {
    let words = masks.words_per_vertex as usize;
    let split = |v: usize, k: usize| (split_votes[v * words + k / 32] >> (k % 32)) & 1 == 1;
    let cosine = |v: usize, s: Vec3| {
        let c = mesh.normals[v].dot(s);
        if mode == Mode::Window {
            c.abs()
        } else {
            c.max(0.0)
        }
    };
    let day: Vec<(usize, Vec3)> = suns.iter().enumerate().filter_map(|(k, s)| s.and_then(|s| s.try_normalize()).map(|s| (k, s))).collect();
    edges(mesh)
        .into_par_iter()
        .map(|edge @ [a, b]| {
            let (a, b) = (a as usize, b as usize);
            let mut error = 0.0f64;
            for &(k, s) in &day {
                let (ca, cb) = (cosine(a, s), cosine(b, s));
                let lit = |v: usize, c: f32| if masks.bit(v, k) { c } else { 0.0 };
                let mut e = (lit(a, ca) - lit(b, cb)).abs();
                if split(a, k) {
                    e = e.max(ca);
                }
                if split(b, k) {
                    e = e.max(cb);
                }
                error += e as f64;
            }
            EdgeError { edge, error: error / day.len().max(1) as f64 }
        })
        .collect()
}
