//! The per-vertex quantity (docs/conventions.md, "Per-vertex transfer") and
//! the estimator's convergence to it at every sample density.
//!
//! Scene: a plane of large triangles (8×8 cells, 6 m across) partly under
//! a roof (a horizontal rectangle 0.6 m up) whose edges run between grid
//! lines, so triangles straddle the penumbra. Open mode, order 2. A plane
//! point x (normal +Y) sees the sky minus the roof:
//!   t_i(x) = (Â_l/π) y_i(+Y) − (1/π) ∫_roof y_i(ω) (ω·Y) dω,
//! the roof term by Lambert's polygon formula (DC, closed form) and by
//! Gauss–Legendre quadrature over the roof's area (every coefficient; DC
//! checked against Lambert). The exact vertex value is the hat-weighted mean
//! t_v = Σ_T ∫_T φ_v t dA / Σ_T |T|/3 over the one-ring, integrated on each
//! triangle by a composite rule.
//!
//! Bakes at 1, 16 and 64 samples per vertex (3, 9 and 33 samples on a
//! plane triangle; 4 would give 3 as 1 does), 16 seeds each: the seed means must match the exact values
//! within their standard errors (RMS of the z-scores, and the worst one),
//! and one another.

use glam::{DVec3, Vec3};
use prtbake::bake::{bake_mesh, BakeParams, Mode, Sampling};
use prtbake::mesh::{Material, Mesh};
use prtbake::verify::shapes;
use std::f64::consts::PI;

const CELLS: u32 = 8;
const SIZE: f32 = 6.0;
const ROOF_HEIGHT: f64 = 0.6;
/// Roof corners (x, z): its edges x = 0.35 and z = ±2 lie between grid
/// lines (0.75 apart). Small enough that the plane's triangles get 3, 9 and
/// 33 samples at 1, 16 and 64 samples per vertex (the density counts the roof).
const ROOF_X: [f64; 2] = [-2.0, 0.35];
const ROOF_Z: [f64; 2] = [-2.0, 2.0];
const COEFFS: usize = 4;
const SEEDS: u32 = 16;
const RAYS: u32 = 512;

/// SH bands 0–1 (docs/conventions.md): y00, then 0.488603·(y, z, x).
fn basis(w: DVec3) -> [f64; COEFFS] {
    let c1 = (3.0 / (4.0 * PI)).sqrt();
    [0.5 / PI.sqrt(), c1 * w.y, c1 * w.z, c1 * w.x]
}

/// A horizontal rectangle above the plane: the roof, or a window.
#[derive(Clone, Copy)]
struct Rect {
    x: [f64; 2],
    z: [f64; 2],
    height: f64,
}

const ROOF: Rect = Rect { x: ROOF_X, z: ROOF_Z, height: ROOF_HEIGHT };

fn corners(r: Rect) -> [DVec3; 4] {
    let (x, z, h) = (r.x, r.z, r.height);
    [DVec3::new(x[0], h, z[0]), DVec3::new(x[1], h, z[0]), DVec3::new(x[1], h, z[1]), DVec3::new(x[0], h, z[1])]
}

fn roof_corners() -> [DVec3; 4] {
    corners(ROOF)
}

/// The plane, then the roof facing down (its own samples are not scored).
fn scene() -> Mesh {
    scene_with(ROOF, Material::opaque("roof", 0.5))
}

/// The plane, then a rectangle of `material` facing down.
fn scene_with(rect: Rect, material: Material) -> Mesh {
    let mut mesh = shapes::plane_grid(CELLS, SIZE);
    let base = mesh.positions.len() as u32;
    mesh.positions.extend(corners(rect).map(|p| p.as_vec3()));
    mesh.normals.extend([Vec3::NEG_Y; 4]);
    // Counter-clockwise seen from below.
    mesh.indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    mesh.tri_material.extend([1, 1]);
    mesh.tri_group.extend([1, 1]);
    mesh.groups.push(material.name.clone());
    mesh.materials.push(material);
    mesh
}

