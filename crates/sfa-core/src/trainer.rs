//! Training one layer of a network under simulated rotation, pass by pass
//! ([`LayerTrainer`]); [`crate::training::fit`] drives it through every
//! layer.

use crate::closures::LoopClosures;
use crate::error::{Result, SfaError};
use crate::fields::{
    check_pairs, cum_strides, fast_graph, interleaved_graph, layer_field, naive_graph, offset_set, Field, ImageGraph,
};
use crate::network::{check_images, Network};
use crate::pixel::Pixel;
use crate::rotation::{Rotation, TrainingPath};
use crate::stats::{Accumulator, GraphPart};
use crate::view::View;
use rayon::prelude::*;
use std::sync::Arc;

mod partitioned;

/// Images whose graphs are built (in parallel) and accumulated at once.
const FEED_CHUNK: usize = 16;

/// One image's rows and graph, ready for accumulation (see
/// [`LayerTrainer::prepare_shared`]).
struct SharedGraph {
    rows: Vec<f64>,
    start: usize,
    n: usize,
    width: usize,
    from_stage: usize,
    weights: Vec<f64>,
    edges: Vec<[usize; 2]>,
    edge_weights: Vec<f64>,
}

/// Trains one layer of a network, pass by pass, on images streamed in
/// chunks. Usage: for each pass (`n_passes()`), feed every image in order
/// ([`feed`](Self::feed)), then [`end_pass`](Self::end_pass).
pub struct LayerTrainer {
    layer: usize,
    rot: Rotation,
    path: TrainingPath,
    pass: usize,
    /// Last-view patches of the previous image (per series), for the pairs
    /// between consecutive images.
    tail: Option<Vec<f64>>,
    images_seen: usize,
    /// Fields of layer `layer - 1` per image, in feeding order (fast path):
    /// filled in the first pass, reused in the next, and advanced by one
    /// layer for the next trainer.
    cache: Option<Vec<Field>>,
    building: Vec<Field>,
    caching: bool,
    /// Reference point of the first layer's lag-product statistics in this
    /// pass (set from the pass's first image).
    reference: Option<Vec<f64>>,
    /// Whether the first layer may use lag products (`periodic.rs`).
    lag_products: bool,
    /// Images whose statistics came from lag products.
    lag_images: usize,
    /// Weight of the derivative pairs between consecutive images (last
    /// view of one image -> first view of the next), relative to the
    /// pairs between consecutive views within an image (weight 1).
    transition_weight: f64,
    /// Loop closures: images whose simulated rotation is interleaved with
    /// an aligned partner's ([`set_loop_closures`](Self::set_loop_closures)).
    closures: Option<Arc<LoopClosures>>,
    /// Fields of the partners, aligned with `cache` (None for images
    /// without a closure).
    partner_cache: Option<Vec<Option<Field>>>,
    partner_building: Vec<Option<Field>>,
    /// Whether the sequence between images is formed from `tail` for every
    /// image of this pass (set by [`prime`](Self::prime) and
    /// [`break_sequence`](Self::break_sequence); without weight sharing and
    /// with transition weight 1 the nodes otherwise continue their own
    /// sequences).
    by_tail: bool,
    /// Spatial pairs added in the pass in progress.
    pairs_fed: usize,
}

impl LayerTrainer {
    /// Starts training `layer` (all layers below must be trained).
    pub fn new(net: &Network, layer: usize, rot: Rotation, path: TrainingPath) -> Result<Self> {
        rot.check(net)?;
        if layer >= net.n_layers() {
            return Err(SfaError::InvalidArgument(format!("layer {} does not exist", layer + 1)));
        }
        if net.n_trained() < layer {
            return Err(SfaError::NotFitted(format!(
                "layer {} cannot train before layers 1..{} are trained",
                layer + 1,
                layer
            )));
        }
        crate::memory::check(
            || {
                let g = &net.geometry()[layer];
                let nodes = if net.spec().weight_sharing { 1 } else { g.n_positions() };
                format!("training layer {} ({nodes} node(s) of {} inputs)", layer + 1, g.in_dim)
            },
            net.spec().training_bytes(net.geometry(), layer),
        )?;
        let path = if net.spec().weight_sharing { path } else { TrainingPath::Naive };
        Ok(LayerTrainer {
            layer,
            rot,
            path,
            pass: 0,
            tail: None,
            images_seen: 0,
            cache: None,
            building: Vec::new(),
            caching: false,
            reference: None,
            lag_products: true,
            lag_images: 0,
            transition_weight: 1.0,
            closures: None,
            partner_cache: None,
            partner_building: Vec::new(),
            by_tail: false,
            pairs_fed: 0,
        })
    }

