//! The clean-up report: counts of every repair, what remains, and a summary.

use super::work::{edge_runs, min_angle, sorted_edges, Work};
use super::CleanParams;
use crate::mesh::Mesh;
use std::fmt::Write as _;

/// Two coplanar triangles that overlap without either being covered.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct OverlapReport {
    /// Input triangle indices.
    pub tri_a: u32,
    pub tri_b: u32,
    /// Centroid of the overlap.
    pub location: [f32; 3],
    /// Area of the overlap.
    pub area: f32,
}

/// A connected component whose winding cannot be made consistent (Möbius-like).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct UnorientableComponent {
    pub triangles: usize,
    /// Input index of the component's lowest triangle.
    pub seed_triangle: u32,
    /// Midpoint of the first edge where the winding contradicts itself.
    pub location: [f32; 3],
}

/// Crossings between two materials that the cut left uncut.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct UncutCrossings {
    pub materials: [String; 2],
    /// Pairs of crossing triangles.
    pub triangle_pairs: usize,
}

/// What a remaining defect is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DefectKind {
    /// `value`: the triangle's smallest angle, degrees.
    SmallAngle,
    /// `value`: the edge's length.
    LongEdge,
    /// `value`: the number of triangles on the edge (3 or more).
    NonManifoldEdge,
}

/// One remaining defect of the output mesh.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct DefectReport {
    pub kind: DefectKind,
    /// Output triangle index.
    pub triangle: u32,
    /// Triangle centroid or edge midpoint.
    pub location: [f32; 3],
    pub value: f32,
}

