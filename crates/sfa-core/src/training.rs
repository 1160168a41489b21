//! The training loop: every untrained layer of a network, pass by pass, on
//! images read from a [`BatchSource`] (thesis sections 3.4, 5.1.3).
//!
//! [`fit`] trains the layers bottom up with a [`LayerTrainer`] each. A
//! layer takes one pass over the data per node stage (two: the linear
//! reduction, then the expansion). A pass either reads the images again
//! (and recomputes the trained layers below) or, when the trainer holds
//! the field cache, the cached fields of the layer below. Before each
//! layer above the first, the cache policy decides whether that layer's
//! input fields are kept; the decisions come back as the
//! [`FitReport::cache_plan`]. Optional spatial pairs (graph-based SFA) are
//! added in every pass of the layers they apply to: streamed passes gather
//! the pairs' images from the source in chunks, cached passes read them
//! from the cache.

use crate::closures::LoopClosures;
use crate::error::{Result, SfaError};
use crate::fields::field_bytes;
use crate::network::Network;
use crate::pixel::{Batch, Pixel};
use crate::rotation::{Rotation, TrainingPath};
use crate::trainer::LayerTrainer;
use crate::with_pixels;
use std::sync::Arc;

/// Where training images come from. Every pass reads all images, in the
/// same order, as batches `n x height x period x channels` of any pixel
/// type; spatial pairs also ask for chosen images.
pub trait BatchSource {
    /// Number of images, if known in advance (for progress reports).
    fn len_hint(&self) -> Option<usize> {
        None
    }