    /// Keeps the lower layers' periodic fields of every image in memory
    /// (f32 for mixed-precision networks) so that later passes and layers
    /// do not recompute them. Fast path only; the images must then be fed
    /// in the same order in every pass.
    pub fn set_caching(&mut self, on: bool) {
        self.caching = on && self.path == TrainingPath::Fast;
    }

    /// Lets the first layer form its linear statistics from lag products
    /// (`periodic.rs`; on by default, used where it pays). Off: one
    /// outer product per patch. Results agree up to rounding.
    pub fn set_lag_products(&mut self, on: bool) {
        self.lag_products = on;
    }

    /// Sets the weight of the derivative pairs between consecutive images
    /// (one pair per RF series: the last view of image `i` and the first
    /// view of image `i + 1`), relative to the pairs between consecutive
    /// views within an image, which keep weight 1. Default 1 (the thesis:
    /// one sequence of all views). Larger values make the slowness
    /// objective weigh the change from one training position to the next
    /// more against the change under rotation. Must be finite and `>= 0`.
    /// Inherited by [`next_layer`](Self::next_layer).
    pub fn set_transition_weight(&mut self, w: f64) -> Result<()> {
        if !(w.is_finite() && w >= 0.0) {
            return Err(SfaError::InvalidArgument(format!("transition_weight must be a finite number >= 0, got {w}")));
        }
        self.transition_weight = w;
        Ok(())
    }

    /// Sets the loop closures of the training run (thesis 6.2.1): every
    /// image with a closure is trained on its simulated rotation
    /// interleaved with its aligned partner's, mixed with the plain
    /// rotation by the closure's weight (see [`LoopClosures`]). Image
    /// indices count the images in the order they are fed. The partners'
    /// fields join the cache. Inherited by [`next_layer`](Self::next_layer);
    /// set before the first image of a pass, and before the first pass
    /// when the fields are cached (the cache keeps the partners' fields).
    pub fn set_loop_closures(&mut self, net: &Network, closures: Option<Arc<LoopClosures>>) -> Result<()> {
        if let Some(c) = &closures {
            let (h, _, ch) = net.input_shape();
            let size = h * self.rot.period * ch;
            if !c.is_empty() && c.image_size() != size {
                return Err(SfaError::ShapeMismatch {
                    what: "values per loop-closure partner image",
                    expected: size,
                    got: c.image_size(),
                });
            }
        }
        if self.images_seen > 0 || self.cache.is_some() || !self.building.is_empty() {
            return Err(SfaError::InvalidArgument(
                "set loop closures before the first image of a pass (before the first pass with the field cache)"
                    .into(),
            ));
        }
        self.closures = closures.filter(|c| !c.is_empty());
        Ok(())
    }

    /// The weight of the pairs between consecutive images (default 1).
    pub fn transition_weight(&self) -> f64 {
        self.transition_weight
    }

    /// Images whose statistics this trainer formed from lag products.
    pub fn lag_product_images(&self) -> usize {
        self.lag_images
    }

    /// True when the next pass reads the cache instead of images
    /// ([`feed_cached`](Self::feed_cached)).
    pub fn has_cache(&self) -> bool {
        self.cache.is_some()
    }

    /// Number of images in the cache.
    pub fn cached_images(&self) -> usize {
        self.cache.as_ref().map_or(0, |c| c.len())
    }

    /// Bytes held by the cache.
    pub fn cache_bytes(&self) -> usize {
        let partners = self.partner_cache.iter().flatten().chain(&self.partner_building).flatten();
        self.cache.iter().flatten().chain(&self.building).chain(partners).map(Field::bytes).sum()
    }