/// Everything [`super::clean_mesh`] did, and the worst of what remains.
///
/// Triangle counts removed are disjoint: a triangle is counted by the first
/// step that removes it.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct CleanReport {
    pub input_triangles: usize,
    pub output_triangles: usize,
    pub input_vertices: usize,
    pub output_vertices: usize,
    /// Vertices merged into another (same point, agreeing attributes), initial and final weld.
    pub welded_vertices: usize,
    /// Collapsed or thinner than the weld tolerance (including those collapsed by zipping).
    pub degenerate_removed: usize,
    /// Duplicates with the kept triangle's winding.
    pub duplicates_removed: usize,
    /// Duplicates with the opposite winding.
    pub flipped_duplicates_removed: usize,
    /// Of the two counts above, those not bit-identical in the input (they matched after welding).
    pub near_duplicates_removed: usize,
    pub covered_coplanar_removed: usize,
    /// Largest first, at most 64 listed.
    pub partial_overlaps: Vec<OverlapReport>,
    pub partial_overlap_count: usize,
    /// Boundary edges before zipping minus after.
    pub zipped_edges: usize,
    /// Boundary points inserted into another triangle's edge.
    pub tjunctions_fixed: usize,
    /// Edges split because they were longer than `max_edge`.
    pub edges_split: usize,
    /// Pairs of triangles found crossing (`cut_intersections`); their
    /// segments are merged into the pieces below.
    pub crossing_pairs: usize,
    /// Pieces of intersection lines cut into the mesh: straight pieces
    /// between the points where a line meets edges or other lines, each
    /// counted once however many pairs found it (`cut_intersections`).
    pub intersections_cut: usize,
    /// Triangles replaced by the re-triangulation of their plane along those
    /// pieces (with the edge neighbours that took a point of a piece, so no
    /// T-junction appears).
    pub triangles_cut: usize,
    /// Vertex copies made so that no vertex spans a cut line or another
    /// non-manifold edge (with `cut_intersections`).
    pub seam_vertices_split: usize,
    /// Crossings of two pieces that a plane's triangulation found and split
    /// alone (normally 0: three triangles meeting at a point share it).
    pub cut_crossings_unshared: usize,
    /// Pieces the triangulation could not insert, and triangles whose
    /// triangulation failed (left uncut; normally 0).
    pub cut_failures: usize,
    /// Points the re-triangulation of cut planes added (inside the planes and
    /// on the cut lines) so that no triangle is a sliver where the input allows.
    pub cut_points_added: usize,
    /// Pieces of cut lines given a point so that the two surfaces meeting
    /// along a line do not share an edge of it (no new non-manifold edge).
    pub cut_lines_separated: usize,
    /// Pieces too short for that: shared edges the cut left (normally 0).
    pub cut_shared_edges_left: usize,
    /// Crossings left uncut: cutting them left triangles under 1° that the
    /// repair below could not raise, so the clean ran again without them
    /// (`cut_retries` times). Counted as the pairs of surfaces (edge-connected
    /// patches of one material) left whole, the pairs of triangles left
    /// besides, and per pair of materials all pairs of triangles left uncut.
    pub cut_surface_pairs_left_uncut: usize,
    pub cut_triangle_pairs_left_uncut: usize,
    pub cut_left_uncut: Vec<UncutCrossings>,
    pub cut_retries: usize,
    /// Triangles removed with an edge two surfaces shared that was too short
    /// to take a point (its two ends became one point of the line).
    pub cut_edges_collapsed: usize,
    /// Triangles the cut made under 1° that were repaired after it (a short
    /// side collapsed, a cap snapped, points inserted with flips around
    /// them, a crease flipped; see `clean::needles`), and the needles left
    /// in the output: triangles the cut made under 1° and thinner than the
    /// input triangle they came from (after the retries' cap, or with
    /// `cut_every_crossing`; otherwise their crossings are left uncut).
    pub cut_needles_repaired: usize,
    pub cut_needles_left: usize,
    /// Collapses (sides and caps), and points added (inserted or splitting an edge), by that repair.
    pub cut_needle_collapses: usize,
    pub cut_needle_points: usize,
    /// Smallest angle (degrees) of the output's triangles that the cut made
    /// (changed from the input, where a crossing changed it or with a corner
    /// at a new point), and of the triangles they replaced (`None` when
    /// nothing was cut).
    pub cut_min_angle_deg: Option<f32>,
    pub cut_replaced_min_angle_deg: Option<f32>,
    /// Slivers before refinement minus slivers after.
    pub slivers_fixed: usize,
    /// Edge flips made to improve slivers.
    pub sliver_flips: usize,
    pub triangles_flipped: usize,
    /// At most 64 listed.
    pub unorientable_components: Vec<UnorientableComponent>,
    pub unorientable_component_count: usize,
    /// Edges with one triangle, on welded positions, before any removal.
    pub boundary_edges_before: usize,
    pub boundary_edges_after: usize,
    /// Edges with three or more triangles, after.
    pub non_manifold_edges: usize,
    /// The input's total area (every triangle, duplicates and overlaps included).
    pub area_before: f64,
    /// The area of the triangles removed as duplicates, covered coplanar
    /// overlaps or degenerate: redundant copies of surface the output keeps.
    pub redundant_area_removed: f64,
    /// The output's total area. `area_before − redundant_area_removed −
    /// area_after` is what the repairs themselves changed (closing cracks).
    pub area_after: f64,
    /// Worst remaining defects: a few of each kind, worst first.
    pub worst: Vec<DefectReport>,
    /// Pipeline rounds run (each round repeats every step; see [`super::MAX_ROUNDS`]).
    pub rounds: usize,
    /// True when the last round repaired nothing: cleaning the output again is a no-op.
    pub converged: bool,
    /// When not converged: the repairs the last round still made, by name and count.
    pub retriggered: Vec<(String, usize)>,
    /// Converged, or the last round's repairs are at most [`READY_SHARE`] of
    /// the output's triangles: local edits a bake does not see as a change of
    /// surface. False: the mesh was still changing; check it before baking.
    pub ready_to_bake: bool,
    /// Work done: candidate pairs the coplanar broad phase enumerated, all rounds.
    /// Near-linear in triangles at any valence (a fan's triangles all share a box).
    pub coplanar_pairs_enumerated: usize,
    /// Resolved tolerances of the first round (world units).
    pub weld_tolerance: f32,
    pub coplanar_tolerance: f32,
    pub zip_tolerance: f32,
}

/// An unconverged clean is ready to bake when its last round's repairs are
/// at most this share of the output's triangles (1 in 100).
pub const READY_SHARE: f64 = 0.01;

