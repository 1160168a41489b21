//! Partitioned (distributed) training: trainers on copies of the network,
//! one per partition of the images, merged on a driver, reproduce `fit`.
mod common;
use common::images;
use sfa_core::{
    fit, Accumulator, CachePolicy, FitOptions, InMemory, LayerSpec, LayerTrainer, LoopClosures, Network, NetworkSpec,
    Result, Rotation, SpatialPairs, TrainingPath,
};
use std::sync::Arc;

fn spec(v: usize, c: usize, sharing: bool) -> NetworkSpec {
    let n_w1 = (v - 4) / 2 + 1;
    NetworkSpec {
        height: 6,
        width: v,
        channels: c,
        layers: vec![
            LayerSpec { rf: (4, 3), stride: (2, 3), n_out: 4, reduce_to: Some(5), degree: 2 },
            LayerSpec { rf: (n_w1, 2), stride: (1, 1), n_out: 3, reduce_to: Some(6), degree: 2 },
        ],
        weight_sharing: sharing,
        tol: 1e-10,
        mixed_precision: false,
    }
}

fn max_rel(a: &[f64], b: &[f64]) -> f64 {
    let scale = a.iter().map(|v| v.abs()).fold(0.0, f64::max).max(1e-300);
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max) / scale
}

fn max_abs(a: &[f64]) -> f64 {
    a.iter().map(|v| v.abs()).fold(0.0, f64::max)
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

/// Largest relative difference of any stage's projection, mean or delta
/// values over every node.
fn weights_differ(a: &Network, b: &Network) -> f64 {
    let mut e = 0.0f64;
    for l in 0..a.n_layers() {
        for (na, nb) in a.nodes(l).iter().zip(b.nodes(l)) {
            for (sa, sb) in na.state(false).stages.iter().zip(&nb.state(false).stages) {
                let (pa, pb) = (sa.solution.as_ref().unwrap(), sb.solution.as_ref().unwrap());
                e = e.max(max_rel(&pa.projection, &pb.projection));
                // means on the scale of the (unit-variance) signals: near 0 above layer 1
                e = e.max(max_abs_diff(&pa.mean, &pb.mean) / max_abs(&pa.mean).max(1.0));
                e = e.max(max_rel(&pa.delta, &pb.delta));
            }
        }
    }
    e
}

#[derive(Clone, Copy)]
struct Plan<'a> {
    rot: Rotation,
    path: TrainingPath,
    tw: f64,
    lag: bool,
    /// Partition starts after the first (image indices).
    cuts: &'a [usize],
    /// Images that start a new recording (no pair with the image before).
    breaks: &'a [usize],
    /// Images per feed call.
    batch: usize,
}

impl Plan<'_> {
    /// Partition boundaries of `n` images: 0, the cuts, `n`.
    fn bounds(&self, n: usize) -> Vec<usize> {
        let mut b = vec![0];
        b.extend_from_slice(self.cuts);
        b.push(n);
        b
    }
}

fn single(net: &mut Network, imgs: &[f64], n: usize, p: &Plan<'_>, cache: bool) {
    let mut opts = FitOptions::new(p.rot);
    opts.path = p.path;
    opts.cache = if cache { CachePolicy::Always } else { CachePolicy::Never };
    opts.transition_weight = p.tw;
    opts.lag_products = p.lag;
    fit(net, &mut InMemory::new(imgs, n, 7).unwrap(), &opts, &mut |_| Ok(())).unwrap();
}