    /// After the last pass: the trainer of the next layer, inheriting the
    /// cache advanced by one layer (computed from the cached fields, in
    /// parallel, without the images).
    pub fn next_layer(self, net: &Network) -> Result<LayerTrainer> {
        if net.n_trained() <= self.layer {
            return Err(SfaError::NotFitted(format!("layer {} is not trained yet", self.layer + 1)));
        }
        let mut next = LayerTrainer::new(net, self.layer + 1, self.rot, self.path)?;
        next.caching = self.caching;
        next.transition_weight = self.transition_weight;
        next.closures = self.closures.clone();
        let mixed = net.spec().mixed_precision;
        if let (true, Some(cache)) = (self.caching, self.cache) {
            let (layer, rot) = (self.layer, self.rot);
            let advanced: Vec<Result<Field>> = cache
                .into_par_iter()
                .map(|f| Ok(layer_field(net, &rot, layer, &[], Some(&f))?.compact(mixed)))
                .collect();
            next.cache = Some(advanced.into_iter().collect::<Result<Vec<_>>>()?);
            if let Some(partners) = self.partner_cache {
                let advanced: Vec<Result<Option<Field>>> = partners
                    .into_par_iter()
                    .map(|f| match f {
                        Some(f) => Ok(Some(layer_field(net, &rot, layer, &[], Some(&f))?.compact(mixed))),
                        None => Ok(None),
                    })
                    .collect();
                next.partner_cache = Some(advanced.into_iter().collect::<Result<Vec<_>>>()?);
            }
        }
        Ok(next)
    }

    /// Feeds the next pass from the cache (every cached image, in order).
    pub fn feed_cached(&mut self, net: &mut Network) -> Result<()> {
        let cache =
            self.cache.take().ok_or_else(|| SfaError::InvalidArgument("this trainer has no cached fields".into()))?;
        let partners = self.partner_cache.take();
        let closures = self.closures.clone();
        let (layer, rot) = (self.layer, self.rot);
        let chunk = FEED_CHUNK;
        let mut result = Ok(());
        for (c, part) in cache.chunks(chunk).enumerate() {
            let graphs: Vec<Result<ImageGraph>> = {
                let net_ref: &Network = net;
                let (partners, closures) = (partners.as_ref(), closures.as_deref());
                part.par_iter()
                    .enumerate()
                    .map(|(b, f)| {
                        let i = c * chunk + b;
                        let plain = fast_graph(net_ref, &rot, &[], layer, Some(f), None)?.0;
                        match closures.and_then(|cl| cl.partner(i)) {
                            None => Ok(plain),
                            Some((_, w)) => {
                                let fa = partners.and_then(|p| p.get(i)).and_then(Option::as_ref).ok_or_else(|| {
                                    SfaError::InvalidArgument(format!("the partner of image {i} is not in the cache"))
                                })?;
                                let ga = fast_graph(net_ref, &rot, &[], layer, Some(fa), None)?.0;
                                interleaved_graph(plain, ga, w)
                            }
                        }
                    })
                    .collect()
            };
            let n = graphs.len();
            if let Err(e) = graphs.into_iter().collect::<Result<Vec<_>>>().and_then(|b| self.feed_shared(net, b)) {
                result = Err(e);
                break;
            }
            self.images_seen += n;
        }
        self.cache = Some(cache);
        self.partner_cache = partners;
        result
    }

    /// Passes over the data this layer needs (2: reduction, then expansion).
    pub fn n_passes(&self, net: &Network) -> usize {
        net.nodes(self.layer)[0].n_stages()
    }

    /// The path in use (naive without weight sharing).
    pub fn path(&self) -> TrainingPath {
        self.path
    }

