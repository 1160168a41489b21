//! `_core.LayerTrainer`: one pass of one layer over a partition of the
//! training images, for partitioned (distributed) training
//! (sfa_core::LayerTrainer::resume; driven by sfanav.sfa.distributed).

use crate::arrays::Images;
use crate::error::{guard, run};
use crate::network::{loop_closures, network_images, zip_pairs, PyNetwork};
use crate::statistics::PyStatistics;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use sfa_core::{with_pixels, Accumulator, LayerTrainer, Rotation, TrainingPath};
use std::sync::Arc;

/// One pass of one layer on a copy of the network (see
/// sfa_core::LayerTrainer): feed a partition's images, export the
/// statistics; or, on the driver, merge them and end the pass.
#[pyclass(name = "LayerTrainer", module = "sfanav._core")]
pub(crate) struct PyLayerTrainer {
    inner: LayerTrainer,
    period: usize,
}

impl PyLayerTrainer {
    /// Borrows images `(N, H, period[, C])` for the network.
    fn images<'py>(&self, obj: &Bound<'py, PyAny>, net: &PyNetwork, what: &str) -> PyResult<Images<'py>> {
        let images = network_images(obj, &net.inner, what)?;
        let w = images.shape[2];
        if w != self.period {
            return Err(PyValueError::new_err(format!(
                "{what} are {w} px wide, the training panoramas {}",
                self.period
            )));
        }
        Ok(images)
    }

    /// Borrows exactly one image `(1, H, period[, C])`.
    fn one_image<'py>(&self, obj: &Bound<'py, PyAny>, net: &PyNetwork, what: &str) -> PyResult<Images<'py>> {
        let images = self.images(obj, net, what)?;
        if images.shape[0] != 1 {
            return Err(PyValueError::new_err(format!(
                "{what}: give one image as a batch of 1, got {}",
                images.shape[0]
            )));
        }
        Ok(images)
    }
}