/// ∫_roof (ω·Y) dω seen from `x` on the plane: Lambert's formula,
/// ½ |Σ_k γ_k (Y · unit(v_k × v_k+1))| with γ_k the angle between the corners.
fn roof_cosine_integral(x: DVec3) -> f64 {
    let v = roof_corners().map(|p| (p - x).normalize());
    let sum: f64 = (0..4).map(|k| (v[k].dot(v[(k + 1) % 4]).clamp(-1.0, 1.0)).acos() * v[k].cross(v[(k + 1) % 4]).normalize().y).sum();
    0.5 * sum.abs()
}

/// Gauss–Legendre nodes and weights on [0, 1] (8 points).
fn gauss_legendre_8() -> [(f64, f64); 8] {
    let nodes = [
        (0.183_434_642_495_649_8, 0.362_683_783_378_362),
        (0.525_532_409_916_329_0, 0.313_706_645_877_887_3),
        (0.796_666_477_413_626_7, 0.222_381_034_453_374_5),
        (0.960_289_856_497_536_3, 0.101_228_536_290_376_3),
    ];
    let mut out = [(0.0, 0.0); 8];
    for (k, &(x, w)) in nodes.iter().enumerate() {
        out[2 * k] = (0.5 - 0.5 * x, 0.5 * w);
        out[2 * k + 1] = (0.5 + 0.5 * x, 0.5 * w);
    }
    out
}

/// ∫_roof y_i(ω) (ω·Y) dω from `x`, over the roof's area: the solid angle
/// of dA is (ω·Y) dA / r² (the roof is horizontal), so the integrand is
/// y_i(ω) h² / r⁴. Composite 8-point Gauss–Legendre on 16×16 panels.
fn roof_integrals(x: DVec3) -> [f64; COEFFS] {
    rect_integrals(x, ROOF)
}

/// ∫_rect y_i(ω) (ω·Y) dω from `x` (see [`roof_integrals`]).
fn rect_integrals(x: DVec3, r: Rect) -> [f64; COEFFS] {
    let panels = 16;
    let rule = gauss_legendre_8();
    let (dx, dz) = ((r.x[1] - r.x[0]) / panels as f64, (r.z[1] - r.z[0]) / panels as f64);
    let mut out = [0.0; COEFFS];
    for i in 0..panels {
        for &(u, wu) in &rule {
            let px = r.x[0] + (i as f64 + u) * dx;
            for j in 0..panels {
                for &(v, wv) in &rule {
                    let pz = r.z[0] + (j as f64 + v) * dz;
                    let d = DVec3::new(px, r.height, pz) - x;
                    let r2 = d.length_squared();
                    let weight = wu * wv * dx * dz * r.height * r.height / (r2 * r2);
                    let y = basis(d / r2.sqrt());
                    out.iter_mut().zip(y).for_each(|(o, y)| *o += weight * y);
                }
            }
        }
    }
    out
}

/// Exact transfer of a plane point: the sky's (Â_0/π = 1, Â_1/π = 2/3) minus the roof's.
fn exact_transfer(x: DVec3) -> [f64; COEFFS] {
    let sky = basis(DVec3::Y);
    let roof = roof_integrals(x);
    [sky[0] - roof[0] / PI, 2.0 / 3.0 * sky[1] - roof[1] / PI, 2.0 / 3.0 * sky[2] - roof[2] / PI, 2.0 / 3.0 * sky[3] - roof[3] / PI]
}

