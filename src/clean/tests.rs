//! Tests of the whole pipeline on the fixtures: exact repair counts, the properties
//! after cleaning, idempotence and determinism.

use super::fixtures::{self, color_at, lightmap_at, uv_at, Fixture};
use super::*;
use glam::Vec3;
use std::collections::HashSet;

/// Relative area tolerance: f32 positions of size ~1..10 carry ~1e-7 relative error
/// per coordinate; the designed areas are exact, so 1e-6 leaves a 10× margin.
const AREA_REL_TOL: f64 = 1e-6;
/// Attributes of moved vertices may lag their position by at most the zip tolerance
/// (≤ 3.5e-4 here) times the attribute gradient (≤ 0.25 per unit).
const ATTRIBUTE_TOL: f32 = 1e-4;

fn clean(f: &Fixture) -> (Mesh, CleanReport) {
    match clean_mesh(&f.mesh, &f.params) {
        Ok(r) => r,
        Err(e) => panic!("{}: {}", f.name, e),
    }
}

/// Counts triangles that repeat another's three positions (any winding unless
/// `per_winding`).
fn count_duplicates(mesh: &Mesh, per_winding: bool) -> usize {
    let mut seen = HashSet::new();
    let mut dups = 0;
    for t in 0..mesh.triangle_count() {
        let p = mesh.triangle_positions(t).map(|p| p.to_array().map(f32::to_bits));
        let start = (0..3).min_by_key(|&i| p[i]).unwrap();
        let rotated = [p[start], p[(start + 1) % 3], p[(start + 2) % 3]];
        let key = if per_winding {
            (rotated, rotated[1] < rotated[2])
        } else {
            let mut s = p;
            s.sort();
            (s, false)
        };
        if !seen.insert(key) {
            dups += 1;
        }
    }
    dups
}

/// Boundary edges of a mesh on bit-identical positions.
fn count_boundary(mesh: &Mesh) -> usize {
    let work = weld::weld_points(mesh, 0.0);
    work::count_boundary_and_non_manifold(&work).0
}

fn mesh_area(mesh: &Mesh) -> f64 {
    (0..mesh.triangle_count())
        .map(|t| {
            let [a, b, c] = mesh.triangle_positions(t).map(|p| p.as_dvec3());
            0.5 * (b - a).cross(c - a).length()
        })
        .sum()
}

fn check_counts(f: &Fixture, r: &CleanReport) {
    let e = &f.expected;
    let n = f.name;
    assert_eq!(r.degenerate_removed, e.degenerate_removed, "{n}: degenerate");
    assert_eq!(r.duplicates_removed, e.duplicates_removed, "{n}: duplicates");
    assert_eq!(r.flipped_duplicates_removed, e.flipped_duplicates_removed, "{n}: flipped duplicates");
    assert_eq!(r.near_duplicates_removed, e.near_duplicates_removed, "{n}: near duplicates");
    assert_eq!(r.covered_coplanar_removed, e.covered_coplanar_removed, "{n}: covered");
    assert_eq!(r.tjunctions_fixed, e.tjunctions_fixed, "{n}: T-junctions");
    assert_eq!(r.zipped_edges, e.zipped_edges, "{n}: zipped edges");
    assert_eq!(r.edges_split, e.edges_split, "{n}: edges split");
    assert_eq!(r.slivers_fixed, e.slivers_fixed, "{n}: slivers");
    assert_eq!(r.triangles_flipped, e.triangles_flipped, "{n}: flipped");
    assert_eq!(r.unorientable_component_count, e.unorientable_components, "{n}: unorientable");
    if let Some(w) = e.welded_vertices {
        assert_eq!(r.welded_vertices, w, "{n}: welded");
    }
    assert_eq!(r.output_triangles, e.output_triangles, "{n}: output triangles");
    assert_eq!(r.boundary_edges_after, e.boundary_edges_after, "{n}: boundary after");
    // One round repairs everything, a second finds nothing left.
    assert!(r.converged && r.rounds <= 2, "{n}: {} rounds, converged {}", r.rounds, r.converged);
    let overlap: f64 = r.partial_overlaps.iter().map(|o| o.area as f64).sum();
    assert!((overlap - e.partial_overlap_area).abs() < 1e-5, "{n}: overlap area {overlap}");
}

