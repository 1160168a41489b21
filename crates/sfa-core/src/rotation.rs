//! Training and inference under simulated rotation (thesis sections 3.4.1,
//! 5.1.3; design note `shared/fast-rotation.md`).
//!
//! A training panorama (height `H`, width `W`, periodic in columns) is shown
//! as `K = ceil(W / step)` views: view `k` is the image rolled left by
//! `k * step` columns, seen through a window of the network's width `V <= W`
//! (view column `c` is image column `(k * step + c) mod W`). The views of all
//! images form one sequence; each RF position has its own time series
//! (derivative pairs: same position, consecutive views; the last view of an
//! image and the first of the next).
//!
//! # Two exact paths
//! * **Naive** ([`Path::Naive`]): build every view, run the trained lower
//!   layers on it, gather every RF. Kept for tests and for networks without
//!   weight sharing.
//! * **Fast** ([`Path::Fast`], weight sharing only): with a shared node, the
//!   RF of layer `l` at position `j` in view `k` is the periodic patch at base
//!   offset `o = (k * step + j * T_l) mod W`, `T_l` the product of the strides
//!   up to `l`, dilated by `T_{l-1}`. Each layer is evaluated once per image
//!   at the distinct offsets (a periodic field), and the statistics get each
//!   offset's multiplicity as a sample weight and each `(o, o + step)` pair's
//!   multiplicity as a pair weight. Both paths give the same node weights up
//!   to rounding.
//!
//! # The first layer, without gathering patches
//! The first layer's patches are windows of the periodic image itself, so
//! two structured shortcuts apply (private module `periodic.rs`):
//! * pass 1 (the linear reduction's statistics): the weighted second moments
//!   of all periodic patches come from lag products of the image's columns
//!   (and of its difference image for the derivatives), with a few
//!   correction rows for offsets whose multiplicity falls short of the
//!   maximum; used where a cost model says it pays;
//! * pass 2 and every later use of the layer's field: the solved linear
//!   stage is one matrix product per RF row over an overlapping strided
//!   view of the columns.
//!
//! # Memory
//! Per image, a layer's training rows are built, fed and dropped; the
//! trainer can cache each image's field of the layer below (`set_caching`)
//! so later passes and layers neither recompute it nor read the images.

use crate::error::{Result, SfaError};
use crate::network::{check_images, LayerGeometry, Network};
use crate::periodic;
use crate::stats::Accumulator;
use crate::view::View;
use rayon::prelude::*;

/// Simulated rotation: lateral shift step and panorama period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rotation {
    /// Shift between consecutive views, in pixels.
    pub step: usize,
    /// Width of the training panoramas (the period `W`); the network's input
    /// width is the window `V <= W`.
    pub period: usize,
}

impl Rotation {
    /// Number of views per panorama, `ceil(period / step)`.
    pub fn n_views(&self) -> usize {
        self.period.div_ceil(self.step)
    }

    fn check(&self, net: &Network) -> Result<()> {
        let (_, v, _) = net.input_shape();
        if self.step == 0 {
            return Err(SfaError::InvalidArgument("rotation step must be at least 1 pixel".into()));
        }
        if self.period < v {
            return Err(SfaError::InvalidArgument(format!(
                "panorama width {} is smaller than the network's input width {v}",
                self.period
            )));
        }
        if self.step > self.period {
            return Err(SfaError::InvalidArgument(format!(
                "rotation step {} exceeds the panorama width {}",
                self.step, self.period
            )));
        }
        Ok(())
    }
}

/// Which training path to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Path {
    Naive,
    Fast,
}

/// One image's training graph for a layer: patch rows, their sample weights,
/// weighted pairs inside the image, and which rows start and end the image's
/// per-position series (for the pairs between consecutive images). Row
/// indices count from the image's first own row.
struct ImageGraph {
    /// `lead + n` rows: the first `lead` are reserved for the previous
    /// image's last views (filled by the trainer, so the image's rows are
    /// never copied to prepend them); the image's own rows follow.
    rows: Vec<f64>,
    lead: usize,
    n: usize,
    /// Row width, and the node stage the rows enter at (0: raw patches; 1:
    /// outputs of the node's linear first stage, formed by
    /// [`periodic::first_stage_outputs`]).
    width: usize,
    from_stage: usize,
    weights: Vec<f64>,
    edges: Vec<[usize; 2]>,
    edge_weights: Vec<f64>,
    /// Per series (RF row x RF position): row of the first view.
    first: Vec<usize>,
    /// Per series: row of the last view.
    last: Vec<usize>,
    /// Statistics formed without rows (first layer, lag products; see
    /// `periodic.rs`); the rows are then only the first and last
    /// views, as weight-0 pair ends.
    moments: Option<Accumulator>,
}

