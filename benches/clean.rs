//! Clean-up speed on a generated triangle soup (a torus with welds, duplicates
//! and slivers to find) at 250k, 500k and 1M triangles: it must scale as n log n.
//!
//! Run: `cargo bench --bench clean`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use prtbake::clean::{clean_mesh, fixtures::large_torus, CleanParams};

fn benches(c: &mut Criterion) {
    let mut group = c.benchmark_group("clean/torus");
    group.sample_size(10);
    for n in [250_000, 500_000, 1_000_000] {
        let fixture = large_torus(n);
        group.throughput(Throughput::Elements(fixture.mesh.triangle_count() as u64));
        group.bench_function(format!("{}k", n / 1000), |b| b.iter(|| clean_mesh(&fixture.mesh, &CleanParams::default()).unwrap()));
    }
    group.finish();
}

criterion_group!(clean_benches, benches);
criterion_main!(clean_benches);
