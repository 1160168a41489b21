//! Thin pyo3 bindings of `sfa-core`, importable as `sfanav._core`.
//!
//! All glue lives in this file: array conversion, error mapping, GIL release
//! and panic containment. Numerics live in `sfa-core`.

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1};
use pyo3::exceptions::{PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use sfa_core::{
    Accumulator, AccumulatorState, LayerSpec, LayerTrainer, Network, NetworkSpec, NodeConfig,
    NodeState, Path, Rotation, SfaError, SfaNode, SolutionState, StageState, View,
};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::{Arc, Mutex};

// ---------------------------------------------------------------- errors

fn to_py(e: SfaError) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// Runs `f` with the GIL released, inside the configured thread pool, and
/// turns a Rust panic into a Python RuntimeError instead of letting it cross.
fn run<R: Send>(py: Python<'_>, f: impl FnOnce() -> sfa_core::Result<R> + Send) -> PyResult<R> {
    let pool = POOL.lock().map(|p| p.clone()).unwrap_or(None);
    let out = py.detach(move || {
        catch_unwind(AssertUnwindSafe(|| match pool {
            Some(p) => p.install(f),
            None => f(),
        }))
    });
    match out {
        Ok(r) => r.map_err(to_py),
        Err(p) => {
            let msg = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown panic".into());
            Err(PyRuntimeError::new_err(format!(
                "internal error in sfanav's Rust core (please report): {msg}"
            )))
        }
    }
}

// ---------------------------------------------------------------- threads

static POOL: Mutex<Option<Arc<rayon::ThreadPool>>> = Mutex::new(None);

/// Sets the number of worker threads used by sfanav's Rust core (0 = one per
/// core, the default).
#[pyfunction]
fn set_num_threads(n: usize) -> PyResult<()> {
    let mut g = POOL
        .lock()
        .map_err(|_| PyRuntimeError::new_err("thread pool lock poisoned"))?;
    if n == 0 {
        *g = None;
        return Ok(());
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build()
        .map_err(|e| PyRuntimeError::new_err(format!("cannot build a thread pool: {e}")))?;
    *g = Some(Arc::new(pool));
    Ok(())
}

/// Number of worker threads the core uses.
#[pyfunction]
fn get_num_threads() -> usize {
    match POOL.lock().ok().and_then(|p| p.clone()) {
        Some(p) => p.current_num_threads(),
        None => rayon::current_num_threads(),
    }
}

// ---------------------------------------------------------------- arrays

/// A borrowed 2-D float array of either precision.
enum Arr<'py> {
    F32(numpy::PyReadonlyArray2<'py, f32>),
    F64(numpy::PyReadonlyArray2<'py, f64>),
}

fn arr2<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<Arr<'py>> {
    if let Ok(a) = obj.cast::<PyArray2<f64>>() {
        return Ok(Arr::F64(a.try_readonly().map_err(|e| PyValueError::new_err(format!("{name}: {e}")))?));
    }
    if let Ok(a) = obj.cast::<PyArray2<f32>>() {
        return Ok(Arr::F32(a.try_readonly().map_err(|e| PyValueError::new_err(format!("{name}: {e}")))?));
    }
    Err(PyTypeError::new_err(format!(
        "{name} must be a 2-D float32 or float64 NumPy array"
    )))
}

fn view_of<'a, T: numpy::Element + sfa_core::Sample>(a: &'a numpy::PyReadonlyArray2<'_, T>) -> View<'a, T> {
    let v = a.as_array();
    let (n, d) = v.dim();
    let s = v.strides();
    // SAFETY: the readonly borrow keeps the array alive and unaliased by
    // Rust writers for the view's lifetime; strides are in elements.
    unsafe { View::from_raw_parts(v.as_ptr(), n, d, s[0], s[1]) }
}

fn out2<'py, T: numpy::Element>(py: Python<'py>, v: Vec<T>, n: usize, m: usize) -> PyResult<Bound<'py, PyAny>> {
    let a = Array2::from_shape_vec((n, m), v)
        .map_err(|e| PyRuntimeError::new_err(format!("internal shape error: {e}")))?;
    Ok(a.into_pyarray(py).into_any())
}