fn check_properties(f: &Fixture, out: &Mesh, r: &CleanReport) {
    let n = f.name;
    out.validate().unwrap_or_else(|e| panic!("{n}: {e}"));
    assert_eq!(count_duplicates(out, f.params.keep_two_sided), 0, "{n}: duplicates remain");
    assert_eq!(count_boundary(out), f.expected.boundary_edges_after, "{n}: boundary (recounted)");
    let area = mesh_area(out);
    let rel = (area - f.expected.area).abs() / f.expected.area;
    assert!(rel <= AREA_REL_TOL, "{n}: area {area} vs designed {} (rel {rel:e})", f.expected.area);
    assert!(((r.area_after - area) / area).abs() <= AREA_REL_TOL, "{n}: reported area");
    let input_area = mesh_area(&f.mesh);
    assert!(
        ((r.area_before - input_area) / input_area).abs() <= AREA_REL_TOL,
        "{n}: reported input area {} vs {input_area}",
        r.area_before
    );
    let by_repairs = (r.area_after - r.area_before + r.redundant_area_removed) / input_area;
    // Only closing a crack changes the area (by the crack's band: 1.0e-5 on the cylinder).
    assert!(by_repairs.abs() <= 2e-5, "{n}: the repairs changed the area by {by_repairs:+.2e} of the input's");
    // Attributes survive: tables, roles, per-triangle (material, group) pairs, UVs, lightmap UVs, colours.
    assert_eq!(out.materials, f.mesh.materials, "{n}: materials");
    assert_eq!(out.groups, f.mesh.groups, "{n}: groups");
    let pairs: HashSet<(u16, u32)> = f.mesh.tri_material.iter().copied().zip(f.mesh.tri_group.iter().copied()).collect();
    for (m, g) in out.tri_material.iter().zip(&out.tri_group) {
        assert!(pairs.contains(&(*m, *g)), "{n}: new material/group pair {m}/{g}");
    }
    assert_eq!(out.uvs.len(), out.vertex_count(), "{n}: uvs");
    assert_eq!(out.lightmap_uvs.len(), out.vertex_count(), "{n}: lightmap uvs");
    assert_eq!(out.colors.len(), out.vertex_count(), "{n}: colours");
    for v in 0..out.vertex_count() {
        let p = out.positions[v];
        assert!(out.uvs[v].abs_diff_eq(uv_at(p), ATTRIBUTE_TOL), "{n}: uv of vertex {v}");
        assert!(out.lightmap_uvs[v].abs_diff_eq(lightmap_at(p), ATTRIBUTE_TOL), "{n}: lightmap uv of vertex {v}");
        let c = color_at(p);
        assert!((0..3).all(|i| (out.colors[v][i] - c[i]).abs() <= ATTRIBUTE_TOL), "{n}: colour of vertex {v}");
        assert!((out.normals[v].length() - 1.0).abs() < 1e-5, "{n}: normal of vertex {v}");
    }
}

#[test]
fn every_fixture_reports_exact_counts_and_keeps_its_properties() {
    for f in fixtures::all_fixtures() {
        let (out, r) = clean(&f);
        eprintln!("{}:\n{}", f.name, r.summary());
        check_counts(&f, &r);
        check_properties(&f, &out, &r);
    }
}

#[test]
fn cleaning_a_cleaned_mesh_changes_nothing() {
    for f in fixtures::all_fixtures() {
        let (once, _) = clean(&f);
        let (twice, r) = clean_mesh(&once, &f.params).unwrap();
        assert_eq!(r.repairs(), 0, "{}: second pass repaired\n{}", f.name, r.summary());
        assert_eq!(twice, once, "{}: second pass changed the mesh", f.name);
    }
}

#[test]
fn cleaning_is_deterministic() {
    for f in fixtures::all_fixtures() {
        let a = clean(&f);
        let b = clean(&f);
        assert_eq!(a, b, "{}", f.name);
    }
}

#[test]
fn nan_vertex_is_refused_by_name() {
    let err = clean_mesh(&fixtures::fixture_nan_vertex(), &CleanParams::default()).unwrap_err();
    assert!(matches!(err, CleanError::NonFinite { vertex: 5, attribute: "position", .. }), "{err:?}");
    assert!(err.to_string().contains("vertex 5"), "{err}");
}

#[test]
fn invalid_params_are_refused() {
    let mesh = fixtures::fixture_slivers().mesh;
    for params in [
        CleanParams { weld_tolerance: Tolerance::Relative(f32::NAN), ..CleanParams::default() },
        CleanParams { zip_tolerance: Tolerance::Absolute(-1.0), ..CleanParams::default() },
        CleanParams { hard_edge_angle_deg: 200.0, ..CleanParams::default() },
        CleanParams { sliver_min_angle_deg: 60.0, ..CleanParams::default() },
        CleanParams { max_edge: Some(0.0), ..CleanParams::default() },
    ] {
        assert!(matches!(clean_mesh(&mesh, &params), Err(CleanError::InvalidParams { .. })), "{params:?}");
    }
}

#[test]
fn broken_mesh_is_refused_not_panicked() {
    let mut mesh = fixtures::fixture_slivers().mesh;
    mesh.indices[4] = 10_000;
    assert!(matches!(clean_mesh(&mesh, &CleanParams::default()), Err(CleanError::InvalidMesh(_))));
    let mut mesh = fixtures::fixture_slivers().mesh;
    mesh.normals[2].x = f32::INFINITY;
    let err = clean_mesh(&mesh, &CleanParams::default()).unwrap_err();
    assert!(matches!(err, CleanError::NonFinite { vertex: 2, attribute: "normal", .. }), "{err:?}");
}

/// Past the bake's extent limit a triangle's f32 area overflows: the mesh
/// is refused, not emptied as if every triangle were degenerate.
#[test]
fn a_mesh_past_the_extent_limit_is_refused_not_emptied() {
    let mut mesh = fixtures::fixture_slivers().mesh;
    mesh.positions.iter_mut().for_each(|p| *p *= 1e20);
    let err = clean_mesh(&mesh, &CleanParams::default()).unwrap_err();
    assert!(matches!(err, CleanError::Extent(crate::trace::SceneError::ExtentTooLarge { .. })), "{err:?}");
    assert!(err.to_string().contains("rescale the model"), "{err}");
}

#[test]
fn empty_mesh_cleans_to_empty() {
    let (out, r) = clean_mesh(&Mesh::default(), &CleanParams::default()).unwrap();
    assert_eq!(out, Mesh::default());
    assert_eq!(r.repairs(), 0);
}

