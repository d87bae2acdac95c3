//! "No more data than a scene needs": the storage of a baked transfer (SH
//! order, colour channels, quantization) chosen from an error budget and
//! measured, so a bundle records what it dropped and what that cost.
//!
//! **Error in shaded radiance.** For a transfer `t` (per vertex, channel,
//! coefficient) and a lighting `L` (RGB SH), the shaded radiance per unit
//! albedo is `R_vc = Σ_i L_ic · t_vc'i` (c' = c for 3 channels, 0 for one).
//! A storage choice gives `R'`; its error under `L` is the relative RMS
//! `sqrt(Σ_vc (R'−R)²) / sqrt(Σ_vc R²)` over every vertex and colour channel.
//! The reported error is the worst over [`reference_lightings`]: clear
//! Preetham skies (sun disc excluded, black ground) at three elevations and
//! four azimuths, so a reduction that only holds for one sky does not pass.
//! The reference is the baked transfer itself (sampling noise is not counted).

use glam::Vec3;
use rayon::prelude::*;

use super::quantize;
use super::types::Quantization;
use crate::sh;

/// A lighting to measure shaded error under: RGB SH, `order²` entries.
#[derive(Clone, Debug)]
pub struct Lighting {
    pub name: String,
    pub sh: Vec<[f32; 3]>,
}

/// Clear skies at sun elevations 10°, 35° and 65° and azimuths 0°, 90°,
/// 180°, 270° (world +Y up), projected to `order` (Preetham, turbidity 3).
pub fn reference_lightings(order: usize) -> Vec<Lighting> {
    let mut out = Vec::new();
    for (k, elevation) in [10.0f32, 35.0, 65.0].into_iter().enumerate() {
        let azimuth = 90.0 * k as f32 + 30.0;
        for turn in 0..4 {
            let a = (azimuth + 90.0 * turn as f32).to_radians();
            let e = elevation.to_radians();
            let sun = Vec3::new(e.cos() * a.sin(), e.sin(), -e.cos() * a.cos());
            let sky = crate::sky::preetham_sky(sun, Vec3::Y, 3.0, order);
            out.push(Lighting {
                name: format!("sky elevation {elevation}° azimuth {:.0}°", (azimuth + 90.0 * turn as f32) % 360.0),
                sh: sky.sky_sh,
            });
        }
    }
    out
}

/// Shaded radiance per unit albedo of every vertex and colour channel
/// (`[vertex][rgb]`) of a transfer with `channels` (1 or 3) and `order`.
/// Bands of `light` beyond `order` are ignored (they meet zero transfer).
pub fn shade(transfer: &[f32], order: usize, channels: usize, light: &[[f32; 3]]) -> Vec<[f64; 3]> {
    let n = sh::coeff_count(order);
    let stride = channels * n;
    transfer
        .chunks_exact(stride.max(1))
        .map(|v| {
            let mut rgb = [0.0f64; 3];
            for (c, out) in rgb.iter_mut().enumerate() {
                let t = &v[if channels == 1 { 0 } else { c * n }..][..n];
                *out = t.iter().zip(light).map(|(&t, l)| t as f64 * l[c] as f64).sum();
            }
            rgb
        })
        .collect()
}

/// Relative RMS difference of two shadings (see the module doc); 0 when both are zero.
pub fn relative_rms(reference: &[[f64; 3]], other: &[[f64; 3]]) -> f64 {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (a, b) in reference.iter().zip(other) {
        for c in 0..3 {
            num += (b[c] - a[c]).powi(2);
            den += a[c] * a[c];
        }
    }
    if den == 0.0 {
        if num == 0.0 {
            0.0
        } else {
            f64::INFINITY
        }
    } else {
        (num / den).sqrt()
    }
}

/// How a transfer is stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Storage {
    pub order: usize,
    pub channels: usize,
    #[serde(serialize_with = "quantization_name")]
    pub quantization: Quantization,
}

fn quantization_name<S: serde::Serializer>(q: &Quantization, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(q.name())
}

/// Bytes one vertex of one stored layer takes (i16 includes its per-vertex scale;
/// the 4-byte padding of a whole layer is not counted).
pub fn bytes_per_vertex(s: &Storage) -> usize {
    let values = s.channels * s.order * s.order;
    match s.quantization {
        Quantization::F32 => 4 * values,
        Quantization::F16 => 2 * values,
        Quantization::I16PerVertexScale => 4 + 2 * values,
        Quantization::F16Tinted => 2 * (s.channels + s.order * s.order),
    }
}