/// Distinct offsets `(k * step + j * t) mod period` for `k < views`,
/// `j < positions`, sorted, with an index map (usize::MAX where absent).
fn offset_set(rot: &Rotation, t: usize, positions: usize) -> (Vec<usize>, Vec<usize>) {
    let w = rot.period;
    let mut present = vec![false; w];
    for k in 0..rot.n_views() {
        for j in 0..positions {
            present[(k * rot.step + j * t) % w] = true;
        }
    }
    let offs: Vec<usize> = (0..w).filter(|&o| present[o]).collect();
    let mut idx = vec![usize::MAX; w];
    for (i, &o) in offs.iter().enumerate() {
        idx[o] = i;
    }
    (offs, idx)
}

/// Column strides `T_l` (product of strides up to and including `l`).
fn cum_strides(geom: &[LayerGeometry]) -> Vec<usize> {
    let mut t = 1;
    geom.iter()
        .map(|g| {
            t *= g.stride_w;
            t
        })
        .collect()
}

/// A layer's periodic output field of one image: `n_h x |offsets| x n_out`.
struct Field {
    data: FieldData,
    idx: Vec<usize>,
    n_off: usize,
    depth: usize,
}

/// Field values: f64, or f32 when cached for a mixed-precision network.
enum FieldData {
    F64(Vec<f64>),
    F32(Vec<f32>),
}

impl Field {
    /// The `depth` values at (row, offset index), written into `out`.
    #[inline]
    fn read(&self, row: usize, i: usize, out: &mut [f64]) {
        let at = (row * self.n_off + i) * self.depth;
        match &self.data {
            FieldData::F64(v) => out.copy_from_slice(&v[at..at + self.depth]),
            FieldData::F32(v) => {
                for (o, x) in out.iter_mut().zip(&v[at..at + self.depth]) {
                    *o = *x as f64;
                }
            }
        }
    }

    fn compact(self, f32_storage: bool) -> Field {
        match (self.data, f32_storage) {
            (FieldData::F64(v), true) => Field {
                data: FieldData::F32(v.into_iter().map(|x| x as f32).collect()),
                ..self
            },
            (data, _) => Field { data, ..self },
        }
    }

    fn bytes(&self) -> usize {
        match &self.data {
            FieldData::F64(v) => v.len() * 8,
            FieldData::F32(v) => v.len() * 4,
        }
    }
}

/// Gathers layer `l`'s periodic patches (rows `0..n_h`, offsets `offs`) of one
/// image, reading the image (l = 0) or the field below.
fn periodic_patches(
    g: &LayerGeometry,
    dilation: usize,
    period: usize,
    image: &[f64],
    below: Option<&Field>,
    offs: &[usize],
    lead: usize,
) -> Vec<f64> {
    let mut all = vec![0.0; (lead + g.n_h * offs.len()) * g.in_dim];
    let out = &mut all[lead * g.in_dim..];
    let c = g.in_c;
    for r in 0..g.n_h {
        for (oi, &o) in offs.iter().enumerate() {
            let p = &mut out[(r * offs.len() + oi) * g.in_dim..(r * offs.len() + oi + 1) * g.in_dim];
            let mut w = 0;
            for dr in 0..g.rf_h {
                let src_row = r * g.stride_h + dr;
                for m in 0..g.rf_w {
                    let col = (o + m * dilation) % period;
                    match below {
                        None => p[w..w + c].copy_from_slice(
                            &image[(src_row * period + col) * c..(src_row * period + col + 1) * c],
                        ),
                        Some(f) => {
                            let i = f.idx[col];
                            debug_assert!(i != usize::MAX, "offset {col} missing below");
                            f.read(src_row, i, &mut p[w..w + c]);
                        }
                    }
                    w += c;
                }
            }
        }
    }
    all
}

