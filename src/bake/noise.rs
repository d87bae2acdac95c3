//! The noise of a vertex's estimate, from its points' spread. A vertex's
//! value is a ratio Σ w·x / Σ w over its one-ring's points
//! (`receivers::point_weights`); its variance is estimated by the delta
//! method, `Var ≈ Σ w² (x − m)² / (Σ w)²`, from per-point moments that a
//! whole bake and a merge of shards sum alike. `adaptive` allocates points
//! by it; every bounce adds its share to the bake's noise estimate.

/// Sums over a vertex's (or an item corner's) points of the moments of
/// their DC `x` under their weights `w`: what the noise estimate needs
/// besides Σ w and Σ w·x; and Σ w·b, b the part of a point's DC (mean over
/// channels) that reached it through the back of its face, which the
/// front-side share is made of (`bake::side_share`; 0 outside window mode).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Moments {
    pub(crate) w2: f64,
    pub(crate) w2x: f64,
    pub(crate) w2x2: f64,
    pub(crate) wb: f64,
}

impl Moments {
    /// Adds a point of weight `w`, DC `x` and back-side DC `back`.
    #[inline]
    pub(crate) fn add(&mut self, w: f32, x: f32, back: f32) {
        let (w2, x) = (f64::from(w) * f64::from(w), f64::from(x));
        self.w2 += w2;
        self.w2x += w2 * x;
        self.w2x2 += w2 * x * x;
        self.wb += f64::from(w) * f64::from(back);
    }

    #[inline]
    pub(crate) fn merge(&mut self, other: &Moments) {
        self.w2 += other.w2;
        self.w2x += other.w2x;
        self.w2x2 += other.w2x2;
        self.wb += other.wb;
    }

    /// `[Σ w², Σ w²x, Σ w²x², Σ w·b]`, as shard files store them.
    pub(crate) fn to_array(self) -> [f64; 4] {
        [self.w2, self.w2x, self.w2x2, self.wb]
    }

    pub(crate) fn from_array([w2, w2x, w2x2, wb]: [f64; 4]) -> Moments {
        Moments { w2, w2x, w2x2, wb }
    }

    /// The moments had every weight been multiplied by `k`.
    pub(crate) fn scaled(&self, k: f64) -> Moments {
        let k2 = k * k;
        Moments { w2: self.w2 * k2, w2x: self.w2x * k2, w2x2: self.w2x2 * k2, wb: self.wb * k }
    }

    /// `Σ w² (x − mean)²`.
    pub(crate) fn spread(&self, mean: f64) -> f64 {
        (self.w2x2 - 2.0 * mean * self.w2x + mean * mean * self.w2).max(0.0)
    }

    /// Standard error of the ratio estimate `mean` = Σ w·x / `weight`.
    pub(crate) fn standard_error(&self, weight: f64, mean: f64) -> f64 {
        if weight > 0.0 {
            self.spread(mean).sqrt() / weight
        } else {
            0.0
        }
    }

    /// Effective number of points, `(Σ w)² / Σ w²`.
    pub(crate) fn effective_count(&self, weight: f64) -> f64 {
        if self.w2 > 0.0 {
            weight * weight / self.w2
        } else {
            0.0
        }
    }

    /// Per-point spread σ, `sqrt(Σ w² (x − mean)² / Σ w²)`.
    pub(crate) fn sigma(&self, mean: f64) -> f64 {
        if self.w2 > 0.0 {
            (self.spread(mean) / self.w2).sqrt()
        } else {
            0.0
        }
    }
}

/// Each vertex's DC statistics in one bounce: what the noise estimate (every
/// bounce) and the allocation (bounce 0) read.
pub(crate) struct VertexDc<'a> {
    pub(crate) weights: &'a [f32],
    /// Σ w·x of the DC per vertex.
    pub(crate) dc_sums: Vec<f32>,
    pub(crate) moments: &'a [Moments],
}

impl<'a> VertexDc<'a> {
    /// From a bounce's per-vertex sums (`[vertex][channel][coeff]`, `stride`
    /// values a vertex): channel 0's DC, whose moments the points kept.
    pub(crate) fn new(weights: &'a [f32], sums: &[f32], stride: usize, moments: &'a [Moments]) -> VertexDc<'a> {
        VertexDc { weights, dc_sums: sums.iter().step_by(stride).copied().collect(), moments }
    }

    /// Each vertex's mean DC, 0 without weight.
    pub(crate) fn mean(&self, v: usize) -> f64 {
        let w = f64::from(self.weights[v]);
        if w > 0.0 {
            f64::from(self.dc_sums[v]) / w
        } else {
            0.0
        }
    }

    /// Each vertex's DC standard error (empty without moments).
    pub(crate) fn standard_errors(&self) -> Vec<f32> {
        (0..self.moments.len()).map(|v| self.moments[v].standard_error(f64::from(self.weights[v]), self.mean(v)) as f32).collect()
    }
}

/// Adds one bounce's per-vertex DC standard errors to the bake's noise
/// estimate (`TransferResult::noise`) in quadrature, as if the bounces'
/// noise were independent; the first bounce's become the estimate. Measured
/// (docs/speed-accuracy.md): the later bounces carry a fifth to a third of
/// the Ferrari's and the room's squared error at the default, and partly
/// cancel bounce 0's in the cabin, where the sum reads about 4% high. A
/// whole bake and a sharded merge call this alike, so their bits agree.
pub(crate) fn add_noise_in_quadrature(noise: &mut Vec<f32>, bounce: &[f32]) {
    if noise.is_empty() {
        noise.extend_from_slice(bounce);
        return;
    }
    for (total, &b) in noise.iter_mut().zip(bounce) {
        *total = (f64::from(*total).powi(2) + f64::from(b).powi(2)).sqrt() as f32;
    }
}
