//! Throughput of the baker on a ≥ 500k-triangle scene (the demo cabin at
//! higher detail) and, when ../shared/data is present, on the Ferrari:
//! BVH build time, occlusion and closest-hit rays/s on 1 and 2 threads, and
//! whole transfer bakes (the Ferrari's at order 3 with 3 bounces).
//! Criterion's "elements/s" are rays per second.
//!
//! And whole bakes of a closed cone whose apex valence grows from 2.5k to
//! 20k (`bake/cone_valence`): the time must grow about as the triangles do
//! (fans, `prtbake::trace::fans`), not as their square.
//!
//! And texel mode on the generated room whose walls run past each other
//! (`bake/texels`): a whole 3-bounce bake, vertices and texels, at 5 cm
//! texels with 4 points each (bounces read from the texels, gathered from
//! bounce 0's hit records); elements/s are the texels' evaluated rays over
//! the whole bake's time.
//!
//! Run: `cargo bench --bench bake` (add `-- trace` etc. to filter; only the
//! cones: `cargo bench --bench bake -- cone_valence`).

use std::path::Path;

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use glam::Vec3;
use prtbake::bake::{bake_mesh, BakeParams, Mode};
use prtbake::clean::fixtures::{fan, FanShape};
use prtbake::fixtures::cabin::generate_cabin;
use prtbake::mesh::{load_mesh, LoadOptions, Mesh};
use prtbake::sampling;
use prtbake::trace::{BatchMode, Batching, BuildQuality, RayQuery, Scene, Traversal};
use rayon::prelude::*;

/// Cells per metre giving the cabin ≥ 500k triangles.
const BIG_DETAIL: f32 = 80.0;
const POINTS: u32 = 8192;
const RAYS_PER_POINT: u32 = 64;

/// Ray origins and directions like the baker's: centroids of a deterministic
/// spread of triangles, cosine-distributed directions over the sphere.
fn workload(mesh: &Mesh, scene: &Scene) -> Vec<RayQuery> {
    let step = (mesh.triangle_count() as u32 / POINTS).max(1);
    let mut rays = Vec::with_capacity((POINTS * RAYS_PER_POINT) as usize);
    for p in 0..POINTS {
        let t = ((p * step) as usize).min(mesh.triangle_count() - 1);
        let [a, b, c] = mesh.triangle_positions(t);
        let n = scene.face_normal(t as u32);
        if n == Vec3::ZERO {
            continue;
        }
        for k in 0..RAYS_PER_POINT {
            let (u1, u2) = sampling::sample_2d(sampling::DirectionPattern::Sobol, k, 0, p);
            let d = sampling::cosine_sphere(n, u1, u2);
            rays.push(RayQuery { origin: scene.offset_origin((a + b + c) / 3.0, n, d), direction: d, t_max: f32::INFINITY });
        }
    }
    rays
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap()
}

fn bench_scene(c: &mut Criterion, name: &str, mesh: &Mesh) {
    let mut group = c.benchmark_group(format!("build/{name}"));
    group.sample_size(10);
    group.bench_function("sah", |b| b.iter(|| Scene::build(mesh, BuildQuality::Sah).unwrap()));
    group.bench_function("ploc", |b| b.iter(|| Scene::build(mesh, BuildQuality::Ploc).unwrap()));
    group.finish();

    let scene = Scene::build(mesh, BuildQuality::Sah).unwrap();
    let rays = workload(mesh, &scene);
    let mut group = c.benchmark_group(format!("trace/{name}"));
    group.sample_size(10);
    group.throughput(Throughput::Elements(rays.len() as u64));
    // A point's rays per call, as the baker traces them, run the way the scene chose.
    let occlusion = |scene: &Scene, pool: &rayon::ThreadPool| {
        pool.install(|| {
            rays.par_chunks(RAYS_PER_POINT as usize)
                .map(|point| {
                    let mut out = [false; RAYS_PER_POINT as usize];
                    scene.occluded_each(point, &mut out[..point.len()]);
                    out.iter().filter(|&&o| o).count()
                })
                .sum::<usize>()
        })
    };
    let closest = |scene: &Scene, pool: &rayon::ThreadPool| {
        pool.install(|| {
            rays.par_chunks(RAYS_PER_POINT as usize)
                .map(|point| {
                    let mut out = [None; RAYS_PER_POINT as usize];
                    scene.closest_hits(point, &mut out[..point.len()]);
                    out.iter().filter(|h| h.is_some()).count()
                })
                .sum::<usize>()
        })
    };
    for threads in [1, 2] {
        let pool = pool(threads);
        group.bench_function(format!("occlusion/{threads}t"), |b| b.iter(|| occlusion(&scene, &pool)));
        group.bench_function(format!("closest_hit/{threads}t"), |b| b.iter(|| closest(&scene, &pool)));
    }
    // The alternatives, on one thread: each way of running a batch, the
    // portable walk and the PLOC tree.
    let pool = pool(1);
    for mode in [BatchMode::OneByOne, BatchMode::Interleaved] {
        let mut forced = Scene::build(mesh, BuildQuality::Sah).unwrap();
        forced.set_batching(Batching { closest_hit: mode, occlusion: mode });
        let mode = format!("{mode:?}").to_lowercase();
        group.bench_function(format!("occlusion_{mode}/1t"), |b| b.iter(|| occlusion(&forced, &pool)));
        group.bench_function(format!("closest_hit_{mode}/1t"), |b| b.iter(|| closest(&forced, &pool)));
    }
    let mut portable = Scene::build(mesh, BuildQuality::Sah).unwrap();
    portable.set_traversal(Traversal::Portable);
    group.bench_function("occlusion_portable/1t", |b| b.iter(|| occlusion(&portable, &pool)));
    group.bench_function("closest_hit_portable/1t", |b| b.iter(|| closest(&portable, &pool)));
    let ploc = Scene::build(mesh, BuildQuality::Ploc).unwrap();
    group.bench_function("occlusion_ploc/1t", |b| b.iter(|| occlusion(&ploc, &pool)));
    group.bench_function("closest_hit_ploc/1t", |b| b.iter(|| closest(&ploc, &pool)));
    group.finish();
}