#[test]
fn partitions_reproduce_fit() {
    let (w, c, n) = (24, 3, 30);
    let imgs = images(n, 6, w, c, 11);
    let rot = Rotation { step: 3, period: w };
    for (sharing, path, tw, lag) in [
        (true, TrainingPath::Fast, 1.0, true),
        (true, TrainingPath::Fast, 1.0, false),
        (true, TrainingPath::Fast, 4.0, true),
        (true, TrainingPath::Naive, 1.0, false),
        (false, TrainingPath::Naive, 1.0, false),
        (false, TrainingPath::Naive, 2.5, false),
    ] {
        for cuts in [&[][..], &[13][..], &[1, 17][..], &[9, 10, 29][..]] {
            let p = Plan { rot, path, tw, lag, cuts, breaks: &[], batch: 4 };
            let mut reference = Network::new(spec(w, c, sharing)).unwrap();
            single(&mut reference, &imgs, n, &p, path == TrainingPath::Fast);
            let mut net = Network::new(spec(w, c, sharing)).unwrap();
            fit_partitioned(&mut net, &imgs, n, &p, &[], &[]).unwrap();
            assert!(net.is_trained());
            let e = weights_differ(&reference, &net);
            assert!(e < 1e-9, "sharing={sharing} {path:?} tw={tw} lag={lag} cuts={cuts:?}: weights differ by {e}");
            let (ya, yb) = (
                reference.transform(&imgs[..5 * 6 * w * c], 5).unwrap(),
                net.transform(&imgs[..5 * 6 * w * c], 5).unwrap(),
            );
            assert!(max_rel(&ya, &yb) < 1e-9);
        }
    }
}

#[test]
fn breaks_end_the_sequence_wherever_they_fall() {
    let (w, c, n) = (24, 1, 30);
    let imgs = images(n, 6, w, c, 5);
    let rot = Rotation { step: 4, period: w };
    for (sharing, path) in [(true, TrainingPath::Fast), (false, TrainingPath::Naive)] {
        let plan = |cuts, breaks| Plan { rot, path, tw: 1.0, lag: true, cuts, breaks, batch: 5 };
        let run = |p: &Plan<'_>| {
            let mut net = Network::new(spec(w, c, sharing)).unwrap();
            fit_partitioned(&mut net, &imgs, n, p, &[], &[]).unwrap();
            net
        };
        // a break at a partition boundary or inside a partition: the same
        let at_cut = run(&plan(&[12, 21], &[21]));
        let inside = run(&plan(&[12], &[21]));
        let one_part = run(&plan(&[], &[21]));
        assert!(weights_differ(&at_cut, &inside) < 1e-9);
        assert!(weights_differ(&at_cut, &one_part) < 1e-9);
        // and not the same as without the break
        let unbroken = run(&plan(&[12, 21], &[]));
        assert!(weights_differ(&at_cut, &unbroken) > 1e-6);
    }
}

#[test]
fn resume_checks_layer_and_pass() {
    let (w, c, n) = (24, 1, 12);
    let imgs = images(n, 6, w, c, 3);
    let size = 6 * w * c;
    let rot = Rotation { step: 4, period: w };
    let mut net = Network::new(spec(w, c, true)).unwrap();
    assert!(LayerTrainer::resume(&net, 0, 1, rot, TrainingPath::Fast).is_err()); // pass 0 first
    assert!(LayerTrainer::resume(&net, 0, 2, rot, TrainingPath::Fast).is_err()); // two passes
    assert!(LayerTrainer::resume(&net, 1, 0, rot, TrainingPath::Fast).is_err()); // layer 1 untrained
    let mut tr = LayerTrainer::resume(&net, 0, 0, rot, TrainingPath::Fast).unwrap();
    assert!(tr.statistics(&net).is_err()); // nothing fed
    let mut nan = imgs[..size].to_vec();
    nan[7] = f64::NAN;
    let e = tr.prime(&net, &nan).unwrap_err().to_string();
    assert!(e.contains("the image before this partition"), "{e}");
    let mut bad = imgs.clone();
    bad[5 * size + 3] = f64::NAN;
    let e = tr.feed(&mut net.clone(), &bad, n).unwrap_err().to_string();
    assert!(e.contains("image 5"), "{e}");
    tr.feed(&mut net, &imgs, n).unwrap();
    let st = tr.statistics(&net).unwrap();
    // merging into a trainer at another pass fails
    let mut driver = Network::new(spec(w, c, true)).unwrap();
    let mut d0 = LayerTrainer::resume(&driver, 0, 0, rot, TrainingPath::Fast).unwrap();
    d0.merge_statistics(&mut driver, &st, n).unwrap();
    d0.end_pass(&mut driver).unwrap();
    assert!(LayerTrainer::resume(&driver, 0, 0, rot, TrainingPath::Fast).is_err());
    let mut d1 = LayerTrainer::resume(&driver, 0, 1, rot, TrainingPath::Fast).unwrap();
    assert!(d1.merge_statistics(&mut driver, &st, n).is_err()); // stage-0 statistics
    assert!(d1.merge_statistics(&mut driver, &[], n).is_err());
}

