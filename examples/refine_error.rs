//! Total error of bundles of different refinements of one surface, as
//! docs/refinement.md reports it ((a) as cleaned, (b) uniform
//! `--max-edge`, (c) `--refine`).
//!
//! cargo run --release --example refine_error -- REFERENCE.prtb BUNDLE.prtb… [--points N]
//!
//! Points spread uniformly by area over the reference mesh's non-window
//! triangles are found on every bundle's mesh, and each bundle's values are
//! interpolated there as the viewer's Gouraud shading does.
//! - **Transfer:** shaded under the twelve reference skies
//!   (`budget::reference_lightings`); the relative RMS against the
//!   reference bundle's interpolated shading, the mean and the largest over
//!   the skies. The reference should be a dense refinement baked with more
//!   rays: what is left of its own noise adds to every row alike.
//! - **Sun masks:** the interpolated bits against a per-point reference shadow
//!   (a ray from each point toward each day step's sun in the reference
//!   mesh: open mode, escapes and the face turned to the sun; window mode,
//!   the first hit is glass, leaving from a side of the point that is not
//!   outside the enclosure, the bake's rule), the mean absolute difference over points and
//!   day steps: the fraction of the surface drawn wrong, on average over the day.
//!
//! A bundle with sun bits per texel (TSUN) is drawn from them, bilinearly
//! over its atlas as the viewer reads them.
//!
//! With `BY_MATERIAL=1`, stderr also splits the sun-mask disagreement (and
//! the drawn and reference lit fractions) by the reference mesh's material.

use glam::Vec3;
use prtbake::bake::{SunMasks, Surfaces};
use prtbake::bundle::{read_bundle, Bundle};
use prtbake::refine::probe::{
    interpolate, interpolate_masks, locate, outside_sides, reference_sun, reference_sun_window, Located, SurfacePoint,
};
use prtbake::trace::{BuildQuality, Scene};

fn load(path: &str) -> Bundle {
    read_bundle(path.as_ref()).unwrap_or_else(|e| panic!("{path}: {e}"))
}

fn located_on(bundle: &Bundle, points: &[SurfacePoint], reach: f32) -> Vec<Option<Located>> {
    let scene = Scene::build(&bundle.mesh, BuildQuality::Sah).expect("scene");
    locate(&scene, points, reach)
}

/// Shading under every reference sky at the points: `[sky][point] rgb`.
fn shaded(bundle: &Bundle, located: &[Option<Located>]) -> Vec<Vec<[f64; 3]>> {
    let transfer = bundle.transfer.as_ref().expect("a transfer section");
    let (order, channels) = (transfer.order as usize, transfer.channels as usize);
    let stride = transfer.values_per_vertex() as usize;
    let rows = interpolate(&bundle.mesh, &transfer.total(), stride, located);
    prtbake::bundle::budget::reference_lightings(order)
        .iter()
        .map(|sky| prtbake::bundle::budget::shade(&rows, order, channels, &sky.sh))
        .collect()
}