#[test]
fn keep_two_sided_keeps_one_triangle_per_winding() {
    let mut f = fixtures::fixture_flipped_duplicate();
    f.params.keep_two_sided = true;
    let (out, r) = clean(&f);
    assert_eq!(r.flipped_duplicates_removed, 0);
    assert_eq!(r.covered_coplanar_removed, 0);
    assert_eq!(r.partial_overlap_count, 0);
    assert_eq!(out.triangle_count(), 35);
    assert_eq!(count_duplicates(&out, true), 0);
}

#[test]
fn partial_overlaps_are_located_inside_the_overlap() {
    let f = fixtures::fixture_partial_overlap();
    let (_, r) = clean(&f);
    assert_eq!(r.partial_overlap_count, 2);
    for o in &r.partial_overlaps {
        let [x, y, z] = o.location;
        assert!((1.0..=2.0).contains(&x) && y.abs() < 1e-6 && (-2.0..=-1.0).contains(&z), "{o:?}");
        assert!((o.area - 0.5).abs() < 1e-6);
    }
}

#[test]
fn hard_edges_survive_on_the_cracked_box() {
    // Every output normal is one of the six face normals, and agrees with each
    // triangle that uses it: welding never averaged across the 90° edges.
    let (out, _) = clean(&fixtures::fixture_cracked_box());
    let axes = [Vec3::X, Vec3::NEG_X, Vec3::Y, Vec3::NEG_Y, Vec3::Z, Vec3::NEG_Z];
    assert!(out.normals.iter().all(|n| axes.iter().any(|a| a.abs_diff_eq(*n, 1e-6))));
    for t in 0..out.triangle_count() {
        let [a, b, c] = out.triangle_positions(t);
        let face = (b - a).cross(c - a).normalize();
        for v in out.triangle(t) {
            assert!(out.normals[v as usize].dot(face) > 0.99, "triangle {t} vertex {v}");
        }
    }
}

#[test]
fn orientation_makes_normals_agree_with_faces_on_boxes() {
    let f = fixtures::fixture_orientation();
    let (out, r) = clean(&f);
    assert_eq!(r.unorientable_components.len(), 1);
    let moebius = out.groups.iter().position(|g| g == "moebius").unwrap() as u32;
    for t in (0..out.triangle_count()).filter(|&t| out.tri_group[t] != moebius) {
        let [a, b, c] = out.triangle_positions(t);
        let face = (b - a).cross(c - a);
        let centre = (a + b + c) / 3.0;
        // Outward: from each box's centre.
        let box_centre = if centre.x > 2.0 { Vec3::new(3.5, 0.5, 0.5) } else { Vec3::splat(0.5) };
        assert!(face.dot(centre - box_centre) > 0.0, "triangle {t} faces inward");
        for v in out.triangle(t) {
            assert!(out.normals[v as usize].dot(face) > 0.0, "triangle {t} vertex {v}");
        }
    }
}

#[test]
fn cleaning_a_large_torus_soup_runs() {
    // Not timed: shows the pipeline copes with 200k triangles in the test profile.
    let f = fixtures::large_torus(200_000);
    let (out, r) = clean(&f);
    eprintln!("large torus:\n{}", r.summary());
    assert_eq!(r.duplicates_removed, f.expected.duplicates_removed);
    assert_eq!(r.flipped_duplicates_removed, f.expected.flipped_duplicates_removed);
    assert_eq!(out.triangle_count(), f.expected.output_triangles);
    assert_eq!(r.boundary_edges_after, 0);
    assert_eq!(r.triangles_flipped, 0);
    assert!((r.area_after - f.expected.area).abs() / f.expected.area < AREA_REL_TOL);
}

#[test]
fn stanford_bunny_report() {
    let Some(path) = shared_data("scans/stanford-bunny.obj") else { return };
    let path = path.as_str();
    let options = tobj::LoadOptions { single_index: true, triangulate: true, ..Default::default() };
    let (models, _) = tobj::load_obj(path, &options).expect("bunny loads");
    let mut mesh = Mesh { materials: vec![crate::mesh::Material::opaque("default", 0.8)], ..Mesh::default() };
    for (g, m) in models.iter().enumerate() {
        let base = mesh.positions.len() as u32;
        mesh.groups.push(m.name.clone());
        let p = &m.mesh.positions;
        mesh.positions.extend(p.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])));
        mesh.indices.extend(m.mesh.indices.iter().map(|&i| base + i));
        mesh.tri_material.resize(mesh.indices.len() / 3, 0);
        mesh.tri_group.resize(mesh.indices.len() / 3, g as u32);
    }
    // Face normals accumulated per vertex (the loader's job in the real crate).
    mesh.normals = vec![Vec3::ZERO; mesh.positions.len()];
    for t in 0..mesh.triangle_count() {
        let [a, b, c] = mesh.triangle_positions(t);
        let n = (b - a).cross(c - a);
        for v in mesh.triangle(t) {
            mesh.normals[v as usize] += n;
        }
    }
    mesh.normals.iter_mut().for_each(|n| *n = n.normalize_or(Vec3::Y));
    let (out, r) = clean_mesh(&mesh, &CleanParams::scan(None)).unwrap();
    println!("stanford bunny:\n{}", r.summary());
    out.validate().unwrap();
    let (again, r2) = clean_mesh(&out, &CleanParams::scan(None)).unwrap();
    assert_eq!(r2.repairs(), 0, "{}", r2.summary());
    assert_eq!(again, out);
}