/// Layer `l`'s periodic field of one image, from the image (l = 0) or the
/// field of layer `l - 1`.
fn layer_field(net: &Network, rot: &Rotation, l: usize, image: &[f64], below: Option<&Field>) -> Result<Field> {
    let geom = net.geometry();
    let t = cum_strides(geom);
    let g = &geom[l];
    let (offs, idx) = offset_set(rot, t[l], g.n_w);
    let dilation = if l == 0 { 1 } else { t[l - 1] };
    let n = g.n_h * offs.len();
    let node = &net.nodes(l)[0];
    let data = match (l, node.linear_first_stage()) {
        (0, Some(first)) => {
            let y = periodic::first_stage_outputs(g, image, rot.period, &offs, first);
            node.transform_from(1, View::from_slice(&y, n, first.2)?)?
        }
        _ => {
            let patches = periodic_patches(g, dilation, rot.period, image, below, &offs, 0);
            net.apply_nodes(l, &patches, n, |_| 0)?
        }
    };
    Ok(Field { data: FieldData::F64(data), idx, n_off: offs.len(), depth: g.n_out })
}

/// Periodic fields of layers `0..upto` of one image (weight sharing only).
fn periodic_fields(net: &Network, rot: &Rotation, image: &[f64], upto: usize) -> Result<Vec<Field>> {
    let mut fields: Vec<Field> = Vec::with_capacity(upto);
    for l in 0..upto {
        let f = layer_field(net, rot, l, image, fields.last())?;
        fields.push(f);
    }
    Ok(fields)
}

/// The fast graph of one image for `layer`; `below` is the field of layer
/// `layer - 1` (computed from the image when None). Also returns that field.
/// `reference`: per-channel reference point for the first layer's
/// lag-product statistics (None: always one row per patch).
fn fast_graph(
    net: &Network,
    rot: &Rotation,
    image: &[f64],
    layer: usize,
    below: Option<&Field>,
    reference: Option<&[f64]>,
) -> Result<(ImageGraph, Option<Field>)> {
    let geom = net.geometry();
    let g = &geom[layer];
    let t = cum_strides(geom);
    let computed = match (below, layer) {
        (None, l) if l > 0 => periodic_fields(net, rot, image, layer)?.pop(),
        _ => None,
    };
    let below = below.or(computed.as_ref());
    let (offs, idx) = offset_set(rot, t[layer], g.n_w);
    let dilation = if layer == 0 { 1 } else { t[layer - 1] };
    let (w, k_views, s) = (rot.period, rot.n_views(), rot.step);
    let no = offs.len();
    let mut mult = vec![0.0; no];
    let mut pmult = vec![0.0; no];
    for k in 0..k_views {
        for j in 0..g.n_w {
            let i = idx[(k * s + j * t[layer]) % w];
            mult[i] += 1.0;
            if k + 1 < k_views {
                pmult[i] += 1.0;
            }
        }
    }
    let lead = g.n_positions();
    let first_offset = |j: usize| (j * t[layer]) % w;
    let last_offset = |j: usize| ((k_views - 1) * s + j * t[layer]) % w;
    if let (0, Some(reference)) = (layer, reference) {
        let per_column = |m: &[f64]| {
            let mut v = vec![0.0; w];
            offs.iter().zip(m).for_each(|(&o, &x)| v[o] = x);
            v
        };
        if let Some(plan) = periodic::plan(g, &per_column(&mult), &per_column(&pmult)) {
            let moments = periodic::lattice_moments(g, &plan, image, w, s, reference, net.spec().mixed_precision)?;
            // Rows: per RF row, the first views then the last views.
            let ends: Vec<usize> = (0..g.n_w).map(first_offset).chain((0..g.n_w).map(last_offset)).collect();
            let rows = periodic_patches(g, 1, w, image, None, &ends, lead);
            let n = g.n_h * ends.len();
            let series = |r: usize, j: usize, end: usize| r * 2 * g.n_w + end * g.n_w + j;
            let (mut first, mut last) = (Vec::new(), Vec::new());
            for r in 0..g.n_h {
                for j in 0..g.n_w {
                    first.push(series(r, j, 0));
                    last.push(series(r, j, 1));
                }
            }
            let graph = ImageGraph {
                rows,
                lead,
                n,
                width: g.in_dim,
                from_stage: 0,
                weights: vec![0.0; n],
                edges: Vec::new(),
                edge_weights: Vec::new(),
                first,
                last,
                moments: Some(moments),
            };
            return Ok((graph, computed));
        }
    }
    // The first layer's second pass: rows enter after the node's solved
    // linear first stage, evaluated without gathering patches.
    let first = if layer == 0 { net.nodes(0)[0].linear_first_stage() } else { None };
    let (rows, width, from_stage) = match first {
        Some(first) => {
            let mut rows = vec![0.0; lead * first.2];
            rows.extend(periodic::first_stage_outputs(g, image, w, &offs, first));
            (rows, first.2, 1)
        }
        None => (periodic_patches(g, dilation, rot.period, image, below, &offs, lead), g.in_dim, 0),
    };
    let n = g.n_h * no;
    let mut weights = Vec::with_capacity(n);
    let (mut edges, mut edge_weights) = (Vec::new(), Vec::new());
    for r in 0..g.n_h {
        weights.extend_from_slice(&mult);
        for (oi, &o) in offs.iter().enumerate() {
            if pmult[oi] > 0.0 {
                edges.push([r * no + oi, r * no + idx[(o + s) % w]]);
                edge_weights.push(pmult[oi]);
            }
        }
    }
    let (mut first, mut last) = (Vec::new(), Vec::new());
    for r in 0..g.n_h {
        for j in 0..g.n_w {
            first.push(r * no + idx[first_offset(j)]);
            last.push(r * no + idx[last_offset(j)]);
        }
    }
    Ok((ImageGraph { rows, lead, n, width, from_stage, weights, edges, edge_weights, first, last, moments: None }, computed))
}

