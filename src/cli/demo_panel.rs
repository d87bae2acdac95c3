//! The demo's panel images (docs/panel.md "Demo"): the driver's view of the
//! LCD under a low sun placed, by time and car heading, where the panel's
//! coating sends the most sunlight through the glass toward the eye, and
//! under an overcast sky.

use std::path::{Path, PathBuf};

use glam::Vec3;
use rayon::prelude::*;
use serde_json::json;

use super::bake_cmd::BakeReport;
use super::panel_cmd::{gather_panel, run_json, stage_images};
use crate::bake::Surfaces;
use crate::brdf::{Brdf, PanelBrdf};
use crate::bundle::{Bundle, LayerKind, Quantization, Transfer, TransferLayer};
use crate::files::Staged;
use crate::fixtures::cabin::DRIVER_EYE;
use crate::mesh::Mesh;
use crate::panel::{Display, Environment, Interior, PanelLayout};
use crate::sky::{Site, TYPICAL_OVERCAST_LUX};
use crate::trace::{BuildQuality, Scene};

/// Texels and samples of the demo's panel images: 128 × 64 texels at 256 samples each.
const TEXELS: (u32, u32) = (128, 64);
const SAMPLES: u32 = 256;
/// Probe points of the glare search: texel centres of an 8 × 4 grid over the panel.
const PROBES: (u32, u32) = (8, 4);
/// The lowest sun the glare search takes, degrees: clear of the horizon's
/// haze and of hills, where a clear-sky sun is still a glare source.
const MIN_SUN_ELEVATION_DEG: f64 = 4.0;

/// (name, EXR, PNG) of each demo panel image.
pub fn paths(dir: &Path) -> Vec<(&'static str, PathBuf, PathBuf)> {
    ["sunny", "overcast"]
        .into_iter()
        .map(|name| (name, dir.join(format!("panel-{name}.exr")), dir.join(format!("panel-{name}.cr.png"))))
        .collect()
}

/// A low sun and the car's heading under it.
struct Glare {
    /// Local time, minutes after midnight.
    minutes: u32,
    /// World direction toward the sun, and its elevation in degrees.
    sun_world: Vec3,
    elevation_deg: f64,
    /// Car yaw, whole degrees.
    yaw: u32,
    /// `Σ_p f cos θ τ` over the probe points, 1/sr.
    score: f32,
}

/// The sun at each local time of the demo date (5-minute steps, 06:00–12:00)
/// at least [`MIN_SUN_ELEVATION_DEG`] up: (minutes, world direction, elevation).
fn morning_suns() -> Vec<(u32, Vec3, f64)> {
    let site = Site::acropolis();
    let date = crate::sky::default_date();
    let tz = crate::sky::athens_utc_offset_minutes(date);
    (72..=144)
        .map(|k| k * 5)
        .filter_map(|minutes| {
            let time = crate::sky::unix_time(date, f64::from(minutes), tz);
            let position = crate::sky::solar_position(&site, time, crate::sky::DEFAULT_DELTA_T_S);
            let direction = crate::sky::sun_direction(&position, crate::sky::default_north(Vec3::Y), Vec3::Y);
            (position.elevation_deg >= MIN_SUN_ELEVATION_DEG).then_some((minutes, direction, position.elevation_deg))
        })
        .collect()
}

