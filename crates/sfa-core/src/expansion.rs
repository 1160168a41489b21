//! Polynomial expansion: all monomials of degree 1..=d of the input
//! features, without the constant.
//!
//! # Order
//! Monomials are grouped by degree (all degree-1 terms, then all degree-2
//! terms, ...). Within a degree, a monomial `x_i x_j ... x_k` is written with
//! non-decreasing indices `i <= j <= ... <= k`, and monomials are sorted
//! lexicographically by that index tuple. For `D = 3`, `d = 2`:
//!
//! `x0, x1, x2, x0x0, x0x1, x0x2, x1x1, x1x2, x2x2`
//!
//! This is the order of MDP's `PolynomialExpansionNode`. The output dimension
//! is `C(D + d, d) - 1` ([`expanded_dim`]).

use crate::error::{Result, SfaError};
use crate::view::{Sample, View};
use rayon::prelude::*;

/// Largest expansion degree accepted.
pub const MAX_DEGREE: usize = 8;

/// `C(n, k)` with overflow detection.
fn binomial(n: usize, k: usize) -> Option<usize> {
    let k = k.min(n - k.min(n));
    let mut r: u128 = 1;
    for i in 0..k {
        r = r * (n - i) as u128 / (i + 1) as u128;
        if r > usize::MAX as u128 {
            return None;
        }
    }
    Some(r as usize)
}

/// Output dimension of the degree-`degree` expansion of `dim` features:
/// `C(dim + degree, degree) - 1`.
pub fn expanded_dim(dim: usize, degree: usize) -> Result<usize> {
    check_degree(degree)?;
    dim.checked_add(degree).and_then(|n| binomial(n, degree)).map(|c| c - 1).ok_or_else(|| {
        SfaError::InvalidArgument(format!("expansion of {dim} features to degree {degree} has too many terms"))
    })
}

fn check_degree(degree: usize) -> Result<()> {
    if degree == 0 || degree > MAX_DEGREE {
        return Err(SfaError::InvalidArgument(format!("degree must be between 1 and {MAX_DEGREE}, got {degree}")));
    }
    Ok(())
}

/// A reusable expansion plan for a fixed input dimension and degree.
#[derive(Clone, Debug)]
pub struct Expansion {
    dim: usize,
    degree: usize,
    out_dim: usize,
    /// For degree k (index k-1): start offset within the degree-k block of the
    /// monomials whose first index is >= i, for i = 0..=dim.
    starts: Vec<Vec<usize>>,
    /// Length of each degree block.
    lens: Vec<usize>,
}

impl Expansion {
    /// Plans the expansion of `dim` features to `degree`.
    pub fn new(dim: usize, degree: usize) -> Result<Self> {
        let out_dim = expanded_dim(dim, degree)?;
        if dim == 0 {
            return Err(SfaError::InvalidArgument("cannot expand zero features".into()));
        }
        // Degree-1 block: x_i, first index i at offset i.
        let mut starts = vec![(0..=dim).collect::<Vec<_>>()];
        let mut lens = vec![dim];
        for k in 2..=degree {
            let prev = &starts[k - 2];
            let prev_len = lens[k - 2];
            // Degree-k block = concat_i x_i * (degree-(k-1) monomials with first index >= i).
            let mut s = Vec::with_capacity(dim + 1);
            let mut off = 0;
            for i in 0..dim {
                s.push(off);
                off += prev_len - prev[i];
            }
            s.push(off);
            lens.push(off);
            starts.push(s);
        }
        debug_assert_eq!(lens.iter().sum::<usize>(), out_dim);
        Ok(Expansion { dim, degree, out_dim, starts, lens })
    }

    /// Input dimension.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Degree.
    pub fn degree(&self) -> usize {
        self.degree
    }

    /// Output dimension, `C(dim + degree, degree) - 1`.
    pub fn out_dim(&self) -> usize {
        self.out_dim
    }

    /// Expands one sample `x` (length `dim`) into `out` (length `out_dim`).
    #[inline]
    pub fn expand_row(&self, x: &[f64], out: &mut [f64]) {
        debug_assert_eq!(x.len(), self.dim);
        debug_assert_eq!(out.len(), self.out_dim);
        out[..self.dim].copy_from_slice(x);
        let mut prev_off = 0;
        let mut off = self.dim;
        for k in 2..=self.degree {
            let prev_starts = &self.starts[k - 2];
            let prev_len = self.lens[k - 2];
            let (done, rest) = out.split_at_mut(off);
            let prev_block = &done[prev_off..prev_off + prev_len];
            let mut w = 0;
            for (i, &xi) in x.iter().enumerate() {
                let src = &prev_block[prev_starts[i]..];
                let dst = &mut rest[w..w + src.len()];
                for (d, &s) in dst.iter_mut().zip(src) {
                    *d = xi * s;
                }
                w += src.len();
            }
            prev_off = off;
            off += self.lens[k - 1];
        }
    }

