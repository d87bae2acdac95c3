//! Adaptive refinement driven by the bake (D3DX's adaptive PRT
//! and seed 001's splitting of large triangles, done by error instead of by
//! edge length): split edges where the baked light differs too much between
//! an edge's two vertices, re-bake, and repeat until no edge is over the
//! error or the vertex budget is spent. Coarse where light is smooth, fine at
//! shadow edges and corners; the result is one mesh, a refinement of the
//! input (the surface does not move: new vertices are edge midpoints).
//!
//! **Edge error.** For the transfer ([`refine_transfer`]): each vertex is
//! shaded (luminance) under [`crate::bundle::budget::reference_lightings`], twelve
//! clear skies; an edge's error is the largest difference between its two
//! vertices over the skies, divided by the larger of their mean and that
//! sky's area-weighted mean shading of the input mesh. So `0.1` is a 10 %
//! step where the edge is brighter than the scene's mean (as a tone-mapped
//! view shows it), and a tenth of the mean in the dark, in a dim cabin as
//! under an open sky. For sun masks
//! ([`refine_sun`]): at each day step a vertex's direct sun is `bit × cos`
//! (the cosine of its normal to the sun, two-sided in window mode); an
//! edge's error is the difference averaged over the day's steps, in units
//! of the sun's normal irradiance, and a vertex whose own vote was split
//! (some of its samples lit, some not: a shadow edge crosses its one-ring
//! without flipping a vertex bit) counts as a full difference on its edges.
//!
//! **Which edges.** Edges over the error and longer than `min_edge`,
//! largest expected gain first (transfer: error × length, whose square
//! tracks the squared error the edge's triangles carry; sun: error ×
//! length², the area drawn wrong), as many as the vertex budget allows; [`crate::clean::split_edges`]
//! then splits them (closed over longest edges, so angles stay bounded).
//!
//! **Re-baking.** The transfer re-bakes only the vertices whose one-ring
//! changed (the corners of split triangles), from the triangles around
//! them; the other vertices keep their values, and bounces ≥ 1 gather from
//! the merged previous bounce. Sun masks likewise re-trace only the samples
//! of the triangles around changed vertices and keep the other vertices'
//! bits. Every round is deterministic, so the result does not depend on the
//! thread count.

mod error;
pub mod probe;

use glam::Vec3;

use crate::bake::{self, BakeError, BakeParams, SunMasks, SunParams, Surfaces, TransferResult};
use crate::clean::split_edges;
use crate::mesh::Mesh;
use crate::trace::{BuildQuality, Scene};

pub use error::{sun_edge_errors, transfer_edge_errors, MeanShading};

/// What the user asks of a refinement.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct RefineParams {
    /// Split edges whose error is above this (see the module doc); `None`:
    /// split by error until the budget is spent.
    pub error: Option<f64>,
    /// The mesh never grows past this many vertices.
    pub max_vertices: usize,
    /// Edges this short (world units) are never split.
    pub min_edge: f32,
    /// At most this many split-and-re-bake rounds: a safety stop, far past
    /// what the budget takes (each round spends a share of it, see
    /// [`round_take`]).
    pub max_rounds: u32,
    /// Transfer: a luminance difference counts only past this many standard
    /// errors of the two vertices' estimates (every bounce's spread), so that
    /// noise is not split; 0 counts noise as light.
    pub noise_sigmas: f64,
}

/// The default `min_edge` as a fraction of the mesh's bounding-box diagonal.
pub const DEFAULT_MIN_EDGE_FRACTION: f32 = 2e-4;
/// The default budget: this many times the input's vertices.
pub const DEFAULT_BUDGET_FACTOR: usize = 4;
/// The largest vertex budget accepted: the refined mesh (with its one-rings),
/// its sample points and order-3 colour transfer take about 0.5 KB a vertex,
/// about 12 GB here, half of a 24 GB machine. More is refused before any work.
pub const MAX_VERTICES: usize = 25_000_000;
/// The default round limit (the budget normally ends a refinement in 8–12 rounds).
pub const DEFAULT_MAX_ROUNDS: u32 = 64;
/// The default `noise_sigmas`: a difference two standard errors deep is
/// noise one time in about twenty (the estimate overstates on stratified
/// points, so fewer in practice).
pub const DEFAULT_NOISE_SIGMAS: f64 = 2.0;
/// A round splits at most `1 / ROUND_BUDGET_SHARE` of the vertex budget
/// left, so later rounds see the light the splits revealed ...
const ROUND_BUDGET_SHARE: usize = 4;
/// ... but at least `1 / ROUND_MIN_SHARE` of the whole growth the budget
/// allows, so the budget is spent in a bounded number of rounds instead of
/// an ever smaller share each round.
const ROUND_MIN_SHARE: usize = 8;