/// The texels' sun bits as the viewer draws them (`lightmap.wgsl`): at each
/// point's atlas position, bilinear between texel centres over the texels
/// that hold light (with texel transfer, a non-zero row; without, every
/// covered texel), else the texel under it. `[point][step]`.
fn texel_masks_at(texels: &prtbake::bundle::TexelLayers, series: &prtbake::bundle::SunSeries, located: &[Option<Located>]) -> Vec<f32> {
    let steps = series.step_count();
    let atlas = &texels.atlas;
    let stride = texels.transfer.as_ref().map_or(0, |t| t.values_per_vertex() as usize);
    let total = texels.transfer.as_ref().map(|t| t.total());
    let holds = |i: usize| total.as_ref().is_none_or(|t| t[i * stride..(i + 1) * stride].iter().any(|&x| x != 0.0));
    let index = |x: i64, y: i64| -> Option<usize> {
        (x >= 0 && y >= 0 && x < atlas.width as i64 && y < atlas.height as i64)
            .then(|| texels.texels.binary_search(&((y * atlas.width as i64 + x) as u32)).ok())
            .flatten()
    };
    let mut out = vec![0.0f32; located.len() * steps];
    for (p, l) in located.iter().enumerate() {
        let Some(l) = l else { continue };
        let uv = atlas.triangle_uv(l.triangle as usize);
        let q = uv[0] * l.barycentrics[0] + uv[1] * l.barycentrics[1] + uv[2] * l.barycentrics[2] - glam::Vec2::splat(0.5);
        let (x0, y0) = (q.x.floor() as i64, q.y.floor() as i64);
        let (fx, fy) = (q.x - q.x.floor(), q.y - q.y.floor());
        let mut taps = Vec::with_capacity(4);
        for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            let w = if dx == 1 { fx } else { 1.0 - fx } * if dy == 1 { fy } else { 1.0 - fy };
            if let Some(i) = index(x0 + dx, y0 + dy).filter(|&i| holds(i)) {
                taps.push((i, w));
            }
        }
        let total: f32 = taps.iter().map(|t| t.1).sum();
        if total <= 1e-6 {
            taps = index((q.x + 0.5).floor() as i64, (q.y + 0.5).floor() as i64).map(|i| vec![(i, 1.0)]).unwrap_or_default();
        }
        let total: f32 = taps.iter().map(|t| t.1).sum::<f32>().max(1e-12);
        for k in 0..steps {
            out[p * steps + k] = taps.iter().map(|&(i, w)| w * series.texel_sun(i, k)).sum::<f32>() / total;
        }
    }
    out
}

