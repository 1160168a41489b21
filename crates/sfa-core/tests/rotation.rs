mod common;
use common::images;
use sfa_core::{
    fit, transform_rotations, CachePolicy, FitOptions, FitReport, InMemory, LayerSpec, LayerTrainer, Network,
    NetworkSpec, Progress, ProgressEvent, Result, Rotation, SfaError, SpatialPairs, TrainingPath,
};

/// Options of [`fit`] for a path, cache on or off and a transition weight.
fn options(rot: Rotation, path: TrainingPath, cache: bool, tw: f64) -> FitOptions {
    let mut opts = FitOptions::new(rot);
    opts.path = path;
    opts.cache = if cache { CachePolicy::Always } else { CachePolicy::Never };
    opts.transition_weight = tw;
    opts
}

/// Trains every layer with [`fit`] on in-memory images (batches of 16).
fn fit_with(net: &mut Network, imgs: &[f64], n: usize, opts: &FitOptions) -> Result<FitReport> {
    fit(net, &mut InMemory::new(imgs, n, 16)?, opts, &mut |_| Ok(()))
}

fn train(
    net: &mut Network,
    rot: Rotation,
    imgs: &[f64],
    n: usize,
    path: TrainingPath,
    cache: bool,
) -> Result<FitReport> {
    fit_with(net, imgs, n, &options(rot, path, cache, 1.0))
}

fn train_weighted(
    net: &mut Network,
    rot: Rotation,
    imgs: &[f64],
    n: usize,
    path: TrainingPath,
    cache: bool,
    tw: f64,
) -> Result<FitReport> {
    fit_with(net, imgs, n, &options(rot, path, cache, tw))
}