/// Vertices a round may add with `room` left of a budget that allows
/// `growth` new vertices in all.
pub fn round_take(room: usize, growth: usize) -> usize {
    room.div_ceil(ROUND_BUDGET_SHARE).max(growth.div_ceil(ROUND_MIN_SHARE)).min(room)
}

/// Rounds the budget still takes from `room` left (each round spending its
/// whole take): an upper bound on the rounds left when no edge converges first.
pub fn rounds_left(mut room: usize, growth: usize) -> usize {
    let mut rounds = 0;
    while room > 0 && rounds < DEFAULT_MAX_ROUNDS as usize {
        room -= round_take(room, growth).max(1);
        rounds += 1;
    }
    rounds
}

impl RefineParams {
    /// `error` and/or `max_vertices` as asked, the rest from `mesh`'s size.
    pub fn for_mesh(mesh: &Mesh, error: Option<f64>, max_vertices: Option<usize>, min_edge: Option<f32>) -> RefineParams {
        RefineParams {
            error,
            max_vertices: max_vertices.unwrap_or(mesh.vertex_count().saturating_mul(DEFAULT_BUDGET_FACTOR).min(MAX_VERTICES)),
            min_edge: min_edge.unwrap_or(DEFAULT_MIN_EDGE_FRACTION * mesh.referenced_diagonal()),
            max_rounds: DEFAULT_MAX_ROUNDS,
            noise_sigmas: DEFAULT_NOISE_SIGMAS,
        }
    }

    /// Checks ranges.
    pub fn check(&self) -> Result<(), BakeError> {
        if let Some(e) = self.error {
            if !(e.is_finite() && e >= 0.0) {
                return Err(BakeError::Params(format!("refine error {e} must be finite and >= 0")));
            }
        }
        if !(self.noise_sigmas.is_finite() && self.noise_sigmas >= 0.0) {
            return Err(BakeError::Params(format!("refine noise sigmas {} must be finite and >= 0", self.noise_sigmas)));
        }
        if !(self.min_edge.is_finite() && self.min_edge >= 0.0) {
            return Err(BakeError::Params(format!("refine min edge {} must be finite and >= 0", self.min_edge)));
        }
        if self.max_vertices > MAX_VERTICES {
            return Err(BakeError::Params(format!("refine budget {} vertices is over the {MAX_VERTICES} that fit", self.max_vertices)));
        }
        Ok(())
    }
}

/// One round of a refinement.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct RoundReport {
    pub vertices: usize,
    pub triangles: usize,
    /// Edges over the error (and longer than `min_edge`) after this round's bake.
    pub edges_over: usize,
    /// Largest edge error after this round's bake.
    pub max_edge_error: f64,
    /// Vertices this round baked (all of them in round 0).
    pub vertices_baked: usize,
    /// Rays traced by this round's bake.
    pub rays_traced: u64,
    pub seconds: f64,
}

/// What a refinement did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct RefineReport {
    pub params: Option<RefineParams>,
    pub rounds: Vec<RoundReport>,
    /// Why it stopped: `converged` (no edge over the error), `budget`,
    /// `min_edge` (every edge over the error is too short) or `rounds`.
    pub stopped: String,
    pub input_vertices: usize,
    pub output_vertices: usize,
    /// Wall time of the whole refinement, and of its BVH builds (one per round).
    pub seconds: f64,
    pub bvh_build_seconds: f64,
}

impl RefineReport {
    /// The report as a bundle's META records it: without timings, so the
    /// bytes depend only on the inputs.
    pub fn meta(&self) -> serde_json::Value {
        let mut value = serde_json::to_value(self).unwrap_or_default();
        if let Some(rounds) = value.get_mut("rounds").and_then(|r| r.as_array_mut()) {
            for round in rounds.iter_mut().filter_map(|r| r.as_object_mut()) {
                round.remove("seconds");
            }
        }
        if let Some(fields) = value.as_object_mut() {
            fields.remove("seconds");
            fields.remove("bvh_build_seconds");
        }
        value
    }

