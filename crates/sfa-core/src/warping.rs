//! Scores of the warping method of snapshot homing (Franz, Schoelkopf,
//! Mallot and Buelthoff 1998), the inner loop of the relative poses of
//! loop closures (`sfanav.loopclosure.relative_pose`).
//!
//! For a pair of panoramas, given as `rows x width` images `a` (frame `i`)
//! and `b` (frame `j`), and a set of warping hypotheses (a baseline
//! direction and a distance ratio each), every hypothesis `h` says at which
//! fractional column `c[h, u]` of `b` the column `u` of `a` appears when the
//! relative heading is zero; a relative heading of `s` columns adds `s`.
//! The score of `(h, s)` is the mean over the columns `u` of the squared
//! distance between column `u` of `a` and column `c[h, u] + s` of `b`,
//! linearly interpolated between the two neighbouring columns of `b`
//! (circularly):
//!
//! ```text
//! D[u, v]     = sum_k (a[k, u] - b[k, v])^2
//! S[h, s]     = mean_u ((1 - t) D[u, f] + t D[u, f + 1]),
//!               f = floor(c[h, u] + s) mod width,  t = frac(c[h, u] + s)
//! ```
//!
//! Min-warping (Moeller 2009, "Local visual homing by warping of
//! two-dimensional images") lets every column have its own landmark
//! distance: the hypotheses come in groups (one baseline direction, its
//! distance ratios), and a group's score takes, column by column, the best
//! ratio of the group before the mean:
//!
//! ```text
//! M[g, s]     = mean_u min_{h in g} ((1 - t) D[u, f] + t D[u, f + 1])
//! ```
//!
//! ([`min_warp_scores`]; groups of one are [`warp_scores`]).
//! [`warp_and_min_warp_scores`] gives both from one pass (each hypothesis's
//! score and each group's minimum share the distance table and the
//! interpolated values): what choosing between the two methods needs.
//!
//! The pairs are scored in parallel (rayon), each with its own `width x
//! width` distance table. Accumulation is in `f64`.

use rayon::prelude::*;

use crate::error::{Result, SfaError};
use crate::memory;

/// Warping scores of `pairs` pairs of panoramas.
///
/// * `a`, `b`: `pairs x rows x width` values (row-major), the two images of
///   each pair;
/// * `columns`: `hypotheses x width` fractional columns (row-major), the
///   same for every pair;
/// * `shifts`: `pairs x n_shifts` relative headings tried per pair, in
///   columns (any real value; taken modulo `width`).
///
/// Returns `pairs x hypotheses x n_shifts` scores (row-major).
///
/// Errors: sizes that disagree, a zero width, rows or hypotheses, a
/// non-finite value in any input, an output beyond the memory limit.
#[allow(clippy::too_many_arguments)]
pub fn warp_scores(
    a: &[f64],
    b: &[f64],
    pairs: usize,
    rows: usize,
    width: usize,
    columns: &[f64],
    shifts: &[f64],
    n_shifts: usize,
) -> Result<Vec<f64>> {
    min_warp_scores(a, b, pairs, rows, width, columns, 1, shifts, n_shifts)
}

/// Min-warping scores of `pairs` pairs of panoramas: as [`warp_scores`],
/// with the `hypotheses` rows of `columns` taken in consecutive groups of
/// `group` (one baseline direction and its distance ratios each); each
/// column of `a` takes the group's best hypothesis before the mean over the
/// columns (see the module docs).
///
/// Returns `pairs x (hypotheses / group) x n_shifts` scores (row-major).
///
/// Errors: as [`warp_scores`], and a zero `group` or hypotheses that do not
/// split into groups of `group`.
#[allow(clippy::too_many_arguments)]
pub fn min_warp_scores(
    a: &[f64],
    b: &[f64],
    pairs: usize,
    rows: usize,
    width: usize,
    columns: &[f64],
    group: usize,
    shifts: &[f64],
    n_shifts: usize,
) -> Result<Vec<f64>> {
    scores::<false>(a, b, pairs, rows, width, columns, group, shifts, n_shifts).map(|(_, mins)| mins)
}