#[test]
fn report_serializes_to_json_with_every_count() {
    let (_, r) = clean(&fixtures::fixture_cylinder_crack());
    let json = serde_json::to_value(&r).unwrap();
    assert_eq!(json["tjunctions_fixed"], 24);
    assert_eq!(json["boundary_edges_after"], 48);
    assert!(json["worst"].is_array() && json["partial_overlaps"].is_array());
    let back: String = r.summary();
    assert!(back.contains("24 T-junctions"), "{back}");
}

/// Cleans a fan and checks what any clean-up must keep: it converges before the
/// round limit, the output is valid with the fan's area (relative 1e-6), and it
/// has no non-manifold edge (a fan has none).
fn clean_fan(shape: fixtures::FanShape, n: usize) -> CleanReport {
    let mesh = fixtures::fan(shape, n);
    let (out, r) = clean_mesh(&mesh, &CleanParams::default()).unwrap();
    let name = format!("{shape:?} {n}");
    assert!(r.converged && r.rounds < MAX_ROUNDS, "{name}: {}", r.summary());
    out.validate().unwrap_or_else(|e| panic!("{name}: {e}"));
    let (before, after) = (mesh_area(&mesh), mesh_area(&out));
    assert!(((after - before) / before).abs() <= AREA_REL_TOL, "{name}: area {before} -> {after}");
    let (_, non_manifold) = work::count_boundary_and_non_manifold(&weld::weld_points(&out, 0.0));
    assert_eq!((non_manifold, r.non_manifold_edges), (0, 0), "{name}: non-manifold edges");
    r
}

#[test]
fn high_valence_fans_clean_and_converge() {
    for (shape, n) in [(fixtures::FanShape::Disc, 10_000), (fixtures::FanShape::Disc, 100_000), (fixtures::FanShape::Cone, 20_000)] {
        let r = clean_fan(shape, n);
        eprintln!("{shape:?} {n}: {} rounds, {} coplanar pairs", r.rounds, r.coplanar_pairs_enumerated);
    }
}

/// The coplanar broad phase's work on a fan: pairs enumerated per triangle stay
/// a small constant from 10k to 100k triangles (a box tree alone enumerates n/2
/// per triangle: 5,000 at 10k, 50,000 at 100k).
#[test]
fn coplanar_work_grows_linearly_on_fans() {
    let per_triangle = |shape, n| {
        let mesh = fixtures::fan(shape, n);
        let tol = CleanParams::default().coplanar_tolerance.resolve(mesh.referenced_diagonal());
        let mut work = weld::weld_points(&mesh, 0.0);
        let pairs = coplanar::remove_covered_coplanar(&mut work, tol, false, true, None).pairs_enumerated;
        pairs as f64 / mesh.triangle_count() as f64
    };
    for shape in [fixtures::FanShape::Disc, fixtures::FanShape::Cone, fixtures::FanShape::Polygon] {
        let (small, large) = (per_triangle(shape, 10_000), per_triangle(shape, 100_000));
        eprintln!("{shape:?}: {small:.2} pairs per triangle at 10k, {large:.2} at 100k");
        // Each sector meets its two neighbours; on the cone the tolerance band
        // (a tilt within the plane tolerance) reaches one sector further at 100k.
        assert!(small > 0.0 && small <= 3.0 && large <= 3.0, "{shape:?}: {small} and {large} pairs per triangle");
    }
}

/// Whatever a mesh does to the rounds, the report says so: a run that stops at
/// the round limit names each repair its last round still made, with its count.
/// (The 100k-corner polygon does not converge today: degenerate caps along its
/// nearly straight rim, removed, leave T-junctions the next round zips.)
#[test]
fn an_unconverged_clean_names_what_kept_retriggering() {
    let (_, r) = clean_mesh(&fixtures::fan(fixtures::FanShape::Polygon, 100_000), &CleanParams::default()).unwrap();
    let summary = r.summary();
    if r.converged {
        assert!(r.retriggered.is_empty(), "{summary}");
        return;
    }
    assert_eq!(r.rounds, MAX_ROUNDS);
    assert!(!r.retriggered.is_empty(), "{summary}");
    let names: Vec<&str> = r.repair_counts().iter().map(|&(name, _)| name).collect();
    for (name, count) in &r.retriggered {
        assert!(names.contains(&name.as_str()) && *count > 0, "{name} {count}");
        assert!(summary.contains(&format!("{name} {count}")), "{summary}");
    }
    // It says whether the output is ready to bake, by the share the last round still changed.
    let repairs: usize = r.retriggered.iter().map(|(_, n)| n).sum();
    let ready = repairs as f64 <= 0.01 * r.output_triangles as f64;
    assert_eq!(r.ready_to_bake, ready, "{summary}");
    assert!(summary.contains(if ready { "safe to bake" } else { "check before baking" }), "{summary}");
    assert!(summary.contains(&format!("{} non-manifold", r.non_manifold_edges)), "{summary}");
}

/// (boundary edges, their length, non-manifold edges, their length) on exact positions.
fn edge_lengths(mesh: &Mesh) -> (usize, f64, usize, f64) {
    let mut point_of: std::collections::HashMap<[u32; 3], u32> = std::collections::HashMap::new();
    let points: Vec<u32> = mesh
        .positions
        .iter()
        .map(|p| {
            let next = point_of.len() as u32;
            *point_of.entry(p.to_array().map(f32::to_bits)).or_insert(next)
        })
        .collect();
    let mut users: std::collections::HashMap<(u32, u32), (u32, f64)> = std::collections::HashMap::new();
    for t in 0..mesh.triangle_count() {
        let v = mesh.triangle(t);
        for i in 0..3 {
            let (a, b) = (v[i] as usize, v[(i + 1) % 3] as usize);
            let key = (points[a].min(points[b]), points[a].max(points[b]));
            let entry = users.entry(key).or_insert((0, mesh.positions[a].as_dvec3().distance(mesh.positions[b].as_dvec3())));
            entry.0 += 1;
        }
    }
    let (mut boundary, mut boundary_length, mut non_manifold, mut non_manifold_length) = (0, 0.0, 0, 0.0);
    for &(count, length) in users.values() {
        if count == 1 {
            boundary += 1;
            boundary_length += length;
        } else if count > 2 {
            non_manifold += 1;
            non_manifold_length += length;
        }
    }
    (boundary, boundary_length, non_manifold, non_manifold_length)
}

