mod common;
use common::*;
use faer::Mat;
use sfa_core::{beta_values, expand, solve, NodeConfig, SfaError, SfaNode, View};

fn toy(n: usize) -> Vec<f64> {
    let mut x = Vec::with_capacity(2 * n);
    for i in 0..n {
        let t = i as f64 / (n - 1) as f64 * 2.0 * std::f64::consts::PI;
        x.push(t.sin() + (11.0 * t).cos().powi(2));
        x.push((11.0 * t).cos());
    }
    x
}

fn corr(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
    let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
    cov / (va * vb).sqrt()
}

fn fit(x: &[f64], n: usize, d: usize, cfg: NodeConfig) -> SfaNode {
    let mut node = SfaNode::new(cfg).unwrap();
    for s in 0..node.n_stages() {
        node.partial_fit(View::from_slice(x, n, d).unwrap(), true).unwrap();
        if s + 1 < node.n_stages() {
            node.finish_stage().unwrap();
        }
    }
    node.ensure_solved().unwrap();
    node
}

#[test]
fn wiskott_sejnowski_toy_problem() {
    let n = 5000;
    let x = toy(n);
    let node =
        fit(&x, n, 2, NodeConfig { n_components: 1, degree: 2, reduce_to: None, tol: 1e-10, mixed_precision: false });
    let y = node.transform(View::from_slice(&x, n, 2).unwrap()).unwrap();
    let s: Vec<f64> = (0..n).map(|i| (i as f64 / (n - 1) as f64 * 2.0 * std::f64::consts::PI).sin()).collect();
    assert!(corr(&y, &s).abs() > 0.99, "corr {}", corr(&y, &s));
}

#[test]
fn outputs_satisfy_the_constraints() {
    let (n, d, m) = (4000, 8, 5);
    let x = correlated(n, d, 11);
    for cfg in [
        NodeConfig { n_components: m, degree: 1, reduce_to: None, tol: 1e-10, mixed_precision: false },
        NodeConfig { n_components: m, degree: 2, reduce_to: None, tol: 1e-10, mixed_precision: false },
        NodeConfig { n_components: m, degree: 2, reduce_to: Some(6), tol: 1e-10, mixed_precision: false },
    ] {
        let node = fit(&x, n, d, cfg);
        let y = node.transform(View::from_slice(&x, n, d).unwrap()).unwrap();
        for a in 0..m {
            let mean = (0..n).map(|i| y[i * m + a]).sum::<f64>() / n as f64;
            assert!(mean.abs() < 1e-8, "mean {mean}");
            for b in 0..m {
                let c = (0..n).map(|i| y[i * m + a] * y[i * m + b]).sum::<f64>() / n as f64;
                let want = if a == b { 1.0 } else { 0.0 };
                assert!((c - want).abs() < 1e-8, "cov[{a},{b}] = {c}");
            }
        }
        // Delta ascending and equal to the outputs' mean squared derivative.
        let delta = node.delta_values().unwrap();
        assert!(delta.windows(2).all(|w| w[0] <= w[1]));
        for a in 0..m {
            let ds = (1..n).map(|i| (y[i * m + a] - y[(i - 1) * m + a]).powi(2)).sum::<f64>() / (n - 1) as f64;
            assert!((ds - delta[a]).abs() < 1e-8 * (1.0 + ds), "{ds} vs {}", delta[a]);
        }
        let beta = beta_values(delta);
        assert!((beta[0] - delta[0].sqrt() / (2.0 * std::f64::consts::PI)).abs() < 1e-15);
    }
}

#[test]
fn generalized_eigenvectors_satisfy_their_equations() {
    let d = 12;
    let mut r = Rng::new(5);
    let g = Mat::from_fn(d, d, |_, _| r.next());
    let h = Mat::from_fn(d, d, |_, _| r.next());
    let b = &g * g.transpose() + Mat::<f64>::identity(d, d) * 0.1;
    let a = &h * h.transpose();
    let e = solve(a.as_ref(), b.as_ref(), d, 1e-12).unwrap();
    let p = &e.vectors;
    let pbp = p.transpose() * &b * p;
    let pap = p.transpose() * &a * p;
    for i in 0..d {
        for j in 0..d {
            let want_b = if i == j { 1.0 } else { 0.0 };
            let want_a = if i == j { e.values[i] } else { 0.0 };
            assert!((pbp[(i, j)] - want_b).abs() < 1e-9);
            assert!((pap[(i, j)] - want_a).abs() < 1e-9 * (1.0 + e.values[d - 1]));
        }
        // Sign convention: largest-magnitude entry positive.
        let col: Vec<f64> = (0..d).map(|k| p[(k, i)]).collect();
        let big = col.iter().cloned().fold(0.0f64, |m, v| if v.abs() > m.abs() { v } else { m });
        assert!(big > 0.0);
    }
    assert!(e.values.windows(2).all(|w| w[0] <= w[1]));
}

