//! How bake time and error scale with rays per sample, window mode with
//! bounces, against a high-ray reference bake of the same scene.
//!
//! cargo run --release --example ray_scaling -- [MESH|cabin] [--window PATTERN] [--detail D]
//!     [--bounces B] [--reference RAYS] [--max RAYS] [--window-sampling] [--same-points]
//!
//! The error is the RMS over vertices of the total DC coefficient minus the
//! reference's (seed 2), relative to the reference's mean DC; printed as a
//! Markdown table. With `--same-points` the reference keeps the bakes'
//! sample positions (point seed 1) and differs only in its rays, so the
//! error is the ray noise alone; without it, it also holds the error of
//! where the samples sit.

use prtbake::bake::{bake_mesh, BakeParams, Mode};
use prtbake::fixtures::cabin::generate_cabin;
use prtbake::mesh::{load_mesh, LoadOptions};

fn arg<T: std::str::FromStr>(args: &[String], name: &str, default: T) -> T {
    args.iter().position(|a| a == name).and_then(|i| args.get(i + 1)).and_then(|v| v.parse().ok()).unwrap_or(default)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let source = args.first().filter(|a| !a.starts_with("--")).cloned().unwrap_or_else(|| "cabin".into());
    let window: String = arg(&args, "--window", "glass".to_string());
    let detail: f32 = arg(&args, "--detail", 24.0);
    let bounces: u32 = arg(&args, "--bounces", 2);
    let reference_rays: u32 = arg(&args, "--reference", 4096);
    let max_rays: u32 = arg(&args, "--max", 4096);
    let window_sampling = args.iter().any(|a| a == "--window-sampling");
    let same_points = args.iter().any(|a| a == "--same-points");
    let mesh = if source == "cabin" {
        generate_cabin(detail).0
    } else {
        load_mesh(source.as_ref(), &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}")).mesh
    };
    let windows = vec![window];
    let bake = |rays: u32, seed: u32, window_sampling: bool| {
        let point_seed = if same_points { Some(1) } else { None };
        let params = BakeParams { order: 3, rays, seed, point_seed, bounces, mode: Mode::Window, window_sampling, ..BakeParams::default() };
        bake_mesh(&mesh, &params, &windows).unwrap().0
    };
    let reference = bake(reference_rays, 2, false);
    let channels = reference.channels;
    let dc = |r: &prtbake::bake::TransferResult, v: usize| r.coefficients(v, 0)[0] as f64;
    let lit: Vec<usize> = (0..mesh.vertex_count()).filter(|&v| dc(&reference, v) > 0.0).collect();
    let mean = lit.iter().map(|&v| dc(&reference, v)).sum::<f64>() / lit.len().max(1) as f64;
    println!(
        "{source}: {} triangles, {} vertices, {} channel(s), {bounces} bounces, reference {reference_rays} rays (seed 2, {} points)",
        mesh.triangle_count(),
        mesh.vertex_count(),
        channels,
        if same_points { "the same" } else { "its own" }
    );
    println!("| rays per sample | seconds | Mrays/s | relative RMS DC error |");
    println!("|---|---|---|---|");
    let mut rays = 64;
    while rays <= max_rays {
        let r = bake(rays, 1, window_sampling);
        let err = (lit.iter().map(|&v| (dc(&r, v) - dc(&reference, v)).powi(2)).sum::<f64>() / lit.len().max(1) as f64).sqrt() / mean;
        println!("| {rays} | {:.2} | {:.2} | {:.4} |", r.stats.seconds, r.stats.rays_per_second / 1e6, err);
        rays *= 4;
    }
}
