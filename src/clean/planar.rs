//! Re-triangulating a planar region with constraints, to a smallest angle.
//!
//! Why: cutting a triangle along the lines where other surfaces cross it,
//! one triangle at a time, leaves slivers wherever a line passes near a
//! corner or runs nearly along an edge (the dining room's floor went from a
//! smallest angle of 32° to 1.3e-4°), and a vertex interpolated across a
//! sliver cannot resolve the light. Here the cut triangles of one plane are
//! re-triangulated together: a constrained Delaunay triangulation (the
//! `spade` crate, exact predicates) of the region's corners and points, its
//! outline and the cut lines as constraints, then Delaunay refinement (Chew
//! and Ruppert; Shewchuk, *Delaunay refinement algorithms for triangular mesh
//! generation*, 2002): a triangle whose smallest angle is below the target
//! gets its circumcentre as a new point, unless that point would lie beyond
//! a constraint or encroach one (lie inside its diametral circle), in which
//! case the constraint is split at its midpoint instead.
//!
//! What may change: points are added inside the region and on the cut lines
//! (splitting a cut line does not move it), and on a rim of the surface
//! (an outline edge no other triangle uses). The rest of the outline is kept
//! whole: it is shared with triangles outside the region, which would
//! otherwise gain a T-junction. An angle between two constraints cannot be
//! improved and is left (the input allows no better); a triangle needing a
//! point closer than `min_spacing` to another is left; at most
//! `max_new_points` points are added (the result says whether that was
//! enough).
//!
//! The region is given by its original triangles (2D, counter-clockwise):
//! the output keeps the faces whose centroid lies in one of them, and every
//! new point reports the original triangle and barycentric coordinates it
//! lies at, so the caller places it on the surface and interpolates its
//! attributes.

use glam::DVec2;
use spade::handles::{FixedDirectedEdgeHandle, FixedFaceHandle, FixedVertexHandle, InnerTag};
use spade::{ConstrainedDelaunayTriangulation, FloatTriangulation, Point2, PositionInTriangulation, Triangulation};
use std::collections::{HashMap, HashSet, VecDeque};
use std::f64::consts::PI;

type Cdt = ConstrainedDelaunayTriangulation<Point2<f64>>;

/// A planar region to re-triangulate (2D coordinates in the region's plane).
pub(crate) struct PlanarRegion {
    /// Positions of the region's points; the index is the point's local id.
    pub points: Vec<DVec2>,
    /// Outline pieces (local ids) and whether each may be split (a rim).
    pub outline: Vec<([usize; 2], bool)>,
    /// Cut pieces (local ids): constraints that may be split.
    pub cuts: Vec<[usize; 2]>,
    /// The original triangles (local ids, counter-clockwise): the region.
    pub triangles: Vec<[usize; 3]>,
    /// Target smallest angle (radians); 0 refines nothing.
    pub min_angle: f64,
    /// No new point closer than this to another.
    pub min_spacing: f64,
    /// At most this many points are added by refinement.
    pub max_new_points: usize,
    /// Faces whose shortest side is shorter than this are not refined.
    pub min_feature: f64,
    /// In [-0.1, 0.1]: splits of a cut piece land this fraction off the
    /// midpoint (or the power-of-two distance), so regions that share a
    /// line (two surfaces crossing) never split it at one point.
    pub split_offset: f64,
}

/// A point the triangulation added (a crossing of two cut pieces, or refinement).
#[derive(Clone, Copy, Debug)]
pub(crate) struct NewPoint {
    /// Its position in the plane (the tests read it).
    #[cfg_attr(not(test), allow(dead_code))]
    pub xy: DVec2,
    /// The original triangle (index into [`PlanarRegion::triangles`]) it lies in.
    pub triangle: usize,
    /// Its barycentric coordinates there.
    pub bary: [f64; 3],
}

