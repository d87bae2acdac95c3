//! Sums to values: each vertex's sums over its weight, the layer a bounce
//! stores and the rows the next bounce gathers from.

use rayon::prelude::*;

use std::sync::Arc;

use crate::bake::gather::RowBuffer;
use crate::bake::noise::Moments;
use crate::bake::texel_lookup::TexelLookup;

/// The previous bounce per vertex in line-aligned rows, what the next
/// bounce gathers from. After bounce 0 it is colourless (one row serves
/// every channel, a third of the bytes of its widened copy).
pub(crate) struct SourceRows {
    pub(crate) rows: RowBuffer,
    /// 1 after bounce 0, else the bake's channels.
    pub(crate) channels: usize,
    /// The row of each triangle corner, when the rows are per triangle
    /// corner (`--gather-fit`, [`super::fit`]); empty: the mesh's vertex indices.
    pub(crate) corner_indices: Vec<u32>,
    /// Texel mode: the previous bounce per texel, which hits on atlas
    /// triangles read instead of `rows`.
    pub(crate) texels: Option<TexelRows>,
    /// Window mode: `rows` holds each receiver's front side's rows, then
    /// every receiver's back side's ([`split_sides`]).
    pub(crate) sides: bool,
}

/// The previous bounce per covered texel, `channels` rows each as [`SourceRows`].
pub(crate) struct TexelRows {
    pub(crate) lookup: Arc<TexelLookup>,
    pub(crate) rows: RowBuffer,
    /// Split by side, as [`SourceRows::sides`].
    pub(crate) sides: bool,
}

impl TexelRows {
    /// Rows past which the texels' back sides lie (0 without the split).
    pub(crate) fn back_offset(&self, stride: usize) -> usize {
        if self.sides {
            self.rows.len() / (2 * stride).max(1)
        } else {
            0
        }
    }
}

impl SourceRows {
    pub(crate) fn empty() -> SourceRows {
        SourceRows { rows: RowBuffer::zeroed(0), channels: 1, corner_indices: Vec::new(), texels: None, sides: false }
    }

    /// Rows past which the receivers' back sides lie (0 without the split).
    pub(crate) fn back_offset(&self, stride: usize) -> usize {
        if self.sides {
            self.rows.len() / (2 * stride).max(1)
        } else {
            0
        }
    }
}

/// Window mode: a bounce's normalised rows (`stride` = `channels` ×
/// `coeffs` per receiver) split by side, what the next bounce gathers: a
/// hit on a face reads that side's light. Each receiver's back share is its
/// back-side DC (Σ w·b / Σ w of `moments` and `weights`) over the row's DC
/// (mean over channels), clamped to [0, 1]; returns every receiver's front
/// rows (the row × (1 − back share)), then every receiver's back rows.
pub(crate) fn split_sides(rows: &[f32], weights: &[f32], moments: &[Moments], channels: usize, coeffs: usize) -> RowBuffer {
    let stride = channels * coeffs;
    let receivers = rows.len() / stride.max(1);
    let mut out = RowBuffer::zeroed(2 * rows.len());
    let (front, back) = out.as_mut_slice().split_at_mut(rows.len());
    front.par_chunks_mut(stride).zip(back.par_chunks_mut(stride)).enumerate().for_each(|(r, (f, b))| {
        let row = &rows[r * stride..(r + 1) * stride];
        let dc = (0..channels).map(|c| f64::from(row[c * coeffs])).sum::<f64>() / channels as f64;
        let w = f64::from(weights.get(r).copied().unwrap_or(0.0));
        let back_dc = match moments.get(r) {
            Some(m) if w > 0.0 => m.wb / w,
            _ => 0.0,
        };
        let back_share = if dc > 0.0 { (back_dc / dc).clamp(0.0, 1.0) as f32 } else { 0.0 };
        for ((f, b), &x) in f.iter_mut().zip(b.iter_mut()).zip(row) {
            *b = back_share * x;
            *f = x - *b;
        }
    });
    debug_assert_eq!(receivers * 2 * stride, out.len());
    out
}

/// Adds `row` to `target`, element by element: the one place per-item sums
/// meet, so whole bakes and merged shards add in the same order.
#[inline]
pub(crate) fn add_row(target: &mut [f32], row: &[f32]) {
    target.iter_mut().zip(row).for_each(|(t, s)| *t += s);
}

/// (c) A bounce's layer: each vertex's sums over its weight, bounce 0
/// widened to all `channels`; zero where a vertex has no weight.
pub(crate) fn normalised_layer(sums: &[f32], weights: &[f32], pass_channels: usize, channels: usize, coeffs: usize) -> Vec<f32> {
    let stride = pass_channels * coeffs;
    let mut layer = vec![0.0f32; weights.len() * channels * coeffs];
    layer.par_chunks_mut(channels * coeffs).zip(sums.par_chunks(stride).zip(weights.par_iter())).for_each(|(dst, (src, &w))| {
        if w > 0.0 {
            for (c, dst) in dst.chunks_exact_mut(coeffs).enumerate() {
                let source_channel = if pass_channels == 1 { 0 } else { c };
                dst.iter_mut().zip(&src[source_channel * coeffs..][..coeffs]).for_each(|(d, s)| *d = s / w);
            }
        }
    });
    layer
}

/// (c) The next bounce's gather rows: the same quotients as
/// [`normalised_layer`], unwidened, into `source` (reusing its buffer).
pub(crate) fn normalise_source_into(source: &mut SourceRows, sums: &[f32], weights: &[f32], pass_channels: usize, coeffs: usize) {
    let stride = pass_channels * coeffs;
    if source.rows.len() != weights.len() * stride {
        source.rows = RowBuffer::zeroed(weights.len() * stride);
    }
    source.channels = pass_channels;
    source.corner_indices.clear();
    source.sides = false;
    normalise_rows(source.rows.as_mut_slice(), sums, weights, stride);
}

/// The next bounce's gather rows from a widened layer (its first
/// `pass_channels` channels: bounce 0's are copies of one).
pub(crate) fn source_from_layer(source: &mut SourceRows, layer: &[f32], pass_channels: usize, channels: usize, coeffs: usize) {
    let stride = pass_channels * coeffs;
    let vertices = layer.len() / (channels * coeffs).max(1);
    if source.rows.len() != vertices * stride {
        source.rows = RowBuffer::zeroed(vertices * stride);
    }
    source.channels = pass_channels;
    source.corner_indices.clear();
    source.sides = false;
    source
        .rows
        .as_mut_slice()
        .par_chunks_mut(stride)
        .zip(layer.par_chunks(channels * coeffs))
        .for_each(|(dst, src)| dst.copy_from_slice(&src[..stride]));
}

/// `dst` = each vertex's row of `sums` over its weight, zero where it has none.
pub(crate) fn normalise_rows(dst: &mut [f32], sums: &[f32], weights: &[f32], stride: usize) {
    dst.par_chunks_mut(stride).zip(sums.par_chunks(stride).zip(weights.par_iter())).for_each(|(dst, (src, &w))| {
        dst.iter_mut().zip(src).for_each(|(d, s)| *d = if w > 0.0 { s / w } else { 0.0 });
    });
}

/// Adds a bounce's layer to the running total (bounce order, as a whole bake).
pub(crate) fn add_layer(total: &mut [f32], layer: &[f32]) {
    total.iter_mut().zip(layer).for_each(|(t, l)| *t += l);
}
