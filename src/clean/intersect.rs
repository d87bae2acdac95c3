//! Cutting where surfaces pass through each other.
//!
//! Why: in architectural and CAD models a wall runs past another wall and a
//! floor runs under and past a wall. A vertex's transfer is the hat-weighted
//! mean over its one-ring, and a triangle that spans both sides of a wall is
//! interpolated across it, so the sky seen outside bleeds into the room as
//! bright bands along the junction (seed 000 calls interpenetrating CAD
//! geometry "a really big problem"). Cutting every triangle along the lines
//! where other triangles cross it makes those lines edges; the weld then keeps
//! the triangles on either side of such a line apart ([`super::weld`],
//! wedges, and [`find_seams`]), so no sample from one side enters a vertex of
//! the other.
//!
//! How:
//! 1. *Pairs*: the coplanar step's broad phase ([`super::hub_pairs`]), boxes
//!    padded by the contact tolerance. Pairs that share an edge are skipped,
//!    and so are coplanar pairs (within the plane tolerance: overlaps are
//!    [`super::coplanar`]'s).
//! 2. *Segment*: each triangle's corners are classified against the other's
//!    plane with [`robust::orient3d`] (Shewchuk's adaptive exact predicate),
//!    then a corner within the contact tolerance of the plane counts as on
//!    it. The pair's intersection is the overlap of the two triangles'
//!    crossings of each other's plane. A pair meeting in a point is not cut,
//!    nor segments shorter than the zip tolerance, nor pairs whose planes meet
//!    at less than about 3° ([`MIN_CUT_SINE`]). A segment lying along an edge
//!    of a triangle does not cut that triangle (a wall standing on a floor is
//!    not cut at its foot, pieces cut before are not cut again): that edge is
//!    a seam, and only where the segment ends inside the edge does the edge
//!    take a point.
//! 3. *Points*: segment ends within the contact tolerance of a corner of the
//!    pair are that corner; new ends closer than it to each other are one
//!    point (transitively), so the pairs along one line and the triangles of
//!    one surface share them, however many pairs found them (1,000 fins on one
//!    axis: 499,500 pairs, one line). A point on an edge goes into every
//!    triangle using the edge (no T-junction).
//! 4. *Planes*: the triangles that take a segment or a point are grouped into
//!    regions (neighbours across an edge with the same two vertices, the same
//!    material and group, facing the same way, within the plane tolerance of
//!    one plane). In each region the segments are merged: the same piece found
//!    by several pairs once, a point within the tolerance of a segment splits
//!    it, two segments crossing are split at their crossing (three surfaces
//!    meeting at a point; crossings closer than the tolerance are one point,
//!    across regions too), and a point where two collinear pieces meet and
//!    nothing else does is dropped (a straight wall crossing a floor is one
//!    line in the floor, not a piece per wall triangle).
//! 5. *No shared edge*: a piece that another surface also has as an edge
//!    (the wall crossing the floor has the same line) would be an edge of four
//!    triangles; the later region takes a point on its piece instead, at a
//!    parameter that no other region uses, so the two surfaces meet along the
//!    line without sharing an edge of it, and no non-manifold edge appears.
//! 6. *Triangulate*: each region is re-triangulated as one polygon with its
//!    outline and pieces as constraints, to the sliver angle where the input
//!    allows it ([`super::planar`]: constrained Delaunay triangulation and
//!    Delaunay refinement, points added inside the plane and on the pieces,
//!    never moving either). New vertices interpolate the attributes of the
//!    original triangle they lie in.
//! 7. *No shared edge, again*: two regions that both hold the ends of a short
//!    piece (or two points merged within the tolerance) may each join them by
//!    an unconstrained Delaunay edge; every surface but the first takes a
//!    point on such an edge, and one too short for a point the weld would
//!    keep is collapsed (the dining room's cut left 430 such edges; none now).
//!
//! Every triangle it changes records the crossings (pairs of triangles, and
//! their surfaces) that changed it or its region ([`CutMemo::cut_by`]); the
//! clean leaves crossings uncut ([`CutMemo::skip`]) when it cannot repair
//! the needles they made.
//!
//! Limits: a segment is straight in each triangle, so curved intersections
//! are cut as polylines at the tessellation's resolution. A region's outline,
//! where it meets triangles outside the region, is kept whole, so a triangle
//! pressed against it may stay below the sliver angle; so does an angle
//! between two constraints (a cut line meeting an edge at 2° makes a 2°
//! corner). Candidate pairs are enumerated by boxes: n triangles that all
//! cross one line are n(n − 1)/2 pairs to test (fast, but quadratic).
//! Measurements: docs/performance.md.

use super::hub_pairs;
use super::planar::{self, PlanarRegion};
use super::spatial::{cluster_points_dense, find, union, Aabb, AabbTree};
use super::work::{edge_runs, sorted_edges, EdgeUse, Work};
use glam::{DVec2, DVec3, Vec3};
use std::collections::{BTreeMap, HashMap, HashSet};

/// What [`cut_intersections`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct CutOutcome {
    /// Pairs of triangles found crossing.
    pub pairs: usize,
    /// Crossing pairs left uncut because they are in [`CutMemo::skip`],
    /// counted per pair of the two triangles' materials.
    pub skipped: BTreeMap<(u16, u16), usize>,
    /// Pieces of intersection lines inserted (after merging, before refinement).
    pub pieces: usize,
    /// Triangles replaced by the re-triangulation of their region.
    pub triangles_cut: usize,
    /// Crossings of two pieces the triangulation found and split (not found in 3D).
    pub unshared_splits: usize,
    /// Pieces the triangulation could not insert (left uncut).
    pub dropped_pieces: usize,
    /// Triangles of regions whose triangulation failed (left whole).
    pub failed_triangles: usize,
    /// Points the re-triangulation added to reach the sliver angle.
    pub refinement_points: usize,
    /// Pieces given a point so that two surfaces do not share them as an edge.
    pub lines_separated: usize,
    /// Pieces still shared (too short to take a point): non-manifold edges left.
    pub shared_left: usize,
    /// Triangles removed by collapsing an edge of two surfaces too short to split.
    pub edges_collapsed: usize,
    /// Smallest angle (radians) of the triangles made, and of those they replaced.
    pub min_angle: f64,
    pub replaced_min_angle: f64,
    /// The cut lines as point edges (lower id first): seams for the wedges.
    pub seams: Vec<(u32, u32)>,
}

/// The tolerances of [`cut_intersections`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct CutTolerances {
    /// Distance within which triangles count as coplanar (the coplanar step's).
    pub plane: f64,
    /// Distance within which a point touches a plane, an edge or another point.
    pub contact: f64,
    /// Segments shorter than this are not cut (the zip tolerance).
    pub min_length: f64,
    /// Target smallest angle of the re-triangulated regions (radians; 0: none).
    pub min_angle: f64,
}

/// Pairs whose planes meet at a smaller angle (sine; about 3°) are not cut:
/// an offset δ of either moves their common line by δ / sin θ, so the cut is
/// ill-conditioned, and such pairs are mostly one surface modelled twice a
/// hair apart (a car's double-sided panels) rather than a wall through a floor.
pub(crate) const MIN_CUT_SINE: f64 = 0.05;
/// The parameters at which the regions after the first place their point on
/// a shared piece: `1/4 + (k + SEPARATION_OFFSET) / 2K` for the k-th of K, in
/// the middle half (no short piece) and not at a dyadic fraction, where
/// refinement splits pieces (midpoints).
const SEPARATION_OFFSET: f64 = 0.618_034;

/// Passes of [`unshare_made_edges`]; each separates every shared edge whose
/// triangles no other edge of the pass changed.
const MAX_UNSHARE_PASSES: usize = 8;

/// Faces whose shortest side is under this many plane tolerances are not
/// refined: near a point where many lines meet (thin triangles crossing at
/// one spot) refinement made triangles so small that triangles of other
/// planes there lie within the plane tolerance of them, which the coplanar
/// step then removed as covered, round after round.
const MIN_REFINED_FACE: f64 = 32.0;