/// Turns a transfer of `(order, channels)` into the values `storage` keeps:
/// bands ≥ `storage.order` dropped, channels averaged to one when
/// `storage.channels == 1`. Quantization is not applied here.
///
/// Precondition: `storage.order ≤ order`, `storage.channels` is `channels` or 1.
pub fn reduce(transfer: &[f32], order: usize, channels: usize, storage: &Storage) -> Vec<f32> {
    let n = sh::coeff_count(order);
    let m = sh::coeff_count(storage.order);
    let mut out = Vec::with_capacity(transfer.len() / (n * channels).max(1) * m * storage.channels);
    for v in transfer.chunks_exact((channels * n).max(1)) {
        if storage.channels == channels {
            for c in 0..channels {
                out.extend_from_slice(&v[c * n..][..m]);
            }
        } else {
            out.extend((0..m).map(|i| (0..channels).map(|c| v[c * n + i]).sum::<f32>() / channels as f32));
        }
    }
    out
}

/// What a reader gets back for `values` stored as `storage`.
pub fn round_trip(values: &[f32], storage: &Storage) -> Vec<f32> {
    let stride = storage.channels * storage.order * storage.order;
    quantize::round_trip(values, stride, storage.channels, storage.quantization)
}

/// One measured storage option.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Candidate {
    #[serde(flatten)]
    pub storage: Storage,
    pub bytes_per_vertex: usize,
    /// Worst relative RMS error in shaded radiance over the reference lightings.
    pub shaded_error: f64,
    /// Largest |coefficient change| from quantization alone (after reduction).
    pub quantization_max_abs: f64,
    /// Worst over the lightings of the estimated total error, the bake's own
    /// noise and this storage's error added in quadrature
    /// (`sqrt(noise² + storage²)` per lighting); `None` when the bake's
    /// noise was not measured.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub total_error: Option<f64>,
}

/// Measures `storage` against the baked transfer `(order, channels)`;
/// with `noise` (per lighting, [`noise_errors`]) also the total error.
pub fn measure(
    transfer: &[f32],
    order: usize,
    channels: usize,
    storage: &Storage,
    lightings: &[Lighting],
    noise: Option<&[f64]>,
) -> Candidate {
    measure_against(transfer, order, channels, storage, lightings, noise, None)
}

/// [`measure`], with the baked transfer's shading under each lighting
/// given when it was computed once for several storages.
fn measure_against(
    transfer: &[f32],
    order: usize,
    channels: usize,
    storage: &Storage,
    lightings: &[Lighting],
    noise: Option<&[f64]>,
    shaded: Option<&[Vec<[f64; 3]>]>,
) -> Candidate {
    let reduced = reduce(transfer, order, channels, storage);
    let stored = round_trip(&reduced, storage);
    let quantization_max_abs = reduced.iter().zip(&stored).map(|(a, b)| (*a as f64 - *b as f64).abs()).fold(0.0, f64::max);
    // Each lighting's sums run in vertex order on one thread, so the error
    // (recorded in META) does not depend on the thread count.
    let per_lighting: Vec<f64> = (0..lightings.len())
        .into_par_iter()
        .map(|k| {
            let sh = &lightings[k].sh;
            let stored_shading = shade(&stored, storage.order, storage.channels, sh);
            match shaded {
                Some(shaded) => relative_rms(&shaded[k], &stored_shading),
                None => relative_rms(&shade(transfer, order, channels, sh), &stored_shading),
            }
        })
        .collect();
    let shaded_error = per_lighting.iter().copied().fold(0.0, f64::max);
    let total_error = noise.map(|n| per_lighting.iter().zip(n).map(|(s, n)| s.hypot(*n)).fold(0.0, f64::max));
    Candidate { storage: *storage, bytes_per_vertex: bytes_per_vertex(storage), shaded_error, quantization_max_abs, total_error }
}

