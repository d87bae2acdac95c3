//! Transfer-layer quantization: f32, f16, and i16 with a per-vertex f32 scale.
//!
//! On-disk layer data (after the layer's 8-byte kind/reserved header), for V vertices
//! of S = channels·order² values each:
//! - F32: `f32 × V·S`.
//! - F16: `u16 (binary16) × V·S`, zero-padded to a multiple of 4 bytes.
//! - I16: `f32 scale × V`, then `i16 × V·S`, zero-padded to a multiple of 4 bytes.
//!
//! Error bounds (asserted in the tests; see [`Quantization`]):
//! - f16, round to nearest even: |v − v'| ≤ 2⁻¹¹·|v| for |v| ≥ 2⁻¹⁴ (normal range),
//!   ≤ 2⁻²⁵ below it (subnormal spacing 2⁻²⁴).
//! - i16: s = f32(max|v| / 32767), q = round(v / s) computed in f64; v' = f32(q·s) with
//!   q·s exact in f64, so |v − v'| ≤ s/2 + ulp_f32(v')/2.

use half::f16;

use super::cursor::{pad_to, put_f32, put_u16, Cursor};
use super::error::BundleError;
use super::types::Quantization;
use super::values::check_i16_scale;

/// Largest magnitude of an i16 code; −32768 is never written, so the range is symmetric.
const I16_MAX: f64 = 32767.0;

/// The per-vertex scale: `max |v| / 32767`, rounded to f32 (0 for an all-zero vertex).
pub fn i16_scale(values: &[f32]) -> f32 {
    let max_abs = values.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    (max_abs as f64 / I16_MAX) as f32
}

/// `round(v / scale)` clamped to ±32767; 0 when `scale` is 0.
pub fn quantize_i16(v: f32, scale: f32) -> i16 {
    if scale == 0.0 {
        return 0;
    }
    (v as f64 / scale as f64).round().clamp(-I16_MAX, I16_MAX) as i16
}

/// `q · scale`, exact in f64 and rounded once to f32.
pub fn dequantize_i16(q: i16, scale: f32) -> f32 {
    (q as f64 * scale as f64) as f32
}

/// The rank-one colour split of one vertex's `channels × n` values (see
/// [`Quantization::F16Tinted`]): tints `k_c = t_c0 / g_0` and the grey mean `g`,
/// before f16 rounding. Tints fall back to 1 where `g_0` is not positive or a
/// ratio is not finite or beyond f16.
pub fn tint_split(values: &[f32], channels: usize) -> (Vec<f32>, Vec<f32>) {
    let channels = channels.max(1);
    let n = values.len() / channels;
    let g: Vec<f32> = (0..n).map(|i| (0..channels).map(|c| values[c * n + i]).sum::<f32>() / channels as f32).collect();
    let tints = (0..channels)
        .map(|c| {
            let k = if n > 0 && g[0] > 0.0 { values[c * n] / g[0] } else { 1.0 };
            if k.is_finite() && k.abs() <= 65504.0 {
                k
            } else {
                1.0
            }
        })
        .collect();
    (tints, g)
}

/// What a reader gets back for `data` stored with `q` (`stride` values per
/// vertex, `channels` channels).
pub fn round_trip(data: &[f32], stride: usize, channels: usize, q: Quantization) -> Vec<f32> {
    let stride = stride.max(1);
    let h = |v: f32| f16::from_f32(v).to_f32();
    match q {
        Quantization::F32 => data.to_vec(),
        Quantization::F16 => data.iter().map(|&v| h(v)).collect(),
        Quantization::I16PerVertexScale => data
            .chunks(stride)
            .flat_map(|vertex| {
                let s = i16_scale(vertex);
                vertex.iter().map(move |&v| dequantize_i16(quantize_i16(v, s), s))
            })
            .collect(),
        Quantization::F16Tinted => data
            .chunks(stride)
            .flat_map(|vertex| {
                let (k, g) = tint_split(vertex, channels);
                k.into_iter().flat_map(move |k| g.clone().into_iter().map(move |g| h(k) * h(g)))
            })
            .collect(),
    }
}

/// Appends one layer's quantized data (V·stride values) in the layout above.
///
/// Precondition: `data.len()` is a multiple of `stride` (callers check), `stride ≥ 1`,
/// and of `channels` for [`Quantization::F16Tinted`].
pub(crate) fn encode_layer(data: &[f32], stride: usize, channels: usize, q: Quantization, out: &mut Vec<u8>) {
    match q {
        Quantization::F16Tinted => {
            for vertex in data.chunks(stride.max(1)) {
                let (k, g) = tint_split(vertex, channels);
                k.iter().chain(&g).for_each(|&v| put_u16(out, f16::from_f32(v).to_bits()));
            }
        }
        Quantization::F32 => data.iter().for_each(|&v| put_f32(out, v)),
        Quantization::F16 => data.iter().for_each(|&v| put_u16(out, f16::from_f32(v).to_bits())),
        Quantization::I16PerVertexScale => {
            let scales: Vec<f32> = data.chunks(stride.max(1)).map(i16_scale).collect();
            scales.iter().for_each(|&s| put_f32(out, s));
            for (values, &s) in data.chunks(stride.max(1)).zip(&scales) {
                values.iter().for_each(|&v| out.extend_from_slice(&quantize_i16(v, s).to_le_bytes()));
            }
        }
    }
    pad_to(out, 4);
}