#[test]
fn rank_deficit_is_dropped_and_reported() {
    let (n, d) = (1000, 5);
    let base = correlated(n, 3, 9);
    // Columns 3 and 4 are linear combinations of columns 0..3.
    let mut x = vec![0.0; n * d];
    for i in 0..n {
        let r = &base[i * 3..i * 3 + 3];
        x[i * d..i * d + 3].copy_from_slice(r);
        x[i * d + 3] = r[0] + r[1];
        x[i * d + 4] = 2.0 * r[2] - r[0];
    }
    let node = fit(&x, n, d, NodeConfig::linear(3));
    assert_eq!(node.rank_deficits(), vec![2]);
    assert!(node.delta_values().unwrap().iter().all(|v| v.is_finite()));
    let mut too_many = SfaNode::new(NodeConfig::linear(4)).unwrap();
    too_many.partial_fit(View::from_slice(&x, n, d).unwrap(), true).unwrap();
    assert!(matches!(too_many.ensure_solved(), Err(SfaError::RankDeficient { rank: 3, requested: 4, .. })));
}

#[test]
fn chunked_partial_fit_equals_fit() {
    let (n, d) = (3000, 6);
    let x = correlated(n, d, 13);
    let cfg = NodeConfig { n_components: 4, degree: 2, reduce_to: Some(5), tol: 1e-10, mixed_precision: false };
    let one = fit(&x, n, d, cfg.clone());
    let mut node = SfaNode::new(cfg).unwrap();
    for stage in 0..2 {
        for (s, e) in [(0, 1000), (1000, 1001), (1001, 3000)] {
            node.partial_fit(View::from_slice(&x[s * d..e * d], e - s, d).unwrap(), s == 0).unwrap();
        }
        if stage == 0 {
            node.finish_stage().unwrap();
        }
    }
    node.ensure_solved().unwrap();
    let (a, b) = (one.delta_values().unwrap(), node.delta_values().unwrap());
    for (u, v) in a.iter().zip(b) {
        assert!((u - v).abs() < 1e-9 * u.abs().max(1e-12), "{u} vs {v}");
    }
    let ya = one.transform(View::from_slice(&x, n, d).unwrap()).unwrap();
    let yb = node.transform(View::from_slice(&x, n, d).unwrap()).unwrap();
    let err = ya.iter().zip(&yb).map(|(u, v)| (u - v).abs()).fold(0.0, f64::max);
    assert!(err < 1e-6, "{err}");
}

#[test]
fn state_round_trip_is_bit_exact() {
    let (n, d) = (800, 4);
    let x = correlated(n, d, 17);
    let node = fit(
        &x,
        n,
        d,
        NodeConfig { n_components: 3, degree: 2, reduce_to: Some(3), tol: 1e-10, mixed_precision: false },
    );
    let back = SfaNode::from_state(&node.state(true)).unwrap();
    assert_eq!(node.state(true), back.state(true));
    let v = View::from_slice(&x, n, d).unwrap();
    let all = node.transform(v).unwrap();
    assert_eq!(all, back.transform(v).unwrap());
    // one row per call (the per-position calls of a network without weight sharing) gives the same rows
    let m = all.len() / n;
    for r in (0..n).step_by(97) {
        let one = back.transform(View::from_slice(&x[r * d..(r + 1) * d], 1, d).unwrap()).unwrap();
        assert!(one.iter().zip(&all[r * m..(r + 1) * m]).all(|(a, b)| (a - b).abs() <= 1e-12 * (1.0 + b.abs())));
    }
    let mut broken = node.state(false);
    broken.stages[1].solution.as_mut().unwrap().projection.pop();
    assert!(SfaNode::from_state(&broken).is_err());
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    assert!(SfaNode::new(NodeConfig::linear(0)).is_err());
    assert!(SfaNode::new(NodeConfig {
        n_components: 1,
        degree: 0,
        reduce_to: None,
        tol: 1e-10,
        mixed_precision: false
    })
    .is_err());
    assert!(SfaNode::new(NodeConfig {
        n_components: 1,
        degree: 1,
        reduce_to: None,
        tol: f64::NAN,
        mixed_precision: false
    })
    .is_err());
    let mut node = SfaNode::new(NodeConfig::linear(2)).unwrap();
    let x = [1.0, 2.0, 3.0];
    assert!(matches!(node.transform(View::from_slice(&x, 1, 3).unwrap()), Err(SfaError::NotFitted(_))));
    node.partial_fit(View::from_slice(&x, 1, 3).unwrap(), true).unwrap();
    assert!(matches!(node.ensure_solved(), Err(SfaError::TooFewSamples { .. })));
    assert!(node.partial_fit(View::from_slice(&x[..2], 1, 2).unwrap(), false).is_err());
    assert!(expand(View::from_slice(&[f64::INFINITY], 1, 1).unwrap(), 2).is_err());
}

