//! A time-lapse step's light as equirect maps, for a path tracer to render
//! what `prtbake view --step K` shows (benches/pathtracer_compare.py --step).
//!
//! cargo run --release --example sky_env -- BUNDLE.prtb STEP ORDER SH.exr FULL.exr [WIDTH]
//!
//! - SH.exr: the step's sky SH fitted to ORDER (the bundle's transfer order),
//!   expanded in prtbake's own basis: the sky light the viewer applies;
//! - FULL.exr: the Preetham sky itself at the step's sun (META
//!   `sun.turbidity`, `sun.up`), without the sun's disc;
//! - stdout: the step's sun as JSON, `{"direction": [x,y,z], "sun_rgb": [r,g,b], "night": bool}`
//!   (toward the sun, world frame; irradiance on a surface facing it).
//!
//! Both maps use prtbake's equirect convention (`sh::equirect_direction`),
//! WIDTH × WIDTH/2 texels (default 512), linear RGB.

use glam::Vec3;
use prtbake::bundle::read_bundle;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 5 {
        eprintln!("usage: sky_env BUNDLE.prtb STEP ORDER SH.exr FULL.exr [WIDTH]");
        std::process::exit(2);
    }
    let bundle = read_bundle(args[0].as_ref()).unwrap_or_else(|e| panic!("{e}"));
    let series = bundle.sun.as_ref().expect("the bundle has no time lapse (run `prtbake sun` on it)");
    let step: usize = args[1].parse().expect("STEP");
    let order: usize = args[2].parse().expect("ORDER");
    let width: usize = args.get(5).map_or(512, |w| w.parse().expect("WIDTH"));
    let height = width / 2;
    let s = series.steps.get(step).unwrap_or_else(|| panic!("step {step} of {}", series.steps.len()));
    // The viewer's lighting: the stored sky SH fitted to the transfer's order.
    let n2 = order * order;
    let sh: Vec<[f32; 3]> = (0..n2).map(|i| s.sky_sh.get(i).copied().unwrap_or([0.0; 3])).collect();
    let turbidity = bundle.meta.pointer("/sun/turbidity").and_then(|t| t.as_f64()).unwrap_or(3.0);
    let up = bundle.meta.pointer("/sun/up").and_then(|u| serde_json::from_value::<[f32; 3]>(u.clone()).ok()).map_or(Vec3::Y, Vec3::from);
    let sun = Vec3::from(s.direction);
    let sky = if s.night { None } else { prtbake::sky::preetham::PreethamSky::new(sun.as_dvec3(), up.as_dvec3(), turbidity) };
    let mut basis = vec![0.0f32; n2];
    let mut sh_map = vec![(0.0f32, 0.0f32, 0.0f32); width * height];
    let mut full_map = vec![(0.0f32, 0.0f32, 0.0f32); width * height];
    for y in 0..height {
        for x in 0..width {
            let d = prtbake::sh::equirect_direction((x as f64 + 0.5) / width as f64, (y as f64 + 0.5) / height as f64);
            prtbake::sh::eval_basis(order, d.as_vec3(), &mut basis);
            let mut c = [0.0f32; 3];
            for (b, l) in basis.iter().zip(&sh) {
                (0..3).for_each(|k| c[k] += b * l[k]);
            }
            sh_map[y * width + x] = (c[0], c[1], c[2]);
            if let Some(sky) = &sky {
                let r = sky.radiance_rgb(d);
                full_map[y * width + x] = (r[0] as f32, r[1] as f32, r[2] as f32);
            }
        }
    }
    for (path, map) in [(&args[3], &sh_map), (&args[4], &full_map)] {
        exr::prelude::write_rgb_file(path, width, height, |x, y| map[y * width + x]).unwrap_or_else(|e| panic!("{path}: {e}"));
    }
    println!("{}", serde_json::json!({ "direction": s.direction, "sun_rgb": s.sun_rgb, "night": s.night }));
}