    /// Feeds `n` images (`n x height x period x channels`, row-major), in
    /// sequence order.
    pub fn feed<P: Pixel>(&mut self, net: &mut Network, images: &[P], n: usize) -> Result<()> {
        let (h, _, c) = net.input_shape();
        let size = h * self.rot.period * c;
        check_images(images, n, size, self.images_seen)?;
        if self.cache.is_some() {
            return Err(SfaError::InvalidArgument(
                "this pass reads the cached fields: call feed_cached instead of feed".into(),
            ));
        }
        let (layer, rot, path) = (self.layer, self.rot, self.path);
        if self.reference.is_none() && n > 0 && self.uses_reference(net) {
            // Per-channel means of the first image: the lag products'
            // reference point for the whole pass.
            self.reference = Some(channel_means(&images[..size], c));
        }
        // Images are turned into graphs and accumulated a chunk at a time,
        // which bounds the memory of the graphs in flight.
        for chunk in images[..n * size].chunks(FEED_CHUNK * size) {
            let base = self.images_seen;
            type Fed = (ImageGraph, Option<Field>, Option<Field>);
            let graphs: Vec<Result<Fed>> = {
                let net_ref: &Network = net;
                let reference = self.reference.as_deref();
                let closures = self.closures.as_deref();
                chunk
                    .par_chunks(size)
                    .enumerate()
                    .map(|(b, img)| -> Result<Fed> {
                        match (path, closures.and_then(|c| c.partner(base + b))) {
                            (TrainingPath::Fast, None) => {
                                let (g, f) = fast_graph(net_ref, &rot, &P::image_f64(img), layer, None, reference)?;
                                Ok((g, f, None))
                            }
                            (TrainingPath::Naive, None) => Ok((naive_graph(net_ref, &rot, img, layer)?, None, None)),
                            (TrainingPath::Fast, Some((a, w))) => {
                                // every view as a row (no lag products), for both images
                                let (gc, fc) = fast_graph(net_ref, &rot, &P::image_f64(img), layer, None, None)?;
                                let (ga, fa) = fast_graph(net_ref, &rot, a, layer, None, None)?;
                                Ok((interleaved_graph(gc, ga, w)?, fc, fa))
                            }
                            (TrainingPath::Naive, Some((a, w))) => {
                                let (gc, ga) =
                                    (naive_graph(net_ref, &rot, img, layer)?, naive_graph(net_ref, &rot, a, layer)?);
                                Ok((interleaved_graph(gc, ga, w)?, None, None))
                            }
                        }
                    })
                    .collect()
            };
            let d = net.geometry()[layer].in_dim;
            let mixed = net.spec().mixed_precision;
            let shared = net.spec().weight_sharing;
            let mut batch = Vec::with_capacity(if shared { graphs.len() } else { 0 });
            for gr in graphs {
                let (gr, field, partner) = gr?;
                if self.caching {
                    if let Some(f) = field {
                        self.building.push(f.compact(mixed));
                        if self.closures.is_some() {
                            self.partner_building.push(partner.map(|f| f.compact(mixed)));
                        }
                    }
                }
                if shared {
                    batch.push(gr);
                } else {
                    self.feed_individual(net, gr, d)?;
                    self.images_seen += 1;
                }
            }
            if shared {
                let n = batch.len();
                self.feed_shared(net, batch)?;
                self.images_seen += n;
            }
        }
        Ok(())
    }