/// Where a point lies on a triangle.
#[derive(Clone, Copy, Debug)]
enum Loc {
    Corner(usize),
    /// On the edge from corner `k` to `k + 1`.
    Edge(usize),
    Interior,
    /// Outside the triangle by more than the tolerance: not inserted.
    Outside,
}

/// A segment end before the new points are clustered.
#[derive(Clone, Copy, Debug)]
enum EndRef {
    Point(u32),
    New(u32),
}

/// A crossing pair's segment, before its ends are points.
struct Raw {
    tris: [u32; 2],
    crossing: Crossing,
    ends: [DVec3; 2],
    /// Per triangle: `None` when the segment does not cut it (along a rim
    /// or a non-manifold edge), `Some(true)` across it, `Some(false)` along one
    /// of its manifold edges (a seam).
    cuts: [Option<bool>; 2],
}

/// One triangle's constraint: two point ids and whether it crosses the triangle (not along an edge).
type Constraint = ([u32; 2], bool);

/// Two surfaces, lower first. A surface is an edge-connected patch of one
/// material and group ([`surfaces`]), named by its first triangle when the
/// cut ran; the same input always gives the same names.
pub(crate) type SurfacePair = (u32, u32);

/// A crossing: its two triangles (as their `tri_origin`, lower first) and their surfaces.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub(crate) struct Crossing {
    pub surfaces: SurfacePair,
    pub triangles: (u32, u32),
}

/// The crossings the cut leaves uncut: those of pairs of triangles, and all
/// those between pairs of surfaces.
#[derive(Clone, Debug, Default)]
pub(crate) struct Skips {
    pub triangles: HashSet<(u32, u32)>,
    pub surfaces: HashSet<SurfacePair>,
}

impl Skips {
    pub(crate) fn contains(&self, c: &Crossing) -> bool {
        self.surfaces.contains(&c.surfaces) || self.triangles.contains(&c.triangles)
    }
}

/// What one clean's cut knows across its rounds and retries.
///
/// `tested`: the triangles the cut has tested against each other, as their
/// corner positions, and `cut`: whether it has cut. The clean cuts once (the
/// first round; [`CutMemo::has_cut`]), so the set only matters to a caller
/// that cuts again: a pair of tested triangles is not tested again (nothing
/// about it changed), a triangle that another step changed or moved is new
/// and tested against all.
#[derive(Default)]
pub(crate) struct CutMemo {
    tested: HashSet<[[u32; 3]; 3]>,
    cut: bool,
    /// Crossings left uncut (the caller's choice).
    pub skip: Skips,
    /// Who cut what, sorted: (triangle, as its `tri_origin`; a crossing that
    /// changed it; `true` when the crossing touched this triangle itself,
    /// `false` when it touched another of its region).
    pub cut_by: Vec<(u32, Crossing, bool)>,
}

impl CutMemo {
    /// A memo that leaves the crossings of `skip` uncut.
    pub(crate) fn skipping(skip: Skips) -> Self {
        CutMemo { skip, ..CutMemo::default() }
    }

    /// True once a round has cut something.
    pub(crate) fn has_cut(&self) -> bool {
        self.cut
    }

    /// The crossings recorded for triangle `origin`, directly or through its region.
    pub(crate) fn causes(&self, origin: u32, direct: bool) -> impl Iterator<Item = Crossing> + '_ {
        let from = self.cut_by.partition_point(|e| e.0 < origin);
        self.cut_by[from..].iter().take_while(move |e| e.0 == origin).filter(move |e| e.2 == direct).map(|e| e.1)
    }

    fn key(work: &Work, t: usize) -> [[u32; 3]; 3] {
        super::work::corner_key(work.tri_positions(t))
    }
}

/// Each triangle's surface: the smallest triangle id of its patch, joined
/// across edges of exactly two triangles with the same material and group.
fn surfaces(work: &Work, edges: &[EdgeUse]) -> Vec<u32> {
    let mut parent: Vec<u32> = (0..work.tris.len() as u32).collect();
    for run in edge_runs(edges) {
        if let [e, f] = run {
            let (a, b) = (e.tri as usize, f.tri as usize);
            if work.tri_material[a] == work.tri_material[b] && work.tri_group[a] == work.tri_group[b] {
                union(&mut parent, e.tri, f.tri);
            }
        }
    }
    (0..parent.len() as u32).map(|t| find(&mut parent, t)).collect()
}

