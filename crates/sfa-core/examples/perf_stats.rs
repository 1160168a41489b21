//! Quick timing of the accumulation pieces: `cargo run --release --example perf_stats -- N D`.
use faer::linalg::matmul::triangular::{matmul as tri, BlockStructure};
use faer::{Accum, Mat, MatRef, Par};
use sfa_core::{Accumulator, View};
use std::time::Instant;

fn main() {
    let args: Vec<usize> = std::env::args().skip(1).map(|a| a.parse().unwrap()).collect();
    let (n, d) = (args.first().copied().unwrap_or(200_000), args.get(1).copied().unwrap_or(300));
    let x: Vec<f64> = (0..n * d).map(|i| ((i * 2654435761usize) % 1000) as f64 / 1000.0).collect();
    for br in [2048usize, 4096, 8192, 16384, 65536] {
        let mut dst = Mat::<f64>::zeros(d, d);
        let t = Instant::now();
        for c in x.chunks(br * d) {
            let m = MatRef::from_row_major_slice(c, c.len() / d, d);
            tri(
                dst.as_mut(),
                BlockStructure::TriangularLower,
                Accum::Add,
                m.transpose(),
                BlockStructure::Rectangular,
                m,
                BlockStructure::Rectangular,
                1.0,
                Par::rayon(0),
            );
        }
        let t1 = t.elapsed().as_secs_f64();
        let mut dst = Mat::<f64>::zeros(d, d);
        let t = Instant::now();
        for c in x.chunks(br * d) {
            let m = MatRef::from_row_major_slice(c, c.len() / d, d);
            faer::linalg::matmul::matmul(dst.as_mut(), Accum::Add, m.transpose(), m, 1.0, Par::rayon(0));
        }
        let t2 = t.elapsed().as_secs_f64();
        let mut dst = Mat::<f64>::zeros(d, d);
        let t = Instant::now();
        for c in x.chunks(br * d) {
            let m = MatRef::from_row_major_slice(c, c.len() / d, d);
            tri(
                dst.as_mut(),
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
        let t3 = t.elapsed().as_secs_f64();
        // Column-major copy of the block (features contiguous per column).
        let mut dst = Mat::<f64>::zeros(d, d);
        let mut cm = Mat::<f64>::zeros(br, d);
        let t = Instant::now();
        for c in x.chunks(br * d) {
            let nb = c.len() / d;
            for j in 0..d {
                for i in 0..nb {
                    cm[(i, j)] = c[i * d + j];
                }
            }
            let m = cm.as_ref().subrows(0, nb);
            tri(
                dst.as_mut(),
                BlockStructure::TriangularLower,
                Accum::Add,
                m.transpose(),
                BlockStructure::Rectangular,
                m,
                BlockStructure::Rectangular,
                1.0,
                Par::rayon(0),
            );
        }
        let t4 = t.elapsed().as_secs_f64();
        println!("block {br}: tri syrk {t1:.3}s  full gemm {t2:.3}s  tri seq {t3:.3}s  colmajor tri {t4:.3}s");
    }
    let t = Instant::now();
    let mut acc = Accumulator::new(d).unwrap();
    acc.update(View::from_slice(&x, n, d).unwrap(), false).unwrap();
    println!("Accumulator::update {:.3}s", t.elapsed().as_secs_f64());
}