/// Per plane vertex, the exact hat-weighted one-ring mean of the transfer:
/// each triangle split into m² similar sub-triangles, each integrated by
/// the 3-point edge-midpoint rule (exact for quadratics).
fn exact_vertex_values(mesh: &Mesh, plane_vertices: usize, m: u32, transfer: impl Fn(DVec3) -> [f64; COEFFS]) -> Vec<[f64; COEFFS]> {
    let mut sums = vec![[0.0f64; COEFFS]; plane_vertices];
    let mut mass = vec![0.0f64; plane_vertices];
    for t in 0..mesh.triangle_count() {
        let corners = mesh.triangle(t);
        if corners.iter().any(|&v| v as usize >= plane_vertices) {
            continue;
        }
        let p = mesh.triangle_positions(t).map(|p| p.as_dvec3());
        let area = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
        let sub_area = area / (m * m) as f64;
        // Sub-triangles in barycentric steps of 1/m: (i, j) up and down.
        let at = |b: [f64; 3]| p[0] * b[0] + p[1] * b[1] + p[2] * b[2];
        let mut add = |a: [f64; 3], b: [f64; 3], c: [f64; 3]| {
            for (e0, e1) in [(a, b), (b, c), (c, a)] {
                let mid = [(e0[0] + e1[0]) / 2.0, (e0[1] + e1[1]) / 2.0, (e0[2] + e1[2]) / 2.0];
                let value = transfer(at(mid));
                for (corner, &v) in corners.iter().enumerate() {
                    let w = mid[corner] * sub_area / 3.0;
                    sums[v as usize].iter_mut().zip(value).for_each(|(s, t)| *s += w * t);
                }
            }
        };
        let bary = |i: u32, j: u32| {
            let (u, v) = (i as f64 / m as f64, j as f64 / m as f64);
            [1.0 - u - v, u, v]
        };
        for i in 0..m {
            for j in 0..m - i {
                add(bary(i, j), bary(i + 1, j), bary(i, j + 1));
                if i + j + 1 < m {
                    add(bary(i + 1, j), bary(i + 1, j + 1), bary(i, j + 1));
                }
            }
        }
        for &v in &corners {
            mass[v as usize] += area / 3.0;
        }
    }
    sums.iter().zip(&mass).map(|(s, &m)| s.map(|x| x / m)).collect()
}

/// Per vertex and coefficient: mean and standard error over `SEEDS` bakes.
struct SeedStats {
    mean: Vec<[f64; COEFFS]>,
    standard_error: Vec<[f64; COEFFS]>,
    /// Per vertex, the RMS over seeds of the bake's own DC noise estimate (`TransferResult::noise`).
    noise: Vec<f64>,
}

/// Samples per triangle, as docs/conventions.md states the rule (checked
/// against the bake's point count): the multiple of three nearest to its
/// share at the mean density, at least three, at most 255.
fn sample_counts(mesh: &Mesh, samples_per_vertex: f32) -> Vec<u32> {
    let areas: Vec<f64> = (0..mesh.triangle_count())
        .map(|t| {
            let p = mesh.triangle_positions(t).map(|p| p.as_dvec3());
            0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length()
        })
        .collect();
    let density = samples_per_vertex as f64 * mesh.vertex_count() as f64 / areas.iter().sum::<f64>();
    areas.iter().map(|a| 3 * ((a * density / 3.0).round() as u32).clamp(1, 85)).collect()
}

fn bake_seeds(mesh: &Mesh, plane_vertices: usize, samples_per_vertex: f32) -> SeedStats {
    bake_seeds_with(mesh, plane_vertices, samples_per_vertex, 0.0)
}

