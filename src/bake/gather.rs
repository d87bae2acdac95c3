//! Bounces ≥ 1 from bounce 0's hit records: a point's estimate is
//! Σ_rays w · ρ(h) · t⁽ᵇ⁻¹⁾(h), with t⁽ᵇ⁻¹⁾(h) interpolated from the hit
//! triangle's corner rows (DESIGN.md "Transfer"; seed 000 §4.1, eq. 6).
//!
//! No ray is traced here, so this is all memory and arithmetic: per record a
//! triangle's corners and albedo, then three corner rows. The rows live in a
//! line-aligned buffer on huge pages ([`RowBuffer`]; random reads of tens of
//! MB would otherwise miss the TLB too), and both dependent reads are
//! prefetched well ahead. For orders 1–5 a point's sums stay in registers
//! over its records, and the kernel runs with AVX2 where the CPU has it. AVX2
//! without FMA rounds as the scalar code does, so the bytes never depend on
//! the CPU or the order path.

use crate::bake::texel_lookup::TexelLookup;
use crate::trace::bvh8::prefetch_bytes;

/// How many records ahead the gather asks for a record's triangle (corner
/// indices, albedo) and, once those have arrived, its corner rows. Both are
/// random reads, and they were ~60% of the gather's time in the demo (perf).
const AHEAD_TRIANGLE: usize = 16;
const AHEAD_ROWS: usize = 8;

/// A cached ray result: no light comes back along this ray in bounces ≥ 1.
pub(crate) const NO_HIT: u64 = u64::MAX;

/// Set in a window-mode record whose ray left its point through the back of
/// the point's face: the gather keeps that side's light apart
/// (`bake::side_share`).
pub(crate) const BACK_SIDE: u64 = 1 << 63;

/// Set in a window-mode record whose ray met the back face of the hit
/// triangle: the gather reads the light of that side of it. Triangle
/// indices stay below 2³⁰ (`check_triangle_count`).
pub(crate) const HIT_BACK: u64 = 1 << 62;

/// Triangles a record can name.
pub(crate) const MAX_RECORD_TRIANGLES: u64 = 1 << 30;

/// Packs a hit on `triangle` at barycentrics (u, v) into one word (16-bit barycentrics).
#[inline]
pub(crate) fn encode_hit(triangle: u32, u: f32, v: f32) -> u64 {
    let q = |x: f32| (x.clamp(0.0, 1.0) * 65535.0).round() as u64;
    (triangle as u64) << 32 | q(u) << 16 | q(v)
}

#[inline(always)]
pub(crate) fn decode_hit(record: u64) -> (usize, f32, f32) {
    let q = |x: u64| (x & 0xffff) as f32 / 65535.0;
    (((record & !(BACK_SIDE | HIT_BACK)) >> 32) as usize, q(record >> 16), q(record))
}

/// Whether a record's ray met the back face of the triangle it hit.
#[inline(always)]
pub(crate) fn hit_back(record: u64) -> bool {
    record & HIT_BACK != 0
}

/// 1 for a record of a ray that left through the back of its point's face, else 0.
#[inline(always)]
pub(crate) fn back_side(record: u64) -> f32 {
    (record >> 63) as f32
}

/// One cache line of floats.
#[derive(Clone, Copy, Default)]
#[repr(C, align(64))]
struct Line([f32; 16]);

/// Per-vertex rows `[vertex][channel][coeff]` in a 64-byte-aligned buffer on huge pages.
pub(crate) struct RowBuffer {
    lines: Vec<Line>,
    len: usize,
}

impl RowBuffer {
    pub(crate) fn zeroed(len: usize) -> RowBuffer {
        // Rows are read at random: huge pages spare most of those reads a TLB miss.
        RowBuffer { lines: crate::trace::hugepages::filled_huge(len.div_ceil(16)), len }
    }
    pub(crate) fn len(&self) -> usize {
        self.len
    }
    pub(crate) fn as_slice(&self) -> &[f32] {
        // SAFETY: `Line` is `repr(C)` around `[f32; 16]` with no padding (64
        // bytes, align 64), so the lines are `16 · lines.len() ≥ len` floats.
        unsafe { std::slice::from_raw_parts(self.lines.as_ptr().cast::<f32>(), self.len) }
    }
    pub(crate) fn as_mut_slice(&mut self) -> &mut [f32] {
        // SAFETY: as in `as_slice`, and `&mut self` makes the borrow unique.
        unsafe { std::slice::from_raw_parts_mut(self.lines.as_mut_ptr().cast::<f32>(), self.len) }
    }
}

