//! Measures ray throughput of the tracing layer on the workload the baker
//! issues (rays from triangle sample points, cosine-distributed over the
//! sphere), and optionally exports the exact rays for `benches/embree_compare.py`.
//!
//! cargo run --release --example trace_rate -- [MESH|cabin] [--rays-per-point N] [--points N]
//!     [--threads T] [--runs R] [--export DIR] [--build sah|ploc] [--portable] [--share G] [--sort]
//!     [--compare-batching] [--rays LOG]
//!
//! `--rays LOG` traces instead the rays a bake logged (`PRTBAKE_LOG_RAYS`,
//! `prtbake::trace::ray_log`), each with the query it was traced with, in
//! the logged batches of one point's rays, and prints the seconds.
//! `--share G` and `--sort` reorder the workload to measure coherence
//! (docs/performance.md); the baker does neither.
//! Prints min / median / max Mrays/s over R runs for occlusion and closest
//! hit, each traced a point's rays per call, run the way the scene chose
//! when it was built (one by one or interleaved; `--compare-batching` times both).

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use glam::Vec3;
use prtbake::fixtures::cabin::generate_cabin;
use prtbake::mesh::{load_mesh, LoadOptions, Mesh};
use prtbake::sampling;
use prtbake::trace::{BatchMode, Batching, BuildQuality, RayQuery, Scene};
use rayon::prelude::*;

