//! Generalized eigen solve by whitening: `cargo bench --bench solve`.
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use faer::Mat;
use sfa_core::solve;

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("solve");
    for d in [50usize, 300, 1000] {
        let mut s = 1u64;
        let mut r = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let g1 = Mat::from_fn(d, d, |_, _| r());
        let g2 = Mat::from_fn(d, d, |_, _| r());
        let b = &g1 * g1.transpose() + Mat::<f64>::identity(d, d);
        let a = &g2 * g2.transpose();
        g.bench_with_input(BenchmarkId::new("whitening", d), &(a, b), |bch, (a, b)| {
            bch.iter(|| solve(a.as_ref(), b.as_ref(), 20.min(d), 1e-10).unwrap())
        });
    }
    g.finish();
}

criterion_group! { name = benches; config = Criterion::default().sample_size(10); targets = bench }
criterion_main!(benches);