/// Issue 20 item 6: `--max-edge` on the grey-white room (CAD slivers) must
/// split and not damage. Sliver flips after the splits once turned
/// near-collinear split points into triangles the next round removed as
/// degenerate: at 0.3 m, 7,447 removals (275 without splits), non-manifold
/// edges 0.70 → 1.69 m long, boundary 321.2 → 323.0 m. A flip must now leave
/// both triangles above the degenerate pass's height, and the clean converges
/// (it stopped after 8 rounds, a flip and a zip undoing each other). Against the default
/// clean (no splits): no more non-manifold length, no longer boundary, at
/// most 10% more degenerate removals, the same area within 1e-5. Skipped
/// when ../shared/data is absent.
#[test]
fn long_edge_splits_on_the_grey_white_room_do_not_damage_it() {
    let Some(path) = shared_data("room-grey-white/grey_white_room_flat.obj") else { return };
    let path = path.as_str();
    let mesh = crate::mesh::load_mesh(path.as_ref(), &crate::mesh::LoadOptions { up: crate::mesh::UpAxis::Y }).unwrap().mesh;
    let (plain, plain_report) = clean_mesh(&mesh, &CleanParams::default()).unwrap();
    let (split, split_report) = clean_mesh(&mesh, &CleanParams { max_edge: Some(0.3), ..CleanParams::default() }).unwrap();
    let (_, plain_boundary, _, plain_non_manifold) = edge_lengths(&plain);
    let (_, split_boundary, _, split_non_manifold) = edge_lengths(&split);
    eprintln!(
        "room: boundary {plain_boundary:.3} -> {split_boundary:.3} m, non-manifold {plain_non_manifold:.3} -> {split_non_manifold:.3} m, degenerate {} -> {}, edges split {}",
        plain_report.degenerate_removed, split_report.degenerate_removed, split_report.edges_split
    );
    assert!(split_report.edges_split > 10_000);
    // A flip is made once per clean: it no longer comes back every round.
    assert!(plain_report.converged && split_report.converged, "{}", split_report.summary());
    assert!(split_non_manifold <= plain_non_manifold + 1e-3, "non-manifold {plain_non_manifold} -> {split_non_manifold} m");
    assert!(split_boundary <= plain_boundary + 1e-3, "boundary {plain_boundary} -> {split_boundary} m");
    assert!(split_report.degenerate_removed * 10 <= plain_report.degenerate_removed * 11, "{}", split_report.summary());
    let (a, b) = (mesh_area(&plain), mesh_area(&split));
    assert!(((b - a) / a).abs() <= 1e-5, "area {a} -> {b}");
}

/// `--max-edge` far below the mesh's scale is refused before any work, with
/// the estimate (a 4 m floor at 1e-9 m ran until killed); the room's real
/// `--max-edge 0.3` stays far below the cap.
#[test]
fn a_max_edge_that_would_explode_the_mesh_is_refused() {
    let mesh = crate::verify::shapes::plane_grid(2, 4.0);
    let refused = clean_mesh(&mesh, &CleanParams { max_edge: Some(1e-9), ..CleanParams::default() }).unwrap_err().to_string();
    assert!(refused.contains("max_edge") && refused.contains("triangles"), "{refused}");
    let (split, _) = clean_mesh(&mesh, &CleanParams { max_edge: Some(0.05), ..CleanParams::default() }).unwrap();
    assert!(split.triangle_count() > 6_000, "{}", split.triangle_count());
}

/// `../shared/data/REL` beside the repository, or `None` (with a notice) when absent.
fn shared_data(rel: &str) -> Option<String> {
    let path = format!("{}/../shared/data/{rel}", env!("CARGO_MANIFEST_DIR"));
    let present = std::path::Path::new(&path).exists();
    if !present {
        eprintln!("skipping: {path} is absent");
    }
    present.then_some(path)
}

/// The default parameters with `cut_intersections` on.
fn cut_params() -> CleanParams {
    CleanParams { cut_intersections: true, ..CleanParams::default() }
}

/// Cleans `mesh` with the cut, checks what every cut must keep (valid, area
/// within 1e-6, converged, a second clean cuts and changes nothing) and
/// returns the output and report.
fn clean_cut(name: &str, mesh: &Mesh) -> (Mesh, CleanReport) {
    let (out, r) = clean_mesh(mesh, &cut_params()).unwrap();
    eprintln!("{name}:\n{}", r.summary());
    out.validate().unwrap_or_else(|e| panic!("{name}: {e}"));
    let (before, after) = (mesh_area(mesh), mesh_area(&out));
    assert!(((after - before) / before).abs() <= AREA_REL_TOL, "{name}: area {before} -> {after}");
    assert!(r.converged, "{name}: {}", r.summary());
    let (again, r2) = clean_mesh(&out, &cut_params()).unwrap();
    assert_eq!((r2.intersections_cut, r2.triangles_cut), (0, 0), "{name}: the second clean cut again\n{}", r2.summary());
    assert_eq!(r2.repairs(), 0, "{name}: the second clean repaired\n{}", r2.summary());
    assert_eq!(again, out, "{name}: the second clean changed the mesh");
    (out, r)
}

