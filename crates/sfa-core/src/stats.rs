//! Streaming second-order statistics for SFA: sample count, mean, covariance
//! of the input and (uncentered) covariance of its time derivative.
//!
//! # Numerics
//! * Sums are `f64`, whatever the input type.
//! * Samples are shifted by a reference point (the first sample seen) before
//!   outer products are formed, so a large common offset does not cancel
//!   catastrophically when the mean is removed at the end.
//! * Outer products run block-wise through faer's triangular (SYRK-like)
//!   matrix product, in parallel; only the lower triangle is accumulated.
//!
//! # Samples, pairs and sequences
//! The accumulator holds two independent moment sets: *samples* (for mean
//! and covariance) and *derivative pairs* `(a, b)` with `d = b - a` (for the
//! derivative covariance). [`Accumulator::update`] feeds a time series: every
//! row is a sample and every consecutive pair of rows is a derivative pair;
//! the last row is carried to the next call so chunked feeding equals one
//! pass, unless the next call starts a new sequence. [`Accumulator::add_samples`]
//! and [`Accumulator::add_pairs`] take weighted samples and weighted pairs
//! directly (simulated rotation with multiplicities, graph-based SFA).
//! Two accumulators merge exactly ([`Accumulator::merge`]).
//!
//! # Normalisation
//! `covariance = sum w (x - mean)(x - mean)^T / sum w` (population
//! covariance: SFA outputs then have unit variance with `ddof = 0`), and
//! `derivative_covariance = sum w_p d d^T / sum w_p` (uncentered, the mean
//! squared derivative of SFA).

use crate::error::{Result, SfaError};
use crate::view::{Sample, View};
use faer::Mat;

/// Streaming accumulator of SFA statistics. See the module documentation.
#[derive(Clone, Debug)]
pub struct Accumulator {
    dim: usize,
    shift: Option<Vec<f64>>,
    n_samples: u64,
    weight_sum: f64,
    sum: Vec<f64>,
    sxx: Mat<f64>,
    n_pairs: u64,
    pair_weight_sum: f64,
    sum_d: Vec<f64>,
    sdd: Mat<f64>,
    first: Option<Vec<f64>>,
    last: Option<Vec<f64>>,
    mixed: bool,
}

/// The plain-data state of an [`Accumulator`], for saving and restoring.
/// Matrices are full symmetric `dim x dim`, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct AccumulatorState {
    pub dim: usize,
    /// Reference point the sums are relative to (empty before the first sample).
    pub shift: Vec<f64>,
    pub n_samples: u64,
    pub weight_sum: f64,
    pub sum: Vec<f64>,
    pub sxx: Vec<f64>,
    pub n_pairs: u64,
    pub pair_weight_sum: f64,
    pub sum_d: Vec<f64>,
    pub sdd: Vec<f64>,
    /// First sample ever seen (empty if none).
    pub first: Vec<f64>,
    /// Last sample of the open sequence (empty if none is open).
    pub last: Vec<f64>,
    /// Products formed in f32 per block (see [`Accumulator::set_mixed_precision`]).
    pub mixed: bool,
}

mod batch;

pub use crate::moments::set_block_rows;
use crate::moments::*;
pub use batch::{GraphPart, RowMap};

impl Accumulator {
    /// An empty accumulator for `dim`-dimensional samples.
    pub fn new(dim: usize) -> Result<Self> {
        if dim == 0 {
            return Err(SfaError::InvalidArgument("statistics need at least one feature".into()));
        }
        let what = || format!("statistics of {dim} features (two {dim} x {dim} matrices)");
        crate::memory::check(what, crate::memory::bytes_of(16, &[dim, dim]))?;
        let matrix = || crate::memory::zeros(dim, dim, what);
        Ok(Accumulator {
            dim,
            shift: None,
            n_samples: 0,
            weight_sum: 0.0,
            sum: vec![0.0; dim],
            sxx: matrix()?,
            n_pairs: 0,
            pair_weight_sum: 0.0,
            sum_d: vec![0.0; dim],
            sdd: matrix()?,
            first: None,
            last: None,
            mixed: false,
        })
    }