/// Every layer and pass: each partition on its own copy of the network
/// (primed with the image before it unless a recording breaks there),
/// statistics merged in partition order on the driver. Loop closures
/// `(past, current, weight)` and spatial pairs `(a, b, weight)` of the
/// whole run are split as the distributed fit splits them:
/// each partition's trainer gets the closures of its own images (indices
/// counted within it, partners the earlier images), and the pairs go to
/// trainers of their own, fed pairs only, two pairs each.
fn fit_partitioned(
    net: &mut Network,
    imgs: &[f64],
    n: usize,
    p: &Plan<'_>,
    closures: &[(usize, usize, f64)],
    pairs: &[(usize, usize, f64)],
) -> Result<()> {
    let size = imgs.len() / n;
    let bounds = p.bounds(n);
    while net.n_trained() < net.n_layers() {
        let layer = net.n_trained();
        for pass in 0..net.nodes(layer)[0].n_stages() {
            let mut results: Vec<Vec<Accumulator>> = Vec::new();
            for w in bounds.windows(2) {
                let (a, b) = (w[0], w[1]);
                let mut local = net.clone();
                let mut tr = LayerTrainer::resume(&local, layer, pass, p.rot, p.path)?;
                tr.set_transition_weight(p.tw)?;
                tr.set_lag_products(p.lag);
                let own: Vec<&(usize, usize, f64)> = closures.iter().filter(|c| (a..b).contains(&c.1)).collect();
                if !own.is_empty() {
                    let partners: Vec<f64> =
                        own.iter().flat_map(|c| imgs[c.0 * size..(c.0 + 1) * size].to_vec()).collect();
                    let lc = LoopClosures::new(
                        own.iter().map(|c| c.1 - a).collect(),
                        own.iter().map(|c| c.2).collect(),
                        partners,
                    )?;
                    tr.set_loop_closures(&local, Some(Arc::new(lc)))?;
                }
                tr.set_reference_image(&local, &imgs[..size])?;
                if a > 0 && !p.breaks.contains(&a) {
                    tr.prime(&local, &imgs[(a - 1) * size..a * size])?;
                }
                let mut i = a;
                while i < b {
                    if i > a && p.breaks.contains(&i) {
                        tr.break_sequence();
                    }
                    // a batch ends before the next break
                    let mut j = (i + p.batch).min(b);
                    if let Some(&k) = p.breaks.iter().filter(|&&k| k > i && k < j).min() {
                        j = k;
                    }
                    tr.feed(&mut local, &imgs[i * size..j * size], j - i)?;
                    i = j;
                }
                results.push(tr.statistics(&local)?);
            }
            for chunk in pairs.chunks(2) {
                let mut local = net.clone();
                let mut tr = LayerTrainer::resume(&local, layer, pass, p.rot, p.path)?;
                let ids: Vec<usize> = chunk.iter().flat_map(|&(a, b, _)| [a, b]).collect();
                let gathered: Vec<f64> = ids.iter().flat_map(|&i| imgs[i * size..(i + 1) * size].to_vec()).collect();
                let local_pairs: Vec<(usize, usize, f64)> =
                    chunk.iter().enumerate().map(|(e, &(_, _, w))| (2 * e, 2 * e + 1, w)).collect();
                tr.feed_pairs(&mut local, &gathered, ids.len(), &local_pairs)?;
                assert_eq!(tr.images_seen(), 0);
                assert_eq!(tr.pairs_fed(), chunk.len());
                results.push(tr.statistics(&local)?);
            }
            let mut merged = results.remove(0);
            for st in &results {
                for (x, y) in merged.iter_mut().zip(st) {
                    x.merge(y)?;
                }
            }
            let mut tr = LayerTrainer::resume(net, layer, pass, p.rot, p.path)?;
            tr.merge_statistics(net, &merged, n)?;
            tr.end_pass(net)?;
        }
    }
    Ok(())
}

