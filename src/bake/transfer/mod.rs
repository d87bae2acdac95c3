//! Per-vertex SH transfer, bounce by bounce (DESIGN.md "Transfer"; seed 000 §4.1, eq. 6).
//!
//! Bounce 0:  t_i⁽⁰⁾(x) = 1/π ∫ y_i(ω) V(x,ω) c(n,ω) dω
//! Bounce b:  t_i⁽ᵇ⁾(x) = 1/π ∫ ρ(h) t_i⁽ᵇ⁻¹⁾(h) [h opaque] c(n,ω) dω
//!
//! Open mode: c = max(n·ω,0), V = 1 when the ray escapes. Window mode: c = |n·ω|,
//! V = τ when the first hit is a window, except on a side of the point outside
//! the enclosure ([`Sides`], docs/conventions.md). Directions are drawn with
//! pdf ∝ c, so each ray's weight is a constant: 1/N (hemisphere) or 2/N (sphere).
//!
//! Points: stratified samples inside each triangle (seed 000 §4.1.1) whose
//! results go to the triangle's vertices by barycentric weight times the area
//! each sample stands for ([`crate::bake::receivers::point_weights`]): a vertex's value estimates the
//! hat-weighted mean of the transfer over its one-ring (docs/conventions.md),
//! whatever the sample density. Or the vertices
//! themselves (`Sampling::Vertex`, kept for comparison: it leaks shadows where
//! triangles overlap). Accumulation runs in fixed item order, so the bytes do
//! not depend on the thread count.

use super::surfaces::Surfaces;
use super::{BakeError, BakeParams, TransferResult};
use crate::mesh::Mesh;
use crate::trace::scene::Scene;

pub(crate) mod adaptive;
pub(crate) mod fit;
pub(crate) mod items;
mod layers;
mod normalise;
pub(crate) mod plan;
mod run;
pub(crate) mod texel_adaptive;
pub(crate) mod texels;
mod update;

pub use items::NothingToBake;
pub(crate) use items::*;
pub(crate) use layers::{bake_layers, bake_layers_with_texels, Kept};
pub(crate) use normalise::*;
pub(crate) use plan::*;
pub(crate) use run::*;
pub(crate) use update::bake_transfer_update;

/// What a vertex's transfer means, recorded in every bundle's META
/// (`conventions.vertex_transfer`): bundles before it (no such key) averaged
/// samples by barycentric weight alone, with one centroid sample on small
/// triangles, so their values depended on the sample density.
pub const VERTEX_ESTIMATOR: &str =
    "estimator 2: hat-weighted mean of the transfer over the vertex's one-ring, parts inside geometry excluded (docs/conventions.md)";

/// Default largest hit cache kept in memory (bytes, [`BakeParams::hit_cache_bytes`]);
/// beyond it later bounces re-trace their rays.
pub const HIT_CACHE_BUDGET_BYTES: u64 = 6 << 30;

/// A hit cache budget for this machine: half the memory available now
/// (Linux `MemAvailable`), or [`HIT_CACHE_BUDGET_BYTES`] where that is
/// unknown. The bytes of a bake never depend on it, only its speed.
pub fn available_hit_cache_bytes() -> u64 {
    // The host's free memory, and a container's limit where one is set
    // (cgroup v2, then v1): /proc/meminfo shows the host's even inside one.
    let read = |path: &str| std::fs::read_to_string(path).ok();
    let available = read("/proc/meminfo").and_then(|info| {
        let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
        line.split_whitespace().nth(1)?.parse::<u64>().ok().map(|kib| kib.saturating_mul(1024))
    });
    let container = ["/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"]
        .iter()
        .find_map(|path| read(path)?.trim().parse::<u64>().ok());
    match (available, container) {
        (None, None) => HIT_CACHE_BUDGET_BYTES,
        (a, c) => a.unwrap_or(u64::MAX).min(c.unwrap_or(u64::MAX)) / 2,
    }
}

/// Bakes transfer for every vertex. Runs on the current rayon pool.
pub fn bake_transfer(mesh: &Mesh, scene: &Scene, surfaces: &Surfaces, params: &BakeParams) -> Result<TransferResult, BakeError> {
    bake_transfer_receivers(mesh, scene, surfaces, params, None)
}

/// [`bake_transfer`] with rays shot only from the triangles flagged in
/// `receivers` (one flag per triangle; `None` = all), while every triangle
/// still occludes: the view-box culling of seed 001 §5 ("precomputing shadows
/// we use the whole dataset"). A kept triangle gets exactly the samples and
/// rays it gets in a full bake (the sample density is that of the full mesh);
/// vertices touching no receiver get zero. Bounces ≥ 1 gather from hit
/// triangles' previous bounce, which is zero on non-receivers: pass `None`
/// when bounces follow, or accept that light.
///
/// Precondition: `receivers`, if given, has one entry per triangle.
///
/// Errors: bad parameters, or a mesh on which no triangle receives light
/// (each a window or of zero area: [`NothingToBake`]), whose bake would
/// store only zeros.
pub fn bake_transfer_receivers(
    mesh: &Mesh,
    scene: &Scene,
    surfaces: &Surfaces,
    params: &BakeParams,
    receivers: Option<&[bool]>,
) -> Result<TransferResult, BakeError> {
    bake_layers(mesh, scene, surfaces, params, receivers, None)
}

