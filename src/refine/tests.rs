use glam::Vec3;

use super::probe::{interpolate, interpolate_masks, locate, reference_sun, surface_points};
use super::*;
use crate::bake::{Mode, Sampling};
use crate::fixtures::builder::MeshBuilder;
use crate::mesh::Material;

/// A 4 m floor in 2 × 2 cells (8 triangles) with a 1 m cube standing on it:
/// contact shadows and darkening the coarse floor cannot draw.
fn floor_and_cube() -> Mesh {
    let mut b = MeshBuilder::new(vec![Material::opaque("grey", 0.5)]);
    b.grid("floor", Vec3::new(-2.0, 0.0, -2.0), Vec3::Z * 4.0, Vec3::X * 4.0, 2, 2, |_, _| 0);
    b.cuboid("cube", Vec3::new(-0.3, 0.0, -0.3), Vec3::new(0.7, 1.0, 0.7), 1.0, 0);
    b.mesh
}

/// The same floor under a blind: seven 0.1 m slats at 1 m, 0.25 m apart,
/// so a sun at an angle draws thin stripes across big triangles.
fn floor_under_blinds() -> Mesh {
    let mut b = MeshBuilder::new(vec![Material::opaque("grey", 0.5)]);
    b.grid("floor", Vec3::new(-2.0, 0.0, -2.0), Vec3::Z * 4.0, Vec3::X * 4.0, 2, 2, |_, _| 0);
    for i in 0..7 {
        let x = -0.9 + 0.25 * i as f32;
        b.cuboid(&format!("slat{i}"), Vec3::new(x, 1.0, -1.0), Vec3::new(x + 0.1, 1.02, 1.0), 1.0, 0);
    }
    b.mesh
}

/// The same floor under a wide slatted roof 2 m up (0.1 m strips every
/// 0.2 m, 12 m long, far past the floor's edges): seen from the floor the
/// slats blur into a smooth half-shade, so the exact transfer varies slowly,
/// while a bake with few rays is noisy from point to point.
fn floor_under_slatted_roof() -> Mesh {
    let mut b = MeshBuilder::new(vec![Material::opaque("grey", 0.5)]);
    b.grid("floor", Vec3::new(-2.0, 0.0, -2.0), Vec3::Z * 4.0, Vec3::X * 4.0, 2, 2, |_, _| 0);
    for i in 0..60 {
        let x = -6.0 + 0.2 * i as f32;
        b.grid(&format!("slat{i}"), Vec3::new(x, 2.0, -6.0), Vec3::X * 0.1, Vec3::Z * 12.0, 1, 1, |_, _| 0);
    }
    b.mesh
}

fn bake_params() -> BakeParams {
    BakeParams { order: 3, rays: 64, bounces: 0, sampling: Sampling::interior(), quiet: true, ..BakeParams::default() }
}

/// Shaded luminance under the reference skies at `points`, per sky then point.
fn shaded_at(mesh: &Mesh, result: &TransferResult, points: &[probe::SurfacePoint]) -> Vec<[f64; 3]> {
    let scene = Scene::build(mesh, BuildQuality::Sah).expect("scene");
    let located = locate(&scene, points, 1e-4);
    assert!(located.iter().all(|l| l.is_some()), "every point lies on the surface");
    let stride = result.channels * crate::sh::coeff_count(result.order);
    let rows = interpolate(mesh, &result.total, stride, &located);
    let mut out = Vec::new();
    for sky in crate::budget::reference_lightings(result.order) {
        out.extend(crate::budget::shade(&rows, result.order, result.channels, &sky.sh));
    }
    out
}

fn refine_with(mesh: &Mesh, error: Option<f64>, budget: usize) -> (Mesh, TransferResult, RefineReport) {
    refine_noise(mesh, &bake_params(), error, budget, DEFAULT_NOISE_SIGMAS)
}

fn refine_noise(
    mesh: &Mesh,
    params: &BakeParams,
    error: Option<f64>,
    budget: usize,
    noise_sigmas: f64,
) -> (Mesh, TransferResult, RefineReport) {
    let refine = RefineParams { error, max_vertices: budget, min_edge: 0.02, max_rounds: DEFAULT_MAX_ROUNDS, noise_sigmas };
    let (m, r, _, report) = refine_transfer(mesh.clone(), params, &[], &[], &refine).expect("refine");
    (m, r, report)
}