fn spec(v: usize, c: usize, stride: usize, sharing: bool) -> NetworkSpec {
    let n_w1 = (v - 4) / stride + 1;
    NetworkSpec {
        height: 6,
        width: v,
        channels: c,
        layers: vec![
            LayerSpec { rf: (4, 3), stride: (stride, 3), n_out: 4, reduce_to: Some(5), degree: 2 },
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

fn compare(v: usize, stride: usize, step: usize, c: usize, cache: bool) {
    compare_weighted(v, stride, step, c, cache, 1.0)
}

fn compare_weighted(v: usize, stride: usize, step: usize, c: usize, cache: bool, tw: f64) {
    let w = 24;
    let n = 40;
    let imgs = images(n, 6, w, c, 7 + step as u64);
    let rot = Rotation { step, period: w };
    let mut naive = Network::new(spec(v, c, stride, true)).unwrap();
    let mut fast = naive.clone();
    train_weighted(&mut naive, rot, &imgs, n, TrainingPath::Naive, false, tw).unwrap();
    train_weighted(&mut fast, rot, &imgs, n, TrainingPath::Fast, cache, tw).unwrap();
    for l in 0..2 {
        let (a, b) = (naive.nodes(l)[0].state(true), fast.nodes(l)[0].state(true));
        for (sa, sb) in a.stages.iter().zip(&b.stages) {
            let (pa, pb) = (sa.solution.as_ref().unwrap(), sb.solution.as_ref().unwrap());
            let e = max_rel(&pa.projection, &pb.projection);
            assert!(e < 1e-9, "v={v} stride={stride} step={step} layer {l}: projection differs by {e}");
            assert!(max_rel(&pa.delta, &pb.delta) < 1e-9);
        }
    }
    // Inference under rotation agrees with rolling and transforming.
    let m = 3;
    let yr = transform_rotations(&fast, rot, &imgs[..2 * 6 * w * c], 2).unwrap();
    let kv = rot.n_views();
    for i in 0..2 {
        for k in 0..kv {
            let img = &imgs[i * 6 * w * c..(i + 1) * 6 * w * c];
            let mut vw = Vec::new();
            for y in 0..6 {
                for x in 0..v {
                    let col = (k * step + x) % w;
                    vw.extend_from_slice(&img[(y * w + col) * c..(y * w + col + 1) * c]);
                }
            }
            let y = fast.transform(&vw, 1).unwrap();
            let got = &yr[(i * kv + k) * m..(i * kv + k + 1) * m];
            assert!(max_rel(&y, got) < 1e-9);
        }
    }
}

#[test]
fn fast_equals_naive_full_window() {
    compare(24, 2, 2, 1, false);
    compare(24, 2, 2, 1, true);
}

#[test]
fn fast_equals_naive_step_not_dividing_stride() {
    compare(24, 2, 3, 1, true);
}

#[test]
fn fast_equals_naive_narrow_window_rgb() {
    compare(16, 2, 5, 3, true);
}

/// Weighted pairs between consecutive images: fast == naive for weights
/// above, below and at zero.
#[test]
fn fast_equals_naive_transition_weights() {
    for tw in [0.0, 0.25, 10.0, 300.0] {
        compare_weighted(24, 2, 2, 1, true, tw);
        compare_weighted(16, 2, 5, 3, false, tw);
    }
}

/// Pair weight of the first stage of the first layer after training, with
/// the given transition weight and lag products on or off.
fn first_pair_weight(spec: NetworkSpec, rot: Rotation, imgs: &[f64], n: usize, tw: f64, lag: bool) -> f64 {
    let mut net = Network::new(spec).unwrap();
    let mut tr = LayerTrainer::new(&net, 0, rot, TrainingPath::Fast).unwrap();
    tr.set_lag_products(lag);
    tr.set_transition_weight(tw).unwrap();
    tr.feed(&mut net, imgs, n).unwrap();
    net.nodes(0)[0].statistics().unwrap().pair_weight_sum()
}

/// The between-image pairs enter with exactly the transition weight: the
/// first stage's pair weight is `W_in + tw * (n - 1) * n_series`, with and
/// without lag products; and the naive path gives the same sums.
#[test]
fn transition_weight_scales_the_between_image_pairs() {
    let (w, n, step) = (48, 12, 3);
    let imgs = images(n, 6, w, 1, 21);
    let rot = Rotation { step, period: w };
    let s = wide_spec(48, 1, 2, false);
    // 19 RF columns x 3 RF rows.
    let n_series = Network::new(s.clone()).unwrap().geometry()[0].n_positions();
    assert_eq!(n_series, 57);
    for lag in [false, true] {
        let w0 = first_pair_weight(s.clone(), rot, &imgs, n, 0.0, lag);
        let w1 = first_pair_weight(s.clone(), rot, &imgs, n, 1.0, lag);
        let w7 = first_pair_weight(s.clone(), rot, &imgs, n, 7.0, lag);
        let between = ((n - 1) * n_series) as f64;
        assert!((w1 - w0 - between).abs() < 1e-9, "lag={lag}: {w1} - {w0} != {between}");
        assert!((w7 - w0 - 7.0 * between).abs() < 1e-9, "lag={lag}");
        // Within-image pairs: (K - 1) per series and image.
        let within = (n * (rot.n_views() - 1) * n_series) as f64;
        assert!((w0 - within).abs() < 1e-9, "lag={lag}: {w0} != {within}");
    }
    let net = Network::new(s).unwrap();
    for v in [-1.0, f64::NAN, f64::INFINITY] {
        let mut t = LayerTrainer::new(&net, 0, rot, TrainingPath::Fast).unwrap();
        let e = t.set_transition_weight(v).unwrap_err().to_string();
        assert!(e.contains("transition_weight"), "{e}");
    }
}

/// Individual nodes: the weighted graph path (any weight != 1) agrees with
/// the sequence path at weight 1 (up to rounding), and a large weight
/// changes the solution.
#[test]
fn individual_nodes_transition_weight() {
    let (w, n) = (24, 30);
    let imgs = images(n, 6, w, 1, 3);
    let rot = Rotation { step: 2, period: w };
    let base = Network::new(spec(24, 1, 4, false)).unwrap();
    let (mut seq, mut graph, mut heavy) = (base.clone(), base.clone(), base);
    train(&mut seq, rot, &imgs, n, TrainingPath::Fast, false).unwrap();
    train_weighted(&mut graph, rot, &imgs, n, TrainingPath::Fast, false, 1.0 + 1e-15).unwrap();
    train_weighted(&mut heavy, rot, &imgs, n, TrainingPath::Fast, false, 50.0).unwrap();
    for l in 0..2 {
        for (i, (a, b)) in seq.nodes(l).iter().zip(graph.nodes(l)).enumerate() {
            let (sa, sb) = (a.state(false), b.state(false));
            for (x, y) in sa.stages.iter().zip(&sb.stages) {
                let (px, py) = (x.solution.as_ref().unwrap(), y.solution.as_ref().unwrap());
                assert!(max_rel(&px.delta, &py.delta) < 1e-9, "layer {l} node {i}");
            }
        }
    }
    let d = |net: &Network| net.nodes(1)[0].state(false).stages[1].solution.clone().unwrap().delta;
    assert!(max_rel(&d(&seq), &d(&heavy)) > 1e-3);
}

/// A small three-layer gray network on 6 x 24 panoramas (reductions in
/// every layer), for the tests that follow fields through layers 2 and 3.
fn three_layer_spec() -> NetworkSpec {
    NetworkSpec {
        height: 6,
        width: 24,
        channels: 1,
        layers: vec![
            LayerSpec { rf: (4, 3), stride: (2, 3), n_out: 4, reduce_to: Some(5), degree: 2 },
            LayerSpec { rf: (3, 2), stride: (2, 1), n_out: 3, reduce_to: Some(6), degree: 2 },
            LayerSpec { rf: (5, 1), stride: (1, 1), n_out: 2, reduce_to: Some(5), degree: 2 },
        ],
        weight_sharing: true,
        tol: 1e-10,
        mixed_precision: false,
    }
}

#[test]
fn cached_fields_advance_through_three_layers() {
    let (w, n) = (24, 40);
    let imgs = images(n, 6, w, 1, 11);
    let spec = three_layer_spec();
    let rot = Rotation { step: 3, period: w };
    let mut naive = Network::new(spec).unwrap();
    let mut cached = naive.clone();
    train(&mut naive, rot, &imgs, n, TrainingPath::Naive, false).unwrap();
    train(&mut cached, rot, &imgs, n, TrainingPath::Fast, true).unwrap();
    for l in 0..3 {
        let (a, b) = (naive.nodes(l)[0].state(false), cached.nodes(l)[0].state(false));
        let (pa, pb) = (a.stages[1].solution.as_ref().unwrap(), b.stages[1].solution.as_ref().unwrap());
        assert!(max_rel(&pa.delta, &pb.delta) < 1e-9, "layer {l}");
    }
}

#[test]
fn individual_nodes_train() {
    let (w, n) = (24, 30);
    let imgs = images(n, 6, w, 1, 3);
    let mut net = Network::new(spec(24, 1, 4, false)).unwrap();
    assert_eq!(net.nodes(0).len(), 6 * 2);
    train(&mut net, Rotation { step: 2, period: w }, &imgs, n, TrainingPath::Fast, true).unwrap();
    let y = net.transform(&imgs[..6 * w], 1).unwrap();
    assert_eq!(y.len(), 3);
    assert!(y.iter().all(|v| v.is_finite()));
}

#[test]
fn bad_specs_name_the_layer() {
    let mut s = spec(24, 1, 2, true);
    s.layers[0].stride = (3, 3);
    let e = Network::new(s).unwrap_err().to_string();
    assert!(e.contains("layer 1") && e.contains("do not tile"), "{e}");
    let mut s = spec(24, 1, 2, true);
    s.layers[1].rf = (5, 2);
    let e = Network::new(s).unwrap_err().to_string();
    assert!(e.contains("layer 2"), "{e}");
    let mut s = spec(24, 1, 2, true);
    s.layers[0].n_out = 100;
    assert!(Network::new(s).unwrap_err().to_string().contains("exceeds the expanded dim"));
}

/// A first layer with wide RFs, where the lag-product statistics
/// (`periodic.rs`) pay and are used.
fn wide_spec(v: usize, c: usize, stride: usize, mixed: bool) -> NetworkSpec {
    let n_w1 = (v - 12) / stride + 1;
    NetworkSpec {
        height: 6,
        width: v,
        channels: c,
        layers: vec![
            LayerSpec { rf: (12, 2), stride: (stride, 2), n_out: 4, reduce_to: Some(6), degree: 2 },
            LayerSpec { rf: (n_w1, 3), stride: (1, 1), n_out: 3, reduce_to: Some(6), degree: 2 },
        ],
        weight_sharing: true,
        tol: 1e-10,
        mixed_precision: mixed,
    }
}

/// Trains every layer on the fast path with the field cache; returns how
/// many images the first layer took through lag products.
fn train_fast(net: &mut Network, rot: Rotation, imgs: &[f64], n: usize, lag: bool) -> usize {
    let mut opts = options(rot, TrainingPath::Fast, true, 1.0);
    opts.lag_products = lag;
    fit_with(net, imgs, n, &opts).unwrap().lag_product_images
}

fn projections(net: &Network) -> Vec<(Vec<f64>, Vec<f64>)> {
    (0..net.n_layers())
        .flat_map(|l| net.nodes(l)[0].state(false).stages)
        .map(|st| {
            let s = st.solution.unwrap();
            (s.projection, s.delta)
        })
        .collect()
}

/// Lag products (on by default) give the naive path's node weights, for
/// full and narrow windows, steps that do and do not divide the stride,
/// gray and RGB; and the structured path really ran.
#[test]
fn lag_product_statistics_equal_naive() {
    // (period, window, stride, step, channels). Offsets on the lattice 2Z
    // (g = 2) for the first and last; g = 1 with steps that do not divide
    // the stride, full and narrow windows, gray and RGB, for the others.
    for (w, v, stride, step, c) in [(24, 24, 2, 2, 1), (48, 40, 2, 3, 3), (48, 48, 2, 5, 1), (36, 36, 2, 2, 1)] {
        let n = 30;
        let imgs = images(n, 6, w, c, 11 + step as u64);
        let rot = Rotation { step, period: w };
        let mut naive = Network::new(wide_spec(v, c, stride, false)).unwrap();
        let mut fast = naive.clone();
        train(&mut naive, rot, &imgs, n, TrainingPath::Naive, false).unwrap();
        let used = train_fast(&mut fast, rot, &imgs, n, true);
        assert_eq!(used, n, "lag products not used for v={v} stride={stride} step={step}");
        for (i, ((pa, da), (pb, db))) in projections(&naive).iter().zip(&projections(&fast)).enumerate() {
            let e = max_rel(pa, pb);
            assert!(e < 1e-9, "v={v} stride={stride} step={step} c={c} stage {i}: projection differs by {e}");
            assert!(max_rel(da, db) < 1e-9);
        }
    }
}

/// Mixed precision: lag products in f32 agree with one f32 outer product
/// per patch to the mixed tolerance.
#[test]
fn lag_products_mixed_precision_close_to_plain() {
    let (w, c, n) = (48, 3, 30);
    let imgs = images(n, 6, w, c, 5);
    let rot = Rotation { step: 3, period: w };
    let mut plain = Network::new(wide_spec(40, c, 2, true)).unwrap();
    let mut lag = plain.clone();
    assert_eq!(train_fast(&mut plain, rot, &imgs, n, false), 0);
    assert_eq!(train_fast(&mut lag, rot, &imgs, n, true), n);
    let (a, b) = (&projections(&plain)[0].1, &projections(&lag)[0].1);
    let e = max_rel(a, b);
    assert!(e < 1e-4, "first-stage Delta values differ by {e}");
}

/// Trains every layer with the spatial pairs fed in every pass (from the
/// cache when the pass reads it).
fn train_pairs(
    net: &mut Network,
    rot: Rotation,
    imgs: &[f64],
    n: usize,
    path: TrainingPath,
    cache: bool,
    pairs: &[(usize, usize, f64)],
) {
    let mut opts = options(rot, path, cache, 1.0);
    opts.pairs =
        Some(SpatialPairs { pairs: pairs.to_vec(), shifts: None, layers: (0..net.n_layers()).collect(), chunk: 7 });
    fit_with(net, imgs, n, &opts).unwrap();
}

fn some_pairs(n: usize) -> Vec<(usize, usize, f64)> {
    (0..n).flat_map(|i| [(i, (i * 7 + 3) % n, 0.5 + (i % 3) as f64), (i, (i + 11) % n, 2.0)]).collect()
}

/// Spatial pairs at every rotation: the fast path (one pair per periodic
/// offset, weighted by multiplicity) equals the naive path (one pair per
/// view and RF position), with and without the field cache, for steps that
/// do and do not divide the stride, narrow windows and RGB.
#[test]
fn spatial_pairs_fast_equals_naive() {
    for (v, stride, step, c, cache) in [(24, 2, 2, 1, true), (24, 2, 3, 1, false), (16, 2, 5, 3, true)] {
        let (w, n) = (24, 30);
        let imgs = images(n, 6, w, c, 31 + step as u64);
        let rot = Rotation { step, period: w };
        let pairs = some_pairs(n);
        let base = Network::new(spec(v, c, stride, true)).unwrap();
        let (mut naive, mut fast, mut plain) = (base.clone(), base.clone(), base);
        train_pairs(&mut naive, rot, &imgs, n, TrainingPath::Naive, false, &pairs);
        train_pairs(&mut fast, rot, &imgs, n, TrainingPath::Fast, cache, &pairs);
        train(&mut plain, rot, &imgs, n, TrainingPath::Fast, cache).unwrap();
        for (i, ((pa, da), (pb, db))) in projections(&naive).iter().zip(&projections(&fast)).enumerate() {
            let e = max_rel(pa, pb);
            assert!(e < 1e-9, "v={v} step={step} c={c} stage {i}: projection differs by {e}");
            assert!(max_rel(da, db) < 1e-9);
        }
        // The pairs change the solution.
        let (a, b) = (&projections(&plain)[3].1, &projections(&fast)[3].1);
        assert!(max_rel(a, b) > 1e-3);
    }
}

/// A three-layer network: pairs from cached fields (layers 2 and 3) equal
/// pairs recomputed from the images.
#[test]
fn spatial_pairs_cached_equal_streamed() {
    let (w, n) = (24, 30);
    let imgs = images(n, 6, w, 1, 13);
    let s = three_layer_spec();
    let rot = Rotation { step: 3, period: w };
    let pairs = some_pairs(n);
    let mut streamed = Network::new(s).unwrap();
    let mut cached = streamed.clone();
    train_pairs(&mut streamed, rot, &imgs, n, TrainingPath::Fast, false, &pairs);
    train_pairs(&mut cached, rot, &imgs, n, TrainingPath::Fast, true, &pairs);
    for (i, ((pa, _), (pb, _))) in projections(&streamed).iter().zip(&projections(&cached)).enumerate() {
        assert!(max_rel(pa, pb) < 1e-9, "stage {i}");
    }
}

/// Each pair adds weight `w x K x n_positions` (every view, every RF
/// position) and no samples; bad pairs are refused.
#[test]
fn spatial_pairs_weight_and_validation() {
    let (w, n) = (24, 10);
    let imgs = images(n, 6, w, 1, 17);
    let rot = Rotation { step: 5, period: w };
    let mut net = Network::new(spec(24, 1, 2, true)).unwrap();
    let np = net.geometry()[0].n_positions();
    let mut tr = LayerTrainer::new(&net, 0, rot, TrainingPath::Fast).unwrap();
    tr.feed(&mut net, &imgs, n).unwrap();
    let before = net.nodes(0)[0].statistics().unwrap().clone();
    tr.feed_pairs(&mut net, &imgs, n, &[(0, 4, 2.5), (3, 9, 1.0), (5, 5, 3.0)]).unwrap();
    let after = net.nodes(0)[0].statistics().unwrap();
    let added = after.pair_weight_sum() - before.pair_weight_sum();
    let expect = 3.5 * (rot.n_views() * np) as f64;
    assert!((added - expect).abs() < 1e-9, "{added} != {expect}");
    assert_eq!(after.weight_sum(), before.weight_sum());
    let e = tr.feed_pairs(&mut net, &imgs, n, &[(0, 10, 1.0)]).unwrap_err().to_string();
    assert!(e.contains("beyond"), "{e}");
    let e = tr.feed_pairs(&mut net, &imgs, n, &[(0, 1, -1.0)]).unwrap_err().to_string();
    assert!(e.contains("non-negative"), "{e}");
    assert!(tr.feed_pairs_cached(&mut net, &[(0, 1, 1.0)]).is_err());
}

/// Individual nodes take the pairs too (one pair per view per node).
#[test]
fn spatial_pairs_individual_nodes() {
    let (w, n) = (24, 20);
    let imgs = images(n, 6, w, 1, 3);
    let rot = Rotation { step: 2, period: w };
    let mut net = Network::new(spec(24, 1, 4, false)).unwrap();
    let mut plain = net.clone();
    train_pairs(&mut net, rot, &imgs, n, TrainingPath::Fast, false, &some_pairs(n));
    train(&mut plain, rot, &imgs, n, TrainingPath::Fast, false).unwrap();
    let d = |x: &Network| x.nodes(1)[0].state(false).stages[1].solution.clone().unwrap().delta;
    assert!(d(&net).iter().all(|v| v.is_finite()));
    assert!(max_rel(&d(&net), &d(&plain)) > 1e-3);
}

/// Shifted pairs read from the cached fields at shifted offsets equal the
/// pairs with image `b` rolled and recomputed (step 3 divides the period).
#[test]
fn shifted_pairs_from_cache_equal_rolled_images() {
    let (w, n, h) = (24, 24, 6);
    let imgs = images(n, h, w, 1, 19);
    let s = three_layer_spec();
    let rot = Rotation { step: 3, period: w };
    let pairs = some_pairs(n);
    let shifts: Vec<usize> = (0..pairs.len()).map(|e| 3 * ((e * 5) % 8)).collect();
    // Reference: the rolled second images appended, pairs to them.
    let mut ext = imgs.clone();
    let mut ref_pairs = Vec::new();
    for (e, (&(a, b, wt), &sh)) in pairs.iter().zip(&shifts).enumerate() {
        let img = &imgs[b * h * w..(b + 1) * h * w];
        for y in 0..h {
            for x in 0..w {
                ext.push(img[y * w + (x + sh) % w]);
            }
        }
        ref_pairs.push((a, n + e, wt));
    }
    let m = n + pairs.len();
    let base = Network::new(s).unwrap();
    let (mut reference, mut cached) = (base.clone(), base);
    // Reference: no cache, pairs from the extended images in every pass.
    let mut tr = LayerTrainer::new(&reference, 0, rot, TrainingPath::Fast).unwrap();
    loop {
        loop {
            tr.feed(&mut reference, &imgs, n).unwrap();
            tr.feed_pairs(&mut reference, &ext, m, &ref_pairs).unwrap();
            if tr.end_pass(&mut reference).unwrap() {
                break;
            }
        }
        if reference.is_trained() {
            break;
        }
        tr = tr.next_layer(&reference).unwrap();
    }
    // fit: streamed passes roll image b of each pair, cached passes read
    // the cached fields at shifted offsets.
    let mut opts = options(rot, TrainingPath::Fast, true, 1.0);
    opts.pairs =
        Some(SpatialPairs { pairs: pairs.clone(), shifts: Some(shifts.clone()), layers: vec![0, 1, 2], chunk: 5 });
    let mut cached_passes = 0;
    let mut count = |p: &Progress| {
        cached_passes += usize::from(p.cached && p.event == ProgressEvent::Start);
        Ok(())
    };
    fit(&mut cached, &mut InMemory::new(&imgs, n, 7).unwrap(), &opts, &mut count).unwrap();
    assert!(cached_passes >= 3);
    for (i, ((pa, _), (pb, _))) in projections(&reference).iter().zip(&projections(&cached)).enumerate() {
        assert!(max_rel(pa, pb) < 1e-9, "stage {i}: {}", max_rel(pa, pb));
    }
    let mut tr = LayerTrainer::new(&cached, 0, rot, TrainingPath::Fast).unwrap();
    let e = tr.feed_pairs_cached_shifted(&mut cached, &pairs[..1], Some(&[4])).unwrap_err().to_string();
    assert!(e.contains("multiple of the step"), "{e}");
}

/// u8 images train to the same weights as the same values in f64, and
/// transform to the same features.
#[test]
fn u8_pixels_equal_f64() {
    let (w, n) = (24, 20);
    let imgs = images(n, 6, w, 3, 5);
    let bytes: Vec<u8> = imgs.iter().map(|v| ((v + 2.5) * 50.0).clamp(0.0, 255.0) as u8).collect();
    let as_f64: Vec<f64> = bytes.iter().map(|&v| v as f64).collect();
    let rot = Rotation { step: 2, period: w };
    let base = Network::new(spec(24, 3, 2, true)).unwrap();
    let (mut a, mut b) = (base.clone(), base);
    let opts = options(rot, TrainingPath::Fast, true, 1.0);
    fit(&mut a, &mut InMemory::new(&bytes, n, 6).unwrap(), &opts, &mut |_| Ok(())).unwrap();
    fit(&mut b, &mut InMemory::new(&as_f64, n, 6).unwrap(), &opts, &mut |_| Ok(())).unwrap();
    assert_eq!(projections(&a), projections(&b));
    assert_eq!(a.transform(&bytes, n).unwrap(), b.transform(&as_f64, n).unwrap());
    let (ra, rb) =
        (transform_rotations(&a, rot, &bytes, n).unwrap(), transform_rotations(&b, rot, &as_f64, n).unwrap());
    assert_eq!(ra, rb);
}

/// fit reports every pass (start, batches, finish), decides the cache per
/// layer by its byte limit, and ends at the first error of the progress
/// callback or of the image source.
#[test]
fn fit_progress_cache_plan_and_errors() {
    let (w, n) = (24, 20);
    let imgs = images(n, 6, w, 1, 9);
    let rot = Rotation { step: 3, period: w };
    let base = Network::new(three_layer_spec()).unwrap();
    let mut events = Vec::new();
    let mut net = base.clone();
    let mut opts = FitOptions::new(rot);
    // Layer 2's input fields (layer 1: 2 x 24 offsets x 4 outputs x 8 bytes
    // x 20 images) exceed the limit; layer 3's do not.
    opts.cache = CachePolicy::Auto(15_000.0);
    let report = fit(&mut net, &mut InMemory::new(&imgs, n, 8).unwrap(), &opts, &mut |p: &Progress| {
        events.push(*p);
        Ok(())
    })
    .unwrap();
    assert!(net.is_trained());
    assert_eq!(report.n_images, n);
    let plan: Vec<(usize, bool)> = report.cache_plan.iter().map(|d| (d.layer, d.kept)).collect();
    assert_eq!(plan, vec![(1, false), (2, true)], "{:?}", report.cache_plan);
    assert_eq!(report.cache_plan[0].bytes, 2 * 24 * 4 * 8 * n);
    let starts: Vec<(usize, usize, bool)> =
        events.iter().filter(|p| p.event == ProgressEvent::Start).map(|p| (p.layer, p.pass, p.cached)).collect();
    assert_eq!(starts, vec![(0, 0, false), (0, 1, false), (1, 0, false), (1, 1, false), (2, 0, false), (2, 1, true)]);
    let first_pass: Vec<usize> = events.iter().take_while(|p| p.pass == 0 && p.layer == 0).map(|p| p.done).collect();
    assert_eq!(first_pass, vec![0, 8, 16, 20, 20]);
    assert!(events.iter().all(|p| p.total == Some(n) && p.n_layers == 3 && p.n_passes == 2));
    // The same weights as a run that caches nothing.
    let mut plain = base.clone();
    fit_with(&mut plain, &imgs, n, &options(rot, TrainingPath::Fast, false, 1.0)).unwrap();
    for (x, y) in projections(&net).iter().zip(&projections(&plain)) {
        assert!(max_rel(&x.0, &y.0) < 1e-9);
    }
    // A failing progress callback ends training with its error.
    let mut net = base.clone();
    let e = fit(&mut net, &mut InMemory::new(&imgs, n, 8).unwrap(), &opts, &mut |p: &Progress| {
        if p.layer == 1 {
            Err(SfaError::Interrupted("stop".into()))
        } else {
            Ok(())
        }
    })
    .unwrap_err();
    assert_eq!(e, SfaError::Interrupted("stop".into()));
    assert_eq!(net.n_trained(), 1);
    // So does a failing source; a trained network is refused.
    struct Failing;
    impl sfa_core::BatchSource for Failing {
        fn for_each_batch(&mut self, _: &mut (dyn FnMut(sfa_core::Batch<'_>) -> Result<()> + Send)) -> Result<()> {
            Err(SfaError::Interrupted("no images".into()))
        }
    }
    let mut net = base.clone();
    assert!(matches!(fit(&mut net, &mut Failing, &opts, &mut |_| Ok(())), Err(SfaError::Interrupted(_))));
    let mut done = plain.clone();
    assert!(fit_with(&mut done, &imgs, n, &opts).unwrap_err().to_string().contains("already trained"));
}

/// Loop-closure feedback: the fast path (cached and streamed) equals the
/// naive per-view path, with weights, and closures change the result.
#[test]
fn loop_closures_fast_equals_naive() {
    use sfa_core::LoopClosures;
    use std::sync::Arc;
    let (w, n, c) = (24, 30, 3);
    let imgs = images(n, 6, w, c, 11);
    let size = 6 * w * c;
    // partners: image p rolled right by s columns (np.roll convention)
    let closures = [(2usize, 20usize, 5usize, 1.0), (4, 25, 0, 0.6), (9, 17, 13, 0.3)];
    let mut partners = Vec::new();
    for &(p, _, s, _) in &closures {
        let img = &imgs[p * size..(p + 1) * size];
        for y in 0..6 {
            for x in 0..w {
                let col = (x + w - s) % w;
                partners.extend_from_slice(&img[(y * w + col) * c..(y * w + col + 1) * c]);
            }
        }
    }
    let lc =
        LoopClosures::new(closures.iter().map(|x| x.1).collect(), closures.iter().map(|x| x.3).collect(), partners)
            .unwrap();
    for (v, stride, step) in [(24, 2, 3), (16, 3, 5), (24, 4, 4)] {
        let rot = Rotation { step, period: w };
        let base = Network::new(spec(v, c, stride, true)).unwrap();
        let run = |path, cache, lc: Option<Arc<LoopClosures>>| {
            let mut net = base.clone();
            let mut opts = options(rot, path, cache, 1.0);
            opts.loop_closures = lc;
            fit_with(&mut net, &imgs, n, &opts).unwrap();
            net
        };
        let lc = Some(Arc::new(lc.clone()));
        let naive = run(TrainingPath::Naive, false, lc.clone());
        let plain = run(TrainingPath::Fast, true, None);
        for cache in [true, false] {
            let fast = run(TrainingPath::Fast, cache, lc.clone());
            for l in 0..2 {
                let (a, b) = (naive.nodes(l)[0].state(true), fast.nodes(l)[0].state(true));
                for (sa, sb) in a.stages.iter().zip(&b.stages) {
                    let (pa, pb) = (sa.solution.as_ref().unwrap(), sb.solution.as_ref().unwrap());
                    let e = max_rel(&pa.delta, &pb.delta);
                    assert!(
                        e < 1e-9,
                        "v={v} stride={stride} step={step} cache={cache} layer {l}: delta differs by {e}"
                    );
                }
            }
        }
        let (a, b) = (naive.nodes(1)[0].state(false), plain.nodes(1)[0].state(false));
        let (da, db) = (&a.stages[1].solution.as_ref().unwrap().delta, &b.stages[1].solution.as_ref().unwrap().delta);
        assert!(max_rel(da, db) > 1e-4, "closures must change the result");
    }
    // a closure naming an image beyond the run is an error, not a panic
    let bad = LoopClosures::new(vec![n + 3], vec![1.0], vec![0.0; size]).unwrap();
    let mut net = Network::new(spec(24, c, 2, true)).unwrap();
    let mut opts = options(Rotation { step: 3, period: w }, TrainingPath::Fast, true, 1.0);
    opts.loop_closures = Some(Arc::new(bad));
    let err = fit_with(&mut net, &imgs, n, &opts).unwrap_err();
    assert!(matches!(err, SfaError::InvalidArgument(_)), "{err:?}");
}
