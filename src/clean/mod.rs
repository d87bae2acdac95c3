//! Mesh clean-up before baking: weld, remove degenerate, duplicate and covered
//! coplanar triangles, zip cracks and T-junctions, cut where surfaces pass
//! through each other (optional), split long edges, flip slivers, orient components.
//!
//! Why: PRT samples visibility on the mesh, and CAD or scanned meshes break it
//! (Sloan-style PRT on industrial data, §4.1.1: "duplicated triangles, cracks
//! between patches resulting from the NURBS tessellation, overlapping triangles,
//! and sometimes quite irregular meshing"; Dellepiane et al. §5.2 on scans: "very
//! large triangles and self-intersecting parts", split recursively, redundant parts
//! removed). A crack lets light into a closed body; a twin triangle shadows its
//! sibling; a sliver's vertices cannot resolve a shadow edge.
//!
//! How (meshoptimizer's style): every step is a remap table or a rewrite of flat
//! buffers; see [`work`] for the point/vertex split every step shares. Pipeline:
//!
//! 1. weld positions within `weld_tolerance`, then vertices whose normals differ
//!    by at most `hard_edge_angle_deg` and whose UVs and colours agree ([`weld`]);
//! 2. remove degenerate triangles ([`degenerate`]);
//! 3. remove duplicates, flipped included ([`duplicates`]);
//! 4. remove coplanar triangles covered by others, report partial overlaps ([`coplanar`]);
//! 5. zip boundary cracks and T-junctions ([`zip`]), then re-run 2, 3 and 4;
//!    with `cut_intersections`, cut every triangle along the segments where
//!    other triangles cross it ([`intersect`]: a wall running past a wall, a
//!    floor under and past a wall); the welds below then keep the two sides
//!    of each cut line apart (vertices are split and merged per wedge,
//!    [`weld::merge_vertices`]);
//! 6. orient components ([`orient`]), then weld vertices again (zipping and
//!    orienting make new agreements, and flips need shared vertices);
//! 7. split edges longer than `max_edge`, flip slivers ([`refine`]);
//! 8. weld once more, drop unused vertices, keep the order of the rest.
//!
//! The cut's triangles under 1° are repaired after it ([`needles`]). Where
//! the repair cannot raise them (a chair's tube crossing another at a
//! grazing angle, a cup's foot sunk 0.75 mm into a table), the clean runs
//! again, up to [`MAX_CUT_RETRIES`] times, leaving their crossings uncut
//! (the pairs of triangles first, then all crossings of their surfaces,
//! edge-connected patches of one material): a millimetre of overlap leaks
//! no light a vertex can see, and a needle draws a streak. The report lists
//! them per pair of materials; `cut_every_crossing` cuts them anyway.
//!
//! A step can enable another that ran before it (a zip makes two patches overlap,
//! a weld lets an edge flip), so the whole pipeline repeats until a round repairs
//! nothing, at most [`MAX_ROUNDS`] times: cleaning a cleaned mesh then changes
//! nothing (the report says whether the last round was clean, and if not,
//! `retriggered` names each repair the last round still made).
//!
//! Every step is near-linear in triangles at any valence: a fan around one point
//! (a big polygon face, a cone's apex) costs what a grid does
//! ([`hub_pairs`]; `benches/clean.rs`, docs/performance.md).
//!
//! Outside the pipeline, [`split_edges`] splits chosen edges of a finished
//! mesh (the same red-green splits, closed over longest edges): adaptive
//! refinement (`crate::refine`) calls it where the bake finds the light changing.
//!
//! Keep-rules are deterministic: the smallest index survives (vertex, point or
//! triangle). Same input and parameters give the same bytes.
//!
//! **Judgement on two-sided sheets:** a flipped duplicate is removed by default
//! (the baker shades both sides with |n·ω| and pushes ray origins off the surface),
//! see [`duplicates`]; `keep_two_sided` keeps one triangle per winding.
//!
//! **Area:** the report's `area_before` is the input's total area and
//! `area_after` the output's; `redundant_area_removed` is the area of the
//! triangles removed as degenerate, duplicate or covered (copies of surface
//! that stays). The rest of the change is the repairs': flips and splits are
//! exact, zipping changes the area only by the crack it closes (a band of the
//! crack's width; on the Ferrari, +1.8e-5 relative, as thin triangles along
//! boundaries collapse).
//!
//! **Self-intersections** (non-coplanar) are cut only with `cut_intersections`
//! (default off for now; measured on the dining room, the grey-white room and
//! the Ferrari in docs/performance.md). Limits: segments shorter than the zip
//! tolerance are not cut, and a pair of input triangles is cut at most once
//! per clean (see [`intersect`]).
//!
//! Not done (yet): hole filling.

