mod common;
use common::*;
use proptest::prelude::*;
use sfa_core::{Accumulator, SfaError, View};

fn acc_of(x: &[f64], n: usize, d: usize) -> Accumulator {
    let mut a = Accumulator::new(d).unwrap();
    a.update(View::from_slice(x, n, d).unwrap(), false).unwrap();
    a
}

fn assert_same(a: &Accumulator, b: &Accumulator, tol: f64) {
    assert_eq!(a.n_samples(), b.n_samples());
    assert_eq!(a.n_pairs(), b.n_pairs());
    let (ca, cb) = (a.covariance().unwrap(), b.covariance().unwrap());
    let (da, db) = (a.derivative_covariance().unwrap(), b.derivative_covariance().unwrap());
    assert!(max_abs_diff(&ca, &cb) <= tol * max_abs(&ca), "cov differs");
    assert!(max_abs_diff(&da, &db) <= tol * max_abs(&da), "dcov differs");
    for (x, y) in a.mean().unwrap().iter().zip(b.mean().unwrap()) {
        assert!((x - y).abs() <= tol * (1.0 + x.abs()));
    }
}

#[test]
fn matches_naive_reference() {
    let (n, d) = (5000, 7);
    let x = correlated(n, d, 1);
    let a = acc_of(&x, n, d);
    let (mean, cov, dcov) = naive_stats(&x, n, d);
    assert!(max_abs_diff(&a.covariance().unwrap(), &cov) < 1e-12 * max_abs(&cov));
    assert!(max_abs_diff(&a.derivative_covariance().unwrap(), &dcov) < 1e-12 * max_abs(&dcov));
    for (u, v) in a.mean().unwrap().iter().zip(&mean) {
        assert!((u - v).abs() < 1e-12);
    }
    assert_eq!(a.n_pairs(), (n - 1) as u64);
}

#[test]
fn small_blocks_and_many_parts_match_the_reference() {
    let (n, d) = (9000, 5);
    let x = correlated(n, d, 21);
    sfa_core::stats::set_block_rows(37);
    let a = acc_of(&x, n, d);
    sfa_core::stats::set_block_rows(0);
    let (_, cov, dcov) = naive_stats(&x, n, d);
    assert!(max_abs_diff(&a.covariance().unwrap(), &cov) < 1e-12 * max_abs(&cov));
    assert!(max_abs_diff(&a.derivative_covariance().unwrap(), &dcov) < 1e-12 * max_abs(&dcov));
    assert_eq!(a.n_pairs(), (n - 1) as u64);
}

#[test]
fn chunked_equals_one_pass_and_breaks_are_respected() {
    let (n, d) = (3001, 5);
    let x = correlated(n, d, 2);
    let whole = acc_of(&x, n, d);
    let mut chunked = Accumulator::new(d).unwrap();
    for (s, e) in [(0, 1), (1, 700), (700, 701), (701, 2999), (2999, 3001)] {
        chunked.update(View::from_slice(&x[s * d..e * d], e - s, d).unwrap(), false).unwrap();
    }
    assert_same(&whole, &chunked, 1e-12);

    // A break at 1000: the pair (999, 1000) must be missing.
    let mut broken = Accumulator::new(d).unwrap();
    broken.update(View::from_slice(&x[..1000 * d], 1000, d).unwrap(), false).unwrap();
    broken.update(View::from_slice(&x[1000 * d..], n - 1000, d).unwrap(), true).unwrap();
    assert_eq!(broken.n_pairs(), (n - 2) as u64);
    let mut want = Accumulator::new(d).unwrap();
    want.add_samples(View::from_slice(&x, n, d).unwrap(), None).unwrap();
    let a: Vec<f64> = (0..n - 1).filter(|&t| t != 999).flat_map(|t| x[t * d..(t + 1) * d].to_vec()).collect();
    let b: Vec<f64> = (1..n).filter(|&t| t != 1000).flat_map(|t| x[t * d..(t + 1) * d].to_vec()).collect();
    want.add_pairs(View::from_slice(&a, n - 2, d).unwrap(), View::from_slice(&b, n - 2, d).unwrap(), None).unwrap();
    assert_same(&broken, &want, 1e-12);
}

