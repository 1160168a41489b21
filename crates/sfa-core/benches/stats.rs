//! Statistics accumulation (covariance + derivative covariance in one pass):
//! `cargo bench --bench stats`.
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use sfa_core::{Accumulator, View};

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("stats_update");
    for (n, d) in [(100_000usize, 300usize), (200_000, 100), (1_000_000, 10)] {
        let x: Vec<f64> = (0..n * d).map(|i| ((i * 2654435761) % 1000) as f64 * 1e-3).collect();
        // Two n x d x d products (covariance and derivative covariance).
        g.throughput(Throughput::Elements((2 * n * d * d) as u64));
        g.bench_with_input(BenchmarkId::new(format!("d{d}"), n), &x, |b, x| {
            b.iter(|| {
                let mut a = Accumulator::new(d).unwrap();
                a.update(View::from_slice(x, n, d).unwrap(), false).unwrap();
                a
            })
        });
    }
    g.finish();
}

criterion_group! { name = benches; config = Criterion::default().sample_size(10); targets = bench }
criterion_main!(benches);
