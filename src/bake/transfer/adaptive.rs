//! Sample points where the noise is (`--adaptive`): bounce 0 is
//! first traced at the base layout (points by area), which also measures
//! each vertex's noise; then extra points go to the triangles around the
//! noisiest vertices, and every later bounce runs over all the points.
//!
//! A vertex's value is a ratio Σ w·x / Σ w over its one-ring's points
//! (`receivers::point_weights`). Its noise is estimated from the points'
//! DC by the delta method, `Var ≈ Σ w² (x − m)² / (Σ w)²`, whose per-point
//! spread `σ² = Σ w² (x − m)² / Σ w²` does not depend on how many points
//! there are. The squared error summed over vertices, which is what a
//! relative RMS over vertices counts, is least for a given number of
//! points when a vertex's effective point count grows as its σ (Neyman
//! allocation); a vertex's σ is taken as the largest over its one-ring's
//! corners, so a vertex whose few points all missed the light, next to
//! noisy ones, is not left alone. Extra points are continued from the same
//! Sobol sequence of the triangle (its samples `n..n + e`), and every sample
//! of a triangle is weighted by `area / (n + e)`: the estimate stays the
//! hat-weighted one-ring mean, only less noisy where the points were added.
//!
//! A vertex none of whose points survived the inside test, next to one
//! whose points did, has no estimate at all: its triangles also grow by
//! [`SEARCH_FACTOR`], on top of the budget, to find the part of its
//! one-ring in the open.

use super::items::Items;
use crate::bake::noise::VertexDc;
use crate::mesh::Mesh;

/// How many times its base points a triangle grows to around a vertex none
/// of whose points survived the inside test while a neighbour's did (a
/// vertex at a wall's foot, its one-ring mostly inside the wall). Its value
/// is the mean over the part of its one-ring in the open, which only more
/// points find, and bounce 0's spread says nothing of it. On the grey-white
/// room at the default bake (docs/speed-accuracy.md): 16 leaves 237 lit
/// vertices black instead of 528, 15% more points, the same error for the
/// time; 4 leaves 395, 64 leaves 130 at 44% more time.
pub(crate) const SEARCH_FACTOR: f64 = 16.0;

/// Extra samples per item of `items` (the base layout: one item per
/// triangle, samples from 0), about `budget` in all, in whole rotation
/// triples, each triangle at most `max_per_triangle` in all.
pub(crate) fn extra_counts(mesh: &Mesh, items: &Items, pilot: &VertexDc, budget: u64, max_per_triangle: u32) -> Vec<u32> {
    let Items::Interior { triangles, counts, .. } = items else { return Vec::new() };
    let vertex_count = mesh.vertex_count();
    let mut sigma = vec![0.0f64; vertex_count];
    let mut effective = vec![0.0f64; vertex_count];
    for v in 0..vertex_count {
        let w = f64::from(pilot.weights[v]);
        if w > 0.0 {
            sigma[v] = pilot.moments[v].sigma(pilot.mean(v));
            effective[v] = pilot.moments[v].effective_count(w);
        }
    }
    // σ pooled over each one-ring: the largest of its triangles' corners.
    let mut pooled = sigma.clone();
    for &t in triangles {
        let corners = mesh.triangle(t as usize);
        let largest = corners.iter().map(|&v| sigma[v as usize]).fold(0.0, f64::max);
        for v in corners {
            pooled[v as usize] = pooled[v as usize].max(largest);
        }
    }
    // Per item, the largest σ / effective points of its corners: when
    // vertices want λ·σ effective points, the item grows by λ times it (at least 1).
    // A corner none of whose points survived the inside test (a vertex at a
    // wall's foot, its one-ring mostly inside the wall) counts as one
    // effective point with its neighbours' σ: the part of its one-ring in
    // the open is what its value is, and only more points can find it
    // (uniform layouts leave such vertices black: 56% of the room's error).
    let ratios: Vec<f64> = triangles
        .iter()
        .map(|&t| {
            let corners = mesh.triangle(t as usize).map(|v| v as usize);
            corners.iter().map(|&v| pooled[v] / effective[v].max(1.0)).fold(0.0, f64::max)
        })
        .collect();
    let extra =
        |lambda: f64| -> Vec<u32> { ratios.iter().zip(counts).map(|(&ratio, &n)| grown_by(n, lambda * ratio, max_per_triangle)).collect() };
    if budget == 0 {
        return vec![0; counts.len()];
    }
    let mut out = if pooled.iter().all(|&s| s <= 0.0) { vec![0; counts.len()] } else { neyman(extra, budget) };
    search_rejected(mesh, triangles, counts, pilot.weights, max_per_triangle, &mut out);
    out
}

