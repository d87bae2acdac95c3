//! The swept scenes: how each is built, what its right answer is, which
//! settings are swept on it, and how a bake is scored.

use std::path::Path;
use std::time::Instant;

use glam::{DVec3, Vec3};

use super::{pattern_name, sampling_name, Row};
use crate::bake::{bake_mesh, BakeError, BakeParams, DirectionPattern, Mode, Sampling, TransferResult};
use crate::bundle::budget::{self, Lighting};
use crate::mesh::Mesh;
use crate::sh;
use crate::verify::{shapes, Y00};

/// Sweep size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Size {
    /// Two ray counts, small scenes: seconds (for tests).
    Quick,
    /// The chart: seven ray counts, the cabin at detail 12.
    Full,
}

impl Size {
    fn rays(self) -> &'static [u32] {
        match self {
            Size::Quick => &[16, 64],
            Size::Full => &[16, 32, 64, 128, 256, 512, 1024],
        }
    }
}

/// One setting swept over ray counts.
#[derive(Clone, Copy, Debug)]
struct Setting {
    pattern: DirectionPattern,
    sampling: Sampling,
    order: usize,
    bounces: u32,
}

impl Setting {
    fn new(pattern: DirectionPattern, sampling: Sampling, order: usize, bounces: u32) -> Setting {
        Setting { pattern, sampling, order, bounces }
    }
    fn label(&self) -> String {
        format!("{} {} order {} bounces {}", pattern_name(self.pattern), sampling_name(self.sampling), self.order, self.bounces)
    }
}

/// Exact (or reference) transfer of a scene: per scored vertex, `channels × order²`.
struct Reference {
    order: usize,
    channels: usize,
    /// Vertices that are scored.
    vertices: Vec<usize>,
    /// `[scored vertex][channel][coeff]`.
    transfer: Vec<f32>,
}

/// A scene ready to sweep.
struct Scene {
    name: &'static str,
    mesh: Mesh,
    mode: Mode,
    reference: Reference,
    settings: Vec<Setting>,
    rays: Vec<u32>,
}

/// Scores a bake: shaded error of its transfer (padded to the reference's
/// order, channels widened) on the scored vertices.
fn score(result: &TransferResult, reference: &Reference, lightings: &[Lighting]) -> f64 {
    let n_ref = sh::coeff_count(reference.order);
    let n = sh::coeff_count(result.order.min(reference.order));
    let mut baked = vec![0.0f32; reference.vertices.len() * reference.channels * n_ref];
    for (k, &v) in reference.vertices.iter().enumerate() {
        for c in 0..reference.channels {
            let src = result.coefficients(v, c.min(result.channels - 1));
            baked[(k * reference.channels + c) * n_ref..][..n].copy_from_slice(&src[..n]);
        }
    }
    lightings
        .iter()
        .map(|l| {
            budget::relative_rms(
                &budget::shade(&reference.transfer, reference.order, reference.channels, &l.sh),
                &budget::shade(&baked, reference.order, reference.channels, &l.sh),
            )
        })
        .fold(0.0, f64::max)
}

fn unoccluded_sphere(size: Size) -> Scene {
    let mesh = shapes::icosphere(3);
    let order = 4;
    let n = sh::coeff_count(order);
    let mut transfer = Vec::with_capacity(mesh.vertex_count() * n);
    let mut y = vec![0.0f64; n];
    for normal in &mesh.normals {
        sh::eval_basis_f64(order, normal.as_dvec3(), &mut y);
        transfer.extend((0..n).map(|i| (sh::clamped_cosine_kernel(sh::band_of_index(i)) / std::f64::consts::PI * y[i]) as f32));
    }
    let sobol = DirectionPattern::Sobol;
    let random = DirectionPattern::Random;
    let interior = Sampling::interior();
    Scene {
        name: "unoccluded-sphere",
        reference: Reference { order, channels: 1, vertices: (0..mesh.vertex_count()).collect(), transfer },
        mesh,
        mode: Mode::Open,
        settings: vec![
            Setting::new(sobol, interior, 4, 0),
            Setting::new(random, interior, 4, 0),
            Setting::new(sobol, interior, 3, 0),
            Setting::new(sobol, interior, 2, 0),
            Setting::new(sobol, Sampling::Vertex, 4, 0),
        ],
        rays: size.rays().to_vec(),
    }
}

