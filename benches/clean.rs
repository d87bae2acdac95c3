//! Clean-up speed on a generated triangle soup (a torus with welds, duplicates
//! and slivers to find) at 250k, 500k and 1M triangles: it must scale as n log n.
//! And on high-valence fans (a disc of 10k and 100k triangles around its
//! centre, a cone with apex valence 20k, a 100k-corner polygon face fanned from
//! one corner), where every triangle shares one point: near-linear too.
//!
//! Run: `cargo bench --bench clean` (only the fans: `cargo bench --bench clean -- fan`).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use prtbake::clean::fixtures::{fan, large_torus, FanShape};
use prtbake::clean::{clean_mesh, CleanParams};
use prtbake::mesh::Mesh;

fn bench_clean(group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>, name: String, mesh: &Mesh) {
    group.throughput(Throughput::Elements(mesh.triangle_count() as u64));
    group.bench_function(name, |b| b.iter(|| clean_mesh(mesh, &CleanParams::default()).unwrap()));
}

fn torus(c: &mut Criterion) {
    let mut group = c.benchmark_group("clean/torus");
    group.sample_size(10);
    for n in [250_000, 500_000, 1_000_000] {
        bench_clean(&mut group, format!("{}k", n / 1000), &large_torus(n).mesh);
    }
    group.finish();
}

fn fans(c: &mut Criterion) {
    let mut group = c.benchmark_group("clean/fan");
    group.sample_size(10);
    for (shape, n) in [(FanShape::Disc, 10_000), (FanShape::Disc, 100_000), (FanShape::Cone, 20_000), (FanShape::Polygon, 100_000)] {
        bench_clean(&mut group, format!("{shape:?}-{}k", n / 1000).to_lowercase(), &fan(shape, n));
    }
    group.finish();
}

criterion_group!(clean_benches, torus, fans);
criterion_main!(clean_benches);