    /// Expands a row-major block `x` (`n x dim`) into `out` (`n x out_dim`),
    /// in parallel over rows.
    pub fn expand_block(&self, x: &[f64], out: &mut [f64]) {
        let n = x.len() / self.dim.max(1);
        debug_assert_eq!(out.len(), n * self.out_dim);
        let rows_per_task = (1 << 14) / self.out_dim.max(1) + 1;
        out.par_chunks_mut(self.out_dim * rows_per_task).zip(x.par_chunks(self.dim * rows_per_task)).for_each(
            |(o, xi)| {
                for (orow, xrow) in o.chunks_mut(self.out_dim).zip(xi.chunks(self.dim)) {
                    self.expand_row(xrow, orow);
                }
            },
        );
    }

    /// Expands every row of `x` into a new row-major `n x out_dim` vector of
    /// the same sample type, in parallel. Fails on NaN/inf or a wrong width.
    pub fn expand<T: Sample>(&self, x: View<'_, T>) -> Result<Vec<T>> {
        if x.ncols() != self.dim {
            return Err(SfaError::ShapeMismatch { what: "number of features", expected: self.dim, got: x.ncols() });
        }
        x.check_finite("input")?;
        let n = x.nrows();
        let od = self.out_dim;
        let mut out = crate::memory::filled(n.checked_mul(od).unwrap_or(usize::MAX), T::from_f64(0.0), || {
            format!("the expansion of {n} rows to {od} terms")
        })?;
        let rows_per_task = ((1 << 14) / od).max(1);
        out.par_chunks_mut(od * rows_per_task).enumerate().for_each_init(
            || (vec![0.0; self.dim], vec![0.0; od]),
            |(xr, er), (c, o)| {
                let r0 = c * rows_per_task;
                for (k, orow) in o.chunks_mut(od).enumerate() {
                    x.row_into(r0 + k, None, xr);
                    self.expand_row(xr, er);
                    for (d, &s) in orow.iter_mut().zip(er.iter()) {
                        *d = T::from_f64(s);
                    }
                }
            },
        );
        Ok(out)
    }

    /// The index tuples of every output monomial, in output order (for
    /// documentation and tests).
    pub fn monomials(&self) -> Vec<Vec<usize>> {
        let mut all: Vec<Vec<usize>> = Vec::with_capacity(self.out_dim);
        let mut prev: Vec<Vec<usize>> = (0..self.dim).map(|i| vec![i]).collect();
        all.extend(prev.iter().cloned());
        for _ in 2..=self.degree {
            let mut cur = Vec::new();
            for i in 0..self.dim {
                for m in prev.iter().filter(|m| m[0] >= i) {
                    let mut t = vec![i];
                    t.extend_from_slice(m);
                    cur.push(t);
                }
            }
            all.extend(cur.iter().cloned());
            prev = cur;
        }
        all
    }
}

/// Convenience: expands `x` to `degree` (see [`Expansion::expand`]).
pub fn expand<T: Sample>(x: View<'_, T>, degree: usize) -> Result<Vec<T>> {
    Expansion::new(x.ncols(), degree)?.expand(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dims_match_binomial() {
        assert_eq!(expanded_dim(3, 2).unwrap(), 9);
        assert_eq!(expanded_dim(23, 2).unwrap(), 299);
        assert_eq!(expanded_dim(10, 3).unwrap(), 285);
        assert_eq!(expanded_dim(5, 1).unwrap(), 5);
        assert!(expanded_dim(5, 0).is_err());
    }

    #[test]
    fn order_is_documented_order() {
        let e = Expansion::new(3, 2).unwrap();
        let m = e.monomials();
        let want: Vec<Vec<usize>> =
            vec![vec![0], vec![1], vec![2], vec![0, 0], vec![0, 1], vec![0, 2], vec![1, 1], vec![1, 2], vec![2, 2]];
        assert_eq!(m, want);
        let x = [2.0, 3.0, 5.0];
        let mut out = vec![0.0; 9];
        e.expand_row(&x, &mut out);
        assert_eq!(out, vec![2., 3., 5., 4., 6., 10., 9., 15., 25.]);
    }

    #[test]
    fn expand_row_matches_monomials_degree3() {
        for dim in 1..6 {
            let e = Expansion::new(dim, 3).unwrap();
            let x: Vec<f64> = (0..dim).map(|i| 1.5 + i as f64 * 0.7).collect();
            let mut out = vec![0.0; e.out_dim()];
            e.expand_row(&x, &mut out);
            let mons = e.monomials();
            assert_eq!(mons.len(), e.out_dim());
            for (m, v) in mons.iter().zip(&out) {
                let want: f64 = m.iter().map(|&i| x[i]).product();
                assert!((want - v).abs() < 1e-12);
                assert!(m.windows(2).all(|w| w[0] <= w[1]));
            }
            // lexicographic within degree, graded overall
            for w in mons.windows(2) {
                assert!(w[0].len() < w[1].len() || w[0] < w[1]);
            }
        }
    }
}
