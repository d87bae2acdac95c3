//! Texel density per chart: fine texels where a chart's light changes (a
//! slat shadow, a contact shadow), coarse ones where it is even (a wall the
//! sun never reaches).
//!
//! A pilot bake on an atlas at the coarsest size measures, per chart, the
//! squared error of storing it at that size ([`ChartDetail`], made by the
//! texel bakes from their own values). [`choose_levels`] then halves the
//! texel size of the chart that buys the most error per added texel, again
//! and again, until the estimate is within the budget; and
//! [`Atlas::with_chart_scales`] repacks the pilot's charts, each scaled by
//! `2^level`, with xatlas.
//!
//! The error model is an edge's: a chart's squared error (area-weighted)
//! halves each time its texel size does (an edge crosses twice the texels,
//! each a quarter of the area). Smooth light falls faster (a quarter), so the
//! model refines more than it must there, never less.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use glam::Vec2;

use super::coverage::Coverage;
use super::{xatlas_ffi, Atlas, AtlasError, NO_CHART, PADDING};

/// Most levels of density (texel sizes `L`, `2L`, … `2^(MAX_LEVELS-1) L`).
pub const MAX_LEVELS: u32 = 4;

/// What a pilot bake measured of each chart of its atlas.
#[derive(Clone, Debug, PartialEq)]
pub struct ChartDetail {
    /// Per chart: the squared error of storing it at the pilot's texel size,
    /// summed over its texels weighted by their covered area (texels²).
    pub error: Vec<f64>,
    /// Per chart: its covered area at the pilot's size (texels²).
    pub area: Vec<f64>,
    /// Σ covered area × value² over all texels: the denominator of the
    /// relative L2 error.
    pub signal: f64,
}

impl ChartDetail {
    /// Sums over each chart's covered texels of `coverage` (of `atlas`):
    /// `measure(i)` gives covered texel `i`'s squared error and squared value
    /// per unit of area, weighted here by the area its triangles cover.
    pub fn from_texels(atlas: &Atlas, coverage: &Coverage, measure: impl Fn(usize) -> (f64, f64)) -> ChartDetail {
        let charts = atlas.chart_count as usize;
        let mut detail = ChartDetail { error: vec![0.0; charts], area: vec![0.0; charts], signal: 0.0 };
        for i in 0..coverage.len() {
            let range = coverage.start[i] as usize..coverage.start[i + 1] as usize;
            let chart = atlas.triangle_chart[coverage.triangle[range.start] as usize] as usize;
            let area = coverage.area[range].iter().map(|&a| f64::from(a)).sum::<f64>().min(1.0);
            let (error, value) = measure(i);
            detail.error[chart] += area * error;
            detail.area[chart] += area;
            detail.signal += area * value;
        }
        detail
    }
}

/// Each chart's level of density and what the choice is estimated to give.
#[derive(Clone, Debug, PartialEq)]
pub struct DensityChoice {
    /// Per chart of the pilot's atlas: 0 keeps the pilot's (coarsest) texel
    /// size, k halves it k times.
    pub levels: Vec<u8>,
    /// Charts at each level, coarsest first.
    pub charts_per_level: Vec<u32>,
    /// Estimated relative L2 error of the stored texels' resolution, after the
    /// choice and with every chart at the pilot's size.
    pub estimated_error: f64,
    pub coarsest_error: f64,
    /// Estimated covered texels after the choice, and with every chart at the finest size.
    pub texel_area: f64,
    pub finest_texel_area: f64,
}

/// A chart's next refinement, ordered by error removed per texel added
/// (ties: the lower chart first, so the choice is the same on every machine).
struct Step {
    gain_per_texel: f64,
    chart: u32,
}

