//! Polynomial expansion throughput: `cargo bench --bench expansion`.
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use sfa_core::{Expansion, View};

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("expansion");
    for (d, degree) in [(23usize, 2usize), (14, 2), (10, 3)] {
        let n = 20_000;
        let x: Vec<f64> = (0..n * d).map(|i| (i % 97) as f64 * 0.01).collect();
        let e = Expansion::new(d, degree).unwrap();
        g.throughput(Throughput::Elements((n * e.out_dim()) as u64));
        g.bench_with_input(BenchmarkId::new(format!("d{d}_deg{degree}"), n), &x, |b, x| {
            b.iter(|| e.expand(View::from_slice(x, n, d).unwrap()).unwrap())
        });
    }
    g.finish();
}

criterion_group! { name = benches; config = Criterion::default().sample_size(10); targets = bench }
criterion_main!(benches);
