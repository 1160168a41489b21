//! Training and inference under simulated rotation (thesis sections 3.4.1,
//! 5.1.3; design and measurements in `docs/fast-rotation.md`).
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
//! * **Naive** ([`TrainingPath::Naive`]): build every view, run the trained lower
//!   layers on it, gather every RF. Kept for tests and for networks without
//!   weight sharing.
//! * **Fast** ([`TrainingPath::Fast`], weight sharing only): with a shared node, the
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
//! # Modules
//! This module holds the rotation itself and inference under it
//! ([`transform_rotations`]); the per-image fields and training graphs are
//! in the private `fields.rs`, the per-layer trainer in
//! [`crate::trainer`] and the whole training loop in [`crate::training`].
//!
//! # Memory
//! Per image, a layer's training rows are built, fed and dropped; the
//! trainer can cache each image's field of the layer below
//! ([`LayerTrainer::set_caching`](crate::LayerTrainer::set_caching)) so
//! later passes and layers neither recompute it nor read the images.

use crate::error::{Result, SfaError};
use crate::fields::{periodic_fields, view};
use crate::network::{check_images, Network};
use crate::pixel::Pixel;
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

    pub(crate) fn check(&self, net: &Network) -> Result<()> {
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

/// How a layer's training data under rotation are formed (both give the
/// same node weights up to rounding; see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrainingPath {
    /// Every view built and run through the lower layers.
    Naive,
    /// Periodic fields with multiplicities (weight sharing only; networks
    /// without it fall back to [`TrainingPath::Naive`]).
    Fast,
}

/// Top-layer outputs of each image under every simulated rotation:
/// `n x n_views x n_outputs`. Fast (periodic fields) with weight sharing;
/// naive otherwise.
pub fn transform_rotations<P: Pixel>(net: &Network, rot: Rotation, images: &[P], n: usize) -> Result<Vec<f64>> {
    rot.check(net)?;
    if !net.is_trained() {
        return Err(SfaError::NotFitted("the network is not trained".into()));
    }
    let (h, v, c) = net.input_shape();
    let size = h * rot.period * c;
    check_images(images, n, size, 0)?;
    let kv = rot.n_views();
    let m = net.n_outputs();
    crate::memory::check(
        || format!("the features of {n} images under {kv} rotations"),
        crate::memory::bytes_of(8, &[n, kv, m]),
    )?;
    let top = net.n_layers() - 1;
    let per: Vec<Result<Vec<f64>>> = images
        .par_chunks(size)
        .map(|img| {
            if net.spec().weight_sharing {
                let fields = periodic_fields(net, &rot, &P::image_f64(img), top + 1)?;
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
