//! The viewer's first progressive panel image (target: the first
//! progressive image in the viewer in ≤ 0.25 s of CPU on 2 cores): one pass at the
//! viewer's first-pass settings (`view::panel`: 128 texels along the long side,
//! 2 samples per texel) on the demo cabin's LCD from the driver's eye, on a
//! 2-thread pool, as the viewer restarts it when the eye moves: the interior's
//! PRT light for the frame's lighting, the pass, and the texture. The BVH is
//! built once when the viewer starts and is not timed.
//!
//! Criterion's time here is the process's CPU time (user + system, all
//! threads: `CLOCK_PROCESS_CPUTIME_ID`), not wall time; on other systems it
//! falls back to wall time.
//!
//! Run: `cargo bench --bench panel_view`.

use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use glam::Vec3;
use prtbake::bundle::{Bundle, LayerKind, Quantization, Transfer, TransferLayer};
use prtbake::fixtures::cabin::generate_cabin;
use prtbake::view::panel::{PanelMapping, PanelRequest, PanelSource};
use prtbake::view::{Backdrop, FrameSettings, LayerSelection, ToneMap};

#[cfg(unix)]
fn cpu_time() -> Duration {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: a valid clock id and a valid out pointer.
    unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut t) };
    Duration::new(t.tv_sec as u64, t.tv_nsec as u32)
}

#[cfg(not(unix))]
fn cpu_time() -> Duration {
    use std::sync::OnceLock;
    static START: OnceLock<std::time::Instant> = OnceLock::new();
    START.get_or_init(std::time::Instant::now).elapsed()
}

fn first_pass(c: &mut Criterion) {
    let (raw, _) = generate_cabin(64.0);
    let (mesh, _) = prtbake::clean::clean_mesh(&raw, &prtbake::clean::CleanParams::cad()).unwrap();
    // Transfer values change the texture, not the work: a constant order-3 RGB transfer.
    let order = 3u32;
    let data = vec![0.05f32; mesh.vertex_count() * 3 * 9];
    let layers = vec![TransferLayer { kind: LayerKind::Total, data }];
    let transfer = Transfer { order, channels: 3, quantization: Quantization::F32, layers, front_share: Vec::new() };
    let bundle =
        Bundle { meta: serde_json::json!({ "params": { "mode": "window" } }), mesh, transfer: Some(transfer), sun: None, texels: None };
    let mapping = PanelMapping::find(&bundle.mesh, Some("lcd_panel"), None, "cabin".as_ref()).unwrap().unwrap();
    let mut source = PanelSource::new(&bundle, &mapping, None).unwrap();
    // The viewer's default sky (no map, no time lapse), turned as the demo's sunny panel.
    let (sh, sky) = prtbake::view::lighting::default_sky(order as usize);
    let rotation = prtbake::view::lighting::car_to_env_rotation(274.0, 0.0, 0.0);
    let lighting = prtbake::view::lighting::rotate_sh(&sh, order as usize, rotation);
    // Without the sun disc (the default sky) and with it (a time-lapse step with the sun term on: one more ray per sample, plus shadow rays).
    let sun_irradiance = prtbake::sky::preetham_sky(sky.sun, Vec3::Y, f64::from(sky.turbidity), 1).sun_rgb_irradiance;
    let cases =
        [("first_pass_2_threads_cpu_time", None), ("first_pass_sun_2_threads_cpu_time", Some(sun_irradiance))].map(|(name, sun)| {
            let backdrop = Backdrop::Sky(prtbake::view::SkyBackdrop { rotation, sun_irradiance: sun, ..sky });
            (name, FrameSettings { lighting: lighting.clone(), sun_step: None, backdrop, tonemap: ToneMap::default() })
        });
    let eye = Vec3::new(-0.42, 1.15, -0.4);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    eprintln!("{}x{} texels, {} on the panel", mapping.layout.width, mapping.layout.height, mapping.layout.covered());
    let mut group = c.benchmark_group("panel_view");
    group.sample_size(20);
    for (name, settings) in &cases {
        group.bench_function(*name, |b| {
            b.iter_custom(|iterations| {
                let mut total = Duration::ZERO;
                for k in 0..iterations {
                    // A new eye each time, as when the camera moves.
                    let request = PanelRequest::new(eye + Vec3::X * (k % 7) as f32 * 1e-3, settings, &LayerSelection::Total, k);
                    let started = cpu_time();
                    pool.install(|| source.gather(&request, 1, |texture| texture.samples > 0));
                    total += cpu_time() - started;
                }
                total
            })
        });
    }
    group.finish();
}

criterion_group!(benches, first_pass);
criterion_main!(benches);