/// Defects listed per kind.
const WORST_PER_KIND: usize = 5;
/// Smallest angles are listed when below this (degrees) or the sliver threshold.
const LISTED_ANGLE_DEG: f32 = 10.0;
/// Without `max_edge`, edges are listed when longer than this fraction of the diagonal.
const LISTED_EDGE_FRACTION: f32 = 0.5;

impl CleanReport {
    /// Every repair count by name, as in the JSON report.
    pub fn repair_counts(&self) -> [(&'static str, usize); 15] {
        [
            ("welded_vertices", self.welded_vertices),
            ("degenerate_removed", self.degenerate_removed),
            ("duplicates_removed", self.duplicates_removed),
            ("flipped_duplicates_removed", self.flipped_duplicates_removed),
            ("covered_coplanar_removed", self.covered_coplanar_removed),
            ("zipped_edges", self.zipped_edges),
            ("tjunctions_fixed", self.tjunctions_fixed),
            ("intersections_cut", self.intersections_cut),
            ("cut_points_added", self.cut_points_added),
            ("cut_lines_separated", self.cut_lines_separated),
            ("cut_needles_repaired", self.cut_needles_repaired),
            ("seam_vertices_split", self.seam_vertices_split),
            ("edges_split", self.edges_split),
            ("sliver_flips", self.sliver_flips),
            ("triangles_flipped", self.triangles_flipped),
        ]
    }

    /// The number of repairs made: zero when cleaning changed nothing.
    pub fn repairs(&self) -> usize {
        self.repair_counts().iter().map(|&(_, n)| n).sum()
    }

    /// Adds a later round's repairs; takes its description of what remains.
    /// `removed_area` is the redundant area that round removed.
    pub(crate) fn absorb(&mut self, later: &CleanReport, removed_area: f64) {
        self.welded_vertices += later.welded_vertices;
        self.degenerate_removed += later.degenerate_removed;
        self.duplicates_removed += later.duplicates_removed;
        self.flipped_duplicates_removed += later.flipped_duplicates_removed;
        self.near_duplicates_removed += later.near_duplicates_removed;
        self.covered_coplanar_removed += later.covered_coplanar_removed;
        self.zipped_edges += later.zipped_edges;
        self.tjunctions_fixed += later.tjunctions_fixed;
        self.crossing_pairs += later.crossing_pairs;
        self.intersections_cut += later.intersections_cut;
        self.cut_points_added += later.cut_points_added;
        self.cut_lines_separated += later.cut_lines_separated;
        self.cut_shared_edges_left += later.cut_shared_edges_left;
        self.cut_edges_collapsed += later.cut_edges_collapsed;
        self.cut_needles_repaired += later.cut_needles_repaired;
        self.cut_needles_left += later.cut_needles_left;
        self.cut_needle_collapses += later.cut_needle_collapses;
        self.cut_needle_points += later.cut_needle_points;
        let least = |a: Option<f32>, b: Option<f32>| match (a, b) {
            (Some(x), Some(y)) => Some(x.min(y)),
            (x, y) => x.or(y),
        };
        self.cut_min_angle_deg = least(self.cut_min_angle_deg, later.cut_min_angle_deg);
        self.cut_replaced_min_angle_deg = least(self.cut_replaced_min_angle_deg, later.cut_replaced_min_angle_deg);
        self.triangles_cut += later.triangles_cut;
        self.seam_vertices_split += later.seam_vertices_split;
        self.cut_crossings_unshared += later.cut_crossings_unshared;
        self.cut_failures += later.cut_failures;
        self.edges_split += later.edges_split;
        self.slivers_fixed += later.slivers_fixed;
        self.sliver_flips += later.sliver_flips;
        self.triangles_flipped += later.triangles_flipped;
        self.coplanar_pairs_enumerated += later.coplanar_pairs_enumerated;
        self.redundant_area_removed += removed_area;
        self.output_triangles = later.output_triangles;
        self.output_vertices = later.output_vertices;
        self.partial_overlaps = later.partial_overlaps.clone();
        self.partial_overlap_count = later.partial_overlap_count;
        self.unorientable_components = later.unorientable_components.clone();
        self.unorientable_component_count = later.unorientable_component_count;
        self.boundary_edges_after = later.boundary_edges_after;
        self.non_manifold_edges = later.non_manifold_edges;
        self.area_after = later.area_after;
        self.worst = later.worst.clone();
    }

    /// The last round's repairs per output triangle (0 when converged).
    pub fn last_round_share(&self) -> f64 {
        let repairs: usize = self.retriggered.iter().map(|(_, n)| n).sum();
        repairs as f64 / self.output_triangles.max(1) as f64
    }

    /// "converged", or which repairs kept re-triggering in the last round
    /// and whether the output is ready to bake ([`CleanReport::ready_to_bake`]).
    pub fn convergence(&self) -> String {
        if self.converged {
            return "converged".into();
        }
        let names: Vec<String> = self.retriggered.iter().map(|(name, n)| format!("{name} {n}")).collect();
        let share = 100.0 * self.last_round_share();
        let remaining = format!(
            "{} partial overlaps, {} non-manifold and {} boundary edges remain",
            self.partial_overlap_count, self.non_manifold_edges, self.boundary_edges_after
        );
        let verdict = if self.ready_to_bake {
            format!(
                "safe to bake: those repairs are {share:.2}% of the {} triangles, local edits that change no surface a bake sees; {remaining}",
                self.output_triangles
            )
        } else {
            format!(
                "check before baking: those repairs are {share:.1}% of the {} triangles, so the mesh was still changing; clean the output again, or find the parts that keep changing with `prtbake inspect`; {remaining}",
                self.output_triangles
            )
        };
        format!("NOT converged; still repairing in the last round: {}; {verdict}", names.join(", "))
    }

    /// A human-readable multi-line summary.
    pub fn summary(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "triangles {} -> {}, vertices {} -> {}",
            self.input_triangles, self.output_triangles, self.input_vertices, self.output_vertices
        );
        let _ = writeln!(s, "welded vertices        {}", self.welded_vertices);
        let _ = writeln!(s, "degenerate removed     {}", self.degenerate_removed);
        let _ = writeln!(
            s,
            "duplicates removed     {} (+{} flipped; {} of them near)",
            self.duplicates_removed, self.flipped_duplicates_removed, self.near_duplicates_removed
        );
        let _ = writeln!(s, "covered coplanar       {}", self.covered_coplanar_removed);
        let _ = writeln!(s, "partial overlaps       {}", self.partial_overlap_count);
        let _ = writeln!(s, "zipped edges           {} ({} T-junctions)", self.zipped_edges, self.tjunctions_fixed);
        let _ = writeln!(
            s,
            "intersections cut      {} ({} crossing pairs, {} triangles cut, {} seam vertices split; {} crossings unshared, {} failures)",
            self.intersections_cut,
            self.crossing_pairs,
            self.triangles_cut,
            self.seam_vertices_split,
            self.cut_crossings_unshared,
            self.cut_failures
        );
        if let (Some(made), Some(replaced)) = (self.cut_min_angle_deg, self.cut_replaced_min_angle_deg) {
            let _ = writeln!(
                s,
                "cut quality            {} points added, {} lines separated ({} shared edges left, {} triangles collapsed with a too short one); smallest angle {made:.3}° (replaced triangles: {replaced:.3}°)",
                self.cut_points_added, self.cut_lines_separated, self.cut_shared_edges_left, self.cut_edges_collapsed
            );
            if self.cut_surface_pairs_left_uncut + self.cut_triangle_pairs_left_uncut > 0 {
                let pairs: Vec<String> = self
                    .cut_left_uncut
                    .iter()
                    .map(|u| {
                        let pairs = if u.triangle_pairs == 1 { "pair" } else { "pairs" };
                        format!("{} × {} ({} triangle {pairs})", u.materials[0], u.materials[1], u.triangle_pairs)
                    })
                    .collect();
                let _ = writeln!(
                    s,
                    "cut left uncut         {} pairs of surfaces and {} more pairs of triangles, found in {} {} (cutting them left triangles under 1°): {}",
                    self.cut_surface_pairs_left_uncut,
                    self.cut_triangle_pairs_left_uncut,
                    self.cut_retries,
                    if self.cut_retries == 1 { "retry" } else { "retries" },
                    pairs.join(", ")
                );
            }
            let _ = writeln!(
                s,
                "cut needles            {} under 1° repaired ({} sides collapsed, {} points inserted), {} left",
                self.cut_needles_repaired, self.cut_needle_collapses, self.cut_needle_points, self.cut_needles_left
            );
        }
        let _ = writeln!(s, "edges split            {}", self.edges_split);
        let _ = writeln!(s, "slivers fixed          {} ({} flips)", self.slivers_fixed, self.sliver_flips);
        let _ = writeln!(
            s,
            "triangles flipped      {} ({} unorientable components)",
            self.triangles_flipped, self.unorientable_component_count
        );
        let _ = writeln!(
            s,
            "boundary edges         {} -> {}, non-manifold edges {}",
            self.boundary_edges_before, self.boundary_edges_after, self.non_manifold_edges
        );
        let _ = writeln!(s, "rounds                 {} ({})", self.rounds, self.convergence());
        // (+ 0.0: no "-0.00e0" for nothing removed.)
        let relative = |x: f64| if self.area_before > 0.0 { x / self.area_before + 0.0 } else { 0.0 };
        let _ = writeln!(
            s,
            "area                   {:.6e} -> {:.6e} ({:+.2e} relative: {:+.2e} redundant copies removed, {:+.2e} by the repairs)",
            self.area_before,
            self.area_after,
            relative(self.area_after - self.area_before),
            relative(-self.redundant_area_removed),
            relative(self.area_after - self.area_before + self.redundant_area_removed)
        );
        for o in self.partial_overlaps.iter().take(WORST_PER_KIND) {
            let _ = writeln!(s, "  overlap of triangles {} and {}: area {:.3e} at {:?}", o.tri_a, o.tri_b, o.area, o.location);
        }
        for c in &self.unorientable_components {
            let _ = writeln!(s, "  unorientable: {} triangles from {} near {:?}", c.triangles, c.seed_triangle, c.location);
        }
        for d in &self.worst {
            let _ = writeln!(s, "  worst {:?}: triangle {} value {:.4} at {:?}", d.kind, d.triangle, d.value, d.location);
        }
        s
    }
}

