//! `_core.Network`: the receptive-field network, its inference, and the
//! training entry point (`fit`) that feeds the core's training loop from
//! Python iterables.

use crate::arrays::{out2, vec1, Images};
use crate::error::{guard, run, Raised};
use crate::state::{get, get_bool_or, node_state_from_dict, node_state_to_dict};
use numpy::IntoPyArray;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use sfa_core::{
    fit, transform_rotations, with_pixels, Batch, BatchSource, CachePolicy, FitOptions, LayerSpec, LoopClosures,
    Network, NetworkSpec, Pixel, Progress, ProgressEvent, Rotation, SpatialPairs, TrainingPath,
};
use std::sync::Arc;

/// Borrows an image batch and checks its height and channel count against
/// the network's input (the width is the panorama period, free).
pub(crate) fn network_images<'py>(obj: &Bound<'py, PyAny>, net: &Network, what: &str) -> PyResult<Images<'py>> {
    let images = Images::borrow(obj)?;
    let [_, h, _, c] = images.shape;
    let (eh, _, ec) = net.input_shape();
    if (h, c) != (eh, ec) {
        return Err(PyValueError::new_err(format!(
            "{what} are {h} px high with {c} channel(s), the network takes {eh} with {ec}"
        )));
    }
    Ok(images)
}

/// Loop closures as Python passes them: the current images' indices, the
/// closures' weights and the aligned partner images `(M, H, W[, C])`, one
/// per closure (converted to f64 here, after a memory check).
pub(crate) fn loop_closures(
    net: &Network,
    period: usize,
    current: Vec<usize>,
    weights: Vec<f64>,
    partners: &Bound<'_, PyAny>,
) -> PyResult<LoopClosures> {
    let images = network_images(partners, net, "loop-closure partner images")?;
    let [m, _, w, _] = images.shape;
    if m != current.len() {
        return Err(PyValueError::new_err(format!("{} loop closures but {m} partner images", current.len())));
    }
    if w != period {
        return Err(PyValueError::new_err(format!(
            "loop-closure partner images are {w} px wide, the training panoramas {period}"
        )));
    }
    let bytes = images.shape.iter().product::<usize>().checked_mul(8);
    guard(|| sfa_core::memory::check(|| format!("{m} loop-closure partner images"), bytes))?;
    let data = images.data();
    let values: Vec<f64> = with_pixels!(data.pixels(), px => px.iter().map(|v| v.to_f64()).collect());
    guard(|| LoopClosures::new(current, weights, values))
}

/// Spatial pairs as Python passes them: (a, b, weights, shifts or None).
type PairsArg = (Vec<usize>, Vec<usize>, Vec<f64>, Option<Vec<usize>>);

pub(crate) fn zip_pairs(a: Vec<usize>, b: Vec<usize>, w: Vec<f64>) -> PyResult<Vec<(usize, usize, f64)>> {
    if a.len() != b.len() || a.len() != w.len() {
        return Err(PyValueError::new_err(format!(
            "pairs: a, b and weights must have the same length, got {}, {} and {}",
            a.len(),
            b.len(),
            w.len()
        )));
    }
    Ok(a.into_iter().zip(b).zip(w).map(|((a, b), w)| (a, b, w)).collect())
}

/// Training images from Python: `batches()` gives a fresh iterable of
/// batches per pass, `gather(ids)` chosen images. Each batch is fetched
/// with the GIL held, then borrowed in place while the core works on it
/// with the GIL released.
struct PySource {
    batches: Py<PyAny>,
    gather: Option<Py<PyAny>>,
    total: Option<usize>,
    /// (height, period, channels) every batch must have.
    shape: (usize, usize, usize),
    raised: Raised,
}