#[test]
fn merge_equals_one_pass() {
    let (n, d) = (4000, 6);
    let x = correlated(n, d, 3);
    let whole = acc_of(&x, n, d);
    let mut left = acc_of(&x[..1500 * d], 1500, d);
    let right = acc_of(&x[1500 * d..], n - 1500, d);
    left.merge_continuing(&right).unwrap();
    assert_same(&whole, &left, 1e-12);

    // Plain merge: the same minus the bridging pair.
    let mut l2 = acc_of(&x[..1500 * d], 1500, d);
    l2.merge(&right).unwrap();
    assert_eq!(l2.n_pairs() + 1, whole.n_pairs());
}

#[test]
fn weights_equal_repetition() {
    let (n, d) = (50, 3);
    let x = correlated(n, d, 4);
    let w: Vec<f64> = (0..n).map(|i| (i % 3) as f64).collect();
    let mut weighted = Accumulator::new(d).unwrap();
    weighted.add_samples(View::from_slice(&x, n, d).unwrap(), Some(&w)).unwrap();
    weighted
        .add_pairs(
            View::from_slice(&x[..(n - 1) * d], n - 1, d).unwrap(),
            View::from_slice(&x[d..], n - 1, d).unwrap(),
            Some(&w[..n - 1]),
        )
        .unwrap();
    let mut rep = Accumulator::new(d).unwrap();
    for i in 0..n {
        for _ in 0..(i % 3) {
            rep.add_samples(View::from_slice(&x[i * d..(i + 1) * d], 1, d).unwrap(), None).unwrap();
            if i + 1 < n {
                rep.add_pairs(
                    View::from_slice(&x[i * d..(i + 1) * d], 1, d).unwrap(),
                    View::from_slice(&x[(i + 1) * d..(i + 2) * d], 1, d).unwrap(),
                    None,
                )
                .unwrap();
            }
        }
    }
    let (ca, cb) = (weighted.covariance().unwrap(), rep.covariance().unwrap());
    assert!(max_abs_diff(&ca, &cb) < 1e-12 * max_abs(&ca));
    let (da, db) = (weighted.derivative_covariance().unwrap(), rep.derivative_covariance().unwrap());
    assert!(max_abs_diff(&da, &db) < 1e-12 * max_abs(&da));
    assert_eq!(weighted.weight_sum(), rep.weight_sum());
}

#[test]
fn large_offsets_do_not_cancel() {
    let (n, d) = (2000, 4);
    let x = correlated(n, d, 5);
    let shifted: Vec<f64> = x.iter().map(|v| v + 1e9).collect();
    let (a, b) = (acc_of(&x, n, d), acc_of(&shifted, n, d));
    let (ca, cb) = (a.covariance().unwrap(), b.covariance().unwrap());
    // Inputs at 1e9 carry an absolute rounding error of ~1e-7 per value.
    assert!(max_abs_diff(&ca, &cb) < 1e-6 * max_abs(&ca), "{}", max_abs_diff(&ca, &cb));
}

#[test]
fn float32_input_accumulates_in_f64() {
    let (n, d) = (1000, 3);
    let x = correlated(n, d, 6);
    let x32: Vec<f32> = x.iter().map(|&v| v as f32).collect();
    let back: Vec<f64> = x32.iter().map(|&v| v as f64).collect();
    let mut a = Accumulator::new(d).unwrap();
    a.update(View::from_slice(&x32, n, d).unwrap(), false).unwrap();
    let b = acc_of(&back, n, d);
    assert_same(&a, &b, 1e-12);
}

#[test]
fn errors_name_the_problem() {
    let mut a = Accumulator::new(2).unwrap();
    let bad = [1.0, 2.0, 3.0, f64::NAN];
    match a.update(View::from_slice(&bad, 2, 2).unwrap(), false) {
        Err(SfaError::NonFinite { row: 1, col: 1, .. }) => {}
        e => panic!("{e:?}"),
    }
    // The failed call left nothing behind.
    assert_eq!(a.n_samples(), 0);
    let wide = [1.0, 2.0, 3.0];
    assert!(matches!(a.update(View::from_slice(&wide, 1, 3).unwrap(), false), Err(SfaError::ShapeMismatch { .. })));
    assert!(matches!(a.covariance(), Err(SfaError::TooFewSamples { .. })));
    let one = [1.0, 2.0];
    assert!(a.add_samples(View::from_slice(&one, 1, 2).unwrap(), Some(&[-1.0])).is_err());
    assert!(Accumulator::new(0).is_err());
}