fn mat_to_py<'py>(py: Python<'py>, m: faer::Mat<f64>) -> PyResult<Bound<'py, PyAny>> {
    let (r, c) = (m.nrows(), m.ncols());
    let v: Vec<f64> = (0..r).flat_map(|i| (0..c).map(move |j| (i, j))).map(|(i, j)| m[(i, j)]).collect();
    out2(py, v, r, c)
}


fn vec1<'py>(py: Python<'py>, v: Vec<f64>) -> Bound<'py, PyAny> {
    PyArray1::from_vec(py, v).into_any()
}

fn opt_weights(w: Option<PyReadonlyArray1<'_, f64>>) -> PyResult<Option<Vec<f64>>> {
    match w {
        None => Ok(None),
        Some(w) => Ok(Some(w.as_array().iter().copied().collect())),
    }
}

// ---------------------------------------------------------------- functions

/// expand(x, degree) -> ndarray: all monomials of degree 1..=degree.
#[pyfunction]
fn expand<'py>(py: Python<'py>, x: &Bound<'py, PyAny>, degree: usize) -> PyResult<Bound<'py, PyAny>> {
    let a = arr2(x, "X")?;
    match &a {
        Arr::F64(a) => {
            let v = view_of(a);
            let e = sfa_core::Expansion::new(v.ncols(), degree).map_err(to_py)?;
            let od = e.out_dim();
            let n = v.nrows();
            let out = run(py, || e.expand(v))?;
            out2(py, out, n, od)
        }
        Arr::F32(a) => {
            let v = view_of(a);
            let e = sfa_core::Expansion::new(v.ncols(), degree).map_err(to_py)?;
            let od = e.out_dim();
            let n = v.nrows();
            let out = run(py, || e.expand(v))?;
            out2(py, out, n, od)
        }
    }
}

/// expanded_dim(n_features, degree) -> int: C(n + d, d) - 1.
#[pyfunction]
fn expanded_dim(n_features: usize, degree: usize) -> PyResult<usize> {
    sfa_core::expanded_dim(n_features, degree).map_err(to_py)
}

/// solve_generalized(a, b, n, tol) -> (values, vectors, rank, dropped)
#[pyfunction]
fn solve_generalized<'py>(
    py: Python<'py>,
    a: numpy::PyReadonlyArray2<'py, f64>,
    b: numpy::PyReadonlyArray2<'py, f64>,
    n: usize,
    tol: f64,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>, usize, Bound<'py, PyAny>)> {
    let to_mat = |x: &numpy::PyReadonlyArray2<'py, f64>| {
        let v = x.as_array();
        faer::Mat::from_fn(v.nrows(), v.ncols(), |i, j| v[(i, j)])
    };
    let (am, bm) = (to_mat(&a), to_mat(&b));
    let g = run(py, || sfa_core::solve(am.as_ref(), bm.as_ref(), n, tol))?;
    Ok((vec1(py, g.values), mat_to_py(py, g.vectors)?, g.rank, vec1(py, g.dropped)))
}

// ---------------------------------------------------------------- Statistics

/// Streaming SFA statistics (see sfa_core::stats).
#[pyclass(name = "Statistics", module = "sfanav._core")]
#[derive(Clone)]
struct PyStatistics {
    inner: Accumulator,
}

#[pymethods]
impl PyStatistics {
    #[new]
    fn new(dim: usize) -> PyResult<Self> {
        Ok(PyStatistics { inner: Accumulator::new(dim).map_err(to_py)? })
    }

    #[pyo3(signature = (x, new_sequence=false))]
    fn update(&mut self, py: Python<'_>, x: &Bound<'_, PyAny>, new_sequence: bool) -> PyResult<()> {
        let acc = &mut self.inner;
        match arr2(x, "X")? {
            Arr::F64(a) => { let v = view_of(&a); run(py, || acc.update(v, new_sequence)) }
            Arr::F32(a) => { let v = view_of(&a); run(py, || acc.update(v, new_sequence)) }
        }
    }

    #[pyo3(signature = (x, weights=None))]
    fn add_samples(&mut self, py: Python<'_>, x: &Bound<'_, PyAny>, weights: Option<PyReadonlyArray1<'_, f64>>) -> PyResult<()> {
        let w = opt_weights(weights)?;
        let acc = &mut self.inner;
        match arr2(x, "X")? {
            Arr::F64(a) => { let v = view_of(&a); run(py, || acc.add_samples(v, w.as_deref())) }
            Arr::F32(a) => { let v = view_of(&a); run(py, || acc.add_samples(v, w.as_deref())) }
        }
    }