/// The Neyman allocation's extras: those of the largest λ whose `extra(λ)`
/// stays within `budget`.
fn neyman(extra: impl Fn(f64) -> Vec<u32>, budget: u64) -> Vec<u32> {
    let total = |e: &[u32]| e.iter().map(|&e| u64::from(e)).sum::<u64>();
    extra(largest_within(|lambda| total(&extra(lambda)), budget))
}

/// The largest λ whose `cost(λ)` stays within `budget`, by bisection on a
/// log scale (the cost grows with λ).
pub(crate) fn largest_within(cost: impl Fn(f64) -> u64, budget: u64) -> f64 {
    let (mut low, mut high) = (0.0f64, 1.0f64);
    while cost(high) < budget && high < 1e30 {
        low = high;
        high *= 16.0;
    }
    for _ in 0..60 {
        let mid = if low > 0.0 { (low * high).sqrt() } else { high / 16.0 };
        if cost(mid) <= budget {
            low = mid;
        } else {
            high = mid;
        }
    }
    low
}

/// The extra points, in whole rotation triples, that grow a triangle of `n`
/// points `factor` times (at least 1×, at most to `max_per_triangle`).
fn grown_by(n: u32, factor: f64, max_per_triangle: u32) -> u32 {
    let k = factor.max(1.0).min(f64::from(max_per_triangle.max(n)) / f64::from(n));
    3 * ((f64::from(n) * (k - 1.0) / 3.0).round() as u32)
}