/// True when no vertex is used by triangles on both sides of the plane
/// `side(p) = 0` (triangles touching it count by their centroid), among the
/// triangles `keep` selects: the cut line is a hard seam.
fn sides_share_no_vertex(mesh: &Mesh, keep: impl Fn(usize) -> bool, side: impl Fn(Vec3) -> f32) -> bool {
    let mut seen: std::collections::HashMap<u32, bool> = std::collections::HashMap::new();
    for t in (0..mesh.triangle_count()).filter(|&t| keep(t)) {
        let [a, b, c] = mesh.triangle_positions(t);
        let positive = side((a + b + c) / 3.0) > 0.0;
        for v in mesh.triangle(t) {
            if *seen.entry(v).or_insert(positive) != positive {
                return false;
            }
        }
    }
    true
}

/// No triangle selected by `keep` has corners strictly on both sides of `side`.
fn no_triangle_spans(mesh: &Mesh, keep: impl Fn(usize) -> bool, side: impl Fn(Vec3) -> f32) -> bool {
    (0..mesh.triangle_count()).filter(|&t| keep(t)).all(|t| {
        let s = mesh.triangle_positions(t).map(&side);
        !(s.iter().any(|&x| x > 1e-6) && s.iter().any(|&x| x < -1e-6))
    })
}

/// Issue 20 (cutting): two quads crossing in an X. Their common line x = y = 0
/// is met by A's diagonal at z = 0 and by B's at z = 1/3, so the pairs of
/// triangles cross in three segments. A's triangle over z ≥ 0 gains an edge
/// point (z = 1), a diagonal point (z = 0) and an interior point (z = 1/3):
/// six points, five on its hull, a chain of constraints: 2·6 − 5 − 2 = 5
/// pieces; A's other triangle gains two edge points joined by a chord: 3;
/// likewise B: 3 and 5. 4 triangles → 16.
#[test]
fn crossing_quads_are_cut_along_their_common_line() {
    let mesh = fixtures::crossing_quads();
    let (out, r) = clean_cut("crossing quads", &mesh);
    assert_eq!((r.intersections_cut, r.triangles_cut, out.triangle_count()), (2, 4, 10));
    let group = |name: &str| out.groups.iter().position(|g| g == name).unwrap() as u32;
    let (a, b) = (group("quad_a"), group("quad_b"));
    let in_a = |t: usize| out.tri_group[t] == a;
    let in_b = |t: usize| out.tri_group[t] == b;
    assert!(no_triangle_spans(&out, in_a, |p| p.x) && no_triangle_spans(&out, in_b, |p| p.y));
    assert!(sides_share_no_vertex(&out, in_a, |p| p.x), "A's sides share a vertex");
    assert!(sides_share_no_vertex(&out, in_b, |p| p.y), "B's sides share a vertex");
    // Without the flag nothing is cut.
    let (plain, r) = clean_mesh(&mesh, &CleanParams::default()).unwrap();
    assert_eq!((r.intersections_cut, plain.triangle_count()), (0, 4));
}

/// Issue 20 (cutting), the floor-under-wall case: a wall whose bottom edge lies
/// on a floor quad and crosses it. Each floor triangle gains two edge points
/// joined by a chord (3 pieces each); the wall's bottom triangle gains three
/// points on its bottom edge (4 pieces), its other triangle none: 4 → 11.
#[test]
fn a_wall_standing_on_a_floor_cuts_the_floor_along_its_foot() {
    let (out, r) = clean_cut("wall on floor", &fixtures::wall_on_floor());
    assert_eq!((r.intersections_cut, r.triangles_cut, out.triangle_count()), (1, 2, 8));
    let floor = out.groups.iter().position(|g| g == "floor").unwrap() as u32;
    let on_floor = |t: usize| out.tri_group[t] == floor;
    assert!(no_triangle_spans(&out, on_floor, |p| p.z - 0.25));
    assert!(sides_share_no_vertex(&out, on_floor, |p| p.z - 0.25), "the floor's sides share a vertex");
    // The cut gives the floor's line a point of its own, so the wall's foot
    // is no edge of the floor; zipping then joins that point to the foot (a
    // T-junction on it), and one piece of the foot is shared: three sheets
    // meet along it, a T-contact that no mesh without T-junctions avoids.
    let (_, non_manifold) = work::count_boundary_and_non_manifold(&weld::weld_points(&out, 0.0));
    assert_eq!(non_manifold, 1, "the foot");
}

/// A wall ending inside a floor triangle slits it: two interior points and
/// the slit between them, 2·5 − 3 − 2 = 5 pieces; the wall is not cut.
#[test]
fn a_wall_ending_inside_a_floor_triangle_slits_it() {
    let (out, r) = clean_cut("wall inside floor triangle", &fixtures::wall_inside_floor_triangle());
    assert_eq!((r.intersections_cut, r.triangles_cut, out.triangle_count()), (1, 1, 8));
}