mod coplanar;
mod degenerate;
mod duplicates;
pub mod fixtures;
mod hub_pairs;
mod intersect;
mod needles;
mod orient;
mod planar;
mod refine;
mod report;
mod spatial;
mod split;
mod weld;
mod work;
mod zip;

pub use report::{CleanReport, DefectKind, DefectReport, OverlapReport, UncutCrossings, UnorientableComponent};
pub use split::{split_edges, EdgeSplit};

use std::collections::{HashMap, HashSet};
use std::time::Instant;

use crate::mesh::Mesh;
use work::{corner_key, count_boundary_and_non_manifold, Work};

/// A length given relative to the mesh's bounding-box diagonal, or absolutely.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub enum Tolerance {
    /// A fraction of the bounding-box diagonal of the referenced vertices.
    Relative(f32),
    /// World units.
    Absolute(f32),
}

impl Tolerance {
    /// The tolerance in world units for a mesh of bounding-box diagonal `diagonal`.
    pub fn resolve(self, diagonal: f32) -> f32 {
        match self {
            Tolerance::Relative(r) => r * diagonal,
            Tolerance::Absolute(a) => a,
        }
    }

    fn value(self) -> f32 {
        match self {
            Tolerance::Relative(v) | Tolerance::Absolute(v) => v,
        }
    }
}

/// Parameters of [`clean_mesh`]. `Copy`; start from [`CleanParams::default`] or a preset.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct CleanParams {
    /// Positions closer than this become one point (default `Relative(1e-6)`).
    /// Also the height under which a triangle counts as degenerate.
    pub weld_tolerance: Tolerance,
    /// Vertices at one point stay apart when their normals differ by more than this
    /// (degrees, 0..=180; default 60): hard edges survive welding.
    pub hard_edge_angle_deg: f32,
    /// Triangles with a smallest angle below this (degrees) are slivers to flip
    /// away where possible; 0 disables (default 5).
    pub sliver_min_angle_deg: f32,
    /// Split edges longer than this (world units) recursively; `None` (default) keeps them.
    pub max_edge: Option<f32>,
    /// Distance from a plane within which triangles count as coplanar (default `Relative(1e-5)`).
    pub coplanar_tolerance: Tolerance,
    /// Boundary cracks narrower than this are zipped (default `Relative(1e-4)`).
    pub zip_tolerance: Tolerance,
    /// Make winding consistent per component (default true).
    pub orient: bool,
    /// Remove coplanar triangles covered by others (default true); overlaps are reported either way.
    pub remove_covered: bool,
    /// Zip cracks and T-junctions (default true).
    pub zip: bool,
    /// Keep one triangle per winding of a duplicated set (two-sided sheets); default false.
    pub keep_two_sided: bool,
    /// Cut triangles along the lines where other triangles pass through them,
    /// and keep the two sides of every such line apart (default false; see
    /// [`intersect`]): a wall running past another, a floor running under and
    /// past a wall stop leaking the light outside into the room.
    pub cut_intersections: bool,
    /// With `cut_intersections`: cut every crossing, also those whose cut
    /// leaves triangles under 1° that the needle repair cannot raise (default
    /// false: the clean runs again leaving those pairs of surfaces uncut, and
    /// reports them).
    pub cut_every_crossing: bool,
}

impl Default for CleanParams {
    fn default() -> Self {
        CleanParams {
            weld_tolerance: Tolerance::Relative(1e-6),
            hard_edge_angle_deg: 60.0,
            sliver_min_angle_deg: 5.0,
            max_edge: None,
            coplanar_tolerance: Tolerance::Relative(1e-5),
            zip_tolerance: Tolerance::Relative(1e-4),
            orient: true,
            remove_covered: true,
            zip: true,
            keep_two_sided: false,
            cut_intersections: false,
            cut_every_crossing: false,
        }
    }
}

impl CleanParams {
    /// Tessellated CAD (NURBS patches): the defaults, everything on.
    pub fn cad() -> Self {
        CleanParams::default()
    }

    /// Scans: smooth normals everywhere (no hard edges to keep), no zipping of the
    /// scan's many small holes; split triangles longer than `max_edge`.
    pub fn scan(max_edge: Option<f32>) -> Self {
        CleanParams { hard_edge_angle_deg: 180.0, zip: false, max_edge, ..CleanParams::default() }
    }

