//! Panel final-gather speed (docs/panel.md): a 400 × 300-texel gather of the
//! demo cabin's LCD (the size seed 000 §3.1 names) at 40 samples per texel
//! (the paper's rough image) and at 256, from the driver's eye under the
//! demo's low sun (MIS: one BRDF ray and one sun-disk ray per sample, plus
//! shadow rays toward the sun from lit interior hits). Criterion's
//! elements/s are the gather's rays/s (BRDF and disk rays). The interior's
//! PRT light is a constant here: it changes the values, not the rays.
//!
//! A third case times the tracer alone on the gather's own first rays
//! (`first_rays_alone_spp40`), the raw rate the gather is measured against.
//!
//! Run: `cargo bench --bench panel` (one case: `cargo bench --bench panel -- spp40`);
//! ten images per case, 16 min in all on two shared cores (docs/panel.md "Speed").

use criterion::{criterion_group, criterion_main, Criterion, SamplingMode, Throughput};
use prtbake::bake::Surfaces;
use prtbake::brdf::PanelBrdf;
use prtbake::fixtures::cabin::{generate_cabin, DRIVER_EYE};
use prtbake::panel::{select_panel, Environment, GatherOptions, Interior, PanelGather, PanelLayout};
use prtbake::trace::{BuildQuality, RayQuery, Scene};
use rayon::prelude::*;

fn panel_gather(c: &mut Criterion) {
    let (raw, _) = generate_cabin(64.0);
    let (mesh, _) = prtbake::clean::clean_mesh(&raw, &prtbake::clean::CleanParams::cad()).unwrap();
    let surfaces = Surfaces::resolve(&mesh, &[]).unwrap();
    let scene = Scene::build(&mesh, BuildQuality::Sah).unwrap();
    let interior = Interior {
        scene: &scene,
        mesh: &mesh,
        surfaces: &surfaces,
        vertex_light: vec![[100.0; 3]; mesh.vertex_count()],
        two_sided: true,
        texel_light: None,
        side_shares: Default::default(),
    };
    let triangles = select_panel(&mesh, Some("lcd_panel"), "cabin".as_ref()).unwrap();
    let layout = PanelLayout::new(&mesh, &triangles, 400, 300, "cabin".as_ref()).unwrap();
    let eye = DRIVER_EYE;
    // The glare case: the sun in the eye's mirror direction at the panel centre
    // (6° up, straight back through the rear window; docs/panel.md).
    let wo = (eye - layout.centre).normalize();
    let mirror = prtbake::brdf::frame::reflect(wo, layout.front);
    let env = Environment::clear_sky(mirror, 3.0, 0.0).unwrap();
    let brdf = PanelBrdf::default();
    let mut group = c.benchmark_group("panel_400x300");
    // Ten timed images each, one per sample (flat sampling): criterion's
    // default linear sampling would time 1 + 2 + … + 10 = 55 images, which at
    // 256 samples per texel is most of an hour on two cores.
    group.sample_size(10).sampling_mode(SamplingMode::Flat);
    for samples in [40u32, 256] {
        let (rays, queries) = {
            let mut g = PanelGather::new(&interior, &env, &brdf, &layout, eye, GatherOptions::default());
            g.refine(samples);
            (g.rays(), g.queries())
        };
        eprintln!("{} texels on the panel, {samples} samples: {rays} rays, {queries} queries traced", layout.covered());
        group.throughput(Throughput::Elements(rays));
        group.bench_function(format!("spp{samples}"), |b| {
            b.iter(|| {
                let mut g = PanelGather::new(&interior, &env, &brdf, &layout, eye, GatherOptions::default());
                g.refine(samples);
                g.rays()
            })
        });
    }
    // The tracer alone on the gather's own first rays (its BRDF draws, 40
    // samples per texel), each texel's as one batch as the gather traces
    // them: the raw rate the gather's rays/s is measured against. The
    // gather also traces continuations through glass, sun-disk rays and
    // shadow rays, and samples and evaluates the BRDF.
    let gather = PanelGather::new(&interior, &env, &brdf, &layout, eye, GatherOptions::default());
    let batches: Vec<Vec<RayQuery>> = (0..layout.texel_count()).map(|texel| gather.first_rays(texel, 0..40)).collect();
    let first_rays: u64 = batches.iter().map(|b| b.len() as u64).sum();
    eprintln!("the first rays of 40 samples: {first_rays}");
    group.throughput(Throughput::Elements(first_rays));
    group.bench_function("first_rays_alone_spp40", |b| {
        b.iter(|| {
            batches
                .par_iter()
                .map(|rays| {
                    let mut hits = vec![None; rays.len()];
                    scene.closest_hits(rays, &mut hits);
                    hits.iter().filter(|h| h.is_some()).count() as u64
                })
                .sum::<u64>()
        })
    });
    group.finish();
}

criterion_group!(benches, panel_gather);
criterion_main!(benches);