/// Pairs that share an edge, share a corner or touch a plane in one point
/// are not cut; neither are coplanar overlaps (the coplanar step reports them).
#[test]
fn touching_and_coplanar_pairs_are_not_cut() {
    for (name, mesh) in [("touching", fixtures::touching_triangles()), ("coplanar", fixtures::fixture_partial_overlap().mesh)] {
        let (out, r) = clean_cut(name, &mesh);
        let (plain, plain_report) = clean_mesh(&mesh, &CleanParams::default()).unwrap();
        assert_eq!((r.intersections_cut, r.triangles_cut), (0, 0), "{name}");
        assert_eq!(out.triangle_count(), plain.triangle_count(), "{name}");
        assert_eq!(r.partial_overlap_count, plain_report.partial_overlap_count, "{name}");
    }
}

/// The fixtures do not cross themselves: with the cut on they clean to what
/// they clean to without it.
#[test]
fn the_cut_changes_nothing_on_fixtures_that_do_not_cross_themselves() {
    for f in fixtures::all_fixtures() {
        let (plain, _) = clean(&f);
        let (cut, r) = clean_mesh(&f.mesh, &CleanParams { cut_intersections: true, ..f.params }).unwrap();
        assert_eq!((r.intersections_cut, r.triangles_cut), (0, 0), "{}", f.name);
        assert_eq!(cut, plain, "{}\n{}", f.name, r.summary());
    }
}

/// Issue 20 (cutting) on the room whose floor and right wall run past the back
/// wall: every crossing is cut, the floor and right wall are split along the
/// back wall's plane with no vertex on both sides, the clean converges and
/// a second clean changes nothing; same input, same bytes.
#[test]
fn the_room_with_walls_running_past_is_cut_at_the_back_wall() {
    let mesh = crate::verify::shapes::room_with_walls_running_past();
    let (out, r) = clean_cut("room", &mesh);
    assert!(r.intersections_cut > 0 && r.triangles_cut > 0 && r.seam_vertices_split > 0, "{}", r.summary());
    let back = crate::verify::shapes::PAST_ROOM_SIZE[2];
    assert!(no_triangle_spans(&out, |_| true, |p| p.z - back));
    assert!(sides_share_no_vertex(&out, |_| true, |p| p.z - back), "a vertex spans the back wall");
    let bits = |m: &Mesh| m.positions.iter().flat_map(|p| p.to_array().map(f32::to_bits)).collect::<Vec<_>>();
    let (again, _) = clean_mesh(&mesh, &cut_params()).unwrap();
    assert_eq!(again, out);
    assert_eq!(bits(&again), bits(&out));
}

/// The cut's broad phase is near-linear around a high-valence point: a 10k fan
/// does not cross itself, and cleaning it with the cut converges quickly.
#[test]
fn a_high_valence_fan_does_not_cut_itself() {
    let mesh = fixtures::fan(fixtures::FanShape::Disc, 10_000);
    let start = std::time::Instant::now();
    let (out, r) = clean_mesh(&mesh, &cut_params()).unwrap();
    eprintln!("disc 10k with the cut: {:.2} s", start.elapsed().as_secs_f64());
    assert_eq!((r.intersections_cut, r.triangles_cut), (0, 0));
    assert_eq!(out.triangle_count(), clean_mesh(&mesh, &CleanParams::default()).unwrap().0.triangle_count());
}

/// Layers along one line are not zipped into each other: `n` coplanar
/// copies slid along a common base (every base corner on every other base)
/// keep their `n` triangles and report each overlapping pair once, and `n`
/// fins with their edges on one axis keep theirs. Zipping every layer's
/// corners into every other layer's edge made n² pieces and, for the stack,
/// n⁴/9 partial overlaps (50 copies: 2,483 triangles and 687,550 overlaps;
/// 100 fins: 9,981 triangles in 4 s and 560 MB). Counts, not time: the work
/// is in the output.
#[test]
fn layers_along_one_line_stay_whole() {
    for n in [10, 50, 100] {
        let (out, r) = clean_mesh(&fixtures::stacked_coplanar(n), &CleanParams::default()).unwrap();
        assert_eq!(
            (out.triangle_count(), r.tjunctions_fixed, r.partial_overlap_count, r.rounds),
            (n, 0, n * (n - 1) / 2, 1),
            "{n} stacked:\n{}",
            r.summary()
        );
        let (out, r) = clean_mesh(&fixtures::fins_on_axis(n), &CleanParams::default()).unwrap();
        assert_eq!((out.triangle_count(), r.tjunctions_fixed, r.rounds), (n, 0, 1), "{n} fins:\n{}", r.summary());
    }
}