#[test]
fn a_batch_of_graphs_trains_a_node_as_the_graphs_one_by_one() {
    use sfa_core::stats::GraphPart;
    let (d, sizes) = (5, [300usize, 1, 450, 200]);
    let n: usize = sizes.iter().sum();
    let x = common::correlated(n, d, 41);
    let cfg = NodeConfig { n_components: 3, degree: 2, reduce_to: Some(4), tol: 1e-10, mixed_precision: false };
    // per graph: a path over its rows (consecutive rows as edges, unit weights), so that the
    // sequence API (Accumulator::update, an independent path) is the reference
    let graphs: Vec<(usize, usize, Vec<f64>, Vec<[usize; 2]>)> = sizes
        .iter()
        .scan(0, |s, &m| {
            let g = (*s, m, vec![1.0; m], (1..m).map(|i| [i - 1, i]).collect());
            *s += m;
            Some(g)
        })
        .collect();
    let (mut one, mut batch) = (SfaNode::new(cfg.clone()).unwrap(), SfaNode::new(cfg).unwrap());
    for _stage in 0..2 {
        for (s, m, _, _) in &graphs {
            one.partial_fit(View::from_slice(&x[s * d..(s + m) * d], *m, d).unwrap(), true).unwrap();
        }
        let ps: Vec<GraphPart<'_, f64>> = graphs
            .iter()
            .map(|(s, m, w, e)| GraphPart {
                x: View::from_slice(&x[s * d..(s + m) * d], *m, d).unwrap(),
                weights: Some(w),
                edges: e,
                edge_weights: None,
            })
            .collect();
        batch.partial_fit_graphs(0, &ps).unwrap();
        one.finish_stage().unwrap();
        batch.finish_stage().unwrap();
    }
    let (ya, yb) = (
        one.transform(View::from_slice(&x, n, d).unwrap()).unwrap(),
        batch.transform(View::from_slice(&x, n, d).unwrap()).unwrap(),
    );
    let scale = ya.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let diff = ya.iter().zip(&yb).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(diff <= 1e-9 * scale, "outputs differ by {diff}");
    // the expansion overflows: a clear error, nothing added
    let huge = vec![1e200; 2 * d];
    let ps =
        [GraphPart { x: View::from_slice(&huge, 2, d).unwrap(), weights: None, edges: &[[0, 1]], edge_weights: None }];
    let mut fresh =
        SfaNode::new(NodeConfig { n_components: 1, degree: 2, reduce_to: None, tol: 1e-10, mixed_precision: false })
            .unwrap();
    let err = fresh.partial_fit_graphs(0, &ps).unwrap_err();
    assert!(err.to_string().contains("overflows"), "{err}");
}

#[test]
fn a_node_loaded_without_statistics_refuses_more_training() {
    use sfa_core::stats::GraphPart;
    let (n, d) = (400, 4);
    let x = correlated(n, d, 23);
    let node = fit(
        &x,
        n,
        d,
        NodeConfig { n_components: 3, degree: 2, reduce_to: Some(3), tol: 1e-10, mixed_precision: false },
    );
    let mut loaded = SfaNode::from_state(&node.state(false)).unwrap();
    let edges: Vec<[usize; 2]> = (1..n).map(|i| [i - 1, i]).collect();
    let part = |x| GraphPart { x, weights: None, edges: &edges, edge_weights: None };
    // rows of stage 0 (raw input) and of stage 1 (the reduced rows): an error, never a panic
    let raw = part(View::from_slice(&x, n, d).unwrap());
    assert!(matches!(loaded.partial_fit_graphs(0, &[raw]), Err(SfaError::NotFitted(_))));
    let reduced = vec![0.5; n * 3];
    let mid = part(View::from_slice(&reduced, n, 3).unwrap());
    assert!(matches!(loaded.partial_fit_graphs(1, &[mid]), Err(SfaError::NotFitted(_))));
    assert!(matches!(loaded.partial_fit(View::from_slice(&x, n, d).unwrap(), true), Err(SfaError::NotFitted(_))));
    // the loaded node still transforms as the trained one
    let v = View::from_slice(&x, n, d).unwrap();
    assert_eq!(node.transform(v).unwrap(), loaded.transform(v).unwrap());
}