    /// Calls `f` with every batch of the training images, in order; stops
    /// at (and returns) the first error, of `f` or of the source.
    fn for_each_batch(&mut self, f: &mut (dyn FnMut(Batch<'_>) -> Result<()> + Send)) -> Result<()>;

    /// Calls `f` once with the images `ids` (indices into the training
    /// images, in that order) as one batch. Needed only for spatial pairs.
    fn gather(&mut self, ids: &[usize], f: &mut (dyn FnMut(Batch<'_>) -> Result<()> + Send)) -> Result<()> {
        let _ = (ids, f);
        Err(SfaError::InvalidArgument("this image source cannot gather images for spatial pairs".into()))
    }
}

/// Images in memory (`n x height x period x channels`, row-major), read in
/// batches of `batch` images.
pub struct InMemory<'a, P> {
    images: &'a [P],
    n: usize,
    batch: usize,
}

impl<'a, P: Pixel> InMemory<'a, P> {
    /// `n` images in one slice, handed out `batch` at a time (at least 1).
    pub fn new(images: &'a [P], n: usize, batch: usize) -> Result<Self> {
        if n == 0 || images.len() % n != 0 {
            return Err(SfaError::InvalidArgument(format!("{} values do not split into {n} images", images.len())));
        }
        Ok(InMemory { images, n, batch: batch.max(1) })
    }
}

impl<P: Pixel> BatchSource for InMemory<'_, P> {
    fn len_hint(&self) -> Option<usize> {
        Some(self.n)
    }

    fn for_each_batch(&mut self, f: &mut (dyn FnMut(Batch<'_>) -> Result<()> + Send)) -> Result<()> {
        let size = self.images.len() / self.n;
        for chunk in self.images.chunks(self.batch * size) {
            f(Batch::new(chunk, chunk.len() / size))?;
        }
        Ok(())
    }

    fn gather(&mut self, ids: &[usize], f: &mut (dyn FnMut(Batch<'_>) -> Result<()> + Send)) -> Result<()> {
        let size = self.images.len() / self.n;
        let mut out = Vec::with_capacity(ids.len() * size);
        for &i in ids {
            if i >= self.n {
                return Err(SfaError::InvalidArgument(format!("image {i} is beyond the {} given", self.n)));
            }
            out.extend_from_slice(&self.images[i * size..(i + 1) * size]);
        }
        f(Batch::new(&out, ids.len()))
    }
}

/// Whether a layer keeps the fields of the layer below in memory for its
/// later passes and for the next layer (fast path only).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CachePolicy {
    /// Cache every layer's input fields.
    Always,
    /// Stream the images in every pass (and recompute the lower layers).
    Never,
    /// Cache a layer's input fields when all images' fields take at most
    /// this many bytes.
    Auto(f64),
}

/// Spatial pairs of training images (see
/// [`LayerTrainer::feed_pairs`] and
/// [`LayerTrainer::feed_pairs_cached_shifted`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SpatialPairs {
    /// `(a, b, weight)`: indices into the training images.
    pub pairs: Vec<(usize, usize, f64)>,
    /// Per pair, a column shift: image `b` is seen rolled left by it.
    /// Cached passes need multiples of the step with the step dividing the
    /// period; choose [`CachePolicy::Never`] otherwise.
    pub shifts: Option<Vec<usize>>,
    /// Layers (0-based) whose passes take the pairs.
    pub layers: Vec<usize>,
    /// Pairs per gathered chunk in streamed passes (at most twice as many
    /// distinct images).
    pub chunk: usize,
}

/// How [`fit`] trains.
#[derive(Clone, Debug, PartialEq)]
pub struct FitOptions {
    pub rotation: Rotation,
    pub path: TrainingPath,
    pub cache: CachePolicy,
    /// Weight of the derivative pairs between consecutive images
    /// ([`LayerTrainer::set_transition_weight`]; 1: the thesis).
    pub transition_weight: f64,
    pub pairs: Option<SpatialPairs>,
    /// Whether the first layer may form its linear statistics from lag
    /// products ([`LayerTrainer::set_lag_products`]).
    pub lag_products: bool,
    /// Loop closures for feedback training, in every layer
    /// ([`LayerTrainer::set_loop_closures`]).
    pub loop_closures: Option<Arc<LoopClosures>>,
}

impl FitOptions {
    /// The defaults: fast path, field cache up to 1 GB, transition weight
    /// 1, no spatial pairs, lag products on.
    pub fn new(rotation: Rotation) -> Self {
        FitOptions {
            rotation,
            path: TrainingPath::Fast,
            cache: CachePolicy::Auto(1e9),
            transition_weight: 1.0,
            pairs: None,
            lag_products: true,
            loop_closures: None,
        }
    }
}

/// The cache decision before training a layer above the first.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CacheDecision {
    /// The layer being trained (0-based); its input is the field of
    /// `layer - 1`.
    pub layer: usize,
    /// Whether those fields are kept.
    pub kept: bool,
    /// Bytes all images' fields take (kept or not).
    pub bytes: usize,
}

/// What [`fit`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FitReport {
    pub cache_plan: Vec<CacheDecision>,
    /// Images in the first pass.
    pub n_images: usize,
    /// Images whose first-layer statistics came from lag products.
    pub lag_product_images: usize,
}

/// What a progress report is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProgressEvent {
    /// A pass starts.
    Start,
    /// More images of the pass are done.
    Advance,
    /// The pass has read all its images.
    Finish,
}

/// A progress report of [`fit`]: layer and pass (0-based), images done.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Progress {
    pub event: ProgressEvent,
    pub layer: usize,
    pub n_layers: usize,
    pub pass: usize,
    pub n_passes: usize,
    /// Whether the pass reads the field cache instead of the images.
    pub cached: bool,
    pub done: usize,
    /// Images in the pass, if known.
    pub total: Option<usize>,
}

/// Trains every untrained layer of `net` on the images of `source`;
/// `progress` hears of every pass's start, batches and end (its error ends
/// training). Returns the cache plan.
pub fn fit<S: BatchSource + ?Sized>(
    net: &mut Network,
    source: &mut S,
    opts: &FitOptions,
    progress: &mut (dyn FnMut(&Progress) -> Result<()> + Send),
) -> Result<FitReport> {
    let n_layers = net.n_layers();
    let start = net.n_trained();
    if start == n_layers {
        return Err(SfaError::InvalidArgument("every layer of this network is already trained".into()));
    }
    if let CachePolicy::Auto(limit) = opts.cache {
        if limit.is_nan() || limit < 0.0 {
            return Err(SfaError::InvalidArgument(format!(
                "cache_limit must be a non-negative number of bytes, got {limit}"
            )));
        }
    }
    if let Some(sp) = &opts.pairs {
        if let Some(l) = sp.layers.iter().find(|&&l| l >= n_layers) {
            return Err(SfaError::InvalidArgument(format!("spatial pairs name layer {}, of {n_layers}", l + 1)));
        }
        if sp.shifts.as_ref().is_some_and(|s| s.len() != sp.pairs.len()) {
            return Err(SfaError::InvalidArgument("spatial pairs: one shift per pair".into()));
        }
    }
    if let (Some(lc), Some(n)) = (&opts.loop_closures, source.len_hint()) {
        check_closures(lc, n)?;
    }
    let rot = opts.rotation;
    let mut tr = LayerTrainer::new(net, start, rot, opts.path)?;
    tr.set_transition_weight(opts.transition_weight)?;
    tr.set_loop_closures(net, opts.loop_closures.clone())?;
    tr.set_lag_products(opts.lag_products);
    let mut report = FitReport::default();
    for layer in start..n_layers {
        if layer > start {
            report.lag_product_images += tr.lag_product_images();
            let partners = opts.loop_closures.as_ref().map_or(0, |c| c.len());
            let bytes = field_bytes(net, &rot, layer - 1) * (report.n_images + partners);
            let kept = match opts.cache {
                CachePolicy::Always => true,
                CachePolicy::Never => false,
                CachePolicy::Auto(limit) => bytes as f64 <= limit,
            };
            report.cache_plan.push(CacheDecision { layer, kept, bytes });
            tr.set_caching(kept);
            tr = tr.next_layer(net)?;
        }
        let pairs = opts.pairs.as_ref().filter(|sp| sp.layers.contains(&layer));
        let n_passes = tr.n_passes(net);
        for pass in 0..n_passes {
            let mut report_at = |event, cached, done, total| {
                progress(&Progress { event, layer, n_layers, pass, n_passes, cached, done, total })
            };
            if tr.has_cache() {
                let total = tr.cached_images();
                report_at(ProgressEvent::Start, true, 0, Some(total))?;
                tr.feed_cached(net)?;
                if let Some(sp) = pairs {
                    tr.feed_pairs_cached_shifted(net, &sp.pairs, sp.shifts.as_deref())?;
                }
                report_at(ProgressEvent::Advance, true, total, Some(total))?;
                report_at(ProgressEvent::Finish, true, total, Some(total))?;
            } else {
                let known = (report.n_images > 0).then_some(report.n_images);
                let total = source.len_hint().or(known);
                report_at(ProgressEvent::Start, false, 0, total)?;
                let mut seen = 0;
                source.for_each_batch(&mut |b: Batch<'_>| {
                    with_pixels!(b.pixels, s => tr.feed(net, s, b.n))?;
                    seen += b.n;
                    report_at(ProgressEvent::Advance, false, seen, total)
                })?;
                report_at(ProgressEvent::Finish, false, seen, total)?;
                if let Some(sp) = pairs {
                    feed_streamed_pairs(&mut tr, net, source, sp)?;
                }
                if layer == start && pass == 0 {
                    report.n_images = seen;
                    if let Some(lc) = &opts.loop_closures {
                        check_closures(lc, seen)?;
                    }
                }
            }
            tr.end_pass(net)?;
        }
    }
    report.lag_product_images += tr.lag_product_images();
    Ok(report)
}

