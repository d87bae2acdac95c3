//! Texel points where the noise is (`--texel-adaptive`): the texels' bounce
//! 0 is first traced at the base points, then each texel's points are
//! multiplied by a whole factor `k` where the light is noisiest, the extra
//! points continuing each footprint part's own Sobol sequence.
//!
//! The image's squared error is a sum over pixels, so a texel counts by its
//! world area `a` (the pixels it covers) times its variance `σ²/n`. That
//! sum is least for a given number of points when `n ∝ √a · σ` (Neyman
//! allocation). A texel's σ is the per-point spread of the DC around the
//! mean of its 3 × 3 neighbourhood in its own chart: with one point a texel
//! its own spread is zero, and a neighbourhood whose points differ (noise,
//! or an edge its footprint integrates) is where more points pay. In window
//! mode most of a car's texels see no glass at all and get nothing: the
//! points go to the cabin.

use crate::bake::noise::Moments;

/// The largest factor a texel's points grow by.
pub(crate) const MAX_FACTOR: u32 = 16;

/// What the allocation reads of bounce 0's base pass, per covered texel.
pub(crate) struct TexelPilot<'a> {
    /// Σ w of the kept points (0: every point inside geometry).
    pub(crate) weights: &'a [f32],
    /// Σ w·x of the DC (channel 0).
    pub(crate) dc_sums: Vec<f64>,
    pub(crate) moments: &'a [Moments],
    /// Base points per texel.
    pub(crate) counts: Vec<u32>,
    /// World area of each texel's footprint.
    pub(crate) areas: Vec<f64>,
    /// Each texel's neighbours in its own chart ([`super::texels::same_chart_neighbours`]).
    pub(crate) neighbours: &'a [Vec<u32>],
}

/// Each texel's factor (1: no extra points), the extra points
/// `Σ counts · (k − 1)` within `budget`.
pub(crate) fn factors(pilot: &TexelPilot, budget: u64) -> Vec<u32> {
    let n = pilot.weights.len();
    let wants: Vec<f64> = (0..n)
        .map(|i| {
            if pilot.weights[i] <= 0.0 || pilot.counts[i] == 0 {
                return 0.0;
            }
            pilot.areas[i].max(0.0).sqrt() * pooled_sigma(pilot, i) / f64::from(pilot.counts[i])
        })
        .collect();
    let factors_at =
        |lambda: f64| -> Vec<u32> { wants.iter().map(|&w| ((lambda * w).round().clamp(1.0, f64::from(MAX_FACTOR))) as u32).collect() };
    let extra = |k: &[u32]| k.iter().zip(&pilot.counts).map(|(&k, &c)| u64::from(c) * u64::from(k - 1)).sum::<u64>();
    if budget == 0 || wants.iter().all(|&w| w <= 0.0) {
        return vec![1; n];
    }
    factors_at(super::adaptive::largest_within(|lambda| extra(&factors_at(lambda)), budget))
}

/// The per-point spread of texel `i`'s neighbourhood (itself and its
/// same-chart neighbours) around the neighbourhood's mean.
fn pooled_sigma(pilot: &TexelPilot, i: usize) -> f64 {
    let mut weight = f64::from(pilot.weights[i]);
    let mut sum = pilot.dc_sums[i];
    let mut moments = pilot.moments[i];
    for &j in &pilot.neighbours[i] {
        weight += f64::from(pilot.weights[j as usize]);
        sum += pilot.dc_sums[j as usize];
        moments.merge(&pilot.moments[j as usize]);
    }
    if weight <= 0.0 {
        return 0.0;
    }
    moments.sigma(sum / weight)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::transfer::texels::same_chart_neighbours;

    /// A row of texels, one chart, one point each: `values` their DC.
    fn row(values: &[f32]) -> (Vec<f32>, Vec<f64>, Vec<Moments>, Vec<Vec<u32>>) {
        let n = values.len() as u32;
        let texels: Vec<u32> = (0..n).collect();
        let neighbours = same_chart_neighbours(&texels, n, &vec![0; n as usize]);
        let moments = values
            .iter()
            .map(|&x| {
                let mut m = Moments::default();
                m.add(1.0, x, 0.0);
                m
            })
            .collect();
        (vec![1.0; values.len()], values.iter().map(|&x| f64::from(x)).collect(), moments, neighbours)
    }

    /// Points go where neighbouring texels disagree (noise), none to the
    /// dark, even texels; the extras stay within the budget and spend most of it.
    #[test]
    fn extra_points_go_to_the_noisy_texels_within_the_budget() {
        // Texels 0..8 dark, 8..16 noisy around 1, 16..24 evenly lit at 1.
        let values: Vec<f32> = (0..24)
            .map(|i| {
                if i < 8 {
                    0.0
                } else if i < 16 {
                    [0.2, 1.8][i % 2]
                } else {
                    1.0
                }
            })
            .collect();
        let (weights, dc_sums, moments, neighbours) = row(&values);
        let pilot = TexelPilot {
            weights: &weights,
            dc_sums,
            moments: &moments,
            counts: vec![1; 24],
            areas: vec![1e-4; 24],
            neighbours: &neighbours,
        };
        let k = factors(&pilot, 40);
        let extra: u32 = k.iter().map(|k| k - 1).sum();
        assert!((32..=40).contains(&extra), "extra points {extra} of a budget of 40: {k:?}");
        assert!(k[..7].iter().all(|&k| k == 1), "dark texels grew: {k:?}");
        assert!(k[17..].iter().all(|&k| k == 1), "evenly lit texels grew: {k:?}");
        assert!(k[9..15].iter().all(|&k| k >= 4), "noisy texels did not grow: {k:?}");
        assert_eq!(factors(&pilot, 0), vec![1; 24]);
    }

    /// At equal noise, a texel of four times the area gets twice the factor.
    #[test]
    fn a_texel_grows_as_the_root_of_its_area() {
        let values: Vec<f32> = (0..8).map(|i| [0.0, 2.0][i % 2]).collect();
        let (weights, dc_sums, moments, _) = row(&values);
        // Two separate pairs of neighbours: texels 0–1 (small) and 2–3 (large).
        let neighbours = vec![vec![1], vec![0], vec![3], vec![2], vec![], vec![], vec![], vec![]];
        let pilot = TexelPilot {
            weights: &weights,
            dc_sums,
            moments: &moments,
            counts: vec![1; 8],
            areas: vec![1.0, 1.0, 4.0, 4.0, 1.0, 1.0, 1.0, 1.0],
            neighbours: &neighbours,
        };
        let k = factors(&pilot, 18);
        assert_eq!((k[0], k[2]), (k[1], k[3]));
        assert_eq!(2 * (k[0] - 1) + 2 * (k[2] - 1), 18, "{k:?}");
        assert!((f64::from(k[2]) / f64::from(k[0]) - 2.0).abs() < 0.35, "{k:?}");
    }
}
