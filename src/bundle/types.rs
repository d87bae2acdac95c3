//! The typed content of a bundle: what [`super::encode_bundle`] takes and
//! [`super::decode_bundle`] returns.

use crate::mesh::Mesh;
pub use crate::sky::SunStep;

/// Everything a `.prtb` file holds.
#[derive(Clone, Debug, PartialEq)]
pub struct Bundle {
    /// Free-form metadata (tool version, parameters, seed, stats, conventions,
    /// measured quantization error). Stored as compact JSON; objects keep
    /// serde_json's key order (sorted), so encoding is deterministic.
    pub meta: serde_json::Value,
    /// The cleaned mesh the transfer and masks refer to, vertex for vertex.
    pub mesh: Mesh,
    /// SH transfer per vertex, if baked.
    pub transfer: Option<Transfer>,
    /// Sun masks and per-step sun/sky data, if baked.
    pub sun: Option<SunSeries>,
    /// Texel mode: the lightmap atlas and transfer per covered texel, if baked.
    pub texels: Option<TexelLayers>,
}

/// Texel mode's part of a bundle (sections ATLS and TXFR; its sun bits are
/// [`SunSeries::texel_masks`], section TSUN).
#[derive(Clone, Debug, PartialEq)]
pub struct TexelLayers {
    /// The mesh's atlas, triangle for triangle.
    pub atlas: crate::atlas::Atlas,
    /// The covered texels (`y * width + x`, ascending), one transfer row each.
    pub texels: Vec<u32>,
    /// Transfer per covered texel, laid out as a vertex transfer is per
    /// vertex; `None` in a sun-only texel bundle (`sun MESH --texel-size`).
    pub transfer: Option<Transfer>,
}

impl Bundle {
    /// Whether META records a window-mode transfer bake (`params.mode`).
    pub fn is_window_mode(&self) -> bool {
        self.meta.pointer("/params/mode").and_then(|m| m.as_str()) == Some("window")
    }

    /// The bake's `--window` patterns META records (`window_patterns`); none when absent.
    pub fn window_patterns(&self) -> Vec<String> {
        window_patterns_in(&self.meta)
    }
}

/// The `window_patterns` a bake's META object (or its `sun` part) records; none when absent.
pub fn window_patterns_in(meta: &serde_json::Value) -> Vec<String> {
    let patterns = meta.get("window_patterns").and_then(|p| p.as_array());
    patterns.map(|list| list.iter().filter_map(|p| p.as_str().map(str::to_string)).collect()).unwrap_or_default()
}

/// Per-vertex SH transfer vectors, one layer per stored bounce (and/or the total).
#[derive(Clone, Debug, PartialEq)]
pub struct Transfer {
    /// SH order n: bands `l < n`, `n²` coefficients, index `i = l(l+1)+m`.
    pub order: u32,
    /// 1 (grey) or 3 (RGB interreflection); any value ≥ 1 is stored.
    pub channels: u32,
    /// How the layers are stored on disk. On read, data is already dequantized.
    pub quantization: Quantization,
    /// Distinct kinds, in the order written.
    pub layers: Vec<TransferLayer>,
    /// Window mode: per receiver, the share of its light that reached it
    /// through the front of its face, in steps of 1/255 (sections SIDE and
    /// TSID); empty: both sides show all of it.
    pub front_share: Vec<f32>,
}

impl Transfer {
    /// Order 1, one channel, all zero: the stand-in a bundle of sun masks
    /// alone is shaded with (the sun term only).
    pub fn zero(vertex_count: usize) -> Transfer {
        Transfer {
            order: 1,
            channels: 1,
            quantization: Quantization::F32,
            layers: vec![TransferLayer { kind: LayerKind::Total, data: vec![0.0; vertex_count] }],
            front_share: Vec::new(),
        }
    }

    /// Values per vertex: `channels · order²` (saturating; absurd sizes fail later checks).
    pub fn values_per_vertex(&self) -> u64 {
        (self.channels as u64).saturating_mul((self.order as u64).saturating_mul(self.order as u64))
    }

    /// The layer of `kind`, if stored.
    pub fn layer(&self, kind: LayerKind) -> Option<&TransferLayer> {
        self.layers.iter().find(|l| l.kind == kind)
    }

    /// Bounce indices stored as separate layers, ascending.
    pub fn stored_bounces(&self) -> Vec<u32> {
        let mut bounces: Vec<u32> =
            self.layers.iter().filter_map(|l| if let LayerKind::Bounce(b) = l.kind { Some(b) } else { None }).collect();
        bounces.sort_unstable();
        bounces
    }