#[test]
fn closures_and_pairs_split_over_partitions_reproduce_fit() {
    let (w, c, n) = (24, 3, 30);
    let imgs = images(n, 6, w, c, 11);
    let size = 6 * w * c;
    let rot = Rotation { step: 3, period: w };
    // closures at a partition's first image (13) and last (12), partners in other partitions
    let closures = [(2, 13, 1.0), (5, 12, 0.5), (20, 27, 1.0), (0, 17, 0.8)];
    let pairs = [(1, 7, 1.0), (3, 25, 0.5), (12, 13, 2.0), (29, 4, 1.0), (8, 9, 0.7)];
    for path in [TrainingPath::Fast, TrainingPath::Naive] {
        let p = Plan { rot, path, tw: 1.0, lag: true, cuts: &[13, 22], breaks: &[], batch: 4 };
        let mut opts = FitOptions::new(rot);
        opts.path = path;
        opts.cache = CachePolicy::Never;
        let partners: Vec<f64> = closures.iter().flat_map(|c| imgs[c.0 * size..(c.0 + 1) * size].to_vec()).collect();
        opts.loop_closures = Some(Arc::new(
            LoopClosures::new(closures.iter().map(|c| c.1).collect(), closures.iter().map(|c| c.2).collect(), partners)
                .unwrap(),
        ));
        opts.pairs = Some(SpatialPairs { pairs: pairs.to_vec(), shifts: None, layers: vec![0, 1], chunk: 3 });
        let mut reference = Network::new(spec(w, c, true)).unwrap();
        fit(&mut reference, &mut InMemory::new(&imgs, n, 7).unwrap(), &opts, &mut |_| Ok(())).unwrap();
        let mut net = Network::new(spec(w, c, true)).unwrap();
        fit_partitioned(&mut net, &imgs, n, &p, &closures, &pairs).unwrap();
        // (closures and pairs leave near-null directions of the top expansion ill-determined: the outputs and
        // the samples and pairs counted are compared tightly, the weights loosely)
        let (ya, yb) = (reference.transform(&imgs, n).unwrap(), net.transform(&imgs, n).unwrap());
        assert!(max_rel(&ya, &yb) < 1e-9, "{path:?}: outputs differ by {}", max_rel(&ya, &yb));
        assert!(weights_differ(&reference, &net) < 1e-5, "{path:?}: {}", weights_differ(&reference, &net));
        let counts = |net: &Network| -> Vec<(u64, u64)> {
            (0..net.n_layers())
                .flat_map(|l| {
                    net.nodes(l)
                        .iter()
                        .flat_map(|node| {
                            node.state(true)
                                .stages
                                .iter()
                                .map(|s| s.stats.as_ref().map_or((0, 0), |a| (a.n_samples, a.n_pairs)))
                                .collect::<Vec<_>>()
                        })
                        .collect::<Vec<_>>()
                })
                .collect()
        };
        assert_eq!(counts(&reference), counts(&net), "{path:?}");
        // a trainer fed nothing has no statistics
        let tr = LayerTrainer::resume(&Network::new(spec(w, c, true)).unwrap(), 0, 0, rot, path).unwrap();
        assert!(tr.statistics(&Network::new(spec(w, c, true)).unwrap()).is_err());
    }
}