    /// One line for stderr.
    pub fn summary(&self) -> String {
        let last = self.rounds.last().cloned().unwrap_or_default();
        let why = match self.stopped.as_str() {
            "converged" => "converged: no edge over the error",
            "budget" => "the vertex budget is spent (--max-vertices)",
            "min_edge" => "every edge over the error is shorter than --min-edge",
            "rounds" => "the safety limit of rounds",
            other => other,
        };
        format!(
            "refine: {} -> {} vertices in {} round(s), {:.1} s ({:.1} s of BVH builds); stopped: {why}; {} edge(s) over the error, largest {:.4}",
            self.input_vertices,
            self.output_vertices,
            self.rounds.len(),
            self.seconds,
            self.bvh_build_seconds,
            last.edges_over,
            last.max_edge_error
        )
    }
}

/// Refines `mesh` by its transfer (module doc) and returns the refined
/// mesh, its transfer (every bounce's layer kept only when
/// `params.store_bounces`), its surfaces and the report.
pub fn refine_transfer(
    mesh: Mesh,
    params: &BakeParams,
    window_patterns: &[String],
    one_sided_patterns: &[String],
    refine: &RefineParams,
) -> Result<(Mesh, TransferResult, Surfaces, RefineReport), BakeError> {
    params.check()?;
    refine.check()?;
    bake::check_mesh(&mesh)?;
    let mut report = RefineReport { params: Some(*refine), input_vertices: mesh.vertex_count(), ..RefineReport::default() };
    let layered = BakeParams { store_bounces: true, ..*params };
    let mut mesh = mesh;
    let mut surfaces = Surfaces::resolve(&mesh, window_patterns)?.with_one_sided(&mesh, one_sided_patterns)?;
    let whole_start = std::time::Instant::now();
    let scene = Scene::build(&mesh, BuildQuality::Sah)?;
    report.bvh_build_seconds += scene.build_time.as_secs_f64();
    let mut result = bake::bake_transfer(&mesh, &scene, &surfaces, &layered)?;
    drop(scene);
    let mean = MeanShading::of(&mesh, &result);
    let mut baked = mesh.vertex_count();
    let started = std::time::Instant::now();
    let mut totals = result.stats.clone();
    loop {
        let errors = transfer_edge_errors(&mesh, &result, &mean, refine.noise_sigmas);
        let step = next_split(&mesh, &errors, refine, &mut report, baked, &result.stats, transfer_priority, params.quiet);
        let Some(split) = step else { break };
        let vertices_before = mesh.vertex_count();
        let rebake = Rebake::of(&split.mesh, &split.changed_triangles);
        let kept_layers: Vec<Vec<f32>> =
            result.bounces.iter().map(|l| extend_rows(l, vertices_before, split.mesh.vertex_count())).collect();
        mesh = split.mesh;
        surfaces = Surfaces::resolve(&mesh, window_patterns)?.with_one_sided(&mesh, one_sided_patterns)?;
        let scene = Scene::build(&mesh, BuildQuality::Sah)?;
        report.bvh_build_seconds += scene.build_time.as_secs_f64();
        let kept_back: Vec<Vec<f32>> = result.back.iter().map(|l| extend_rows(l, vertices_before, mesh.vertex_count())).collect();
        let kept = bake::transfer::Kept { layers: &kept_layers, back: &kept_back, vertices: &rebake.kept_vertices };
        let kept_noise = extend_rows(&result.noise, vertices_before, mesh.vertex_count());
        let kept_share = extend_rows(&result.front_share, vertices_before, mesh.vertex_count());
        result = bake::transfer::bake_transfer_update(&mesh, &scene, &surfaces, &layered, &rebake.receivers, &kept)?;
        // A kept vertex keeps its value, so it keeps its noise and side share too.
        for (values, kept_values) in [(&mut result.noise, &kept_noise), (&mut result.front_share, &kept_share)] {
            if values.len() == kept_values.len() {
                for (v, value) in values.iter_mut().enumerate().filter(|(v, _)| rebake.kept_vertices[*v]) {
                    *value = kept_values[v];
                }
            }
        }
        baked = rebake.kept_vertices.iter().filter(|&&k| !k).count();
        totals.points += result.stats.points;
        totals.points_rejected += result.stats.points_rejected;
        totals.rays += result.stats.rays;
        totals.rays_traced += result.stats.rays_traced;
        totals.rays_gathered += result.stats.rays_gathered;
    }
    report.output_vertices = mesh.vertex_count();
    report.seconds = whole_start.elapsed().as_secs_f64();
    // The stats count every round's work; the rest describes the final mesh.
    let seconds = started.elapsed().as_secs_f64() + totals.seconds;
    result.stats = bake::BakeStats {
        points: totals.points,
        points_rejected: totals.points_rejected,
        rays: totals.rays,
        rays_traced: totals.rays_traced,
        rays_gathered: totals.rays_gathered,
        seconds,
        rays_per_second: totals.rays_traced as f64 / seconds.max(1e-9),
        evaluations_per_second: totals.rays as f64 / seconds.max(1e-9),
        ..result.stats
    };
    if !params.store_bounces {
        result.bounces.clear();
    }
    Ok((mesh, result, surfaces, report))
}

