//! A mesh's lightmap atlas at a texel size: unwrap time, charts, size,
//! texel use (covered texels over the texture) and the coverage's build time.
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
    }
    Ok(())
}