fn arg<T: std::str::FromStr>(args: &[String], name: &str, default: T) -> T {
    args.iter().position(|a| a == name).and_then(|i| args.get(i + 1)).and_then(|v| v.parse().ok()).unwrap_or(default)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let source = args.first().filter(|a| !a.starts_with("--")).cloned().unwrap_or_else(|| "cabin".into());
    let rays_per_point: u32 = arg(&args, "--rays-per-point", 64);
    let points: u32 = arg(&args, "--points", 16384);
    let threads: usize = arg(&args, "--threads", 1);
    let runs: usize = arg(&args, "--runs", 3);
    let export: Option<PathBuf> = args.iter().position(|a| a == "--export").and_then(|i| args.get(i + 1)).map(PathBuf::from);

    let mesh: Mesh = if source == "cabin" {
        generate_cabin(80.0).0
    } else {
        load_mesh(source.as_ref(), &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}")).mesh
    };
    let start = Instant::now();
    let quality = if arg(&args, "--build", "sah".to_string()) == "ploc" { BuildQuality::Ploc } else { BuildQuality::Sah };
    let mut scene = Scene::build(&mesh, quality).unwrap();
    if args.iter().any(|a| a == "--portable") {
        scene.set_traversal(prtbake::trace::Traversal::Portable);
    }
    let build = start.elapsed().as_secs_f64();
    if let Some(log) = args.iter().position(|a| a == "--rays").and_then(|i| args.get(i + 1)) {
        if let Some(dir) = &export {
            export_triangles(&mesh, dir);
        }
        return trace_logged(&scene, log, threads, runs, build);
    }

    // Sample points: centroids of an even spread of triangles, in mesh order.
    // `--share G`: G consecutive points use one direction set (the first
    // point's) and their rays go direction-major, a measure of what sharing
    // directions between neighbours would buy (1: every point its own set).
    // `--sort`: each set in Morton order of its Sobol pairs.
    let share: u32 = arg(&args, "--share", 1).max(1);
    let sort = args.iter().any(|a| a == "--sort");
    let step = (mesh.triangle_count() as u32 / points).max(1);
    let mut rays: Vec<(Vec3, Vec3)> = Vec::new();
    for group in (0..points).step_by(share as usize) {
        let members: Vec<(Vec3, Vec3)> = (group..(group + share).min(points))
            .filter_map(|p| {
                let t = ((p * step) as usize).min(mesh.triangle_count() - 1);
                let n = scene.face_normal(t as u32);
                let [a, b, c] = mesh.triangle_positions(t);
                (n != Vec3::ZERO).then_some(((a + b + c) / 3.0, n))
            })
            .collect();
        let mut pairs: Vec<(f32, f32)> =
            (0..rays_per_point).map(|k| sampling::sample_2d(sampling::DirectionPattern::Sobol, k, 0, group)).collect();
        if sort {
            pairs.sort_by_key(|&(u1, u2)| morton_key(u1, u2));
        }
        for &(u1, u2) in &pairs {
            for &(centroid, n) in &members {
                let d = sampling::cosine_sphere(n, u1, u2);
                rays.push((scene.offset_origin(centroid, n, d), d));
            }
        }
    }
    let queries: Vec<RayQuery> = rays.iter().map(|&(origin, direction)| RayQuery { origin, direction, t_max: f32::INFINITY }).collect();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    // Each batch is one point's rays, as the baker traces them.
    let batch = rays_per_point as usize;
    let measure = |name: &str, f: &(dyn Fn(&[RayQuery]) -> usize + Sync)| {
        let mut rates: Vec<f64> = (0..runs)
            .map(|_| {
                let t = Instant::now();
                let hits: usize =
                    pool.install(|| queries.par_chunks(batch * (4096 / batch).max(1)).map(|c| c.chunks(batch).map(f).sum::<usize>()).sum());
                std::hint::black_box(hits);
                rays.len() as f64 / t.elapsed().as_secs_f64() / 1e6
            })
            .collect();
        rates.sort_by(f64::total_cmp);
        println!(
            "{name:<12} {threads} thread(s): min {:.3}  median {:.3}  max {:.3} Mrays/s",
            rates[0],
            rates[rates.len() / 2],
            rates[rates.len() - 1]
        );
    };
    println!(
        "{source}: {} triangles, {quality:?} BVH build {:.3}s, {:?} traversal, {:?}, {} rays ({} points x {})",
        mesh.triangle_count(),
        build,
        scene.traversal(),
        scene.batching(),
        rays.len(),
        rays.len() as u32 / rays_per_point,
        rays_per_point
    );
    measure("occlusion", &|q| occluded_count(&scene, q));
    measure("closest_hit", &|q| hit_count(&scene, q));
    // `--compare-batching`: both ways of running a batch, whichever the scene chose.
    if args.iter().any(|a| a == "--compare-batching") {
        for mode in [BatchMode::OneByOne, BatchMode::Interleaved] {
            let mut forced = Scene::build(&mesh, quality).unwrap();
            forced.set_traversal(scene.traversal());
            forced.set_batching(Batching { closest_hit: mode, occlusion: mode });
            measure(&format!("occlusion {mode:?}"), &|q| occluded_count(&forced, q));
            measure(&format!("closest_hit {mode:?}"), &|q| hit_count(&forced, q));
        }
    }

    if let Some(dir) = export {
        export_triangles(&mesh, &dir);
        let mut r = std::io::BufWriter::new(std::fs::File::create(dir.join("rays.f32")).unwrap());
        for (o, d) in &rays {
            r.write_all(bytemuck_vec3(*o).as_slice()).unwrap();
            r.write_all(bytemuck_vec3(*d).as_slice()).unwrap();
        }
        println!("exported {} triangles and {} rays to {}", mesh.triangle_count(), rays.len(), dir.display());
    }
}

/// Rays of a batch that hit something (closest hit through the batch API).
fn hit_count(scene: &Scene, queries: &[RayQuery]) -> usize {
    let mut out = vec![None; queries.len()];
    scene.closest_hits(queries, &mut out);
    out.iter().filter(|h| h.is_some()).count()
}

/// Rays of a batch that are blocked (occlusion through the batch API).
fn occluded_count(scene: &Scene, queries: &[RayQuery]) -> usize {
    let mut out = vec![false; queries.len()];
    scene.occluded_each(queries, &mut out);
    out.iter().filter(|&&o| o).count()
}