/// Checks spatial pairs `(a, b, w)` against `n` images.
fn check_pairs(pairs: &[(usize, usize, f64)], n: usize) -> Result<()> {
    for (e, &(a, b, w)) in pairs.iter().enumerate() {
        if a >= n || b >= n {
            return Err(SfaError::InvalidArgument(format!(
                "pair {e} ({a}, {b}) names an image beyond the {n} given"
            )));
        }
        if !(w.is_finite() && w >= 0.0) {
            return Err(SfaError::InvalidArgument(format!(
                "pair {e}: weights must be finite and non-negative, got {w}"
            )));
        }
    }
    Ok(())
}

/// View `k` of a `h x period x c` image through a window of `v` columns.
fn view(image: &[f64], h: usize, period: usize, c: usize, v: usize, shift: usize) -> Vec<f64> {
    let mut out = vec![0.0; h * v * c];
    for r in 0..h {
        for col in 0..v {
            let src = (r * period + (shift + col) % period) * c;
            out[(r * v + col) * c..(r * v + col + 1) * c].copy_from_slice(&image[src..src + c]);
        }
    }
    out
}

fn naive_graph(net: &Network, rot: &Rotation, image: &[f64], layer: usize) -> Result<ImageGraph> {
    let g = &net.geometry()[layer];
    let (h, v, c) = net.input_shape();
    let np = g.n_positions();
    let kv = rot.n_views();
    let lead = np;
    let mut rows = vec![0.0; (lead + kv * np) * g.in_dim];
    for k in 0..kv {
        let vw = view(image, h, rot.period, c, v, k * rot.step);
        let f = net.field_below(&vw, layer)?;
        for r in 0..g.n_h {
            for j in 0..g.n_w {
                let i = lead + k * np + r * g.n_w + j;
                g.gather(&f, r, j, &mut rows[i * g.in_dim..(i + 1) * g.in_dim]);
            }
        }
    }
    let mut edges = Vec::new();
    for k in 0..kv.saturating_sub(1) {
        for p in 0..np {
            edges.push([k * np + p, (k + 1) * np + p]);
        }
    }
    let ne = edges.len();
    Ok(ImageGraph {
        rows,
        lead,
        n: kv * np,
        width: g.in_dim,
        from_stage: 0,
        weights: vec![1.0; kv * np],
        edges,
        edge_weights: vec![1.0; ne],
        first: (0..np).collect(),
        last: (0..np).map(|p| (kv - 1) * np + p).collect(),
        moments: None,
    })
}

/// Trains one layer of a network, pass by pass, on images streamed in
/// chunks. Usage: for each pass (`n_passes()`), feed every image in order
/// ([`feed`](Self::feed)), then [`end_pass`](Self::end_pass).
pub struct LayerTrainer {
    layer: usize,
    rot: Rotation,
    path: Path,
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
}