/// The warping's and min-warping's scores of `pairs` pairs from one pass:
/// `(warping, min_warping)`, as [`warp_scores`] (`pairs x hypotheses x
/// n_shifts`) and [`min_warp_scores`] with `group` (`pairs x (hypotheses /
/// group) x n_shifts`) return them, bit for bit, for about 1.2x the cost of
/// either.
///
/// Errors: as [`min_warp_scores`].
#[allow(clippy::too_many_arguments)]
pub fn warp_and_min_warp_scores(
    a: &[f64],
    b: &[f64],
    pairs: usize,
    rows: usize,
    width: usize,
    columns: &[f64],
    group: usize,
    shifts: &[f64],
    n_shifts: usize,
) -> Result<(Vec<f64>, Vec<f64>)> {
    scores::<true>(a, b, pairs, rows, width, columns, group, shifts, n_shifts)
}

/// The driver of both: `(each hypothesis's scores, empty without BOTH;
/// each group's min-warping scores)`, the pairs in parallel.
#[allow(clippy::too_many_arguments)]
fn scores<const BOTH: bool>(
    a: &[f64],
    b: &[f64],
    pairs: usize,
    rows: usize,
    width: usize,
    columns: &[f64],
    group: usize,
    shifts: &[f64],
    n_shifts: usize,
) -> Result<(Vec<f64>, Vec<f64>)> {
    let (image, hyps) = check_inputs(a, b, pairs, rows, width, columns, group, shifts, n_shifts, BOTH)?;
    let groups = hyps / group;
    let per_pair = if BOTH { hyps * n_shifts } else { 0 };
    let mut each = vec![0.0f64; pairs * per_pair];
    let mut mins = vec![0.0f64; pairs * groups * n_shifts];
    if pairs == 0 {
        return Ok((each, mins));
    }
    // one (possibly empty) slice of `each` per pair, so that both outputs go through one parallel loop
    let mut each_of: Vec<&mut [f64]> =
        if BOTH { each.chunks_mut(per_pair).collect() } else { (0..pairs).map(|_| Default::default()).collect() };
    mins.par_chunks_mut(groups * n_shifts).zip(each_of.par_iter_mut()).enumerate().for_each(|(p, (dst, e))| {
        let pa = &a[p * image..(p + 1) * image];
        let pb = &b[p * image..(p + 1) * image];
        let sh = &shifts[p * n_shifts..(p + 1) * n_shifts];
        score_pair::<BOTH>(pa, pb, rows, width, columns, hyps, group, sh, dst, e);
    });
    Ok((each, mins))
}