/// Hands one Python batch to `f` (GIL released); the outer error is
/// Python's, the inner the core's.
fn feed_batch(
    py: Python<'_>,
    obj: &Bound<'_, PyAny>,
    (h, w, c): (usize, usize, usize),
    f: &mut (dyn FnMut(Batch<'_>) -> sfa_core::Result<()> + Send),
) -> PyResult<sfa_core::Result<()>> {
    let images = Images::borrow(obj)?;
    let [n, bh, bw, bc] = images.shape;
    if (bh, bc) != (h, c) {
        return Err(PyValueError::new_err(format!(
            "training images are {bh} px high with {bc} channel(s), the network takes {h} with {c}"
        )));
    }
    if bw != w {
        return Err(PyValueError::new_err(format!("all images must be {w} px wide, got {bw}")));
    }
    let data = images.data();
    let pixels = data.pixels();
    Ok(py.detach(|| f(Batch { pixels, n })))
}

impl BatchSource for PySource {
    fn len_hint(&self) -> Option<usize> {
        self.total
    }

    fn for_each_batch(
        &mut self,
        f: &mut (dyn FnMut(Batch<'_>) -> sfa_core::Result<()> + Send),
    ) -> sfa_core::Result<()> {
        let (batches, shape) = (&self.batches, self.shape);
        let r = Python::attach(|py| -> PyResult<sfa_core::Result<()>> {
            for item in batches.bind(py).call0()?.try_iter()? {
                if let Err(e) = feed_batch(py, &item?, shape, f)? {
                    return Ok(Err(e));
                }
            }
            Ok(Ok(()))
        });
        self.raised.keep(r)
    }

    fn gather(
        &mut self,
        ids: &[usize],
        f: &mut (dyn FnMut(Batch<'_>) -> sfa_core::Result<()> + Send),
    ) -> sfa_core::Result<()> {
        let (gather, shape) = (&self.gather, self.shape);
        let r = Python::attach(|py| -> PyResult<sfa_core::Result<()>> {
            let gather = gather.as_ref().ok_or_else(|| PyValueError::new_err("spatial pairs need gather(ids)"))?;
            let batch = gather.bind(py).call1((ids.to_vec(),))?;
            feed_batch(py, &batch, shape, f)
        });
        self.raised.keep(r)
    }
}

pub(crate) fn spec_from_dict(d: &Bound<'_, PyDict>) -> PyResult<NetworkSpec> {
    let list = d
        .get_item("layers")?
        .ok_or_else(|| PyValueError::new_err("network spec: missing 'layers'"))?
        .cast_into::<PyList>()
        .map_err(|_| PyValueError::new_err("network spec: 'layers' must be a list"))?;
    let mut layers = Vec::new();
    for item in list.iter() {
        let l =
            item.cast_into::<PyDict>().map_err(|_| PyValueError::new_err("network spec: each layer must be a dict"))?;
        layers.push(LayerSpec {
            rf: get(&l, "rf")?,
            stride: get(&l, "stride")?,
            n_out: get(&l, "n_out")?,
            reduce_to: get(&l, "reduce_to")?,
            degree: get(&l, "degree")?,
        });
    }
    Ok(NetworkSpec {
        height: get(d, "height")?,
        width: get(d, "width")?,
        channels: get(d, "channels")?,
        layers,
        weight_sharing: get(d, "weight_sharing")?,
        tol: get(d, "tol")?,
        mixed_precision: get_bool_or(d, "mixed_precision", false)?,
    })
}

/// The receptive-field SFA network (see sfa_core::network); wrapped by
/// sfanav.Network.
#[pyclass(name = "Network", module = "sfanav._core")]
#[derive(Clone)]
pub(crate) struct PyNetwork {
    pub(crate) inner: Network,
}

#[pymethods]
impl PyNetwork {
    #[new]
    fn new(spec: &Bound<'_, PyDict>) -> PyResult<Self> {
        let spec = spec_from_dict(spec)?;
        Ok(PyNetwork { inner: guard(|| Network::new(spec))? })
    }

    fn geometry<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let out = PyList::empty(py);
        for (l, g) in self.inner.geometry().iter().enumerate() {
            let d = PyDict::new(py);
            d.set_item("input", (g.in_w, g.in_h, g.in_c))?;
            d.set_item("rf", (g.rf_w, g.rf_h))?;
            d.set_item("stride", (g.stride_w, g.stride_h))?;
            d.set_item("grid", (g.n_w, g.n_h))?;
            d.set_item("in_dim", g.in_dim)?;
            d.set_item("reduce_to", g.reduce_to)?;
            d.set_item("degree", g.degree)?;
            d.set_item("n_out", g.n_out)?;
            d.set_item("n_nodes", self.inner.nodes(l).len())?;
            let nodes = self.inner.nodes(l);
            let rd: Vec<Vec<usize>> = nodes.iter().map(|n| n.rank_deficits()).collect();
            d.set_item("rank_deficits", rd)?;
            d.set_item(
                "reduced_to",
                nodes.iter().map(|n| n.stage_outputs().first().copied().unwrap_or(0)).collect::<Vec<_>>(),
            )?;
            out.append(d)?;
        }
        Ok(out)
    }

    #[getter]
    fn n_layers(&self) -> usize {
        self.inner.n_layers()
    }
    #[getter]
    fn n_trained(&self) -> usize {
        self.inner.n_trained()
    }
    #[getter]
    fn n_outputs(&self) -> usize {
        self.inner.n_outputs()
    }
    #[getter]
    fn input_shape(&self) -> (usize, usize, usize) {
        self.inner.input_shape()
    }

    #[getter]
    fn delta_values<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let top = self.inner.n_layers() - 1;
        Ok(vec1(py, guard(|| self.inner.nodes(top)[0].delta_values().map(<[f64]>::to_vec))?))
    }

    /// transform(images) -> (N, n_outputs): images (N, H, W[, C]) of the
    /// network's input size, uint8, float32 or float64 (read in place).
    fn transform<'py>(&self, py: Python<'py>, images: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        let images = Images::borrow(images)?;
        let [n, h, w, c] = images.shape;
        let (eh, ew, ec) = self.inner.input_shape();
        if (h, w, c) != (eh, ew, ec) {
            return Err(PyValueError::new_err(format!(
                "images are {w}x{h} with {c} channel(s), the network takes {ew}x{eh} with {ec}"
            )));
        }
        let net = &self.inner;
        let data = images.data();
        let px = data.pixels();
        let y = run(py, || with_pixels!(px, s => net.transform(s, n)))?;
        out2(py, y, n, net.n_outputs())
    }

    /// transform_rotations(images, step) -> (N, K, n_outputs)
    fn transform_rotations<'py>(
        &self,
        py: Python<'py>,
        images: &Bound<'py, PyAny>,
        step: usize,
    ) -> PyResult<Bound<'py, PyAny>> {
        let images = network_images(images, &self.inner, "images")?;
        let [n, _, w, _] = images.shape;
        let rot = Rotation { step, period: w };
        let net = &self.inner;
        let data = images.data();
        let px = data.pixels();
        let y = run(py, || with_pixels!(px, s => transform_rotations(net, rot, s, n)))?;
        let (k, m) = (rot.n_views(), net.n_outputs());
        let a = numpy::ndarray::Array3::from_shape_vec((n, k, m), y)
            .map_err(|e| PyRuntimeError::new_err(format!("internal shape error: {e}")))?;
        Ok(a.into_pyarray(py).into_any())
    }

    /// fit(batches, step, period, ...) -> cache plan: trains every layer
    /// (sfa_core::fit). `batches()` returns a fresh iterable of image
    /// batches (N, H, period[, C]) each time it is called; `gather(ids)`
    /// returns the images `ids` as one batch (spatial pairs only);
    /// `progress(event, layer, n_layers, pass, n_passes, done, total,
    /// cached)` hears of every pass ("start", "advance", "finish"; layer
    /// and pass 0-based). `cache`: True, False or None (auto: up to
    /// `cache_limit` bytes). `pairs`: (a, b, weights, shifts or None),
    /// applied to the 1-based `pair_layers` (default all), gathered
    /// `pair_chunk` pairs at a time. A Python exception raised by a
    /// callback comes out of fit unchanged. Returns [(layer (1-based),
    /// kept, bytes)] for every layer above the first.
    #[pyo3(signature = (batches, step, period, *, fast=true, cache=None, cache_limit=1e9, transition_weight=1.0,
                        pairs=None, pair_layers=None, gather=None, pair_chunk=16, closures=None, total=None,
                        progress=None))]
    #[allow(clippy::too_many_arguments)]
    fn fit(
        &mut self,
        py: Python<'_>,
        batches: Py<PyAny>,
        step: usize,
        period: usize,
        fast: bool,
        cache: Option<bool>,
        cache_limit: f64,
        transition_weight: f64,
        pairs: Option<PairsArg>,
        pair_layers: Option<Vec<usize>>,
        gather: Option<Py<PyAny>>,
        pair_chunk: usize,
        closures: Option<(Vec<usize>, Vec<f64>, Bound<'_, PyAny>)>,
        total: Option<usize>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Vec<(usize, bool, usize)>> {
        let n_layers = self.inner.n_layers();
        let mut opts = FitOptions::new(Rotation { step, period });
        opts.path = if fast { TrainingPath::Fast } else { TrainingPath::Naive };
        opts.cache = match cache {
            Some(true) => CachePolicy::Always,
            Some(false) => CachePolicy::Never,
            None => CachePolicy::Auto(cache_limit),
        };
        opts.transition_weight = transition_weight;
        if let Some((a, b, w, shifts)) = pairs {
            let layers = match pair_layers {
                None => (0..n_layers).collect(),
                Some(ls) => {
                    if let Some(&l) = ls.iter().find(|&&l| l == 0 || l > n_layers) {
                        return Err(PyValueError::new_err(format!(
                            "pair_layers must name layers 1..{n_layers}, got {l}"
                        )));
                    }
                    ls.into_iter().map(|l| l - 1).collect()
                }
            };
            if gather.is_none() {
                return Err(PyValueError::new_err("spatial pairs need gather(ids)"));
            }
            opts.pairs = Some(SpatialPairs { pairs: zip_pairs(a, b, w)?, shifts, layers, chunk: pair_chunk });
        }
        if let Some((current, weights, partners)) = closures {
            opts.loop_closures = Some(Arc::new(loop_closures(&self.inner, period, current, weights, &partners)?));
        }
        let (h, _, c) = self.inner.input_shape();
        let mut source = PySource { batches, gather, total, shape: (h, period, c), raised: Raised::default() };
        let mut raised = Raised::default();
        let mut report = |p: &Progress| -> sfa_core::Result<()> {
            let Some(cb) = &progress else { return Ok(()) };
            let event = match p.event {
                ProgressEvent::Start => "start",
                ProgressEvent::Advance => "advance",
                ProgressEvent::Finish => "finish",
            };
            let r = Python::attach(|py| {
                cb.bind(py)
                    .call1((event, p.layer, p.n_layers, p.pass, p.n_passes, p.done, p.total, p.cached))
                    .map(|_| Ok(()))
            });
            raised.keep(r)
        };
        let net = &mut self.inner;
        let out = run(py, || fit(net, &mut source, &opts, &mut report));
        if let Some(e) = source.raised.take().or_else(|| raised.take()) {
            return Err(e);
        }
        let plan = out?.cache_plan;
        Ok(plan.into_iter().map(|d| (d.layer + 1, d.kept, d.bytes)).collect())
    }

    #[pyo3(signature = (with_statistics=false))]
    fn node_states<'py>(&self, py: Python<'py>, with_statistics: bool) -> PyResult<Bound<'py, PyList>> {
        let out = PyList::empty(py);
        for layer in self.inner.node_states(with_statistics) {
            let l = PyList::empty(py);
            for st in &layer {
                l.append(node_state_to_dict(py, st)?)?;
            }
            out.append(l)?;
        }
        Ok(out)
    }

    #[staticmethod]
    fn from_states(spec: &Bound<'_, PyDict>, states: &Bound<'_, PyList>, trained: usize) -> PyResult<Self> {
        let spec = spec_from_dict(spec)?;
        let mut all = Vec::new();
        for layer in states.iter() {
            let layer = layer
                .cast_into::<PyList>()
                .map_err(|_| PyValueError::new_err("invalid model state: node states must be lists"))?;
            let mut v = Vec::new();
            for st in layer.iter() {
                let st = st
                    .cast_into::<PyDict>()
                    .map_err(|_| PyValueError::new_err("invalid model state: a node state must be a dict"))?;
                v.push(node_state_from_dict(&st)?);
            }
            all.push(v);
        }
        Ok(PyNetwork { inner: guard(|| Network::from_states(spec, &all, trained))? })
    }

    fn copy(&self) -> Self {
        self.clone()
    }
}