impl LayerTrainer {
    /// Starts training `layer` (all layers below must be trained).
    pub fn new(net: &Network, layer: usize, rot: Rotation, path: Path) -> Result<Self> {
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
        let path = if net.spec().weight_sharing { path } else { Path::Naive };
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
        })
    }

    /// Keeps the lower layers' periodic fields of every image in memory
    /// (f32 for mixed-precision networks) so that later passes and layers
    /// do not recompute them. Fast path only; the images must then be fed
    /// in the same order in every pass.
    pub fn set_caching(&mut self, on: bool) {
        self.caching = on && self.path == Path::Fast;
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
            return Err(SfaError::InvalidArgument(format!(
                "transition_weight must be a finite number >= 0, got {w}"
            )));
        }
        self.transition_weight = w;
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
        self.cache.iter().flatten().chain(&self.building).map(Field::bytes).sum()
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
        let mixed = net.spec().mixed_precision;
        if let (true, Some(cache)) = (self.caching, self.cache) {
            let (layer, rot) = (self.layer, self.rot);
            let advanced: Vec<Result<Field>> = cache
                .into_par_iter()
                .map(|f| Ok(layer_field(net, &rot, layer, &[], Some(&f))?.compact(mixed)))
                .collect();
            next.cache = Some(advanced.into_iter().collect::<Result<Vec<_>>>()?);
        }
        Ok(next)
    }

    /// Feeds the next pass from the cache (every cached image, in order).
    pub fn feed_cached(&mut self, net: &mut Network) -> Result<()> {
        let cache = self
            .cache
            .take()
            .ok_or_else(|| SfaError::InvalidArgument("this trainer has no cached fields".into()))?;
        let (layer, rot) = (self.layer, self.rot);
        let chunk = 16;
        let mut result = Ok(());
        for part in cache.chunks(chunk) {
            let graphs: Vec<Result<(ImageGraph, Option<Field>)>> = {
                let net_ref: &Network = net;
                part.par_iter().map(|f| fast_graph(net_ref, &rot, &[], layer, Some(f), None)).collect()
            };
            for g in graphs {
                match g.and_then(|(gr, _)| self.feed_shared(net, gr)) {
                    Ok(()) => self.images_seen += 1,
                    Err(e) => {
                        result = Err(e);
                        break;
                    }
                }
            }
            if result.is_err() {
                break;
            }
        }
        self.cache = Some(cache);
        result
    }

    /// Passes over the data this layer needs (2: reduction, then expansion).
    pub fn n_passes(&self, net: &Network) -> usize {
        net.nodes(self.layer)[0].n_stages()
    }

    /// The path in use (naive without weight sharing).
    pub fn path(&self) -> Path {
        self.path
    }

    /// Feeds `n` images (`n x height x period x channels`, row-major), in
    /// sequence order.
    pub fn feed(&mut self, net: &mut Network, images: &[f64], n: usize) -> Result<()> {
        let (h, _, c) = net.input_shape();
        let size = h * self.rot.period * c;
        check_images(images, n, size, self.images_seen)?;
        if self.cache.is_some() {
            return Err(SfaError::InvalidArgument(
                "this pass reads the cached fields: call feed_cached instead of feed".into(),
            ));
        }
        let (layer, rot, path) = (self.layer, self.rot, self.path);
        if layer == 0
            && path == Path::Fast
            && self.reference.is_none()
            && n > 0
            && self.lag_products
            && net.nodes(0)[0].trains_on_raw_input()
        {
            // Per-channel means of the first image: the lag products'
            // reference point for the whole pass.
            let mut mean = vec![0.0; c];
            images[..size].chunks_exact(c).for_each(|px| mean.iter_mut().zip(px).for_each(|(m, v)| *m += v));
            mean.iter_mut().for_each(|m| *m /= (size / c) as f64);
            self.reference = Some(mean);
        }
        let graphs: Vec<Result<(ImageGraph, Option<Field>)>> = {
            let net_ref: &Network = net;
            let reference = self.reference.as_deref();
            images
                .par_chunks(size)
                .map(|img| match path {
                    Path::Fast => fast_graph(net_ref, &rot, img, layer, None, reference),
                    Path::Naive => Ok((naive_graph(net_ref, &rot, img, layer)?, None)),
                })
                .collect()
        };
        let d = net.geometry()[layer].in_dim;
        let mixed = net.spec().mixed_precision;
        for gr in graphs {
            let (gr, field) = gr?;
            if self.caching {
                if let Some(f) = field {
                    self.building.push(f.compact(mixed));
                }
            }
            if net.spec().weight_sharing {
                self.feed_shared(net, gr)?;
            } else {
                self.feed_individual(net, gr, d)?;
            }
            self.images_seen += 1;
        }
        Ok(())
    }

    fn feed_shared(&mut self, net: &mut Network, gr: ImageGraph) -> Result<()> {
        let ns = gr.first.len();
        let d = gr.width;
        let mut rows = gr.rows;
        let (start, n, weights, edges, ew) = match self.tail.take() {
            None => (gr.lead, gr.n, gr.weights, gr.edges, gr.edge_weights),
            Some(tail) => {
                // The previous image's last views go into the reserved
                // leading rows, as weight-0 samples that end one pair each.
                debug_assert_eq!(gr.lead, ns);
                rows[..ns * d].copy_from_slice(&tail);
                let mut w = vec![0.0; ns];
                w.extend_from_slice(&gr.weights);
                let mut e: Vec<[usize; 2]> = (0..ns).map(|i| [i, ns + gr.first[i]]).collect();
                e.extend(gr.edges.iter().map(|[a, b]| [a + ns, b + ns]));
                let mut ew = vec![self.transition_weight; ns];
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
        let node = &mut net.nodes_mut(self.layer)[0];
        if let Some(m) = &gr.moments {
            node.merge_statistics(m)?;
            self.lag_images += 1;
        }
        let x = View::from_slice(&rows[start * d..], n, d)?;
        if gr.from_stage == 0 {
            node.partial_fit_graph(x, Some(&weights), &edges, Some(&ew))?;
        } else {
            node.partial_fit_graph_from(gr.from_stage, x, Some(&weights), &edges, Some(&ew))?;
        }
        self.tail = Some(tail);
        Ok(())
    }

    fn feed_individual(&mut self, net: &mut Network, gr: ImageGraph, d: usize) -> Result<()> {
        // Naive graph: rows are (view, position); each position's rows form
        // one series continuing across images.
        let np = gr.first.len();
        let kv = gr.n / np;
        let first_image = self.images_seen == 0;
        let tw = self.transition_weight;
        let nodes = net.nodes_mut(self.layer);
        if tw == 1.0 {
            return nodes.par_iter_mut().enumerate().try_for_each(|(p, node)| {
                let mut x = vec![0.0; kv * d];
                for k in 0..kv {
                    let src = (gr.lead + k * np + p) * d;
                    x[k * d..(k + 1) * d].copy_from_slice(&gr.rows[src..src + d]);
                }
                node.partial_fit(View::from_slice(&x, kv, d)?, first_image)
            });
        }
        // Weighted transition: each node's series as a graph, with the
        // previous image's last view as a weight-0 leading row.
        let tail = self.tail.take();
        let r = nodes.par_iter_mut().enumerate().try_for_each(|(p, node)| {
            let lead = usize::from(tail.is_some());
            let mut x = vec![0.0; (lead + kv) * d];
            if let Some(t) = &tail {
                x[..d].copy_from_slice(&t[p * d..(p + 1) * d]);
            }
            for k in 0..kv {
                let src = (gr.lead + k * np + p) * d;
                x[(lead + k) * d..(lead + k + 1) * d].copy_from_slice(&gr.rows[src..src + d]);
            }
            let mut w = vec![1.0; lead + kv];
            let mut ew = vec![1.0; lead + kv - 1];
            if lead == 1 {
                w[0] = 0.0;
                ew[0] = tw;
            }
            let edges: Vec<[usize; 2]> = (0..lead + kv - 1).map(|i| [i, i + 1]).collect();
            node.partial_fit_graph(View::from_slice(&x, lead + kv, d)?, Some(&w), &edges, Some(&ew))
        });
        let mut next = vec![0.0; np * d];
        for p in 0..np {
            let src = (gr.lead + (kv - 1) * np + p) * d;
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
    pub fn feed_pairs(
        &mut self,
        net: &mut Network,
        images: &[f64],
        n: usize,
        pairs: &[(usize, usize, f64)],
    ) -> Result<()> {
        let (h, _, c) = net.input_shape();
        let size = h * self.rot.period * c;
        check_images(images, n, size, 0)?;
        check_pairs(pairs, n)?;
        let (layer, rot, path) = (self.layer, self.rot, self.path);
        let graphs: Vec<ImageGraph> = {
            let net_ref: &Network = net;
            let r: Vec<Result<ImageGraph>> = images
                .par_chunks(size)
                .map(|img| match path {
                    Path::Fast => fast_graph(net_ref, &rot, img, layer, None, None).map(|(g, _)| g),
                    Path::Naive => naive_graph(net_ref, &rot, img, layer),
                })
                .collect();
            r.into_iter().collect::<Result<_>>()?
        };
        self.add_pair_graphs(net, &graphs, pairs, None)
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
                return Err(SfaError::ShapeMismatch { what: "number of pair shifts", expected: pairs.len(), got: sh.len() });
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
        let cache = self
            .cache
            .take()
            .ok_or_else(|| SfaError::InvalidArgument("this trainer has no cached fields".into()))?;
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
            if w == 0.0 || a == b {
                continue;
            }
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
                    node.partial_fit_graph(View::from_slice(&x, 2 * kv, d)?, Some(&vec![0.0; 2 * kv]), &edges, Some(&ew))
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
        let r: Result<()> = nodes.par_iter_mut().try_for_each(|node| {
            if last {
                node.ensure_solved()
            } else {
                node.finish_stage()
            }
        });
        r.map_err(|e| match e {
            SfaError::RankDeficient { rank, requested, dim, tol } => SfaError::InvalidArgument(format!(
                "layer {}: {}",
                layer + 1,
                SfaError::RankDeficient { rank, requested, dim, tol }
            )),
            e => e,
        })?;
        self.pass += 1;
        self.tail = None;
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
        }
        self.images_seen = 0;
        if last {
            net.set_trained(layer + 1);
        }
        Ok(last)
    }
}

/// Top-layer outputs of each image under every simulated rotation:
/// `n x n_views x n_outputs`. Fast (periodic fields) with weight sharing;
/// naive otherwise.
pub fn transform_rotations(net: &Network, rot: Rotation, images: &[f64], n: usize) -> Result<Vec<f64>> {
    rot.check(net)?;
    if !net.is_trained() {
        return Err(SfaError::NotFitted("the network is not trained".into()));
    }
    let (h, v, c) = net.input_shape();
    let size = h * rot.period * c;
    check_images(images, n, size, 0)?;
    let kv = rot.n_views();
    let m = net.n_outputs();
    let top = net.n_layers() - 1;
    let per: Vec<Result<Vec<f64>>> = images
        .par_chunks(size)
        .map(|img| {
            if net.spec().weight_sharing {
                let fields = periodic_fields(net, &rot, img, top + 1)?;
                let f = fields.last().expect("top field");
                Ok((0..kv)
                    .flat_map(|k| {
                        let mut v = vec![0.0; m];
                        f.read(0, f.idx[(k * rot.step) % rot.period], &mut v);
                        v
                    })
                    .collect())
            } else {
                let mut out = Vec::with_capacity(kv * m);
                for k in 0..kv {
                    out.extend(net.field_below(&view(img, h, rot.period, c, v, k * rot.step), top + 1)?);
                }
                Ok(out)
            }
        })
        .collect();
    let mut y = Vec::with_capacity(n * kv * m);
    for p in per {
        y.extend(p?);
    }
    Ok(y)
}

/// Convenience: trains every untrained layer on an in-memory batch.
pub fn train(net: &mut Network, rot: Rotation, images: &[f64], n: usize, path: Path, cache: bool) -> Result<()> {
    train_weighted(net, rot, images, n, path, cache, 1.0)
}

/// [`train`] with the weight of the pairs between consecutive images
/// ([`LayerTrainer::set_transition_weight`]).
pub fn train_weighted(
    net: &mut Network,
    rot: Rotation,
    images: &[f64],
    n: usize,
    path: Path,
    cache: bool,
    transition_weight: f64,
) -> Result<()> {
    let mut tr = LayerTrainer::new(net, net.n_trained(), rot, path)?;
    tr.set_caching(cache);
    tr.set_transition_weight(transition_weight)?;
    loop {
        loop {
            if tr.has_cache() {
                tr.feed_cached(net)?;
            } else {
                tr.feed(net, images, n)?;
            }
            if tr.end_pass(net)? {
                break;
            }
        }
        if net.is_trained() {
            return Ok(());
        }
        tr = tr.next_layer(net)?;
    }
}