/// Validates the inputs of the scores and checks their memory; returns the
/// values per image and the number of hypotheses.
#[allow(clippy::too_many_arguments)]
fn check_inputs(
    a: &[f64],
    b: &[f64],
    pairs: usize,
    rows: usize,
    width: usize,
    columns: &[f64],
    group: usize,
    shifts: &[f64],
    n_shifts: usize,
    both: bool,
) -> Result<(usize, usize)> {
    if group == 0 {
        return Err(SfaError::InvalidArgument("min-warping needs groups of at least one hypothesis".into()));
    }
    if width == 0 || rows == 0 {
        return Err(SfaError::InvalidArgument(format!(
            "warping needs images of at least one row and column, got {rows} x {width}"
        )));
    }
    let image = rows.checked_mul(width).ok_or_else(|| SfaError::InvalidArgument("image size overflows".into()))?;
    let expect = pairs.checked_mul(image).ok_or_else(|| SfaError::InvalidArgument("pair images overflow".into()))?;
    for (what, v) in [("warping images a (pairs x rows x width)", a), ("warping images b (pairs x rows x width)", b)] {
        if v.len() != expect {
            return Err(SfaError::ShapeMismatch { what, expected: expect, got: v.len() });
        }
    }
    if columns.is_empty() || columns.len() % width != 0 {
        return Err(SfaError::InvalidArgument(format!(
            "{} warped columns do not split into hypotheses of width {width}",
            columns.len()
        )));
    }
    let hyps = columns.len() / width;
    if hyps % group != 0 {
        return Err(SfaError::InvalidArgument(format!(
            "{hyps} warping hypotheses do not split into groups of {group}"
        )));
    }
    let groups = hyps / group;
    if n_shifts == 0 {
        return Err(SfaError::InvalidArgument("warping needs at least one relative heading (shift)".into()));
    }
    let n_sh = pairs.checked_mul(n_shifts).ok_or_else(|| SfaError::InvalidArgument("shifts overflow".into()))?;
    if shifts.len() != n_sh {
        return Err(SfaError::ShapeMismatch {
            what: "warping shifts (pairs x n_shifts)",
            expected: n_sh,
            got: shifts.len(),
        });
    }
    for (what, v, cols) in [
        ("warping images a", a, width),
        ("warping images b", b, width),
        ("warped columns", columns, width),
        ("warping shifts", shifts, n_shifts),
    ] {
        if let Some(at) = v.iter().position(|x| !x.is_finite()) {
            return Err(SfaError::NonFinite { what, row: at / cols, col: at % cols });
        }
    }
    let out_len = memory::bytes_of(8, &[pairs, if both { groups + hyps } else { groups }, n_shifts]);
    let threads = rayon::current_num_threads().max(1);
    let table = memory::bytes_of(8, &[width, width, threads]);
    let warped = memory::bytes_of(16, &[group, width, threads]);
    memory::check(
        || format!("warping scores of {pairs} pairs x {hyps} hypotheses x {n_shifts} shifts"),
        memory::total(&[out_len, table, warped]),
    )?;
    Ok((image, hyps))
}

