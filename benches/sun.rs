//! Sun-mask speed: the default day (92 steps) over a colonnade of more than a
//! million vertices, in rays per second (criterion reports elements/s = rays/s).
//!
//! Configurations: step-outer in packets with the shadow cache (the
//! default), step-outer one ray at a time with the shadow cache and without
//! it, point-outer with it. Set `PRTBAKE_BENCH_DETAIL=monument` for the
//! 400k-vertex colonnade (quicker).
//!
//! Run: `cargo bench --bench sun` (one configuration: `cargo bench --bench sun -- step_outer_packets`).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use prtbake::bake::{bake_sun_masks, LoopOrder, SunParams, Surfaces};
use prtbake::fixtures::colonnade::{colonnade, ColonnadeParams};
use prtbake::sky::{self, SkyFrame};
use prtbake::trace::{BuildQuality, Scene};

fn sun_masks(c: &mut Criterion) {
    let params = match std::env::var("PRTBAKE_BENCH_DETAIL").as_deref() {
        Ok("monument") => ColonnadeParams::monument(),
        _ => ColonnadeParams::million(),
    };
    let mesh = colonnade(&params);
    let surfaces = Surfaces::resolve(&mesh, &[]).unwrap();
    let scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
    let frame = SkyFrame { north: sky::default_north(glam::Vec3::Y), up: glam::Vec3::Y, turbidity: 3.0, sky_order: 0 };
    let steps = sky::day_steps(&sky::Site::acropolis(), &sky::default_timeline(), sky::DEFAULT_DELTA_T_S, &frame);
    let suns = sky::day_directions(&steps);
    let configs = [
        ("step_outer_packets", LoopOrder::StepOuter, true, true),
        ("step_outer_cached", LoopOrder::StepOuter, true, false),
        ("step_outer_uncached", LoopOrder::StepOuter, false, false),
        ("point_outer_cached", LoopOrder::PointOuter, true, false),
    ];
    // Rays are the same in every configuration: count them once.
    let rays = bake_sun_masks(&mesh, &scene, &surfaces, &suns, &SunParams::default()).unwrap().stats.rays;
    eprintln!("{} vertices, {} triangles, {} steps, {rays} rays per bake", mesh.vertex_count(), mesh.triangle_count(), suns.len());
    let mut group = c.benchmark_group(format!("sun_masks_{}v_92steps", mesh.vertex_count()));
    group.sample_size(10);
    group.throughput(Throughput::Elements(rays));
    for (name, loop_order, shadow_cache, packets) in configs {
        let p = SunParams { loop_order, shadow_cache, packets, ..SunParams::default() };
        group.bench_function(name, |b| b.iter(|| bake_sun_masks(&mesh, &scene, &surfaces, &suns, &p).unwrap()));
    }
    group.finish();
}

criterion_group!(benches, sun_masks);
criterion_main!(benches);