/// What a bounce gathers from.
pub(crate) struct Gather<'a> {
    /// Per triangle, the three receivers a hit reads (`Receivers::hit_table`).
    indices: &'a [u32],
    /// Per-channel albedo per triangle.
    albedo: &'a [[f32; 3]],
    /// The previous bounce per receiver, `[receiver][source channel][coeff]`.
    rows: &'a [f32],
    coeffs: usize,
    /// Channels of `rows`: 1 when every output channel reads the same row
    /// (bounce 0's colourless transfer), else `channels`.
    source_channels: usize,
    /// Channels of the result.
    channels: usize,
    /// Whether the AVX2 kernel may run: private, and set only from the CPU's
    /// report, since running it without AVX2 is undefined behaviour.
    avx2: bool,
    /// Texel mode: the previous bounce per texel, read bilinearly at a hit
    /// on an atlas triangle ([`Gather::with_texels`]); `rows` then serve the
    /// rest (back sides, triangles outside the atlas).
    texels: Option<(&'a TexelLookup, &'a [f32])>,
    /// Window mode with the sides split ([`Gather::with_sides`]): the rows
    /// (receivers) past which each receiver's back side's rows lie, read by
    /// a hit on a back face; 0: both faces read the same rows.
    back_offset: usize,
    texel_back_offset: usize,
}

impl<'a> Gather<'a> {
    /// A gather of `channels` channels from `rows` (`source_channels` per
    /// vertex), on the AVX2 kernel when this CPU has it.
    pub(crate) fn new(
        indices: &'a [u32],
        albedo: &'a [[f32; 3]],
        rows: &'a [f32],
        coeffs: usize,
        source_channels: usize,
        channels: usize,
    ) -> Gather<'a> {
        Gather {
            indices,
            albedo,
            rows,
            coeffs,
            source_channels,
            channels,
            avx2: crate::trace::bvh8::avx2_available(),
            texels: None,
            back_offset: 0,
            texel_back_offset: 0,
        }
    }

    /// Reads hits on atlas triangles from `rows` per texel of `lookup`
    /// (`source_channels` per texel, as the vertex rows).
    pub(crate) fn with_texels(self, lookup: &'a TexelLookup, rows: &'a [f32]) -> Gather<'a> {
        Gather { texels: Some((lookup, rows)), ..self }
    }

    /// Rows split by side ([`crate::bake::transfer::split_sides`]): a hit on
    /// a back face reads the receiver's row `back_offset` rows on (texels:
    /// `texel_back_offset`); 0 reads the same row from either face.
    pub(crate) fn with_sides(self, back_offset: usize, texel_back_offset: usize) -> Gather<'a> {
        Gather { back_offset, texel_back_offset, ..self }
    }
}