impl PartialEq for Step {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Step {}
impl PartialOrd for Step {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Step {
    fn cmp(&self, other: &Self) -> Ordering {
        self.gain_per_texel.total_cmp(&other.gain_per_texel).then_with(|| other.chart.cmp(&self.chart))
    }
}

/// Picks each chart's level (0 ..= `levels - 1`) so that the estimated
/// relative L2 error, `sqrt(Σ error_c / 2^level_c / signal)`, is at most
/// `budget` with the fewest texels, greedily: the chart whose next halving
/// removes the most error per texel it adds goes first. When even the
/// finest size everywhere is over the budget, every chart with any error is
/// at the finest.
pub fn choose_levels(detail: &ChartDetail, levels: u32, budget: f64) -> DensityChoice {
    let charts = detail.error.len();
    let top = levels.clamp(1, MAX_LEVELS) as u8 - 1;
    let mut level = vec![0u8; charts];
    let allowed = budget.max(0.0).powi(2) * detail.signal;
    let mut total: f64 = detail.error.iter().sum();
    let coarsest = total;
    let step = |c: usize, k: u8| {
        // Halving removes half the chart's error at level k and adds 3 × its area × 4^k.
        let gain = detail.error[c] / f64::from(1u32 << (k + 1));
        let cost = 3.0 * detail.area[c] * f64::from(1u32 << (2 * k));
        Step { gain_per_texel: if cost > 0.0 { gain / cost } else { 0.0 }, chart: c as u32 }
    };
    let mut heap: BinaryHeap<Step> =
        (0..charts).filter(|&c| top > 0 && detail.error[c] > 0.0 && detail.area[c] > 0.0).map(|c| step(c, 0)).collect();
    while total > allowed {
        let Some(next) = heap.pop() else { break };
        let c = next.chart as usize;
        total -= detail.error[c] / f64::from(1u32 << (level[c] + 1));
        level[c] += 1;
        if level[c] < top {
            heap.push(step(c, level[c]));
        }
    }
    let relative = |e: f64| if detail.signal > 0.0 { (e.max(0.0) / detail.signal).sqrt() } else { 0.0 };
    let texel_area = (0..charts).map(|c| detail.area[c] * f64::from(1u32 << (2 * level[c]))).sum::<f64>();
    DensityChoice {
        charts_per_level: (0..=top).map(|k| level.iter().filter(|&&l| l == k).count() as u32).collect(),
        estimated_error: relative(total),
        coarsest_error: relative(coarsest),
        texel_area,
        finest_texel_area: detail.area.iter().sum::<f64>() * f64::from(1u32 << (2 * top)),
        levels: level,
    }
}

impl Atlas {
    /// This atlas's charts repacked at `texel_size` when that is this
    /// atlas's over 1, 2, 4 or 8 ([`Atlas::with_chart_scales`], every chart
    /// alike): a second atlas of the same mesh that shares the first's
    /// charts and costs no unwrap. `None` for any other ratio.
    pub fn with_texel_size(&self, texel_size: f32) -> Option<Result<Atlas, AtlasError>> {
        let level = self.repack_level(texel_size)?;
        Some(match level {
            0 => Ok(self.clone()),
            _ => self.with_chart_scales(&vec![level as u8; self.chart_count as usize]),
        })
    }

    /// k when `texel_size` is this atlas's over 2^k, k < [`MAX_LEVELS`].
    pub fn repack_level(&self, texel_size: f32) -> Option<u32> {
        // Halving an f32 is exact, so 0.08 / 8 is 0.01 as the user typed it.
        (0..MAX_LEVELS).find(|&k| self.texel_size / (1u32 << k) as f32 == texel_size)
    }

