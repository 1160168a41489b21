//! The kernels behind [`crate::stats::Accumulator`]: centred row blocks
//! multiplied into lower-triangular moment sums (f64, or f32 products summed
//! in f64), in parallel over contiguous row ranges, with finite and weight
//! checks. Private to the crate.

use crate::error::{Result, SfaError};
use faer::linalg::matmul::triangular::{matmul as tri_matmul, BlockStructure};
use faer::{Accum, Mat, MatRef, Par};
use rayon::prelude::*;

static BLOCK_ROWS_OVERRIDE: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// Overrides the rows per block (0 restores the default). For tests that
/// must cross block boundaries on small data; results do not depend on it
/// beyond rounding.
#[doc(hidden)]
pub fn set_block_rows(rows: usize) {
    BLOCK_ROWS_OVERRIDE.store(rows, std::sync::atomic::Ordering::Relaxed);
}

/// Rows per sub-block a worker converts and multiplies at a time: about
/// 512 KB per buffer, so the converted rows are still in the core's cache
/// when the product reads them (measured in `docs/benchmarks.md`).
pub(crate) fn block_rows(dim: usize) -> usize {
    match BLOCK_ROWS_OVERRIDE.load(std::sync::atomic::Ordering::Relaxed) {
        0 => ((1usize << 16) / dim.max(1)).clamp(64, 1 << 13),
        r => r,
    }
}

/// Most rows whose products are summed in f32 before they are added to
/// the f64 sums (mixed precision): bounds the f32 rounding of a moment to
/// about 256 ulp, whatever the number of rows fed in one call.
const MIXED_BLOCK_ROWS: usize = 256;

/// Fewest rows worth a parallel part of their own: about 2^25 multiply-adds
/// of SYRK work (372 rows at d = 300, 2048 at d = 128), so that one image's
/// patches of a 300-dim layer (1800 rows in Table 5.2 layer 2) still use
/// every thread, while tiny dimensions do not pay for a second d x d
/// matrix per thread.
pub(crate) fn min_rows_per_part(d: usize) -> usize {
    ((1usize << 25) / (d * d).max(1)).clamp(64, 1 << 16)
}