impl Gather<'_> {
    /// Adds `weight · ρ(h) · t⁽ᵇ⁻¹⁾(h)` over the first `count` records of
    /// `records` into `result` (`[channel][coeff]`), in record order. Records
    /// after `count` (the next points') are only prefetched. Returns the DC
    /// summed over channels that the records marked [`BACK_SIDE`] added.
    pub(crate) fn point(&self, records: &[u64], count: usize, weight: f32, result: &mut [f32]) -> f32 {
        if self.texels.is_some() {
            return self.general(records, count, weight, result);
        }
        let mono = self.source_channels == 1;
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: `avx2` is set only when the CPU reported AVX2.
            return unsafe { self.point_avx2(records, count, weight, result, mono) };
        }
        self.dispatch(records, count, weight, result, mono)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn point_avx2(&self, records: &[u64], count: usize, weight: f32, result: &mut [f32], mono: bool) -> f32 {
        self.dispatch(records, count, weight, result, mono)
    }

    /// Picks a kernel whose sums fit in registers, or the general one.
    #[inline(always)]
    fn dispatch(&self, records: &[u64], count: usize, weight: f32, result: &mut [f32], mono: bool) -> f32 {
        macro_rules! fixed {
            ($n:literal) => {
                match (self.channels, mono) {
                    (1, _) => self.fixed::<$n, 1, true>(records, count, weight, result),
                    (3, true) => self.fixed::<$n, 3, true>(records, count, weight, result),
                    (3, false) => self.fixed::<$n, 3, false>(records, count, weight, result),
                    _ => self.general(records, count, weight, result),
                }
            };
        }
        match self.coeffs {
            1 => fixed!(1),
            4 => fixed!(4),
            9 => fixed!(9),
            16 => fixed!(16),
            25 => fixed!(25),
            _ => self.general(records, count, weight, result),
        }
    }

    /// Asks for the corner indices and albedo of a record's triangle, and
    /// for the corner rows of a record further on, whose triangle was asked
    /// for `AHEAD_TRIANGLE - AHEAD_ROWS` records ago. Reading texels, it asks
    /// for the triangle's atlas corners instead (the texels themselves
    /// depend on the hit point), and no corner rows.
    #[inline(always)]
    fn prefetch(&self, records: &[u64], i: usize) {
        if let Some(&ahead) = records.get(i + AHEAD_TRIANGLE).filter(|&&r| r != NO_HIT) {
            let triangle = decode_hit(ahead).0;
            prefetch_bytes(self.albedo.as_ptr().wrapping_add(triangle), 12);
            match self.texels {
                Some((lookup, _)) => lookup.prefetch(triangle),
                None => prefetch_bytes(self.indices.as_ptr().wrapping_add(3 * triangle), 12),
            }
        }
        if self.texels.is_some() {
            return;
        }
        if let Some(&ahead) = records.get(i + AHEAD_ROWS).filter(|&&r| r != NO_HIT) {
            let stride = self.source_channels * self.coeffs;
            let triangle = decode_hit(ahead).0;
            let offset = self.row_offset(hit_back(ahead));
            for &vertex in &self.indices[3 * triangle..3 * triangle + 3] {
                prefetch_bytes(self.rows.as_ptr().wrapping_add((vertex as usize + offset) * stride), stride * 4);
            }
        }
    }

    /// The rows a hit on a back face (`back`) or a front face reads from.
    #[inline(always)]
    fn row_offset(&self, back: bool) -> usize {
        if back {
            self.back_offset
        } else {
            0
        }
    }

    /// A hit's corner rows (those of the side hit), barycentric weights and albedo.
    #[inline(always)]
    fn corners(&self, triangle: usize, u: f32, v: f32, back: bool) -> ([&[f32]; 3], [f32; 3], [f32; 3]) {
        let stride = self.source_channels * self.coeffs;
        let offset = self.row_offset(back);
        let corner = |k: usize| &self.rows[(self.indices[3 * triangle + k] as usize + offset) * stride..][..stride];
        ([corner(0), corner(1), corner(2)], [1.0 - u - v, u, v], self.albedo[triangle])
    }

    /// `N` coefficients, `CH` channels, `MONO`: one source row for every
    /// channel. The sums stay in registers over the point's records.
    #[inline(always)]
    fn fixed<const N: usize, const CH: usize, const MONO: bool>(
        &self,
        records: &[u64],
        count: usize,
        weight: f32,
        result: &mut [f32],
    ) -> f32 {
        let mut sums = [[0.0f32; N]; CH];
        let mut back = 0.0f32;
        for (c, sum) in sums.iter_mut().enumerate() {
            sum.copy_from_slice(&result[c * N..(c + 1) * N]);
        }
        for i in 0..count {
            self.prefetch(records, i);
            let record = records[i];
            if record == NO_HIT {
                continue;
            }
            let (triangle, u, v) = decode_hit(record);
            let ([s0, s1, s2], [b0, b1, b2], albedo) = self.corners(triangle, u, v, hit_back(record));
            if MONO {
                let (x0, x1, x2) = (&s0[..N], &s1[..N], &s2[..N]);
                let mut blend = [0.0f32; N];
                for k in 0..N {
                    blend[k] = b0 * x0[k] + b1 * x1[k] + b2 * x2[k];
                }
                let mut dc = 0.0f32;
                for (c, sum) in sums.iter_mut().enumerate() {
                    let w = weight * albedo[c];
                    for k in 0..N {
                        sum[k] += w * blend[k];
                    }
                    dc += w * blend[0];
                }
                back += back_side(record) * dc;
            } else {
                let mut dc = 0.0f32;
                for (c, sum) in sums.iter_mut().enumerate() {
                    let w = weight * albedo[c];
                    let span = c * N..(c + 1) * N;
                    let (x0, x1, x2) = (&s0[span.clone()], &s1[span.clone()], &s2[span]);
                    for k in 0..N {
                        sum[k] += w * (b0 * x0[k] + b1 * x1[k] + b2 * x2[k]);
                    }
                    dc += w * (b0 * x0[0] + b1 * x1[0] + b2 * x2[0]);
                }
                back += back_side(record) * dc;
            }
        }
        for (c, sum) in sums.iter().enumerate() {
            result[c * N..(c + 1) * N].copy_from_slice(sum);
        }
        back
    }

    /// Any order and channel count, summing in `result`. Same operations in
    /// the same order as [`Gather::fixed`], so the same bits.
    #[inline(always)]
    fn general(&self, records: &[u64], count: usize, weight: f32, result: &mut [f32]) -> f32 {
        let mut back = 0.0f32;
        for i in 0..count {
            self.prefetch(records, i);
            let record = records[i];
            if record != NO_HIT {
                let (triangle, u, v) = decode_hit(record);
                back += back_side(record) * self.add_hit(triangle, u, v, hit_back(record), weight, result);
            }
        }
        back
    }

    /// Adds `weight · ρ(h) · t⁽ᵇ⁻¹⁾(h)` for one hit at barycentrics (u, v) of
    /// `triangle`, on its back face when `back`; returns the DC it added,
    /// summed over channels (the fixed kernels' operations, so the same bits).
    #[inline]
    pub(crate) fn add_hit(&self, triangle: usize, u: f32, v: f32, back: bool, weight: f32, result: &mut [f32]) -> f32 {
        let n = self.coeffs;
        if let Some((lookup, rows)) = self.texels {
            if let Some((ids, texel_weights)) = lookup.bilinear(triangle, u, v) {
                let stride = self.source_channels * n;
                let offset = if back { self.texel_back_offset } else { 0 };
                let mut dc = 0.0f32;
                for (c, &reflect) in self.albedo[triangle].iter().enumerate().take(self.channels) {
                    let source = if self.source_channels == 1 { 0..n } else { c * n..(c + 1) * n };
                    for (&id, &share) in ids.iter().zip(&texel_weights) {
                        if share > 0.0 {
                            let w = weight * reflect * share;
                            let row = &rows[(id as usize + offset) * stride..][source.clone()];
                            result[c * n..(c + 1) * n].iter_mut().zip(row).for_each(|(d, x)| *d += w * x);
                            dc += w * row[0];
                        }
                    }
                }
                return dc;
            }
        }
        let ([s0, s1, s2], [b0, b1, b2], albedo) = self.corners(triangle, u, v, back);
        let mut dc = 0.0f32;
        for (c, &reflect) in albedo.iter().enumerate().take(self.channels) {
            let w = weight * reflect;
            let source = if self.source_channels == 1 { 0..n } else { c * n..(c + 1) * n };
            let (x0, x1, x2) = (&s0[source.clone()], &s1[source.clone()], &s2[source]);
            for (k, d) in result[c * n..(c + 1) * n].iter_mut().enumerate() {
                *d += w * (b0 * x0[k] + b1 * x1[k] + b2 * x2[k]);
            }
            dc += w * (b0 * x0[0] + b1 * x1[0] + b2 * x2[0]);
        }
        dc
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small random mesh's worth of gather inputs.
    struct Fixture {
        indices: Vec<u32>,
        albedo: Vec<[f32; 3]>,
        rows: RowBuffer,
        records: Vec<u64>,
    }

    fn fixture(coeffs: usize, source_channels: usize, seed: u64) -> Fixture {
        let mut state = seed;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 33) as u32
        };
        let (vertices, triangles) = (50u32, 40usize);
        let indices = (0..3 * triangles).map(|_| next() % vertices).collect();
        let albedo = (0..triangles).map(|_| [0, 1, 2].map(|_| (next() % 1000) as f32 / 1000.0)).collect();
        // Front rows, then back rows (the sides split, `Gather::with_sides`).
        let mut rows = RowBuffer::zeroed(2 * vertices as usize * source_channels * coeffs);
        rows.as_mut_slice().iter_mut().for_each(|x| *x = (next() % 20001) as f32 / 10000.0 - 1.0);
        let records = (0..300)
            .map(|_| {
                let (u, v) = ((next() % 1000) as f32 / 2000.0, (next() % 1000) as f32 / 2000.0);
                if next() % 5 == 0 {
                    NO_HIT
                } else {
                    let side = if next() % 3 == 0 { BACK_SIDE } else { 0 };
                    let face = if next() % 4 == 0 { HIT_BACK } else { 0 };
                    encode_hit(next() % triangles as u32, u, v) | side | face
                }
            })
            .collect();
        Fixture { indices, albedo, rows, records }
    }

    /// The plain formula, record by record, in f64 (the oracle): the sums,
    /// and the DC over channels of the records marked back side.
    fn expected(f: &Fixture, g: &Gather, count: usize, weight: f32) -> (Vec<f64>, f64) {
        let n = g.coeffs;
        let mut out = vec![0.0f64; g.channels * n];
        let mut back = 0.0f64;
        let vertices = f.rows.len() / (2 * g.source_channels * n);
        for &record in f.records.iter().take(count).filter(|&&r| r != NO_HIT) {
            let (t, u, v) = decode_hit(record);
            let b = [1.0 - u - v, u, v];
            let offset = if hit_back(record) { vertices } else { 0 };
            for c in 0..g.channels {
                let source = if g.source_channels == 1 { 0 } else { c };
                for k in 0..n {
                    let value: f64 = (0..3)
                        .map(|j| {
                            b[j] as f64
                                * f.rows.as_slice()[(f.indices[3 * t + j] as usize + offset) * g.source_channels * n + source * n + k]
                                    as f64
                        })
                        .sum();
                    out[c * n + k] += (weight * f.albedo[t][c]) as f64 * value;
                    if k == 0 && record & BACK_SIDE != 0 {
                        back += (weight * f.albedo[t][c]) as f64 * value;
                    }
                }
            }
        }
        (out, back)
    }

    #[test]
    fn kernels_match_the_formula_and_each_other_bit_for_bit() {
        for coeffs in [1, 4, 9, 16, 25, 36] {
            for (channels, source_channels) in [(1, 1), (3, 1), (3, 3)] {
                let f = fixture(coeffs, source_channels, (coeffs * 10 + channels + source_channels) as u64);
                let mut outputs = Vec::new();
                for avx2 in [false, crate::trace::bvh8::avx2_available()] {
                    let vertices = f.rows.len() / (2 * source_channels * coeffs);
                    let g = Gather { avx2, ..Gather::new(&f.indices, &f.albedo, f.rows.as_slice(), coeffs, source_channels, channels) }
                        .with_sides(vertices, 0);
                    let count = 64;
                    let weight = 2.0 / 64.0;
                    // Fixed kernel (orders 1-5) or general, then the general one on its own.
                    let mut fast = vec![0.0f32; channels * coeffs];
                    let fast_back = g.point(&f.records, count, weight, &mut fast);
                    let mut general = vec![0.0f32; channels * coeffs];
                    let general_back = g.general(&f.records, count, weight, &mut general);
                    assert_eq!(
                        fast.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                        general.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
                    );
                    assert_eq!(fast_back.to_bits(), general_back.to_bits());
                    let (oracle, oracle_back) = expected(&f, &g, count, weight);
                    for (got, want) in fast.iter().zip(&oracle) {
                        assert!(
                            (*got as f64 - want).abs() <= 1e-5 * (1.0 + want.abs()),
                            "{coeffs} coeffs, {channels}/{source_channels}: {got} vs {want}"
                        );
                    }
                    assert!(oracle_back.abs() > 1e-3, "the fixture marks some hits back side");
                    assert!((fast_back as f64 - oracle_back).abs() <= 1e-5 * (1.0 + oracle_back.abs()), "{fast_back} vs {oracle_back}");
                    outputs.push((fast.iter().map(|x| x.to_bits()).collect::<Vec<_>>(), fast_back.to_bits()));
                }
                assert_eq!(outputs[0], outputs[1], "AVX2 and scalar kernels differ");
            }
        }
    }

    #[test]
    fn rows_are_line_aligned_and_hits_round_trip() {
        let rows = RowBuffer::zeroed(100);
        assert_eq!(rows.as_slice().as_ptr() as usize % 64, 0);
        assert_eq!(rows.as_slice().len(), 100);
        let (t, u, v) = decode_hit(encode_hit(123_456, 0.25, 0.5));
        assert_eq!(t, 123_456);
        assert_eq!(decode_hit(encode_hit(123_456, 0.25, 0.5) | BACK_SIDE).0, 123_456);
        assert_eq!((back_side(encode_hit(7, 0.0, 0.0)), back_side(encode_hit(7, 0.0, 0.0) | BACK_SIDE)), (0.0, 1.0));
        assert!((u - 0.25).abs() < 1.0 / 65535.0 && (v - 0.5).abs() < 1.0 / 65535.0);
    }
}