/// The scores of one pair into `dst` (`hyps / group x shifts.len()`), and
/// with `BOTH` each hypothesis's into `each` (`hyps x shifts.len()`).
#[allow(clippy::too_many_arguments)]
fn score_pair<const BOTH: bool>(
    a: &[f64],
    b: &[f64],
    rows: usize,
    width: usize,
    columns: &[f64],
    hyps: usize,
    group: usize,
    shifts: &[f64],
    dst: &mut [f64],
    each: &mut [f64],
) {
    let w = width;
    let stride = w + 1; // each row of D carries its first column again at the end: no wrap for `f + 1`
                        // D[u, v] = |a_u|^2 + |b_v|^2 - 2 a_u . b_v
    let mut na = vec![0.0f64; w];
    let mut nb = vec![0.0f64; w];
    for k in 0..rows {
        let (ra, rb) = (&a[k * w..(k + 1) * w], &b[k * w..(k + 1) * w]);
        for u in 0..w {
            na[u] += ra[u] * ra[u];
            nb[u] += rb[u] * rb[u];
        }
    }
    let mut d = vec![0.0f64; w * stride];
    for k in 0..rows {
        let (ra, rb) = (&a[k * w..(k + 1) * w], &b[k * w..(k + 1) * w]);
        for u in 0..w {
            let x = -2.0 * ra[u];
            let row = &mut d[u * stride..u * stride + w];
            for (dv, bv) in row.iter_mut().zip(rb) {
                *dv += x * bv;
            }
        }
    }
    for u in 0..w {
        let row = &mut d[u * stride..(u + 1) * stride];
        for (dv, nbv) in row[..w].iter_mut().zip(&nb) {
            *dv += na[u] + nbv;
        }
        row[w] = row[0];
    }
    let wf = w as f64;
    let ns = shifts.len();
    // split each shift into an integer number of columns (reduced modulo the width) and a fraction; shifts
    // that share one fraction (every integer shift, the library's case) share the floors of the columns
    let mut whole = vec![0usize; ns];
    let mut frac = vec![0.0f64; ns];
    for (si, &s) in shifts.iter().enumerate() {
        let f = s.floor();
        frac[si] = s - f;
        whole[si] = (f.rem_euclid(wf) as usize) % w;
    }
    // the floors and fractions of the warped columns of one group's hypotheses (group x w), and the running
    // minimum over them of one column's values at the shifts of one fraction (min-warping; groups of one
    // add the values themselves, in the same order)
    let mut base = vec![0usize; group * w];
    let mut t = vec![0.0f64; group * w];
    let mut mins = vec![0.0f64; ns];
    let mut acc = vec![0.0f64; ns];
    for g in 0..hyps / group {
        acc.iter_mut().for_each(|x| *x = 0.0);
        let cols = &columns[g * group * w..(g + 1) * group * w];
        let mut si0 = 0;
        while si0 < ns {
            // the run of shifts with the fraction of shift si0
            let fr = frac[si0];
            let mut si1 = si0 + 1;
            while si1 < ns && frac[si1] == fr {
                si1 += 1;
            }
            for (k, &c0) in cols.iter().enumerate() {
                let c = c0 + fr;
                let f = c.floor();
                t[k] = c - f;
                base[k] = (f.rem_euclid(wf) as usize) % w;
            }
            for u in 0..w {
                let row = &d[u * stride..(u + 1) * stride];
                mins[si0..si1].fill(f64::INFINITY);
                for h in 0..group {
                    let (bu, tu) = (base[h * w + u], t[h * w + u]);
                    for si in si0..si1 {
                        let mut f0 = bu + whole[si];
                        if f0 >= w {
                            f0 -= w;
                        }
                        let v = row[f0] + tu * (row[f0 + 1] - row[f0]);
                        mins[si] = mins[si].min(v);
                        if BOTH {
                            each[((g * group + h) * ns) + si] += v;
                        }
                    }
                }
                for si in si0..si1 {
                    acc[si] += mins[si];
                }
            }
            si0 = si1;
        }
        for si in 0..ns {
            dst[g * ns + si] = acc[si] / wf;
        }
    }
    if BOTH {
        each.iter_mut().for_each(|x| *x /= wf);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The formula of the module docs, evaluated directly.
    fn naive(a: &[f64], b: &[f64], rows: usize, w: usize, columns: &[f64], shifts: &[f64]) -> Vec<f64> {
        let hyps = columns.len() / w;
        let mut out = Vec::new();
        for h in 0..hyps {
            for &s in shifts {
                let mut acc = 0.0;
                for u in 0..w {
                    let c = columns[h * w + u] + s;
                    let f = c.floor();
                    let t = c - f;
                    let f0 = (f as i64).rem_euclid(w as i64) as usize;
                    let f1 = (f0 + 1) % w;
                    let dist = |v: usize| (0..rows).map(|k| (a[k * w + u] - b[k * w + v]).powi(2)).sum::<f64>();
                    acc += (1.0 - t) * dist(f0) + t * dist(f1);
                }
                out.push(acc / w as f64);
            }
        }
        out
    }

    fn lcg(n: usize, seed: u64) -> Vec<f64> {
        let mut x = seed;
        (0..n)
            .map(|_| {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((x >> 11) as f64) / ((1u64 << 53) as f64) - 0.5
            })
            .collect()
    }

    #[test]
    fn matches_the_formula() {
        let (pairs, rows, w) = (3, 4, 24);
        let a = lcg(pairs * rows * w, 1);
        let b = lcg(pairs * rows * w, 2);
        let columns: Vec<f64> = lcg(5 * w, 3).iter().map(|v| (v + 0.5) * w as f64).collect();
        let shifts: Vec<f64> = vec![-3.0, 0.0, 2.5, 30.25, -1.75, 5.0, 0.5, 11.0, -26.0];
        let got = warp_scores(&a, &b, pairs, rows, w, &columns, &shifts, 3).unwrap();
        for p in 0..pairs {
            let want = naive(
                &a[p * rows * w..(p + 1) * rows * w],
                &b[p * rows * w..(p + 1) * rows * w],
                rows,
                w,
                &columns,
                &shifts[p * 3..(p + 1) * 3],
            );
            for (g, e) in got[p * 15..(p + 1) * 15].iter().zip(&want) {
                assert!((g - e).abs() <= 1e-12 * (1.0 + e.abs()), "{g} vs {e}");
            }
        }
    }

    /// Min-warping's formula, evaluated directly: per column the group's least interpolated distance.
    fn naive_min(
        a: &[f64],
        b: &[f64],
        rows: usize,
        w: usize,
        columns: &[f64],
        group: usize,
        shifts: &[f64],
    ) -> Vec<f64> {
        let hyps = columns.len() / w;
        let mut out = Vec::new();
        for g in 0..hyps / group {
            for &s in shifts {
                let mut acc = 0.0;
                for u in 0..w {
                    let mut m = f64::INFINITY;
                    for h in g * group..(g + 1) * group {
                        let c = columns[h * w + u] + s;
                        let f = c.floor();
                        let t = c - f;
                        let f0 = (f as i64).rem_euclid(w as i64) as usize;
                        let f1 = (f0 + 1) % w;
                        let dist = |v: usize| (0..rows).map(|k| (a[k * w + u] - b[k * w + v]).powi(2)).sum::<f64>();
                        m = m.min((1.0 - t) * dist(f0) + t * dist(f1));
                    }
                    acc += m;
                }
                out.push(acc / w as f64);
            }
        }
        out
    }

    #[test]
    fn min_warping_matches_its_formula() {
        let (pairs, rows, w, group) = (2, 3, 18, 3);
        let a = lcg(pairs * rows * w, 11);
        let b = lcg(pairs * rows * w, 12);
        let columns: Vec<f64> = lcg(6 * w, 13).iter().map(|v| (v + 0.5) * w as f64).collect();
        let shifts: Vec<f64> = vec![-2.0, 0.0, 0.5, 1.0, 7.25, -3.0, 3.0, 3.5];
        let got = min_warp_scores(&a, &b, pairs, rows, w, &columns, group, &shifts, 4).unwrap();
        assert_eq!(got.len(), pairs * 2 * 4);
        let plain = warp_scores(&a, &b, pairs, rows, w, &columns, &shifts, 4).unwrap();
        for p in 0..pairs {
            let img = p * rows * w..(p + 1) * rows * w;
            let want = naive_min(&a[img.clone()], &b[img], rows, w, &columns, group, &shifts[p * 4..(p + 1) * 4]);
            for (gi, e) in got[p * 8..(p + 1) * 8].iter().zip(&want) {
                assert!((gi - e).abs() <= 1e-12 * (1.0 + e.abs()), "{gi} vs {e}");
            }
            // the per-column minimum is never above any one hypothesis of its group
            for gr in 0..2 {
                for si in 0..4 {
                    let m = got[p * 8 + gr * 4 + si];
                    for h in gr * group..(gr + 1) * group {
                        assert!(m <= plain[p * 24 + h * 4 + si] + 1e-12);
                    }
                }
            }
        }
        assert!(min_warp_scores(&a, &b, pairs, rows, w, &columns, 0, &shifts, 4).is_err());
        assert!(min_warp_scores(&a, &b, pairs, rows, w, &columns, 4, &shifts, 4).is_err());
    }

    #[test]
    fn both_methods_from_one_pass_are_each_methods_scores() {
        let (pairs, rows, w, group) = (3, 3, 18, 3);
        let a = lcg(pairs * rows * w, 21);
        let b = lcg(pairs * rows * w, 22);
        let columns: Vec<f64> = lcg(6 * w, 23).iter().map(|v| (v + 0.5) * w as f64).collect();
        let shifts: Vec<f64> = lcg(pairs * 5, 24).iter().map(|v| (v * 40.0).round() / 2.0).collect();
        let (each, mins) = warp_and_min_warp_scores(&a, &b, pairs, rows, w, &columns, group, &shifts, 5).unwrap();
        // one pass: each hypothesis's sum in the same order as the warping's own pass, the minimum as min-warping's
        assert_eq!(mins, min_warp_scores(&a, &b, pairs, rows, w, &columns, group, &shifts, 5).unwrap());
        let plain = warp_scores(&a, &b, pairs, rows, w, &columns, &shifts, 5).unwrap();
        assert_eq!(each.len(), plain.len());
        for (x, y) in each.iter().zip(&plain) {
            assert!((x - y).abs() <= 1e-12 * (1.0 + y.abs()), "{x} vs {y}");
        }
        assert!(warp_and_min_warp_scores(&a, &b, pairs, rows, w, &columns, 4, &shifts, 5).is_err());
        assert!(warp_and_min_warp_scores(&a, &b, pairs, rows, w, &columns, 0, &shifts, 5).is_err());
        let empty = warp_and_min_warp_scores(&[], &[], 0, rows, w, &columns, group, &[], 5).unwrap();
        assert!(empty.0.is_empty() && empty.1.is_empty());
    }

    #[test]
    fn integer_and_mixed_shifts_match_the_formula() {
        let (rows, w) = (3, 20);
        let a = lcg(rows * w, 4);
        let b = lcg(rows * w, 5);
        let columns: Vec<f64> = lcg(4 * w, 6).iter().map(|v| (v + 0.5) * w as f64).collect();
        for shifts in [vec![-25.0, -3.0, 0.0, 1.0, 2.0, 19.0, 41.0], vec![1.0, 1.5, 2.0, 2.5, 2.5, -0.25]] {
            let got = warp_scores(&a, &b, 1, rows, w, &columns, &shifts, shifts.len()).unwrap();
            let want = naive(&a, &b, rows, w, &columns, &shifts);
            for (g, e) in got.iter().zip(&want) {
                assert!((g - e).abs() <= 1e-12 * (1.0 + e.abs()), "{g} vs {e}");
            }
        }
    }

    #[test]
    fn a_turned_copy_scores_zero_at_its_turn() {
        let (rows, w) = (2, 16);
        let a = lcg(rows * w, 7);
        // b is a turned by 3 columns: b[k, (u + 3) % w] = a[k, u]
        let mut b = vec![0.0; rows * w];
        for k in 0..rows {
            for u in 0..w {
                b[k * w + (u + 3) % w] = a[k * w + u];
            }
        }
        let identity: Vec<f64> = (0..w).map(|u| u as f64).collect();
        let shifts: Vec<f64> = (0..w).map(|s| s as f64).collect();
        let s = warp_scores(&a, &b, 1, rows, w, &identity, &shifts, w).unwrap();
        let best = (0..w).min_by(|&i, &j| s[i].total_cmp(&s[j])).unwrap();
        assert_eq!(best, 3);
        assert!(s[3].abs() < 1e-12);
    }

    #[test]
    fn bad_input_is_an_error() {
        let a = vec![0.0; 8];
        assert!(warp_scores(&a, &a, 1, 2, 4, &[0.0; 4], &[0.0], 1).is_ok());
        assert!(warp_scores(&a, &a[..7], 1, 2, 4, &[0.0; 4], &[0.0], 1).is_err());
        assert!(warp_scores(&a, &a, 1, 2, 4, &[0.0; 3], &[0.0], 1).is_err());
        assert!(warp_scores(&a, &a, 1, 2, 4, &[0.0; 4], &[], 0).is_err());
        assert!(warp_scores(&a, &a, 1, 2, 4, &[f64::NAN, 0.0, 0.0, 0.0], &[0.0], 1).is_err());
        assert!(warp_scores(&a, &a, 1, 0, 4, &[0.0; 4], &[0.0], 1).is_err());
        assert_eq!(warp_scores(&[], &[], 0, 2, 4, &[0.0; 4], &[], 1).unwrap().len(), 0);
    }
}