/// The re-triangulated region.
#[derive(Default)]
pub(crate) struct PlanarResult {
    /// Points added, local ids `points.len()..` in order.
    pub new_points: Vec<NewPoint>,
    /// Faces (local ids), counter-clockwise, with the original triangle holding each centroid.
    pub faces: Vec<([usize; 3], usize)>,
    /// The cut pieces as the result has them (split by crossings and refinement), local ids.
    pub cut_pieces: Vec<[usize; 2]>,
    /// Crossings of two cut pieces that the triangulation split.
    pub crossings: usize,
    /// Constraint pieces that could not be inserted (they crossed the outline).
    pub dropped: usize,
    /// Points added by refinement.
    pub refinement_points: usize,
    /// False when refinement stopped at `max_new_points`.
    pub complete: bool,
    /// Points of the input at one position with an earlier one (merged there).
    pub merged_points: usize,
    /// Vertices within the snap distance of a cut piece that were put on it.
    pub snapped: usize,
    /// For each input point: the original triangle it lies in and its barycentric coordinates there.
    pub point_at: Vec<(usize, [f64; 3])>,
}

/// Re-triangulates `region` (see the module doc). `None` when the
/// triangulation refuses a point (non-finite coordinates).
pub(crate) fn triangulate(region: &PlanarRegion) -> Option<PlanarResult> {
    let mut cdt = Cdt::new();
    let locator = Locator::new(&region.points, &region.triangles);
    // Local ids by vertex index; input points at one position share a vertex.
    let mut local_of: Vec<usize> = Vec::with_capacity(region.points.len());
    let mut handle_of: Vec<FixedVertexHandle> = Vec::with_capacity(region.points.len());
    let mut result = PlanarResult { complete: true, ..PlanarResult::default() };
    for (i, p) in region.points.iter().enumerate() {
        let h = cdt.insert(Point2::new(p.x, p.y)).ok()?;
        if h.index() == local_of.len() {
            local_of.push(i);
        } else {
            result.merged_points += 1;
        }
        handle_of.push(h);
    }
    let key = |a: FixedVertexHandle, b: FixedVertexHandle| (a.index().min(b.index()), a.index().max(b.index()));
    let edge_key = |cdt: &Cdt, e: FixedDirectedEdgeHandle| {
        let e = cdt.directed_edge(e);
        key(e.from().fix(), e.to().fix())
    };
    // Outline pieces, kept or splittable (rims), as vertex pairs.
    let mut kept: HashSet<(usize, usize)> = HashSet::new();
    let mut rims: HashSet<(usize, usize)> = HashSet::new();
    for &([a, b], rim) in &region.outline {
        let (ha, hb) = (handle_of[a], handle_of[b]);
        if ha == hb {
            continue;
        }
        let edges = cdt.try_add_constraint(ha, hb);
        if edges.is_empty() && !cdt.exists_constraint(ha, hb) {
            result.dropped += 1;
        }
        for e in edges {
            let k = edge_key(&cdt, e);
            if rim && !kept.contains(&k) {
                rims.insert(k);
            } else {
                rims.remove(&k);
                kept.insert(k);
            }
        }
    }
    // Cut pieces: crossings between them are split; one crossing the outline is dropped.
    for &[a, b] in &region.cuts {
        let (ha, hb) = (handle_of[a], handle_of[b]);
        if ha == hb || cdt.exists_constraint(ha, hb) {
            continue;
        }
        let conflicts: Vec<(usize, usize)> = cdt.get_conflicting_edges_between_vertices(ha, hb).map(|e| edge_key(&cdt, e.fix())).collect();
        if conflicts.is_empty() {
            cdt.add_constraint(ha, hb);
        } else if conflicts.iter().any(|k| kept.contains(k) || rims.contains(k)) {
            result.dropped += 1;
        } else {
            let before = cdt.num_vertices();
            cdt.add_constraint_and_split(ha, hb, |p| p);
            result.crossings += cdt.num_vertices() - before;
        }
    }
    // Outside the region: faces reached from the hull across an even number
    // of outline pieces (a centroid test misjudges the slivers that the
    // rounded positions of an edge's points make along it).
    let outside = outside_faces(&cdt, &kept, &rims);
    result.snapped += snap_to_cuts(&mut cdt, &outside, &kept, &rims, 2.0 * region.min_spacing);
    if region.min_angle > 0.0 {
        refine(&mut cdt, region, &outside, &mut kept, &mut rims, &mut result);
        result.snapped += snap_to_cuts(&mut cdt, &outside, &kept, &rims, 2.0 * region.min_spacing);
    }

    // Where every point lies on the original triangles.
    let at = |xy: DVec2| locator.locate(xy).unwrap_or_else(|| locator.nearest(xy));
    result.point_at = region.points.iter().map(|&p| at(p)).collect();
    let first_new = local_of.len();
    for v in first_new..cdt.num_vertices() {
        let p = cdt.vertex(FixedVertexHandle::from_index(v)).position();
        let xy = DVec2::new(p.x, p.y);
        let (triangle, bary) = at(xy);
        result.new_points.push(NewPoint { xy, triangle, bary });
    }
    let local =
        |h: FixedVertexHandle| if h.index() < first_new { local_of[h.index()] } else { region.points.len() + h.index() - first_new };
    for f in cdt.inner_faces().filter(|f| !outside.contains(&f.fix())) {
        let [a, b, c] = f.positions();
        let (t, _) = at(DVec2::new((a.x + b.x + c.x) / 3.0, (a.y + b.y + c.y) / 3.0));
        result.faces.push((f.vertices().map(|v| local(v.fix())), t));
    }
    for e in cdt.undirected_edges() {
        let [a, b] = e.vertices().map(|v| v.fix());
        if e.is_constraint_edge() && !kept.contains(&key(a, b)) && !rims.contains(&key(a, b)) {
            result.cut_pieces.push([local(a), local(b)]);
        }
    }
    Some(result)
}