/// Cuts every live triangle along the segments where other triangles cross
/// it (see the module doc). `memo` holds the triangles earlier rounds tested.
pub(crate) fn cut_intersections(work: &mut Work, tol: &CutTolerances, memo: &mut CutMemo) -> CutOutcome {
    let n = work.tris.len();
    let corners: Vec<[DVec3; 3]> = (0..n).map(|t| work.tri_positions(t).map(|p| p.as_dvec3())).collect();
    let points: Vec<[u32; 3]> = (0..n).map(|t| work.tri_points(t)).collect();
    let usable = |t: usize| {
        let [a, b, c] = points[t];
        work.tri_alive[t] && a != b && b != c && c != a && work.tri_cross(t).length_squared() > 0.0
    };
    let boxes: Vec<Aabb> =
        (0..n).map(|t| if usable(t) { Aabb::of_points(&work.tri_positions(t), tol.contact as f32) } else { Aabb::EMPTY }).collect();
    let settled: Vec<bool> = (0..n).map(|t| boxes[t] != Aabb::EMPTY && memo.tested.contains(&CutMemo::key(work, t))).collect();
    let candidates = candidate_pairs(&points, &corners, &boxes, &settled, tol.contact);
    let edge_users = EdgeUsers(sorted_edges(work));
    let surface = surfaces(work, &edge_users.0);
    let mut out = CutOutcome { min_angle: f64::INFINITY, replaced_min_angle: f64::INFINITY, ..CutOutcome::default() };

    // 1-2. Segments of the crossing pairs, ends as positions.
    let mut raw: Vec<Raw> = Vec::new();
    for &(a, b) in &candidates {
        let (a, b) = (a as usize, b as usize);
        let shared = points[a].iter().filter(|p| points[b].contains(p)).count();
        if shared >= 2 {
            continue;
        }
        let Some(ends) = pair_segment(corners[a], corners[b], tol.plane, tol.contact).filter(|e| e[0].distance(e[1]) >= tol.min_length)
        else {
            continue;
        };
        let (oa, ob) = (work.tri_origin[a], work.tri_origin[b]);
        let crossing = Crossing { surfaces: (surface[a].min(surface[b]), surface[a].max(surface[b])), triangles: (oa.min(ob), oa.max(ob)) };
        if memo.skip.contains(&crossing) {
            let (ma, mb) = (work.tri_material[a], work.tri_material[b]);
            *out.skipped.entry((ma.min(mb), ma.max(mb))).or_default() += 1;
            continue;
        }
        // Along an edge: a seam, unless the edge is a rim, non-manifold or a seam already.
        let cut_of = |t: usize| match along_edge(corners[t], ends, tol.contact) {
            None => Some(true),
            Some(k) => {
                let users = edge_users.of(points[t][k], points[t][(k + 1) % 3]);
                (users.len() == 2 && !splits_vertices(work, users)).then_some(false)
            }
        };
        let cuts = [cut_of(a), cut_of(b)];
        if cuts == [None, None] {
            continue;
        }
        raw.push(Raw { tris: [a as u32, b as u32], crossing, ends, cuts });
    }

    // 3. Point ids: a corner of the pair within the tolerance, else a new point (clustered).
    let mut new_positions: Vec<Vec3> = Vec::new();
    let ends_of: Vec<[EndRef; 2]> = raw
        .iter()
        .map(|r| {
            r.ends.map(|p| {
                let (points, corners) = (&points, &corners);
                let nearest = r
                    .tris
                    .iter()
                    .flat_map(|&t| (0..3).map(move |k| (points[t as usize][k], corners[t as usize][k])))
                    .map(|(id, c)| (c.distance(p), id))
                    .filter(|&(d, _)| d <= tol.contact)
                    .min_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
                match nearest {
                    Some((_, id)) => EndRef::Point(id),
                    None => {
                        new_positions.push(p.as_vec3());
                        EndRef::New(new_positions.len() as u32 - 1)
                    }
                }
            })
        })
        .collect();
    let new_point = push_clustered(work, &new_positions, tol.contact);
    let point_of = |e: EndRef| match e {
        EndRef::Point(id) => id,
        EndRef::New(i) => new_point[i as usize],
    };

    // Constraints per triangle, and the points each edge takes.
    let mut constraints: BTreeMap<u32, Vec<Constraint>> = BTreeMap::new();
    let mut edge_points: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
    // The crossings that changed each triangle, and those that put each edge's points.
    let mut causes: Vec<(u32, Crossing)> = Vec::new();
    let mut edge_causes: HashMap<(u32, u32), Vec<Crossing>> = HashMap::new();
    let mut seams: Vec<(u32, u32)> = Vec::new();
    let mut touched: HashSet<u32> = HashSet::new();
    for (r, ends) in raw.iter().zip(&ends_of) {
        let ends = ends.map(point_of);
        if ends[0] == ends[1] {
            continue;
        }
        let mut crossing = false;
        for (&t, &cut) in r.tris.iter().zip(&r.cuts) {
            let Some(across) = cut else { continue };
            let locs = ends.map(|p| locate_point(work, &points, &corners, t, p, tol.contact));
            if locs.iter().any(|l| matches!(l, Loc::Outside)) {
                continue;
            }
            for (&p, loc) in ends.iter().zip(&locs) {
                if let Loc::Edge(k) = *loc {
                    let key = edge_key(points[t as usize][k], points[t as usize][(k + 1) % 3]);
                    edge_points.entry(key).or_default().push(p);
                    edge_causes.entry(key).or_default().push(r.crossing);
                }
            }
            if !across && locs.iter().all(|l| matches!(l, Loc::Corner(_))) {
                // Along a whole edge: a seam, nothing to cut.
                seams.push(edge_key(ends[0], ends[1]));
            }
            if across {
                touched.insert(t);
                causes.push((t, r.crossing));
                crossing = true;
            }
            constraints.entry(t).or_default().push((ends, across));
        }
        out.pairs += usize::from(crossing);
    }
    for (&(a, b), list) in &mut edge_points {
        list.sort_unstable();
        list.dedup();
        touched.extend(edge_users.of(a, b).iter().map(|e| e.tri));
        for e in edge_users.of(a, b) {
            causes.extend(edge_causes[&(a, b)].iter().map(|&c| (e.tri, c)));
        }
    }
    if touched.is_empty() {
        out.seams = seams;
        memo.tested = (0..n).filter(|&t| work.tri_alive[t]).map(|t| CutMemo::key(work, t)).collect();
        return out;
    }

    // 4. Regions and their pieces.
    let regions = group_regions(work, &points, &corners, &edge_users, &touched, tol.plane);
    record_causes(work, &regions, causes, &mut memo.cut_by);
    let mut plans: Vec<Plan> =
        regions.into_iter().map(|r| plan_region(work, &points, &corners, &edge_users, &edge_points, &constraints, r, tol)).collect();
    split_at_crossings(work, &mut plans, tol.contact);
    for plan in &mut plans {
        plan.finish_pieces(work, tol.contact);
        out.pieces += plan.pieces.iter().filter(|p| p.1).count();
    }
    // 5. No piece is an edge of two surfaces.
    separate_shared_pieces(work, &mut plans, &edge_users, &mut out, tol.contact);

    // 6. Triangulate.
    let first_new = work.tris.len();
    for plan in &plans {
        triangulate_region(work, &corners, plan, tol, &mut out);
    }
    // 7. No edge of two surfaces made by the triangulations themselves.
    let made = |t: u32| t as usize >= first_new || plans.iter().any(|p| p.region.tris.binary_search(&t).is_ok());
    unshare_made_edges(work, made, &mut out, tol.contact);
    out.seams.extend(seams);
    out.seams.sort_unstable();
    out.seams.dedup();
    work.compact_triangles();
    memo.tested = (0..work.tris.len()).map(|t| CutMemo::key(work, t)).collect();
    memo.cut = true;
    out
}

/// The pairs to test: every pair with overlapping boxes but those of two
/// settled triangles. All unsettled (the first round): the coplanar step's
/// broad phase, near-linear at high-valence points; otherwise the same among
/// the unsettled, and each unsettled box against a tree of the settled.
fn candidate_pairs(points: &[[u32; 3]], corners: &[[DVec3; 3]], boxes: &[Aabb], settled: &[bool], tol: f64) -> Vec<(u32, u32)> {
    let fresh: Vec<Aabb> = boxes.iter().zip(settled).map(|(&b, &s)| if s { Aabb::EMPTY } else { b }).collect();
    let mut pairs = hub_pairs::candidate_pairs(points, corners, &fresh, tol).pairs;
    let old: Vec<u32> = (0..boxes.len() as u32).filter(|&t| settled[t as usize]).collect();
    if !old.is_empty() {
        let tree = AabbTree::build(old.iter().map(|&t| boxes[t as usize]).collect());
        let mut hits = Vec::new();
        for t in (0..boxes.len()).filter(|&t| fresh[t] != Aabb::EMPTY) {
            hits.clear();
            tree.query(&fresh[t], &mut hits);
            pairs.extend(hits.iter().map(|&i| (old[i as usize].min(t as u32), old[i as usize].max(t as u32))));
        }
        pairs.sort_unstable();
    }
    pairs
}

/// Appends the positions as points, those closer than `tol` to each other
/// (transitively) as one (the first); returns each position's point id.
fn push_clustered(work: &mut Work, positions: &[Vec3], tol: f64) -> Vec<u32> {
    // Bit-identical positions first (the pairs along one line find its ends
    // thousands of times; clustering compares the points of a cell pairwise).
    let mut first: HashMap<[u32; 3], u32> = HashMap::new();
    let distinct: Vec<u32> = (0..positions.len() as u32)
        .filter(|&i| *first.entry(positions[i as usize].to_array().map(f32::to_bits)).or_insert(i) == i)
        .collect();
    let reps = cluster_points_dense(positions, &distinct, tol as f32);
    let mut point = vec![u32::MAX; positions.len()];
    for (&i, &r) in distinct.iter().zip(&reps) {
        if point[r as usize] == u32::MAX {
            point[r as usize] = work.push_point(positions[r as usize]);
        }
        point[i as usize] = point[r as usize];
    }
    for i in 0..positions.len() {
        point[i] = point[first[&positions[i].to_array().map(f32::to_bits)] as usize];
    }
    point
}

/// A point edge as its two point ids, the lower first.
fn edge_key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

/// True when the two users of an edge have different vertices at one of its
/// ends: the edge is already a seam (a cut line, a hard edge or a UV seam).
fn splits_vertices(work: &Work, users: &[EdgeUse]) -> bool {
    let vertex_at = |e: &EdgeUse, p: u32| {
        let t = e.tri as usize;
        (0..3).find(|&c| work.vertex_point[work.tris[t][c] as usize] == p).map(|c| work.tris[t][c])
    };
    let (e, f) = (&users[0], &users[1]);
    [e.lo, e.hi].iter().any(|&p| vertex_at(e, p) != vertex_at(f, p))
}

/// The edge of the triangle with corners `c` that holds both points (within `tol`), if any.
fn along_edge(c: [DVec3; 3], ends: [DVec3; 2], tol: f64) -> Option<usize> {
    let on = |loc: Loc| -> [bool; 3] {
        match loc {
            Loc::Corner(k) => {
                let mut e = [false; 3];
                e[k] = true;
                e[(k + 2) % 3] = true;
                e
            }
            Loc::Edge(k) => {
                let mut e = [false; 3];
                e[k] = true;
                e
            }
            _ => [false; 3],
        }
    };
    let corner_or = |p: DVec3| match (0..3).find(|&k| c[k].distance(p) <= tol) {
        Some(k) => Loc::Corner(k),
        None => locate(c, p, tol),
    };
    let (x, y) = (on(corner_or(ends[0])), on(corner_or(ends[1])));
    (0..3).find(|&k| x[k] && y[k])
}

