//! What a bake traces: its work items (triangles with their sample counts,
//! or vertices), where sample points lie in a triangle and what each weighs.

use crate::bake::receivers::Receivers;
use crate::bake::surfaces::Surfaces;
use crate::bake::twins::Twins;
use crate::bake::{BakeError, BakeParams, Mode, Sampling};
use crate::mesh::Mesh;
use crate::sampling::{hash_seed, sample_2d, square_to_triangle};

/// Stream tags that keep the random streams of different uses apart.
pub(crate) const TAG_POSITION: u32 = 0x5053_0001;

/// The work items of a bake and how their points map to vertices. Their
/// order is the order every sum runs in, whole bake or shards.
pub(crate) enum Items {
    /// Triangles with `counts[k]` samples each; `first_sample[k]` is the
    /// global index of the first. An item holds the triangle's samples
    /// `first_index[k]..first_index[k] + counts[k]` (empty: from 0) of
    /// `weight_count[k]` in all (empty: `counts[k]`), which sets each
    /// sample's weight: a triangle can be split over two items when
    /// adaptive allocation (`bake::transfer::adaptive`) adds samples to it.
    Interior {
        triangles: Vec<u32>,
        counts: Vec<u32>,
        first_sample: Vec<u32>,
        first_index: Vec<u32>,
        weight_count: Vec<u32>,
    },
    Vertex {
        vertices: Vec<u32>,
    },
}

/// One interior item's samples: samples `first_index..first_index + count`
/// of triangle `triangle`'s sequence, at global points `first_sample..`,
/// each weighing `area / weight_count`.
pub(crate) struct ItemSamples {
    pub(crate) triangle: u32,
    pub(crate) count: u32,
    pub(crate) first_sample: u32,
    pub(crate) first_index: u32,
    pub(crate) weight_count: u32,
}

impl Items {
    /// Item `item`'s samples, for an interior layout.
    pub(crate) fn samples(&self, item: usize) -> Option<ItemSamples> {
        let Items::Interior { triangles, counts, first_sample, first_index, weight_count } = self else { return None };
        Some(ItemSamples {
            triangle: triangles[item],
            count: counts[item],
            first_sample: first_sample[item],
            first_index: first_index.get(item).copied().unwrap_or(0),
            weight_count: weight_count.get(item).copied().unwrap_or(counts[item]),
        })
    }
    /// Adaptive allocation's layout: the interior `base` items with `extra[k]`
    /// more samples each, one item of `n + e` points per triangle (samples
    /// 0..n + e of its Sobol sequence, each weighing area / (n + e)), point
    /// indices in item order.
    pub(crate) fn unified(base: &Items, extra: &[u32]) -> Items {
        let Items::Interior { triangles, counts, .. } = base else { unreachable!("adaptive allocation needs interior sampling") };
        let counts: Vec<u32> = counts.iter().zip(extra).map(|(&n, &e)| n + e).collect();
        let mut first_sample = Vec::with_capacity(counts.len());
        let mut next = 0u32;
        for &c in &counts {
            first_sample.push(next);
            // Saturates past u32: `check_point_count` refuses such a bake.
            next = next.saturating_add(c);
        }
        Items::Interior { triangles: triangles.clone(), counts, first_sample, first_index: Vec::new(), weight_count: Vec::new() }
    }

    /// The extra points of the `base` items in `range` as items of their own,
    /// one per item with `extra[k] > 0`: samples `n..n + e` of `n + e`, at
    /// their places in the `unified` layout.
    pub(crate) fn extras(base: &Items, extra: &[u32], unified: &Items, range: std::ops::Range<usize>) -> Items {
        let (Items::Interior { triangles, counts, .. }, Items::Interior { first_sample: unified_first, .. }) = (base, unified) else {
            unreachable!("adaptive allocation needs interior sampling")
        };
        let with_extra: Vec<usize> = range.filter(|&k| extra[k] > 0).collect();
        Items::Interior {
            triangles: with_extra.iter().map(|&k| triangles[k]).collect(),
            counts: with_extra.iter().map(|&k| extra[k]).collect(),
            first_sample: with_extra.iter().map(|&k| unified_first[k] + counts[k]).collect(),
            first_index: with_extra.iter().map(|&k| counts[k]).collect(),
            weight_count: with_extra.iter().map(|&k| counts[k] + extra[k]).collect(),
        }
    }