/// Bytes one encoded layer occupies (with padding), or `None` on overflow.
pub(crate) fn layer_bytes(vertex_count: u64, stride: u64, channels: u64, q: Quantization) -> Option<u64> {
    let values = vertex_count.checked_mul(stride)?;
    let raw = match q {
        Quantization::F16Tinted => {
            let grey = if channels == 0 || stride % channels != 0 { return None } else { stride / channels };
            vertex_count.checked_mul(channels.checked_add(grey)?)?.checked_mul(2)?
        }
        Quantization::F32 => values.checked_mul(4)?,
        Quantization::F16 => values.checked_mul(2)?,
        Quantization::I16PerVertexScale => vertex_count.checked_mul(4)?.checked_add(values.checked_mul(2)?)?,
    };
    raw.checked_add(3).map(|n| n / 4 * 4)
}

/// Reads layer number `layer`, written by [`encode_layer`], and dequantizes it.
/// Refuses i16 scales out of range and the i16 code −32768; the caller checks
/// that the values are finite (`values::check_layer`).
pub(crate) fn decode_layer(
    cur: &mut Cursor,
    vertex_count: u64,
    stride: u64,
    channels: u64,
    q: Quantization,
    layer: usize,
) -> Result<Vec<f32>, BundleError> {
    let values = vertex_count.checked_mul(stride).ok_or_else(|| cur.error("transfer size overflows"))?;
    let data = match q {
        Quantization::F16Tinted => {
            // layer_bytes already checked the length and that channels divides stride.
            let (c, n) = (channels as usize, (stride / channels.max(1)) as usize);
            let words = cur.u16s(vertex_count * (channels + stride / channels.max(1)), "tinted f16 transfer values")?;
            let h = |b: u16| f16::from_bits(b).to_f32();
            let mut out = Vec::with_capacity(values as usize);
            for vertex in words.chunks_exact(c + n) {
                let (k, g) = vertex.split_at(c);
                for &k in k {
                    out.extend(g.iter().map(|&g| h(k) * h(g)));
                }
            }
            out
        }
        Quantization::F32 => cur.f32s(values, "f32 transfer values")?,
        Quantization::F16 => cur.u16s(values, "f16 transfer values")?.into_iter().map(|b| f16::from_bits(b).to_f32()).collect(),
        Quantization::I16PerVertexScale => {
            let scales = cur.f32s(vertex_count, "i16 per-vertex scales")?;
            let codes = cur.u16s(values, "i16 transfer values")?;
            if codes.iter().any(|&c| c as i16 == i16::MIN) {
                return Err(cur.error("i16 code -32768 is reserved"));
            }
            for (v, (&scale, vertex_codes)) in scales.iter().zip(codes.chunks(stride.max(1) as usize)).enumerate() {
                check_i16_scale(layer, v, scale, vertex_codes).map_err(BundleError::bad_value(cur.tag()))?;
            }
            let per_vertex_scale = scales.iter().flat_map(|&s| std::iter::repeat(s).take(stride as usize));
            codes.iter().zip(per_vertex_scale).map(|(&c, s)| dequantize_i16(c as i16, s)).collect()
        }
    };
    cur.padding(4, "transfer layer")?;
    Ok(data)
}

/// What `q` does to `data`: `(max_abs, rms)` of `v − dequantize(quantize(v))`, in f64.
///
/// `channels · order²` values form one vertex (the i16 scale's scope); a trailing
/// partial vertex gets its own scale. Non-finite data gives non-finite errors.
/// Record the result in the bundle's META (the encoder does not).
pub fn quantization_error(data: &[f32], channels: u32, order: u32, q: Quantization) -> (f64, f64) {
    let stride = (channels as usize).saturating_mul((order as usize).saturating_mul(order as usize)).max(1);
    let mut max_abs = 0.0f64;
    let mut sum_sq = 0.0f64;
    for values in data.chunks(stride) {
        let back = round_trip(values, stride, channels as usize, q);
        for (&v, &back) in values.iter().zip(&back) {
            let err = (v as f64 - back as f64).abs();
            max_abs = if err.is_nan() { f64::NAN } else { max_abs.max(err) };
            sum_sq += err * err;
        }
    }
    let rms = if data.is_empty() { 0.0 } else { (sum_sq / data.len() as f64).sqrt() };
    (max_abs, rms)
}