    /// An empty accumulator whose sums are taken relative to `reference`
    /// (instead of the first sample): pick a point near the data, e.g. an
    /// expected mean. Fails on an empty or non-finite reference.
    pub fn with_reference(reference: Vec<f64>) -> Result<Self> {
        let mut a = Accumulator::new(reference.len())?;
        if let Some(col) = reference.iter().position(|v| !v.is_finite()) {
            return Err(SfaError::NonFinite { what: "reference point", row: 0, col });
        }
        a.shift = Some(reference);
        Ok(a)
    }

    /// `scale x (lattice sums) - self`, for `periodic.rs`: `self` holds
    /// correction rows relative to a zero reference in coordinates already
    /// centred at `shift`; `sxx` / `sdd` (lower triangles used) and the sums
    /// are the scaled lattice moments in the same coordinates. Reuses the
    /// given matrices (no d x d copies).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn lattice_minus(
        &self,
        shift: Vec<f64>,
        (n_samples, weight_sum, mut sum, mut sxx): (u64, f64, Vec<f64>, Mat<f64>),
        (n_pairs, pair_weight_sum, mut sum_d, mut sdd): (u64, f64, Vec<f64>, Mat<f64>),
    ) -> Accumulator {
        let sub = |dst: &mut Mat<f64>, src: &Mat<f64>| {
            let d = src.nrows();
            for j in 0..d {
                let dc = dst.col_mut(j).try_as_col_major_mut().expect("contiguous");
                let sc = src.col(j).try_as_col_major().expect("contiguous");
                dc.as_slice_mut()[j..].iter_mut().zip(&sc.as_slice()[j..]).for_each(|(a, b)| *a -= b);
            }
        };
        sub(&mut sxx, &self.sxx);
        sub(&mut sdd, &self.sdd);
        sum.iter_mut().zip(&self.sum).for_each(|(a, b)| *a -= b);
        sum_d.iter_mut().zip(&self.sum_d).for_each(|(a, b)| *a -= b);
        Accumulator {
            dim: self.dim,
            shift: Some(shift),
            n_samples,
            weight_sum: weight_sum - self.weight_sum,
            sum,
            sxx,
            n_pairs,
            pair_weight_sum: pair_weight_sum - self.pair_weight_sum,
            sum_d,
            sdd,
            first: None,
            last: None,
            mixed: self.mixed,
        }
    }

    /// Mixed precision: outer products of each cache-sized block of rows are
    /// formed in f32 and summed into the f64 totals (faster: `docs/benchmarks.md`;
    /// relative error of the moments about 1e-6 instead of 1e-15). Rows are
    /// still centred in f64 first. Meant for image data, which carries far
    /// fewer significant digits.
    pub fn set_mixed_precision(&mut self, mixed: bool) {
        self.mixed = mixed;
    }

    /// Whether products are formed in f32 (see [`set_mixed_precision`](Self::set_mixed_precision)).
    pub fn is_mixed_precision(&self) -> bool {
        self.mixed
    }

    /// Sample dimension.
    pub fn dim(&self) -> usize {
        self.dim
    }
    /// Number of samples added (unweighted count).
    pub fn n_samples(&self) -> u64 {
        self.n_samples
    }
    /// Sum of sample weights (equals `n_samples` for unit weights).
    pub fn weight_sum(&self) -> f64 {
        self.weight_sum
    }
    /// Number of derivative pairs added (unweighted count).
    pub fn n_pairs(&self) -> u64 {
        self.n_pairs
    }
    /// Sum of derivative-pair weights.
    pub fn pair_weight_sum(&self) -> f64 {
        self.pair_weight_sum
    }

    fn check_width<T: Sample>(&self, x: &View<'_, T>) -> Result<()> {
        if x.ncols() != self.dim {
            return Err(SfaError::ShapeMismatch { what: "number of features", expected: self.dim, got: x.ncols() });
        }
        Ok(())
    }

    fn ensure_shift<T: Sample>(&mut self, x: &View<'_, T>, what: &'static str) -> Result<()> {
        if self.shift.is_none() && x.nrows() > 0 {
            let mut s = vec![0.0; self.dim];
            x.row_into(0, None, &mut s);
            if let Some(col) = s.iter().position(|v| !v.is_finite()) {
                return Err(SfaError::NonFinite { what, row: 0, col });
            }
            self.first = Some(s.clone());
            self.shift = Some(s);
        }
        Ok(())
    }

    /// Ends the open sequence: the next [`update`](Self::update) forms no
    /// derivative pair with the samples seen so far.
    pub fn break_sequence(&mut self) {
        self.last = None;
    }

    /// Feeds a chunk of a time series (rows are consecutive samples).
    ///
    /// Every row is a unit-weight sample; every consecutive pair of rows is a
    /// unit-weight derivative pair. Unless `new_sequence` is true, the last
    /// row of the previous call and the first row of this one also form a
    /// pair, so feeding a series in chunks equals feeding it at once.
    pub fn update<T: Sample>(&mut self, x: View<'_, T>, new_sequence: bool) -> Result<()> {
        self.check_width(&x)?;
        if new_sequence {
            self.last = None;
        }
        let n = x.nrows();
        if n == 0 {
            return Ok(());
        }
        self.ensure_shift(&x, "input")?;
        let d = self.dim;
        let shift = self.shift.as_deref().expect("shift set");
        // The carried sample, centred like the others.
        let carry: Option<Vec<f64>> = self.last.as_ref().map(|l| l.iter().zip(shift).map(|(a, b)| a - b).collect());
        let m = parallel_moments(n, d, Kind::Both, self.mixed, "input", |s, e, cb, db, sum, sum_d| {
            let nr = e - s;
            for (k, i) in (s..e).enumerate() {
                let row = &mut cb[k * d..(k + 1) * d];
                x.row_into(i, Some(shift), row);
                if let Some(j) = first_non_finite(row) {
                    return Err((i, j));
                }
                sum.iter_mut().zip(row.iter()).for_each(|(a, v)| *a += v);
            }
            // Derivative rows c[i] - c[i-1]; the sample before this block is
            // re-read (or is the carried sample at the start of the call).
            let before: Option<Vec<f64>> = if s > 0 {
                let mut r = vec![0.0; d];
                x.row_into(s - 1, Some(shift), &mut r);
                Some(r)
            } else {
                carry.clone()
            };
            let mut nd = 0;
            if let Some(b) = &before {
                db[..d].iter_mut().zip(cb[..d].iter().zip(b)).for_each(|(o, (c, p))| *o = c - p);
                nd = 1;
            }
            for k in 1..nr {
                let (prev, cur) = (&cb[(k - 1) * d..k * d], &cb[k * d..(k + 1) * d]);
                db[nd * d..(nd + 1) * d].iter_mut().zip(cur.iter().zip(prev)).for_each(|(o, (c, p))| *o = c - p);
                nd += 1;
            }
            for row in db[..nd * d].chunks_exact(d) {
                sum_d.iter_mut().zip(row).for_each(|(a, v)| *a += v);
            }
            Ok((nr, nd))
        })?;
        self.absorb(&m);
        self.n_samples += n as u64;
        self.weight_sum += n as f64;
        self.pair_weight_sum += m.n_pairs as f64;
        let mut last = vec![0.0; d];
        x.row_into(n - 1, None, &mut last);
        self.last = Some(last);
        Ok(())
    }

    /// Adds gathered moments (lower triangles) into the running sums.
    fn absorb(&mut self, m: &Moments) {
        add_lower(&mut self.sxx, &m.sxx);
        add_lower(&mut self.sdd, &m.sdd);
        self.sum.iter_mut().zip(&m.sum).for_each(|(a, b)| *a += b);
        self.sum_d.iter_mut().zip(&m.sum_d).for_each(|(a, b)| *a += b);
        self.n_pairs += m.n_pairs;
    }

    /// Adds samples with optional non-negative weights (default 1). Forms no
    /// derivative pairs and does not touch the open sequence.
    pub fn add_samples<T: Sample>(&mut self, x: View<'_, T>, weights: Option<&[f64]>) -> Result<()> {
        self.check_width(&x)?;
        check_weights(weights, x.nrows(), "sample weights")?;
        if x.nrows() == 0 {
            return Ok(());
        }
        self.ensure_shift(&x, "samples")?;
        let m = self.sample_moments(&x, weights)?;
        self.absorb_samples(&m, x.nrows(), weights);
        Ok(())
    }

    /// Weighted sample moments of `x` (checked, shift set), not yet added.
    fn sample_moments<T: Sample>(&self, x: &View<'_, T>, weights: Option<&[f64]>) -> Result<Moments> {
        let d = self.dim;
        let shift = self.shift.as_deref().expect("shift set");
        parallel_moments(x.nrows(), d, Kind::Samples, self.mixed, "samples", |s, e, cb, _db, sum, _sum_d| {
            let mut k = 0;
            for i in s..e {
                let row = &mut cb[k * d..(k + 1) * d];
                x.row_into(i, Some(shift), row);
                if let Some(j) = first_non_finite(row) {
                    return Err((i, j));
                }
                let w = weights.map_or(1.0, |w| w[i]);
                if w == 0.0 {
                    // Contributes nothing (a pair end only): no product work.
                    continue;
                }
                let sw = w.sqrt();
                for (a, v) in sum.iter_mut().zip(row.iter_mut()) {
                    *a += w * *v;
                    *v *= sw;
                }
                k += 1;
            }
            Ok((k, 0))
        })
    }

    fn absorb_samples(&mut self, m: &Moments, n: usize, weights: Option<&[f64]>) {
        self.absorb(m);
        self.n_samples += n as u64;
        self.weight_sum += weights.map_or(n as f64, |w| w.iter().sum());
    }

    fn absorb_pairs(&mut self, m: &Moments, n: usize, weights: Option<&[f64]>) {
        self.absorb(m);
        self.pair_weight_sum += weights.map_or(n as f64, |w| w.iter().sum());
    }

    /// Adds derivative pairs `d_i = b_i - a_i` with optional non-negative
    /// weights (default 1). Touches neither the sample moments nor the open
    /// sequence.
    pub fn add_pairs<T: Sample>(&mut self, a: View<'_, T>, b: View<'_, T>, weights: Option<&[f64]>) -> Result<()> {
        self.check_width(&a)?;
        self.check_width(&b)?;
        if a.nrows() != b.nrows() {
            return Err(SfaError::ShapeMismatch {
                what: "number of pair ends (rows of b vs rows of a)",
                expected: a.nrows(),
                got: b.nrows(),
            });
        }
        let n = a.nrows();
        check_weights(weights, n, "pair weights")?;
        if n == 0 {
            return Ok(());
        }
        let m = self.pair_moments(n, weights, |i, row, _tmp| {
            b.row_into(i, None, row);
            for (j, o) in row.iter_mut().enumerate() {
                *o -= a.get(i, j).to_f64();
            }
        })?;
        self.absorb_pairs(&m, n, weights);
        Ok(())
    }

    /// Adds derivative rows `d_i` directly (when the caller already holds
    /// the differences), with optional non-negative weights (default 1).
    pub fn add_differences<T: Sample>(&mut self, dx: View<'_, T>, weights: Option<&[f64]>) -> Result<()> {
        self.check_width(&dx)?;
        let n = dx.nrows();
        check_weights(weights, n, "difference weights")?;
        if n == 0 {
            return Ok(());
        }
        let m = self.pair_moments(n, weights, |i, row, _tmp| dx.row_into(i, None, row))?;
        self.absorb_pairs(&m, n, weights);
        Ok(())
    }

    /// Moments of `n` weighted derivative rows, not yet added;
    /// `diff(i, row, scratch)` writes pair `i`'s difference into `row`.
    fn pair_moments<F>(&self, n: usize, weights: Option<&[f64]>, diff: F) -> Result<Moments>
    where
        F: Fn(usize, &mut [f64], &mut [f64]) + Sync,
    {
        let d = self.dim;
        parallel_moments(n, d, Kind::Pairs, self.mixed, "pairs", |s, e, _cb, db, _sum, sum_d| {
            let mut tmp = vec![0.0; d];
            for (k, i) in (s..e).enumerate() {
                let row = &mut db[k * d..(k + 1) * d];
                diff(i, row, &mut tmp);
                if let Some(j) = first_non_finite(row) {
                    return Err((i, j));
                }
                let w = weights.map_or(1.0, |w| w[i]);
                let sw = w.sqrt();
                for (acc, v) in sum_d.iter_mut().zip(row.iter_mut()) {
                    *acc += w * *v;
                    *v *= sw;
                }
            }
            Ok((0, e - s))
        })
    }

    fn check_edges<T: Sample>(x: &View<'_, T>, edges: &[[usize; 2]], weights: Option<&[f64]>) -> Result<()> {
        check_weights(weights, edges.len(), "pair weights")?;
        if let Some(e) = edges.iter().find(|e| e[0] >= x.nrows() || e[1] >= x.nrows()) {
            return Err(SfaError::InvalidArgument(format!(
                "pair ({}, {}) refers to a sample outside 0..{}",
                e[0],
                e[1],
                x.nrows()
            )));
        }
        Ok(())
    }

    /// Moments of the indexed pairs `x[b] - x[a]` (checked), not yet added.
    fn indexed_pair_moments<T: Sample>(
        &self,
        x: &View<'_, T>,
        edges: &[[usize; 2]],
        weights: Option<&[f64]>,
    ) -> Result<Moments> {
        self.pair_moments(edges.len(), weights, |i, row, tmp| {
            let [ia, ib] = edges[i];
            x.row_into(ib, None, row);
            x.row_into(ia, None, tmp);
            row.iter_mut().zip(tmp.iter()).for_each(|(r, t)| *r -= t);
        })
    }

    /// Adds derivative pairs given as row indices into `x`: pair `i` is
    /// `x[edges[i][1]] - x[edges[i][0]]`, with optional non-negative weights
    /// (default 1). This is how graph-structured training (simulated
    /// rotation with multiplicities, graph-based SFA) feeds pairs without
    /// materialising both ends.
    pub fn add_pairs_indexed<T: Sample>(
        &mut self,
        x: View<'_, T>,
        edges: &[[usize; 2]],
        weights: Option<&[f64]>,
    ) -> Result<()> {
        self.check_width(&x)?;
        Self::check_edges(&x, edges, weights)?;
        if edges.is_empty() {
            return Ok(());
        }
        let m = self.indexed_pair_moments(&x, edges, weights)?;
        self.absorb_pairs(&m, edges.len(), weights);
        Ok(())
    }

    /// A weighted sample graph at once: every row of `x` is a sample
    /// (`add_samples`) and every edge a derivative pair (`add_pairs_indexed`).
    /// Everything is checked and gathered before anything is added, so on
    /// error the statistics are unchanged (no copy of them is needed).
    pub fn add_graph<T: Sample>(
        &mut self,
        x: View<'_, T>,
        sample_weights: Option<&[f64]>,
        edges: &[[usize; 2]],
        edge_weights: Option<&[f64]>,
    ) -> Result<()> {
        self.add_graphs(&[GraphPart { x, weights: sample_weights, edges, edge_weights }], None)
    }

    /// Adds everything `other` accumulated (exact up to rounding). No
    /// derivative pair is formed between the two; the open sequence of `self`
    /// stays open. Use [`merge_continuing`](Self::merge_continuing) when
    /// `other` holds the continuation of `self`'s sequence.
    pub fn merge(&mut self, other: &Accumulator) -> Result<()> {
        if other.dim != self.dim {
            return Err(SfaError::ShapeMismatch {
                what: "dimension of the merged statistics",
                expected: self.dim,
                got: other.dim,
            });
        }
        let Some(ob) = other.shift.as_ref() else {
            // `other` has no samples; pairs may still be present.
            self.merge_pairs(other);
            return Ok(());
        };
        if self.shift.is_none() {
            self.shift = Some(ob.clone());
            self.first = other.first.clone();
        }
        let a = self.shift.as_ref().expect("shift set");
        let d = self.dim;
        // Re-reference other's sums from its shift b to our shift a:
        // x - a = (x - b) + delta, delta = b - a.
        let delta: Vec<f64> = ob.iter().zip(a).map(|(b, a)| b - a).collect();
        let w = other.weight_sum;
        for i in 0..d {
            for j in 0..=i {
                let v = other.sxx[(i, j)] + other.sum[i] * delta[j] + delta[i] * other.sum[j] + w * delta[i] * delta[j];
                self.sxx[(i, j)] += v;
            }
            self.sum[i] += other.sum[i] + w * delta[i];
        }
        self.n_samples += other.n_samples;
        self.weight_sum += w;
        self.merge_pairs(other);
        Ok(())
    }

    fn merge_pairs(&mut self, other: &Accumulator) {
        let d = self.dim;
        for i in 0..d {
            for j in 0..=i {
                self.sdd[(i, j)] += other.sdd[(i, j)];
            }
            self.sum_d[i] += other.sum_d[i];
        }
        self.n_pairs += other.n_pairs;
        self.pair_weight_sum += other.pair_weight_sum;
    }

    /// Merges `other` as the continuation of this accumulator's open
    /// sequence: also adds the derivative pair from our last sample to
    /// `other`'s first, and `other`'s open sequence becomes ours. This makes
    /// splitting one long series across workers exact.
    pub fn merge_continuing(&mut self, other: &Accumulator) -> Result<()> {
        let bridge = match (&self.last, &other.first) {
            (Some(l), Some(f)) => Some((l.clone(), f.clone())),
            _ => None,
        };
        self.merge(other)?;
        if let Some((l, f)) = bridge {
            let d = self.dim;
            self.add_pairs(View::from_slice(&l, 1, d)?, View::from_slice(&f, 1, d)?, None)?;
        }
        self.last = other.last.clone();
        Ok(())
    }

    /// Weighted mean of the samples.
    pub fn mean(&self) -> Result<Vec<f64>> {
        self.require_samples(1)?;
        let shift = self.shift.as_ref().expect("shift set");
        Ok(shift.iter().zip(&self.sum).map(|(s, v)| s + v / self.weight_sum).collect())
    }

    fn require_samples(&self, needed: usize) -> Result<()> {
        if self.n_samples > 0 && self.weight_sum <= 0.0 {
            return Err(SfaError::InvalidArgument(format!(
                "the weights of all {} training samples are 0: at least one sample needs a positive weight",
                self.n_samples
            )));
        }
        if (self.n_samples as usize) < needed {
            return Err(SfaError::TooFewSamples {
                what: "number of training samples",
                needed,
                got: self.n_samples as usize,
            });
        }
        Ok(())
    }

    /// Population covariance of the samples (full symmetric `dim x dim`).
    pub fn covariance(&self) -> Result<Mat<f64>> {
        self.require_samples(2)?;
        let w = self.weight_sum;
        let d = self.dim;
        let mu: Vec<f64> = self.sum.iter().map(|v| v / w).collect();
        let mut c = crate::memory::zeros(d, d, || format!("a covariance matrix of {d} features"))?;
        for i in 0..d {
            for j in 0..=i {
                let v = self.sxx[(i, j)] / w - mu[i] * mu[j];
                c[(i, j)] = v;
                c[(j, i)] = v;
            }
        }
        Ok(c)
    }

    /// Uncentered covariance of the derivative pairs, `sum w d d^T / sum w`.
    pub fn derivative_covariance(&self) -> Result<Mat<f64>> {
        if self.n_pairs == 0 || self.pair_weight_sum <= 0.0 {
            return Err(SfaError::TooFewSamples {
                what: "number of derivative pairs (consecutive samples of one sequence)",
                needed: 1,
                got: 0,
            });
        }
        let w = self.pair_weight_sum;
        let d = self.dim;
        let mut c = crate::memory::zeros(d, d, || format!("a derivative covariance matrix of {d} features"))?;
        for i in 0..d {
            for j in 0..=i {
                let v = self.sdd[(i, j)] / w;
                c[(i, j)] = v;
                c[(j, i)] = v;
            }
        }
        Ok(c)
    }

    /// Weighted mean of the derivative (diagnostic: near zero on long series).
    pub fn derivative_mean(&self) -> Result<Vec<f64>> {
        if self.pair_weight_sum <= 0.0 {
            return Err(SfaError::TooFewSamples { what: "number of derivative pairs", needed: 1, got: 0 });
        }
        Ok(self.sum_d.iter().map(|v| v / self.pair_weight_sum).collect())
    }

    /// The accumulator's plain-data state.
    pub fn state(&self) -> AccumulatorState {
        let d = self.dim;
        let full = |m: &Mat<f64>| {
            let mut v = vec![0.0; d * d];
            for i in 0..d {
                for j in 0..=i {
                    v[i * d + j] = m[(i, j)];
                    v[j * d + i] = m[(i, j)];
                }
            }
            v
        };
        AccumulatorState {
            dim: d,
            shift: self.shift.clone().unwrap_or_default(),
            n_samples: self.n_samples,
            weight_sum: self.weight_sum,
            sum: self.sum.clone(),
            sxx: full(&self.sxx),
            n_pairs: self.n_pairs,
            pair_weight_sum: self.pair_weight_sum,
            sum_d: self.sum_d.clone(),
            sdd: full(&self.sdd),
            first: self.first.clone().unwrap_or_default(),
            last: self.last.clone().unwrap_or_default(),
            mixed: self.mixed,
        }
    }

    /// Restores an accumulator from [`state`](Self::state), checking shapes
    /// and values.
    pub fn from_state(s: &AccumulatorState) -> Result<Self> {
        let d = s.dim;
        let bad = |m: String| Err(SfaError::InvalidState(format!("statistics: {m}")));
        if d == 0 {
            return bad("dimension is 0".into());
        }
        let Some(dd) = d.checked_mul(d) else {
            return bad(format!("dimension {d} is too large"));
        };
        for (name, len, want) in
            [("sum", s.sum.len(), d), ("sum_d", s.sum_d.len(), d), ("sxx", s.sxx.len(), dd), ("sdd", s.sdd.len(), dd)]
        {
            if len != want {
                return bad(format!("{name} has {len} values, expected {want}"));
            }
        }
        for (name, v) in [("shift", &s.shift), ("first", &s.first), ("last", &s.last)] {
            if !(v.is_empty() || v.len() == d) {
                return bad(format!("{name} has {} values, expected 0 or {d}", v.len()));
            }
        }
        let all = [&s.shift, &s.sum, &s.sxx, &s.sum_d, &s.sdd, &s.first, &s.last];
        if all.iter().any(|v| v.iter().any(|x| !x.is_finite()))
            || !s.weight_sum.is_finite()
            || !s.pair_weight_sum.is_finite()
            || s.weight_sum < 0.0
            || s.pair_weight_sum < 0.0
        {
            return bad("non-finite or negative values".into());
        }
        if s.n_samples > 0 && s.shift.is_empty() {
            // (A reference point without samples is fine: `with_reference`.)
            return bad("sample count and reference point disagree".into());
        }
        let mat = |v: &Vec<f64>| -> Result<Mat<f64>> {
            let mut m = crate::memory::zeros(d, d, || format!("statistics of {d} features"))?;
            for j in 0..d {
                for i in 0..d {
                    m[(i, j)] = v[i * d + j];
                }
            }
            Ok(m)
        };
        Ok(Accumulator {
            dim: d,
            shift: (!s.shift.is_empty()).then(|| s.shift.clone()),
            n_samples: s.n_samples,
            weight_sum: s.weight_sum,
            sum: s.sum.clone(),
            sxx: mat(&s.sxx)?,
            n_pairs: s.n_pairs,
            pair_weight_sum: s.pair_weight_sum,
            sum_d: s.sum_d.clone(),
            sdd: mat(&s.sdd)?,
            first: (!s.first.is_empty()).then(|| s.first.clone()),
            last: (!s.last.is_empty()).then(|| s.last.clone()),
            mixed: s.mixed,
        })
    }
}