/// The cut's work follows the pieces it cuts. `n` fins crossing along one
/// axis are `n (n − 1) / 2` crossing pairs but one line: each fin is cut
/// once, into 5 triangles (one fin 4: the first to claim the line; the
/// others take a point on it so no edge is shared). `n` thin triangles
/// through one point: every pair crosses, each pair's segment is 2 pieces
/// in each of its triangles (split at the common point), and the
/// re-triangulation stays within a few triangles per piece. Cutting the
/// pieces of the cut again, round after round, made 20 thin triangles
/// 5,285 triangles without converging and 1,000 fins ran past 240 s.
#[test]
fn the_cut_grows_with_its_pieces_on_thin_crossings_and_fins() {
    // Fins closer than about 3° (MIN_CUT_SINE) do not cross: 100 fins 1.8°
    // apart lose 100 of their 4,950 pairs, 1,000 fins 15 per fin.
    for (n, pairs) in [(10, 45), (100, 4_850), (1000, 484_500)] {
        let (out, r) = clean_mesh(&fixtures::fins_through_axis(n), &cut_params()).unwrap();
        let got = (r.crossing_pairs, r.intersections_cut, r.triangles_cut, out.triangle_count(), r.non_manifold_edges, r.converged);
        assert_eq!(got, (pairs, n, n, 5 * n - 2, 0, true), "{n} fins:\n{}", r.summary());
    }
    // Non-manifold edges: the zip joins no rims onto an edge two triangles
    // already share; what is left comes from pieces of many sheets meeting
    // within the tolerance at the common point.
    for (n, triangles, non_manifold) in [(10, 589, 0), (20, 2_854, 12), (30, 7_019, 21)] {
        let every = CleanParams { cut_every_crossing: true, ..cut_params() };
        let (out, r) = clean_mesh(&fixtures::thin_crossing(n), &every).unwrap();
        eprintln!("{n} thin: {} triangles\n{}", out.triangle_count(), r.summary());
        let pairs = n * (n - 1) / 2;
        assert_eq!((r.crossing_pairs, r.intersections_cut, r.triangles_cut), (pairs, 4 * pairs, n), "{n} thin:\n{}", r.summary());
        assert!(
            r.converged && out.triangle_count() <= 5 * r.intersections_cut,
            "{n} thin: {} triangles\n{}",
            out.triangle_count(),
            r.summary()
        );
        assert_eq!((out.triangle_count(), r.non_manifold_edges), (triangles, non_manifold), "{n} thin");
    }
}

/// An unconverged clean says whether its output is ready to bake: the last
/// round's repairs at most 1% of the output's triangles are local edits
/// ("safe to bake"), more mean the mesh was still changing ("check before
/// baking"); either way it names what remains.
#[test]
fn an_unconverged_clean_says_whether_its_output_is_ready_to_bake() {
    let report = |repairs: usize| {
        let mut r =
            CleanReport { converged: false, rounds: MAX_ROUNDS, output_triangles: 10_000, non_manifold_edges: 7, ..Default::default() };
        r.retriggered = vec![("zipped_edges".to_string(), repairs)];
        r.ready_to_bake = r.last_round_share() <= super::report::READY_SHARE;
        r
    };
    let few = report(100);
    assert!(few.ready_to_bake);
    let text = few.convergence();
    assert!(text.contains("zipped_edges 100") && text.contains("safe to bake") && text.contains("1.00% of the 10000 triangles"), "{text}");
    assert!(text.contains("7 non-manifold"), "{text}");
    let many = report(101);
    assert!(!many.ready_to_bake);
    let text = many.convergence();
    assert!(text.contains("check before baking") && text.contains("clean the output again"), "{text}");
    let done = CleanReport { converged: true, ready_to_bake: true, ..Default::default() };
    assert_eq!(done.convergence(), "converged");
}

/// The smallest angle of a mesh's triangles, in degrees.
fn smallest_angle_deg(mesh: &Mesh) -> f64 {
    (0..mesh.triangle_count())
        .map(|t| work::min_angle(mesh.triangle_positions(t).map(|p| p.as_dvec3())).to_degrees())
        .fold(f64::INFINITY, f64::min)
}

/// The cut leaves no needle: where the input's triangles are all at least
/// 1°, so are the output's (the dining room's floor went to 1.3e-4° before
/// the cut's needles were repaired), and the rooms and quads get no
/// non-manifold edge (ten triangles crossing at one point share their lines).
/// Where the repair cannot raise what the cut made (twenty thin triangles
/// through one point: their pieces meet within the tolerance there), those
/// pairs of surfaces are left uncut and named; cutting them anyway leaves
/// non-manifold edges (the growth test below).
#[test]
fn the_cut_leaves_no_triangle_under_one_degree() {
    let cases = [
        ("room", crate::verify::shapes::room_with_walls_running_past(), 0),
        ("crossing quads", fixtures::crossing_quads(), 0),
        ("wall inside floor triangle", fixtures::wall_inside_floor_triangle(), 0),
        ("10 thin", fixtures::thin_crossing(10), 0),
        ("20 thin", fixtures::thin_crossing(20), 169),
    ];
    for (name, mesh, left_uncut) in cases {
        let input = smallest_angle_deg(&mesh);
        let (out, r) = clean_mesh(&mesh, &cut_params()).unwrap();
        let output = smallest_angle_deg(&out);
        eprintln!(
            "{name}: smallest angle {input:.3}° -> {output:.3}°, {} needles repaired, {} left",
            r.cut_needles_repaired, r.cut_needles_left
        );
        assert!(r.triangles_cut > 0, "{name}");
        assert!(output >= input.min(1.0), "{name}: {input}° -> {output}°\n{}", r.summary());
        assert!(r.cut_min_angle_deg.unwrap() >= 1.0, "{name}\n{}", r.summary());
        assert_eq!((r.cut_needles_left, r.non_manifold_edges), (0, 0), "{name}");
        // Each thin triangle is a surface of its own: surface pairs are triangle pairs.
        let skipped = r.cut_surface_pairs_left_uncut + r.cut_triangle_pairs_left_uncut;
        assert_eq!(skipped, left_uncut, "{name}\n{}", r.summary());
        let uncut: usize = r.cut_left_uncut.iter().map(|u| u.triangle_pairs).sum();
        assert_eq!(uncut, left_uncut, "{name}");
        if name == "20 thin" {
            assert_eq!(r.crossing_pairs + uncut, 20 * 19 / 2);
            assert!(r.summary().contains("paint × paint (169 triangle pairs)"), "{}", r.summary());
        }
    }
}