/// Per lighting, the relative RMS of shaded radiance (as [`relative_rms`]
/// counts it) that the bake's own noise amounts to: a vertex's DC standard
/// error over every bounce `noise[v]` (`TransferResult::noise`) is its DC's
/// absolute noise in every channel, scaled to each lighting as the vertex's
/// shading per unit of its DC. `None` unless `noise` has one value per vertex.
pub fn noise_errors(transfer: &[f32], order: usize, channels: usize, noise: &[f32], lightings: &[Lighting]) -> Option<Vec<f64>> {
    let n = sh::coeff_count(order);
    let stride = (channels * n).max(1);
    if noise.is_empty() || noise.len() * stride != transfer.len() {
        return None;
    }
    let errors = lightings
        .par_iter()
        .map(|l| {
            let (mut spread, mut norm) = (0.0f64, 0.0f64);
            for (v, rgb) in shade(transfer, order, channels, &l.sh).iter().enumerate() {
                for (c, &r) in rgb.iter().enumerate() {
                    let dc = f64::from(transfer[v * stride + if channels == 1 { 0 } else { c * n }]);
                    if dc > 0.0 {
                        spread += (f64::from(noise[v]) * r / dc).powi(2);
                    }
                    norm += r * r;
                }
            }
            if norm > 0.0 {
                (spread / norm).sqrt()
            } else {
                0.0
            }
        })
        .collect();
    Some(errors)
}

/// Every storage at most as rich as the bake: orders 1..=order, channels
/// (`channels`, and 1 when `channels` > 1), the allowed quantizations.
pub fn candidates(order: usize, channels: usize, quantizations: &[Quantization]) -> Vec<Storage> {
    let mut out = Vec::new();
    for o in 1..=order {
        let mut cs = vec![channels];
        if channels > 1 {
            cs.push(1);
        }
        for c in cs {
            for &q in quantizations {
                // A tint only makes sense on several channels.
                if q != Quantization::F16Tinted || c > 1 {
                    out.push(Storage { order: o, channels: c, quantization: q });
                }
            }
        }
    }
    out
}

/// The outcome of a budgeted choice.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Choice {
    pub chosen: Candidate,
    /// Error budget (relative RMS in shaded radiance), if one was given.
    pub budget: Option<f64>,
    /// Every option measured, in the order tried.
    pub measured: Vec<Candidate>,
    /// Worst over the lightings of the bake's own estimated noise
    /// ([`noise_errors`]), when measured: the part of the budget storage
    /// cannot spend.
    pub noise_error: Option<f64>,
}

impl Choice {
    /// Whether the chosen storage keeps the error the budget counts (the
    /// total when the noise is known, else storage alone) within it.
    pub fn within_budget(&self) -> bool {
        self.budget.is_none_or(|b| self.chosen.total_error.unwrap_or(self.chosen.shaded_error) <= b)
    }

    /// The error a storage had to keep within: the budget, or with the
    /// noise alone over it, the noise and [`OVER_BUDGET_SLACK`].
    pub fn limit(&self) -> f64 {
        self.budget.map_or(f64::INFINITY, |b| limit_within(b, self.noise_error))
    }
}

/// The error a storage must keep within under `budget`: the budget, or when
/// the noise alone is over it (no total can then be within it), the noise
/// and [`OVER_BUDGET_SLACK`].
fn limit_within(budget: f64, noise_error: Option<f64>) -> f64 {
    match noise_error {
        Some(n) if n > budget => n * (1.0 + OVER_BUDGET_SLACK),
        _ => budget,
    }
}

/// The smallest storage (bytes per vertex; ties: smaller error) whose shaded
/// error is within `budget`, among `storages`. Falls back to the bake as is
/// (f32) when none fits. Non-finite errors never fit.
pub fn choose(transfer: &[f32], order: usize, channels: usize, storages: &[Storage], budget: f64, lightings: &[Lighting]) -> Choice {
    choose_within_total(transfer, order, channels, storages, budget, lightings, None)
}

/// How much a storage may add to the bake's own noise when the noise alone
/// is over the budget: 1% of it (`sqrt(noise² + storage²) ≤ 1.01 · noise`,
/// storage error up to 14% of the noise). No storage can meet such a budget;
/// f32 would keep every bit of a bake whose error is its noise, at up to
/// 4.5× the bytes of one that adds a hundredth to it.
pub const OVER_BUDGET_SLACK: f64 = 0.01;