    /// Transfer of all light: the `Total` layer, or else the sum of the stored
    /// bounce layers (in ascending bounce order). Empty when there are no layers.
    pub fn total(&self) -> Vec<f32> {
        match self.layer(LayerKind::Total) {
            Some(total) => total.data.clone(),
            None => self.sum_bounces(|_| true),
        }
    }

    /// Sum of the stored bounce layers for which `pick(bounce)` holds, in ascending
    /// bounce order (deterministic); zeros of the right length when none is picked.
    pub fn sum_bounces(&self, pick: impl Fn(u32) -> bool) -> Vec<f32> {
        let len = self.layers.first().map_or(0, |l| l.data.len());
        let mut sum = vec![0.0f32; len];
        for b in self.stored_bounces().into_iter().filter(|&b| pick(b)) {
            if let Some(layer) = self.layer(LayerKind::Bounce(b)) {
                sum.iter_mut().zip(&layer.data).for_each(|(s, x)| *s += x);
            }
        }
        sum
    }
}

/// Which quantity a transfer layer holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LayerKind {
    /// Sum of all bounces. On disk: kind 0.
    Total,
    /// Bounce b alone (0 = direct from the environment). On disk: kind 1 + b.
    Bounce(u32),
}

impl std::fmt::Display for LayerKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LayerKind::Total => write!(f, "total"),
            LayerKind::Bounce(b) => write!(f, "bounce {b}"),
        }
    }
}

impl LayerKind {
    /// The on-disk code: 0 total, 1 + b for bounce b; `None` for `Bounce(u32::MAX)`.
    pub fn code(self) -> Option<u32> {
        match self {
            LayerKind::Total => Some(0),
            LayerKind::Bounce(b) => b.checked_add(1),
        }
    }
    /// Inverse of [`LayerKind::code`].
    pub fn from_code(code: u32) -> LayerKind {
        match code {
            0 => LayerKind::Total,
            b => LayerKind::Bounce(b - 1),
        }
    }
}

/// One transfer layer.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferLayer {
    pub kind: LayerKind,
    /// Vertex-major `[vertex][channel][coeff]`: value `((v·channels)+c)·order² + i`.
    /// Length `vertex_count · channels · order²`; finite values only.
    pub data: Vec<f32>,
}

/// Storage precision of transfer layers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Quantization {
    /// Bit-exact. On disk: 0.
    F32,
    /// IEEE binary16, round to nearest even; |error| ≤ max(2⁻¹¹·|v|, 2⁻²⁵). On disk: 1.
    F16,
    /// Per vertex, scale s = max|v| / 32767 (f32) and values round(v / s) in
    /// −32767..=32767; |error| ≤ s/2 + half an f32 ulp of the result. On disk: 2.
    I16PerVertexScale,
    /// Rank-one colour: per vertex one grey f16 vector `g` (the mean of the
    /// channels) and one f16 tint `k_c` per channel (`t_c0 / g_0`, exact in
    /// DC), decoded as `t_ci = k_c · g_i`. Lossy beyond quantization wherever
    /// the channels differ in shape, not only in scale: measure it (see
    /// `budget`). 2·(C + n²) bytes per vertex. On disk: 3.
    F16Tinted,
}

impl Quantization {
    /// The on-disk code.
    pub fn code(self) -> u32 {
        match self {
            Quantization::F32 => 0,
            Quantization::F16 => 1,
            Quantization::I16PerVertexScale => 2,
            Quantization::F16Tinted => 3,
        }
    }
    /// Inverse of [`Quantization::code`]; `None` for unknown codes.
    pub fn from_code(code: u32) -> Option<Quantization> {
        match code {
            0 => Some(Quantization::F32),
            1 => Some(Quantization::F16),
            2 => Some(Quantization::I16PerVertexScale),
            3 => Some(Quantization::F16Tinted),
            _ => None,
        }
    }
    /// Short lowercase name for reports: `f32`, `f16`, `i16`, `f16-tinted`.
    pub fn name(self) -> &'static str {
        match self {
            Quantization::F32 => "f32",
            Quantization::F16 => "f16",
            Quantization::I16PerVertexScale => "i16",
            Quantization::F16Tinted => "f16-tinted",
        }
    }
}