/// Delaunay refinement of the inside faces (see the module doc).
fn refine(
    cdt: &mut Cdt,
    region: &PlanarRegion,
    outside: &HashSet<FixedFaceHandle<InnerTag>>,
    kept: &mut HashSet<(usize, usize)>,
    rims: &mut HashSet<(usize, usize)>,
    result: &mut PlanarResult,
) {
    let key = |a: FixedVertexHandle, b: FixedVertexHandle| (a.index().min(b.index()), a.index().max(b.index()));
    let skinny = |p: [Point2<f64>; 3]| smallest_angle(p).1 < region.min_angle;
    let scan = |cdt: &Cdt| -> VecDeque<[FixedVertexHandle; 3]> {
        cdt.inner_faces().filter(|f| skinny(f.positions()) && !outside.contains(&f.fix())).map(|f| f.vertices().map(|v| v.fix())).collect()
    };
    let mut queue = scan(cdt);
    let spacing2 = region.min_spacing * region.min_spacing;
    // Points added on a constraint: the ends of the constraint they split, as given.
    let mut chains: HashMap<usize, [usize; 2]> = HashMap::new();
    let mut added = 0;
    let mut added_at_scan = 0;
    loop {
        let Some(vs) = queue.pop_front() else {
            // Flips far from a new point (restoring the Delaunay property
            // after a constraint split) can make skinny faces nobody queued.
            if added == added_at_scan {
                break;
            }
            added_at_scan = added;
            queue = scan(cdt);
            continue;
        };
        if added >= region.max_new_points {
            result.complete = false;
            break;
        }
        let Some(face) = find_face(cdt, vs) else { continue };
        let f = cdt.face(face);
        let pos = f.positions();
        if !skinny(pos) || outside.contains(&face) {
            continue;
        }
        // A face this small is left: tiny features where many lines meet,
        // which refined make triangles the coplanar step takes for overlaps.
        let (corner, _) = smallest_angle(pos);
        if shortest2(pos) <= region.min_feature * region.min_feature {
            continue;
        }
        // An angle between two constraints stays (the input allows no better).
        let at = |i: usize| f.vertices()[i].fix();
        let (z, x, y) = (at(corner), at((corner + 1) % 3), at((corner + 2) % 3));
        if cdt.exists_constraint(z, x) && cdt.exists_constraint(z, y) {
            continue;
        }
        // Nor one whose shortest side joins points added on two constraints
        // from one vertex: splitting there only moves the small angle inward
        // (Miller, Pav and Walkington, "When and why Delaunay refinement
        // algorithms work", 2005; spade's refinement does the same).
        if let (Some(cx), Some(cy)) = (chains.get(&x.index()), chains.get(&y.index())) {
            if cx.iter().any(|v| cy.contains(v)) && !cdt.exists_constraint(x, y) {
                continue;
            }
        }
        let c = f.circumcenter();
        let centroid = Point2::new((pos[0].x + pos[1].x + pos[2].x) / 3.0, (pos[0].y + pos[1].y + pos[2].y) / 3.0);
        // Beyond a constraint: split that constraint, if it may be split.
        let beyond = cdt.get_conflicting_edges_between_points(centroid, c).next().map(|e| e.fix());
        let split_edge = match beyond {
            Some(e) => Some(e),
            None => encroached(cdt, c, kept, region.min_angle),
        };
        let new_vertex = match split_edge {
            Some(e) => {
                let k = {
                    let e = cdt.directed_edge(e);
                    key(e.from().fix(), e.to().fix())
                };
                if kept.contains(&k) {
                    // Beyond or encroaching a kept edge: any point here would
                    // crowd that edge, which needs a point on it to improve.
                    continue;
                } else {
                    match split_constraint(cdt, e, rims, &mut chains, spacing2, region.split_offset) {
                        Some(v) => v,
                        None => {
                            // Too short to split: it is kept from now on.
                            rims.remove(&k);
                            kept.insert(k);
                            continue;
                        }
                    }
                }
            }
            None => {
                if cdt.get_vertices_in_circle(c, spacing2).next().is_some() {
                    continue;
                }
                match cdt.insert(c) {
                    Ok(v) => v,
                    Err(_) => continue,
                }
            }
        };
        added += 1;
        result.refinement_points += 1;
        queue.push_back(vs);
        let around: Vec<[FixedVertexHandle; 3]> = cdt
            .vertex(new_vertex)
            .out_edges()
            .filter_map(|e| e.face().as_inner())
            .filter(|f| skinny(f.positions()))
            .map(|f| f.vertices().map(|v| v.fix()))
            .collect();
        queue.extend(around);
    }
}