/// Sample points of the base layout of a bake of `mesh` with `params`
/// (before adaptive allocation adds any): a sharded bake's merge reports
/// `BakeStats::points_added` against it, as a whole bake does.
pub fn base_point_count(mesh: &Mesh, surfaces: &Surfaces, params: &BakeParams) -> Result<u64, BakeError> {
    Ok(build_items_with_twins(mesh, surfaces, sampled_triangles(mesh, surfaces)?, params, None).0.point_count())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::Sampling;
    use crate::bake::{bake_mesh, BakeError};
    use crate::verify::shapes;

    #[test]
    fn point_counts_past_u32_are_refused_not_wrapped() {
        assert!(super::check_point_count(u32::MAX as u64).is_ok());
        let error = super::check_point_count(u32::MAX as u64 + 1).unwrap_err().to_string();
        assert!(error.contains("4294967296 sample points") && error.contains("samples per vertex"), "{error}");
    }

    /// Spheres passing through each other: a point's inside verdict comes
    /// from the same 32 probe directions whatever `--rays` is; with fewer
    /// rays the probe-only ones are traced a short reach (twice the reject
    /// distance), and the points rejected are the same.
    #[test]
    fn the_inside_verdict_does_not_depend_on_the_rays() {
        let mut mesh = shapes::icosphere(3);
        for x in [0.7f32, 1.4] {
            let mut other = shapes::icosphere(3);
            shapes::transform(&mut other, 1.0, glam::Vec3::new(x, 0.1 * x, 0.0));
            shapes::append(&mut mesh, &other);
        }
        let rejected = |rays: u32| {
            let params = BakeParams { order: 2, rays, seed: 4, adaptive: 0.0, ..BakeParams::default() };
            let stats = bake_mesh(&mesh, &params, &[]).unwrap().0.stats;
            (stats.points_rejected, stats.vertices_without_samples, stats.points)
        };
        let full = rejected(32);
        assert!(full.0 > full.2 / 10, "the fixture has points inside geometry: {full:?}");
        for rays in [1, 8, 31] {
            assert_eq!(rejected(rays), full, "{rays} rays");
        }
    }

    /// A plane of 8 triangles whose first `windows` are windows and whose
    /// next `degenerate` ones are collapsed to a point.
    fn plane_with(windows: usize, degenerate: usize) -> (Mesh, Vec<String>) {
        let mut mesh = shapes::plane_grid(2, 1.0);
        mesh.groups = vec!["wall".into(), "glass".into()];
        mesh.tri_group = (0..8).map(|t| u32::from(t < windows)).collect();
        for t in windows..windows + degenerate {
            let [a, b, c] = mesh.triangle(t);
            // A fresh vertex per corner, all at one point: neighbours keep their area.
            for (k, v) in [a, b, c].into_iter().enumerate() {
                mesh.positions.push(mesh.positions[a as usize]);
                mesh.normals.push(mesh.normals[v as usize]);
                mesh.indices[3 * t + k] = mesh.positions.len() as u32 - 1;
            }
        }
        (mesh, vec!["glass".into()])
    }

    /// A bake in which no triangle receives light (every one a window or of
    /// zero area) is refused, saying which; one receiving triangle is enough.
    #[test]
    fn a_bake_where_no_triangle_receives_light_is_refused_with_the_reason() {
        let params = BakeParams { rays: 8, ..BakeParams::default() };
        let vertex = BakeParams { sampling: Sampling::Vertex, ..params };
        for (windows, degenerate, reason) in [
            (8, 0, "nothing to bake: every triangle is a window (8 of 8): no surface receives light"),
            (0, 8, "nothing to bake: all 8 triangles are degenerate (zero area)"),
            (3, 5, "nothing to bake: no triangle receives light: of 8, 3 are windows and 5 are degenerate (zero area)"),
            (7, 1, "of 8, 7 are windows and 1 is degenerate (zero area)"),
        ] {
            let (mesh, patterns) = plane_with(windows, degenerate);
            for params in [params, vertex] {
                let refused = bake_mesh(&mesh, &params, &patterns).err().expect("refused");
                let expected = NothingToBake { triangles: 8, windows, degenerate };
                assert!(matches!(&refused, BakeError::NothingToBake(n) if *n == expected), "{refused:?}");
                assert!(refused.to_string().contains(reason), "{refused}");
            }
        }
        let (mesh, patterns) = plane_with(4, 3);
        let result = bake_mesh(&mesh, &params, &patterns).unwrap().0;
        assert!(result.stats.points > 0 && result.total.iter().any(|&t| t > 0.0));
    }

    #[test]
    fn one_or_no_triangle_is_named_plainly() {
        let message = |triangles, windows, degenerate| NothingToBake { triangles, windows, degenerate }.to_string();
        assert_eq!(message(0, 0, 0), "nothing to bake: the mesh has no triangles");
        assert_eq!(message(1, 1, 0), "nothing to bake: the only triangle is a window: no surface receives light");
        assert_eq!(message(1, 0, 1), "nothing to bake: the only triangle is degenerate (zero area)");
    }
}