#[test]
fn transfer_refinement_lowers_the_error_against_a_dense_reference() {
    let mesh = floor_and_cube();
    let floor = |t: usize| mesh.tri_group[t] == 0;
    let points = surface_points(&mesh, 4000, 7, floor);
    // Reference: the floor split uniformly to 6 cm edges, baked with 4x the rays.
    let dense = crate::clean::split_edges(&mesh, &[]).mesh;
    let dense = uniform_split(dense, 0.06);
    let params = BakeParams { rays: 256, ..bake_params() };
    let (reference, _, _) = crate::bake::bake_mesh(&dense, &params, &[]).expect("reference");
    let want = shaded_at(&dense, &reference, &points);

    let (coarse, _, _) = crate::bake::bake_mesh(&mesh, &bake_params(), &[]).expect("coarse");
    let coarse_error = crate::budget::relative_rms(&want, &shaded_at(&mesh, &coarse, &points));
    let (refined, result, report) = refine_with(&mesh, Some(0.05), 2000);
    let refined_error = crate::budget::relative_rms(&want, &shaded_at(&refined, &result, &points));
    assert!(refined.vertex_count() <= 2000 && refined.vertex_count() > 4 * mesh.vertex_count(), "{}", report.summary());
    assert!(report.rounds.len() >= 3, "{}", report.summary());
    assert!(refined_error < 0.5 * coarse_error, "error {coarse_error:.4} -> {refined_error:.4}; {}", report.summary());
    // Later rounds re-bake only the neighbourhoods of the splits.
    let (baked, all): (usize, usize) = report.rounds.iter().fold((0, 0), |(b, a), r| (b + r.vertices_baked, a + r.vertices));
    assert!(baked < all * 3 / 4, "{:?}", report.rounds);
    eprintln!("coarse {coarse_error:.4} refined {refined_error:.4} ({} vertices); {}", refined.vertex_count(), report.summary());
}

/// Splits every edge of `mesh` longer than `max_edge` (for references).
fn uniform_split(mut mesh: Mesh, max_edge: f32) -> Mesh {
    loop {
        let long: Vec<[u32; 2]> = (0..mesh.triangle_count())
            .flat_map(|t| {
                let v = mesh.triangle(t);
                [0, 1, 2].map(|c| [v[c], v[(c + 1) % 3]])
            })
            .filter(|&[a, b]| mesh.positions[a as usize].distance(mesh.positions[b as usize]) > max_edge)
            .collect();
        if long.is_empty() {
            return mesh;
        }
        mesh = crate::clean::split_edges(&mesh, &long).mesh;
    }
}

#[test]
fn noise_is_not_split_but_light_is() {
    // Under the slatted roof the floor's light is smooth: differences between
    // its vertices at 8 rays are noise. Noise-blind refinement splits the
    // floor on them and draws the noise; noise-aware refinement leaves it
    // nearly as it was (the budget goes to the strips' real light changes).
    let mesh = floor_under_slatted_roof();
    let floor = |t: usize| mesh.tri_group[t] == 0;
    let points = surface_points(&mesh, 3000, 5, floor);
    let reference_mesh = uniform_split(crate::clean::split_edges(&mesh, &[]).mesh, 0.5);
    let (reference, _, _) = crate::bake::bake_mesh(&reference_mesh, &BakeParams { rays: 1024, ..bake_params() }, &[]).expect("reference");
    let want = shaded_at(&reference_mesh, &reference, &points);
    let noisy = BakeParams { rays: 8, ..bake_params() };
    let floor_vertices = |m: &Mesh| (0..m.vertex_count()).filter(|&v| m.positions[v].y < 0.5).count();
    let budget = mesh.vertex_count() + 3000;
    let (blind, blind_result, blind_report) = refine_noise(&mesh, &noisy, Some(0.05), budget, 0.0);
    let (aware, aware_result, aware_report) = refine_noise(&mesh, &noisy, Some(0.05), budget, DEFAULT_NOISE_SIGMAS);
    let blind_error = crate::budget::relative_rms(&want, &shaded_at(&blind, &blind_result, &points));
    let aware_error = crate::budget::relative_rms(&want, &shaded_at(&aware, &aware_result, &points));
    eprintln!(
        "noise-blind: {} floor vertices, error {blind_error:.4}, {}; noise-aware: {} floor vertices, error {aware_error:.4}, {}",
        floor_vertices(&blind),
        blind_report.summary(),
        floor_vertices(&aware),
        aware_report.summary()
    );
    let added = |m: &Mesh| floor_vertices(m) - floor_vertices(&mesh);
    assert!(added(&blind) >= 40, "noise-blind refinement splits the noise: {} floor vertices added", added(&blind));
    assert!(added(&aware) * 8 < added(&blind), "{} floor vertices added against {}", added(&aware), added(&blind));
    assert!(aware_error < 0.6 * blind_error, "floor error: noise-aware {aware_error:.4} against noise-blind {blind_error:.4}");
}

#[test]
fn transfer_refinement_is_deterministic_across_thread_counts_and_keeps_the_budget() {
    let mesh = floor_and_cube();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("pool");
        pool.install(|| refine_with(&mesh, None, 300))
    };
    let (m1, r1, rep1) = run(1);
    let (m2, r2, rep2) = run(2);
    assert_eq!(m1, m2);
    assert_eq!(r1.total, r2.total);
    assert_eq!(rep1.rounds.len(), rep2.rounds.len());
    assert!(m1.vertex_count() <= 300 && m1.vertex_count() > 150, "{}", rep1.summary());
    assert_eq!(rep1.stopped, "budget");
}

