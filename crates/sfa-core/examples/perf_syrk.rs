//! Sequential SYRK variants on one thread: `cargo run --release --example perf_syrk -- N D`.
use faer::linalg::matmul::matmul;
use faer::linalg::matmul::triangular::{matmul as tri, BlockStructure};
use faer::{Accum, Mat, MatRef, Par};
use std::time::Instant;

fn main() {
    let args: Vec<usize> = std::env::args().skip(1).map(|a| a.parse().unwrap()).collect();
    let (n, d) = (args.first().copied().unwrap_or(100_000), args.get(1).copied().unwrap_or(300));
    let br = 8192;
    let x: Vec<f64> = (0..n * d).map(|i| ((i * 2654435761usize) % 1000) as f64 / 1000.0).collect();
    for rep in 0..2 {
        let mut dst = Mat::<f64>::zeros(d, d);
        let t = Instant::now();
        for c in x.chunks(br * d) {
            let m = MatRef::from_row_major_slice(c, c.len() / d, d);
            tri(dst.as_mut(), BlockStructure::TriangularLower, Accum::Add, m.transpose(), BlockStructure::Rectangular, m, BlockStructure::Rectangular, 1.0, Par::Seq);
        }
        let t_tri = t.elapsed().as_secs_f64();
        let mut dst2 = Mat::<f64>::zeros(d, d);
        let t = Instant::now();
        for c in x.chunks(br * d) {
            let m = MatRef::from_row_major_slice(c, c.len() / d, d);
            matmul(dst2.as_mut(), Accum::Add, m.transpose(), m, 1.0, Par::Seq);
        }
        let t_full = t.elapsed().as_secs_f64();
        let mut res = vec![];
        for w in [32usize, 48, 64, 96, 128] {
            let mut dst3 = Mat::<f64>::zeros(d, d);
            let t = Instant::now();
            for c in x.chunks(br * d) {
                let m = MatRef::from_row_major_slice(c, c.len() / d, d);
                let mut j = 0;
                while j < d {
                    let wj = w.min(d - j);
                    let lhs = m.subcols(j, d - j).transpose();
                    let rhs = m.subcols(j, wj);
                    matmul(dst3.as_mut().submatrix_mut(j, j, d - j, wj), Accum::Add, lhs, rhs, 1.0, Par::Seq);
                    j += wj;
                }
            }
            res.push((w, t.elapsed().as_secs_f64()));
            if rep == 0 && w == 64 {
                let mut e = 0.0f64;
                for jj in 0..d { for ii in jj..d { e = e.max((dst3[(ii, jj)] - dst2[(ii, jj)]).abs()); } }
                eprintln!("block-col max err {e:e}");
            }
        }
        println!("tri {t_tri:.3}  full {t_full:.3}  blockcol {res:?}");
    }
}