#[test]
fn state_round_trip_is_exact() {
    let (n, d) = (300, 4);
    let x = correlated(n, d, 7);
    let a = acc_of(&x, n, d);
    let b = Accumulator::from_state(&a.state()).unwrap();
    assert_eq!(a.state(), b.state());
    let mut s = a.state();
    s.sxx.pop();
    assert!(matches!(Accumulator::from_state(&s), Err(SfaError::InvalidState(_))));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    #[test]
    fn any_split_and_merge_equals_one_pass(n in 3usize..400, d in 1usize..6, cut in 1usize..399, seed in 0u64..1000) {
        let cut = 1 + cut % (n - 1);
        let x = correlated(n, d, seed);
        let whole = acc_of(&x, n, d);
        let mut a = acc_of(&x[..cut * d], cut, d);
        let b = acc_of(&x[cut * d..], n - cut, d);
        a.merge_continuing(&b).unwrap();
        assert_same(&whole, &a, 1e-10);
        let mut c = Accumulator::new(d).unwrap();
        c.update(View::from_slice(&x[..cut * d], cut, d).unwrap(), false).unwrap();
        c.update(View::from_slice(&x[cut * d..], n - cut, d).unwrap(), false).unwrap();
        assert_same(&whole, &c, 1e-10);
    }
}

#[test]
fn mixed_precision_is_close_to_double() {
    let (n, d) = (20000, 40);
    let x = correlated(n, d, 31);
    let a = acc_of(&x, n, d);
    let mut b = Accumulator::new(d).unwrap();
    b.set_mixed_precision(true);
    b.update(View::from_slice(&x, n, d).unwrap(), false).unwrap();
    let (ca, cb) = (a.covariance().unwrap(), b.covariance().unwrap());
    let (da, db) = (a.derivative_covariance().unwrap(), b.derivative_covariance().unwrap());
    let ec = max_abs_diff(&ca, &cb) / max_abs(&ca);
    let ed = max_abs_diff(&da, &db) / max_abs(&da);
    assert!(ec < 1e-5 && ed < 1e-5, "{ec} {ed}");
    assert!(ec > 0.0, "mixed precision should not be bit-identical to double");
    let back = Accumulator::from_state(&b.state()).unwrap();
    assert!(back.is_mixed_precision());
}

/// Random graphs over `parts` blocks of rows: weights in [0, 2] (some 0),
/// edges between random rows of the same block.
fn random_graphs(
    x: &[f64],
    d: usize,
    sizes: &[usize],
    seed: u64,
) -> Vec<(usize, usize, Vec<f64>, Vec<[usize; 2]>, Vec<f64>)> {
    let mut r = common::Rng::new(seed);
    let mut start = 0;
    let mut out = Vec::new();
    for &n in sizes {
        let w: Vec<f64> = (0..n).map(|i| if i % 7 == 3 { 0.0 } else { 1.0 + r.next() }).collect();
        let edges: Vec<[usize; 2]> = (0..2 * n)
            .map(|_| {
                [((r.next() + 1.0) / 2.0 * n as f64) as usize % n, ((r.next() + 1.0) / 2.0 * n as f64) as usize % n]
            })
            .collect();
        let ew: Vec<f64> = edges.iter().map(|_| 1.0 + r.next()).collect();
        out.push((start, n, w, edges, ew));
        start += n;
    }
    assert!(start * d <= x.len());
    out
}