    #[pyo3(signature = (a, b, weights=None))]
    fn add_pairs(&mut self, py: Python<'_>, a: &Bound<'_, PyAny>, b: &Bound<'_, PyAny>, weights: Option<PyReadonlyArray1<'_, f64>>) -> PyResult<()> {
        let w = opt_weights(weights)?;
        let acc = &mut self.inner;
        match (arr2(a, "a")?, arr2(b, "b")?) {
            (Arr::F64(a), Arr::F64(b)) => { let (va, vb) = (view_of(&a), view_of(&b)); run(py, || acc.add_pairs(va, vb, w.as_deref())) }
            (Arr::F32(a), Arr::F32(b)) => { let (va, vb) = (view_of(&a), view_of(&b)); run(py, || acc.add_pairs(va, vb, w.as_deref())) }
            _ => Err(PyTypeError::new_err("a and b must have the same dtype")),
        }
    }

    fn break_sequence(&mut self) {
        self.inner.break_sequence();
    }

    fn merge(&mut self, other: &PyStatistics) -> PyResult<()> {
        self.inner.merge(&other.inner).map_err(to_py)
    }

    fn merge_continuing(&mut self, other: &PyStatistics) -> PyResult<()> {
        self.inner.merge_continuing(&other.inner).map_err(to_py)
    }

    fn copy(&self) -> Self {
        self.clone()
    }

    fn mean<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(vec1(py, self.inner.mean().map_err(to_py)?))
    }

    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        mat_to_py(py, self.inner.covariance().map_err(to_py)?)
    }

    fn derivative_covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        mat_to_py(py, self.inner.derivative_covariance().map_err(to_py)?)
    }

    fn derivative_mean<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(vec1(py, self.inner.derivative_mean().map_err(to_py)?))
    }

    #[getter]
    fn dim(&self) -> usize { self.inner.dim() }
    #[getter]
    fn n_samples(&self) -> u64 { self.inner.n_samples() }
    #[getter]
    fn n_pairs(&self) -> u64 { self.inner.n_pairs() }
    #[getter]
    fn weight_sum(&self) -> f64 { self.inner.weight_sum() }
    #[getter]
    fn pair_weight_sum(&self) -> f64 { self.inner.pair_weight_sum() }

    fn get_state<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        acc_state_to_dict(py, &self.inner.state())
    }

    #[staticmethod]
    fn from_state(state: &Bound<'_, PyDict>) -> PyResult<Self> {
        let s = acc_state_from_dict(state)?;
        Ok(PyStatistics { inner: Accumulator::from_state(&s).map_err(to_py)? })
    }

    fn __repr__(&self) -> String {
        format!(
            "Statistics(dim={}, n_samples={}, n_pairs={})",
            self.inner.dim(), self.inner.n_samples(), self.inner.n_pairs()
        )
    }
}

// ---------------------------------------------------------------- state <-> dict

