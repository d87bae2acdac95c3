//! Grey SH lighting from an environment map, and each bundle's per-vertex
//! shading under it: what benches/cycles_compare.py compares with Cycles.
//!
//! cargo run --release --example sh_shade -- ENV.exr ORDER OUT_DIR [BUNDLE.prtb…]
//!
//! Writes OUT_DIR/lighting.json: `{"order", "coefficients", "lift"}`, the
//! map's SH projection (docs/conventions.md "Environment maps") averaged over
//! RGB, as prtbake's one-channel bakes average albedo, plus the uniform light
//! `lift` (added to DC) that raises its minimum over the sphere to zero: an
//! order-3 projection of a sky with a sun rings negative below the horizon,
//! and a renderer cannot emit negative light. For each bundle, writes
//! OUT_DIR/<bundle stem>.shade.f32: per vertex (little-endian f32) the
//! shaded radiance per unit albedo `Σ_i L_i t_i` of channel 0's total
//! transfer; and OUT_DIR/<stem>.positions.f32 (x, y, z per vertex) for the
//! first bundle, so the comparison can check it shades the same vertices.

use std::path::Path;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 3 {
        eprintln!("usage: sh_shade ENV.exr ORDER OUT_DIR [BUNDLE.prtb…]");
        std::process::exit(2);
    }
    let order: usize = args[1].parse().unwrap_or_else(|_| panic!("ORDER {}: expected a number", args[1]));
    let out_dir = Path::new(&args[2]);
    std::fs::create_dir_all(out_dir).unwrap_or_else(|e| panic!("{}: {e}", out_dir.display()));
    let image = prtbake::sh::load_equirect(args[0].as_ref()).unwrap_or_else(|e| panic!("{e}"));
    let rgb = prtbake::sh::project_equirect(&image, order);
    let mut grey: Vec<f64> = rgb.iter().map(|c| (c[0] as f64 + c[1] as f64 + c[2] as f64) / 3.0).collect();
    // The minimum over a fine grid of directions (the function is smooth at order ≤ 4).
    let mut basis = vec![0.0f64; grey.len()];
    let mut lowest = f64::INFINITY;
    for row in 0..512 {
        for col in 0..1024 {
            let direction = prtbake::sh::equirect_direction((col as f64 + 0.5) / 1024.0, (row as f64 + 0.5) / 512.0);
            prtbake::sh::eval_basis_f64(order, direction, &mut basis);
            lowest = lowest.min(grey.iter().zip(&basis).map(|(l, y)| l * y).sum());
        }
    }
    let lift = (-lowest).max(0.0);
    // y_00 = 1/√(4π): a uniform light `lift` has L_00 = lift·√(4π).
    grey[0] += lift * (4.0 * std::f64::consts::PI).sqrt();
    let lighting = serde_json::json!({ "order": order, "coefficients": grey, "lift": lift, "minimum_before_lift": lowest });
    let write = |name: String, bytes: &[u8]| {
        let path = out_dir.join(name);
        prtbake::files::atomic::write_atomic(&path, bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    };
    write("lighting.json".into(), lighting.to_string().as_bytes());
    for (k, path) in args[3..].iter().enumerate() {
        let bundle = prtbake::bundle::read_bundle(path.as_ref()).unwrap_or_else(|e| panic!("{e}"));
        let transfer = bundle.transfer.unwrap_or_else(|| panic!("{path}: no transfer section"));
        assert!(transfer.order as usize >= order, "{path}: order {} below the lighting's {order}", transfer.order);
        let coeffs = (transfer.order * transfer.order) as usize;
        let stride = transfer.values_per_vertex() as usize;
        let shade: Vec<u8> = transfer
            .total()
            .chunks_exact(stride)
            .flat_map(|v| {
                let s: f64 = grey.iter().zip(&v[..coeffs]).map(|(l, &t)| l * t as f64).sum();
                (s as f32).to_le_bytes()
            })
            .collect();
        let stem = Path::new(path).file_stem().unwrap().to_string_lossy().into_owned();
        write(format!("{stem}.shade.f32"), &shade);
        if k == 0 {
            let positions: Vec<u8> = bundle.mesh.positions.iter().flat_map(|p| p.to_array()).flat_map(f32::to_le_bytes).collect();
            write(format!("{stem}.positions.f32"), &positions);
        }
    }
}