/// Loop closures must name images among the `n` of the run.
fn check_closures(lc: &LoopClosures, n: usize) -> Result<()> {
    match lc.max_current() {
        Some(m) if m >= n => Err(SfaError::InvalidArgument(format!(
            "a loop closure names image {m}, but the training run has {n} images"
        ))),
        _ => Ok(()),
    }
}

/// Feeds spatial pairs in chunks of at most `2 * chunk` distinct images
/// (sorted by the smaller index, then the second, so that neighbours in the
/// run share chunks), gathered from the source.
fn feed_streamed_pairs<S: BatchSource + ?Sized>(
    tr: &mut LayerTrainer,
    net: &mut Network,
    source: &mut S,
    sp: &SpatialPairs,
) -> Result<()> {
    let mut order: Vec<usize> = (0..sp.pairs.len()).collect();
    order.sort_by_key(|&e| {
        let (a, b, _) = sp.pairs[e];
        (a.min(b), b)
    });
    for sel in order.chunks(sp.chunk.max(1)) {
        let mut ids: Vec<usize> = sel.iter().flat_map(|&e| [sp.pairs[e].0, sp.pairs[e].1]).collect();
        ids.sort_unstable();
        ids.dedup();
        let pos = |i: usize| ids.binary_search(&i).expect("gathered id");
        let local: Vec<(usize, usize, f64)> = sel
            .iter()
            .map(|&e| {
                let (a, b, w) = sp.pairs[e];
                (pos(a), pos(b), w)
            })
            .collect();
        let shifts: Option<Vec<usize>> = sp.shifts.as_ref().map(|s| sel.iter().map(|&e| s[e]).collect());
        let n = ids.len();
        source.gather(&ids, &mut |b: Batch<'_>| {
            if b.n != n {
                return Err(SfaError::ShapeMismatch { what: "gathered images", expected: n, got: b.n });
            }
            with_pixels!(b.pixels, s => tr.feed_pairs_shifted(net, s, n, &local, shifts.as_deref()))
        })?;
    }
    Ok(())
}