/// The glare heading: over the morning's suns and every whole-degree yaw,
/// the one that maximises `Σ_p f(sun, eye) cos θ_sun τ(p → sun)` over the
/// probe points `p` of the panel, with `τ` the glass transmittance of a
/// shadow ray toward the sun (0 when the car's body or a seat blocks it).
/// The mirror direction alone is not enough: from a centre-stack display it
/// may meet the roof or a seat, and the sun then glares only where the
/// coating's lobe reaches a window. The first maximum in (time, yaw) order
/// wins, so the choice is the same at any thread count.
fn glare_heading(interior: &Interior, probes: &PanelLayout, brdf: &PanelBrdf) -> Option<Glare> {
    let points: Vec<(Vec3, Vec3, Vec3, Vec3, Vec3)> = (0..probes.texel_count())
        .filter(|&i| probes.triangle[i] != crate::panel::layout::NO_TRIANGLE)
        .map(|i| {
            let (p, n) = (probes.point[i], probes.normal[i]);
            let (t, b) = crate::sampling::tangent_frame(n);
            (p, n, t, b, (DRIVER_EYE - p).normalize())
        })
        .collect();
    let suns = morning_suns();
    let score = |&(_, sun_world, _): &(u32, Vec3, f64), yaw: u32| -> f32 {
        let sun = crate::panel::environment::yaw_rotation(yaw as f32).transpose() * sun_world;
        points
            .iter()
            .map(|&(p, n, t, b, eye)| {
                let local = |d: Vec3| Vec3::new(d.dot(t), d.dot(b), d.dot(n));
                let (wi, wo) = (local(sun), local(eye));
                let reflected = brdf.eval(wi, wo)[1] * wi.z.max(0.0);
                if reflected <= 0.0 {
                    return 0.0;
                }
                reflected * interior.sky_transmittance(p, n, sun).0
            })
            .sum()
    };
    let scores: Vec<f32> = (0..suns.len() * 360).into_par_iter().map(|k| score(&suns[k / 360], (k % 360) as u32)).collect();
    let mut best: Option<(usize, f32)> = None;
    for (k, &s) in scores.iter().enumerate() {
        if s > 0.0 && best.is_none_or(|(_, b)| s > b) {
            best = Some((k, s));
        }
    }
    best.map(|(k, score)| {
        let (minutes, sun_world, elevation_deg) = suns[k / 360];
        Glare { minutes, sun_world, elevation_deg, yaw: (k % 360) as u32, score }
    })
}

