//! A mesh's lightmap atlas at a texel size: unwrap time, charts, size,
//! texel use (covered texels over the texture), the coverage's build time,
//! and how far charts fold (chart-internal edges by the angle between their
//! two triangles: a texel across a fold mixes two faces' light).
//!
//! Run: `cargo run --release --example atlas_probe -- MESH TEXEL_SIZE…`
//! (docs/image-accuracy.md's atlas rows come from it).

use prtbake::atlas::{coverage::Coverage, Atlas};
use prtbake::mesh::{load_mesh, LoadOptions};
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((path, sizes)) = args.split_first() else {
        anyhow::bail!("usage: atlas_probe MESH TEXEL_SIZE…");
    };
    let mesh = load_mesh(path.as_ref(), &LoadOptions::default())?.mesh;
    println!("{path}: {} triangles, {} vertices", mesh.triangle_count(), mesh.vertex_count());
    // How far charts fold: chart-internal mesh edges by the angle between
    // their two triangles' normals (a texel across a fold mixes two faces' light).
    let folds = |atlas: &Atlas| {
        let mut edges: std::collections::HashMap<(u32, u32), u32> = std::collections::HashMap::new();
        let normal = |t: usize| {
            let [a, b, c] = mesh.triangle_positions(t);
            (b - a).cross(c - a).normalize_or_zero()
        };
        let mut counts = [0usize; 4];
        let mut internal = 0usize;
        for t in 0..mesh.triangle_count() {
            for k in 0..3 {
                let (u, v) = (mesh.indices[3 * t + k], mesh.indices[3 * t + (k + 1) % 3]);
                let key = (u.min(v), u.max(v));
                if let Some(&s) = edges.get(&key) {
                    if atlas.triangle_chart[s as usize] == atlas.triangle_chart[t] && atlas.triangle_chart[t] != prtbake::atlas::NO_CHART {
                        internal += 1;
                        let angle = normal(s as usize).dot(normal(t)).clamp(-1.0, 1.0).acos().to_degrees();
                        for (i, limit) in [10.0, 30.0, 60.0, 85.0].iter().enumerate() {
                            if angle > *limit {
                                counts[i] += 1;
                            }
                        }
                    }
                } else {
                    edges.insert(key, t as u32);
                }
            }
        }
        println!("  chart-internal edges {internal}; folded over 10/30/60/85 degrees: {counts:?}");
    };
    for size in sizes {
        let size: f32 = size.parse()?;
        let clock = Instant::now();
        let atlas = Atlas::unwrap(&mesh, size)?;
        let unwrap = clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        let cover = Coverage::of(&atlas);
        let covered = clock.elapsed().as_secs_f64();
        let texels = atlas.width as f64 * atlas.height as f64;
        println!(
            "texel {size} m: {:.2} s unwrap, {} charts, {} x {} texels, {} covered ({:.1}% use), {} texel-triangle pairs, coverage {:.2} s",
            unwrap,
            atlas.chart_count,
            atlas.width,
            atlas.height,
            cover.len(),
            100.0 * cover.len() as f64 / texels,
            cover.triangle.len(),
            covered
        );
        folds(&atlas);
    }
    Ok(())
}