/// `dst += rows^T rows` on the lower triangle; `rows` is row-major `n x d`.
/// Sequential: parallelism is over row ranges (see [`parallel_moments`]).
pub(crate) fn syrk_add(dst: &mut Mat<f64>, rows: &[f64], n: usize, d: usize) {
    if n == 0 {
        return;
    }
    let m = MatRef::from_row_major_slice(rows, n, d);
    tri_matmul(
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

/// Mixed precision: `dst += rows^T rows` with the block's products formed in
/// f32 (`tmp` holds the block result) and added into the f64 sums.
pub(crate) fn syrk_add_mixed(
    dst: &mut Mat<f64>,
    rows: &[f64],
    n: usize,
    d: usize,
    buf: &mut Vec<f32>,
    tmp: &mut Mat<f32>,
) {
    if n == 0 {
        return;
    }
    buf.clear();
    buf.extend(rows[..n * d].iter().map(|&v| v as f32));
    let m = MatRef::from_row_major_slice(&buf[..], n, d);
    tri_matmul(
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
        let dc = dst.col_mut(j).try_as_col_major_mut().expect("contiguous");
        let tc = tmp.col(j).try_as_col_major().expect("contiguous");
        dc.as_slice_mut()[j..].iter_mut().zip(&tc.as_slice()[j..]).for_each(|(a, b)| *a += *b as f64);
    }
}

/// Which moment sets a [`parallel_moments`] call gathers.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum Kind {
    Samples,
    Pairs,
    Both,
}

impl Kind {
    fn samples(self) -> bool {
        self != Kind::Pairs
    }
    fn pairs(self) -> bool {
        self != Kind::Samples
    }
}

/// Moments gathered from a range of rows (lower triangles only). A moment
/// set a call does not gather stays a 0 x 0 matrix: no allocation, nothing
/// to add (a d x d f64 matrix is 1.5 MB at d = 432, and these are made per
/// call and per thread).
pub(crate) struct Moments {
    pub(crate) sxx: Mat<f64>,
    pub(crate) sdd: Mat<f64>,
    pub(crate) sum: Vec<f64>,
    pub(crate) sum_d: Vec<f64>,
    pub(crate) n_pairs: u64,
}

impl Moments {
    pub(crate) fn zeros(d: usize, kind: Kind) -> Self {
        let ds = if kind.samples() { d } else { 0 };
        let dp = if kind.pairs() { d } else { 0 };
        Moments { sxx: Mat::zeros(ds, ds), sdd: Mat::zeros(dp, dp), sum: vec![0.0; d], sum_d: vec![0.0; d], n_pairs: 0 }
    }

    /// No moments at all (nothing to add).
    pub(crate) fn empty(d: usize) -> Self {
        Moments { sxx: Mat::zeros(0, 0), sdd: Mat::zeros(0, 0), sum: vec![0.0; d], sum_d: vec![0.0; d], n_pairs: 0 }
    }

    pub(crate) fn add(&mut self, o: &Moments) {
        add_lower(&mut self.sxx, &o.sxx);
        add_lower(&mut self.sdd, &o.sdd);
        self.sum.iter_mut().zip(&o.sum).for_each(|(a, b)| *a += b);
        self.sum_d.iter_mut().zip(&o.sum_d).for_each(|(a, b)| *a += b);
        self.n_pairs += o.n_pairs;
    }
}

/// `dst += src` on the lower triangle; a 0 x 0 `src` adds nothing.
pub(crate) fn add_lower(dst: &mut Mat<f64>, src: &Mat<f64>) {
    let d = src.nrows();
    if d == 0 {
        return;
    }
    debug_assert_eq!(dst.nrows(), d);
    for j in 0..d {
        let (dc, sc) = (
            dst.col_mut(j).try_as_col_major_mut().expect("contiguous"),
            src.col(j).try_as_col_major().expect("contiguous"),
        );
        dc.as_slice_mut()[j..].iter_mut().zip(&sc.as_slice()[j..]).for_each(|(a, b)| *a += b);
    }
}

/// What a fill callback returns for rows `start..end`: it writes sample rows
/// into the first buffer and derivative-pair rows into the second (both
/// centred and multiplied by the square root of their weights), adds the
/// weighted sums to the two sum vectors, and returns the number of sample
/// rows and pair rows written, or the first non-finite element `(row, col)`.
type Filled = std::result::Result<(usize, usize), (usize, usize)>;

/// Most contiguous parts [`parallel_moments`] splits its rows into (and so
/// the most threads it keeps busy). The split depends on the data's shape
/// only, never on the thread count, so results are bit-identical whatever
/// `set_num_threads` says.
pub(crate) const MAX_PARTS: usize = 16;

/// Splits rows `0..n` into at most [`MAX_PARTS`] contiguous parts of at
/// least [`min_rows_per_part`] rows; each part converts its rows block by
/// block (`fill`) and multiplies them into its own moments with a
/// sequential SYRK; parts are summed in order. The partition and the order
/// of the sums depend on `n` and `d` only, so the result is the same for
/// every thread count. (Splitting the long row dimension beats splitting
/// the small `d x d` output; measured in `docs/benchmarks.md`.)
pub(crate) fn parallel_moments<F>(
    n: usize,
    d: usize,
    kind: Kind,
    mixed: bool,
    what: &'static str,
    fill: F,
) -> Result<Moments>
where
    F: Fn(usize, usize, &mut [f64], &mut [f64], &mut [f64], &mut [f64]) -> Filled + Sync,
{
    let parts = MAX_PARTS.min(n.div_ceil(min_rows_per_part(d))).max(1);
    let per = n.div_ceil(parts);
    let br = if mixed { block_rows(d).min(MIXED_BLOCK_ROWS) } else { block_rows(d) };
    let results: Vec<std::result::Result<Moments, (usize, usize)>> = (0..parts)
        .into_par_iter()
        .map(|p| {
            let (lo, hi) = (p * per, ((p + 1) * per).min(n));
            let mut m = Moments::zeros(d, kind);
            let rows = br.min(hi.saturating_sub(lo)).max(1);
            let mut cbuf = vec![0.0; if kind.samples() { rows * d } else { 0 }];
            let mut dbuf = vec![0.0; if kind.pairs() { rows * d } else { 0 }];
            let (mut buf32, mut tmp32) = if mixed {
                (Vec::with_capacity(rows * d), Mat::<f32>::zeros(d, d))
            } else {
                (Vec::new(), Mat::<f32>::zeros(0, 0))
            };
            let mut s = lo;
            while s < hi {
                let e = (s + br).min(hi);
                let (nc, nd) = fill(s, e, &mut cbuf, &mut dbuf, &mut m.sum, &mut m.sum_d)?;
                if mixed {
                    syrk_add_mixed(&mut m.sxx, &cbuf, nc, d, &mut buf32, &mut tmp32);
                    syrk_add_mixed(&mut m.sdd, &dbuf, nd, d, &mut buf32, &mut tmp32);
                } else {
                    syrk_add(&mut m.sxx, &cbuf[..nc * d], nc, d);
                    syrk_add(&mut m.sdd, &dbuf[..nd * d], nd, d);
                }
                m.n_pairs += nd as u64;
                s = e;
            }
            Ok(m)
        })
        .collect();
    let mut total: Option<Moments> = None;
    for r in results {
        match r {
            Ok(m) => match total.as_mut() {
                None => total = Some(m),
                Some(t) => t.add(&m),
            },
            Err((row, col)) => return Err(SfaError::NonFinite { what, row, col }),
        }
    }
    Ok(total.unwrap_or_else(|| Moments::zeros(d, kind)))
}

#[inline]
pub(crate) fn first_non_finite(row: &[f64]) -> Option<usize> {
    if row.iter().all(|v| v.is_finite()) {
        None
    } else {
        row.iter().position(|v| !v.is_finite())
    }
}

pub(crate) fn check_weights(w: Option<&[f64]>, n: usize, what: &'static str) -> Result<()> {
    if let Some(w) = w {
        if w.len() != n {
            return Err(SfaError::ShapeMismatch { what, expected: n, got: w.len() });
        }
        if let Some(i) = w.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(SfaError::InvalidArgument(format!(
                "{what}: weights must be finite and non-negative (index {i} is {})",
                w[i]
            )));
        }
    }
    Ok(())
}