/// Gathers both panels from the demo's bake and stages their images; returns their JSON.
pub fn run(
    mesh: &Mesh,
    report: &BakeReport,
    paths: &[(&'static str, PathBuf, PathBuf)],
    quiet: bool,
    staged: &mut Staged,
) -> anyhow::Result<serde_json::Value> {
    let result = &report.result;
    let bundle = Bundle {
        meta: json!({ "params": { "mode": "window" } }),
        mesh: mesh.clone(),
        transfer: Some(Transfer {
            order: result.order as u32,
            channels: result.channels as u32,
            quantization: Quantization::F32,
            layers: vec![TransferLayer { kind: LayerKind::Total, data: result.total.clone() }],
        }),
        sun: None,
    };
    let brdf = PanelBrdf::default();
    let display = Display::default();
    let triangles = crate::panel::select_panel(mesh, Some("lcd_panel"), &report.output)?;
    let probes = PanelLayout::new(mesh, &triangles, PROBES.0, PROBES.1, &report.output)?;
    let surfaces = Surfaces::resolve(mesh, &[])?;
    let scene = Scene::build(mesh, BuildQuality::Sah)?;
    let interior = Interior { scene: &scene, mesh, surfaces: &surfaces, vertex_light: Vec::new(), two_sided: true };
    let glare = glare_heading(&interior, &probes, &brdf)
        .ok_or_else(|| anyhow::anyhow!("demo: no morning sun reaches the panel through a window at any heading"))?;
    let Glare { minutes, sun_world, elevation_deg: elevation, yaw, score } = glare;
    let sunny = Environment::clear_sky(sun_world, crate::sky::DEFAULT_TURBIDITY, yaw as f32)
        .ok_or_else(|| anyhow::anyhow!("demo: the chosen sun is below the horizon"))?;
    let overcast = Environment::overcast(TYPICAL_OVERCAST_LUX);
    let mut out = serde_json::Map::new();
    for ((name, exr, png), env) in paths.iter().zip([&sunny, &overcast]) {
        let mut run = gather_panel(
            &bundle,
            &report.output,
            Some("lcd_panel"),
            DRIVER_EYE,
            env,
            &brdf,
            Some(TEXELS),
            SAMPLES,
            1,
            display,
            3.0,
            quiet,
        )?;
        run.brdf = "antiglare".into();
        stage_images(&run, exr, png, display, staged)?;
        let mut entry = run_json(&run, exr, png, display, SAMPLES);
        entry["eye"] = json!(DRIVER_EYE.to_array());
        if *name == "sunny" {
            entry["local_time"] = json!(format!("{:02}:{:02}", minutes / 60, minutes % 60));
            entry["date"] = json!("2026-03-20");
            entry["sun_elevation_deg"] = json!(elevation);
            entry["yaw_deg"] = json!(yaw);
            // What the glare search maximised: Σ_p f cos θ τ over its probe points (1/sr).
            entry["glare_score"] = json!(score);
            // How far the chosen sun is from the eye's mirror direction at the panel centre.
            let sun_car = sunny.sun.map_or(Vec3::Y, |sun| sun.direction);
            let wo = (DRIVER_EYE - probes.centre).normalize();
            let mirror = crate::brdf::frame::reflect(wo, probes.front);
            entry["sun_direction_car"] = json!(sun_car.to_array());
            entry["sun_from_mirror_deg"] = json!(sun_car.dot(mirror).clamp(-1.0, 1.0).acos().to_degrees());
            entry["command"] = json!(format!(
                "prtbake panel demo-out/cabin.prtb --panel lcd_panel --eye={} --sky --time {:02}:{:02} --yaw {yaw} --texels 128x64 --samples 256 -o panel-sunny.exr",
                eye_arg(),
                minutes / 60,
                minutes % 60
            ));
        } else {
            entry["command"] = json!(format!(
                "prtbake panel demo-out/cabin.prtb --panel lcd_panel --eye={} --overcast --texels 128x64 --samples 256 -o panel-overcast.exr",
                eye_arg()
            ));
        }
        if !quiet {
            let r = &run.readability;
            eprintln!(
                "panel {name}: contrast ratio min {:.2}, median {:.2}, {:.0}% below 3:1 ({:.1} s)",
                r.min_contrast_ratio,
                r.median_contrast_ratio,
                100.0 * r.fraction_below_threshold,
                run.seconds
            );
        }
        out.insert(name.to_string(), entry);
    }
    Ok(serde_json::Value::Object(out))
}

/// `DRIVER_EYE` as `--eye` takes it.
fn eye_arg() -> String {
    format!("{},{},{}", DRIVER_EYE.x, DRIVER_EYE.y, DRIVER_EYE.z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::MaterialRole;

    fn search(mesh: &Mesh) -> Option<(Glare, PanelLayout)> {
        let triangles = crate::panel::select_panel(mesh, Some("lcd_panel"), "cabin".as_ref()).unwrap();
        let probes = PanelLayout::new(mesh, &triangles, PROBES.0, PROBES.1, "cabin".as_ref()).unwrap();
        let surfaces = Surfaces::resolve(mesh, &[]).unwrap();
        let scene = Scene::build(mesh, BuildQuality::Sah).unwrap();
        let interior = Interior { scene: &scene, mesh, surfaces: &surfaces, vertex_light: Vec::new(), two_sided: true };
        glare_heading(&interior, &probes, &PanelBrdf::default()).map(|glare| (glare, probes))
    }

    /// In the cabin the eye's mirror direction at the panel centre leaves
    /// through the rear window, so the search lands the sun on it (within the
    /// 5-minute and 1° steps); with the glass made opaque next to no sun reaches the panel.
    #[test]
    fn glare_search_finds_the_sun_in_the_mirror_direction_and_next_to_none_without_windows() {
        // Cleaned as the demo does: the raw cabin's roof crack lets sunlight through.
        let (raw, _) = crate::fixtures::cabin::generate_cabin(24.0);
        let (mut mesh, _) = crate::clean::clean_mesh(&raw, &crate::clean::CleanParams::cad()).unwrap();
        let (glare, probes) = search(&mesh).expect("a glare heading");
        let sun_car = crate::panel::environment::yaw_rotation(glare.yaw as f32).transpose() * glare.sun_world;
        let mirror = crate::brdf::frame::reflect((DRIVER_EYE - probes.centre).normalize(), probes.front);
        let degrees = sun_car.dot(mirror).clamp(-1.0, 1.0).acos().to_degrees();
        assert!(degrees < 1.5, "sun {degrees:.2}° from the mirror direction (yaw {}, {} min)", glare.yaw, glare.minutes);
        assert!(glare.elevation_deg >= MIN_SUN_ELEVATION_DEG);
        mesh.materials.iter_mut().filter(|m| m.role == MaterialRole::Window).for_each(|m| m.role = MaterialRole::Opaque);
        // Not exactly zero: at its best heading some shadow ray still leaves
        // the glassless cabin (0.23 % of the glazed score, 2026-11-24; where
        // it escapes is not traced down), so this is a bound.
        let leak = search(&mesh).map_or(0.0, |(g, _)| g.score);
        assert!(leak < 1e-2 * glare.score, "without windows {leak} against {}", glare.score);
    }
}