/// Grows to [`SEARCH_FACTOR`] × its base points (at most `max_per_triangle`)
/// every triangle with a corner whose points were all rejected while a
/// neighbour's were not; a vertex deep inside geometry, all of whose
/// neighbours are rejected too, gets nothing.
fn search_rejected(mesh: &Mesh, triangles: &[u32], counts: &[u32], weights: &[f32], max_per_triangle: u32, extra: &mut [u32]) {
    let mut near_weighted = vec![false; weights.len()];
    for &t in triangles {
        let corners = mesh.triangle(t as usize);
        if corners.iter().any(|&v| weights[v as usize] > 0.0) {
            corners.iter().for_each(|&v| near_weighted[v as usize] = true);
        }
    }
    for ((&t, &n), e) in triangles.iter().zip(counts).zip(extra.iter_mut()) {
        if mesh.triangle(t as usize).iter().any(|&v| weights[v as usize] <= 0.0 && near_weighted[v as usize]) {
            *e = (*e).max(grown_by(n, SEARCH_FACTOR, max_per_triangle));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::noise::Moments;
    use crate::verify::shapes;

    /// The moments give the delta-method standard error of a weighted mean,
    /// and scaling every weight leaves the mean's error unchanged.
    #[test]
    fn moments_give_the_weighted_mean_standard_error() {
        let points = [(0.5f32, 1.0f32), (1.0, 3.0), (0.25, 2.0), (2.0, 0.5)];
        let mut m = Moments::default();
        for &(w, x) in &points {
            m.add(w, x, 0.0);
        }
        let weight: f64 = points.iter().map(|&(w, _)| w as f64).sum();
        let mean = points.iter().map(|&(w, x)| w as f64 * x as f64).sum::<f64>() / weight;
        let expected = points.iter().map(|&(w, x)| (w as f64 * (x as f64 - mean)).powi(2)).sum::<f64>().sqrt() / weight;
        assert!((m.standard_error(weight, mean) - expected).abs() < 1e-12);
        let scaled = m.scaled(0.3);
        assert!((scaled.standard_error(0.3 * weight, mean) - expected).abs() < 1e-12);
        assert!((m.effective_count(weight) - weight * weight / points.iter().map(|&(w, _)| (w * w) as f64).sum::<f64>()).abs() < 1e-12);
        // Equal values: no spread, no error; no weight: none either.
        let mut flat = Moments::default();
        (0..4).for_each(|_| flat.add(1.0, 2.0, 0.0));
        assert_eq!(flat.standard_error(4.0, 2.0), 0.0);
        assert_eq!(Moments::default().standard_error(0.0, 0.0), 0.0);
    }

    /// A 4×4 grid, 6 samples per triangle; vertex `noisy` alone has spread.
    fn grid_pilot(noisy: usize) -> (Mesh, Items, Vec<f32>, Vec<f32>, Vec<Moments>) {
        let mesh = shapes::plane_grid(4, 1.0);
        let triangles: Vec<u32> = (0..mesh.triangle_count() as u32).collect();
        let counts = vec![6u32; triangles.len()];
        let first_sample = (0..triangles.len() as u32).map(|k| 6 * k).collect();
        let items = Items::Interior { triangles, counts, first_sample, first_index: Vec::new(), weight_count: Vec::new() };
        let n = mesh.vertex_count();
        let weights = vec![1.0f32; n];
        let dc_sums = vec![0.5f32; n];
        let mut moments = vec![Moments::default(); n];
        for (v, m) in moments.iter_mut().enumerate() {
            // Six points of weight 1/6 around the mean 0.5; spread only at `noisy`.
            let half_range = if v == noisy { 0.4 } else { 0.0 };
            for k in 0..6 {
                m.add(1.0 / 6.0, 0.5 + if k % 2 == 0 { half_range } else { -half_range }, 0.0);
            }
        }
        (mesh, items, weights, dc_sums, moments)
    }

    #[test]
    fn extra_points_go_around_the_noisy_vertex_within_the_budget() {
        let noisy = 12; // the grid's centre vertex
        let (mesh, items, weights, dc_sums, moments) = grid_pilot(noisy);
        let pilot = VertexDc { weights: &weights, dc_sums, moments: &moments };
        let Items::Interior { triangles, counts, .. } = &items else { unreachable!() };
        let base: u64 = counts.iter().map(|&c| c as u64).sum();
        for budget in [0u64, 30, base, 4 * base] {
            let extra = extra_counts(&mesh, &items, &pilot, budget, 48);
            let total: u64 = extra.iter().map(|&e| e as u64).sum();
            assert!(total <= budget, "budget {budget}: {total} extra");
            assert!(extra.iter().all(|&e| e % 3 == 0 && e + 6 <= 48), "whole triples, at most 48 in a triangle: {extra:?}");
            // Only triangles with a corner within one ring of the noisy vertex (pooled σ) gain.
            let near = |t: u32| {
                let ring: Vec<u32> =
                    (0..mesh.triangle_count()).map(|u| mesh.triangle(u)).filter(|c| c.contains(&(noisy as u32))).flatten().collect();
                mesh.triangle(t as usize).iter().any(|v| ring.contains(v))
            };
            for (k, &e) in extra.iter().enumerate() {
                assert!(e == 0 || near(triangles[k]), "triangle {} far from the noise got {e}", triangles[k]);
            }
            // (30 extra cannot give each triangle near the noise a whole triple: none gets any.)
            if budget >= base {
                let around: u64 = extra
                    .iter()
                    .enumerate()
                    .filter(|&(k, _)| mesh.triangle(triangles[k] as usize).contains(&(noisy as u32)))
                    .map(|(_, &e)| e as u64)
                    .sum();
                assert!(around > 0, "budget {budget}: nothing went next to the noisy vertex");
            }
        }
        // No spread anywhere: nothing to add.
        let (mesh, items, weights, dc_sums, moments) = grid_pilot(usize::MAX);
        let extra = extra_counts(&mesh, &items, &VertexDc { weights: &weights, dc_sums, moments: &moments }, 1000, 256);
        assert!(extra.iter().all(|&e| e == 0));
    }

    #[test]
    fn a_vertex_whose_points_were_all_rejected_gets_points_when_its_neighbours_are_lit() {
        let dark = 12; // the centre vertex: every point around it was inside geometry
        let (mesh, items, mut weights, mut dc_sums, _) = grid_pilot(usize::MAX);
        let mut moments = vec![Moments::default(); weights.len()];
        for (v, m) in moments.iter_mut().enumerate() {
            if v != dark {
                // The same small spread everywhere else.
                (0..6).for_each(|k| m.add(1.0 / 6.0, 0.5 + if k % 2 == 0 { 0.1 } else { -0.1 }, 0.0));
            }
        }
        weights[dark] = 0.0;
        dc_sums[dark] = 0.0;
        let pilot = VertexDc { weights: &weights, dc_sums, moments: &moments };
        let Items::Interior { triangles, counts, .. } = &items else { unreachable!() };
        let base: u64 = counts.iter().map(|&c| c as u64).sum();
        let extra = extra_counts(&mesh, &items, &pilot, base / 4, 48);
        let touches = |k: usize| mesh.triangle(triangles[k] as usize).contains(&(dark as u32));
        let around: Vec<u32> = (0..extra.len()).filter(|&k| touches(k)).map(|k| extra[k]).collect();
        let elsewhere: Vec<u32> = (0..extra.len()).filter(|&k| !touches(k)).map(|k| extra[k]).collect();
        assert!(around.iter().all(|&e| e > 0), "the dark vertex's one-ring got {around:?}");
        assert!(around.iter().min() >= elsewhere.iter().max(), "around {around:?}, elsewhere {elsewhere:?}");
    }

    #[test]
    fn a_rejected_vertex_next_to_unlit_points_is_searched_on_top_of_the_budget() {
        // The 5 × 5 grid's columns 0, 1 and 2 inside a wall (every point
        // rejected), columns 3 and 4 in the open but unlit at bounce 0 (no
        // spread anywhere: the Neyman allocation adds nothing). Column 2
        // borders points that survived; columns 0 and 1 do not.
        let (mesh, items, mut weights, mut dc_sums, _) = grid_pilot(usize::MAX);
        let moments = vec![Moments::default(); weights.len()];
        dc_sums.iter_mut().for_each(|s| *s = 0.0);
        let column = |v: u32| v % 5;
        for v in 0..weights.len() as u32 {
            if column(v) <= 2 {
                weights[v as usize] = 0.0;
            }
        }
        let pilot = VertexDc { weights: &weights, dc_sums, moments: &moments };
        let Items::Interior { triangles, .. } = &items else { unreachable!() };
        let extra = extra_counts(&mesh, &items, &pilot, 1, 48);
        for (k, &t) in triangles.iter().enumerate() {
            let columns = mesh.triangle(t as usize).map(column);
            // 6 points grow to 16 × 6 = 96, capped at 48: 42 more, where a corner sits in column 2.
            let expected = if columns.contains(&2) { 42 } else { 0 };
            assert_eq!(extra[k], expected, "triangle {t}, columns {columns:?}");
        }
        // No budget (`--adaptive 0`), no search.
        assert!(extra_counts(&mesh, &items, &pilot, 0, 48).iter().all(|&e| e == 0));
    }

    /// The unified layout gives each triangle one item of n + e points in
    /// item order; the extra items hold samples n..n + e of n + e at their
    /// unified places, and only for the items of the range that gained any.
    #[test]
    fn unified_and_extra_items_continue_the_triangles_samples_in_place() {
        let (_, items, ..) = grid_pilot(0);
        let mut extra = vec![0u32; items.len()];
        extra[3] = 9;
        extra[7] = 3;
        let unified = Items::unified(&items, &extra);
        let Items::Interior { triangles, counts, first_sample, first_index, weight_count } = &unified else { unreachable!() };
        assert_eq!(triangles.len(), items.len());
        assert!(first_index.is_empty() && weight_count.is_empty());
        assert_eq!((counts[2], counts[3], counts[7]), (6, 15, 9));
        assert_eq!((first_sample[3], first_sample[4], first_sample[8]), (18, 33, 6 * 8 + 12));
        assert_eq!(unified.point_count(), items.point_count() + 12);
        let extras = Items::extras(&items, &extra, &unified, 0..items.len());
        let Items::Interior { triangles, counts, first_sample, first_index, weight_count } = &extras else { unreachable!() };
        assert_eq!(triangles, &vec![3, 7]);
        assert_eq!((counts.clone(), first_index.clone(), weight_count.clone()), (vec![9, 3], vec![6, 6], vec![15, 9]));
        // Right after each triangle's base points in the unified layout.
        assert_eq!(first_sample, &vec![18 + 6, 6 * 7 + 9 + 6]);
        let later = Items::extras(&items, &extra, &unified, 4..items.len());
        assert_eq!(later.len(), 1);
    }
}