/// The most compact quantization whose measured max error is within `max_abs_budget`:
/// f16 (2 bytes/value), then i16 (2 bytes/value + 4 bytes/vertex), else f32.
/// Returns it with its measured `(max_abs, rms)`.
pub fn choose_quantization(data: &[f32], channels: u32, order: u32, max_abs_budget: f64) -> (Quantization, f64, f64) {
    for q in [Quantization::F16, Quantization::I16PerVertexScale] {
        let (max_abs, rms) = quantization_error(data, channels, order, q);
        if max_abs <= max_abs_budget {
            return (q, max_abs, rms);
        }
    }
    (Quantization::F32, 0.0, 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic pseudo-random values spanning several decades, both signs.
    fn spread_values(n: usize) -> Vec<f32> {
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        (0..n)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                let unit = (x >> 11) as f64 / (1u64 << 53) as f64;
                let exponent = ((x >> 3) % 9) as i32 - 6; // 1e-6 .. 1e2
                ((unit * 2.0 - 1.0) * 10f64.powi(exponent)) as f32
            })
            .collect()
    }

    fn half_ulp(v: f32) -> f64 {
        let a = v.abs();
        ((f32::from_bits(a.to_bits() + 1) - a) as f64) / 2.0
    }

    #[test]
    fn f16_error_is_within_relative_bound() {
        for v in spread_values(20_000) {
            let back = f16::from_f32(v).to_f32();
            let err = (v as f64 - back as f64).abs();
            let bound = (v.abs() as f64 * 2f64.powi(-11)).max(2f64.powi(-25));
            assert!(err <= bound, "v={v} back={back} err={err} bound={bound}");
        }
    }

    #[test]
    fn i16_error_is_within_half_a_step() {
        let data = spread_values(9 * 3 * 500);
        for values in data.chunks(27) {
            let s = i16_scale(values);
            for &v in values {
                let back = dequantize_i16(quantize_i16(v, s), s);
                let err = (v as f64 - back as f64).abs();
                assert!(err <= s as f64 / 2.0 + half_ulp(back), "v={v} s={s} err={err}");
            }
            // The largest value uses the full code range.
            let max = values.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            let peak = values.iter().find(|v| v.abs() == max).unwrap();
            assert_eq!(quantize_i16(*peak, s).unsigned_abs(), 32767);
        }
    }

    #[test]
    fn quantization_error_matches_codec_round_trip() {
        // 40 vertices of 3 channels × order 2; positive DC so tints are meaningful.
        let mut data = spread_values(12 * 40);
        data.chunks_mut(4).for_each(|c| c[0] = c[0].abs() + 0.5);
        for q in [Quantization::F32, Quantization::F16, Quantization::I16PerVertexScale, Quantization::F16Tinted] {
            let mut bytes = Vec::new();
            encode_layer(&data, 12, 3, q, &mut bytes);
            assert_eq!(bytes.len() as u64, layer_bytes(40, 12, 3, q).unwrap());
            let back = decode_layer(&mut Cursor::new(&bytes, *b"XFER"), 40, 12, 3, q, 0).unwrap();
            assert_eq!(back, round_trip(&data, 12, 3, q), "{q:?}");
            let measured = data.iter().zip(&back).map(|(a, b)| (*a as f64 - *b as f64).abs()).fold(0.0, f64::max);
            let (max_abs, rms) = quantization_error(&data, 3, 2, q);
            assert_eq!(max_abs, measured, "{q:?}");
            assert!(rms <= max_abs);
            if q == Quantization::F32 {
                assert_eq!(back, data);
            }
        }
    }

    /// A vertex whose channels differ only by scale survives the tint exactly (to f16).
    #[test]
    fn tint_is_exact_for_scaled_channels() {
        let g = [0.3f32, -0.1, 0.05, 0.02];
        let data: Vec<f32> = [1.0f32, 0.5, 0.25].iter().flat_map(|k| g.iter().map(move |x| k * x)).collect();
        let back = round_trip(&data, 12, 3, Quantization::F16Tinted);
        for (a, b) in data.iter().zip(&back) {
            assert!((a - b).abs() <= 2e-3 * a.abs().max(1e-3), "{a} vs {b}");
        }
        let (k, _) = tint_split(&[0.0; 12], 3);
        assert_eq!(k, vec![1.0; 3]);
    }

    #[test]
    fn all_zero_vertex_quantizes_to_zero_scale() {
        assert_eq!(i16_scale(&[0.0; 9]), 0.0);
        assert_eq!(quantize_i16(0.0, 0.0), 0);
        assert_eq!(quantization_error(&[0.0; 9], 1, 3, Quantization::I16PerVertexScale), (0.0, 0.0));
    }

    #[test]
    fn choose_quantization_prefers_f16_then_i16() {
        let data = spread_values(9 * 100);
        let (f16_err, _) = quantization_error(&data, 1, 3, Quantization::F16);
        let (i16_err, _) = quantization_error(&data, 1, 3, Quantization::I16PerVertexScale);
        assert_eq!(choose_quantization(&data, 1, 3, f16_err).0, Quantization::F16);
        if i16_err < f16_err {
            assert_eq!(choose_quantization(&data, 1, 3, i16_err).0, Quantization::I16PerVertexScale);
        }
        assert_eq!(choose_quantization(&data, 1, 3, 0.0).0, Quantization::F32);
    }
}
