//! Moments of all periodic patches of an image at once: the first layer's
//! linear statistics on the fast rotation path, from lag products.
//!
//! On the fast path ([`crate::rotation`]) layer 1 sees, per RF row `r`, the
//! patches `P(r, o)` of the periodic panorama at column offsets `o`, with a
//! sample multiplicity `w(o)` and a pair multiplicity `p(o)` for the
//! derivative `P(r, o + s) - P(r, o)`. Its first node stage is linear, so its
//! statistics are sums of outer products of raw patches, and patches at
//! neighbouring offsets share all but one column. Write `a_r(c)` for column
//! `c` of RF row `r` (its `rf_h x channels` values). If the offsets form the
//! lattice `o = 0, g, 2g, ...` (mod `W`) with one common weight, the block
//! of the patch second moment between patch columns `m <= m'` is
//!
//! ```text
//!   sum_{o in lattice} a(o + m) a(o + m')^T = H(m mod g, m' - m),
//!   H(rho, delta) = sum_{c = rho mod g} a(c) a(c + delta)^T,
//! ```
//!
//! a lag product: `g x rf_w` small matrices per row instead of one `d x d`
//! outer product per patch (`d = rf_w rf_h channels`). The derivative
//! moments are the same with the difference image `a(c + s) - a(c)`.
//! Real multiplicities are nearly uniform (Table 5.2: 19 or 20 per offset),
//! so the moments are `w_max` times the lattice sums minus a correction
//! accumulated from the few offsets with `w(o) < w_max`, as ordinary rows.
//! For Table 5.2 layer 1 this is about 0.44 of the multiply-adds of one
//! outer product per patch. Exact up to rounding; the caller falls back to
//! the plain path when the plan does not pay ([`plan`] returns None).

use crate::error::{Result, SfaError};
use crate::network::LayerGeometry;
use crate::stats::Accumulator;
use crate::view::{Sample, View};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};
use rayon::prelude::*;

/// How one image's lattice moments are formed (see the module docs).
#[derive(Clone, Debug)]
pub(crate) struct Plan {
    /// Lattice spacing `g` (divides the period).
    g: usize,
    /// Largest sample / pair multiplicity on the lattice.
    w_max: f64,
    p_max: f64,
    /// Lattice offsets whose multiplicity falls short of the maximum, with
    /// the shortfall (subtracted as weighted rows).
    short_samples: Vec<(usize, f64)>,
    short_pairs: Vec<(usize, f64)>,
    /// Offsets with a positive multiplicity (the unweighted counts).
    n_samples: usize,
    n_pairs: usize,
    /// The period (panorama width) the plan is for.
    period: usize,
}