fn plane_under_sphere(size: Size) -> Scene {
    let (radius, height, cells) = (0.5f32, 1.0f32, 32u32);
    let mut mesh = shapes::plane_grid(cells, 4.0);
    let mut sphere = shapes::icosphere(3);
    shapes::transform(&mut sphere, radius, Vec3::new(0.0, height, 0.0));
    shapes::append(&mut mesh, &sphere);
    let order = 4;
    // The polygonal sphere's silhouette lies between its vertex and face radii (icosphere(3): ~0.997).
    let effective_radius = radius as f64 * (1.0 + 0.995) / 2.0;
    let centre = DVec3::new(0.0, height as f64, 0.0);
    let (mut vertices, mut transfer) = (Vec::new(), Vec::new());
    for i in 0..((cells + 1) * (cells + 1)) as usize {
        let x = mesh.positions[i].as_dvec3();
        let to_centre = centre - x;
        let alpha = (effective_radius / to_centre.length()).asin();
        let beta = to_centre.normalize().dot(DVec3::Y).acos();
        if alpha + beta > 88f64.to_radians() {
            continue;
        }
        vertices.push(i);
        transfer.extend(crate::verify::plane_point_reference(order, x, centre, effective_radius).into_iter().map(|v| v as f32));
    }
    let interior = Sampling::interior();
    Scene {
        name: "plane-under-sphere",
        reference: Reference { order, channels: 1, vertices, transfer },
        mesh,
        mode: Mode::Open,
        settings: vec![
            Setting::new(DirectionPattern::Sobol, interior, 4, 0),
            Setting::new(DirectionPattern::Random, interior, 4, 0),
            Setting::new(DirectionPattern::Sobol, Sampling::Vertex, 4, 0),
            Setting::new(DirectionPattern::Random, Sampling::Vertex, 4, 0),
            Setting::new(DirectionPattern::Sobol, interior, 2, 0),
        ],
        rays: size.rays().to_vec(),
    }
}

/// Rays of the high-sample reference bakes.
const REFERENCE_RAYS: u32 = 4096;

fn covered_floor(size: Size) -> Result<Scene, BakeError> {
    let (mesh, row) = shapes::covered_floor(0.02);
    let (leak_free, _) = shapes::covered_floor(-0.02);
    let order = 2;
    let rays = if size == Size::Quick { 512 } else { REFERENCE_RAYS };
    let params = BakeParams { order, rays, ..BakeParams::default() };
    let (reference, _, _) = bake_mesh(&leak_free, &params, &[])?;
    let transfer = row.iter().flat_map(|&v| reference.coefficients(v, 0).to_vec()).collect();
    let interior = Sampling::interior();
    Ok(Scene {
        name: "covered-floor",
        reference: Reference { order, channels: 1, vertices: row, transfer },
        mesh,
        mode: Mode::Open,
        settings: vec![
            Setting::new(DirectionPattern::Sobol, interior, order, 0),
            Setting::new(DirectionPattern::Random, interior, order, 0),
            Setting::new(DirectionPattern::Sobol, Sampling::Vertex, order, 0),
            Setting::new(DirectionPattern::Random, Sampling::Vertex, order, 0),
        ],
        rays: size.rays().to_vec(),
    })
}

fn integrating_sphere(size: Size) -> Scene {
    let (albedo, cap) = (0.7f32, 0.6f32);
    let (mesh, f) = shapes::integrating_sphere(3, albedo, cap, shapes::Opening::Window);
    let mut on_wall = vec![true; mesh.vertex_count()];
    for t in 0..mesh.triangle_count() {
        if mesh.materials[mesh.tri_material[t] as usize].role == crate::mesh::MaterialRole::Window {
            mesh.triangle(t).iter().for_each(|&i| on_wall[i as usize] = false);
        }
    }
    let vertices: Vec<usize> = (0..mesh.vertex_count()).filter(|&i| on_wall[i] && mesh.positions[i].y < cap).collect();
    // Every bounce summed: t_00 = y00·f / (1 − ρ(1−f)). Only DC has a closed form: scored at order 1.
    let rho = albedo as f64;
    let exact = (Y00 * f / (1.0 - rho * (1.0 - f))) as f32;
    let transfer = vec![exact; vertices.len()];
    let s = DirectionPattern::Sobol;
    let interior = Sampling::interior();
    Scene {
        name: "integrating-sphere",
        reference: Reference { order: 1, channels: 1, vertices, transfer },
        mesh,
        mode: Mode::Window,
        settings: vec![
            Setting::new(s, interior, 1, 0),
            Setting::new(s, interior, 1, 1),
            Setting::new(s, interior, 1, 2),
            Setting::new(s, interior, 1, 4),
            Setting::new(s, interior, 1, 8),
            Setting::new(DirectionPattern::Random, interior, 1, 8),
        ],
        rays: size.rays().to_vec(),
    }
}

/// Cells per metre of the swept cabin (the demo uses 64; 12 keeps the sweep short).
pub const CHART_CABIN_DETAIL: f32 = 12.0;

