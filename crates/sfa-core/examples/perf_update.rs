//! `Accumulator::update` at several block sizes: `cargo run --release --example perf_update -- N D`.
use sfa_core::{stats::set_block_rows, Accumulator, View};
use std::time::Instant;

fn main() {
    let args: Vec<usize> = std::env::args().skip(1).map(|a| a.parse().unwrap()).collect();
    let (n, d) = (args.first().copied().unwrap_or(200_000), args.get(1).copied().unwrap_or(300));
    let x: Vec<f64> = (0..n * d).map(|i| ((i * 2654435761usize) % 1000) as f64 / 1000.0).collect();
    for _ in 0..3 {
        let mut line = String::new();
        for br in [128usize, 512, 2048, 8192, 0] {
            set_block_rows(br);
            let t = Instant::now();
            let mut a = Accumulator::new(d).unwrap();
            a.update(View::from_slice(&x, n, d).unwrap(), false).unwrap();
            line += &format!("{br}:{:.3} ", t.elapsed().as_secs_f64());
        }
        println!("{line}");
    }
}