/// A day's time lapse: per-step sun and sky, and a shadow bit per (vertex, step).
#[derive(Clone, Debug, PartialEq)]
pub struct SunSeries {
    /// SH order of each step's sky radiance (0 = no sky).
    pub sky_order: u32,
    /// One entry per time step; `steps.len()` is the step count.
    pub steps: Vec<SunStep>,
    /// `ceil(steps.len() / 32)`.
    pub words_per_vertex: u32,
    /// Vertex-major bits: vertex v, step k is bit `k % 32` of word
    /// `v · words_per_vertex + k / 32`; 1 = sunlit. Bits at steps ≥ `steps.len()` are 0.
    pub masks: Vec<u32>,
    /// Texel mode (section TSUN): the same bits per covered texel of the
    /// bundle's atlas, texel-major with `words_per_vertex` words each; empty
    /// when the sun was baked per vertex only.
    pub texel_masks: Vec<u32>,
    /// Texel mode (section TSUF, with `sun --texel-fractions`): per covered
    /// texel and step, the share of its footprint that sees the sun in
    /// 4 bits (value/15), `ceil(steps / 8)` words a texel, step k in bits
    /// `4 (k % 8)` of word `k / 8`; empty when not stored.
    pub texel_fractions: Vec<u32>,
    /// The atlas the texel masks lie on when it is not the bundle's
    /// (section TSAT): sun bits on finer texels than the texel transfer's,
    /// which a slat's sharp shadow needs and the soft sky light does not.
    /// `None`: they lie on [`TexelLayers`]' atlas.
    pub texel_atlas: Option<TexelAtlas>,
}

/// An atlas and its covered texels, in id order (the layout of ATLS).
#[derive(Clone, Debug, PartialEq)]
pub struct TexelAtlas {
    pub atlas: crate::atlas::Atlas,
    pub texels: Vec<u32>,
}

impl SunSeries {
    /// A series with its bits per vertex only (no texel masks).
    pub fn per_vertex(sky_order: u32, steps: Vec<SunStep>, words_per_vertex: u32, masks: Vec<u32>) -> SunSeries {
        SunSeries { sky_order, steps, words_per_vertex, masks, texel_masks: Vec::new(), texel_fractions: Vec::new(), texel_atlas: None }
    }

    /// Whether `vertex` is sunlit at `step`. Out-of-range arguments give `false`.
    pub fn bit(&self, vertex: usize, step: usize) -> bool {
        let word =
            vertex.checked_mul(self.words_per_vertex as usize).and_then(|w| w.checked_add(step / 32)).and_then(|w| self.masks.get(w));
        step < self.steps.len() && word.is_some_and(|w| (w >> (step % 32)) & 1 == 1)
    }

    /// Packs `f(vertex, step)` for every vertex and step into
    /// `(words_per_vertex, masks)` in the layout of [`SunSeries::masks`].
    pub fn pack(step_count: usize, vertex_count: usize, f: impl Fn(usize, usize) -> bool) -> (u32, Vec<u32>) {
        let words_per_vertex = step_count.div_ceil(32);
        let mut masks = vec![0u32; words_per_vertex * vertex_count];
        for (vertex, words) in masks.chunks_exact_mut(words_per_vertex.max(1)).enumerate() {
            for step in 0..step_count {
                if f(vertex, step) {
                    words[step / 32] |= 1 << (step % 32);
                }
            }
        }
        (words_per_vertex as u32, masks)
    }

    /// Whether covered texel `i` (an index into [`TexelLayers::texels`]) is
    /// sunlit at `step`; `false` without texel masks or out of range.
    pub fn texel_bit(&self, i: usize, step: usize) -> bool {
        let word =
            i.checked_mul(self.words_per_vertex as usize).and_then(|w| w.checked_add(step / 32)).and_then(|w| self.texel_masks.get(w));
        step < self.steps.len() && word.is_some_and(|w| (w >> (step % 32)) & 1 == 1)
    }

    /// The sunlit share of covered texel `i` at `step` (0..=1): its
    /// fraction when stored, else its bit; 0 out of range.
    pub fn texel_sun(&self, i: usize, step: usize) -> f32 {
        if self.texel_fractions.is_empty() {
            return if self.texel_bit(i, step) { 1.0 } else { 0.0 };
        }
        let words = self.steps.len().div_ceil(8);
        let word = i.checked_mul(words).and_then(|w| w.checked_add(step / 8)).and_then(|w| self.texel_fractions.get(w));
        match word {
            Some(w) if step < self.steps.len() => ((w >> (4 * (step % 8))) & 0xF) as f32 / 15.0,
            _ => 0.0,
        }
    }

    /// The number of covered texels the texel masks have, given the
    /// bundle's texels: those of the sun's own atlas when it has one.
    pub fn texel_count(&self, bundle_texels: Option<&TexelLayers>) -> Option<usize> {
        match &self.texel_atlas {
            Some(own) => Some(own.texels.len()),
            None => bundle_texels.map(|t| t.texels.len()),
        }
    }

    /// Number of time steps.
    pub fn step_count(&self) -> usize {
        self.steps.len()
    }
}