/// Puts every vertex within `snap` of a cut piece of its face (not at its
/// ends) on that piece: the piece is split there. Lines meeting at a very
/// small angle (thin triangles crossing near one spot) otherwise leave faces
/// thinner than the weld tolerance, which the next round removes as
/// degenerate. Returns the number of vertices snapped.
fn snap_to_cuts(
    cdt: &mut Cdt,
    outside: &HashSet<FixedFaceHandle<InnerTag>>,
    kept: &HashSet<(usize, usize)>,
    rims: &HashSet<(usize, usize)>,
    snap: f64,
) -> usize {
    let mut snapped = 0;
    for _ in 0..64 {
        let mut found: Option<(FixedVertexHandle, FixedVertexHandle, FixedVertexHandle)> = None;
        'faces: for f in cdt.inner_faces().filter(|f| !outside.contains(&f.fix())) {
            for e in f.adjacent_edges() {
                let (a, b) = (e.from().fix(), e.to().fix());
                let k = (a.index().min(b.index()), a.index().max(b.index()));
                if !e.is_constraint_edge() || kept.contains(&k) || rims.contains(&k) {
                    continue;
                }
                let Some(c) = e.opposite_vertex() else { continue };
                let (pa, pb, pc) = (e.from().position(), e.to().position(), c.position());
                let (ab, ac) = (DVec2::new(pb.x - pa.x, pb.y - pa.y), DVec2::new(pc.x - pa.x, pc.y - pa.y));
                let s = ac.dot(ab) / ab.length_squared();
                if s > 0.0 && s < 1.0 && ab.perp_dot(ac).abs() / ab.length() <= snap {
                    found = Some((a, b, c.fix()));
                    break 'faces;
                }
            }
        }
        let Some((a, b, c)) = found else { break };
        let Some(e) = cdt.get_edge_from_neighbors(a, b).map(|e| e.as_undirected().fix()) else { break };
        cdt.remove_constraint_edge(e);
        cdt.try_add_constraint(a, c);
        cdt.try_add_constraint(c, b);
        snapped += 1;
    }
    snapped
}

