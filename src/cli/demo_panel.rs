//! The demo's panel images (docs/panel.md "Demo"): the driver's view of the
//! LCD under a low sun placed, by time and car heading, where the panel's
//! coating sends the most sunlight through the glass toward the eye, and
//! under an overcast sky.

use std::path::{Path, PathBuf};

use glam::Vec3;
use serde_json::json;

use super::bake_cmd::BakeReport;
use super::panel_cmd::{gather_panel, run_json, stage_images};
use crate::bake::Surfaces;
use crate::brdf::PanelBrdf;
use crate::bundle::{Bundle, LayerKind, Quantization, Transfer, TransferLayer};
use crate::files::Staged;
use crate::fixtures::cabin::DRIVER_EYE;
use crate::mesh::Mesh;
use crate::panel::glare::{glare_heading, Glare, PROBES};
use crate::panel::{Display, Environment, Interior, PanelLayout};
use crate::sky::TYPICAL_OVERCAST_LUX;
use crate::trace::{BuildQuality, Scene};

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
            front_share: Vec::new(),
        }),
        sun: None,
        texels: None,
    };
    let brdf = PanelBrdf::default();
    let display = Display::default();
    let triangles = crate::panel::select_panel(mesh, Some("lcd_panel"), &report.output)?;
    let probes = PanelLayout::new(mesh, &triangles, PROBES.0, PROBES.1, &report.output)?;
    let surfaces = Surfaces::resolve(mesh, &[])?;
    let scene = Scene::build(mesh, BuildQuality::Sah)?;
    let interior = Interior::unlit(&scene, mesh, &surfaces);
    let glare = glare_heading(&interior, &probes, &brdf, DRIVER_EYE)
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
