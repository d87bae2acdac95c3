//! prtbake's per-vertex values against an independent path tracer on the
//! same quantity (benches/mitsuba_probe.py: Mitsuba 3's hat-weighted
//! one-ring mean of the DC transfer).
//!
//! ```text
//! cargo run --release --example probe_rings -- rings MESH OUT.csv [--random N] [--free SIZE] [--seed S]
//! cargo run --release --example probe_rings -- compare BUNDLE.prtb REFERENCE.csv…
//! ```
//!
//! `rings` writes the one-ring file the probe reads (`--rings`), in
//! prtbake's vertex order and frame, with the corners' normals: every
//! triangle that is sampled (not a window, not of zero area) around each
//! chosen vertex. `--random N` takes N vertices at random (seeded); `--free
//! SIZE` only vertices whose one-ring lies within SIZE of them (small rings,
//! where a vertex's mean and the surface at the vertex agree).
//!
//! `compare` reads each reference CSV (`id,dc_mean,dc_stderr,…`) and the
//! bundle's total transfer (channel 0, DC), and prints per file: the
//! vertices compared, the relative RMS difference `√(Σ(p−m)²/Σm²)`, the
//! reference's own noise on the same scale `√(Σσ²/Σm²)`, and the mean ratio
//! `Σp/Σm`.

use std::collections::HashSet;
use std::path::Path;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("rings") => rings(&args[1..]),
        Some("compare") => compare(&args[1..]),
        _ => Err("usage: probe_rings rings MESH OUT.csv [--random N] [--free SIZE] [--seed S] | compare BUNDLE REFERENCE.csv…".into()),
    };
    if let Err(e) = result {
        eprintln!("error: {e}");
        std::process::exit(2);
    }
}

fn flag(args: &[String], name: &str) -> Option<String> {
    args.windows(2).find(|w| w[0] == name).map(|w| w[1].clone())
}

fn rings(args: &[String]) -> Result<(), String> {
    let (mesh_path, out) = match args {
        [m, o, ..] => (Path::new(m), Path::new(o)),
        _ => return Err("rings MESH OUT.csv".into()),
    };
    let mesh = prtbake::mesh::load_mesh(mesh_path, &prtbake::mesh::LoadOptions::default()).map_err(|e| e.to_string())?.mesh;
    let surfaces = prtbake::bake::Surfaces::resolve(&mesh, &[]).map_err(|e| e.to_string())?;
    let seed: u64 = flag(args, "--seed").map_or(Ok(1), |s| s.parse()).map_err(|e| format!("--seed: {e}"))?;
    let free: Option<f32> = flag(args, "--free").map(|s| s.parse()).transpose().map_err(|e| format!("--free: {e}"))?;
    let random: Option<usize> = flag(args, "--random").map(|s| s.parse()).transpose().map_err(|e| format!("--random: {e}"))?;
    // One-rings of sampled triangles.
    let mut ring: Vec<Vec<u32>> = vec![Vec::new(); mesh.vertex_count()];
    for t in 0..mesh.triangle_count() {
        let [a, b, c] = mesh.triangle_positions(t);
        if surfaces.window_transmittance[t].is_some() || (b - a).cross(c - a).length() <= 0.0 {
            continue;
        }
        for v in mesh.triangle(t) {
            ring[v as usize].push(t as u32);
        }
    }
    let mut candidates: Vec<u32> = (0..mesh.vertex_count() as u32)
        .filter(|&v| !ring[v as usize].is_empty())
        .filter(|&v| {
            free.is_none_or(|size| {
                let p = mesh.positions[v as usize];
                ring[v as usize].iter().all(|&t| mesh.triangle_positions(t as usize).iter().all(|q| q.distance(p) <= size))
            })
        })
        .collect();
    if let Some(n) = random {
        // A seeded Fisher–Yates prefix.
        let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
        for i in 0..n.min(candidates.len()) {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let j = i + (state % (candidates.len() - i) as u64) as usize;
            candidates.swap(i, j);
        }
        candidates.truncate(n);
        candidates.sort_unstable();
    }
    let mut text = String::from("id,tri,ax,ay,az,bx,by,bz,cx,cy,cz,corner,nax,nay,naz,nbx,nby,nbz,ncx,ncy,ncz\n");
    let chosen: HashSet<u32> = candidates.iter().copied().collect();
    for &v in &candidates {
        for &t in &ring[v as usize] {
            let corners = mesh.triangle(t as usize);
            let corner = ["a", "b", "c"][corners.iter().position(|&c| c == v).unwrap_or(0)];
            let p: Vec<String> =
                corners.iter().map(|&c| mesh.positions[c as usize]).flat_map(|q| q.to_array()).map(|x| x.to_string()).collect();
            let n: Vec<String> =
                corners.iter().map(|&c| mesh.normals[c as usize]).flat_map(|q| q.to_array()).map(|x| x.to_string()).collect();
            text += &format!("{v},{t},{},{corner},{}\n", p.join(","), n.join(","));
        }
    }
    std::fs::write(out, text).map_err(|e| format!("{}: {e}", out.display()))?;
    println!(
        "{}: {} vertices ({} candidates{})",
        out.display(),
        chosen.len(),
        candidates.len(),
        free.map(|f| format!(", rings within {f}")).unwrap_or_default()
    );
    Ok(())
}

fn compare(args: &[String]) -> Result<(), String> {
    let Some((bundle_path, references)) = args.split_first() else { return Err("compare BUNDLE REFERENCE.csv…".into()) };
    let bundle = prtbake::bundle::read_bundle(Path::new(bundle_path)).map_err(|e| e.to_string())?;
    let transfer = bundle.transfer.as_ref().ok_or("the bundle has no transfer")?;
    let total = transfer.total();
    let stride = (transfer.channels * transfer.order * transfer.order) as usize;
    println!("| reference | vertices | relative RMS difference | reference noise | mean ratio prtbake/reference |");
    println!("|---|---:|---:|---:|---:|");
    for reference in references {
        let text = std::fs::read_to_string(reference).map_err(|e| format!("{reference}: {e}"))?;
        let (mut diff2, mut ref2, mut noise2, mut sum_p, mut sum_m, mut n) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64, 0usize);
        for line in text.lines().filter(|l| !l.starts_with("id")) {
            let f: Vec<&str> = line.split(',').collect();
            let (Some(id), Some(m), Some(sigma), Some(used)) = (
                f.first().and_then(|s| s.parse::<usize>().ok()),
                f.get(1).and_then(|s| s.parse::<f64>().ok()),
                f.get(2).and_then(|s| s.parse::<f64>().ok()),
                f.get(3).and_then(|s| s.parse::<u64>().ok()),
            ) else {
                continue;
            };
            // Vertices the reference found no point for, or gave no spread, are not compared.
            if used < 2 || !sigma.is_finite() || id * stride >= total.len() {
                continue;
            }
            let p = f64::from(total[id * stride]);
            diff2 += (p - m) * (p - m);
            ref2 += m * m;
            noise2 += sigma * sigma;
            sum_p += p;
            sum_m += m;
            n += 1;
        }
        println!(
            "| {reference} | {n} | {:.4} | {:.4} | {:.4} |",
            (diff2 / ref2.max(1e-30)).sqrt(),
            (noise2 / ref2.max(1e-30)).sqrt(),
            sum_p / sum_m.max(1e-30)
        );
    }
    Ok(())
}