/// Refines `mesh` by its sun masks over the day `suns` (module doc) and
/// returns the refined mesh, its masks and the report.
pub fn refine_sun(
    mesh: Mesh,
    window_patterns: &[String],
    suns: &[Option<Vec3>],
    params: &SunParams,
    refine: &RefineParams,
) -> Result<(Mesh, SunMasks, RefineReport), BakeError> {
    refine.check()?;
    bake::check_mesh(&mesh)?;
    let mut report = RefineReport { params: Some(*refine), input_vertices: mesh.vertex_count(), ..RefineReport::default() };
    let mut mesh = mesh;
    let started = std::time::Instant::now();
    let surfaces = Surfaces::resolve(&mesh, window_patterns)?;
    let scene = Scene::build(&mesh, BuildQuality::Sah)?;
    report.bvh_build_seconds += scene.build_time.as_secs_f64();
    let (mut masks, mut split_votes) = bake::sun::bake_sun_masks_split(&mesh, &scene, &surfaces, suns, params)?;
    let (mut rays, mut baked) = (masks.stats.rays, mesh.vertex_count());
    loop {
        let errors = sun_edge_errors(&mesh, &masks, &split_votes, suns, params.mode);
        let stats = bake::BakeStats { rays_traced: masks.stats.rays, seconds: masks.stats.seconds, ..Default::default() };
        let Some(split) = next_split(&mesh, &errors, refine, &mut report, baked, &stats, sun_priority, params.quiet) else { break };
        let words = masks.words_per_vertex as usize;
        let rebake = Rebake::of(&split.mesh, &split.changed_triangles);
        let previous_masks = SunMasks { masks: extend_rows(&masks.masks, mesh.vertex_count(), split.mesh.vertex_count()), ..masks };
        let previous_split = extend_rows(&split_votes, mesh.vertex_count(), split.mesh.vertex_count());
        debug_assert_eq!(previous_split.len(), split.mesh.vertex_count() * words);
        mesh = split.mesh;
        let surfaces = Surfaces::resolve(&mesh, window_patterns)?;
        let scene = Scene::build(&mesh, BuildQuality::Sah)?;
        report.bvh_build_seconds += scene.build_time.as_secs_f64();
        (masks, split_votes) = bake::sun::bake_sun_masks_update(
            &mesh,
            &scene,
            &surfaces,
            suns,
            params,
            &rebake.receivers,
            &bake::sun::SunKept { vertices: &rebake.kept_vertices, masks: &previous_masks, split_votes: &previous_split },
        )?;
        rays += masks.stats.rays;
        baked = rebake.kept_vertices.iter().filter(|&&k| !k).count();
    }
    report.output_vertices = mesh.vertex_count();
    report.seconds = started.elapsed().as_secs_f64();
    // The stats count every round's rays; the rest describes the final mesh.
    masks.stats.rays = rays;
    masks.stats.seconds = started.elapsed().as_secs_f64();
    masks.stats.rays_per_second = rays as f64 / masks.stats.seconds.max(1e-9);
    Ok((mesh, masks, report))
}

/// Which transfer edges split first: error × length. Linear interpolation
/// across an edge of length `l` with a jump `e` is wrong by about `e` over
/// a band of area ∝ `l²`, so the squared error it adds is ∝ (e·l)².
fn transfer_priority(error: f64, length: f64) -> f64 {
    error * length
}

/// Which sun edges split first: error × length². The disagreement counted
/// is an area (drawn lit where the sun is blocked, or the reverse), ∝ e·l².
fn sun_priority(error: f64, length: f64) -> f64 {
    error * length * length
}

/// An edge (vertex pair) and its error.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgeError {
    pub edge: [u32; 2],
    pub error: f64,
}