fn window_mode(bundle: &Bundle) -> bool {
    let mode = |key: &str| bundle.meta.pointer(key).and_then(|m| m.as_str()).map(str::to_string);
    mode("/sun/params/mode").or_else(|| mode("/params/mode")).is_some_and(|m| m == "window")
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut count = 50_000usize;
    if let Some(i) = args.iter().position(|a| a == "--points") {
        count = args.get(i + 1).and_then(|n| n.parse().ok()).expect("--points N");
        args.drain(i..i + 2);
    }
    let Some((reference_path, others)) = args.split_first().filter(|(_, o)| !o.is_empty()) else {
        eprintln!("usage: refine_error REFERENCE.prtb BUNDLE.prtb… [--points N]");
        std::process::exit(2);
    };
    let reference = load(reference_path);
    let patterns: Vec<String> = ["/sun/window_patterns", "/window_patterns"]
        .iter()
        .find_map(|k| reference.meta.pointer(k).and_then(|v| v.as_array()))
        .map(|a| a.iter().filter_map(|p| p.as_str().map(str::to_string)).collect())
        .unwrap_or_default();
    let surfaces = Surfaces::resolve(&reference.mesh, &patterns).expect("surfaces");
    let opaque = |t: usize| surfaces.window_transmittance[t].is_none();
    let points = prtbake::refine::probe::surface_points(&reference.mesh, count, 1, opaque);
    let reach = 1e-5 * reference.mesh.diagonal();
    let reference_located = located_on(&reference, &points, reach);
    let found = reference_located.iter().filter(|l| l.is_some()).count();
    println!("reference {reference_path}: {} vertices; {found} of {count} points found", reference.mesh.vertex_count());

    let want = reference.transfer.as_ref().map(|_| shaded(&reference, &reference_located));
    // Sun reference: one ray per point and day step in the reference mesh.
    let sun_reference = reference.sun.as_ref().map(|series| {
        let scene = Scene::build(&reference.mesh, BuildQuality::Sah).expect("scene");
        let window = window_mode(&reference);
        let suns: Vec<Vec3> = series.steps.iter().map(|s| if s.night { Vec3::ZERO } else { Vec3::from(s.direction) }).collect();
        // Window mode draws light through glass only on a side of a point that
        // is not outside the enclosure, as the bake does (unless it kept them).
        let keep_outside_sides = reference.meta.pointer("/sun/params/keep_outside_sides").and_then(|v| v.as_bool()).unwrap_or(false);
        let outside = if window { outside_sides(&scene, &surfaces, &points, keep_outside_sides) } else { Vec::new() };
        let lit: Vec<Vec<f32>> = suns
            .iter()
            .map(|&sun| {
                if sun == Vec3::ZERO {
                    vec![0.0; points.len()]
                } else if window {
                    reference_sun_window(&scene, &surfaces, &points, &outside, sun)
                } else {
                    reference_sun(&scene, &points, sun)
                }
            })
            .collect();
        (suns, lit)
    });

    println!("| bundle | vertices | transfer error, mean over skies | largest | sun-mask disagreement |");
    println!("|---|---:|---:|---:|---:|");
    for path in others {
        let bundle = load(path);
        let located = located_on(&bundle, &points, reach);
        let both: Vec<usize> = (0..points.len()).filter(|&p| located[p].is_some() && reference_located[p].is_some()).collect();
        let transfer = match (&want, &bundle.transfer) {
            (Some(want), Some(_)) => {
                let got = shaded(&bundle, &located);
                let errors: Vec<f64> = want
                    .iter()
                    .zip(&got)
                    .map(|(w, g)| {
                        let w: Vec<[f64; 3]> = both.iter().map(|&p| w[p]).collect();
                        let g: Vec<[f64; 3]> = both.iter().map(|&p| g[p]).collect();
                        prtbake::bundle::budget::relative_rms(&w, &g)
                    })
                    .collect();
                let mean = errors.iter().sum::<f64>() / errors.len() as f64;
                let max = errors.iter().copied().fold(0.0, f64::max);
                (format!("{mean:.4}"), format!("{max:.4}"))
            }
            _ => ("-".into(), "-".into()),
        };
        let sun = match (&sun_reference, &bundle.sun) {
            (Some((suns, lit)), Some(series)) => {
                let drawn = match &bundle.texels {
                    Some(texels) if !series.texel_masks.is_empty() => texel_masks_at(texels, series, &located),
                    _ => {
                        let masks =
                            SunMasks { words_per_vertex: series.words_per_vertex, masks: series.masks.clone(), stats: Default::default() };
                        interpolate_masks(&bundle.mesh, &masks, suns.len(), &located)
                    }
                };
                let (mut sum, mut drawn_sum, mut lit_sum) = (0.0f64, 0.0f64, 0.0f64);
                for &p in &both {
                    for k in 0..suns.len() {
                        sum += (drawn[p * suns.len() + k] - lit[k][p]).abs() as f64;
                        drawn_sum += drawn[p * suns.len() + k] as f64;
                        lit_sum += lit[k][p] as f64;
                    }
                }
                let n = (both.len() * suns.len()).max(1) as f64;
                if std::env::var_os("BY_MATERIAL").is_some() {
                    let mut per = vec![[0.0f64; 3]; reference.mesh.materials.len()];
                    for &p in &both {
                        let t = reference_located[p].map_or(0, |l| l.triangle as usize);
                        let m = &mut per[reference.mesh.tri_material[t] as usize];
                        for k in 0..suns.len() {
                            m[0] += (drawn[p * suns.len() + k] - lit[k][p]).abs() as f64 / n;
                            m[1] += drawn[p * suns.len() + k] as f64 / n;
                            m[2] += lit[k][p] as f64 / n;
                        }
                    }
                    for (m, e) in per.iter().enumerate().filter(|(_, e)| e[0] > 1e-4) {
                        eprintln!("  {path}: {} {:.4} (drawn {:.4}, reference {:.4})", reference.mesh.materials[m].name, e[0], e[1], e[2]);
                    }
                }
                format!("{:.4} (lit: drawn {:.4}, reference {:.4})", sum / n, drawn_sum / n, lit_sum / n)
            }
            _ => "-".into(),
        };
        println!("| {path} | {} | {} | {} | {sun} |", bundle.mesh.vertex_count(), transfer.0, transfer.1);
    }
}