#[pymethods]
impl PyLayerTrainer {
    /// LayerTrainer(net, layer, pass_, step, period, *, fast, transition_weight,
    /// lag_products): pass `pass_` of `layer` (0-based) on `net`, whose
    /// earlier passes are done.
    #[new]
    #[pyo3(signature = (net, layer, pass_, step, period, *, fast=true, transition_weight=1.0, lag_products=true))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        net: &PyNetwork,
        layer: usize,
        pass_: usize,
        step: usize,
        period: usize,
        fast: bool,
        transition_weight: f64,
        lag_products: bool,
    ) -> PyResult<Self> {
        let path = if fast { TrainingPath::Fast } else { TrainingPath::Naive };
        let rot = Rotation { step, period };
        let inner = guard(|| {
            let mut tr = LayerTrainer::resume(&net.inner, layer, pass_, rot, path)?;
            tr.set_transition_weight(transition_weight)?;
            tr.set_lag_products(lag_products);
            Ok(tr)
        })?;
        Ok(PyLayerTrainer { inner, period })
    }

    #[getter]
    fn layer(&self) -> usize {
        self.inner.layer()
    }

    #[getter]
    fn pass_(&self) -> usize {
        self.inner.pass()
    }

    #[getter]
    fn images_seen(&self) -> usize {
        self.inner.images_seen()
    }

    /// Spatial pairs fed in this pass (weight > 0, between two different
    /// images or an image and itself rolled).
    #[getter]
    fn pairs_fed(&self) -> usize {
        self.inner.pairs_fed()
    }

    fn n_passes(&self, net: &PyNetwork) -> usize {
        self.inner.n_passes(&net.inner)
    }

    /// The loop closures of this partition's images: `current` indexes the
    /// images in the order this trainer is fed them, `partners` (M, H, W[,
    /// C]) are the aligned earlier images, `weights` in [0, 1]. Before the
    /// first image of the pass.
    fn set_loop_closures(
        &mut self,
        net: &PyNetwork,
        current: Vec<usize>,
        weights: Vec<f64>,
        partners: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let lc = loop_closures(&net.inner, self.period, current, weights, partners)?;
        let (tr, n) = (&mut self.inner, &net.inner);
        guard(|| tr.set_loop_closures(n, Some(Arc::new(lc))))
    }

    /// Adds spatial pairs `(a[e], b[e], weights[e])` between the images
    /// (N, H, W[, C]) given here (indices into them), image `b` seen rolled
    /// left by `shifts[e]` columns when given; no samples and no sequence.
    #[pyo3(signature = (net, images, a, b, weights, shifts=None))]
    #[allow(clippy::too_many_arguments)]
    fn feed_pairs(
        &mut self,
        py: Python<'_>,
        net: &mut PyNetwork,
        images: &Bound<'_, PyAny>,
        a: Vec<usize>,
        b: Vec<usize>,
        weights: Vec<f64>,
        shifts: Option<Vec<usize>>,
    ) -> PyResult<()> {
        let images = self.images(images, net, "pair images")?;
        let n = images.shape[0];
        let pairs = zip_pairs(a, b, weights)?;
        let data = images.data();
        let px = data.pixels();
        let (tr, nt) = (&mut self.inner, &mut net.inner);
        run(py, || with_pixels!(px, s => tr.feed_pairs_shifted(nt, s, n, &pairs, shifts.as_deref())))
    }

    /// The first image of the whole pass (1, H, W[, C]): the reference
    /// point of the first layer's lag products, the same in every
    /// partition.
    fn set_reference_image(&mut self, py: Python<'_>, net: &PyNetwork, image: &Bound<'_, PyAny>) -> PyResult<()> {
        let images = self.one_image(image, net, "the reference image")?;
        let data = images.data();
        let px = data.pixels();
        let (tr, n) = (&mut self.inner, &net.inner);
        run(py, || with_pixels!(px, s => tr.set_reference_image(n, s)))
    }

    /// The image before this partition (1, H, W[, C]), when the partition
    /// continues its sequence: its pair with the first image is counted
    /// here, its statistics are not.
    fn prime(&mut self, py: Python<'_>, net: &PyNetwork, image: &Bound<'_, PyAny>) -> PyResult<()> {
        let images = self.one_image(image, net, "the image before the partition")?;
        let data = images.data();
        let px = data.pixels();
        let (tr, n) = (&mut self.inner, &net.inner);
        run(py, || with_pixels!(px, s => tr.prime(n, s)))
    }

    /// No derivative pair between the last image fed and the next.
    fn break_sequence(&mut self) {
        self.inner.break_sequence();
    }

    /// Feeds images (N, H, W[, C]) in sequence order.
    fn feed(&mut self, py: Python<'_>, net: &mut PyNetwork, images: &Bound<'_, PyAny>) -> PyResult<()> {
        let images = self.images(images, net, "training images")?;
        let n = images.shape[0];
        let data = images.data();
        let px = data.pixels();
        let (tr, nt) = (&mut self.inner, &mut net.inner);
        run(py, || with_pixels!(px, s => tr.feed(nt, s, n)))
    }

    /// The statistics of the layer's nodes in training (one per node).
    fn statistics(&self, net: &PyNetwork) -> PyResult<Vec<PyStatistics>> {
        let st = guard(|| self.inner.statistics(&net.inner))?;
        Ok(st.into_iter().map(|inner| PyStatistics { inner }).collect())
    }

    /// Adds the merged statistics of `n_images` images (one per node).
    fn merge_statistics(
        &mut self,
        net: &mut PyNetwork,
        stats: Vec<PyRef<'_, PyStatistics>>,
        n_images: usize,
    ) -> PyResult<()> {
        let accs: Vec<Accumulator> = stats.iter().map(|s| s.inner.clone()).collect();
        let (tr, nt) = (&mut self.inner, &mut net.inner);
        guard(|| tr.merge_statistics(nt, &accs, n_images))
    }

    /// Solves the stage trained in this pass; True when the layer is done.
    fn end_pass(&mut self, py: Python<'_>, net: &mut PyNetwork) -> PyResult<bool> {
        let (tr, nt) = (&mut self.inner, &mut net.inner);
        run(py, || tr.end_pass(nt))
    }

    fn __repr__(&self) -> String {
        format!(
            "LayerTrainer(layer={}, pass={}, images_seen={})",
            self.inner.layer(),
            self.inner.pass(),
            self.inner.images_seen()
        )
    }
}