    pub(crate) fn len(&self) -> usize {
        match self {
            Items::Interior { triangles, .. } => triangles.len(),
            Items::Vertex { vertices } => vertices.len(),
        }
    }
    pub(crate) fn corners(&self) -> usize {
        match self {
            Items::Interior { .. } => 3,
            Items::Vertex { .. } => 1,
        }
    }
    /// Global index of the first point of `item` (`len()`: the point count).
    pub(crate) fn first_point(&self, item: usize) -> usize {
        match self {
            Items::Interior { first_sample, .. } => match first_sample.get(item) {
                Some(&first) => first as usize,
                None => self.point_count() as usize,
            },
            Items::Vertex { .. } => item,
        }
    }
    pub(crate) fn point_count(&self) -> u64 {
        match self {
            Items::Interior { counts, .. } => counts.iter().map(|&c| c as u64).sum(),
            Items::Vertex { vertices } => vertices.len() as u64,
        }
    }
    /// Sample points of each item, in item order (what a shard's share is measured in).
    pub(crate) fn points_per_item(&self) -> Vec<u32> {
        match self {
            Items::Interior { counts, .. } => counts.clone(),
            Items::Vertex { vertices } => vec![1; vertices.len()],
        }
    }
    /// The receivers item `item`'s corners add to (a vertex item: its vertex, thrice).
    pub(crate) fn corner_receivers(&self, receivers: &Receivers, item: usize) -> [u32; 3] {
        match self {
            Items::Interior { triangles, .. } => receivers.of_triangle(triangles[item]),
            Items::Vertex { vertices } => [vertices[item]; 3],
        }
    }
    /// The first item that adds to each receiver (`u32::MAX`: none): a range
    /// of items holds a receiver's first sums exactly when it holds this item.
    pub(crate) fn first_items(&self, receivers: &Receivers) -> Vec<u32> {
        let mut first = vec![u32::MAX; receivers.count()];
        for item in 0..self.len() {
            for &r in &self.corner_receivers(receivers, item)[..self.corners()] {
                let slot = &mut first[r as usize];
                *slot = (*slot).min(item as u32);
            }
        }
        first
    }
}

/// The items of a bake: [`build_items`] on the mesh, and in open mode
/// with bounces (two-sided, interior sampling) the twins of the sampled
/// triangles whose back can be lit, appended as items of their own with
/// their triangle's sample count (the density is the mesh's), on the
/// augmented mesh `bake::twins` makes. `None` when there are no twins.
pub(crate) fn build_items_with_twins(
    mesh: &Mesh,
    surfaces: &Surfaces,
    sampled: Vec<u32>,
    params: &BakeParams,
    receivers: Option<&[bool]>,
) -> (Items, Option<(Mesh, Surfaces, Twins)>) {
    let wants_twins = params.two_sided && params.mode == Mode::Open && params.bounces > 0 && params.sampling != Sampling::Vertex;
    let twinned = if wants_twins { crate::bake::twins::twinned_triangles(mesh, surfaces, &sampled) } else { Vec::new() };
    let items = build_items(mesh, sampled, params, receivers);
    if !twinned.iter().any(|&t| t) {
        return (items, None);
    }
    let (aug, aug_surfaces, twins) = crate::bake::twins::augment(mesh, surfaces, &twinned);
    let Items::Interior { mut triangles, mut counts, mut first_sample, .. } = items else { unreachable!("twins need interior sampling") };
    let count_of: std::collections::HashMap<u32, u32> = triangles.iter().copied().zip(counts.iter().copied()).collect();
    let mut next = counts.iter().fold(0u32, |a, &c| a.saturating_add(c));
    for (k, &source) in twins.source_triangle.iter().enumerate() {
        // A twin receives where its triangle does (view-box culling, partial re-bakes).
        let Some(&count) = count_of.get(&source) else { continue };
        triangles.push((twins.triangles + k) as u32);
        counts.push(count);
        first_sample.push(next);
        next = next.saturating_add(count);
    }
    (
        Items::Interior { triangles, counts, first_sample, first_index: Vec::new(), weight_count: Vec::new() },
        Some((aug, aug_surfaces, twins)),
    )
}

