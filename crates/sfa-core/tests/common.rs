#![allow(dead_code)]
//! Shared test helpers.

use faer::Mat;

/// Deterministic pseudo-random numbers (xorshift64*), uniform in [-1, 1).
pub struct Rng(u64);
impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E3779B97F4A7C15) | 1)
    }
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let v = self.0.wrapping_mul(0x2545F4914F6CDD1D);
        (v >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// `n x d` row-major correlated time series: random walks mixed with noise.
pub fn correlated(n: usize, d: usize, seed: u64) -> Vec<f64> {
    let mut r = Rng::new(seed);
    let mix: Vec<f64> = (0..d * d).map(|_| r.next()).collect();
    let mut state = vec![0.0; d];
    let mut out = vec![0.0; n * d];
    for t in 0..n {
        for s in state.iter_mut() {
            *s += 0.05 * r.next();
        }
        let noise: Vec<f64> = (0..d).map(|_| r.next()).collect();
        for i in 0..d {
            let mut v = 0.0;
            for j in 0..d {
                v += mix[i * d + j] * (state[j] + 0.3 * noise[j]);
            }
            out[t * d + i] = v;
        }
    }
    out
}

pub fn max_abs_diff(a: &Mat<f64>, b: &Mat<f64>) -> f64 {
    let mut m = 0.0f64;
    for j in 0..a.ncols() {
        for i in 0..a.nrows() {
            m = m.max((a[(i, j)] - b[(i, j)]).abs());
        }
    }
    m
}

pub fn max_abs(a: &Mat<f64>) -> f64 {
    let mut m = 0.0f64;
    for j in 0..a.ncols() {
        for i in 0..a.nrows() {
            m = m.max(a[(i, j)].abs());
        }
    }
    m
}

/// Naive reference statistics of one sequence (for tests only).
pub fn naive_stats(x: &[f64], n: usize, d: usize) -> (Vec<f64>, Mat<f64>, Mat<f64>) {
    let mean: Vec<f64> = (0..d).map(|j| (0..n).map(|i| x[i * d + j]).sum::<f64>() / n as f64).collect();
    let cov = Mat::from_fn(d, d, |a, b| {
        (0..n).map(|i| (x[i * d + a] - mean[a]) * (x[i * d + b] - mean[b])).sum::<f64>() / n as f64
    });
    let dcov = Mat::from_fn(d, d, |a, b| {
        (1..n).map(|i| (x[i * d + a] - x[(i - 1) * d + a]) * (x[i * d + b] - x[(i - 1) * d + b])).sum::<f64>()
            / (n - 1) as f64
    });
    (mean, cov, dcov)
}

/// `n` periodic random images `h x w x c` with smooth structure.
pub fn images(n: usize, h: usize, w: usize, c: usize, seed: u64) -> Vec<f64> {
    let mut r = Rng::new(seed);
    let mut out = Vec::with_capacity(n * h * w * c);
    for _ in 0..n {
        let phases: Vec<f64> = (0..6).map(|_| r.next() * 3.0).collect();
        for y in 0..h {
            for x in 0..w {
                for ch in 0..c {
                    let a = 2.0 * std::f64::consts::PI * x as f64 / w as f64;
                    let v = (a + phases[0] + y as f64 * 0.3).sin()
                        + 0.5 * (2.0 * a + phases[1] * (1.0 + ch as f64)).cos()
                        + 0.3 * (3.0 * a + phases[2] * y as f64).sin()
                        + 0.2 * r.next();
                    out.push(v);
                }
            }
        }
    }
    out
}