fn get<'py, T: for<'a> FromPyObject<'a, 'py>>(d: &Bound<'py, PyDict>, key: &str) -> PyResult<T>
where
    for<'a> <T as FromPyObject<'a, 'py>>::Error: Into<PyErr>,
{
    match d.get_item(key)? {
        Some(v) => v.extract::<T>().map_err(|e| {
            let e: PyErr = e.into();
            PyValueError::new_err(format!("invalid model state: field '{key}': {e}"))
        }),
        None => Err(PyValueError::new_err(format!("invalid model state: missing field '{key}'"))),
    }
}

fn get_bool_or(d: &Bound<'_, PyDict>, key: &str, default: bool) -> PyResult<bool> {
    match d.get_item(key)? {
        Some(v) => v
            .extract::<bool>()
            .map_err(|_| PyValueError::new_err(format!("invalid model state: field '{key}' must be a bool"))),
        None => Ok(default),
    }
}

fn get_vec(d: &Bound<'_, PyDict>, key: &str) -> PyResult<Vec<f64>> {
    match d.get_item(key)? {
        Some(v) => {
            let a = v.cast::<PyArray1<f64>>().map_err(|_| {
                PyValueError::new_err(format!("invalid model state: field '{key}' must be a 1-D float64 array"))
            })?;
            Ok(a.readonly().as_array().iter().copied().collect())
        }
        None => Err(PyValueError::new_err(format!("invalid model state: missing field '{key}'"))),
    }
}

fn acc_state_to_dict<'py>(py: Python<'py>, s: &AccumulatorState) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("dim", s.dim)?;
    d.set_item("shift", vec1(py, s.shift.clone()))?;
    d.set_item("n_samples", s.n_samples)?;
    d.set_item("weight_sum", s.weight_sum)?;
    d.set_item("sum", vec1(py, s.sum.clone()))?;
    d.set_item("sxx", vec1(py, s.sxx.clone()))?;
    d.set_item("n_pairs", s.n_pairs)?;
    d.set_item("pair_weight_sum", s.pair_weight_sum)?;
    d.set_item("sum_d", vec1(py, s.sum_d.clone()))?;
    d.set_item("sdd", vec1(py, s.sdd.clone()))?;
    d.set_item("first", vec1(py, s.first.clone()))?;
    d.set_item("last", vec1(py, s.last.clone()))?;
    d.set_item("mixed", s.mixed)?;
    Ok(d)
}

fn acc_state_from_dict(d: &Bound<'_, PyDict>) -> PyResult<AccumulatorState> {
    Ok(AccumulatorState {
        dim: get(d, "dim")?,
        shift: get_vec(d, "shift")?,
        n_samples: get(d, "n_samples")?,
        weight_sum: get(d, "weight_sum")?,
        sum: get_vec(d, "sum")?,
        sxx: get_vec(d, "sxx")?,
        n_pairs: get(d, "n_pairs")?,
        pair_weight_sum: get(d, "pair_weight_sum")?,
        sum_d: get_vec(d, "sum_d")?,
        sdd: get_vec(d, "sdd")?,
        first: get_vec(d, "first")?,
        last: get_vec(d, "last")?,
        mixed: get_bool_or(d, "mixed", false)?,
    })
}

fn node_state_to_dict<'py>(py: Python<'py>, s: &NodeState) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("n_components", s.config.n_components)?;
    d.set_item("degree", s.config.degree)?;
    d.set_item("reduce_to", s.config.reduce_to)?;
    d.set_item("tol", s.config.tol)?;
    d.set_item("mixed_precision", s.config.mixed_precision)?;
    d.set_item("n_features", s.n_features)?;
    d.set_item("training_stage", s.training_stage)?;
    let stages = PyList::empty(py);
    for st in &s.stages {
        let sd = PyDict::new(py);
        sd.set_item("degree", st.degree)?;
        sd.set_item("n_out", st.n_out)?;
        sd.set_item("input_dim", st.input_dim)?;
        match &st.solution {
            Some(sol) => {
                let so = PyDict::new(py);
                so.set_item("mean", vec1(py, sol.mean.clone()))?;
                so.set_item("projection", vec1(py, sol.projection.clone()))?;
                so.set_item("n_out", sol.n_out)?;
                so.set_item("delta", vec1(py, sol.delta.clone()))?;
                so.set_item("rank", sol.rank)?;
                so.set_item("dropped", vec1(py, sol.dropped.clone()))?;
                sd.set_item("solution", so)?;
            }
            None => sd.set_item("solution", py.None())?,
        }
        match &st.stats {
            Some(a) => sd.set_item("stats", acc_state_to_dict(py, a)?)?,
            None => sd.set_item("stats", py.None())?,
        }
        stages.append(sd)?;
    }
    d.set_item("stages", stages)?;
    Ok(d)
}

fn opt_dict<'py>(d: &Bound<'py, PyDict>, key: &str) -> PyResult<Option<Bound<'py, PyDict>>> {
    match d.get_item(key)? {
        None => Ok(None),
        Some(v) if v.is_none() => Ok(None),
        Some(v) => Ok(Some(v.cast_into::<PyDict>().map_err(|_| {
            PyValueError::new_err(format!("invalid model state: field '{key}' must be a dict or None"))
        })?)),
    }
}