/// The reference bake's parameters for the cabin.
fn cabin_reference_params(size: Size) -> BakeParams {
    BakeParams { order: 3, rays: if size == Size::Quick { 256 } else { 2048 }, bounces: 3, mode: Mode::Window, ..BakeParams::default() }
}

/// The demo cabin (cleaned as `demo` does) and its reference, read from
/// `cache` when it holds a bundle of the same mesh and parameters, else baked and written there.
fn cabin(size: Size, cache: &Path) -> anyhow::Result<Scene> {
    let detail = if size == Size::Quick { 4.0 } else { CHART_CABIN_DETAIL };
    let (raw, _) = crate::fixtures::cabin::generate_cabin(detail);
    let (mesh, _) = crate::clean::clean_mesh(&raw, &crate::clean::CleanParams::cad())?;
    let params = cabin_reference_params(size);
    let key =
        serde_json::json!({ "detail": detail, "params": params, "vertices": mesh.vertex_count(), "triangles": mesh.triangle_count() });
    let cached = crate::bundle::read_bundle(cache).ok().filter(|b| b.meta.get("chart_reference") == Some(&key) && b.mesh == mesh);
    let (order, channels, total) = match cached.and_then(|b| b.transfer) {
        Some(t) => (t.order as usize, t.channels as usize, t.layers.into_iter().next().map(|l| l.data).unwrap_or_default()),
        None => {
            eprintln!("chart: baking the cabin reference ({} rays, {} bounces) into {}", params.rays, params.bounces, cache.display());
            let (result, _, _) = bake_mesh(&mesh, &params, &[])?;
            let meta = serde_json::json!({ "chart_reference": key });
            let bundle = crate::bundle::make_bundle(&mesh, &result, &params, meta);
            crate::bundle::write_bundle(cache, &bundle)?;
            (result.order, result.channels, result.total)
        }
    };
    let s = DirectionPattern::Sobol;
    let interior = Sampling::interior();
    let rays: Vec<u32> = size.rays().iter().copied().filter(|&r| r <= 256).collect();
    Ok(Scene {
        name: "cabin",
        reference: Reference { order, channels, vertices: (0..mesh.vertex_count()).collect(), transfer: total },
        mesh,
        mode: Mode::Window,
        settings: vec![
            Setting::new(s, interior, 3, 3),
            Setting::new(DirectionPattern::Random, interior, 3, 3),
            Setting::new(s, Sampling::Vertex, 3, 3),
            Setting::new(s, interior, 3, 1),
            Setting::new(s, interior, 3, 0),
            Setting::new(s, interior, 2, 3),
        ],
        rays,
    })
}

/// Runs the sweep; `cache_dir` holds the cabin reference. Progress on stderr.
pub fn sweep(size: Size, cache_dir: &Path) -> anyhow::Result<Vec<Row>> {
    let scenes = vec![
        unoccluded_sphere(size),
        plane_under_sphere(size),
        covered_floor(size)?,
        integrating_sphere(size),
        cabin(size, &cache_dir.join(if size == Size::Quick { "cabin-reference-quick.prtb" } else { "cabin-reference.prtb" }))?,
    ];
    let mut rows = Vec::new();
    for scene in &scenes {
        let lightings = budget::reference_lightings(scene.reference.order);
        // One untimed bake first, so the first timed point does not pay for cold caches.
        let warm = BakeParams { rays: 4, mode: scene.mode, ..BakeParams::default() };
        bake_mesh(&scene.mesh, &warm, &[])?;
        for setting in &scene.settings {
            for &rays in &scene.rays {
                let params = BakeParams {
                    order: setting.order,
                    rays,
                    mode: scene.mode,
                    sampling: setting.sampling,
                    bounces: setting.bounces,
                    pattern: setting.pattern,
                    ..BakeParams::default()
                };
                let started = Instant::now();
                let (result, _, _) = bake_mesh(&scene.mesh, &params, &[])?;
                let seconds = started.elapsed().as_secs_f64();
                let error = score(&result, &scene.reference, &lightings);
                eprintln!("chart: {:<20} {:<40} {:>5} rays  {:>8.3}s  error {:.3e}", scene.name, setting.label(), rays, seconds, error);
                rows.push(Row {
                    scene: scene.name.into(),
                    setting: setting.label(),
                    pattern: pattern_name(setting.pattern).into(),
                    sampling: sampling_name(setting.sampling).into(),
                    order: setting.order,
                    bounces: setting.bounces,
                    rays,
                    seconds,
                    error,
                    pareto: false,
                });
            }
        }
    }
    super::pareto::mark_fronts(&mut rows);
    Ok(rows)
}
