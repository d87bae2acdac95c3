//! The demo's panel images (docs/panel.md "Demo"): the driver's view of the
//! LCD under a low sun placed where the panel mirrors it toward the eye, and
//! under an overcast sky.

use std::path::{Path, PathBuf};

use glam::Vec3;
use serde_json::json;

use super::bake_cmd::BakeReport;
use super::panel_cmd::{gather_panel, run_json, stage_images};
use crate::brdf::{Brdf, PanelBrdf};
use crate::bundle::{Bundle, LayerKind, Quantization, Transfer, TransferLayer};
use crate::files::Staged;
use crate::mesh::Mesh;
use crate::panel::{Display, Environment};
use crate::sky::{Site, TYPICAL_OVERCAST_LUX};

/// The driver's eye in the demo cabin: above the front-left seat.
pub const DRIVER_EYE: Vec3 = Vec3::new(-0.42, 1.15, -0.4);
/// Texels and samples of the demo's panel images: 128 × 64 texels at 256 samples each.
const TEXELS: (u32, u32) = (128, 64);
const SAMPLES: u32 = 256;

/// (name, EXR, PNG) of each demo panel image.
pub fn paths(dir: &Path) -> Vec<(&'static str, PathBuf, PathBuf)> {
    ["sunny", "overcast"]
        .into_iter()
        .map(|name| (name, dir.join(format!("panel-{name}.exr")), dir.join(format!("panel-{name}.cr.png"))))
        .collect()
}

/// The date's local time (5-minute steps, 06:00–12:00) whose sun elevation is
/// nearest `elevation_deg`, and the sun's world direction then.
fn morning_sun_at(elevation_deg: f64) -> (u32, Vec3, f64) {
    let site = Site::acropolis();
    let date = crate::sky::default_date();
    let tz = crate::sky::athens_utc_offset_minutes(date);
    let at = |minutes: u32| {
        let time = crate::sky::unix_time(date, f64::from(minutes), tz);
        crate::sky::solar_position(&site, time, crate::sky::DEFAULT_DELTA_T_S)
    };
    let minutes = (72..=144)
        .map(|k| k * 5)
        .min_by(|&a, &b| (at(a).elevation_deg - elevation_deg).abs().total_cmp(&(at(b).elevation_deg - elevation_deg).abs()));
    let minutes = minutes.unwrap_or(510);
    let position = at(minutes);
    (minutes, crate::sky::sun_direction(&position, crate::sky::default_north(Vec3::Y), Vec3::Y), position.elevation_deg)
}

/// The yaw (whole degrees) that turns the sun where the panel's BRDF sends
/// the most of it toward the eye from the panel centre: the glare heading.
fn glare_yaw(sun_world: Vec3, centre: Vec3, normal: Vec3, brdf: &PanelBrdf) -> f32 {
    let (t, b) = crate::bake::sampling::tangent_frame(normal);
    let local = |d: Vec3| Vec3::new(d.dot(t), d.dot(b), d.dot(normal));
    let wo = local((DRIVER_EYE - centre).normalize());
    let glare = |yaw: u32| {
        let sun_car = glam::Mat3::from_rotation_y((yaw as f32).to_radians()).transpose() * sun_world;
        let wi = local(sun_car);
        brdf.eval(wi, wo)[1] * wi.z.max(0.0)
    };
    (0..360).max_by(|&a, &b| glare(a).total_cmp(&glare(b))).unwrap_or(0) as f32
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
    let layout = crate::panel::PanelLayout::new(mesh, &triangles, 2, 1, &report.output)?;
    // The mirror direction of the eye at the panel centre gives the sun height to look for.
    let wo = (DRIVER_EYE - layout.centre).normalize();
    let mirror = 2.0 * wo.dot(layout.front) * layout.front - wo;
    let (minutes, sun_world, elevation) = morning_sun_at(f64::from(mirror.y.asin().to_degrees()));
    let yaw = glare_yaw(sun_world, layout.centre, layout.front, &brdf);
    let sunny = Environment::clear_sky(sun_world, crate::sky::DEFAULT_TURBIDITY, yaw)
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
            entry["command"] = json!(format!(
                "prtbake panel demo-out/cabin.prtb --panel lcd_panel --eye=-0.42,1.15,-0.4 --sky --time {:02}:{:02} --yaw {yaw} --texels 128x64 --samples 256 -o panel-sunny.exr",
                minutes / 60,
                minutes % 60
            ));
        } else {
            entry["command"] = json!("prtbake panel demo-out/cabin.prtb --panel lcd_panel --eye=-0.42,1.15,-0.4 --overcast --texels 128x64 --samples 256 -o panel-overcast.exr");
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