fn node_state_from_dict(d: &Bound<'_, PyDict>) -> PyResult<NodeState> {
    let config = NodeConfig {
        n_components: get(d, "n_components")?,
        degree: get(d, "degree")?,
        reduce_to: get(d, "reduce_to")?,
        tol: get(d, "tol")?,
        mixed_precision: get_bool_or(d, "mixed_precision", false)?,
    };
    let list = d
        .get_item("stages")?
        .ok_or_else(|| PyValueError::new_err("invalid model state: missing field 'stages'"))?;
    let list = list
        .cast_into::<PyList>()
        .map_err(|_| PyValueError::new_err("invalid model state: 'stages' must be a list"))?;
    let mut stages = Vec::new();
    for item in list.iter() {
        let sd = item
            .cast_into::<PyDict>()
            .map_err(|_| PyValueError::new_err("invalid model state: a stage must be a dict"))?;
        let solution = match opt_dict(&sd, "solution")? {
            Some(so) => Some(SolutionState {
                mean: get_vec(&so, "mean")?,
                projection: get_vec(&so, "projection")?,
                n_out: get(&so, "n_out")?,
                delta: get_vec(&so, "delta")?,
                rank: get(&so, "rank")?,
                dropped: get_vec(&so, "dropped")?,
            }),
            None => None,
        };
        let stats = match opt_dict(&sd, "stats")? {
            Some(a) => Some(acc_state_from_dict(&a)?),
            None => None,
        };
        stages.push(StageState {
            degree: get(&sd, "degree")?,
            n_out: get(&sd, "n_out")?,
            input_dim: get(&sd, "input_dim")?,
            solution,
            stats,
        });
    }
    Ok(NodeState {
        config,
        n_features: get(d, "n_features")?,
        training_stage: get(d, "training_stage")?,
        stages,
    })
}

// ---------------------------------------------------------------- SfaNode

/// The SFA node (see sfa_core::node); wrapped by sfanav.SFA.
#[pyclass(name = "SfaNode", module = "sfanav._core")]
#[derive(Clone)]
struct PySfaNode {
    inner: SfaNode,
}

#[pymethods]
impl PySfaNode {
    #[new]
    #[pyo3(signature = (n_components, degree=1, reduce_to=None, tol=sfa_core::DEFAULT_TOL, mixed_precision=false))]
    fn new(n_components: usize, degree: usize, reduce_to: Option<usize>, tol: f64, mixed_precision: bool) -> PyResult<Self> {
        let inner = SfaNode::new(NodeConfig { n_components, degree, reduce_to, tol, mixed_precision }).map_err(to_py)?;
        Ok(PySfaNode { inner })
    }

    #[pyo3(signature = (x, new_sequence=false))]
    fn partial_fit(&mut self, py: Python<'_>, x: &Bound<'_, PyAny>, new_sequence: bool) -> PyResult<()> {
        let node = &mut self.inner;
        match arr2(x, "X")? {
            Arr::F64(a) => { let v = view_of(&a); run(py, || node.partial_fit(v, new_sequence)) }
            Arr::F32(a) => { let v = view_of(&a); run(py, || node.partial_fit(v, new_sequence)) }
        }
    }

    fn finish_stage(&mut self, py: Python<'_>) -> PyResult<()> {
        let node = &mut self.inner;
        run(py, || node.finish_stage())
    }

    fn ensure_solved(&mut self, py: Python<'_>) -> PyResult<()> {
        let node = &mut self.inner;
        run(py, || node.ensure_solved())
    }

    fn reset(&mut self) {
        self.inner.reset();
    }