/// [`bake_seeds`] with adaptive allocation adding `adaptive` × the base points.
fn bake_seeds_with(mesh: &Mesh, plane_vertices: usize, samples_per_vertex: f32, adaptive: f32) -> SeedStats {
    let counts = sample_counts(mesh, samples_per_vertex);
    let base_points = counts.iter().map(|&c| c as u64).sum::<u64>();
    let mut noise = vec![0.0f64; plane_vertices];
    let mut values = vec![Vec::new(); plane_vertices];
    for seed in 1..=SEEDS {
        let params = BakeParams {
            order: 2,
            rays: RAYS,
            seed,
            mode: Mode::Open,
            sampling: Sampling::Interior { samples_per_vertex, max_per_triangle: 256 },
            adaptive,
            ..BakeParams::default()
        };
        let result = bake_mesh(mesh, &params, &[]).unwrap().0;
        assert_eq!(result.stats.points_rejected, 0, "no plane or roof point lies inside geometry");
        if adaptive == 0.0 {
            assert_eq!(result.stats.points, base_points, "the sample rule as documented");
        } else {
            let budget = (base_points as f64 * (1.0 + adaptive as f64)) as u64;
            assert!(result.stats.points > base_points && result.stats.points <= budget, "{} points, budget {budget}", result.stats.points);
        }
        for (v, n) in noise.iter_mut().enumerate() {
            *n += (result.noise[v] as f64).powi(2) / SEEDS as f64;
        }
        for (v, list) in values.iter_mut().enumerate() {
            let c = result.coefficients(v, 0);
            list.push([c[0] as f64, c[1] as f64, c[2] as f64, c[3] as f64]);
        }
    }
    let n = SEEDS as f64;
    let mean: Vec<[f64; COEFFS]> = values.iter().map(|l| std::array::from_fn(|k| l.iter().map(|x| x[k]).sum::<f64>() / n)).collect();
    let standard_error = values
        .iter()
        .zip(&mean)
        .map(|(l, m)| std::array::from_fn(|k| (l.iter().map(|x| (x[k] - m[k]).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt()))
        .collect::<Vec<[f64; COEFFS]>>();
    eprintln!("spv {samples_per_vertex}: {} samples on each plane triangle", counts[0]);
    SeedStats { mean, standard_error, noise: noise.into_iter().map(f64::sqrt).collect() }
}

/// Floor of a standard error: the exact values' own error (the one-ring
/// integration moves by < 1e-5 from m = 6 to 24) and the f32 sums' rounding.
const ERROR_FLOOR: f64 = 1e-5;

/// (RMS z, worst |z|, worst |difference|) of `a` against `b` (exact values,
/// or another density's seed means) over vertices, for coefficients `ks`,
/// with standard errors combined in quadrature.
fn compare(a: &SeedStats, b_mean: &[[f64; COEFFS]], b: Option<&SeedStats>, ks: &[usize]) -> (f64, f64, f64) {
    let (mut sum_z2, mut worst_z, mut worst_d, mut count) = (0.0f64, 0.0f64, 0.0f64, 0usize);
    for v in 0..b_mean.len() {
        for &k in ks {
            let d = a.mean[v][k] - b_mean[v][k];
            let e_b = b.map_or(0.0, |b| b.standard_error[v][k]);
            let sigma = (a.standard_error[v][k].powi(2) + e_b * e_b).sqrt().max(ERROR_FLOOR);
            let z = d / sigma;
            sum_z2 += z * z;
            worst_z = worst_z.max(z.abs());
            worst_d = worst_d.max(d.abs());
            count += 1;
        }
    }
    ((sum_z2 / count as f64).sqrt(), worst_z, worst_d)
}

/// The exact values themselves: Lambert's closed form and the area
/// quadrature agree on DC, and the one-ring integration has converged.
#[test]
fn exact_vertex_values_are_converged() {
    let mesh = scene();
    let plane_vertices = ((CELLS + 1) * (CELLS + 1)) as usize;
    for v in (0..plane_vertices).step_by(7) {
        let x = mesh.positions[v].as_dvec3();
        let (lambert, area) = (roof_cosine_integral(x), roof_integrals(x)[0] / basis(DVec3::Y)[0]);
        assert!((lambert - area).abs() < 1e-7, "vertex {v}: Lambert {lambert} vs quadrature {area}");
    }
    let dc = |x: DVec3| [basis(DVec3::Y)[0] * (1.0 - roof_cosine_integral(x) / PI), 0.0, 0.0, 0.0];
    let coarse = exact_vertex_values(&mesh, plane_vertices, 6, dc);
    let fine = exact_vertex_values(&mesh, plane_vertices, 24, dc);
    let worst = coarse.iter().zip(&fine).map(|(a, b)| (a[0] - b[0]).abs()).fold(0.0, f64::max);
    assert!(worst < 1e-5, "one-ring integration moved by {worst:.2e} from m = 6 to 24");
}

#[test]
fn estimator_converges_to_the_hat_weighted_mean_at_every_density() {
    let mesh = scene();
    let plane_vertices = ((CELLS + 1) * (CELLS + 1)) as usize;
    let exact = exact_vertex_values(&mesh, plane_vertices, 6, exact_transfer);
    // Spread of the exact values: what the estimator has to resolve.
    let (lo, hi) = exact.iter().fold((f64::MAX, f64::MIN), |(lo, hi), e| (lo.min(e[0]), hi.max(e[0])));
    eprintln!("exact DC over plane vertices: {lo:.4} … {hi:.4}");
    let densities = [1.0f32, 16.0, 64.0];
    let stats: Vec<SeedStats> = densities.iter().map(|&spv| bake_seeds(&mesh, plane_vertices, spv)).collect();
    eprintln!("{:>4} {:>12} {:>12} {:>10} {:>10} {:>12}", "spv", "DC max|err|", "b1 max|err|", "DC rms z", "b1 rms z", "max SE");
    let mut verdicts = Vec::new();
    for (spv, s) in densities.iter().zip(&stats) {
        let (dc_z, dc_worst_z, dc_err) = compare(s, &exact, None, &[0]);
        let (b1_z, b1_worst_z, b1_err) = compare(s, &exact, None, &[1, 2, 3]);
        let max_se = s.standard_error.iter().flatten().fold(0.0f64, |m, &e| m.max(e));
        eprintln!("{spv:>4} {dc_err:>12.2e} {b1_err:>12.2e} {dc_z:>10.2} {b1_z:>10.2} {max_se:>12.2e}");
        verdicts.push((*spv, dc_z, dc_worst_z, b1_z, b1_worst_z));
    }
    let mut pairs = Vec::new();
    for (i, j) in [(0, 1), (0, 2), (1, 2)] {
        let (z, worst_z, worst_d) = compare(&stats[i], &stats[j].mean, Some(&stats[j]), &[0, 1, 2, 3]);
        eprintln!("spv {} vs {}: max |mean difference| {worst_d:.2e}, RMS z {z:.2}, worst z {worst_z:.1}", densities[i], densities[j]);
        pairs.push((densities[i], densities[j], z, worst_z));
    }
    // Unbiased: the seed means' z-scores are t-distributed with 15 degrees of
    // freedom (RMS ≈ 1.07 ± 0.1 over 81 DC or 243 band-1 values); a bias of
    // one standard error everywhere would give about √2. A single |z| over 7
    // has probability 5e-6 under t(15): over the ~1,500 values checked, a
    // 1% chance.
    for (spv, dc_z, dc_worst_z, b1_z, b1_worst_z) in verdicts {
        assert!(dc_z < 1.3 && dc_worst_z < 7.0, "spv {spv}: DC RMS z {dc_z:.2}, worst {dc_worst_z:.1}");
        assert!(b1_z < 1.3 && b1_worst_z < 7.0, "spv {spv}: band 1 RMS z {b1_z:.2}, worst {b1_worst_z:.1}");
    }
    for (a, b, z, worst_z) in pairs {
        assert!(z < 1.3 && worst_z < 7.0, "spv {a} vs {b}: RMS z {z:.2}, worst {worst_z:.1}");
    }
}

/// Window mode, bounce 0, on the same plane lit only through one window
/// (a rectangle facing down, transmittance 1): a plane point's exact
/// transfer is (1/π) ∫_window y_i(ω) (ω·Y) dω, the hat-weighted vertex
/// values as above. Per bake, the RMS error of DC over the plane vertices
/// (relative to the RMS exact DC); over 16 seeds, its mean for cosine rays
/// alone at 2N rays and for MIS (N cosine + N aimed at the glass, the same
/// traced rays), and MIS's z-scores.
fn window_errors(window: Rect, rays: u32) -> (f64, f64, f64) {
    let mut glass = Material::opaque("glass", 0.0);
    glass.role = prtbake::mesh::MaterialRole::Window;
    let mesh = scene_with(window, glass);
    let plane_vertices = ((CELLS + 1) * (CELLS + 1)) as usize;
    let exact = exact_vertex_values(&mesh, plane_vertices, 6, |x| rect_integrals(x, window).map(|v| v / PI));
    let exact_rms = (exact.iter().map(|e| e[0] * e[0]).sum::<f64>() / plane_vertices as f64).sqrt();
    let bake = |seed: u32, rays: u32, window_sampling: bool| {
        let params = BakeParams {
            order: 2,
            rays,
            seed,
            mode: Mode::Window,
            window_sampling,
            // A pane over an open plane: no enclosure, every side sees the sky.
            keep_outside_sides: true,
            sampling: Sampling::Interior { samples_per_vertex: 16.0, max_per_triangle: 256 },
            ..BakeParams::default()
        };
        let result = bake_mesh(&mesh, &params, &[]).unwrap().0;
        (0..plane_vertices).map(|v| result.coefficients(v, 0)[0] as f64).collect::<Vec<f64>>()
    };
    let rms_error =
        |dc: &[f64]| (dc.iter().zip(&exact).map(|(d, e)| (d - e[0]).powi(2)).sum::<f64>() / plane_vertices as f64).sqrt() / exact_rms;
    let (mut cosine, mut mis) = (0.0, 0.0);
    let mut mis_values = vec![Vec::new(); plane_vertices];
    for seed in 1..=SEEDS {
        cosine += rms_error(&bake(seed, 2 * rays, false)) / SEEDS as f64;
        let dc = bake(seed, rays, true);
        mis += rms_error(&dc) / SEEDS as f64;
        mis_values.iter_mut().zip(&dc).for_each(|(l, &d)| l.push(d));
    }
    let n = SEEDS as f64;
    let z2: f64 = mis_values
        .iter()
        .zip(&exact)
        .map(|(l, e)| {
            let mean = l.iter().sum::<f64>() / n;
            let se = (l.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt().max(ERROR_FLOOR);
            ((mean - e[0]) / se).powi(2)
        })
        .sum();
    (cosine, mis, (z2 / plane_vertices as f64).sqrt())
}

/// Window sampling (`--window-sampling`: panes by area, directions by
/// solid angle, MIS with the cosine rays) is unbiased, and at the same
/// traced rays never worse than cosine rays alone (measured: 0.68× their
/// error, asserted ≤ 1×) under a large
/// window close to the plane (the roof's rectangle 0.6 m up, where the old
/// area-sampled estimator's 1/r² weights blew up) and far better under a
/// small high one (0.4 × 0.3 m, 2.5 m up), where few cosine rays find it
/// (measured 0.013×, asserted ≤ 0.1×).
#[test]
fn window_sampling_is_unbiased_and_never_worse_than_cosine_rays() {
    let large_close = ROOF;
    let small_high = Rect { x: [-0.6, -0.2], z: [0.3, 0.6], height: 2.5 };
    for (name, window, most_ratio) in [("large close", large_close, 1.0), ("small high", small_high, 0.1)] {
        let (cosine, mis, z) = window_errors(window, 32);
        eprintln!(
            "{name} window: relative RMS error of DC, cosine 64 rays {cosine:.4}, MIS 32 + 32 {mis:.4} (ratio {:.2}), MIS RMS z {z:.2}",
            mis / cosine
        );
        assert!(z < 1.3, "{name}: MIS seed means off the exact values, RMS z {z:.2}");
        assert!(mis < most_ratio * cosine, "{name}: MIS {mis:.4} against cosine {cosine:.4}");
    }
}

/// Adaptive allocation (`--adaptive`) keeps the estimator's expectation:
/// at 9 samples per plane triangle plus as many again placed by the
/// pilot's noise, the seed means match the exact values as the uniform
/// densities do. And it puts them where the noise is: the summed squared
/// DC error over the plane's vertices (16 seeds' spread) is below that of
/// the uniform layout with twice the samples per vertex (about as many
/// points), and each bake's own noise estimate bounds the seeds' spread
/// from above, within 5×.
#[test]
fn adaptive_allocation_converges_to_the_same_values_with_less_noise() {
    let mesh = scene();
    let plane_vertices = ((CELLS + 1) * (CELLS + 1)) as usize;
    let exact = exact_vertex_values(&mesh, plane_vertices, 6, exact_transfer);
    let adaptive = bake_seeds_with(&mesh, plane_vertices, 16.0, 1.0);
    let (dc_z, dc_worst_z, _) = compare(&adaptive, &exact, None, &[0]);
    let (b1_z, b1_worst_z, _) = compare(&adaptive, &exact, None, &[1, 2, 3]);
    eprintln!("adaptive: DC RMS z {dc_z:.2} (worst {dc_worst_z:.1}), band 1 RMS z {b1_z:.2} (worst {b1_worst_z:.1})");
    assert!(dc_z < 1.3 && dc_worst_z < 7.0 && b1_z < 1.3 && b1_worst_z < 7.0, "adaptive allocation is biased");

    let uniform = bake_seeds(&mesh, plane_vertices, 32.0);
    // Squared error per bake summed over vertices: n × SE² of the seed mean.
    let summed = |s: &SeedStats| s.standard_error.iter().map(|e| e[0] * e[0] * SEEDS as f64).sum::<f64>();
    let (a, u) = (summed(&adaptive), summed(&uniform));
    eprintln!("summed squared DC error per bake: adaptive {a:.3e}, uniform at twice the density {u:.3e} ({:.2}x)", a / u);
    assert!(a < 0.8 * u, "adaptive {a:.3e} against uniform {u:.3e}");
    // The bakes' own estimates against the seeds' spread (RMS over vertices).
    for (name, s) in [("adaptive", &adaptive), ("uniform", &uniform)] {
        let spread = (s.standard_error.iter().map(|e| e[0] * e[0] * SEEDS as f64).sum::<f64>() / plane_vertices as f64).sqrt();
        let estimate = (s.noise.iter().map(|n| n * n).sum::<f64>() / plane_vertices as f64).sqrt();
        eprintln!("{name}: RMS noise estimate {estimate:.3e}, seeds' spread {spread:.3e}");
        // Measured 3.5–3.6×: the estimate treats the points as independent, and
        // Sobol points stratify the penumbra better than that. It must not
        // understate the noise (refinement or a user would read it as a bound).
        assert!(spread <= estimate && estimate < 5.0 * spread, "{name}: estimate {estimate:.3e} against spread {spread:.3e}");
    }
}

/// The bake's noise estimate (`TransferResult::noise`, what `--max-error`
/// adds to storage error) covers every bounce, not bounce 0 alone. Inside
/// the integrating sphere (window mode, albedo 0.6, two bounces), over 12
/// seeds: at every vertex it is at least bounce 0's own estimate (the same
/// bake without bounces); what it adds to it (in quadrature) is the later
/// bounces' noise, within 3× of the seeds' spread of bounces 1–2's DC
/// (RMS over the wall's vertices); and it bounds the seeds' spread of the
/// total DC from above, within 5×.
#[test]
fn noise_estimate_covers_the_later_bounces() {
    let (mesh, _) = shapes::integrating_sphere(3, 0.6, 0.7, shapes::Opening::Window);
    let bake = |seed: u32, bounces: u32| {
        let params = BakeParams { order: 1, rays: 64, seed, mode: Mode::Window, bounces, store_bounces: true, ..BakeParams::default() };
        bake_mesh(&mesh, &params, &[]).unwrap().0
    };
    let seeds = 12u32;
    let wall: Vec<usize> = {
        let first = bake(1, 0);
        (0..mesh.vertex_count()).filter(|&v| first.noise[v] > 0.0).collect()
    };
    assert!(wall.len() > 100, "{} wall vertices with a noise estimate", wall.len());
    let (mut totals, mut later) = (vec![Vec::new(); wall.len()], vec![Vec::new(); wall.len()]);
    let (mut all_noise2, mut direct_noise2) = (0.0f64, 0.0f64);
    for seed in 1..=seeds {
        let (all, direct) = (bake(seed, 2), bake(seed, 0));
        for (i, &v) in wall.iter().enumerate() {
            assert!(all.noise[v] >= direct.noise[v], "seed {seed}, vertex {v}: {} below bounce 0's {}", all.noise[v], direct.noise[v]);
            let total = all.coefficients(v, 0)[0] as f64;
            totals[i].push(total);
            later[i].push(total - all.bounces[0][v * all.total.len() / mesh.vertex_count()] as f64);
            all_noise2 += (all.noise[v] as f64).powi(2);
            direct_noise2 += (direct.noise[v] as f64).powi(2);
        }
    }
    let count = (wall.len() * seeds as usize) as f64;
    let (estimate, later_estimate) = ((all_noise2 / count).sqrt(), ((all_noise2 - direct_noise2) / count).sqrt());
    // RMS over vertices of the seeds' standard deviation.
    let spread = |values: &[Vec<f64>]| {
        let n = seeds as f64;
        let variance: f64 = values
            .iter()
            .map(|l| {
                let mean = l.iter().sum::<f64>() / n;
                l.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)
            })
            .sum();
        (variance / values.len() as f64).sqrt()
    };
    let (total_spread, later_spread) = (spread(&totals), spread(&later));
    eprintln!(
        "DC noise: total spread {total_spread:.3e}, estimate {estimate:.3e}; bounces 1-2 spread {later_spread:.3e}, their part of the estimate {later_estimate:.3e}"
    );
    assert!(
        later_estimate > later_spread / 3.0 && later_estimate < 3.0 * later_spread,
        "later bounces: estimate {later_estimate:.3e} against the seeds' spread {later_spread:.3e}"
    );
    assert!(
        total_spread <= estimate && estimate < 5.0 * total_spread,
        "estimate {estimate:.3e} against the seeds' spread {total_spread:.3e}"
    );
}