/// Lists the work items: the `sampled` triangles (interior sampling), or
/// their vertices (vertex sampling).
pub(crate) fn build_items(mesh: &Mesh, sampled: Vec<u32>, params: &BakeParams, receivers: Option<&[bool]>) -> Items {
    let receives = |t: u32| receivers.is_none_or(|r| r[t as usize]);
    match params.sampling {
        Sampling::Vertex => {
            let mut used = vec![false; mesh.vertex_count()];
            for &t in sampled.iter().filter(|&&t| receives(t)) {
                for v in mesh.triangle(t as usize) {
                    used[v as usize] = true;
                }
            }
            Items::Vertex { vertices: (0..mesh.vertex_count() as u32).filter(|&v| used[v as usize]).collect() }
        }
        Sampling::Interior { samples_per_vertex, max_per_triangle } => {
            // Density comes from the whole scene, so a culled bake samples its
            // kept triangles exactly as a full bake would.
            let layout = interior_layout(mesh, sampled, samples_per_vertex, max_per_triangle);
            let (triangles, counts): (Vec<u32>, Vec<u32>) =
                layout.triangles.iter().zip(&layout.counts).filter(|(&t, _)| receives(t)).map(|(&t, &c)| (t, c)).unzip();
            let mut first_sample = Vec::with_capacity(counts.len());
            let mut next = 0u32;
            for &c in &counts {
                first_sample.push(next);
                // Saturates past u32: `check_point_count` refuses such a bake.
                next = next.saturating_add(c);
            }
            Items::Interior { triangles, counts, first_sample, first_index: Vec::new(), weight_count: Vec::new() }
        }
    }
}

/// Triangles that receive samples: neither windows nor degenerate. Refuses
/// a mesh with none: its bake would store nothing but zeros.
pub(crate) fn sampled_triangles(mesh: &Mesh, surfaces: &Surfaces) -> Result<Vec<u32>, NothingToBake> {
    let is_window = |t: u32| surfaces.window_transmittance[t as usize].is_some();
    let sampled: Vec<u32> = (0..mesh.triangle_count() as u32).filter(|&t| !is_window(t) && triangle_area(mesh, t) > 0.0).collect();
    if !sampled.is_empty() {
        return Ok(sampled);
    }
    let windows = (0..mesh.triangle_count() as u32).filter(|&t| is_window(t)).count();
    Err(NothingToBake { triangles: mesh.triangle_count(), windows, degenerate: mesh.triangle_count() - windows })
}

/// Why a bake would store nothing: no triangle receives light, because
/// each is a window (light passes through it) or degenerate (zero area).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("nothing to bake: {}", why_nothing_receives(*.triangles, *.windows, *.degenerate))]
pub struct NothingToBake {
    pub triangles: usize,
    pub windows: usize,
    /// Opaque triangles of zero area.
    pub degenerate: usize,
}

/// [`NothingToBake`]'s reason in words, a lone triangle named as such.
pub(crate) fn why_nothing_receives(triangles: usize, windows: usize, degenerate: usize) -> String {
    match (triangles, windows, degenerate) {
        (0, _, _) => "the mesh has no triangles".into(),
        (1, 1, _) => "the only triangle is a window: no surface receives light".into(),
        (1, _, _) => "the only triangle is degenerate (zero area)".into(),
        (n, w, _) if w == n => format!("every triangle is a window ({n} of {n}): no surface receives light"),
        (n, 0, _) => format!("all {n} triangles are degenerate (zero area)"),
        (n, w, d) => {
            let windows = if w == 1 { "is a window" } else { "are windows" };
            let degenerate = if d == 1 { "is degenerate" } else { "are degenerate" };
            format!("no triangle receives light: of {n}, {w} {windows} and {d} {degenerate} (zero area)")
        }
    }
}

/// Where interior samples go: `counts[k]` samples in `triangles[k]`, whose
/// global sample indices start at `first_sample[k]` (a prefix sum).
pub(crate) struct InteriorLayout {
    pub triangles: Vec<u32>,
    pub counts: Vec<u32>,
    pub first_sample: Vec<u32>,
}

impl InteriorLayout {
    /// Total number of samples.
    pub fn sample_count(&self) -> u64 {
        self.counts.iter().map(|&c| c as u64).sum()
    }
}