    fn transform<'py>(&self, py: Python<'py>, x: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        let node = &self.inner;
        let m = node.n_outputs();
        match arr2(x, "X")? {
            Arr::F64(a) => { let v = view_of(&a); let n = v.nrows(); let y = run(py, || node.transform(v))?; out2(py, y, n, m) }
            Arr::F32(a) => { let v = view_of(&a); let n = v.nrows(); let y = run(py, || node.transform(v))?; out2(py, y, n, m) }
        }
    }

    #[getter]
    fn delta_values<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(vec1(py, self.inner.delta_values().map_err(to_py)?.to_vec()))
    }

    #[getter]
    fn n_features(&self) -> Option<usize> { self.inner.n_features() }
    #[getter]
    fn n_stages(&self) -> usize { self.inner.n_stages() }
    #[getter]
    fn training_stage(&self) -> usize { self.inner.training_stage() }
    #[getter]
    fn is_solved(&self) -> bool { self.inner.is_solved() }
    #[getter]
    fn rank_deficits(&self) -> Vec<usize> { self.inner.rank_deficits() }
    #[getter]
    fn stage_outputs(&self) -> Vec<usize> { self.inner.stage_outputs() }

    fn statistics(&self) -> Option<PyStatistics> {
        self.inner.statistics().map(|a| PyStatistics { inner: a.clone() })
    }

    #[pyo3(signature = (with_statistics=true))]
    fn get_state<'py>(&self, py: Python<'py>, with_statistics: bool) -> PyResult<Bound<'py, PyDict>> {
        node_state_to_dict(py, &self.inner.state(with_statistics))
    }

    #[staticmethod]
    fn from_state(state: &Bound<'_, PyDict>) -> PyResult<Self> {
        let s = node_state_from_dict(state)?;
        Ok(PySfaNode { inner: SfaNode::from_state(&s).map_err(to_py)? })
    }

    fn copy(&self) -> Self {
        self.clone()
    }
}


// ---------------------------------------------------------------- Network

/// Image batches as contiguous f64 (N, H, W, C) data: converts float32,
/// float64 or uint8 arrays of 3 (gray) or 4 dimensions.
/// Panoramas as f64 with their shape, checked against the network's input
/// height and channel count (the width is the panorama period, free).
fn network_images(obj: &Bound<'_, PyAny>, net: &Network, what: &str) -> PyResult<(Vec<f64>, [usize; 4])> {
    let (data, [n, h, w, c]) = images_f64(obj)?;
    let (eh, _, ec) = net.input_shape();
    if (h, c) != (eh, ec) {
        return Err(PyValueError::new_err(format!(
            "{what} are {h} px high with {c} channel(s), the network takes {eh} with {ec}"
        )));
    }
    Ok((data, [n, h, w, c]))
}

fn images_f64(obj: &Bound<'_, PyAny>) -> PyResult<(Vec<f64>, [usize; 4])> {
    fn shape4(sh: &[usize]) -> PyResult<[usize; 4]> {
        match sh.len() {
            3 => Ok([sh[0], sh[1], sh[2], 1]),
            4 => Ok([sh[0], sh[1], sh[2], sh[3]]),
            _ => Err(PyValueError::new_err(format!(
                "images must have shape (N, H, W) or (N, H, W, C), got {} dimensions",
                sh.len()
            ))),
        }
    }
    macro_rules! conv {
        ($t:ty) => {
            if let Ok(a) = obj.cast::<numpy::PyArrayDyn<$t>>() {
                let r = a.try_readonly().map_err(|e| PyValueError::new_err(format!("images: {e}")))?;
                let v = r.as_array();
                let sh = shape4(v.shape())?;
                return Ok((v.iter().map(|&x| x as f64).collect(), sh));
            }
        };
    }
    conv!(f64);
    conv!(f32);
    conv!(u8);
    Err(PyTypeError::new_err("images must be a NumPy array of float32, float64 or uint8"))
}