/// Where point `p` lies on triangle `t` (a corner when it is one by id).
fn locate_point(work: &Work, points: &[[u32; 3]], corners: &[[DVec3; 3]], t: u32, p: u32, tol: f64) -> Loc {
    match points[t as usize].iter().position(|&c| c == p) {
        Some(k) => Loc::Corner(k),
        None => locate(corners[t as usize], work.points[p as usize].as_dvec3(), tol),
    }
}

/// Unit normal of a triangle (zero for a degenerate one).
fn normal(t: [DVec3; 3]) -> DVec3 {
    (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero()
}

/// A region: triangles (ascending) and the vertex each uses at each of its points.
struct Region {
    tris: Vec<u32>,
    vertex_of: HashMap<u32, u32>,
}

/// Groups the touched triangles into planar regions (see the module doc, step 4).
fn group_regions(
    work: &Work,
    points: &[[u32; 3]],
    corners: &[[DVec3; 3]],
    edge_users: &EdgeUsers,
    touched: &HashSet<u32>,
    plane_tol: f64,
) -> Vec<Region> {
    let mut seeds: Vec<u32> = touched.iter().copied().collect();
    seeds.sort_unstable();
    let mut assigned: HashSet<u32> = HashSet::new();
    let mut regions = Vec::new();
    for seed in seeds {
        if !assigned.insert(seed) {
            continue;
        }
        let s = seed as usize;
        let (origin, n) = (corners[s][0], normal(corners[s]));
        let mut vertex_of: HashMap<u32, u32> = (0..3).map(|k| (points[s][k], work.tris[s][k])).collect();
        let mut tris = vec![seed];
        let mut next = 0;
        while next < tris.len() {
            let t = tris[next] as usize;
            next += 1;
            for k in 0..3 {
                let users = edge_users.of(points[t][k], points[t][(k + 1) % 3]);
                let [e, f] = users else { continue };
                let u = if e.tri as usize == t { f.tri } else { e.tri };
                let ui = u as usize;
                let joins = touched.contains(&u)
                    && !assigned.contains(&u)
                    && work.tri_material[ui] == work.tri_material[s]
                    && work.tri_group[ui] == work.tri_group[s]
                    && normal(corners[ui]).dot(n) > 0.0
                    && corners[ui].iter().all(|&c| (c - origin).dot(n).abs() <= plane_tol)
                    && (0..3).all(|c| vertex_of.get(&points[ui][c]).is_none_or(|&v| v == work.tris[ui][c]));
                if joins {
                    assigned.insert(u);
                    (0..3).for_each(|c| {
                        vertex_of.insert(points[ui][c], work.tris[ui][c]);
                    });
                    tris.push(u);
                }
            }
        }
        tris.sort_unstable();
        regions.push(Region { tris, vertex_of });
    }
    regions
}

/// Adds to `cut_by` (kept sorted) the crossings that changed each
/// triangle (`causes`, by work triangle): directly, and through the other
/// triangles of its region, which is re-triangulated as one.
fn record_causes(work: &Work, regions: &[Region], mut causes: Vec<(u32, Crossing)>, cut_by: &mut Vec<(u32, Crossing, bool)>) {
    causes.sort_unstable();
    causes.dedup();
    let of = |t: u32| {
        let from = causes.partition_point(|c| c.0 < t);
        causes[from..].iter().take_while(move |c| c.0 == t).map(|c| c.1)
    };
    for region in regions {
        let mut shared: Vec<Crossing> = region.tris.iter().flat_map(|&t| of(t)).collect();
        shared.sort_unstable();
        shared.dedup();
        for &t in &region.tris {
            let origin = work.tri_origin[t as usize];
            cut_by.extend(of(t).map(|c| (origin, c, true)));
            cut_by.extend(shared.iter().map(|&c| (origin, c, false)));
        }
    }
    cut_by.sort_unstable();
    cut_by.dedup();
}

/// One region's plan: its points and the pieces to insert.
struct Plan {
    region: Region,
    /// The region's plane: origin, two axes and the normal.
    frame: [DVec3; 4],
    /// Point ids; the index is the local id.
    points: Vec<u32>,
    local: HashMap<u32, usize>,
    /// Outline pieces (point ids) and whether each is a rim.
    outline: Vec<([u32; 2], bool)>,
    on_outline: HashSet<u32>,
    /// Segments (point ids, deduplicated), whether they cross (not along an
    /// edge), and the points found inside each.
    cuts: Vec<([u32; 2], bool, Vec<u32>)>,
    /// The pieces to insert, once [`Plan::finish_pieces`] ran.
    pieces: Vec<([u32; 2], bool)>,
    /// Pieces on the outline (no constraint needed): seams.
    seams: Vec<(u32, u32)>,
}

impl Plan {
    fn add_point(&mut self, p: u32) -> usize {
        let next = self.points.len();
        *self.local.entry(p).or_insert_with(|| {
            self.points.push(p);
            next
        })
    }

    /// Splits the segments at their inner points, merges duplicates, drops
    /// the pieces on the outline and the points where two collinear pieces
    /// meet and nothing else does (see the module doc, step 4).
    fn finish_pieces(&mut self, work: &Work, tol: f64) {
        let pos = |p: u32| work.points[p as usize].as_dvec3();
        let mut pieces: BTreeMap<(u32, u32), bool> = BTreeMap::new();
        for ([a, b], across, inner) in &self.cuts {
            let (pa, dir) = (pos(*a), pos(*b) - pos(*a));
            let mut chain: Vec<(f64, u32)> = inner.iter().map(|&p| ((pos(p) - pa).dot(dir), p)).collect();
            chain.push((f64::NEG_INFINITY, *a));
            chain.push((f64::INFINITY, *b));
            chain.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
            chain.dedup_by_key(|x| x.1);
            for w in chain.windows(2) {
                if w[0].1 != w[1].1 {
                    *pieces.entry(edge_key(w[0].1, w[1].1)).or_insert(false) |= *across;
                }
            }
        }
        let outline: HashSet<(u32, u32)> = self.outline.iter().map(|&([a, b], _)| edge_key(a, b)).collect();
        let on_outline: Vec<(u32, u32)> = pieces.keys().copied().filter(|k| outline.contains(k)).collect();
        for k in &on_outline {
            pieces.remove(k);
        }
        self.seams.extend(on_outline);

        // Joints: a free point of two collinear pieces.
        let mut at: HashMap<u32, Vec<(u32, u32)>> = HashMap::new();
        for &(a, b) in pieces.keys() {
            at.entry(a).or_default().push((a, b));
            at.entry(b).or_default().push((a, b));
        }
        let mut joints: Vec<u32> = at
            .iter()
            .filter(|(p, list)| list.len() == 2 && !self.region.vertex_of.contains_key(p) && !self.on_outline.contains(p))
            .map(|(&p, _)| p)
            .collect();
        joints.sort_unstable();
        for x in joints {
            let Some(list) = at.get(&x).filter(|l| l.len() == 2).cloned() else { continue };
            let other = |k: (u32, u32)| if k.0 == x { k.1 } else { k.0 };
            let (a, b) = (other(list[0]), other(list[1]));
            let merged = edge_key(a, b);
            let (pa, pb, px) = (pos(a), pos(b), pos(x));
            let ab = pb - pa;
            let s = (px - pa).dot(ab) / ab.length_squared();
            if a == b || pieces.contains_key(&merged) || !(0.0..=1.0).contains(&s) || px.distance(pa + ab * s) > tol {
                continue;
            }
            let across = pieces.remove(&list[0]).unwrap_or(false) | pieces.remove(&list[1]).unwrap_or(false);
            pieces.insert(merged, across);
            at.remove(&x);
            for (end, old) in [(a, list[0]), (b, list[1])] {
                if let Some(l) = at.get_mut(&end) {
                    l.retain(|&k| k != old);
                    l.push(merged);
                }
            }
        }
        self.pieces = pieces.into_iter().map(|((a, b), across)| ([a, b], across)).collect();
        // Only the points the triangulation needs: corners, outline and piece ends.
        let mut used: Vec<u32> = self.region.vertex_of.keys().copied().collect();
        used.extend(self.on_outline.iter().copied());
        used.extend(self.pieces.iter().flat_map(|p| p.0));
        used.sort_unstable();
        used.dedup();
        self.points.clear();
        self.local.clear();
        for p in used {
            self.add_point(p);
        }
    }
}

/// The plan of one region: its outline (with the points its edges take) and
/// its segments with the points within the tolerance of each.
#[allow(clippy::too_many_arguments)]
fn plan_region(
    work: &Work,
    points: &[[u32; 3]],
    corners: &[[DVec3; 3]],
    edge_users: &EdgeUsers,
    edge_points: &HashMap<(u32, u32), Vec<u32>>,
    constraints: &BTreeMap<u32, Vec<Constraint>>,
    region: Region,
    tol: &CutTolerances,
) -> Plan {
    let first = region.tris[0] as usize;
    let n = normal(corners[first]);
    let u = (corners[first][1] - corners[first][0]).normalize_or_zero();
    let frame = [corners[first][0], u, n.cross(u), n];
    let members: HashSet<u32> = region.tris.iter().copied().collect();
    let mut plan = Plan {
        region,
        frame,
        points: Vec::new(),
        local: HashMap::new(),
        outline: Vec::new(),
        on_outline: HashSet::new(),
        cuts: Vec::new(),
        pieces: Vec::new(),
        seams: Vec::new(),
    };
    let tris = plan.region.tris.clone();
    let pos = |p: u32| work.points[p as usize].as_dvec3();
    let mut outline: BTreeMap<(u32, u32), bool> = BTreeMap::new();
    for &t in &tris {
        for k in 0..3 {
            let (a, b) = (points[t as usize][k], points[t as usize][(k + 1) % 3]);
            let users = edge_users.of(a, b);
            if users.len() == 2 && users.iter().all(|e| members.contains(&e.tri)) {
                continue;
            }
            let mut chain = vec![a];
            if let Some(list) = edge_points.get(&edge_key(a, b)) {
                let mut along: Vec<(f64, u32)> = list.iter().map(|&p| ((pos(p) - pos(a)).dot(pos(b) - pos(a)), p)).collect();
                along.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
                chain.extend(along.into_iter().map(|x| x.1));
            }
            chain.push(b);
            chain.dedup();
            for w in chain.windows(2) {
                // Never split, rims included: points added on a rim are boundary
                // points, which zipping welds to other surfaces' rim points
                // within its tolerance (fins on one axis: their rims meet there).
                outline.insert(edge_key(w[0], w[1]), false);
            }
            plan.on_outline.extend(chain);
        }
    }
    plan.outline = outline.into_iter().map(|((a, b), rim)| ([a, b], rim)).collect();
    let mut cuts: BTreeMap<(u32, u32), bool> = BTreeMap::new();
    for t in &tris {
        for &([a, b], across) in constraints.get(t).map(Vec::as_slice).unwrap_or_default() {
            *cuts.entry(edge_key(a, b)).or_insert(false) |= across;
        }
    }
    plan.cuts = cuts.into_iter().map(|((a, b), across)| ([a, b], across, Vec::new())).collect();
    // Points within the tolerance of a segment split it.
    let mut candidates: Vec<u32> = plan.region.vertex_of.keys().copied().collect();
    candidates.extend(plan.on_outline.iter().copied());
    candidates.extend(plan.cuts.iter().flat_map(|c| c.0));
    candidates.sort_unstable();
    candidates.dedup();
    let boxes: Vec<Aabb> = plan.cuts.iter().map(|c| Aabb::of_points(&c.0.map(|p| work.points[p as usize]), tol.contact as f32)).collect();
    let tree = AabbTree::build(boxes);
    let mut found = Vec::new();
    for &p in &candidates {
        let q = work.points[p as usize];
        found.clear();
        tree.query(&Aabb { min: q, max: q }, &mut found);
        for &c in &found {
            let cut = &mut plan.cuts[c as usize];
            if !cut.0.contains(&p) && on_segment(pos(cut.0[0]), pos(cut.0[1]), q.as_dvec3(), tol.contact) {
                cut.2.push(p);
            }
        }
    }
    plan
}

/// Splits the segments of each region where two of them cross (three
/// surfaces meet at a point); crossings closer than `tol` are one point,
/// across regions too, and one within `tol` of a point already on both
/// segments is that point.
fn split_at_crossings(work: &mut Work, plans: &mut [Plan], tol: f64) {
    let mut found: Vec<(usize, usize, usize, Vec3)> = Vec::new();
    for (r, plan) in plans.iter().enumerate() {
        let pos = |p: u32| work.points[p as usize].as_dvec3();
        let boxes: Vec<Aabb> = plan.cuts.iter().map(|c| Aabb::of_points(&c.0.map(|p| work.points[p as usize]), tol as f32)).collect();
        let tree = AabbTree::build(boxes.clone());
        let mut hits = Vec::new();
        for (i, c) in plan.cuts.iter().enumerate() {
            hits.clear();
            tree.query(&boxes[i], &mut hits);
            hits.sort_unstable();
            for &j in hits.iter().filter(|&&j| j as usize > i) {
                let d = &plan.cuts[j as usize];
                if c.0.iter().any(|p| d.0.contains(p)) {
                    continue;
                }
                let Some(q) = segment_crossing([pos(c.0[0]), pos(c.0[1])], [pos(d.0[0]), pos(d.0[1])], tol) else { continue };
                let shared = c.2.iter().any(|p| (d.2.contains(p) || d.0.contains(p)) && pos(*p).distance(q) <= 2.0 * tol)
                    || d.2.iter().any(|p| c.0.contains(p));
                if !shared {
                    found.push((r, i, j as usize, q.as_vec3()));
                }
            }
        }
    }
    let positions: Vec<Vec3> = found.iter().map(|f| f.3).collect();
    let ids = push_clustered(work, &positions, tol);
    for (&(r, i, j, _), &p) in found.iter().zip(&ids) {
        for c in [i, j] {
            let inner = &mut plans[r].cuts[c].2;
            if !inner.contains(&p) {
                inner.push(p);
            }
        }
    }
}

/// Gives each piece that another surface also has as an edge a point of its
/// own (see the module doc, step 5).
fn separate_shared_pieces(work: &mut Work, plans: &mut [Plan], edge_users: &EdgeUsers, out: &mut CutOutcome, tol: f64) {
    let in_region: HashSet<u32> = plans.iter().flat_map(|p| p.region.tris.iter().copied()).collect();
    let outline: HashSet<(u32, u32)> = plans.iter().flat_map(|p| p.outline.iter().map(|&([a, b], _)| edge_key(a, b))).collect();
    let mut claimed: HashSet<(u32, u32)> = HashSet::new();
    let mut needs: BTreeMap<(u32, u32), Vec<(usize, usize)>> = BTreeMap::new();
    for (r, plan) in plans.iter().enumerate() {
        for (i, &([a, b], _)) in plan.pieces.iter().enumerate() {
            let key = edge_key(a, b);
            let existing = outline.contains(&key) || edge_users.of(a, b).iter().any(|e| !in_region.contains(&e.tri));
            if existing || !claimed.insert(key) {
                needs.entry(key).or_default().push((r, i));
            }
        }
    }
    let mut split: Vec<(usize, usize, u32)> = Vec::new();
    for ((lo, hi), list) in needs {
        let (a, b) = (work.points[lo as usize].as_dvec3(), work.points[hi as usize].as_dvec3());
        let count = list.len() as f64;
        if a.distance(b) * 0.5 * SEPARATION_OFFSET.min(1.0 - SEPARATION_OFFSET) / count <= 2.0 * tol {
            out.shared_left += list.len();
            continue;
        }
        for (k, (r, i)) in list.into_iter().enumerate() {
            let s = 0.25 + 0.5 * (k as f64 + SEPARATION_OFFSET) / count;
            let m = work.push_point(a.lerp(b, s).as_vec3());
            split.push((r, i, m));
            out.lines_separated += 1;
        }
    }
    split.sort_unstable_by(|x, y| (x.0, std::cmp::Reverse(x.1)).cmp(&(y.0, std::cmp::Reverse(y.1))));
    for (r, i, m) in split {
        let plan = &mut plans[r];
        let ([a, b], across) = plan.pieces.remove(i);
        plan.pieces.push(([a, m], across));
        plan.pieces.push(([m, b], across));
        plan.add_point(m);
    }
}

/// Separates, in every surface but one, each point edge that the
/// triangulations gave to two surfaces (the users of an edge made by the cut,
/// `made`, paired by facing: opposite directions and the nearest normals).
/// Step 5 separates the pieces two regions both insert; this catches the
/// rest: two points that both regions hold (the ends of a short piece of a
/// line crossing both, points merged within the contact tolerance) joined by
/// an unconstrained Delaunay edge in each. A point goes on the edge, off the
/// midpoint, in the two triangles of each later surface, which then meets the
/// first along the line without sharing an edge there. An edge too short for
/// a point farther than `2 tol` from both ends (the weld would merge it back)
/// is collapsed instead: it lies on both planes, so its ends are one point of
/// the line, and the triangles on it vanish.
fn unshare_made_edges(work: &mut Work, made: impl Fn(u32) -> bool, out: &mut CutOutcome, tol: f64) {
    let unit_normal = |work: &Work, t: u32| work.tri_cross(t as usize).normalize_or_zero();
    // A triangle split once is not split again in the same pass (its uses are stale).
    for _ in 0..MAX_UNSHARE_PASSES {
        let edges = sorted_edges(work);
        let shared: Vec<Vec<EdgeUse>> = super::work::edge_runs(&edges)
            .filter(|run| run.len() > 2 && run.iter().any(|e| made(e.tri)))
            .map(<[EdgeUse]>::to_vec)
            .collect();
        if shared.is_empty() {
            return;
        }
        let mut changed: HashSet<u32> = HashSet::new();
        let mut collapse: Vec<(u32, u32)> = Vec::new();
        for run in shared {
            if run.iter().any(|e| changed.contains(&e.tri)) {
                continue;
            }
            changed.extend(run.iter().map(|e| e.tri));
            let mut groups: Vec<Vec<EdgeUse>> = Vec::new();
            let mut left: Vec<EdgeUse> = run;
            while !left.is_empty() {
                let e = left.remove(0);
                let n = unit_normal(work, e.tri);
                let partner = (0..left.len())
                    .filter(|&i| left[i].forward != e.forward)
                    .max_by(|&i, &j| n.dot(unit_normal(work, left[i].tri)).total_cmp(&n.dot(unit_normal(work, left[j].tri))));
                match partner {
                    Some(i) => groups.push(vec![e, left.remove(i)]),
                    None => groups.push(vec![e]),
                }
            }
            let (lo, hi) = (groups[0][0].lo, groups[0][0].hi);
            let (a, b) = (work.points[lo as usize].as_dvec3(), work.points[hi as usize].as_dvec3());
            let later = (groups.len() - 1) as f64;
            if a.distance(b) * 0.5 * SEPARATION_OFFSET.min(1.0 - SEPARATION_OFFSET) / later <= 2.0 * tol {
                collapse.push((lo, hi));
                continue;
            }
            let is_seam = out.seams.contains(&(lo, hi));
            for (k, group) in groups.into_iter().enumerate().skip(1) {
                let s = 0.25 + 0.5 * (k as f64 - 1.0 + SEPARATION_OFFSET) / later;
                let m = work.push_point(a.lerp(b, s).as_vec3());
                let mut mid_vertex: HashMap<(u32, u32), u32> = HashMap::new();
                for e in group {
                    let t = e.tri as usize;
                    let c = e.corner as usize;
                    let v = work.tris[t];
                    let (va, vb, vo) = (v[c], v[(c + 1) % 3], v[(c + 2) % 3]);
                    let (v_lo, v_hi) = if e.forward { (va, vb) } else { (vb, va) };
                    let mid = *mid_vertex.entry((v_lo, v_hi)).or_insert_with(|| work.push_vertex_lerp(v_lo, v_hi, s as f32, m));
                    work.tris[t] = [va, mid, vo];
                    work.push_tri_like([mid, vb, vo], t);
                    for tri in [[va, mid, vo], [mid, vb, vo]] {
                        let p = tri.map(|x| work.points[work.vertex_point[x as usize] as usize].as_dvec3());
                        out.min_angle = out.min_angle.min(super::work::min_angle(p));
                    }
                }
                out.lines_separated += 1;
                if is_seam {
                    out.seams.extend([edge_key(lo, m), edge_key(m, hi)]);
                }
            }
        }
        if !collapse.is_empty() {
            let mut remap: Vec<u32> = (0..work.points.len() as u32).collect();
            let root = |remap: &Vec<u32>, mut p: u32| {
                while remap[p as usize] != p {
                    p = remap[p as usize];
                }
                p
            };
            for (lo, hi) in collapse {
                let (r_lo, r_hi) = (root(&remap, lo), root(&remap, hi));
                remap[r_lo.max(r_hi) as usize] = r_lo.min(r_hi);
            }
            let remap: Vec<u32> = (0..remap.len() as u32).map(|p| root(&remap, p)).collect();
            work.remap_points(&remap);
            for t in 0..work.tris.len() {
                let [p, q, r] = work.tri_points(t);
                if work.tri_alive[t] && (p == q || q == r || r == p) {
                    work.tri_alive[t] = false;
                    out.edges_collapsed += 1;
                }
            }
            for seam in &mut out.seams {
                *seam = edge_key(remap[seam.0 as usize], remap[seam.1 as usize]);
            }
            out.seams.retain(|s| s.0 != s.1);
        }
    }
}

/// Re-triangulates one region ([`super::planar`]) and writes its triangles
/// over the region's (new vertices interpolate the original triangle they lie in).
fn triangulate_region(work: &mut Work, corners: &[[DVec3; 3]], plan: &Plan, tol: &CutTolerances, out: &mut CutOutcome) {
    let [o, u, v, _] = plan.frame;
    let project = |p: DVec3| DVec2::new((p - o).dot(u), (p - o).dot(v));
    let tris = &plan.region.tris;
    let local = |p: u32| plan.local[&p];
    let region = PlanarRegion {
        points: plan.points.iter().map(|&p| project(work.points[p as usize].as_dvec3())).collect(),
        outline: plan.outline.iter().map(|&([a, b], rim)| ([local(a), local(b)], rim)).collect(),
        cuts: plan.pieces.iter().map(|&([a, b], _)| [local(a), local(b)]).collect(),
        triangles: tris.iter().map(|&t| work.tri_points(t as usize).map(local)).collect(),
        min_angle: tol.min_angle,
        min_spacing: 2.0 * tol.contact,
        max_new_points: 2 * plan.points.len() + 32,
        min_feature: MIN_REFINED_FACE * tol.plane,
        split_offset: 0.2 * ((plan.region.tris[0] as f64 * SEPARATION_OFFSET).fract() - 0.5),
    };
    let Some(result) = planar::triangulate(&region) else {
        out.failed_triangles += tris.len();
        return;
    };
    out.unshared_splits += result.crossings;
    out.dropped_pieces += result.dropped;
    out.refinement_points += result.refinement_points;
    for &t in tris {
        out.replaced_min_angle = out.replaced_min_angle.min(super::work::min_angle(corners[t as usize]));
    }
    // Points: the region's corners keep their vertices; others interpolate.
    let original = |i: usize| tris[i] as usize;
    let mut point_ids = plan.points.clone();
    let mut vertices: Vec<u32> = Vec::with_capacity(plan.points.len() + result.new_points.len());
    for (i, &p) in plan.points.iter().enumerate() {
        let vertex = match plan.region.vertex_of.get(&p) {
            Some(&vertex) => vertex,
            None => {
                let (t, w) = result.point_at[i];
                work.push_vertex_bary(work.tris[original(t)], w.map(|x| x as f32), p)
            }
        };
        vertices.push(vertex);
    }
    for q in &result.new_points {
        let c = corners[original(q.triangle)];
        let position = c[0] * q.bary[0] + c[1] * q.bary[1] + c[2] * q.bary[2];
        let p = work.push_point(position.as_vec3());
        point_ids.push(p);
        vertices.push(work.push_vertex_bary(work.tris[original(q.triangle)], q.bary.map(|x| x as f32), p));
    }
    // Faces in their original triangle's slot, then at the end.
    let mut faces = result.faces.clone();
    faces.sort_by_key(|&(_, parent)| parent);
    let mut filled = vec![false; tris.len()];
    for &(f, parent) in &faces {
        let tri = f.map(|i| vertices[i]);
        let t = original(parent);
        if filled[parent] {
            work.push_tri_like(tri, t);
        } else {
            work.tris[t] = tri;
            filled[parent] = true;
        }
        let angle = super::work::min_angle(f.map(|i| work.points[point_ids[i] as usize].as_dvec3()));
        out.min_angle = out.min_angle.min(angle);
    }
    for (i, &t) in tris.iter().enumerate() {
        if !filled[i] {
            work.tri_alive[t as usize] = false;
        }
    }
    out.triangles_cut += tris.len();
    out.seams.extend(result.cut_pieces.iter().map(|&[a, b]| edge_key(point_ids[a], point_ids[b])));
    out.seams.extend(plan.seams.iter().copied());
}

/// The point edges where a cut separates a surface: edges of two triangles
/// with different vertices at an end (the only ones the weld could join),
/// along which a third triangle, not in their plane and not using the edge,
/// lies for more than `tol` (within `tol` of it). Cleaning a cut mesh again
/// finds its cut lines this way, so the weld keeps their sides apart.
pub(crate) fn find_seams(work: &Work, tol: f64) -> HashSet<(u32, u32)> {
    let edges = sorted_edges(work);
    let candidates: Vec<(u32, u32, u32, u32)> = super::work::edge_runs(&edges)
        .filter_map(|run| match run {
            [e, f] if splits_vertices(work, run) => Some((e.lo, e.hi, e.tri, f.tri)),
            _ => None,
        })
        .collect();
    let mut seams = HashSet::new();
    if candidates.is_empty() {
        return seams;
    }
    let live: Vec<u32> = (0..work.tris.len() as u32).filter(|&t| work.tri_alive[t as usize]).collect();
    let tree = AabbTree::build(live.iter().map(|&t| Aabb::of_points(&work.tri_positions(t as usize), tol as f32)).collect());
    for (lo, hi, t1, t2) in candidates {
        let (a, b) = (work.points[lo as usize], work.points[hi as usize]);
        let n1 = work.tri_cross(t1 as usize).normalize_or_zero();
        let lies_along = tree.any(&Aabb::of_points(&[a, b], 0.0), |i| {
            let w = live[i as usize];
            if w == t1 || w == t2 {
                return false;
            }
            let c = work.tri_positions(w as usize).map(|p| p.as_dvec3());
            let nw = normal(c);
            nw.cross(n1).length() >= MIN_CUT_SINE && overlap_length(c, nw, a.as_dvec3(), b.as_dvec3(), tol) > tol
        });
        if lies_along {
            seams.insert((lo, hi));
        }
    }
    seams
}

/// The length of segment `a`–`b` within `tol` of triangle `c` (unit normal `n`).
fn overlap_length(c: [DVec3; 3], n: DVec3, a: DVec3, b: DVec3, tol: f64) -> f64 {
    if (a - c[0]).dot(n).abs() > tol || (b - c[0]).dot(n).abs() > tol {
        return 0.0;
    }
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    for k in 0..3 {
        let inward = n.cross(c[(k + 1) % 3] - c[k]).normalize_or_zero();
        let (da, db) = ((a - c[k]).dot(inward) + tol, (b - c[k]).dot(inward) + tol);
        if da < 0.0 && db < 0.0 {
            return 0.0;
        }
        if da < 0.0 {
            lo = lo.max(da / (da - db));
        } else if db < 0.0 {
            hi = hi.min(da / (da - db));
        }
    }
    (hi - lo).max(0.0) * a.distance(b)
}

/// The pair's intersection segment, or `None` when the triangles do not cross
/// (disjoint, coplanar, or meeting in a point).
fn pair_segment(a: [DVec3; 3], b: [DVec3; 3], plane_tol: f64, tol: f64) -> Option<[DVec3; 2]> {
    let sign = |d: f64| {
        if d.abs() <= tol {
            0
        } else if d > 0.0 {
            1
        } else {
            -1
        }
    };
    let one_side = |s: [i32; 3]| s.iter().all(|&x| x > 0) || s.iter().all(|&x| x < 0);
    // Most candidate pairs end here: one triangle on one side of the other's plane.
    let db = plane_distances(a, b);
    let sb = db.map(sign);
    if one_side(sb) {
        return None;
    }
    let da = plane_distances(b, a);
    let sa = da.map(sign);
    if one_side(sa) {
        return None;
    }
    // Coplanar within the plane tolerance: the coplanar step's.
    if da.iter().all(|d| d.abs() <= plane_tol) && db.iter().all(|d| d.abs() <= plane_tol) {
        return None;
    }
    if sa == [0; 3] || sb == [0; 3] {
        return None;
    }
    let dir = normal(a).cross(normal(b));
    // Shallow crossings are not cut (see MIN_CUT_SINE).
    if dir.length() < MIN_CUT_SINE {
        return None;
    }
    let (ea, eb) = (plane_crossing(a, da, sa)?, plane_crossing(b, db, sb)?);
    let param = |p: DVec3| p.dot(dir);
    let order = |e: [DVec3; 2]| if param(e[0]) <= param(e[1]) { e } else { [e[1], e[0]] };
    let (ea, eb) = (order(ea), order(eb));
    let start = if param(eb[0]) > param(ea[0]) { eb[0] } else { ea[0] };
    let end = if param(eb[1]) < param(ea[1]) { eb[1] } else { ea[1] };
    if param(end) - param(start) <= 0.0 || start.distance(end) <= tol {
        return None;
    }
    Some([start, end])
}

/// Signed distances of `pts` from the plane of `tri` (along its normal): the
/// sign from the exact `orient3d`, the size from the same determinant.
fn plane_distances(tri: [DVec3; 3], pts: [DVec3; 3]) -> [f64; 3] {
    let c = |p: DVec3| robust::Coord3D { x: p.x, y: p.y, z: p.z };
    let twice_area = (tri[1] - tri[0]).cross(tri[2] - tri[0]).length();
    // orient3d is positive below the plane, where the normal points away.
    pts.map(|p| -robust::orient3d(c(tri[0]), c(tri[1]), c(tri[2]), c(p)) / twice_area)
}

/// Where a triangle meets a plane, from its corners' signed distances `d` and
/// signs `s` (not all on one side): two points (equal for a touch).
fn plane_crossing(t: [DVec3; 3], d: [f64; 3], s: [i32; 3]) -> Option<[DVec3; 2]> {
    let mut found = [DVec3::ZERO; 2];
    let mut n = 0;
    let mut push = |p: DVec3| {
        if n < 2 {
            found[n] = p;
        }
        n += 1;
    };
    for i in 0..3 {
        if s[i] == 0 {
            push(t[i]);
        }
    }
    for i in 0..3 {
        let j = (i + 1) % 3;
        if s[i] * s[j] < 0 {
            let u = d[i] / (d[i] - d[j]);
            push(t[i] + (t[j] - t[i]) * u);
        }
    }
    match n {
        1 => Some([found[0], found[0]]),
        2 => Some(found),
        _ => None,
    }
}

/// The live triangles' point edges, sorted ([`sorted_edges`]).
struct EdgeUsers(Vec<EdgeUse>);

impl EdgeUsers {
    /// The uses of the edge between points `a` and `b`.
    fn of(&self, a: u32, b: u32) -> &[EdgeUse] {
        let key = (a.min(b), a.max(b));
        let start = self.0.partition_point(|e| (e.lo, e.hi) < key);
        let end = start + self.0[start..].partition_point(|e| (e.lo, e.hi) == key);
        &self.0[start..end]
    }
}

/// Where `p` lies on the triangle with corners `c`, within `tol` of its edges.
fn locate(c: [DVec3; 3], p: DVec3, tol: f64) -> Loc {
    let (e0, e1, e2) = (c[1] - c[0], c[2] - c[0], p - c[0]);
    let (d00, d01, d11) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
    let (d20, d21) = (e2.dot(e0), e2.dot(e1));
    let denom = d00 * d11 - d01 * d01;
    if denom <= 0.0 {
        return Loc::Outside;
    }
    let b1 = (d11 * d20 - d01 * d21) / denom;
    let b2 = (d00 * d21 - d01 * d20) / denom;
    let bary = [1.0 - b1 - b2, b1, b2];
    let twice_area = e0.cross(e1).length();
    // Distance from the edge opposite corner i: its barycentric times the height.
    let dist: [f64; 3] = [0, 1, 2].map(|i| bary[i] * twice_area / c[(i + 1) % 3].distance(c[(i + 2) % 3]));
    if dist.iter().any(|&d| d < -tol) {
        return Loc::Outside;
    }
    let near: Vec<usize> = (0..3).filter(|&i| dist[i] <= tol).collect();
    match near.as_slice() {
        [] => Loc::Interior,
        [i] => Loc::Edge((i + 1) % 3),
        // Near two edges: at their common corner, which it is not (ids differ):
        // on the edge it is nearer to.
        _ => {
            let i = *near.iter().min_by(|&&x, &&y| dist[x].total_cmp(&dist[y]).then(x.cmp(&y))).unwrap_or(&near[0]);
            let k = (i + 1) % 3;
            let (bk, bn) = (bary[k].max(0.0), bary[(k + 1) % 3].max(0.0));
            if bk + bn <= 0.0 {
                return Loc::Outside;
            }
            Loc::Edge(k)
        }
    }
}

/// True when `p` lies within `tol` of segment `a`–`b`, farther than `tol` from both ends.
fn on_segment(a: DVec3, b: DVec3, p: DVec3, tol: f64) -> bool {
    let ab = b - a;
    let len2 = ab.length_squared();
    if len2 == 0.0 || p.distance(a) <= tol || p.distance(b) <= tol {
        return false;
    }
    let u = (p - a).dot(ab) / len2;
    u > 0.0 && u < 1.0 && p.distance(a + ab * u) <= tol
}

/// The crossing of two segments (nearly in one plane) inside both, farther
/// than `tol` from their ends, when they pass within `2 tol` of each other there.
fn segment_crossing(x: [DVec3; 2], y: [DVec3; 2], tol: f64) -> Option<DVec3> {
    let (d1, d2, r) = (x[1] - x[0], y[1] - y[0], x[0] - y[0]);
    let (a, e, f) = (d1.dot(d1), d2.dot(d2), d2.dot(r));
    let (b, c) = (d1.dot(d2), d1.dot(r));
    let denom = a * e - b * b;
    if denom <= 1e-12 * a * e {
        return None;
    }
    let s = (b * f - c * e) / denom;
    let u = (a * f - b * c) / denom;
    if !(0.0..=1.0).contains(&s) || !(0.0..=1.0).contains(&u) {
        return None;
    }
    let (p, q) = (x[0] + d1 * s, y[0] + d2 * u);
    let mid = (p + q) * 0.5;
    let away = |seg: [DVec3; 2]| mid.distance(seg[0]) > tol && mid.distance(seg[1]) > tol;
    (p.distance(q) <= 2.0 * tol && away(x) && away(y)).then_some(mid)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(p: [[f64; 3]; 3]) -> [DVec3; 3] {
        p.map(DVec3::from)
    }

    #[test]
    fn crossing_triangles_meet_in_their_common_segment() {
        // A in y = 0, B in x = 0.3: they cross along x = 0.3, y = 0.
        let a = tri([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]);
        let b = tri([[0.3, -1.0, 0.2], [0.3, 1.0, 0.2], [0.3, 0.0, 0.5]]);
        let [p, q] = pair_segment(a, b, 1e-9, 1e-9).unwrap();
        let (lo, hi) = if p.z < q.z { (p, q) } else { (q, p) };
        assert!(lo.distance(DVec3::new(0.3, 0.0, 0.2)) < 1e-12, "{lo}");
        assert!(hi.distance(DVec3::new(0.3, 0.0, 0.5)) < 1e-12, "{hi}");
    }

    /// Two surfaces whose triangulations both hold the edge from (0,0,0) to
    /// (len,0,0): A in z = 0, B in y = 0, two triangles each on the edge.
    fn two_surfaces_on_one_edge(len: f32) -> Work {
        let p = [[0.0, 0.0, 0.0], [len, 0.0, 0.0], [0.5, 1.0, 0.0], [0.5, -1.0, 0.0], [0.5, 0.0, 1.0], [0.5, 0.0, -1.0]];
        let mesh = crate::mesh::Mesh {
            positions: p.iter().map(|&q| glam::Vec3::from(q)).collect(),
            normals: vec![glam::Vec3::Z; 6],
            indices: vec![0, 1, 2, 1, 0, 3, 0, 1, 4, 1, 0, 5],
            tri_material: vec![0; 4],
            tri_group: vec![0; 4],
            ..crate::mesh::Mesh::default()
        };
        super::super::weld::weld_points(&mesh, 0.0)
    }

    #[test]
    fn an_edge_of_two_surfaces_is_split_in_the_second_only() {
        let mut work = two_surfaces_on_one_edge(1.0);
        let area = work.total_area();
        let mut out = CutOutcome { min_angle: f64::INFINITY, ..CutOutcome::default() };
        unshare_made_edges(&mut work, |_| true, &mut out, 1e-6);
        assert_eq!(super::super::work::count_boundary_and_non_manifold(&work).1, 0);
        assert_eq!((work.tris.len(), out.lines_separated, out.edges_collapsed), (6, 1, 0));
        assert!((work.total_area() - area).abs() < 1e-12 * area, "area {} against {area}", work.total_area());
        // The first surface (z = 0) keeps its edge; the second (y = 0) holds the new point on it.
        let on_plane = |axis: usize| (0..work.tris.len()).filter(|&t| work.tri_positions(t).iter().all(|q| q[axis] == 0.0)).count();
        assert_eq!((on_plane(2), on_plane(1)), (2, 4));
        let m = work.points[6];
        assert!(m.y == 0.0 && m.z == 0.0 && m.x > 0.25 && m.x < 0.75, "{m}");
    }

    #[test]
    fn an_edge_of_two_surfaces_too_short_to_split_is_collapsed() {
        // 3 µm against a 1 µm tolerance: no point on it is 2 µm from both ends.
        let mut work = two_surfaces_on_one_edge(3e-6);
        let mut out = CutOutcome { min_angle: f64::INFINITY, ..CutOutcome::default() };
        unshare_made_edges(&mut work, |_| true, &mut out, 1e-6);
        assert_eq!((out.lines_separated, out.edges_collapsed), (0, 4));
        assert_eq!((0..4).filter(|&t| work.tri_alive[t]).count(), 0);
        // Made edges only: untouched triangles' shared edges are left alone.
        let mut work = two_surfaces_on_one_edge(1.0);
        unshare_made_edges(&mut work, |_| false, &mut out, 1e-6);
        assert_eq!(super::super::work::count_boundary_and_non_manifold(&work).1, 1);
    }

    #[test]
    fn touching_in_a_point_or_coplanar_is_no_segment() {
        let a = tri([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]);
        // Touches A's plane in one corner only.
        let b = tri([[0.2, 0.0, 0.2], [0.2, 1.0, 0.2], [0.4, 1.0, 0.2]]);
        assert!(pair_segment(a, b, 1e-9, 1e-9).is_none());
        // Coplanar and overlapping.
        let c = tri([[0.1, 0.0, 0.1], [2.0, 0.0, 0.1], [0.1, 0.0, 2.0]]);
        assert!(pair_segment(a, c, 1e-9, 1e-9).is_none());
    }
}