    /// Only welding, degenerate and duplicate removal: never moves or adds geometry.
    pub fn minimal() -> Self {
        CleanParams { sliver_min_angle_deg: 0.0, orient: false, remove_covered: false, zip: false, ..CleanParams::default() }
    }

    /// Checks every field's range.
    pub fn validate(&self) -> Result<(), CleanError> {
        let bad = |name: &'static str, problem: String| Err(CleanError::InvalidParams { name, problem });
        for (name, tol) in [
            ("weld_tolerance", self.weld_tolerance),
            ("coplanar_tolerance", self.coplanar_tolerance),
            ("zip_tolerance", self.zip_tolerance),
        ] {
            if !(tol.value().is_finite() && tol.value() >= 0.0) {
                return bad(name, format!("{:?} must be finite and >= 0", tol));
            }
        }
        if !(0.0..=180.0).contains(&self.hard_edge_angle_deg) {
            return bad("hard_edge_angle_deg", format!("{} is not in 0..=180", self.hard_edge_angle_deg));
        }
        if !(0.0..60.0).contains(&self.sliver_min_angle_deg) {
            return bad("sliver_min_angle_deg", format!("{} is not in 0..60", self.sliver_min_angle_deg));
        }
        if let Some(m) = self.max_edge {
            if !(m.is_finite() && m > 0.0) {
                return bad("max_edge", format!("{} must be finite and > 0", m));
            }
        }
        Ok(())
    }
}