fn bench_bake(c: &mut Criterion, name: &str, mesh: &Mesh, window: &[String]) {
    let mode = if window.is_empty() { Mode::Open } else { Mode::Window };
    let params = BakeParams { order: 3, rays: 8, mode, ..BakeParams::default() };
    let (probe, _, _) = bake_mesh(mesh, &params, window).unwrap();
    let mut group = c.benchmark_group(format!("bake/{name}"));
    group.sample_size(10);
    group.throughput(Throughput::Elements(probe.stats.rays));
    for threads in [1, 2] {
        let pool = pool(threads);
        group.bench_function(format!("order3_8rays_{threads}t"), |b| {
            b.iter_batched(|| (), |_| pool.install(|| bake_mesh(mesh, &params, window).unwrap()), BatchSize::PerIteration)
        });
    }
    group.finish();
}

/// A whole bake: the Ferrari in window mode, order 3, 3 bounces, 64
/// rays, 2 threads. Elements/s is the effective rate (rays traced / bake
/// time), to set against `trace/ferrari/closest_hit/2t`
/// (`benches/bake_rate.py` pairs the two run by run).
fn bench_ferrari_bake(c: &mut Criterion, mesh: &Mesh) {
    let window = ["Glass_Gray".to_string()];
    let params = BakeParams { order: 3, rays: 64, bounces: 3, mode: Mode::Window, ..BakeParams::default() };
    let pool = pool(2);
    let (probe, _, _) = pool.install(|| bake_mesh(mesh, &params, &window).unwrap());
    let mut group = c.benchmark_group("bake/ferrari");
    group.sample_size(10);
    group.measurement_time(std::time::Duration::from_secs_f64(probe.stats.seconds * 12.0));
    group.throughput(Throughput::Elements(probe.stats.rays_traced));
    group.bench_function("order3_3bounces_64rays_2t", |b| {
        b.iter_batched(|| (), |_| pool.install(|| bake_mesh(mesh, &params, &window).unwrap()), BatchSize::PerIteration)
    });
    group.finish();
}

fn benches(c: &mut Criterion) {
    let (cabin, _) = generate_cabin(BIG_DETAIL);
    assert!(cabin.triangle_count() >= 500_000, "{}", cabin.triangle_count());
    bench_scene(c, "cabin", &cabin);
    bench_bake(c, "cabin_open", &cabin, &[]);
    bench_bake(c, "cabin_window", &cabin, &["glass".to_string()]);
    let ferrari = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/car-ferrari458/ferrari_nodraco.glb");
    match load_mesh(&ferrari, &LoadOptions::default()) {
        Ok(loaded) => {
            bench_scene(c, "ferrari", &loaded.mesh);
            bench_ferrari_bake(c, &loaded.mesh);
        }
        Err(e) => eprintln!("SKIP ferrari benches: {e}"),
    }
}

/// The review's case: a closed cone baked at `--rays 4 --threads 1`, apex
/// (and base centre) of valence 2.5k to 20k. Before fans: 0.34, 1.12, 4.16
/// and 17.8 s; elements/s is triangles per second, flat when the bake is linear.
fn cone_valence(c: &mut Criterion) {
    let mut group = c.benchmark_group("bake/cone_valence");
    group.sample_size(10);
    group.sampling_mode(criterion::SamplingMode::Flat);
    group.warm_up_time(std::time::Duration::from_millis(500));
    group.measurement_time(std::time::Duration::from_secs(2));
    let params = BakeParams { rays: 4, ..BakeParams::default() };
    let pool = pool(1);
    for valence in [2_500, 5_000, 10_000, 20_000] {
        let cone = fan(FanShape::ClosedCone, valence);
        group.throughput(Throughput::Elements(cone.triangle_count() as u64));
        group.bench_function(format!("{:.1}k", valence as f64 / 1000.0), |b| {
            b.iter_batched(|| (), |_| pool.install(|| bake_mesh(&cone, &params, &[]).unwrap()), BatchSize::PerIteration)
        });
    }
    group.finish();
}

/// A texel bake (atlas made once, outside the timing), 2 threads.
fn texels(c: &mut Criterion) {
    use prtbake::atlas::Atlas;
    use prtbake::bake::surfaces::Surfaces;
    let mesh = prtbake::verify::shapes::room_with_walls_running_past();
    let scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
    let surfaces = Surfaces::resolve(&mesh, &[]).unwrap();
    let atlas = Atlas::unwrap(&mesh, 0.05).unwrap();
    let params = BakeParams { order: 3, rays: 32, bounces: 3, quiet: true, ..BakeParams::default() };
    let pool = pool(2);
    let bake = || pool.install(|| prtbake::bake::texels::bake_texels(&mesh, &scene, &surfaces, &params, atlas.clone(), 4).unwrap());
    let (_, probe) = bake();
    let mut group = c.benchmark_group("bake/texels");
    group.sample_size(10);
    group.throughput(Throughput::Elements(probe.rays));
    group.bench_function(format!("room_5cm_4points_3bounces_{}texels_2t", probe.texels.len()), |b| {
        b.iter_batched(|| (), |_| bake(), BatchSize::PerIteration)
    });
    group.finish();
}

criterion_group!(bake_benches, benches, cone_valence, texels);
criterion_main!(bake_benches);