/// The faces outside the region: those reached from the convex hull across
/// an even number of outline pieces (`kept` and `rims`), as a flood fill
/// that crosses every edge.
fn outside_faces(cdt: &Cdt, kept: &HashSet<(usize, usize)>, rims: &HashSet<(usize, usize)>) -> HashSet<FixedFaceHandle<InnerTag>> {
    let is_outline = |a: usize, b: usize| {
        let k = (a.min(b), a.max(b));
        kept.contains(&k) || rims.contains(&k)
    };
    let mut parity: HashMap<FixedFaceHandle<InnerTag>, bool> = HashMap::new();
    let mut stack: Vec<(FixedFaceHandle<InnerTag>, bool)> = Vec::new();
    for f in cdt.inner_faces() {
        for e in f.adjacent_edges() {
            if e.rev().face().is_outer() && !parity.contains_key(&f.fix()) {
                let crossed = is_outline(e.from().fix().index(), e.to().fix().index());
                parity.insert(f.fix(), crossed);
                stack.push((f.fix(), crossed));
            }
        }
    }
    while let Some((f, inside)) = stack.pop() {
        for e in cdt.face(f).adjacent_edges() {
            let Some(g) = e.rev().face().as_inner() else { continue };
            if parity.contains_key(&g.fix()) {
                continue;
            }
            let next = inside ^ is_outline(e.from().fix().index(), e.to().fix().index());
            parity.insert(g.fix(), next);
            stack.push((g.fix(), next));
        }
    }
    parity.into_iter().filter(|&(_, inside)| !inside).map(|(f, _)| f).collect()
}

/// The face with vertices `vs` (in any rotation), if it still exists.
fn find_face(cdt: &Cdt, vs: [FixedVertexHandle; 3]) -> Option<FixedFaceHandle<InnerTag>> {
    let e = cdt.get_edge_from_neighbors(vs[0], vs[1])?;
    let f = e.face().as_inner()?;
    f.vertices().iter().any(|v| v.fix() == vs[2]).then(|| f.fix())
}

/// A constraint edge that inserting `c` would encroach (the cavity of `c`:
/// the faces whose circumcircle holds it, reached without crossing a
/// constraint; a constraint on its border whose diametral circle holds `c`,
/// or for a kept edge, which is never split, the thinner lens from which it
/// subtends more than π − 2 `min_angle`: a point there makes a skinny
/// triangle on it, while the diametral circle of a long kept edge would
/// stop every point near it).
fn encroached(cdt: &Cdt, c: Point2<f64>, kept: &HashSet<(usize, usize)>, min_angle: f64) -> Option<FixedDirectedEdgeHandle> {
    let start = match cdt.locate(c) {
        PositionInTriangulation::OnFace(f) => vec![f],
        PositionInTriangulation::OnEdge(e) => {
            let e = cdt.directed_edge(e);
            if e.is_constraint_edge() {
                return Some(e.fix());
            }
            [e.face().as_inner(), e.rev().face().as_inner()].into_iter().flatten().map(|f| f.fix()).collect()
        }
        _ => return None,
    };
    let coord = |p: Point2<f64>| robust::Coord { x: p.x, y: p.y };
    let mut seen: HashSet<_> = start.iter().copied().collect();
    let mut stack = start;
    while let Some(f) = stack.pop() {
        for e in cdt.face(f).adjacent_edges() {
            if e.is_constraint_edge() {
                let [a, b] = e.positions();
                let (ca, cb) = (DVec2::new(a.x - c.x, a.y - c.y), DVec2::new(b.x - c.x, b.y - c.y));
                let [ia, ib] = [e.from().fix(), e.to().fix()].map(|v| v.index());
                let subtended = ca.perp_dot(cb).abs().atan2(ca.dot(cb));
                let limit = if kept.contains(&(ia.min(ib), ia.max(ib))) { PI - 2.0 * min_angle } else { PI / 2.0 };
                if subtended > limit {
                    return Some(e.fix());
                }
                continue;
            }
            let Some(g) = e.rev().face().as_inner() else { continue };
            if seen.contains(&g.fix()) {
                continue;
            }
            let [p, q, r] = g.positions();
            if robust::incircle(coord(p), coord(q), coord(r), coord(c)) > 0.0 {
                seen.insert(g.fix());
                stack.push(g.fix());
            }
        }
    }
    None
}