#[test]
fn a_batch_of_graphs_equals_the_graphs_one_by_one() {
    use sfa_core::stats::GraphPart;
    let d = 6;
    let sizes = [1, 40, 0, 700, 3, 333];
    let n: usize = sizes.iter().sum();
    let x = correlated(n, d, 31);
    let graphs = random_graphs(&x, d, &sizes, 5);
    // reference: the samples and the indexed pairs of each graph, added separately
    let mut one = Accumulator::new(d).unwrap();
    for (s, m, w, e, ew) in &graphs {
        let v = View::from_slice(&x[s * d..(s + m) * d], *m, d).unwrap();
        one.add_samples(v, Some(w)).unwrap();
        one.add_pairs_indexed(v, e, Some(ew)).unwrap();
    }
    sfa_core::stats::set_block_rows(29); // cross block and part boundaries inside and between graphs
    let parts: Vec<GraphPart<'_, f64>> = graphs
        .iter()
        .map(|(s, m, w, e, ew)| GraphPart {
            x: View::from_slice(&x[s * d..(s + m) * d], *m, d).unwrap(),
            weights: Some(w),
            edges: e,
            edge_weights: Some(ew),
        })
        .collect();
    let mut batch = Accumulator::new(d).unwrap();
    batch.add_graphs(&parts, None).unwrap();
    sfa_core::stats::set_block_rows(0);
    assert_same(&one, &batch, 1e-12);
    assert_eq!(one.weight_sum(), batch.weight_sum());
    assert!((one.pair_weight_sum() - batch.pair_weight_sum()).abs() < 1e-9);
}

#[test]
fn a_mapped_batch_equals_the_mapped_rows() {
    use sfa_core::stats::GraphPart;
    use sfa_core::Expansion;
    let d = 4;
    let ex = Expansion::new(d, 2).unwrap();
    let e = ex.out_dim();
    let sizes = [50, 120];
    let n: usize = sizes.iter().sum();
    let x = correlated(n, d, 32);
    let mut xe = vec![0.0; n * e];
    for i in 0..n {
        ex.expand_row(&x[i * d..(i + 1) * d], &mut xe[i * e..(i + 1) * e]);
    }
    let graphs = random_graphs(&x, d, &sizes, 6);
    let mut plain = Accumulator::new(e).unwrap();
    for (s, m, w, ed, ew) in &graphs {
        let v = View::from_slice(&xe[s * e..(s + m) * e], *m, e).unwrap();
        plain.add_samples(v, Some(w)).unwrap();
        plain.add_pairs_indexed(v, ed, Some(ew)).unwrap();
    }
    let parts: Vec<GraphPart<'_, f64>> = graphs
        .iter()
        .map(|(s, m, w, ed, ew)| GraphPart {
            x: View::from_slice(&x[s * d..(s + m) * d], *m, d).unwrap(),
            weights: Some(w),
            edges: ed,
            edge_weights: Some(ew),
        })
        .collect();
    let f = |a: &[f64], o: &mut [f64]| ex.expand_row(a, o);
    let mut mapped = Accumulator::new(e).unwrap();
    mapped.add_graphs(&parts, Some((d, &f))).unwrap();
    assert_same(&plain, &mapped, 1e-12);
}

#[test]
fn a_failing_batch_adds_nothing() {
    use sfa_core::stats::GraphPart;
    let d = 3;
    let x = correlated(20, d, 33);
    let mut bad = x.clone();
    bad[13 * d + 1] = f64::NAN;
    let mut a = Accumulator::new(d).unwrap();
    a.update(View::from_slice(&x, 20, d).unwrap(), false).unwrap();
    let before = a.state();
    let edges = [[0usize, 1usize]];
    let ok = GraphPart { x: View::from_slice(&x, 20, d).unwrap(), weights: None, edges: &edges, edge_weights: None };
    let nan = GraphPart { x: View::from_slice(&bad, 20, d).unwrap(), weights: None, edges: &edges, edge_weights: None };
    assert!(matches!(a.add_graphs(&[ok, nan], None), Err(SfaError::NonFinite { row: 13, col: 1, .. })));
    assert_eq!(a.state(), before);
    // wrong width and an edge outside its graph
    let wide =
        GraphPart { x: View::from_slice(&x[..20], 5, 4).unwrap(), weights: None, edges: &[], edge_weights: None };
    assert!(matches!(a.add_graphs(&[wide], None), Err(SfaError::ShapeMismatch { .. })));
    let far = [[0usize, 20usize]];
    let out = GraphPart { x: View::from_slice(&x, 20, d).unwrap(), weights: None, edges: &far, edge_weights: None };
    assert!(matches!(a.add_graphs(&[out], None), Err(SfaError::InvalidArgument(_))));
    assert_eq!(a.state(), before);
}
