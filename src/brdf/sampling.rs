//! Tabulated discrete distributions for the table sampler: many rows of the
//! same length, stored flat, each with its probabilities and cumulative sums.

/// `rows` discrete distributions over `0..len`, built from non-negative weights.
#[derive(Clone, Debug)]
pub struct DiscreteTables {
    len: usize,
    /// Per row: `len` probabilities (0 for every entry of an all-zero row).
    probability: Vec<f32>,
    /// Per row: `len + 1` cumulative sums, from 0 to exactly 1.
    cumulative: Vec<f32>,
    /// Per row: the sum of its weights (0 for a row that cannot be sampled).
    total: Vec<f64>,
}

impl DiscreteTables {
    /// Builds `rows` distributions of `len` entries; `weight(row, i)` must be
    /// finite and ≥ 0 (negative or NaN weights count as 0).
    pub fn build(rows: usize, len: usize, mut weight: impl FnMut(usize, usize) -> f64) -> DiscreteTables {
        let mut probability = Vec::with_capacity(rows * len);
        let mut cumulative = Vec::with_capacity(rows * (len + 1));
        let mut total = Vec::with_capacity(rows);
        let mut weights = vec![0.0f64; len];
        for row in 0..rows {
            for (i, w) in weights.iter_mut().enumerate() {
                let x = weight(row, i);
                *w = if x.is_finite() && x > 0.0 { x } else { 0.0 };
            }
            let sum: f64 = weights.iter().sum();
            total.push(sum);
            let scale = if sum > 0.0 { 1.0 / sum } else { 0.0 };
            let mut running = 0.0f64;
            cumulative.push(0.0);
            for &w in &weights {
                probability.push((w * scale) as f32);
                running += w * scale;
                cumulative.push(running.min(1.0) as f32);
            }
            if sum > 0.0 {
                // Exactly 1, so every u in [0, 1) lands in a positive entry.
                *cumulative.last_mut().unwrap() = 1.0;
            }
        }
        DiscreteTables { len, probability, cumulative, total }
    }

    /// The sum of the weights of `row`.
    pub fn total(&self, row: usize) -> f64 {
        self.total[row]
    }

    /// Probability of entry `i` of `row`.
    pub fn probability(&self, row: usize, i: usize) -> f32 {
        self.probability[row * self.len + i]
    }

    /// Draws an entry of `row` from `u` in [0,1): the entry `i` with
    /// `cdf[i] ≤ u < cdf[i+1]` (never a zero-probability entry), and `u`
    /// rescaled to [0,1) within it for reuse. `None` for an all-zero row.
    pub fn sample(&self, row: usize, u: f32) -> Option<(usize, f32)> {
        if self.total[row] <= 0.0 {
            return None;
        }
        // Outside [0, 1) (or NaN) would pick an empty end entry.
        let u = if u >= 0.0 { u.min(1.0 - f32::EPSILON / 2.0) } else { 0.0 };
        let cdf = &self.cumulative[row * (self.len + 1)..(row + 1) * (self.len + 1)];
        // First edge above u, minus one; u < 1 = cdf[len] keeps it in range.
        let above = cdf.partition_point(|&c| c <= u);
        let i = above.clamp(1, self.len) - 1;
        let width = cdf[i + 1] - cdf[i];
        let rest = if width > 0.0 { (u - cdf[i]) / width } else { 0.5 };
        Some((i, rest.clamp(0.0, 1.0 - f32::EPSILON / 2.0)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_skip_zero_entries_and_rescale_u() {
        let t = DiscreteTables::build(2, 4, |row, i| if row == 1 { 0.0 } else { [1.0, 0.0, 3.0, f64::NAN][i] });
        assert_eq!(t.probability(0, 2), 0.75);
        assert_eq!(t.probability(0, 3), 0.0);
        assert_eq!(t.sample(0, 0.0), Some((0, 0.0)));
        assert_eq!(t.sample(0, 0.125), Some((0, 0.5)));
        // u = 0.25 is where entry 1 (empty) and entry 2 meet: entry 2.
        assert_eq!(t.sample(0, 0.25).unwrap().0, 2);
        let (i, rest) = t.sample(0, 0.999_999_94).unwrap();
        assert!(i == 2 && rest < 1.0);
        assert_eq!(t.sample(0, 1.0).unwrap().0, 2);
        assert_eq!(t.sample(0, f32::NAN).unwrap().0, 0);
        assert_eq!(t.sample(1, 0.5), None);
        assert_eq!(t.total(0), 4.0);
    }
}
