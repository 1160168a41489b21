//! The generalized symmetric eigenproblem of SFA, `A w = lambda B w` with `A`
//! the derivative covariance and `B` the input covariance, solved by
//! whitening.
//!
//! 1. Eigendecompose `B = U S U^T`.
//! 2. Drop every direction whose eigenvalue is at most `tol * max(S)` (a
//!    *relative* tolerance, so the result does not depend on the data's
//!    scale); the number dropped is the rank deficit. Nothing is divided by a
//!    near-zero variance.
//! 3. Whiten with `W = U_r S_r^{-1/2}` and eigendecompose `W^T A W = V L V^T`.
//! 4. The generalized eigenvectors are `P = W V`, with `P^T B P = I` and
//!    `P^T A P = L`, eigenvalues (Delta values) ascending.
//!
//! # Sign convention
//! Each output direction (column of `P`) is flipped so that its entry of
//! largest magnitude is positive (the first such entry on ties). This makes
//! results deterministic across runs and platforms.

use crate::error::{Result, SfaError};
use faer::{Mat, MatRef, Side};

/// Default relative tolerance below which covariance directions are dropped.
pub const DEFAULT_TOL: f64 = 1e-10;

/// Result of [`solve`].
#[derive(Clone, Debug)]
pub struct GeneralizedEigen {
    /// The `n` smallest generalized eigenvalues, ascending.
    pub values: Vec<f64>,
    /// `dim x n` eigenvectors (columns), `B`-orthonormal.
    pub vectors: Mat<f64>,
    /// Number of covariance directions kept.
    pub rank: usize,
    /// Eigenvalues of `B` that were dropped (ascending), relative tolerance
    /// `tol`.
    pub dropped: Vec<f64>,
}

impl GeneralizedEigen {
    /// Number of dropped covariance directions.
    pub fn rank_deficit(&self) -> usize {
        self.dropped.len()
    }
}

/// Parts faer splits the solve's eigendecompositions and products into.
/// faer reads a process-wide setting whose default follows the thread count
/// of the pool it runs in, and its blocking, and so its rounding, follows
/// that; a fixed count makes the solve's result the same for every
/// `set_num_threads` (this crate is faer's only user in the process).
pub const SOLVE_PARTS: usize = 4;

fn fixed_parallelism() {
    faer::set_global_parallelism(faer::Par::rayon(SOLVE_PARTS));
}

fn eigh(m: MatRef<'_, f64>, what: &str) -> Result<(Vec<f64>, Mat<f64>)> {
    let e = m
        .self_adjoint_eigen(Side::Lower)
        .map_err(|e| SfaError::Numerical(format!("eigendecomposition of the {what} failed: {e:?}")))?;
    let s = e.S().column_vector().iter().copied().collect::<Vec<_>>();
    Ok((s, e.U().to_owned()))
}

/// Solves `a w = lambda b w` for the `n` smallest eigenvalues (see the module
/// documentation). `a` and `b` are symmetric `dim x dim`.
pub fn solve(a: MatRef<'_, f64>, b: MatRef<'_, f64>, n: usize, tol: f64) -> Result<GeneralizedEigen> {
    solve_impl(a, b, n, tol, true)
}

/// Like [`solve`], but returns `min(n, rank)` eigenpairs instead of failing
/// when fewer than `n` covariance directions survive the tolerance (used by
/// the dimension-reducing stage of a node). Fails only at rank 0.
pub fn solve_up_to(a: MatRef<'_, f64>, b: MatRef<'_, f64>, n: usize, tol: f64) -> Result<GeneralizedEigen> {
    solve_impl(a, b, n, tol, false)
}

fn solve_impl(a: MatRef<'_, f64>, b: MatRef<'_, f64>, n: usize, tol: f64, strict: bool) -> Result<GeneralizedEigen> {
    fixed_parallelism();
    let d = b.nrows();
    if b.ncols() != d || a.nrows() != d || a.ncols() != d {
        return Err(SfaError::InvalidArgument(format!(
            "matrices must be square and of equal size, got {}x{} and {}x{}",
            a.nrows(),
            a.ncols(),
            b.nrows(),
            b.ncols()
        )));
    }
    // The whitening, the reduced problem and the eigen workspaces: about
    // six d x d matrices at once.
    crate::memory::check(|| format!("the eigenproblem of {d} dimensions"), crate::memory::bytes_of(48, &[d, d]))?;
    if !(tol.is_finite() && tol >= 0.0 && tol < 1.0) {
        return Err(SfaError::InvalidArgument(format!("tol must be in [0, 1), got {tol}")));
    }
    if n == 0 || n > d {
        return Err(SfaError::InvalidArgument(format!(
            "number of outputs must be between 1 and the input dimension {d}, got {n}"
        )));
    }
    for (name, m) in [("derivative covariance", a), ("covariance", b)] {
        for j in 0..d {
            for i in 0..d {
                if !m[(i, j)].is_finite() {
                    return Err(SfaError::Numerical(format!(
                        "the {name} is not finite: the statistics overflowed (the input or its expansion is too large; scale it down)"
                    )));
                }
            }
        }
    }
    let (s, u) = eigh(b, "covariance")?;
    let smax = s.last().copied().unwrap_or(0.0);
    if !(smax > 0.0) {
        return Err(SfaError::RankDeficient { rank: 0, requested: n, dim: d, tol });
    }
    let thresh = tol * smax;
    let keep: Vec<usize> = (0..d).filter(|&i| s[i] > thresh).collect();
    let dropped: Vec<f64> = (0..d).filter(|&i| s[i] <= thresh).map(|i| s[i]).collect();
    let r = keep.len();
    let n = if strict { n } else { n.min(r) };
    if r < n || r == 0 {
        return Err(SfaError::RankDeficient { rank: r, requested: n, dim: d, tol });
    }
    // Whitening matrix W = U_r S_r^{-1/2}, dim x r.
    let w = Mat::from_fn(d, r, |i, k| u[(i, keep[k])] / s[keep[k]].sqrt());
    let aw = &w.transpose() * a * &w;
    // Symmetrize against rounding.
    let aw = Mat::from_fn(r, r, |i, j| 0.5 * (aw[(i, j)] + aw[(j, i)]));
    let (l, v) = eigh(aw.as_ref(), "whitened derivative covariance")?;
    let vn = v.as_ref().subcols(0, n);
    let mut p = &w * vn;
    for j in 0..n {
        let mut best = 0;
        let mut bv = 0.0f64;
        for i in 0..d {
            let x = p[(i, j)].abs();
            if x > bv {
                bv = x;
                best = i;
            }
        }
        if p[(best, j)] < 0.0 {
            for i in 0..d {
                p[(i, j)] = -p[(i, j)];
            }
        }
    }
    Ok(GeneralizedEigen { values: l[..n].to_vec(), vectors: p, rank: r, dropped })
}
