//! Clean-up speed on a generated triangle soup (a torus with welds, duplicates
//! and slivers to find) at 250k, 500k and 1M triangles: it must scale as n log n.
//! And on high-valence fans (a disc of 10k and 100k triangles around its
//! centre, a cone with apex valence 20k, a 100k-corner polygon face fanned from
//! one corner), where every triangle shares one point: near-linear too.
//!
//! And `--cut-intersections` where cuts crowd: `n` fins crossing along one
//! axis (`n (n − 1) / 2` crossing pairs, one line per fin) and `n` thin
//! triangles crossing at one point (every pair crosses): the work follows
//! the pieces cut, not the pairs' squares.
//!
//! Run: `cargo bench --bench clean` (only the fans: `cargo bench --bench clean -- fan`;
//! only the cut: `cargo bench --bench clean -- cut`).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use prtbake::clean::fixtures::{fan, fins_through_axis, large_torus, thin_crossing, FanShape};
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

fn cut(c: &mut Criterion) {
    let mut group = c.benchmark_group("clean/cut");
    group.sample_size(10);
    let params = CleanParams { cut_intersections: true, ..CleanParams::default() };
    let cases = [
        ("fins-100", fins_through_axis(100)),
        ("fins-1000", fins_through_axis(1000)),
        ("thin-20", thin_crossing(20)),
        ("thin-30", thin_crossing(30)),
    ];
    for (name, mesh) in cases {
        group.throughput(Throughput::Elements(mesh.triangle_count() as u64));
        group.bench_function(name, |b| b.iter(|| clean_mesh(&mesh, &params).unwrap()));
    }
    group.finish();
}

criterion_group!(clean_benches, torus, fans, cut);
criterion_main!(clean_benches);