#[test]
fn a_kept_vertex_keeps_its_value_and_a_new_one_is_baked() {
    let mesh = floor_and_cube();
    let (refined, result, report) = refine_with(&mesh, Some(0.05), 400);
    assert!(refined.vertex_count() > mesh.vertex_count());
    let stride = result.channels * crate::sh::coeff_count(result.order);
    // No vertex with samples around it is left at zero: every new vertex was baked.
    // Floor vertices outside the cube's footprint see some sky.
    let open_floor = |v: usize| {
        let p = refined.positions[v];
        refined.normals[v].y > 0.9 && p.y < 0.5 && !(p.x > -0.31 && p.x < 0.71 && p.z > -0.31 && p.z < 0.71)
    };
    let lit_floor_vertices = (0..refined.vertex_count()).filter(|&v| open_floor(v) && result.total[v * stride] > 0.0).count();
    let floor_vertices = (0..refined.vertex_count()).filter(|&v| open_floor(v)).count();
    assert!(floor_vertices > 100);
    assert_eq!(lit_floor_vertices, floor_vertices, "{}", report.summary());
}

#[test]
fn sun_refinement_draws_slat_shadows_4x_closer_to_the_per_point_reference() {
    let mesh = floor_under_blinds();
    let suns: Vec<Option<Vec3>> = (0..8).map(|k| Some(Vec3::new(0.35 + 0.05 * k as f32, 1.0, 0.2).normalize())).collect();
    let params = SunParams { mode: Mode::Open, ..SunParams::default() };
    let floor = |t: usize| mesh.tri_group[t] == 0;
    let points = surface_points(&mesh, 20_000, 3, floor);
    let scene = Scene::build(&mesh, BuildQuality::Sah).expect("scene");
    let reference: Vec<Vec<f32>> = suns.iter().map(|s| reference_sun(&scene, &points, s.unwrap_or(Vec3::Y))).collect();
    let disagreement = |m: &Mesh, masks: &SunMasks| {
        let scene = Scene::build(m, BuildQuality::Sah).expect("scene");
        let located = locate(&scene, &points, 1e-4);
        let drawn = interpolate_masks(m, masks, suns.len(), &located);
        let mut sum = 0.0f64;
        for (p, row) in drawn.chunks_exact(suns.len()).enumerate() {
            for (k, &d) in row.iter().enumerate() {
                sum += (d - reference[k][p]).abs() as f64;
            }
        }
        sum / (points.len() * suns.len()) as f64
    };
    let surfaces = Surfaces::resolve(&mesh, &[]).expect("surfaces");
    let coarse = crate::bake::bake_sun_masks(&mesh, &scene, &surfaces, &suns, &params).expect("sun");
    let before = disagreement(&mesh, &coarse);
    let refine = RefineParams {
        error: Some(0.1),
        max_vertices: 20_000,
        min_edge: 0.01,
        max_rounds: DEFAULT_MAX_ROUNDS,
        noise_sigmas: DEFAULT_NOISE_SIGMAS,
    };
    let (refined, masks, report) = refine_sun(mesh.clone(), &[], &suns, &params, &refine).expect("refine");
    let after = disagreement(&refined, &masks);
    assert!(before > 0.05, "the coarse floor misses the stripes: {before:.4}");
    assert!(after * 4.0 < before, "disagreement {before:.4} -> {after:.4}; {}", report.summary());
    assert!(refined.vertex_count() <= 20_000);
    // Later rounds re-trace only around the splits, and the result does not depend on the threads.
    assert!(report.rounds[1..].iter().any(|r| r.vertices_baked < r.vertices / 2), "{:?}", report.rounds);
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool");
    let (again, again_masks, _) = one.install(|| refine_sun(mesh.clone(), &[], &suns, &params, &refine)).expect("refine");
    assert_eq!(again, refined);
    assert_eq!(again_masks.masks, masks.masks);
}

/// The budget, not a fixed round cap, ends a refinement: each round takes a
/// quarter of the room left but at least an eighth of the whole growth, so
/// the budget is spent in at most 8 + log_{4/3} 2 ≈ 11 rounds.
#[test]
fn rounds_spend_the_budget_in_a_bounded_number_of_rounds() {
    for growth in [1usize, 7, 1000, 460_000, 25_000_000] {
        let rounds = super::rounds_left(growth, growth);
        assert!((1..=11).contains(&rounds), "growth {growth}: {rounds} rounds");
        let mut room = growth;
        let mut takes = Vec::new();
        while room > 0 {
            let take = super::round_take(room, growth);
            assert!(take >= 1 && take <= room);
            takes.push(take);
            room -= take;
        }
        assert_eq!(takes.len(), rounds);
        assert!(takes.iter().all(|&t| t >= growth.div_ceil(8).min(t)), "{takes:?}");
    }
}