/// Records the round just baked and chooses the next split: `None` when
/// the refinement stops (the reason goes into `report.stopped`).
#[allow(clippy::too_many_arguments)] // the round's state, each needed to choose the split
fn next_split(
    mesh: &Mesh,
    errors: &[EdgeError],
    refine: &RefineParams,
    report: &mut RefineReport,
    vertices_baked: usize,
    stats: &bake::BakeStats,
    priority: fn(f64, f64) -> f64,
    quiet: bool,
) -> Option<crate::clean::EdgeSplit> {
    let threshold = refine.error.unwrap_or(0.0);
    let length = |[a, b]: [u32; 2]| mesh.positions[a as usize].distance(mesh.positions[b as usize]);
    let over: Vec<&EdgeError> = errors.iter().filter(|e| e.error > threshold).collect();
    let mut candidates: Vec<(f64, [u32; 2])> =
        over.iter().filter(|e| length(e.edge) > refine.min_edge).map(|e| (priority(e.error, length(e.edge) as f64), e.edge)).collect();
    report.rounds.push(RoundReport {
        vertices: mesh.vertex_count(),
        triangles: mesh.triangle_count(),
        edges_over: over.len(),
        max_edge_error: errors.iter().map(|e| e.error).fold(0.0, f64::max),
        vertices_baked,
        rays_traced: stats.rays_traced,
        seconds: stats.seconds,
    });
    if !quiet {
        let last = &report.rounds[report.rounds.len() - 1];
        let growth = refine.max_vertices.saturating_sub(report.input_vertices);
        let left = if over.is_empty() { 0 } else { rounds_left(refine.max_vertices.saturating_sub(mesh.vertex_count()), growth) };
        eprintln!(
            "refine round {}: {} of {} vertices ({:.0}% of the budget spent), {} edge(s) over the error {}, largest {:.4}; at most {left} more round(s)",
            report.rounds.len(),
            last.vertices,
            refine.max_vertices,
            100.0 * (last.vertices.saturating_sub(report.input_vertices)) as f64 / growth.max(1) as f64,
            last.edges_over,
            threshold,
            last.max_edge_error
        );
    }
    let stop = |report: &mut RefineReport, why: &str| {
        report.stopped = why.to_string();
        None
    };
    if over.is_empty() {
        return stop(report, "converged");
    }
    if candidates.is_empty() {
        return stop(report, "min_edge");
    }
    if report.rounds.len() > refine.max_rounds as usize {
        return stop(report, "rounds");
    }
    let room = refine.max_vertices.saturating_sub(mesh.vertex_count());
    if room == 0 {
        return stop(report, "budget");
    }
    // Largest integrated error first; ties by edge, so the order is fixed.
    candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    // A round spends a share of the budget (`round_take`), so that later
    // rounds, which see the light the splits revealed, choose the rest.
    // Each split edge adds a vertex (more on creases and through the
    // longest-edge closure): halve the take until the result fits.
    let growth = refine.max_vertices.saturating_sub(report.input_vertices);
    let mut take = candidates.len().min(round_take(room, growth));
    while take > 0 {
        let edges: Vec<[u32; 2]> = candidates[..take].iter().map(|c| c.1).collect();
        let split = split_edges(mesh, &edges);
        if split.mesh.vertex_count() <= refine.max_vertices {
            return Some(split);
        }
        take /= 2;
    }
    stop(report, "budget")
}

/// Which vertices a round re-bakes and from which triangles.
struct Rebake {
    /// True for vertices whose one-ring did not change.
    kept_vertices: Vec<bool>,
    /// Triangles around the re-baked vertices (all their samples are needed).
    receivers: Vec<bool>,
}

impl Rebake {
    fn of(mesh: &Mesh, changed_triangles: &[bool]) -> Rebake {
        let mut kept_vertices = vec![true; mesh.vertex_count()];
        for t in (0..mesh.triangle_count()).filter(|&t| changed_triangles[t]) {
            for v in mesh.triangle(t) {
                kept_vertices[v as usize] = false;
            }
        }
        let receivers = (0..mesh.triangle_count()).map(|t| mesh.triangle(t).iter().any(|&v| !kept_vertices[v as usize])).collect();
        Rebake { kept_vertices, receivers }
    }
}

/// `rows` (one row per vertex of `before` vertices) with zero (default) rows appended up to `after` vertices.
fn extend_rows<T: Copy + Default>(rows: &[T], before: usize, after: usize) -> Vec<T> {
    let stride = rows.len().checked_div(before).unwrap_or(0);
    let mut out = rows.to_vec();
    out.resize(after * stride, T::default());
    out
}

#[cfg(test)]
mod tests;