/// Splits constraint edge `e` at its midpoint (both halves stay
/// constraints, rims stay rims); `None` when the halves would be shorter
/// than the spacing (squared: `spacing2`).
fn split_constraint(
    cdt: &mut Cdt,
    e: FixedDirectedEdgeHandle,
    rims: &mut HashSet<(usize, usize)>,
    chains: &mut HashMap<usize, [usize; 2]>,
    spacing2: f64,
    offset: f64,
) -> Option<FixedVertexHandle> {
    let (a, b, pa, pb) = {
        let e = cdt.directed_edge(e);
        (e.from().fix(), e.to().fix(), e.from().position(), e.to().position())
    };
    let length = ((pb.x - pa.x).powi(2) + (pb.y - pa.y).powi(2)).sqrt();
    if length * length / 4.0 <= spacing2 {
        return None;
    }
    // The midpoint; next to a given vertex, at a power-of-two distance from
    // it (Ruppert's concentric shells: splits on two constraints from one
    // vertex then meet at equal distances and stop encroaching each other).
    let (ca, cb) = (chains.get(&a.index()).copied(), chains.get(&b.index()).copied());
    let shell = |half: f64| (nearest_power_of_two(half) * (1.0 + offset) / length).clamp(0.25, 0.75);
    let t = match (ca, cb) {
        (Some(_), None) => 1.0 - shell(length / 2.0),
        (None, Some(_)) => shell(length / 2.0),
        _ => 0.5 + offset,
    };
    let m = Point2::new(pa.x + (pb.x - pa.x) * t, pa.y + (pb.y - pa.y) * t);
    let key = |a: FixedVertexHandle, b: FixedVertexHandle| (a.index().min(b.index()), a.index().max(b.index()));
    let rim = rims.remove(&key(a, b));
    cdt.remove_constraint_edge(cdt.directed_edge(e).as_undirected().fix());
    let v = cdt.insert(m).ok()?;
    chains.insert(v.index(), ca.or(cb).unwrap_or([a.index(), b.index()]));
    for (x, y) in [(a, v), (v, b)] {
        for half in cdt.try_add_constraint(x, y) {
            if rim {
                let h = cdt.directed_edge(half);
                rims.insert(key(h.from().fix(), h.to().fix()));
            }
        }
    }
    Some(v)
}

/// The squared length of a face's shortest side.
fn shortest2(p: [Point2<f64>; 3]) -> f64 {
    (0..3).map(|i| length2(&[p[i], p[(i + 1) % 3]])).fold(f64::INFINITY, f64::min)
}

fn length2([a, b]: &[Point2<f64>; 2]) -> f64 {
    (b.x - a.x).powi(2) + (b.y - a.y).powi(2)
}

/// The power of two nearest to `x` (> 0), in log scale.
fn nearest_power_of_two(x: f64) -> f64 {
    2f64.powf(x.log2().round())
}