    /// Feeds consecutive images' graphs (weight sharing): each image's
    /// rows get the previous image's last views as leading pair ends, then
    /// all images are accumulated at once ([`SfaNode::partial_fit_graphs`]).
    fn feed_shared(&mut self, net: &mut Network, graphs: Vec<ImageGraph>) -> Result<()> {
        let mut lattice = Vec::new();
        let prepared: Vec<SharedGraph> =
            graphs.into_iter().map(|gr| self.prepare_shared(gr, &mut lattice)).collect::<Result<_>>()?;
        if !lattice.is_empty() {
            let reference = self.reference.as_deref().expect("lag products have a reference");
            let geom = &net.geometry()[self.layer];
            let m = crate::periodic::lattice_moments(geom, &lattice, reference, net.spec().mixed_precision)?;
            net.nodes_mut(self.layer)[0].merge_statistics(&m)?;
            self.lag_images += lattice.len();
        }
        let node = &mut net.nodes_mut(self.layer)[0];
        let mut i = 0;
        while i < prepared.len() {
            let from = prepared[i].from_stage;
            let j = i + prepared[i..].iter().take_while(|p| p.from_stage == from).count();
            let parts = prepared[i..j]
                .iter()
                .map(|p| {
                    Ok(GraphPart {
                        x: View::from_slice(&p.rows[p.start * p.width..], p.n, p.width)?,
                        weights: Some(&p.weights),
                        edges: &p.edges,
                        edge_weights: Some(&p.edge_weights),
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            node.partial_fit_graphs(from, &parts)?;
            i = j;
        }
        Ok(())
    }

    /// One image's graph with the previous image's last views in its
    /// reserved leading rows (weight-0 samples that end one pair each);
    /// keeps this image's last views as the next tail and moves its
    /// lag-product statistics to `lattice`.
    fn prepare_shared(
        &mut self,
        gr: ImageGraph,
        lattice: &mut Vec<crate::periodic::LatticeImage>,
    ) -> Result<SharedGraph> {
        let ns = gr.first.len();
        let d = gr.width;
        let mut rows = gr.rows;
        let (start, n, weights, edges, ew) = match self.tail.take() {
            None => (gr.lead, gr.n, gr.weights, gr.edges, gr.edge_weights),
            Some(tail) => {
                debug_assert_eq!(gr.lead, ns);
                rows[..ns * d].copy_from_slice(&tail);
                let mut w = vec![0.0; ns];
                w.extend_from_slice(&gr.weights);
                let tw = self.transition_weight;
                let (mut e, mut ew): (Vec<[usize; 2]>, Vec<f64>) = if gr.alt_first.is_empty() {
                    ((0..ns).map(|i| [i, ns + gr.first[i]]).collect(), vec![tw; ns])
                } else {
                    // a loop closure's series starts at its partner's first view and at its own
                    let (wa, wc) = (gr.alt_weight, 1.0 - gr.alt_weight);
                    (0..ns)
                        .flat_map(|i| [([i, ns + gr.first[i]], tw * wc), ([i, ns + gr.alt_first[i]], tw * wa)])
                        .filter(|&(_, w)| w > 0.0)
                        .unzip()
                };
                e.extend(gr.edges.iter().map(|[a, b]| [a + ns, b + ns]));
                ew.extend_from_slice(&gr.edge_weights);
                (0, ns + gr.n, w, e, ew)
            }
        };
        let own = gr.lead * d;
        let mut tail = vec![0.0; ns * d];
        for (i, &r) in gr.last.iter().enumerate() {
            let src = own + r * d;
            tail[i * d..(i + 1) * d].copy_from_slice(&rows[src..src + d]);
        }
        if let Some(m) = gr.moments {
            lattice.push(m);
        }
        self.tail = Some(tail);
        Ok(SharedGraph { rows, start, n, width: d, from_stage: gr.from_stage, weights, edges, edge_weights: ew })
    }

    fn feed_individual(&mut self, net: &mut Network, gr: ImageGraph, d: usize) -> Result<()> {
        // Naive graph: rows are (view, position), row u belongs to position
        // u % np; each position's rows form one series continuing across
        // images.
        let np = gr.first.len();
        let kv = gr.n / np;
        let first_image = self.images_seen == 0;
        let tw = self.transition_weight;
        let nodes = net.nodes_mut(self.layer);
        // (with loop closures, or a sequence primed or broken, every image
        // takes the graph path, which keeps the tail)
        if tw == 1.0 && self.closures.is_none() && !self.by_tail {
            return nodes.par_iter_mut().enumerate().try_for_each(|(p, node)| {
                let mut x = vec![0.0; kv * d];
                for k in 0..kv {
                    let src = (gr.lead + k * np + p) * d;
                    x[k * d..(k + 1) * d].copy_from_slice(&gr.rows[src..src + d]);
                }
                node.partial_fit(View::from_slice(&x, kv, d)?, first_image)
            });
        }
        // Weighted transition or a loop closure: each node's series as a
        // graph, with the previous image's last view as a weight-0 leading
        // row.
        let tail = self.tail.take();
        let lead = usize::from(tail.is_some());
        let mut by_node: Vec<(Vec<[usize; 2]>, Vec<f64>)> = vec![(Vec::new(), Vec::new()); np];
        for (&[a, b], &w) in gr.edges.iter().zip(&gr.edge_weights) {
            debug_assert_eq!(a % np, b % np);
            let (e, ew) = &mut by_node[a % np];
            e.push([lead + a / np, lead + b / np]);
            ew.push(w);
        }
        let r = nodes.par_iter_mut().zip(by_node).enumerate().try_for_each(|(p, (node, (mut edges, mut ew)))| {
            let mut x = vec![0.0; (lead + kv) * d];
            if let Some(t) = &tail {
                x[..d].copy_from_slice(&t[p * d..(p + 1) * d]);
            }
            for k in 0..kv {
                let src = (gr.lead + k * np + p) * d;
                x[(lead + k) * d..(lead + k + 1) * d].copy_from_slice(&gr.rows[src..src + d]);
            }
            let mut w = vec![0.0; lead];
            w.extend((0..kv).map(|k| gr.weights[k * np + p]));
            if lead == 1 {
                let wc = if gr.alt_first.is_empty() { 1.0 } else { 1.0 - gr.alt_weight };
                if tw * wc > 0.0 {
                    edges.push([0, 1 + gr.first[p] / np]);
                    ew.push(tw * wc);
                }
                if !gr.alt_first.is_empty() && tw * gr.alt_weight > 0.0 {
                    edges.push([0, 1 + gr.alt_first[p] / np]);
                    ew.push(tw * gr.alt_weight);
                }
            }
            node.partial_fit_graph(View::from_slice(&x, lead + kv, d)?, Some(&w), &edges, Some(&ew))
        });
        let mut next = vec![0.0; np * d];
        for p in 0..np {
            let src = (gr.lead + gr.last[p]) * d;
            next[p * d..(p + 1) * d].copy_from_slice(&gr.rows[src..src + d]);
        }
        self.tail = Some(next);
        r
    }

    /// Adds *spatial pairs* of training images to this pass (graph-based
    /// SFA, Escalante & Wiskott 2013): every `(a, b, w)` in `pairs` makes,
    /// at **every** simulated rotation `k` and RF position, a derivative
    /// pair between the RF input of view `k` of image `a` and that of view
    /// `k` of image `b`, with weight `w` (images index `images`, `n x
    /// height x period x channels`). With weight sharing (fast path) this is
    /// one pair per distinct periodic offset, weighted `w` x the offset's
    /// multiplicity; the naive path forms every view. No samples are added
    /// and the sequence (the pairs between consecutive images fed with
    /// [`feed`](Self::feed)) is untouched; call in any pass, before
    /// [`end_pass`](Self::end_pass), in every pass of every layer to get the
    /// same graph throughout.
    pub fn feed_pairs<P: Pixel>(
        &mut self,
        net: &mut Network,
        images: &[P],
        n: usize,
        pairs: &[(usize, usize, f64)],
    ) -> Result<()> {
        self.feed_pairs_shifted(net, images, n, pairs, None)
    }

    /// [`feed_pairs`](Self::feed_pairs) where image `b` of pair `e` is seen
    /// rolled left by `shifts[e]` columns (any shift; the rolled image's
    /// graph is formed from a rolled copy, one per pair with a shift that is
    /// not a multiple of the period).
    pub fn feed_pairs_shifted<P: Pixel>(
        &mut self,
        net: &mut Network,
        images: &[P],
        n: usize,
        pairs: &[(usize, usize, f64)],
        shifts: Option<&[usize]>,
    ) -> Result<()> {
        let (h, _, c) = net.input_shape();
        let w = self.rot.period;
        let size = h * w * c;
        check_images(images, n, size, 0)?;
        check_pairs(pairs, n)?;
        if let Some(sh) = shifts {
            if sh.len() != pairs.len() {
                return Err(SfaError::ShapeMismatch {
                    what: "number of pair shifts",
                    expected: pairs.len(),
                    got: sh.len(),
                });
            }
        }
        // Image b of every shifted pair, rolled, after the given images.
        let mut local = pairs.to_vec();
        let mut rolled: Vec<P> = Vec::new();
        for (e, p) in local.iter_mut().enumerate() {
            let s = shifts.map_or(0, |sh| sh[e] % w);
            if s == 0 {
                continue;
            }
            let img = &images[p.1 * size..(p.1 + 1) * size];
            for r in 0..h {
                for col in 0..w {
                    let src = (r * w + (col + s) % w) * c;
                    rolled.extend_from_slice(&img[src..src + c]);
                }
            }
            p.1 = n + rolled.len() / size - 1;
        }
        let (layer, rot, path) = (self.layer, self.rot, self.path);
        let graphs: Vec<ImageGraph> = {
            let net_ref: &Network = net;
            let r: Vec<Result<ImageGraph>> = images
                .par_chunks(size)
                .chain(rolled.par_chunks(size))
                .map(|img| match path {
                    TrainingPath::Fast => {
                        fast_graph(net_ref, &rot, &P::image_f64(img), layer, None, None).map(|(g, _)| g)
                    }
                    TrainingPath::Naive => naive_graph(net_ref, &rot, img, layer),
                })
                .collect();
            r.into_iter().collect::<Result<_>>()?
        };
        self.add_pair_graphs(net, &graphs, &local, None)
    }

    /// [`feed_pairs`](Self::feed_pairs) for a pass that reads the cached
    /// fields: `a`, `b` index the cached images (the order they were fed).
    pub fn feed_pairs_cached(&mut self, net: &mut Network, pairs: &[(usize, usize, f64)]) -> Result<()> {
        self.feed_pairs_cached_shifted(net, pairs, None)
    }

    /// [`feed_pairs_cached`](Self::feed_pairs_cached) where image `b` of
    /// pair `e` is seen rolled left by `shifts[e]` columns (the pair then
    /// compares two different orientations), read from the cached field at
    /// the shifted offsets: exact, and equal to feeding the rolled images,
    /// when the step divides the period and every shift is a multiple of
    /// the step.
    pub fn feed_pairs_cached_shifted(
        &mut self,
        net: &mut Network,
        pairs: &[(usize, usize, f64)],
        shifts: Option<&[usize]>,
    ) -> Result<()> {
        if let Some(sh) = shifts {
            if sh.len() != pairs.len() {
                return Err(SfaError::ShapeMismatch {
                    what: "number of pair shifts",
                    expected: pairs.len(),
                    got: sh.len(),
                });
            }
            let (step, w) = (self.rot.step, self.rot.period);
            if let Some(e) = sh.iter().position(|&x| x % w != 0 && (w % step != 0 || x % step != 0)) {
                return Err(SfaError::InvalidArgument(format!(
                    "pair {e}: shift {} is not a multiple of the step {step} (or the step does not divide the \
                     period {w}); roll the image instead",
                    sh[e]
                )));
            }
        }
        let cache =
            self.cache.take().ok_or_else(|| SfaError::InvalidArgument("this trainer has no cached fields".into()))?;
        let result = (|| {
            check_pairs(pairs, cache.len())?;
            let (layer, rot) = (self.layer, self.rot);
            // Graphs of the images the pairs touch, in chunks of distinct images.
            let chunk = 64;
            let mut at = 0;
            while at < pairs.len() {
                // Pairs whose images fit in one chunk of distinct images.
                let mut ids: Vec<usize> = Vec::new();
                let mut end = at;
                while end < pairs.len() {
                    let (a, b, _) = pairs[end];
                    let extra = usize::from(!ids.contains(&a)) + usize::from(!ids.contains(&b) && a != b);
                    if ids.len() + extra > chunk && end > at {
                        break;
                    }
                    for i in [a, b] {
                        if !ids.contains(&i) {
                            ids.push(i);
                        }
                    }
                    end += 1;
                }
                let graphs: Vec<ImageGraph> = {
                    let net_ref: &Network = net;
                    let r: Vec<Result<ImageGraph>> = ids
                        .par_iter()
                        .map(|&i| fast_graph(net_ref, &rot, &[], layer, Some(&cache[i]), None).map(|(g, _)| g))
                        .collect();
                    r.into_iter().collect::<Result<_>>()?
                };
                let local: Vec<(usize, usize, f64)> = pairs[at..end]
                    .iter()
                    .map(|&(a, b, w)| {
                        let pos = |x: usize| ids.iter().position(|&y| y == x).expect("id");
                        (pos(a), pos(b), w)
                    })
                    .collect();
                self.add_pair_graphs(net, &graphs, &local, shifts.map(|sh| &sh[at..end]))?;
                at = end;
            }
            Ok(())
        })();
        self.cache = Some(cache);
        result
    }

    /// Adds the pairs between the rows of `graphs[a]` and `graphs[b]`.
    fn add_pair_graphs(
        &mut self,
        net: &mut Network,
        graphs: &[ImageGraph],
        pairs: &[(usize, usize, f64)],
        shifts: Option<&[usize]>,
    ) -> Result<()> {
        let shared = net.spec().weight_sharing;
        // Fast-path row layout (for shifted pairs): row r * no + oi is
        // offset offs[oi] of RF row r.
        let (offs, idx) = {
            let g = &net.geometry()[self.layer];
            offset_set(&self.rot, cum_strides(net.geometry())[self.layer], g.n_w)
        };
        for (e, &(a, b, w)) in pairs.iter().enumerate() {
            let shift = shifts.map_or(0, |sh| sh[e] % self.rot.period);
            if w == 0.0 || (a == b && shift == 0) {
                continue; // (an image and its rolled self do make a pair)
            }
            self.pairs_fed += 1;
            let (ga, gb) = (&graphs[a], &graphs[b]);
            let d = ga.width;
            let n = ga.n;
            debug_assert_eq!((gb.n, gb.width, gb.from_stage), (n, d, ga.from_stage));
            if shared {
                let mut rows = Vec::with_capacity(2 * n * d);
                rows.extend_from_slice(&ga.rows[ga.lead * d..]);
                rows.extend_from_slice(&gb.rows[gb.lead * d..]);
                let zeros = vec![0.0; 2 * n];
                let edges: Vec<[usize; 2]> = if shift == 0 {
                    (0..n).map(|k| [k, n + k]).collect()
                } else {
                    let no = offs.len();
                    (0..n)
                        .map(|k| {
                            let (r, oi) = (k / no, k % no);
                            let j = idx[(offs[oi] + shift) % self.rot.period];
                            debug_assert!(j != usize::MAX);
                            [k, n + r * no + j]
                        })
                        .collect()
                };
                let ew: Vec<f64> = ga.weights.iter().map(|m| w * m).collect();
                let x = View::from_slice(&rows, 2 * n, d)?;
                let node = &mut net.nodes_mut(self.layer)[0];
                if ga.from_stage == 0 {
                    node.partial_fit_graph(x, Some(&zeros), &edges, Some(&ew))?;
                } else {
                    node.partial_fit_graph_from(ga.from_stage, x, Some(&zeros), &edges, Some(&ew))?;
                }
            } else {
                // Naive graphs: rows (view, position); one node per position.
                let np = ga.first.len();
                let kv = n / np;
                net.nodes_mut(self.layer).par_iter_mut().enumerate().try_for_each(|(p, node)| {
                    let mut x = vec![0.0; 2 * kv * d];
                    for (half, g) in [ga, gb].into_iter().enumerate() {
                        for k in 0..kv {
                            let src = (g.lead + k * np + p) * d;
                            let dst = (half * kv + k) * d;
                            x[dst..dst + d].copy_from_slice(&g.rows[src..src + d]);
                        }
                    }
                    let edges: Vec<[usize; 2]> = (0..kv).map(|k| [k, kv + k]).collect();
                    let ew = vec![w; kv];
                    node.partial_fit_graph(
                        View::from_slice(&x, 2 * kv, d)?,
                        Some(&vec![0.0; 2 * kv]),
                        &edges,
                        Some(&ew),
                    )
                })?;
            }
        }
        Ok(())
    }

    /// Ends a pass over the data: solves the node stage trained in it.
    /// Returns true when the layer is fully trained.
    pub fn end_pass(&mut self, net: &mut Network) -> Result<bool> {
        if self.images_seen == 0 {
            return Err(SfaError::TooFewSamples { what: "training images in this pass", needed: 1, got: 0 });
        }
        let n_passes = self.n_passes(net);
        let last = self.pass + 1 == n_passes;
        let layer = self.layer;
        let nodes = net.nodes_mut(layer);
        let r: Result<()> =
            nodes.par_iter_mut().try_for_each(|node| if last { node.ensure_solved() } else { node.finish_stage() });
        r.map_err(|e| match e {
            SfaError::RankDeficient { rank, requested, dim, tol } => SfaError::InvalidArgument(format!(
                "layer {}: {}",
                layer + 1,
                SfaError::RankDeficient { rank, requested, dim, tol }
            )),
            e => e,
        })?;
        self.pass += 1;
        self.pairs_fed = 0;
        self.tail = None;
        self.by_tail = false;
        self.reference = None;
        if let Some(c) = &self.cache {
            if c.len() != self.images_seen {
                return Err(SfaError::InvalidArgument(format!(
                    "{} images were fed in this pass but {} in the first",
                    self.images_seen,
                    c.len()
                )));
            }
        }
        if !self.building.is_empty() {
            self.cache = Some(std::mem::take(&mut self.building));
            if self.closures.is_some() {
                self.partner_cache = Some(std::mem::take(&mut self.partner_building));
            }
        }
        self.images_seen = 0;
        if last {
            net.set_trained(layer + 1);
        }
        Ok(last)
    }
}

/// Per-channel means of one image (`pixels x c` values).
fn channel_means<P: Pixel>(image: &[P], c: usize) -> Vec<f64> {
    let mut mean = vec![0.0; c];
    image.chunks_exact(c).for_each(|px| mean.iter_mut().zip(px).for_each(|(m, v)| *m += v.to_f64()));
    mean.iter_mut().for_each(|m| *m /= (image.len() / c) as f64);
    mean
}