fn spec_from_dict(d: &Bound<'_, PyDict>) -> PyResult<NetworkSpec> {
    let list = d
        .get_item("layers")?
        .ok_or_else(|| PyValueError::new_err("network spec: missing 'layers'"))?
        .cast_into::<PyList>()
        .map_err(|_| PyValueError::new_err("network spec: 'layers' must be a list"))?;
    let mut layers = Vec::new();
    for item in list.iter() {
        let l = item
            .cast_into::<PyDict>()
            .map_err(|_| PyValueError::new_err("network spec: each layer must be a dict"))?;
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
struct PyNetwork {
    inner: Network,
}

#[pymethods]
impl PyNetwork {
    #[new]
    fn new(spec: &Bound<'_, PyDict>) -> PyResult<Self> {
        Ok(PyNetwork { inner: Network::new(spec_from_dict(spec)?).map_err(to_py)? })
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
            d.set_item("reduced_to", nodes.iter().map(|n| n.stage_outputs().first().copied().unwrap_or(0)).collect::<Vec<_>>())?;
            out.append(d)?;
        }
        Ok(out)
    }

    #[getter]
    fn n_layers(&self) -> usize { self.inner.n_layers() }
    #[getter]
    fn n_trained(&self) -> usize { self.inner.n_trained() }
    #[getter]
    fn n_outputs(&self) -> usize { self.inner.n_outputs() }
    #[getter]
    fn input_shape(&self) -> (usize, usize, usize) { self.inner.input_shape() }

    #[getter]
    fn delta_values<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let top = self.inner.n_layers() - 1;
        Ok(vec1(py, self.inner.nodes(top)[0].delta_values().map_err(to_py)?.to_vec()))
    }

    /// transform(images) -> (N, n_outputs): images (N, H, W[, C]) of the
    /// network's input size.
    fn transform<'py>(&self, py: Python<'py>, images: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        let (data, [n, h, w, c]) = images_f64(images)?;
        let (eh, ew, ec) = self.inner.input_shape();
        if (h, w, c) != (eh, ew, ec) {
            return Err(PyValueError::new_err(format!(
                "images are {w}x{h} with {c} channel(s), the network takes {ew}x{eh} with {ec}"
            )));
        }
        let net = &self.inner;
        let y = run(py, || net.transform(&data, n))?;
        out2(py, y, n, net.n_outputs())
    }

    /// transform_rotations(images, step) -> (N, K, n_outputs)
    fn transform_rotations<'py>(&self, py: Python<'py>, images: &Bound<'py, PyAny>, step: usize) -> PyResult<Bound<'py, PyAny>> {
        let (data, [n, _, w, _]) = network_images(images, &self.inner, "images")?;
        let rot = Rotation { step, period: w };
        let net = &self.inner;
        let y = run(py, || sfa_core::rotation::transform_rotations(net, rot, &data, n))?;
        let (k, m) = (rot.n_views(), net.n_outputs());
        let a = numpy::ndarray::Array3::from_shape_vec((n, k, m), y)
            .map_err(|e| PyRuntimeError::new_err(format!("internal shape error: {e}")))?;
        Ok(a.into_pyarray(py).into_any())
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
        Ok(PyNetwork { inner: Network::from_states(spec, &all, trained).map_err(to_py)? })
    }

    fn copy(&self) -> Self {
        self.clone()
    }
}

