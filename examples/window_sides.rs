//! How much of a window-mode bake's light reaches surfaces from both sides.
//!
//! Window mode's transfer is side-blind: a point's rays cover the whole
//! sphere (∝ |n·ω|), and the light through glass from either side is summed
//! into one transfer, which the viewer shows on both sides. Right for a
//! surface whose back lies inside a closed solid (its back rays meet the
//! solid, not glass); wrong for a single sheet that glass lights from both
//! sides, or from one side while the camera sees the other.
//!
//! Per triangle (its centroid, the two hemispheres of its face normal), the
//! cosine-weighted fraction of rays whose first hit is glass, on each side;
//! printed: the area with glass light on both sides, and there the weaker
//! sides' light against the stronger sides'.
//!
//! cargo run --release --example window_sides -- MESH --window PATTERN [--rays N] [--threads T]

use glam::Vec3;
use prtbake::bake::Surfaces;
use prtbake::mesh::{load_mesh, LoadOptions};
use prtbake::trace::{BuildQuality, Scene};
use rayon::prelude::*;

fn arg<T: std::str::FromStr>(args: &[String], name: &str, default: T) -> T {
    args.iter().position(|a| a == name).and_then(|i| args.get(i + 1)).and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// Fraction of `rays` cosine-distributed directions about `n` from `point`
/// whose first hit is glass (a window of transmittance > 0).
fn glass_fraction(scene: &Scene, surfaces: &Surfaces, point: Vec3, n: Vec3, rays: u32, seed: u32) -> f32 {
    let (t, b) = n.any_orthonormal_pair();
    let origin = scene.offset_origin(point, n, n);
    let mut through = 0u32;
    for k in 0..rays {
        let (u, v) = prtbake::sampling::sample_2d(prtbake::sampling::DirectionPattern::Sobol, k, 0, seed);
        // Malley: a uniform disk point lifted to the hemisphere.
        let (r, phi) = (u.sqrt(), 2.0 * std::f32::consts::PI * v);
        let d = (t * (r * phi.cos()) + b * (r * phi.sin()) + n * (1.0 - u).max(0.0).sqrt()).normalize();
        let glass = scene
            .closest_hit(origin, d, f32::INFINITY)
            .is_some_and(|hit| surfaces.window_transmittance[hit.triangle as usize].is_some_and(|tau| tau > 0.0));
        through += u32::from(glass);
    }
    through as f32 / rays as f32
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args.first().filter(|a| !a.starts_with("--")).expect("usage: window_sides MESH --window PATTERN [--rays N]");
    let window: String = arg(&args, "--window", "glass".to_string());
    let rays: u32 = arg(&args, "--rays", 128);
    let threads: usize = arg(&args, "--threads", 2);
    rayon::ThreadPoolBuilder::new().num_threads(threads).build_global().unwrap();
    let mesh = load_mesh(path.as_ref(), &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}")).mesh;
    let surfaces = Surfaces::resolve(&mesh, &[window]).unwrap();
    let scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
    // Per opaque triangle: area, and the glass fraction of its front and back.
    let sides: Vec<(f32, f32, f32)> = (0..mesh.triangle_count())
        .into_par_iter()
        .filter(|&t| surfaces.window_transmittance[t].is_none())
        .map(|t| {
            let [a, b, c] = mesh.triangle_positions(t);
            let cross = (b - a).cross(c - a);
            let area = 0.5 * cross.length();
            if area <= 0.0 {
                return (0.0, 0.0, 0.0);
            }
            let (n, centre) = (cross.normalize(), (a + b + c) / 3.0);
            let front = glass_fraction(&scene, &surfaces, centre, n, rays, 2 * t as u32);
            let back = glass_fraction(&scene, &surfaces, centre, -n, rays, 2 * t as u32 + 1);
            (area, front, back)
        })
        .collect();
    let total_area: f64 = sides.iter().map(|s| s.0 as f64).sum();
    let lit: f64 = sides.iter().filter(|s| s.1.max(s.2) > 0.0).map(|s| s.0 as f64).sum();
    let both: f64 = sides.iter().filter(|s| s.1.min(s.2) >= 0.05 * s.1.max(s.2) && s.1.max(s.2) > 0.0).map(|s| s.0 as f64).sum();
    // Where both sides are lit, the viewer shows front + back on each: the
    // brighter side too bright by min/max, the dimmer by max/min.
    let two_sided = sides.iter().filter(|s| s.1.min(s.2) >= 0.05 * s.1.max(s.2) && s.1.max(s.2) > 0.0);
    let (weak, strong) = two_sided.fold((0.0f64, 0.0f64), |(w, st), s| (w + (s.0 * s.1.min(s.2)) as f64, st + (s.0 * s.1.max(s.2)) as f64));
    println!(
        "{}: {} opaque triangles, {:.3} m²; {:.1}% of it lit through glass; {:.1}% lit on both sides (the weaker side ≥ 5% of the stronger)",
        path,
        sides.len(),
        total_area,
        100.0 * lit / total_area,
        100.0 * both / total_area + 0.0
    );
    println!(
        "on those, the weaker sides' glass light is {:.1}% of the stronger sides' (area-weighted): each side shows both",
        100.0 * weak / strong.max(1e-30) + 0.0
    );
}
