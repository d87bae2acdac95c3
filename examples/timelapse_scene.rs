//! A small time-lapse bundle for the viewer until `prtbake sun` lands: a
//! colonnade and a sphere on a ground plane, transfer baked in open mode,
//! and the Parthenon demo's day (92 steps, 06:57–17:34 every 7 min, Athens,
//! 2026-03-20) with exact per-vertex sun bits (ray toward the sun through the
//! baker's BVH), sun colour and the Preetham sky SH per step.
//!
//! ```sh
//! cargo run --release --example timelapse_scene -- demo-out/colonnade.prtb
//! cargo run --release -- view demo-out/colonnade.prtb --time 09:00
//! ```

use std::path::PathBuf;

use glam::Vec3;
use prtbake::bake::{bake_mesh, BakeParams, BuildQuality, Scene};
use prtbake::bundle::{write_bundle, SunSeries, SunStep};
use prtbake::fixtures::builder::MeshBuilder;
use prtbake::mesh::Material;
use prtbake::sky;
use prtbake::verify::shapes;

fn main() -> anyhow::Result<()> {
    let output = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| "demo-out/colonnade.prtb".into()));
    if let Some(dir) = output.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }

    // Ground, two rows of columns under an architrave, a sphere.
    let marble = |name: &str, a: [f32; 3]| Material { albedo: a, ..Material::opaque(name, 0.0) };
    let mut b = MeshBuilder::new(vec![marble("ground", [0.45, 0.42, 0.36]), marble("marble", [0.75, 0.72, 0.66])]);
    let (ground, stone) = (b.material("ground"), b.material("marble"));
    b.grid("ground", Vec3::new(-7.0, 0.0, -7.0), Vec3::Z * 14.0, Vec3::X * 14.0, 140, 140, |_, _| ground);
    for row in [-1.2f32, 1.2] {
        for k in 0..6 {
            let x = -3.0 + 1.2 * k as f32;
            b.cuboid(&format!("column{row}{k}"), Vec3::new(x - 0.18, 0.0, row - 0.18), Vec3::new(x + 0.18, 2.6, row + 0.18), 12.0, stone);
        }
    }
    b.cuboid("architrave", Vec3::new(-3.5, 2.6, -1.6), Vec3::new(3.5, 3.0, 1.6), 8.0, stone);
    let mut mesh = b.mesh;
    let mut sphere = shapes::icosphere(4);
    sphere.materials[0] = marble("sphere", [0.7, 0.3, 0.2]);
    shapes::transform(&mut sphere, 0.8, Vec3::new(0.0, 0.8, 3.6));
    shapes::append(&mut mesh, &sphere);
    eprintln!("scene: {} triangles, {} vertices", mesh.triangle_count(), mesh.vertex_count());

    // Transfer (sky light, with interreflection) and the BVH for sun rays.
    let params = BakeParams { order: 3, rays: 128, bounces: 1, quiet: false, ..BakeParams::default() };
    let (result, _, _) = bake_mesh(&mesh, &params, &[])?;
    let scene = Scene::build(&mesh, BuildQuality::Medium);

    // The day: sun direction, colour and sky per step; bits by tracing toward the sun.
    let site = sky::Site::acropolis();
    let (north, up) = (Vec3::NEG_Z, Vec3::Y);
    let order = params.order;
    let steps: Vec<SunStep> = sky::default_timeline()
        .steps
        .iter()
        .map(|&t| {
            let position = sky::solar_position(&site, t, sky::DEFAULT_DELTA_T_S);
            let direction = sky::sun_direction(&position, north, up);
            let sun_sky = sky::preetham_sky(direction, up, 3.0, order);
            SunStep {
                unix_time_utc: t,
                direction: direction.to_array(),
                elevation_deg: position.elevation_deg as f32,
                azimuth_deg: position.azimuth_deg as f32,
                sun_rgb: sun_sky.sun_rgb_irradiance,
                night: sun_sky.night,
                sky_sh: sun_sky.sky_sh,
            }
        })
        .collect();
    let (words_per_vertex, masks) = SunSeries::pack(steps.len(), mesh.vertex_count(), |v, k| {
        let s = Vec3::from_array(steps[k].direction);
        let n = mesh.normals[v];
        !steps[k].night && n.dot(s) > 0.0 && !scene.occluded(scene.offset_origin(mesh.positions[v], n, s), s, f32::INFINITY)
    });
    let mut bundle = prtbake::cli::bake_cmd::make_bundle(&mesh, &result, &params, serde_json::json!({ "source": "examples/timelapse_scene.rs" }));
    bundle.sun = Some(SunSeries { sky_order: order as u32, steps, words_per_vertex, masks });
    write_bundle(&output, &bundle)?;
    eprintln!("wrote {}", output.display());
    Ok(())
}