fn gcd(a: usize, b: usize) -> usize {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

/// The plan for layer-0 geometry `geom`, period `w`, per-column sample and
/// pair multiplicities (length `w`; zero where an offset is absent), or
/// None when one outer product per patch is cheaper.
pub(crate) fn plan(geom: &LayerGeometry, mult: &[f64], pmult: &[f64]) -> Option<Plan> {
    let w = mult.len();
    if w == 0 || pmult.len() != w {
        return None;
    }
    let g = (0..w).filter(|&o| mult[o] > 0.0 || pmult[o] > 0.0).fold(w, gcd);
    let lattice = (0..w).step_by(g);
    let w_max = lattice.clone().map(|o| mult[o]).fold(0.0, f64::max);
    let p_max = lattice.clone().map(|o| pmult[o]).fold(0.0, f64::max);
    if w_max <= 0.0 {
        return None;
    }
    let short = |m: &[f64], top: f64| -> Vec<(usize, f64)> {
        lattice.clone().filter(|&o| m[o] < top).map(|o| (o, top - m[o])).collect()
    };
    let short_samples = short(mult, w_max);
    let short_pairs = short(pmult, p_max);
    let n_samples = mult.iter().filter(|&&v| v > 0.0).count();
    let n_pairs = pmult.iter().filter(|&&v| v > 0.0).count();
    // Multiply-adds per RF row: lag products of the image and of its
    // difference image, plus the correction rows; against one (half) outer
    // product per weighted patch.
    let q = (geom.rf_h * geom.in_c) as f64;
    let d = geom.in_dim as f64;
    let lag = 2.0 * w as f64 * geom.rf_w as f64 * q * q;
    let rows = |n: usize| n as f64 * d * d / 2.0;
    let structured = lag + rows(short_samples.len() + short_pairs.len());
    let plain = rows(n_samples + n_pairs);
    (structured < 0.75 * plain).then_some(Plan {
        g,
        w_max,
        p_max,
        short_samples,
        short_pairs,
        n_samples,
        n_pairs,
        period: w,
    })
}

/// One RF row's columns, `(w + rf_w - 1) x q` row-major, wrapped around
/// the period so that the patch at column `c` is the contiguous run of rows
/// `c .. c + rf_w`. `value(col, dr, ch)` gives the entry.
fn columns<T: Sample>(geom: &LayerGeometry, w: usize, value: impl Fn(usize, usize, usize) -> f64) -> Vec<T> {
    let (q, c) = (geom.rf_h * geom.in_c, geom.in_c);
    let n = w + geom.rf_w - 1;
    let mut out = Vec::with_capacity(n * q);
    for col in 0..n {
        for dr in 0..geom.rf_h {
            for ch in 0..c {
                out.push(T::from_f64(value(col % w, dr, ch)));
            }
        }
    }
    out
}

/// Lag products and column sums of one wrapped column array (see
/// [`columns`]): `h[rho]` is `q x (rf_w q)` with block `delta` equal to
/// `H(rho, delta)`; `s[rho]` is the sum of the columns `c = rho mod g`.
fn lag_products<T>(cols: &[T], geom: &LayerGeometry, w: usize, g: usize, h: &mut [Mat<f64>], s: &mut [Vec<f64>])
where
    T: Sample + faer::traits::ComplexField,
{
    let q = geom.rf_h * geom.in_c;
    let wq = geom.rf_w * q;
    let n_rho = w / g;
    let mut tmp = Mat::<T>::zeros(q, wq);
    for rho in 0..g {
        let a = MatRef::from_row_major_slice_with_stride(&cols[rho * q..], n_rho, q, g * q);
        let b = MatRef::from_row_major_slice_with_stride(&cols[rho * q..], n_rho, wq, g * q);
        matmul(tmp.as_mut(), Accum::Replace, a.transpose(), b, <T as Sample>::from_f64(1.0), Par::Seq);
        let hr = &mut h[rho];
        for j in 0..wq {
            for i in 0..q {
                hr[(i, j)] += Sample::to_f64(tmp[(i, j)]);
            }
        }
        for i in 0..n_rho {
            let row = &cols[(rho + i * g) * q..(rho + i * g + 1) * q];
            s[rho].iter_mut().zip(row).for_each(|(acc, v)| *acc += Sample::to_f64(*v));
        }
    }
}

/// Lattice sums of one kind (samples or derivatives) over all RF rows.
struct LatticeSums {
    h: Vec<Mat<f64>>,
    s: Vec<Vec<f64>>,
}

impl LatticeSums {
    fn zeros(geom: &LayerGeometry, g: usize) -> Self {
        let q = geom.rf_h * geom.in_c;
        LatticeSums { h: (0..g).map(|_| Mat::zeros(q, geom.rf_w * q)).collect(), s: vec![vec![0.0; q]; g] }
    }

    fn add(&mut self, o: &LatticeSums) {
        for (a, b) in self.h.iter_mut().zip(&o.h) {
            *a += b;
        }
        for (a, b) in self.s.iter_mut().zip(&o.s) {
            a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
        }
    }

    /// The `d x d` second moment (lower triangle filled) and the `d` sum of
    /// the lattice patches (patch index `(dr * rf_w + m) * channels + ch`),
    /// times `scale`.
    fn assemble(&self, geom: &LayerGeometry, g: usize, scale: f64) -> (Vec<f64>, Mat<f64>) {
        let (rf_w, c, d) = (geom.rf_w, geom.in_c, geom.in_dim);
        let q = geom.rf_h * c;
        let idx = |dr: usize, m: usize, ch: usize| (dr * rf_w + m) * c + ch;
        let mut sxx = Mat::<f64>::zeros(d, d);
        for m in 0..rf_w {
            let hr = &self.h[m % g];
            for m2 in m..rf_w {
                let delta = m2 - m;
                for a in 0..q {
                    let i = idx(a / c, m, a % c);
                    for b in 0..q {
                        let j = idx(b / c, m2, b % c);
                        let v = scale * hr[(a, delta * q + b)];
                        if i >= j {
                            sxx[(i, j)] = v;
                        } else {
                            sxx[(j, i)] = v;
                        }
                    }
                }
            }
        }
        let mut sum = vec![0.0; d];
        for m in 0..rf_w {
            for a in 0..q {
                sum[idx(a / c, m, a % c)] = scale * self.s[m % g][a];
            }
        }
        (sum, sxx)
    }
}

/// One image's share of layer 0's periodic-patch statistics under a
/// [`Plan`]: its lattice sums (samples and derivatives) and its correction
/// rows (the shortfall offsets' patches and derivatives, centred, in patch
/// order), to be combined with other images' by [`lattice_moments`].
pub(crate) struct LatticeImage {
    plan: Plan,
    x: LatticeSums,
    dx: LatticeSums,
    short_x: Vec<f64>,
    short_d: Vec<f64>,
}

/// [`LatticeImage`] of one `in_h x period x in_c` image (row-major; the
/// network may see a narrower window): weighted samples `P(r, o)` and
/// weighted pairs `P(r, o + step) - P(r, o)`, centred at the per-channel
/// `reference` (e.g. the first image's channel means) repeated over the
/// patch. `mixed`: lag products in f32 summed in f64 per row and lattice
/// class (as the accumulator's mixed precision does).
pub(crate) fn lattice_image(
    geom: &LayerGeometry,
    plan: &Plan,
    image: &[f64],
    period: usize,
    step: usize,
    reference: &[f64],
    mixed: bool,
) -> LatticeImage {
    let (w, c, d) = (period, geom.in_c, geom.in_dim);
    debug_assert_eq!(image.len(), geom.in_h * w * c);
    let g = plan.g;
    let px = |row: usize, col: usize, ch: usize| image[(row * w + col) * c + ch];
    // Per RF row: lattice sums of centred patches and of derivatives, and
    // the correction rows (the shortfall offsets' patches).
    struct RowPart {
        x: LatticeSums,
        dx: LatticeSums,
    }
    let gather = |cols: &[f64], offs: &[(usize, f64)], out: &mut [f64]| {
        let q = geom.rf_h * c;
        let mut at_out = 0;
        for &(o, _) in offs {
            let patch = &cols[o * q..(o + geom.rf_w) * q]; // (m, dr, ch) order
            for dr in 0..geom.rf_h {
                for m in 0..geom.rf_w {
                    let at = (m * geom.rf_h + dr) * c;
                    out[at_out..at_out + c].copy_from_slice(&patch[at..at + c]);
                    at_out += c;
                }
            }
        }
    };
    // Correction rows of every RF row, written in place (no concatenation).
    let (ns, np) = (plan.short_samples.len(), plan.short_pairs.len());
    // (At least one value per RF row, so that every row gets a chunk.)
    let (cs, cp) = ((ns * d).max(1), (np * d).max(1));
    let mut short_x = vec![0.0; geom.n_h * cs];
    let mut short_d = vec![0.0; geom.n_h * cp];
    let parts: Vec<RowPart> = short_x
        .par_chunks_mut(cs)
        .zip(short_d.par_chunks_mut(cp))
        .enumerate()
        .map(|(r, (sx, sd))| {
            let r0 = r * geom.stride_h;
            let centred = |col: usize, dr: usize, ch: usize| px(r0 + dr, col, ch) - reference[ch];
            let diff = |col: usize, dr: usize, ch: usize| px(r0 + dr, (col + step) % w, ch) - px(r0 + dr, col, ch);
            let xc: Vec<f64> = columns(geom, w, centred);
            let dc: Vec<f64> = columns(geom, w, diff);
            let mut x = LatticeSums::zeros(geom, g);
            let mut dx = LatticeSums::zeros(geom, g);
            if mixed {
                let x32: Vec<f32> = xc.iter().map(|&v| v as f32).collect();
                let d32: Vec<f32> = dc.iter().map(|&v| v as f32).collect();
                lag_products(&x32, geom, w, g, &mut x.h, &mut x.s);
                lag_products(&d32, geom, w, g, &mut dx.h, &mut dx.s);
            } else {
                lag_products(&xc, geom, w, g, &mut x.h, &mut x.s);
                lag_products(&dc, geom, w, g, &mut dx.h, &mut dx.s);
            }
            gather(&xc, &plan.short_samples, &mut sx[..ns * d]);
            gather(&dc, &plan.short_pairs, &mut sd[..np * d]);
            RowPart { x, dx }
        })
        .collect();
    let mut x = LatticeSums::zeros(geom, g);
    let mut dx = LatticeSums::zeros(geom, g);
    for p in &parts {
        x.add(&p.x);
        dx.add(&p.dx);
    }
    short_x.truncate(geom.n_h * ns * d);
    short_d.truncate(geom.n_h * np * d);
    LatticeImage { plan: plan.clone(), x, dx, short_x, short_d }
}

/// The statistics of layer 0's periodic patches of `images` (their
/// [`LatticeImage`]s, all under one plan and one `reference`), as one
/// accumulator: the lattice sums are added up and assembled once, and the
/// correction rows of all images are accumulated at once.
pub(crate) fn lattice_moments(
    geom: &LayerGeometry,
    images: &[LatticeImage],
    reference: &[f64],
    mixed: bool,
) -> Result<Accumulator> {
    let (c, d) = (geom.in_c, geom.in_dim);
    let plan = &images.first().ok_or_else(|| SfaError::InvalidArgument("no lattice images".into()))?.plan;
    let g = plan.g;
    let mut x = LatticeSums::zeros(geom, g);
    let mut dx = LatticeSums::zeros(geom, g);
    for im in images {
        debug_assert_eq!((im.plan.g, im.plan.w_max, im.plan.p_max), (g, plan.w_max, plan.p_max));
        x.add(&im.x);
        dx.add(&im.dx);
    }
    let wx: Vec<f64> = (0..geom.n_h).flat_map(|_| plan.short_samples.iter().map(|&(_, v)| v)).collect();
    let wd: Vec<f64> = (0..geom.n_h).flat_map(|_| plan.short_pairs.iter().map(|&(_, v)| v)).collect();
    // The shortfall, as ordinary weighted rows relative to the same (zero)
    // reference in the centred coordinates.
    let mut short = Accumulator::with_reference(vec![0.0; d])?;
    short.set_mixed_precision(mixed);
    let sx = images.iter().map(|im| View::from_slice(&im.short_x, wx.len(), d)).collect::<Result<Vec<_>>>()?;
    let sd = images.iter().map(|im| View::from_slice(&im.short_d, wd.len(), d)).collect::<Result<Vec<_>>>()?;
    short.add_samples_batch(&sx, &wx)?;
    short.add_differences_batch(&sd, &wd)?;
    let k = images.len();
    let n_h = geom.n_h as f64;
    let lattice = (plan.period / g) as f64;
    let shift: Vec<f64> = (0..d).map(|i| reference[i % c]).collect();
    let (sum, sxx) = x.assemble(geom, g, plan.w_max);
    let (sum_d, sdd) = dx.assemble(geom, g, plan.p_max);
    let samples = ((k * geom.n_h * plan.n_samples) as u64, k as f64 * plan.w_max * n_h * lattice, sum, sxx);
    let pairs = ((k * geom.n_h * plan.n_pairs) as u64, k as f64 * plan.p_max * n_h * lattice, sum_d, sdd);
    Ok(short.lattice_minus(shift, samples, pairs))
}

/// Outputs of a solved linear first stage, `(x - mean) P`, for the periodic
/// patches of one `in_h x period x in_c` image at column offsets `offs`:
/// `n_h x |offs| x k`, row-major (row `r * |offs| + i`). Every patch of an
/// RF row is a window of one wrapped column array, so the patches are the
/// rows of an overlapping strided matrix (row stride = one column) and one
/// matrix product per RF row evaluates them all, without gathering them.
pub(crate) fn first_stage_outputs(
    geom: &LayerGeometry,
    image: &[f64],
    period: usize,
    offs: &[usize],
    (mean, projection, k): (&[f64], &[f64], usize),
) -> Vec<f64> {
    let (w, c, d) = (period, geom.in_c, geom.in_dim);
    let q = geom.rf_h * c;
    let wq = geom.rf_w * q;
    debug_assert_eq!(image.len(), geom.in_h * w * c);
    // Projection rows in the wrapped arrays' (m, dr, ch) order.
    let patch_index = |a: usize| {
        let (m, rest) = (a / q, a % q);
        let (dr, ch) = (rest / c, rest % c);
        (dr * geom.rf_w + m) * c + ch
    };
    let p = Mat::<f64>::from_fn(wq, k, |a, j| projection[patch_index(a) * k + j]);
    let bias: Vec<f64> = (0..k).map(|j| (0..d).map(|i| mean[i] * projection[i * k + j]).sum()).collect();
    let no = offs.len();
    let mut out = vec![0.0; geom.n_h * no * k];
    out.par_chunks_mut(no * k).enumerate().for_each(|(r, o)| {
        let r0 = r * geom.stride_h;
        let cols: Vec<f64> = columns(geom, w, |col, dr, ch| image[((r0 + dr) * w + col) * c + ch]);
        let patches = MatRef::from_row_major_slice_with_stride(&cols, w, wq, q);
        let mut y = Mat::<f64>::zeros(w, k);
        matmul(y.as_mut(), Accum::Replace, patches, p.as_ref(), 1.0, Par::Seq);
        for (i, &off) in offs.iter().enumerate() {
            for j in 0..k {
                o[i * k + j] = y[(off, j)] - bias[j];
            }
        }
    });
    out
}