/// Why [`clean_mesh`] refused its input.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CleanError {
    /// A vertex attribute is NaN or infinite.
    #[error("mesh clean-up: vertex {vertex} has a non-finite {attribute}: {value}")]
    NonFinite { vertex: u32, attribute: &'static str, value: String },
    /// The mesh breaks an invariant of [`Mesh::validate`].
    #[error("mesh clean-up: invalid mesh: {0}")]
    InvalidMesh(String),
    /// A parameter is out of range.
    #[error("mesh clean-up: parameter {name}: {problem}")]
    InvalidParams { name: &'static str, problem: String },
    /// More vertices or triangles than `u32` indices address.
    #[error("mesh clean-up: {0} elements do not fit u32 indices")]
    TooLarge(usize),
    /// Coordinates so far apart that the f32 geometry overflows (the bake's limit).
    #[error("mesh clean-up: {0}")]
    Extent(#[from] crate::trace::SceneError),
}

/// Cleans `mesh` (see the module doc for the steps) and reports every repair.
///
/// The output keeps the material table, group names, material roles, UVs and
/// colours; new vertices (splits) interpolate attributes along their edge.
/// Triangle order follows the input (split triangles follow their parent's slot
/// and the end of the list).
///
/// # Errors
/// [`CleanError::NonFinite`] names the first vertex with a NaN or infinite position,
/// normal, UV or colour; [`CleanError::InvalidMesh`] for a broken invariant;
/// [`CleanError::InvalidParams`] for a parameter out of range.
pub fn clean_mesh(mesh: &Mesh, params: &CleanParams) -> Result<(Mesh, CleanReport), CleanError> {
    clean_mesh_timed(mesh, params).map(|(mesh, report, _)| (mesh, report))
}

/// [`clean_mesh`], with the seconds each step took over all rounds.
pub fn clean_mesh_timed(mesh: &Mesh, params: &CleanParams) -> Result<(Mesh, CleanReport, StepTimes), CleanError> {
    params.validate()?;
    check_input(mesh)?;
    if let Some(max_edge) = params.max_edge {
        refine::check_split_size(mesh, max_edge)?;
    }
    // Crossings whose cut leaves triangles under the needle angle that the
    // repair cannot raise are left uncut: the clean runs again without them.
    let mut skip = intersect::Skips::default();
    let input_corners = params.cut_intersections.then(|| InputCorners::of(mesh));
    let mut all_times = StepTimes::default();
    let mut retries = 0;
    loop {
        let mut memo = intersect::CutMemo::skipping(skip.clone());
        let (round, mut report, times) = clean_rounds(mesh, params, &mut memo);
        all_times.absorb(&times);
        let made = input_corners.as_ref().map(|corners| cut_made(mesh, corners, &round, &memo, retries));
        let more = made.as_ref().map_or(intersect::Skips::default(), |m| m.causes.clone());
        let nothing_more = more.triangles.is_subset(&skip.triangles) && more.surfaces.is_subset(&skip.surfaces);
        if nothing_more || retries == MAX_CUT_RETRIES || params.cut_every_crossing {
            report.cut_surface_pairs_left_uncut = skip.surfaces.len();
            report.cut_triangle_pairs_left_uncut = skip.triangles.len();
            report.cut_retries = retries;
            if let Some(made) = made.filter(|m| m.min_angle.is_finite()) {
                report.cut_min_angle_deg = Some(made.min_angle.to_degrees() as f32);
                report.cut_needles_left = made.needles;
            }
            // Canonical order: what `bake --clean` bakes is what a cleaned file loads as.
            let mut clock = Instant::now();
            let mesh = round.mesh.into_canonical_order();
            all_times.lap("weld again and report", &mut clock);
            return Ok((mesh, report, all_times));
        }
        skip.triangles.extend(more.triangles);
        skip.surfaces.extend(more.surfaces);
        retries += 1;
    }
}

/// Runs rounds of the pipeline until one repairs nothing (or [`MAX_ROUNDS`]).
fn clean_rounds(mesh: &Mesh, params: &CleanParams, memo: &mut intersect::CutMemo) -> (Round, CleanReport, StepTimes) {
    let identity: Vec<u32> = (0..mesh.triangle_count() as u32).collect();
    let mut flipped = refine::FlippedEdges::default();
    let mut round = clean_once(mesh, params, &identity, &mut flipped, memo);
    let mut report = round.report.clone();
    let mut times = round.times.clone();
    report.rounds = 1;
    // Repeat until a round repairs nothing, so that cleaning a cleaned mesh is a no-op.
    while round.report.repairs() > 0 && report.rounds < MAX_ROUNDS {
        round = clean_once(&round.mesh, params, &round.origin, &mut flipped, memo);
        report.absorb(&round.report, round.removed_area);
        times.absorb(&round.times);
        report.rounds += 1;
    }
    report.converged = round.report.repairs() == 0;
    report.retriggered = round.report.repair_counts().iter().filter(|&&(_, n)| n > 0).map(|&(name, n)| (name.to_string(), n)).collect();
    report.ready_to_bake = report.converged || report.last_round_share() <= report::READY_SHARE;
    (round, report, times)
}

/// The triangles of a clean's final mesh that its cut made: changed from
/// the input, on a triangle a crossing changed or with a corner that is no
/// input position (the needle repair after the cut splits and flips into
/// the triangles around the cut ones).
struct CutMade {
    /// Their smallest angle (radians; infinite when there are none).
    min_angle: f64,
    /// How many are needles: under 1°, and thinner than the input triangle
    /// they came from (a cut through a triangle that was already a needle
    /// makes needles no repair can avoid; the cut made it no worse).
    needles: usize,
    /// The crossings to leave uncut next time, wider with each retry: the
    /// pairs of triangles whose crossing touched a needle's triangle (or,
    /// where none did, the triangles around its corners; a needle that
    /// outlives that lies where the neighbours' crossings meet it); then
    /// every crossing of their pairs of surfaces; then every crossing of the
    /// surfaces that cut their regions.
    causes: intersect::Skips,
}

/// The input's triangles (by corner positions) and positions (by bits):
/// what the cut's check compares the output with, the same every retry.
struct InputCorners {
    triangles: HashSet<[[u32; 3]; 3]>,
    points: HashSet<[u32; 3]>,
}

impl InputCorners {
    fn of(input: &Mesh) -> Self {
        InputCorners {
            triangles: (0..input.triangle_count()).map(|t| corner_key(input.triangle_positions(t))).collect(),
            points: input.positions.iter().map(|&p| bits(p)).collect(),
        }
    }
}

/// A position's bits: the key of an exact position.
fn bits(p: glam::Vec3) -> [u32; 3] {
    p.to_array().map(f32::to_bits)
}

fn cut_made(input: &Mesh, input_corners: &InputCorners, round: &Round, memo: &intersect::CutMemo, retry: usize) -> CutMade {
    let mesh = &round.mesh;
    // The triangles at each position, for needles no crossing touched.
    let mut around: HashMap<[u32; 3], Vec<u32>> = HashMap::new();
    for t in 0..mesh.triangle_count() {
        mesh.triangle_positions(t).iter().for_each(|&p| around.entry(bits(p)).or_default().push(t as u32));
    }
    let needle = NEEDLE_ANGLE_DEG.to_radians();
    let mut made = CutMade { min_angle: f64::INFINITY, needles: 0, causes: intersect::Skips::default() };
    for t in 0..mesh.triangle_count() {
        let corners = mesh.triangle_positions(t);
        let crossed = memo.causes(round.origin[t], false).next().is_some();
        let moved = corners.iter().any(|&p| !input_corners.points.contains(&bits(p)));
        if !(crossed || moved) || input_corners.triangles.contains(&corner_key(corners)) {
            continue;
        }
        let angle = work::min_angle(corners.map(|p| p.as_dvec3()));
        made.min_angle = made.min_angle.min(angle);
        // A needle is thinner than 1° and than the input triangle it came from.
        let parent = work::min_angle(input.triangle_positions(round.origin[t] as usize).map(|p| p.as_dvec3()));
        if angle >= needle.min(parent) {
            continue;
        }
        made.needles += 1;
        let origins: Vec<u32> = match crossed {
            true => vec![round.origin[t]],
            false => corners.iter().flat_map(|&p| &around[&bits(p)]).map(|&u| round.origin[u as usize]).collect(),
        };
        let next = &mut made.causes;
        for origin in origins {
            let direct = memo.causes(origin, true);
            match retry {
                0 => next.triangles.extend(direct.map(|c| c.triangles)),
                1 => next.surfaces.extend(direct.map(|c| c.surfaces)),
                _ => next.surfaces.extend(memo.causes(origin, false).map(|c| c.surfaces)),
            }
        }
    }
    made
}

/// Times the clean runs again leaving uncut the crossings whose cut left needles.
const MAX_CUT_RETRIES: usize = 3;

/// Upper bound on clean-up rounds. Measured: the Ferrari (359k triangles) converges
/// in 3 rounds, the grey-white room (143k, many coplanar overlaps) in 7.
pub const MAX_ROUNDS: usize = 8;

/// The cut's triangles under this angle (degrees) are repaired after it
/// ([`needles`]): a vertex interpolated across a thinner triangle cannot
/// resolve the light along it.
const NEEDLE_ANGLE_DEG: f64 = 1.0;

/// The result of one round of the pipeline.
struct Round {
    mesh: Mesh,
    report: CleanReport,
    /// Original input triangle of each output triangle.
    origin: Vec<u32>,
    /// Area of the redundant triangles removed (degenerate, duplicate, covered).
    removed_area: f64,
    /// Seconds each step took.
    times: StepTimes,
}

/// Seconds each step of the clean-up took, summed over its rounds: where a
/// slow clean spends its time (`clean`'s time line). Kept out of
/// [`CleanReport`], which holds only what the same input always gives.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StepTimes {
    /// Steps in pipeline order: (name, seconds).
    pub steps: Vec<(&'static str, f64)>,
}

impl StepTimes {
    fn add(&mut self, name: &'static str, seconds: f64) {
        match self.steps.iter_mut().find(|(n, _)| *n == name) {
            Some((_, t)) => *t += seconds,
            None => self.steps.push((name, seconds)),
        }
    }

    /// Adds the time since `*since` to step `name` and restarts the clock.
    fn lap(&mut self, name: &'static str, since: &mut Instant) {
        let now = Instant::now();
        self.add(name, (now - *since).as_secs_f64());
        *since = now;
    }

    fn absorb(&mut self, later: &StepTimes) {
        later.steps.iter().for_each(|&(name, t)| self.add(name, t));
    }
}

/// One pass of the pipeline over a validated mesh. `origin` maps `mesh`'s triangles
/// to the original input's, for the ids in the report; `flipped` holds the edges
/// earlier rounds flipped, which are not flipped again.
fn clean_once(
    mesh: &Mesh,
    params: &CleanParams,
    origin: &[u32],
    flipped: &mut refine::FlippedEdges,
    memo: &mut intersect::CutMemo,
) -> Round {
    let diagonal = mesh.referenced_diagonal();
    let weld_tol = params.weld_tolerance.resolve(diagonal);
    let plane_tol = params.coplanar_tolerance.resolve(diagonal);
    let zip_tol = params.zip_tolerance.resolve(diagonal);
    let cos_hard_edge = params.hard_edge_angle_deg.to_radians().cos();
    let sliver_rad = (params.sliver_min_angle_deg as f64).to_radians();
    // A contact within the weld tolerance counts (never below 1e-9 of the diagonal).
    let contact_tol = (weld_tol as f64).max(1e-9 * diagonal as f64);
    let mut times = StepTimes::default();
    let mut clock = Instant::now();

    let mut r = CleanReport {
        input_triangles: mesh.triangle_count(),
        input_vertices: mesh.vertex_count(),
        weld_tolerance: weld_tol,
        coplanar_tolerance: plane_tol,
        zip_tolerance: zip_tol,
        ..CleanReport::default()
    };
    let input_area: f64 = (0..mesh.triangle_count())
        .map(|t| {
            let [a, b, c] = mesh.triangle_positions(t).map(|p| p.as_dvec3());
            0.5 * (b - a).cross(c - a).length()
        })
        .sum();

    // 1. Weld.
    let mut work = weld::weld_points(mesh, weld_tol);
    // With the cut, vertices of two wedges (the sides of a cut line) never
    // merge; they are split per wedge only from step 6 on, once duplicates
    // (whose shared edges look non-manifold) are gone.
    let (keep, split) = match params.cut_intersections {
        true => (weld::Seams::Keep, weld::Seams::Split),
        false => (weld::Seams::Ignore, weld::Seams::Ignore),
    };
    // The cut lines of a cut mesh, found again by their geometry: never welded across.
    let seams = |work: &Work| match params.cut_intersections {
        true => intersect::find_seams(work, contact_tol),
        false => weld::SeamEdges::new(),
    };
    let step1_seams = seams(&work);
    r.welded_vertices = merge(&mut work, cos_hard_edge, keep, &step1_seams, &mut r);
    r.boundary_edges_before = count_boundary_and_non_manifold(&work).0;
    times.lap("weld", &mut clock);

    // 2-4. Remove redundant triangles.
    let mut removed_area = remove_degenerate_and_duplicates(&mut work, mesh, weld_tol, params, &mut r);
    work.compact_triangles();
    removed_area += remove_covered(&mut work, plane_tol, params, &mut r);
    work.compact_triangles();
    times.lap("duplicates and overlaps", &mut clock);

    // 5. Zip.
    if params.zip {
        let z = zip::zip_boundaries(&mut work, zip_tol);
        r.zipped_edges = z.zipped_edges;
        r.tjunctions_fixed = z.tjunctions;
        r.degenerate_removed += z.collapsed;
        removed_area += remove_degenerate_and_duplicates(&mut work, mesh, weld_tol, params, &mut r);
        if z.welded_points + z.tjunctions > 0 {
            // Zipping moved points: patches may now cover each other.
            removed_area += remove_covered(&mut work, plane_tol, params, &mut r);
        }
        work.compact_triangles();
    }
    times.lap("zip", &mut clock);

    // 5b. Cut where triangles cross (after zipping: cracks closed, copies gone).
    // The triangles before the cut, or (rounds after it) this round's input:
    // what is not among them was made here, and its needles are repaired.
    let before_cut: Option<HashSet<[[u32; 3]; 3]>> = match (params.cut_intersections, memo.has_cut()) {
        (true, true) => Some((0..mesh.triangle_count()).map(|t| corner_key(mesh.triangle_positions(t))).collect()),
        (true, false) => Some((0..work.tris.len()).filter(|&t| work.tri_alive[t]).map(|t| corner_key(work.tri_positions(t))).collect()),
        (false, _) => None,
    };
    let mut cut_seams = weld::SeamEdges::new();
    // Once per clean: the rounds after it meet the cut's own pieces, whose
    // points f32 rounded off their lines, and cutting those again made new
    // slivers for the next round to remove (20 thin triangles crossing at a
    // point: 5,285 triangles, not converged after 8 rounds).
    if params.cut_intersections && !memo.has_cut() {
        let tolerances =
            intersect::CutTolerances { plane: plane_tol as f64, contact: contact_tol, min_length: zip_tol as f64, min_angle: sliver_rad };
        let c = intersect::cut_intersections(&mut work, &tolerances, memo);
        r.crossing_pairs = c.pairs;
        let name = |m: u16| mesh.materials.get(m as usize).map_or_else(|| format!("material {m}"), |m| m.name.clone());
        r.cut_left_uncut =
            c.skipped.iter().map(|(&(a, b), &n)| report::UncutCrossings { materials: [name(a), name(b)], triangle_pairs: n }).collect();
        r.intersections_cut = c.pieces;
        r.triangles_cut = c.triangles_cut;
        r.cut_crossings_unshared = c.unshared_splits;
        r.cut_failures = c.dropped_pieces + c.failed_triangles;
        r.cut_points_added = c.refinement_points;
        r.cut_lines_separated = c.lines_separated;
        r.cut_shared_edges_left = c.shared_left;
        r.cut_edges_collapsed = c.edges_collapsed;
        if c.triangles_cut > 0 {
            r.cut_min_angle_deg = Some(c.min_angle.to_degrees() as f32);
            r.cut_replaced_min_angle_deg = Some(c.replaced_min_angle.to_degrees() as f32);
        }
        cut_seams.extend(c.seams);
    }
    times.lap("cut", &mut clock);

    // 6. Orient (before refining: flips need consistent winding).
    if params.orient {
        let o = orient::orient_components(&mut work);
        r.triangles_flipped = o.flipped;
        r.unorientable_components = o.unorientable;
        r.unorientable_component_count = o.unorientable_count;
    }
    // Zipping and orienting make vertices agree; merged vertices let edges flip.
    cut_seams.extend(seams(&work));
    r.welded_vertices += merge(&mut work, cos_hard_edge, split, &cut_seams, &mut r);
    times.lap("orient", &mut clock);

    // 6b. Needles made since the cut: collapsed or refined away (after the
    // weld, so vertices agree across the edges they may flip).
    if let Some(before) = before_cut.filter(|_| memo.has_cut()) {
        let made: Vec<bool> =
            (0..work.tris.len()).map(|t| work.tri_alive[t] && !before.contains(&corner_key(work.tri_positions(t)))).collect();
        let tolerances = needles::NeedleTolerances {
            min_angle: NEEDLE_ANGLE_DEG.to_radians(),
            collapse: zip_tol as f64,
            plane: plane_tol as f64,
            height: weld_tol as f64,
            spacing: zip_tol as f64,
        };
        let n = needles::repair_needles(&mut work, &made, &tolerances);
        r.cut_needles_repaired = n.needles_before.saturating_sub(n.needles_after);
        r.cut_needles_left = n.needles_after;
        r.cut_needle_collapses = n.sides_collapsed;
        r.cut_needle_points = n.points_inserted + n.edges_split;
        if n.min_angle_after.is_finite() {
            r.cut_min_angle_deg = Some(n.min_angle_after.to_degrees() as f32);
        }
        work.compact_triangles();
        times.lap("cut needles", &mut clock);
    }

    // 7. Refine.
    let slivers_before = refine::count_slivers(&work, sliver_rad);
    if let Some(max_edge) = params.max_edge {
        r.edges_split = refine::split_long_edges(&mut work, max_edge);
    }
    r.sliver_flips = refine::flip_slivers(&mut work, sliver_rad, plane_tol, weld_tol, params.max_edge, flipped);
    r.slivers_fixed = slivers_before.saturating_sub(refine::count_slivers(&work, sliver_rad));
    times.lap("slivers and long edges", &mut clock);

    // 8. Weld again and write out.
    let step8_seams = seams(&work);
    r.welded_vertices += merge(&mut work, cos_hard_edge, split, &step8_seams, &mut r);
    work.compact_triangles();
    let (boundary, non_manifold) = count_boundary_and_non_manifold(&work);
    r.boundary_edges_after = boundary;
    r.non_manifold_edges = non_manifold;
    r.area_before = input_area;
    r.redundant_area_removed = removed_area;
    r.area_after = work.total_area();
    let out = write_mesh(&work, mesh);
    r.output_triangles = out.triangle_count();
    r.output_vertices = out.vertex_count();
    r.worst = report::worst_defects(&work, &out, params);
    // Report ids of the original input, not of this round's.
    let to_input = |t: u32| origin[t as usize];
    r.partial_overlaps.iter_mut().for_each(|o| (o.tri_a, o.tri_b) = (to_input(o.tri_a), to_input(o.tri_b)));
    r.unorientable_components.iter_mut().for_each(|c| c.seed_triangle = to_input(c.seed_triangle));
    let origin = work.tri_origin.iter().map(|&t| to_input(t)).collect();
    times.lap("weld again and report", &mut clock);
    Round { mesh: out, report: r, origin, removed_area, times }
}

/// Merges vertices (steps 1, 6 and 8), keeping or splitting wedges apart
/// (`seams`), so cut lines stay hard. Returns the vertices merged.
fn merge(work: &mut Work, cos_hard_edge: f32, seams: weld::Seams, cut_seams: &weld::SeamEdges, r: &mut CleanReport) -> usize {
    let (merged, split) = weld::merge_vertices(work, cos_hard_edge, seams, cut_seams);
    r.seam_vertices_split += split;
    merged
}

/// Steps 2 and 3; adds to the report's counts and returns the area removed.
fn remove_degenerate_and_duplicates(work: &mut Work, input: &Mesh, weld_tol: f32, params: &CleanParams, r: &mut CleanReport) -> f64 {
    let (degenerate, degenerate_area) = degenerate::remove_degenerate(work, weld_tol);
    r.degenerate_removed += degenerate;
    let dup = duplicates::remove_duplicates(work, input, params.keep_two_sided);
    r.duplicates_removed += dup.same;
    r.flipped_duplicates_removed += dup.flipped;
    r.near_duplicates_removed += dup.near;
    degenerate_area + dup.area
}

/// Step 4; adds to the report's counts, replaces its overlaps, returns the area removed.
fn remove_covered(work: &mut Work, plane_tol: f32, params: &CleanParams, r: &mut CleanReport) -> f64 {
    let max_sine = params.cut_intersections.then_some(intersect::MIN_CUT_SINE);
    let cop = coplanar::remove_covered_coplanar(work, plane_tol, params.keep_two_sided, params.remove_covered, max_sine);
    r.covered_coplanar_removed += cop.removed;
    r.partial_overlaps = cop.partial;
    r.partial_overlap_count = cop.partial_count;
    r.coplanar_pairs_enumerated += cop.pairs_enumerated;
    cop.removed_area
}

/// Refuses non-finite attributes (naming the vertex) and broken invariants.
fn check_input(mesh: &Mesh) -> Result<(), CleanError> {
    let non_finite =
        |vertex: usize, attribute: &'static str, value: String| CleanError::NonFinite { vertex: vertex as u32, attribute, value };
    if let Some(v) = mesh.positions.iter().position(|p| !p.is_finite()) {
        return Err(non_finite(v, "position", format!("{:?}", mesh.positions[v])));
    }
    mesh.validate().map_err(CleanError::InvalidMesh)?;
    // Areas and normals here are f32 like the bake's: past its limit a huge
    // triangle's area overflows and it would be removed as degenerate.
    crate::trace::check_extent(mesh)?;
    if let Some(v) = mesh.normals.iter().position(|n| !n.is_finite()) {
        return Err(non_finite(v, "normal", format!("{:?}", mesh.normals[v])));
    }
    if let Some(v) = mesh.uvs.iter().position(|uv| !uv.is_finite()) {
        return Err(non_finite(v, "uv", format!("{:?}", mesh.uvs[v])));
    }
    if let Some(v) = mesh.lightmap_uvs.iter().position(|uv| !uv.is_finite()) {
        return Err(non_finite(v, "lightmap uv", format!("{:?}", mesh.lightmap_uvs[v])));
    }
    if let Some(v) = mesh.colors.iter().position(|c| !c.iter().all(|x| x.is_finite())) {
        return Err(non_finite(v, "colour", format!("{:?}", mesh.colors[v])));
    }
    // Splits append vertices and triangles: leave head-room below u32::MAX.
    let largest = mesh.vertex_count().max(mesh.indices.len());
    if largest > (u32::MAX / 4) as usize {
        return Err(CleanError::TooLarge(largest));
    }
    Ok(())
}

/// Bounding-box diagonal of the vertices the triangles use (unused vertices do not
/// count, so a cleaned mesh resolves relative tolerances the same way).
/// Writes the live triangles and their vertices (in id order) to a new mesh,
/// without the vertices no triangle uses.
fn write_mesh(work: &Work, input: &Mesh) -> Mesh {
    let mut used = vec![false; work.vertex_point.len()];
    for tri in &work.tris {
        tri.iter().for_each(|&v| used[v as usize] = true);
    }
    write_vertices(work, input, &used)
}

/// Writes the triangles and the vertices flagged in `used` (in id order).
fn write_vertices(work: &Work, input: &Mesh, used: &[bool]) -> Mesh {
    let mut remap = vec![u32::MAX; used.len()];
    let mut out = Mesh {
        materials: input.materials.clone(),
        groups: input.groups.clone(),
        tri_material: work.tri_material.clone(),
        tri_group: work.tri_group.clone(),
        ..Mesh::default()
    };
    for v in (0..used.len()).filter(|&v| used[v]) {
        remap[v] = out.positions.len() as u32;
        out.positions.push(work.points[work.vertex_point[v] as usize]);
        out.normals.push(work.normals[v]);
        if !work.uvs.is_empty() {
            out.uvs.push(work.uvs[v]);
        }
        if !work.lightmap_uvs.is_empty() {
            out.lightmap_uvs.push(work.lightmap_uvs[v]);
        }
        if !work.colors.is_empty() {
            out.colors.push(work.colors[v]);
        }
    }
    out.indices = work.tris.iter().flat_map(|tri| tri.map(|v| remap[v as usize])).collect();
    out
}

#[cfg(test)]
mod tests;