/// The corner with the smallest angle and that angle (radians).
fn smallest_angle(p: [Point2<f64>; 3]) -> (usize, f64) {
    let v = p.map(|q| DVec2::new(q.x, q.y));
    (0..3)
        .map(|i| {
            let (e1, e2) = (v[(i + 1) % 3] - v[i], v[(i + 2) % 3] - v[i]);
            let (l1, l2) = (e1.length(), e2.length());
            let angle = if l1 == 0.0 || l2 == 0.0 { 0.0 } else { e1.perp_dot(e2).abs().atan2(e1.dot(e2)) };
            (i, angle)
        })
        .fold((0, f64::INFINITY), |best, x| if x.1 < best.1 { x } else { best })
}

/// Point location among the region's original triangles: a uniform grid of
/// cells listing the triangles whose box meets them.
struct Locator {
    tris: Vec<[DVec2; 3]>,
    origin: DVec2,
    cell: f64,
    dims: [usize; 2],
    /// CSR: triangles of cell `i` are `items[start[i]..start[i + 1]]`.
    start: Vec<u32>,
    items: Vec<u32>,
}

/// Barycentric slack for "inside an original triangle" (relative).
const INSIDE_EPS: f64 = 1e-9;

impl Locator {
    fn new(points: &[DVec2], triangles: &[[usize; 3]]) -> Locator {
        let tris: Vec<[DVec2; 3]> = triangles.iter().map(|t| t.map(|i| points[i])).collect();
        let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
        for p in tris.iter().flatten() {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        let extent = (hi - lo).max(DVec2::splat(1e-300));
        let cells = (tris.len() as f64).sqrt().ceil().clamp(1.0, 1024.0);
        let cell = extent.max_element() / cells;
        let dims = [((extent.x / cell) as usize + 1).min(2048), ((extent.y / cell) as usize + 1).min(2048)];
        let mut locator = Locator { tris, origin: lo, cell, dims, start: Vec::new(), items: Vec::new() };
        let mut pairs: Vec<(u32, u32)> = Vec::new();
        for (t, tri) in locator.tris.iter().enumerate() {
            let (a, b) = (tri[0].min(tri[1]).min(tri[2]), tri[0].max(tri[1]).max(tri[2]));
            let ([x0, y0], [x1, y1]) = (locator.cell_of(a), locator.cell_of(b));
            for y in y0..=y1 {
                for x in x0..=x1 {
                    pairs.push(((y * dims[0] + x) as u32, t as u32));
                }
            }
        }
        pairs.sort_unstable();
        locator.start = vec![0; dims[0] * dims[1] + 1];
        for &(c, _) in &pairs {
            locator.start[c as usize + 1] += 1;
        }
        for i in 0..dims[0] * dims[1] {
            locator.start[i + 1] += locator.start[i];
        }
        locator.items = pairs.into_iter().map(|(_, t)| t).collect();
        locator
    }

    fn cell_of(&self, p: DVec2) -> [usize; 2] {
        let c = ((p - self.origin) / self.cell).floor();
        [(c.x.max(0.0) as usize).min(self.dims[0] - 1), (c.y.max(0.0) as usize).min(self.dims[1] - 1)]
    }

    /// The first original triangle holding `p` (within the slack) and `p`'s barycentric coordinates there.
    fn locate(&self, p: DVec2) -> Option<(usize, [f64; 3])> {
        let [x, y] = self.cell_of(p);
        let c = y * self.dims[0] + x;
        let items = &self.items[self.start[c] as usize..self.start[c + 1] as usize];
        items.iter().map(|&t| t as usize).find_map(|t| {
            let w = barycentric(self.tris[t], p)?;
            w.iter().all(|&x| x >= -INSIDE_EPS).then_some((t, w))
        })
    }

    /// The original triangle nearest to `p` (by its least barycentric), clamped into it.
    fn nearest(&self, p: DVec2) -> (usize, [f64; 3]) {
        let mut best = (0, [1.0 / 3.0; 3], f64::NEG_INFINITY);
        for (t, tri) in self.tris.iter().enumerate() {
            if let Some(w) = barycentric(*tri, p) {
                let least = w[0].min(w[1]).min(w[2]);
                if least > best.2 {
                    best = (t, w, least);
                }
            }
        }
        let w = best.1.map(|x| x.max(0.0));
        let sum = w[0] + w[1] + w[2];
        (best.0, if sum > 0.0 { w.map(|x| x / sum) } else { [1.0 / 3.0; 3] })
    }
}

/// Barycentric coordinates of `p` in triangle `t`; `None` for a degenerate triangle.
fn barycentric(t: [DVec2; 3], p: DVec2) -> Option<[f64; 3]> {
    let d = (t[1] - t[0]).perp_dot(t[2] - t[0]);
    if d == 0.0 {
        return None;
    }
    let w0 = (t[1] - p).perp_dot(t[2] - p) / d;
    let w1 = (t[2] - p).perp_dot(t[0] - p) / d;
    Some([w0, w1, 1.0 - w0 - w1])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square_with_slit(min_angle_deg: f64) -> (PlanarRegion, PlanarResult) {
        // A 4 × 4 square (two triangles) with a short cut near one corner, nearly along an edge.
        let points = vec![
            DVec2::new(0.0, 0.0),
            DVec2::new(4.0, 0.0),
            DVec2::new(4.0, 4.0),
            DVec2::new(0.0, 4.0),
            DVec2::new(0.5, 0.05),
            DVec2::new(1.5, 0.07),
        ];
        let region = PlanarRegion {
            points,
            outline: vec![([0, 1], true), ([1, 2], true), ([2, 3], false), ([3, 0], false)],
            cuts: vec![[4, 5]],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            min_angle: min_angle_deg.to_radians(),
            min_spacing: 1e-6,
            max_new_points: 1000,
            min_feature: 1e-3,
            split_offset: 0.0,
        };
        let result = triangulate(&region).unwrap();
        (region, result)
    }

    fn area(points: &[DVec2], f: [usize; 3]) -> f64 {
        0.5 * (points[f[1]] - points[f[0]]).perp_dot(points[f[2]] - points[f[0]])
    }

    #[test]
    fn refinement_reaches_the_angle_and_keeps_the_area_and_the_cut() {
        let (region, r) = square_with_slit(20.0);
        assert!(r.complete && r.dropped == 0, "{} points", r.refinement_points);
        let mut all = region.points.clone();
        all.extend(r.new_points.iter().map(|p| p.xy));
        let total: f64 = r.faces.iter().map(|&(f, _)| area(&all, f)).sum();
        assert!((total - 16.0).abs() < 1e-9, "area {total}");
        assert!(r.faces.iter().all(|&(f, _)| area(&all, f) > 0.0), "a face is not counter-clockwise");
        // The cut is there, split into pieces along its line.
        let along: f64 = r.cut_pieces.iter().map(|&[a, b]| all[a].distance(all[b])).sum();
        assert!((along - all[4].distance(all[5])).abs() < 1e-9, "cut length {along}");
        let angles: Vec<f64> =
            r.faces.iter().map(|&(f, _)| smallest_angle(f.map(|i| Point2::new(all[i].x, all[i].y))).1.to_degrees()).collect();
        let below = angles.iter().filter(|&&a| a < 20.0 - 1e-9).count();
        let least = angles.iter().copied().fold(f64::INFINITY, f64::min);
        eprintln!("{} faces, {} points added, {below} below 20°, least {least:.2}°", r.faces.len(), r.refinement_points);
        // The kept outline (top and left) is not split: no new point on it.
        for p in &r.new_points {
            assert!(p.xy.y < 4.0 - 1e-9 && p.xy.x > 1e-9, "{:?} on a kept edge", p.xy);
        }
    }

    #[test]
    fn without_a_target_the_constrained_triangulation_alone() {
        let (_, r) = square_with_slit(0.0);
        assert_eq!((r.refinement_points, r.new_points.len()), (0, 0));
        // 6 points, 4 on the hull, one constraint: 2·6 − 4 − 2 = 6 faces.
        assert_eq!(r.faces.len(), 6);
    }
}
