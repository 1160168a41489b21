//! Time of a trained quadratic node's transform of one row at a time (the
//! per-position calls of a network without weight sharing):
//! `cargo run --release --example perf_apply -p sfa-core -- [CALLS]`.
//! Prints microseconds per call.
use sfa_core::view::View;
use sfa_core::{NodeConfig, SfaNode};
use std::time::Instant;

fn main() {
    let calls: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(20000);
    let (n, d) = (4000, 32);
    let x: Vec<f64> = (0..n * d)
        .map(|k| ((k as u64).wrapping_mul(2654435761) % 10007) as f64 / 10007.0 + (k / d) as f64 * 1e-3)
        .collect();
    let cfg = NodeConfig { n_components: 32, degree: 2, reduce_to: Some(24), ..NodeConfig::linear(32) };
    let mut node = SfaNode::new(cfg).unwrap();
    for s in 0..node.n_stages() {
        node.partial_fit(View::from_slice(&x, n, d).unwrap(), true).unwrap();
        if s + 1 < node.n_stages() {
            node.finish_stage().unwrap();
        }
    }
    node.ensure_solved().unwrap();
    let mut sink = 0.0;
    let t0 = Instant::now();
    for i in 0..calls {
        let r = i % n;
        let y = node.transform(View::from_slice(&x[r * d..(r + 1) * d], 1, d).unwrap()).unwrap();
        sink += y[0];
    }
    let us = t0.elapsed().as_secs_f64() * 1e6 / calls as f64;
    println!("{us:.2} us per one-row transform (checksum {sink:.3})");
}