fn zip_pairs(a: Vec<usize>, b: Vec<usize>, w: Vec<f64>) -> PyResult<Vec<(usize, usize, f64)>> {
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

/// Trains one layer pass by pass (see sfa_core::rotation::LayerTrainer).
#[pyclass(name = "LayerTrainer", module = "sfanav._core")]
struct PyLayerTrainer {
    inner: Option<LayerTrainer>,
}

impl PyLayerTrainer {
    fn get(&mut self) -> PyResult<&mut LayerTrainer> {
        self.inner
            .as_mut()
            .ok_or_else(|| PyValueError::new_err("this trainer was handed on with next_layer()"))
    }
}

#[pymethods]
impl PyLayerTrainer {
    #[new]
    #[pyo3(signature = (network, layer, step, period, fast=true, cache=false, transition_weight=1.0))]
    fn new(
        network: &PyNetwork,
        layer: usize,
        step: usize,
        period: usize,
        fast: bool,
        cache: bool,
        transition_weight: f64,
    ) -> PyResult<Self> {
        let path = if fast { Path::Fast } else { Path::Naive };
        let mut inner = LayerTrainer::new(&network.inner, layer, Rotation { step, period }, path).map_err(to_py)?;
        inner.set_caching(cache);
        inner.set_transition_weight(transition_weight).map_err(to_py)?;
        Ok(PyLayerTrainer { inner: Some(inner) })
    }

    /// Weight of the derivative pairs between consecutive images relative
    /// to the pairs within an image (1: the thesis); inherited by next_layer().
    #[getter]
    fn transition_weight(&mut self) -> PyResult<f64> {
        Ok(self.get()?.transition_weight())
    }

    fn n_passes(&mut self, network: &PyNetwork) -> PyResult<usize> {
        Ok(self.get()?.n_passes(&network.inner))
    }

    #[getter]
    fn fast(&mut self) -> PyResult<bool> {
        Ok(self.get()?.path() == Path::Fast)
    }

    /// Whether this trainer keeps the lower layer's fields (built in its
    /// first pass) and hands them on with next_layer(); off drops them.
    fn set_caching(&mut self, on: bool) -> PyResult<()> {
        self.get()?.set_caching(on);
        Ok(())
    }

    #[getter]
    fn has_cache(&mut self) -> PyResult<bool> {
        Ok(self.get()?.has_cache())
    }

    #[getter]
    fn cache_bytes(&mut self) -> PyResult<usize> {
        Ok(self.get()?.cache_bytes())
    }

    #[getter]
    fn cached_images(&mut self) -> PyResult<usize> {
        Ok(self.get()?.cached_images())
    }

    fn feed(&mut self, py: Python<'_>, network: &mut PyNetwork, images: &Bound<'_, PyAny>) -> PyResult<()> {
        let (data, [n, ..]) = network_images(images, &network.inner, "training images")?;
        let tr = self.get()?;
        let net = &mut network.inner;
        run(py, || tr.feed(net, &data, n))
    }

    fn feed_cached(&mut self, py: Python<'_>, network: &mut PyNetwork) -> PyResult<()> {
        let tr = self.get()?;
        let net = &mut network.inner;
        run(py, || tr.feed_cached(net))
    }

    /// Spatial pairs (a[e], b[e], weights[e]) between the given images, at
    /// every simulated rotation (see sfa_core LayerTrainer::feed_pairs).
    fn feed_pairs(
        &mut self,
        py: Python<'_>,
        network: &mut PyNetwork,
        images: &Bound<'_, PyAny>,
        a: Vec<usize>,
        b: Vec<usize>,
        weights: Vec<f64>,
    ) -> PyResult<()> {
        let pairs = zip_pairs(a, b, weights)?;
        let (data, [n, ..]) = network_images(images, &network.inner, "training images")?;
        let tr = self.get()?;
        let net = &mut network.inner;
        run(py, || tr.feed_pairs(net, &data, n, &pairs))
    }

    /// Spatial pairs between cached images (indices in feeding order);
    /// with shifts, image b of each pair is seen rolled left by its shift
    /// (multiples of the step, which must divide the period).
    #[pyo3(signature = (network, a, b, weights, shifts=None))]
    fn feed_pairs_cached(
        &mut self,
        py: Python<'_>,
        network: &mut PyNetwork,
        a: Vec<usize>,
        b: Vec<usize>,
        weights: Vec<f64>,
        shifts: Option<Vec<usize>>,
    ) -> PyResult<()> {
        let pairs = zip_pairs(a, b, weights)?;
        let tr = self.get()?;
        let net = &mut network.inner;
        run(py, || tr.feed_pairs_cached_shifted(net, &pairs, shifts.as_deref()))
    }

    fn end_pass(&mut self, py: Python<'_>, network: &mut PyNetwork) -> PyResult<bool> {
        let tr = self.get()?;
        let net = &mut network.inner;
        run(py, || tr.end_pass(net))
    }

    /// The trainer of the next layer, inheriting (and advancing) the cache;
    /// this trainer is consumed.
    fn next_layer(&mut self, py: Python<'_>, network: &PyNetwork) -> PyResult<PyLayerTrainer> {
        let tr = self
            .inner
            .take()
            .ok_or_else(|| PyValueError::new_err("this trainer was already handed on"))?;
        let net = &network.inner;
        let next = run(py, || tr.next_layer(net));
        Ok(PyLayerTrainer { inner: Some(next?) })
    }
}

// ---------------------------------------------------------------- module

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("DEFAULT_TOL", sfa_core::DEFAULT_TOL)?;
    m.add_function(wrap_pyfunction!(expand, m)?)?;
    m.add_function(wrap_pyfunction!(expanded_dim, m)?)?;
    m.add_function(wrap_pyfunction!(solve_generalized, m)?)?;
    m.add_function(wrap_pyfunction!(set_num_threads, m)?)?;
    m.add_function(wrap_pyfunction!(get_num_threads, m)?)?;
    m.add_class::<PyStatistics>()?;
    m.add_class::<PySfaNode>()?;
    m.add_class::<PyNetwork>()?;
    m.add_class::<PyLayerTrainer>()?;
    Ok(())
}