/// Spreads about `samples_per_vertex × vertex count` samples over `triangles`
/// by area (at least three, at most `max_per_triangle`, per triangle; see
/// [`samples_in_triangle`]). The one placement rule transfer and sun masks share.
pub(crate) fn interior_layout(mesh: &Mesh, triangles: Vec<u32>, samples_per_vertex: f32, max_per_triangle: u32) -> InteriorLayout {
    let total_area: f64 = triangles.iter().map(|&t| triangle_area(mesh, t) as f64).sum();
    let density = samples_per_vertex as f64 * mesh.vertex_count() as f64 / total_area.max(f64::MIN_POSITIVE);
    let counts: Vec<u32> =
        triangles.iter().map(|&t| samples_in_triangle(triangle_area(mesh, t) as f64 * density, max_per_triangle)).collect();
    let mut first_sample = Vec::with_capacity(counts.len());
    let mut next = 0u32;
    for &c in &counts {
        first_sample.push(next);
        // Saturates past u32: `check_point_count` refuses such a bake.
        next = next.saturating_add(c);
    }
    InteriorLayout { triangles, counts, first_sample }
}

/// Sample points are indexed with `u32`: refuses a bake with more.
pub(crate) fn check_point_count(points: u64) -> Result<(), BakeError> {
    if points > u32::MAX as u64 {
        return Err(BakeError::Params(format!(
            "{points} sample points, more than the {} this baker indexes: lower the samples per vertex",
            u32::MAX
        )));
    }
    Ok(())
}

/// Sample count for a triangle that should get `expected` samples: the
/// nearest multiple of three, at least three (one rotation triple, see
/// [`triangle_sample`]) and at most `max` rounded down to a multiple of
/// three (but three when `max` is smaller). The count sets only the noise:
/// each sample is weighted by the area it stands for ([`crate::bake::receivers::point_weights`]),
/// and a whole triple gives each corner exactly a third of that area, so
/// the normalising weights are exact at every density. (A lone uniform
/// point would leave its weight to chance: a ratio estimator's bias and
/// more noise; a lone centroid would estimate the centroid's value.)
pub(crate) fn samples_in_triangle(expected: f64, max: u32) -> u32 {
    let triples = (expected / 3.0).round().max(1.0) as u32;
    3 * triples.min((max / 3).max(1))
}

/// Barycentrics of sample `s` in mesh triangle `t` (vertex indices
/// `corners`) for a bake seeded with `seed`: the same points whatever pass
/// asks (transfer, sun masks).
///
/// The points are laid out on the corners sorted by vertex index, then
/// mapped back: a triangle whose winding is flipped (its corners listed in
/// another order) gets the same points, so window mode stays side-blind.
///
/// Samples come as the three cyclic rotations of one Owen-scrambled Sobol
/// point (each uniform over the triangle). A symmetric set gives each
/// corner the same total barycentric weight (a third of the samples), so the
/// normalising weights are exact, and the mean position each corner receives
/// leans toward no neighbour: smooth transfer is reproduced to second order.
/// Independent points leave a first-order bias (measured: 1.1e-2 in band 1
/// on the 2,562-vertex icosphere, against 1.5e-4 at the vertices).
#[inline]
pub(crate) fn triangle_sample(pattern: crate::sampling::DirectionPattern, seed: u32, t: u32, corners: [u32; 3], s: u32) -> [f32; 3] {
    let (u1, u2) = sample_2d(pattern, s / 3, 0, hash_seed(&[seed, TAG_POSITION, t]));
    let b = square_to_triangle(u1, u2);
    let sorted = match s % 3 {
        0 => b,
        1 => [b[1], b[2], b[0]],
        _ => [b[2], b[0], b[1]],
    };
    let mut order = [0usize, 1, 2];
    order.sort_unstable_by_key(|&k| corners[k]);
    let mut out = [0.0; 3];
    for (rank, &corner) in order.iter().enumerate() {
        out[corner] = sorted[rank];
    }
    out
}

pub(crate) fn triangle_area(mesh: &Mesh, t: u32) -> f32 {
    let [a, b, c] = mesh.triangle_positions(t as usize);
    0.5 * (b - a).cross(c - a).length()
}