/// [`choose`], the budget counting the total error when `noise` (per
/// lighting, [`noise_errors`]) is known: the bake's own noise and the
/// storage's error in quadrature, `sqrt(noise² + storage²)`, the worst over
/// the lightings. When nothing fits because the noise alone is over the
/// budget, the smallest storage that adds at most [`OVER_BUDGET_SLACK`] to
/// the noise is kept instead (else the bake as it is), and
/// [`Choice::within_budget`] says the budget was not met.
pub fn choose_within_total(
    transfer: &[f32],
    order: usize,
    channels: usize,
    storages: &[Storage],
    budget: f64,
    lightings: &[Lighting],
    noise: Option<&[f64]>,
) -> Choice {
    // The baked shading once per lighting for every candidate, while it takes
    // at most 512 MiB (24 bytes a vertex and lighting); else each recomputes it.
    let vertices = transfer.len() / (channels * sh::coeff_count(order)).max(1);
    let shaded: Option<Vec<Vec<[f64; 3]>>> = (storages.len() > 1 && vertices * lightings.len() * 24 <= 512 << 20)
        .then(|| lightings.par_iter().map(|l| shade(transfer, order, channels, &l.sh)).collect());
    let measured: Vec<Candidate> =
        storages.par_iter().map(|s| measure_against(transfer, order, channels, s, lightings, noise, shaded.as_deref())).collect();
    drop(shaded);
    let noise_error = noise.map(|n| n.iter().copied().fold(0.0, f64::max));
    let limit = limit_within(budget, noise_error);
    let fitting = measured
        .iter()
        .filter(|c| c.total_error.unwrap_or(c.shaded_error) <= limit)
        .min_by(|a, b| a.bytes_per_vertex.cmp(&b.bytes_per_vertex).then(a.shaded_error.total_cmp(&b.shaded_error)));
    let chosen = match fitting {
        Some(c) => c.clone(),
        None => measure(transfer, order, channels, &Storage { order, channels, quantization: Quantization::F32 }, lightings, noise),
    };
    Choice { chosen, budget: Some(budget), measured, noise_error }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The choice measures its candidates in parallel against the baked
    /// shading computed once: every candidate is what [`measure`] alone
    /// gives, to the bit, on one thread and on two.
    #[test]
    fn a_choice_measures_each_candidate_as_measure_does_on_any_thread_count() {
        let (order, channels) = (3, 3);
        let transfer = smooth_transfer(2_000, order, channels);
        let noise = vec![0.01f32; 2_000];
        let lightings = reference_lightings(order);
        let noise = noise_errors(&transfer, order, channels, &noise, &lightings);
        let storages = candidates(order, channels, &[Quantization::F16, Quantization::F16Tinted, Quantization::I16PerVertexScale]);
        let alone: Vec<String> = storages
            .iter()
            .map(|s| serde_json::to_string(&measure(&transfer, order, channels, s, &lightings, noise.as_deref())).unwrap())
            .collect();
        for threads in [1, 2] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let choice = pool.install(|| choose_within_total(&transfer, order, channels, &storages, 0.02, &lightings, noise.as_deref()));
            let measured: Vec<String> = choice.measured.iter().map(|c| serde_json::to_string(c).unwrap()).collect();
            assert_eq!(measured, alone, "{threads} thread(s)");
        }
    }

    /// With the noise alone over the budget, the smallest storage that adds
    /// at most 1% to the noise is kept, not f32; the choice says the budget
    /// was missed. Without a measured noise, the budget is storage's alone.
    #[test]
    fn over_the_budget_storage_adds_at_most_a_hundredth_to_the_noise() {
        let (order, channels) = (3, 3);
        let transfer = smooth_transfer(2_000, order, channels);
        let lightings = reference_lightings(order);
        let noise = noise_errors(&transfer, order, channels, &vec![0.05f32; 2_000], &lightings).unwrap();
        let worst = noise.iter().copied().fold(0.0, f64::max);
        let all = [Quantization::F16, Quantization::F16Tinted, Quantization::I16PerVertexScale, Quantization::F32];
        let storages = candidates(order, channels, &all);
        let limit = worst * (1.0 + OVER_BUDGET_SLACK);
        let over = choose_within_total(&transfer, order, channels, &storages, worst / 2.0, &lightings, Some(&noise));
        let total = over.chosen.total_error.unwrap();
        assert!(!over.within_budget() && total >= worst && total <= limit, "total {total}, noise {worst}");
        assert_eq!(over.limit(), limit);
        let f32_bytes = bytes_per_vertex(&Storage { order, channels, quantization: Quantization::F32 });
        assert!(over.chosen.bytes_per_vertex < f32_bytes, "{:?}", over.chosen.storage);
        for c in over.measured.iter().filter(|c| c.bytes_per_vertex < over.chosen.bytes_per_vertex) {
            assert!(c.total_error.unwrap() > limit, "{:?} is smaller and within the slack", c.storage);
        }
        // Within the budget the rule is untouched: the budget, not the slack.
        let loose = choose_within_total(&transfer, order, channels, &storages, 2.0 * worst, &lightings, Some(&noise));
        assert!(loose.within_budget() && loose.limit() == 2.0 * worst);
        // No noise measured: a budget of 0 keeps the bake as it is.
        let exact = choose_within_total(&transfer, order, channels, &storages, 0.0, &lightings, None);
        assert_eq!(exact.chosen.storage, Storage { order, channels, quantization: Quantization::F32 });
    }

    fn smooth_transfer(vertices: usize, order: usize, channels: usize) -> Vec<f32> {
        let n = sh::coeff_count(order);
        let mut out = Vec::new();
        let mut basis = vec![0.0f32; n];
        for v in 0..vertices {
            let a = v as f32 * 0.37;
            let normal = Vec3::new(a.cos(), 0.5 + 0.4 * (a * 1.3).sin(), a.sin()).normalize();
            sh::eval_basis(order, normal, &mut basis);
            for c in 0..channels {
                let tint = 1.0 - 0.2 * c as f32;
                for (i, y) in basis.iter().enumerate() {
                    let l = sh::band_of_index(i);
                    out.push(tint * sh::clamped_cosine_kernel(l) as f32 / std::f32::consts::PI * y);
                }
            }
        }
        out
    }

    #[test]
    fn noise_errors_are_the_dc_noise_relative_to_the_shading() {
        // DC-only transfer under a constant sky: each vertex's shading is
        // L0·t0, so the shaded noise relative RMS is sqrt(Σ σ²) / sqrt(Σ t0²).
        let order = 2;
        let n = sh::coeff_count(order);
        let dc = [0.5f32, 0.25, 0.0, 1.0];
        let noise = [0.05f32, 0.0, 0.3, 0.1];
        let mut t = vec![0.0f32; dc.len() * n];
        dc.iter().enumerate().for_each(|(v, &d)| t[v * n] = d);
        let mut sky = vec![[0.0f32; 3]; n];
        sky[0] = [2.0, 1.0, 0.5];
        let lights = [Lighting { name: "constant".into(), sh: sky }];
        let got = noise_errors(&t, order, 1, &noise, &lights).unwrap()[0];
        // The black vertex's noise has nothing to scale (its shading is 0).
        let want = ((0.05f64.powi(2) + 0.1f64.powi(2)) / (0.25 + 0.0625 + 1.0)).sqrt();
        assert!((got - want).abs() < 1e-6, "{got} vs {want}");
        assert!(noise_errors(&t, order, 1, &[], &lights).is_none());
        assert!(noise_errors(&t, order, 1, &noise[..3], &lights).is_none());
    }

    #[test]
    fn reduce_keeps_low_bands_and_averages_channels() {
        let t: Vec<f32> = (0..2 * 3 * 9).map(|x| x as f32).collect();
        let r = reduce(&t, 3, 3, &Storage { order: 2, channels: 3, quantization: Quantization::F32 });
        assert_eq!(&r[..4], &[0.0, 1.0, 2.0, 3.0]);
        assert_eq!(&r[4..8], &[9.0, 10.0, 11.0, 12.0]);
        assert_eq!(r.len(), 2 * 3 * 4);
        let g = reduce(&t, 3, 3, &Storage { order: 1, channels: 1, quantization: Quantization::F32 });
        assert_eq!(g, vec![9.0, 36.0]);
    }

    #[test]
    fn identity_storage_has_zero_error() {
        let t = smooth_transfer(50, 3, 3);
        let lights = reference_lightings(3);
        let c = measure(&t, 3, 3, &Storage { order: 3, channels: 3, quantization: Quantization::F32 }, &lights, None);
        assert_eq!(c.shaded_error, 0.0);
        assert_eq!(c.bytes_per_vertex, 108);
    }

    #[test]
    fn a_loose_budget_drops_bands_and_a_tight_one_keeps_f32() {
        let t = smooth_transfer(200, 3, 3);
        let lights = reference_lightings(3);
        let all = candidates(3, 3, &[Quantization::F32, Quantization::F16, Quantization::I16PerVertexScale]);
        let tight = choose(&t, 3, 3, &all, 0.0, &lights);
        assert_eq!(tight.chosen.storage, Storage { order: 3, channels: 3, quantization: Quantization::F32 });
        let loose = choose(&t, 3, 3, &all, 0.5, &lights);
        assert!(loose.chosen.storage.order < 3 && loose.chosen.shaded_error <= 0.5, "{:?}", loose.chosen);
        // f16 at full order is far below 1%.
        let f16 = measure(&t, 3, 3, &Storage { order: 3, channels: 3, quantization: Quantization::F16 }, &lights, None);
        assert!(f16.shaded_error < 1e-3, "{}", f16.shaded_error);
    }
}