    /// This atlas's charts repacked, chart `c` scaled by `2^levels[c]`:
    /// the same triangles in the same charts, at texel size `texel_size /
    /// 2^levels[c]` each. The result's [`Atlas::texel_size`] is the finest
    /// chart's. Packed as [`Atlas::unwrap`] packs (xatlas, [`PADDING`],
    /// bilinear), so no texel holds or blends two charts.
    pub fn with_chart_scales(&self, levels: &[u8]) -> Result<Atlas, AtlasError> {
        if levels.len() != self.chart_count as usize || levels.iter().any(|&l| u32::from(l) >= MAX_LEVELS) {
            return Err(AtlasError::Refused(format!(
                "{} chart levels for {} charts (each below {MAX_LEVELS})",
                levels.len(),
                self.chart_count
            )));
        }
        let triangles = self.triangle_count();
        let mut uv = self.uv.clone();
        let mut scaled = vec![false; uv.len()];
        // Triangles in no chart are made degenerate, so that xatlas leaves them out again.
        let mut indices = self.indices.clone();
        for t in 0..triangles {
            let chart = self.triangle_chart[t];
            if chart == NO_CHART {
                indices[3 * t + 1] = indices[3 * t];
                indices[3 * t + 2] = indices[3 * t];
                continue;
            }
            let scale = (1u32 << levels[chart as usize]) as f32;
            for &v in &self.indices[3 * t..3 * t + 3] {
                if !scaled[v as usize] {
                    uv[v as usize] *= scale;
                    scaled[v as usize] = true;
                }
            }
        }
        let finest = levels.iter().copied().max().unwrap_or(0);
        let texel_size = self.texel_size / (1u32 << finest) as f32;
        // SAFETY: the declaration points into `uv`, `indices` and the charts (one material each),
        // which outlive the calls (xatlas copies them in AddUvMesh); the
        // atlas is read before it is destroyed, within the counts it gives.
        let mut packed = unsafe {
            use xatlas_ffi as x;
            let mut decl = std::mem::MaybeUninit::<x::UvMeshDecl>::uninit();
            x::xatlasUvMeshDeclInit(decl.as_mut_ptr());
            let mut decl = decl.assume_init();
            decl.vertexUvData = uv.as_ptr().cast();
            decl.vertexStride = std::mem::size_of::<Vec2>() as u32;
            decl.vertexCount = uv.len() as u32;
            decl.indexData = indices.as_ptr().cast();
            decl.indexCount = indices.len() as u32;
            decl.indexFormat = x::INDEX_FORMAT_UINT32;
            decl.faceMaterialData = self.triangle_chart.as_ptr();
            let handle = x::xatlasCreate();
            x::check_added(handle, x::xatlasAddUvMesh(handle, &decl)).map_err(AtlasError::Refused)?;
            x::xatlasComputeCharts(handle, &x::chart_options());
            // The input is in texels of the pilot's size, scaled per chart.
            x::xatlasPackCharts(handle, &x::pack_options(1.0, PADDING));
            let result = Self::read(&*handle, triangles, texel_size);
            x::xatlasDestroy(handle);
            result?
        };
        // A UV mesh's output vertex is its input vertex (`xref`): this atlas's.
        packed.source_vertex = packed.source_vertex.iter().map(|&v| self.source_vertex[v as usize]).collect();
        for t in (0..triangles).filter(|&t| self.triangle_chart[t] == NO_CHART) {
            packed.indices[3 * t..3 * t + 3].copy_from_slice(&self.indices[3 * t..3 * t + 3]);
            packed.triangle_chart[t] = NO_CHART;
        }
        if let Some(t) = (0..triangles).find(|&t| (self.triangle_chart[t] == NO_CHART) != (packed.triangle_chart[t] == NO_CHART)) {
            return Err(AtlasError::Refused(format!("repacking left triangle {t} out of its chart")));
        }
        Ok(packed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::verify::shapes;
    use glam::Vec3;

    fn detail(error: &[f64], area: &[f64], signal: f64) -> ChartDetail {
        ChartDetail { error: error.to_vec(), area: area.to_vec(), signal }
    }

    /// The greedy order on three charts worked by hand: chart 0's first
    /// halving removes 2 for 3 texels, chart 2's 0.5 for 3, chart 0's second
    /// 1 for 12, chart 2's second 0.25 for 12; a chart with no error never
    /// moves. Each budget stops the walk at the first total within it.
    #[test]
    fn levels_go_where_they_remove_most_error_per_texel_until_the_budget_holds() {
        let d = detail(&[4.0, 0.0, 1.0], &[1.0, 10.0, 1.0], 100.0);
        let at = |budget: f64| choose_levels(&d, 3, budget);
        // Totals along the walk: 5 → 3 → 2.5 → 1.5 → 1.25 (relative: sqrt(total / 100)).
        for (budget, levels, total) in [
            (0.3, vec![0, 0, 0], 5.0),
            (0.2, vec![1, 0, 0], 3.0),
            (0.17, vec![1, 0, 1], 2.5),
            (0.13, vec![2, 0, 1], 1.5),
            (0.0, vec![2, 0, 2], 1.25),
        ] {
            let c = at(budget);
            assert_eq!(c.levels, levels, "budget {budget}");
            assert!((c.estimated_error - (total / 100.0f64).sqrt()).abs() < 1e-12, "budget {budget}: {}", c.estimated_error);
            assert!((c.coarsest_error - 0.05f64.sqrt()).abs() < 1e-12);
            let texels: f64 = levels.iter().zip(&d.area).map(|(&l, a)| a * 4f64.powi(i32::from(l))).sum();
            assert_eq!(c.texel_area, texels);
            assert_eq!(c.finest_texel_area, 12.0 * 16.0);
            assert_eq!(c.charts_per_level.iter().sum::<u32>(), 3);
        }
        // One level is the uniform atlas; nothing to measure keeps everything coarse.
        assert_eq!(choose_levels(&d, 1, 0.0).levels, vec![0, 0, 0]);
        assert_eq!(choose_levels(&detail(&[0.0, 0.0], &[1.0, 1.0], 0.0), 3, 0.0).levels, vec![0, 0]);
    }

    /// Two 2 m squares apart, unwrapped at 0.1 m (charts about 20 texels
    /// wide), one chart scaled by 4: its triangles keep their chart and their
    /// corners' mesh vertices, its atlas area grows 16× (the other's stays,
    /// both within xatlas's rounding of a chart's extent up to whole texels),
    /// no texel holds or blends two charts, and the result is the same on a
    /// second run.
    #[test]
    fn a_chart_scaled_by_two_levels_takes_sixteen_times_the_texels_and_nothing_else_changes() {
        let mut mesh = shapes::plane_grid(2, 2.0);
        let mut other = shapes::plane_grid(2, 2.0);
        shapes::transform(&mut other, 1.0, Vec3::new(5.0, 0.0, 0.0));
        shapes::append(&mut mesh, &other);
        let atlas = Atlas::unwrap(&mesh, 0.1).unwrap();
        assert!(atlas.chart_count >= 2);
        let first = atlas.triangle_chart[0];
        let levels: Vec<u8> = (0..atlas.chart_count).map(|c| if c == first { 2 } else { 0 }).collect();
        let scaled = atlas.with_chart_scales(&levels).unwrap();
        assert_eq!(scaled, atlas.with_chart_scales(&levels).unwrap(), "repacking is not deterministic");
        assert_eq!(scaled.texel_size, 0.025);
        assert_eq!(scaled.chart_count, atlas.chart_count);
        assert_eq!(scaled.texels_mixing_charts(), (0, 0));
        for t in 0..mesh.triangle_count() {
            for k in 0..3 {
                assert_eq!(
                    scaled.source_vertex[scaled.indices[3 * t + k] as usize],
                    atlas.source_vertex[atlas.indices[3 * t + k] as usize]
                );
            }
        }
        let area = |a: &Atlas, t: usize| {
            let [p, q, r] = a.triangle_uv(t);
            0.5 * f64::from((q - p).perp_dot(r - p).abs())
        };
        for chart in 0..atlas.chart_count {
            let members: Vec<usize> = (0..mesh.triangle_count()).filter(|&t| atlas.triangle_chart[t] == chart).collect();
            let new_chart = scaled.triangle_chart[members[0]];
            assert!(members.iter().all(|&t| scaled.triangle_chart[t] == new_chart), "chart {chart} was split");
            let before: f64 = members.iter().map(|&t| area(&atlas, t)).sum();
            let after: f64 = members.iter().map(|&t| area(&scaled, t)).sum();
            let expected = if chart == first { 16.0 } else { 1.0 };
            assert!((after / before / expected - 1.0).abs() < 0.12, "chart {chart}: area ×{} for ×{expected}", after / before);
        }
        assert!(atlas.with_chart_scales(&levels[1..]).is_err(), "a level per chart is required");
    }
}
