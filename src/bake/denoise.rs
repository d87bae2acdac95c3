//! A denoiser for baked receivers, guided by the bake's own noise estimate.
//!
//! Each pass replaces a receiver's value by an area-weighted mean over
//! itself and its edge neighbours, each neighbour weighted by how well
//! noise explains its difference: `w = exp(−Δ² / (2 k² (σ_u² + σ_v²)))`,
//! Δ the two receivers' DC difference (channel 0), σ their standard errors
//! (`TransferResult::noise`), `k` the strength. A difference the noise
//! explains is averaged away; one several σ larger (a shadow edge, a
//! contact shadow the light really has) keeps its neighbour's weight near
//! zero, so the edge stays where it is. Neighbours whose shading normals
//! part by more than [`CREASE_COS`] are not mixed (a crease the mesh shares
//! vertices across). Every SH coefficient and channel moves with the same
//! weights, and so does each stored bounce, so the bounces still add to the
//! total. Each pass also carries the noise through (σ² of a weighted mean)
//! for the next. Each receiver's output depends only on the inputs, so the
//! bytes do not depend on the thread count.

use rayon::prelude::*;

use crate::mesh::Mesh;

/// Neighbours whose normals' cosine is below this are never mixed (about 37°).
pub const CREASE_COS: f32 = 0.8;

/// Passes of the filter: each widens the footprint by one ring.
pub const PASSES: usize = 2;

/// Receivers per parallel task.
const PER_TASK: usize = 4096;

/// Neighbours per receiver, sorted and unique (compressed rows): a vertex's
/// edge neighbours, or a texel's 8 surrounding texels of its chart.
pub(crate) struct Neighbours {
    offsets: Vec<u32>,
    list: Vec<u32>,
}

impl Neighbours {
    fn build(mesh: &Mesh) -> Neighbours {
        let mut pairs: Vec<(u32, u32)> = Vec::with_capacity(mesh.indices.len() * 2);
        for tri in mesh.indices.chunks_exact(3) {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                if a != b {
                    pairs.push((a, b));
                    pairs.push((b, a));
                }
            }
        }
        Neighbours::from_pairs(mesh.vertex_count(), pairs)
    }

    /// From directed pairs `(receiver, neighbour)` over `n` receivers.
    pub(crate) fn from_pairs(n: usize, mut pairs: Vec<(u32, u32)>) -> Neighbours {
        pairs.sort_unstable();
        pairs.dedup();
        let mut offsets = vec![0u32; n + 1];
        for &(a, _) in &pairs {
            offsets[a as usize + 1] += 1;
        }
        for v in 0..n {
            offsets[v + 1] += offsets[v];
        }
        Neighbours { offsets, list: pairs.into_iter().map(|(_, b)| b).collect() }
    }

    fn of(&self, v: usize) -> &[u32] {
        &self.list[self.offsets[v] as usize..self.offsets[v + 1] as usize]
    }
}

/// A third of the area of the triangles around each vertex.
fn vertex_areas(mesh: &Mesh) -> Vec<f32> {
    let mut area = vec![0.0f32; mesh.vertex_count()];
    for t in 0..mesh.triangle_count() {
        let third = (mesh.triangle_area(t) / 3.0) as f32;
        for v in mesh.triangle(t) {
            area[v as usize] += third;
        }
    }
    area
}

/// Filters `total` (`[vertex][channel][coeff]`, `stride` floats a vertex) and
/// each of `layers` alike, in place, at strength `k` (> 0), guided by
/// `noise` (one standard error per vertex of the DC of channel 0); `noise`
/// becomes the filtered values' standard error. Does nothing when the bake
/// measured no noise (`noise` empty).
pub fn denoise(mesh: &Mesh, total: &mut [f32], layers: &mut [Vec<f32>], noise: &mut Vec<f32>, stride: usize, k: f32) {
    let n = mesh.vertex_count();
    if noise.len() != n || total.len() != n * stride || k <= 0.0 || stride == 0 {
        return;
    }
    let neighbours = Neighbours::build(mesh);
    let area = vertex_areas(mesh);
    let mixes = |u: usize, v: usize| mesh.normals[u].dot(mesh.normals[v]) >= CREASE_COS;
    filter_receivers(&neighbours, &area, mixes, total, layers, noise, stride, k);
}