/// The worst remaining defects of the output: smallest angles, longest edges,
/// non-manifold edges (triangle ids index `out`, which has `work`'s triangle order).
pub(crate) fn worst_defects(work: &Work, out: &Mesh, params: &CleanParams) -> Vec<DefectReport> {
    let mut worst = Vec::new();
    let centroid = |t: usize| {
        let [a, b, c] = out.triangle_positions(t);
        ((a + b + c) / 3.0).to_array()
    };

    // Smallest angles.
    let angle_limit = LISTED_ANGLE_DEG.max(params.sliver_min_angle_deg);
    let mut angles: Vec<(f32, usize)> = (0..out.triangle_count())
        .map(|t| (min_angle(out.triangle_positions(t).map(|p| p.as_dvec3())).to_degrees() as f32, t))
        .filter(|&(a, _)| a < angle_limit)
        .collect();
    angles.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
    worst.extend(angles.iter().take(WORST_PER_KIND).map(|&(a, t)| DefectReport {
        kind: DefectKind::SmallAngle,
        triangle: t as u32,
        location: centroid(t),
        value: a,
    }));

    // Longest edges and non-manifold edges, on point topology.
    let edges = sorted_edges(work);
    let edge_limit = params.max_edge.unwrap_or(LISTED_EDGE_FRACTION * out.diagonal());
    let mut long = Vec::new();
    let mut non_manifold = Vec::new();
    for run in edge_runs(&edges) {
        let e = run[0];
        let (a, b) = (work.points[e.lo as usize], work.points[e.hi as usize]);
        let mid = (0.5 * (a + b)).to_array();
        let len = a.distance(b);
        if len > edge_limit {
            long.push(DefectReport { kind: DefectKind::LongEdge, triangle: e.tri, location: mid, value: len });
        }
        if run.len() > 2 {
            let value = run.len() as f32;
            non_manifold.push(DefectReport { kind: DefectKind::NonManifoldEdge, triangle: e.tri, location: mid, value });
        }
    }
    long.sort_by(|x, y| y.value.total_cmp(&x.value).then(x.triangle.cmp(&y.triangle)));
    worst.extend(long.into_iter().take(WORST_PER_KIND));
    worst.extend(non_manifold.into_iter().take(WORST_PER_KIND));
    worst
}