/// Writes the mesh's triangles for `benches/embree_compare.py` (9 f32 each).
fn export_triangles(mesh: &Mesh, dir: &std::path::Path) {
    std::fs::create_dir_all(dir).unwrap();
    let mut tris = std::io::BufWriter::new(std::fs::File::create(dir.join("triangles.f32")).unwrap());
    for t in 0..mesh.triangle_count() {
        for p in mesh.triangle_positions(t) {
            tris.write_all(bytemuck_vec3(p).as_slice()).unwrap();
        }
    }
}

/// Traces a bake's logged rays, each batch (a point's consecutive rays of
/// one query, at most 64) through the batch API, on `threads` threads.
fn trace_logged(scene: &Scene, log: &str, threads: usize, runs: usize, build: f64) {
    use prtbake::trace::ray_log::{decode, LoggedQuery};
    let bytes = std::fs::read(log).unwrap_or_else(|e| panic!("{log}: {e}"));
    let rays = decode(&bytes).unwrap_or_else(|| panic!("{log}: not a ray log (whole 32-byte records)"));
    let mut batches: Vec<(LoggedQuery, Vec<RayQuery>)> = Vec::new();
    for (query, kind) in rays.iter().copied() {
        match batches.last_mut() {
            Some((k, batch)) if *k == kind && batch.len() < 64 => batch.push(query),
            _ => batches.push((kind, vec![query])),
        }
    }
    let closest = rays.iter().filter(|r| r.1 == LoggedQuery::ClosestHit).count();
    println!(
        "{log}: {} rays ({closest} closest hit, {} occlusion) in {} batches; BVH build {build:.3}s, {:?}",
        rays.len(),
        rays.len() - closest,
        batches.len(),
        scene.batching()
    );
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    // Each query's batches in one parallel pass, so each gets its own time.
    for kind in [LoggedQuery::ClosestHit, LoggedQuery::Occlusion] {
        let of_kind: Vec<&Vec<RayQuery>> = batches.iter().filter(|(k, _)| *k == kind).map(|(_, q)| q).collect();
        let count: usize = of_kind.iter().map(|q| q.len()).sum();
        if count == 0 {
            continue;
        }
        let mut seconds: Vec<f64> = (0..runs)
            .map(|_| {
                let t = Instant::now();
                let hits: usize = pool.install(|| {
                    of_kind
                        .par_chunks(64)
                        .map(|chunk| {
                            chunk
                                .iter()
                                .map(|q| match kind {
                                    LoggedQuery::ClosestHit => hit_count(scene, q),
                                    LoggedQuery::Occlusion => occluded_count(scene, q),
                                })
                                .sum::<usize>()
                        })
                        .sum()
                });
                std::hint::black_box(hits);
                t.elapsed().as_secs_f64()
            })
            .collect();
        seconds.sort_by(f64::total_cmp);
        let median = seconds[seconds.len() / 2];
        println!(
            "logged {:<11} {threads} thread(s): {count} rays, min {:.3}  median {:.3}  max {:.3} s, {:.3} Mrays/s (median)",
            format!("{kind:?}"),
            seconds[0],
            median,
            seconds[seconds.len() - 1],
            count as f64 / median / 1e6
        );
    }
}

/// Morton (Z-order) key of a point of the unit square, 16 bits per axis:
/// neighbouring keys are neighbouring pairs, so neighbouring directions.
fn morton_key(u1: f32, u2: f32) -> u64 {
    let spread = |x: f32| {
        let mut v = (x * 65535.0) as u64;
        v = (v | v << 16) & 0x0000_ffff_0000_ffff;
        v = (v | v << 8) & 0x00ff_00ff_00ff_00ff;
        v = (v | v << 4) & 0x0f0f_0f0f_0f0f_0f0f;
        v = (v | v << 2) & 0x3333_3333_3333_3333;
        (v | v << 1) & 0x5555_5555_5555_5555
    };
    spread(u1) << 1 | spread(u2)
}

fn bytemuck_vec3(v: Vec3) -> Vec<u8> {
    [v.x, v.y, v.z].iter().flat_map(|x| x.to_le_bytes()).collect()
}