/// The filter over any receivers: `neighbours` and `area` per receiver,
/// `mixes(u, v)` false where two neighbours must never be averaged.
#[allow(clippy::too_many_arguments)]
pub(crate) fn filter_receivers(
    neighbours: &Neighbours,
    area: &[f32],
    mixes: impl Fn(usize, usize) -> bool + Sync,
    total: &mut [f32],
    layers: &mut [Vec<f32>],
    noise: &mut Vec<f32>,
    stride: usize,
    k: f32,
) {
    let n = area.len();
    if noise.len() != n || total.len() != n * stride || k <= 0.0 || stride == 0 {
        return;
    }
    let inv_two_k2 = 1.0 / (2.0 * k * k);
    for _ in 0..PASSES {
        // Each vertex's (neighbour, weight) pairs, itself first, from this pass's inputs.
        let weights: Vec<Vec<(u32, f32)>> = (0..n)
            .into_par_iter()
            .with_min_len(PER_TASK)
            .map(|v| {
                let mut out = vec![(v as u32, area[v])];
                let dc_v = total[v * stride];
                let var_v = noise[v] * noise[v];
                for &u in neighbours.of(v) {
                    let u_index = u as usize;
                    if !mixes(u_index, v) {
                        continue;
                    }
                    let spread = var_v + noise[u_index] * noise[u_index];
                    let delta = total[u_index * stride] - dc_v;
                    let w = if spread > 0.0 {
                        (-(delta * delta) * inv_two_k2 / spread).exp()
                    } else if delta == 0.0 {
                        1.0
                    } else {
                        0.0
                    };
                    if w > 0.0 && area[u_index] > 0.0 {
                        out.push((u, w * area[u_index]));
                    }
                }
                out
            })
            .collect();
        let sums: Vec<f32> = weights.iter().map(|w| w.iter().map(|&(_, w)| w).sum()).collect();
        let filter = |values: &[f32]| -> Vec<f32> {
            let mut out = vec![0.0f32; values.len()];
            out.par_chunks_mut(stride * PER_TASK).enumerate().for_each(|(chunk, rows)| {
                for (local, row) in rows.chunks_exact_mut(stride).enumerate() {
                    let v = chunk * PER_TASK + local;
                    let sum = sums[v];
                    if sum <= 0.0 {
                        row.copy_from_slice(&values[v * stride..][..stride]);
                        continue;
                    }
                    for &(u, w) in &weights[v] {
                        let src = &values[u as usize * stride..][..stride];
                        row.iter_mut().zip(src).for_each(|(r, s)| *r += w * s);
                    }
                    row.iter_mut().for_each(|r| *r /= sum);
                }
            });
            out
        };
        let filtered = filter(total);
        total.copy_from_slice(&filtered);
        for layer in layers.iter_mut().filter(|l| l.len() == n * stride) {
            *layer = filter(layer);
        }
        let next_noise: Vec<f32> = (0..n)
            .into_par_iter()
            .with_min_len(PER_TASK)
            .map(|v| {
                let sum = sums[v];
                if sum <= 0.0 {
                    return noise[v];
                }
                weights[v].iter().map(|&(u, w)| (w * noise[u as usize]).powi(2)).sum::<f32>().sqrt() / sum
            })
            .collect();
        *noise = next_noise;
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::verify::shapes;

    /// Standard normal numbers, Box–Muller from a 64-bit LCG seeded with
    /// `seed`: fixed, so the denoiser tests (vertices and texels) are exact.
    pub(crate) fn gaussian_stream(mut state: u64) -> impl FnMut() -> f32 {
        move || {
            let mut uniform = || {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
            };
            let (a, b) = (uniform(), uniform());
            ((-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()) as f32
        }
    }

    /// A flat plane: 0.5 plus noise of known σ on the left half, 0 (a
    /// shadow) on the right. The filter lowers the noise on the lit half
    /// by more than 2x and leaves the shadow edge where it is: no vertex of
    /// the shadow half rises above 0.05, no lit vertex falls below 0.35.
    #[test]
    fn noise_falls_and_a_sharp_shadow_edge_stays_put() {
        let mesh = shapes::plane_grid(24, 1.0);
        let n = mesh.vertex_count();
        let sigma = 0.04f32;
        let mut gauss = gaussian_stream(12345);
        let lit = |v: usize| mesh.positions[v].x < 0.0;
        let clean: Vec<f32> = (0..n).map(|v| if lit(v) { 0.5 } else { 0.0 }).collect();
        let mut total: Vec<f32> = (0..n).map(|v| clean[v] + if lit(v) { sigma * gauss() } else { 0.0 }).collect();
        let mut noise: Vec<f32> = (0..n).map(|v| if lit(v) { sigma } else { 0.0 }).collect();
        let rms = |values: &[f32]| {
            let lit_vertices: Vec<usize> = (0..n).filter(|&v| lit(v) && mesh.positions[v].x < -0.1).collect();
            (lit_vertices.iter().map(|&v| (values[v] - clean[v]).powi(2)).sum::<f32>() / lit_vertices.len() as f32).sqrt()
        };
        let before = rms(&total);
        denoise(&mesh, &mut total, &mut [], &mut noise, 1, 2.0);
        let after = rms(&total);
        assert!(before > 0.03 && after < before / 2.0, "rms {before} → {after}");
        for v in 0..n {
            if lit(v) {
                assert!(total[v] > 0.35, "lit vertex {v} at {:?} fell to {}", mesh.positions[v], total[v]);
            } else {
                assert!(total[v] < 0.05, "shadowed vertex {v} at {:?} rose to {}", mesh.positions[v], total[v]);
            }
        }
        // The carried noise estimate fell with the values.
        let lit_noise: Vec<f32> = (0..n).filter(|&v| lit(v) && mesh.positions[v].x < -0.1).map(|v| noise[v]).collect();
        assert!(lit_noise.iter().all(|&s| s < sigma / 1.5), "{lit_noise:?}");
    }

    /// No noise measured, or zero strength: nothing moves.
    #[test]
    fn without_a_noise_estimate_nothing_moves() {
        let mesh = shapes::plane_grid(4, 1.0);
        let values: Vec<f32> = (0..mesh.vertex_count()).map(|v| v as f32).collect();
        let mut total = values.clone();
        denoise(&mesh, &mut total, &mut [], &mut Vec::new(), 1, 2.0);
        assert_eq!(total, values);
        let mut noise = vec![0.1; mesh.vertex_count()];
        denoise(&mesh, &mut total, &mut [], &mut noise, 1, 0.0);
        assert_eq!(total, values);
    }
}
