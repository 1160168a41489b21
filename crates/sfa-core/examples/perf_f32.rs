//! f32 vs f64 sequential SYRK on small blocks: `cargo run --release --example perf_f32 -- D [ROWS]`.
use faer::linalg::matmul::triangular::{matmul as tri, BlockStructure};
use faer::{Accum, Mat, MatRef, Par};
use std::time::Instant;

fn main() {
    let d: usize = std::env::args().nth(1).map_or(432, |a| a.parse().unwrap());
    let rows: usize = std::env::args().nth(2).map_or((1usize << 16) / d, |a| a.parse().unwrap());
    let n_blocks = 60_000 / rows;
    let x64: Vec<f64> = (0..rows * d).map(|i| ((i * 2654435761usize) % 1000) as f64 / 1000.0).collect();
    let x32: Vec<f32> = x64.iter().map(|&v| v as f32).collect();
    for _ in 0..3 {
        let mut acc = Mat::<f64>::zeros(d, d);
        let t = Instant::now();
        for _ in 0..n_blocks {
            let m = MatRef::from_row_major_slice(&x64, rows, d);
            tri(
                acc.as_mut(),
                BlockStructure::TriangularLower,
                Accum::Add,
                m.transpose(),
                BlockStructure::Rectangular,
                m,
                BlockStructure::Rectangular,
                1.0,
                Par::Seq,
            );
        }
        let t64 = t.elapsed().as_secs_f64();
        let mut tmp = Mat::<f32>::zeros(d, d);
        let mut acc2 = Mat::<f64>::zeros(d, d);
        let t = Instant::now();
        for _ in 0..n_blocks {
            let m = MatRef::from_row_major_slice(&x32, rows, d);
            tri(
                tmp.as_mut(),
                BlockStructure::TriangularLower,
                Accum::Replace,
                m.transpose(),
                BlockStructure::Rectangular,
                m,
                BlockStructure::Rectangular,
                1.0f32,
                Par::Seq,
            );
            for j in 0..d {
                for i in j..d {
                    acc2[(i, j)] += tmp[(i, j)] as f64;
                }
            }
        }
        let t32 = t.elapsed().as_secs_f64();
        let gf = (n_blocks * rows * d * d) as f64 * 1e-9;
        println!(
            "d={d} rows/block={rows}: f64 {:.1} GFLOP/s  f32+add {:.1} GFLOP/s  ratio {:.2}",
            gf / t64,
            gf / t32,
            t64 / t32
        );
    }
}
