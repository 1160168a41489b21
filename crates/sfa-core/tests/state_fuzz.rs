//! Structure-aware fuzzing of the state parsers (property tests): states of
//! trained nodes and networks with one or two fields changed together (the
//! edits a model file with recomputed checksums can carry) must be refused
//! with an error or restore into something that works; never a panic or an
//! allocation beyond the memory limit.

use proptest::prelude::*;
use sfa_core::{LayerSpec, Network, NetworkSpec, NodeConfig, NodeState, SfaNode, View};

const INTERESTING: [usize; 12] = [0, 1, 2, 3, 7, 48, 1000, 1 << 20, 1 << 32, 1 << 40, usize::MAX / 2, usize::MAX];

fn trained_node(reduce: bool, with_stats: bool) -> NodeState {
    let n = 300;
    let d = 4;
    let x: Vec<f64> = (0..n * d).map(|i| ((i * 7919) % 1013) as f64 / 100.0 + (i / d) as f64 * 0.01).collect();
    let cfg = NodeConfig { n_components: 2, degree: 2, reduce_to: reduce.then_some(3), ..NodeConfig::linear(2) };
    let mut node = SfaNode::new(cfg).unwrap();
    for _ in 0..node.n_stages() {
        node.partial_fit(View::from_slice(&x, n, d).unwrap(), true).unwrap();
        node.finish_stage().unwrap();
    }
    node.state(with_stats)
}

/// One integer field of a node state, by index.
fn field(st: &mut NodeState, which: usize) -> Option<&mut usize> {
    let n_stages = st.stages.len();
    let s = which / 8 % n_stages.max(1);
    match which % 8 {
        0 => Some(&mut st.n_features),
        1 => Some(&mut st.training_stage),
        2 => Some(&mut st.config.n_components),
        3 => Some(&mut st.config.degree),
        4 => st.stages.get_mut(s).map(|x| &mut x.input_dim),
        5 => st.stages.get_mut(s).map(|x| &mut x.n_out),
        6 => st.stages.get_mut(s).and_then(|x| x.solution.as_mut()).map(|x| &mut x.rank),
        _ => st.stages.get_mut(s).and_then(|x| x.stats.as_mut()).map(|x| &mut x.dim),
    }
}

fn use_node(node: &SfaNode) {
    if let Some(d) = node.n_features() {
        if d <= 1 << 16 && node.is_solved() {
            let x = vec![0.5; 2 * d];
            let _ = node.transform(View::from_slice(&x, 2, d).unwrap());
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 600, ..ProptestConfig::default() })]

    #[test]
    fn edited_node_states_never_panic(
        reduce in any::<bool>(),
        stats in any::<bool>(),
        a in 0usize..32,
        b in 0usize..32,
        va in 0usize..INTERESTING.len(),
        same in any::<bool>(),
        vb in 0usize..INTERESTING.len(),
        drop_vec in 0usize..6,
    ) {
        let mut st = trained_node(reduce, stats);
        let v = INTERESTING[va];
        if let Some(f) = field(&mut st, a) { *f = v; }
        let w = if same { v } else { INTERESTING[vb] };
        if let Some(f) = field(&mut st, b) { *f = w; }
        if let Some(sol) = st.stages.last_mut().and_then(|s| s.solution.as_mut()) {
            match drop_vec {
                0 => { sol.mean.pop(); }
                1 => sol.projection.truncate(sol.projection.len() / 2),
                2 => sol.delta.push(f64::NAN),
                3 => sol.dropped.push(1.0),
                _ => {}
            }
        }
        match SfaNode::from_state(&st) {
            Ok(node) => use_node(&node),
            Err(e) => prop_assert!(!e.to_string().is_empty()),
        }
    }

    #[test]
    fn edited_network_states_never_panic(
        layer in 0usize..2,
        a in 0usize..32,
        va in 0usize..INTERESTING.len(),
        trained in 0usize..4,
        n_nodes in 0usize..3,
    ) {
        let spec = NetworkSpec {
            height: 4, width: 12, channels: 1,
            layers: vec![
                LayerSpec { rf: (6, 4), stride: (6, 4), n_out: 3, reduce_to: None, degree: 2 },
                LayerSpec { rf: (2, 1), stride: (1, 1), n_out: 2, reduce_to: None, degree: 2 },
            ],
            weight_sharing: true, tol: 1e-10, mixed_precision: false,
        };
        let net = trained_network(&spec);
        let mut states = net.node_states(false);
        if let Some(st) = states[layer].get_mut(0) {
            if let Some(f) = field(st, a) { *f = INTERESTING[va]; }
        }
        match n_nodes { 0 => states[layer].clear(), 2 => { let s = states[layer][0].clone(); states[layer].push(s) } _ => {} }
        if let Ok(net) = Network::from_states(spec.clone(), &states, trained) {
            if net.is_trained() {
                let _ = net.transform(&vec![0u8; 48], 1);
            }
        }
    }
}

fn trained_network(spec: &NetworkSpec) -> Network {
    use sfa_core::{fit, FitOptions, InMemory, Rotation};
    let n = 20;
    let imgs: Vec<f64> = (0..n * 48).map(|i| (((i * 2654435761usize) >> 7) % 255) as f64 + (i / 48) as f64).collect();
    let mut net = Network::new(spec.clone()).unwrap();
    let mut src = InMemory::new(&imgs, n, 8).unwrap();
    fit(&mut net, &mut src, &FitOptions::new(Rotation { step: 6, period: 12 }), &mut |_| Ok(())).unwrap();
    net
}
