//! `_core.Statistics`: streaming SFA statistics.

use crate::arrays::{arr2, mat_to_py, opt_weights, vec1, view_of, Arr};
use crate::error::{guard, run};
use crate::state::{acc_state_from_dict, acc_state_to_dict};
use numpy::PyReadonlyArray1;
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use sfa_core::Accumulator;

/// Streaming SFA statistics (see sfa_core::stats).
#[pyclass(name = "Statistics", module = "sfanav._core")]
#[derive(Clone)]
pub(crate) struct PyStatistics {
    pub(crate) inner: Accumulator,
}

#[pymethods]
impl PyStatistics {
    #[new]
    fn new(dim: usize) -> PyResult<Self> {
        Ok(PyStatistics { inner: guard(|| Accumulator::new(dim))? })
    }

    #[pyo3(signature = (x, new_sequence=false))]
    fn update(&mut self, py: Python<'_>, x: &Bound<'_, PyAny>, new_sequence: bool) -> PyResult<()> {
        let acc = &mut self.inner;
        match arr2(x, "X")? {
            Arr::F64(a) => {
                let v = view_of(&a);
                run(py, || acc.update(v, new_sequence))
            }
            Arr::F32(a) => {
                let v = view_of(&a);
                run(py, || acc.update(v, new_sequence))
            }
        }
    }

    #[pyo3(signature = (x, weights=None))]
    fn add_samples(
        &mut self,
        py: Python<'_>,
        x: &Bound<'_, PyAny>,
        weights: Option<PyReadonlyArray1<'_, f64>>,
    ) -> PyResult<()> {
        let w = opt_weights(weights)?;
        let acc = &mut self.inner;
        match arr2(x, "X")? {
            Arr::F64(a) => {
                let v = view_of(&a);
                run(py, || acc.add_samples(v, w.as_deref()))
            }
            Arr::F32(a) => {
                let v = view_of(&a);
                run(py, || acc.add_samples(v, w.as_deref()))
            }
        }
    }

    #[pyo3(signature = (a, b, weights=None))]
    fn add_pairs(
        &mut self,
        py: Python<'_>,
        a: &Bound<'_, PyAny>,
        b: &Bound<'_, PyAny>,
        weights: Option<PyReadonlyArray1<'_, f64>>,
    ) -> PyResult<()> {
        let w = opt_weights(weights)?;
        let acc = &mut self.inner;
        match (arr2(a, "a")?, arr2(b, "b")?) {
            (Arr::F64(a), Arr::F64(b)) => {
                let (va, vb) = (view_of(&a), view_of(&b));
                run(py, || acc.add_pairs(va, vb, w.as_deref()))
            }
            (Arr::F32(a), Arr::F32(b)) => {
                let (va, vb) = (view_of(&a), view_of(&b));
                run(py, || acc.add_pairs(va, vb, w.as_deref()))
            }
            _ => Err(PyTypeError::new_err("a and b must have the same dtype")),
        }
    }

    fn break_sequence(&mut self) {
        self.inner.break_sequence();
    }

    fn merge(&mut self, other: &PyStatistics) -> PyResult<()> {
        let (a, b) = (&mut self.inner, &other.inner);
        guard(|| a.merge(b))
    }

    fn merge_continuing(&mut self, other: &PyStatistics) -> PyResult<()> {
        let (a, b) = (&mut self.inner, &other.inner);
        guard(|| a.merge_continuing(b))
    }

    fn copy(&self) -> Self {
        self.clone()
    }

    fn mean<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(vec1(py, guard(|| self.inner.mean())?))
    }

    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        mat_to_py(py, guard(|| self.inner.covariance())?)
    }

    fn derivative_covariance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        mat_to_py(py, guard(|| self.inner.derivative_covariance())?)
    }

    fn derivative_mean<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(vec1(py, guard(|| self.inner.derivative_mean())?))
    }

    #[getter]
    fn dim(&self) -> usize {
        self.inner.dim()
    }
    #[getter]
    fn n_samples(&self) -> u64 {
        self.inner.n_samples()
    }
    #[getter]
    fn n_pairs(&self) -> u64 {
        self.inner.n_pairs()
    }
    #[getter]
    fn weight_sum(&self) -> f64 {
        self.inner.weight_sum()
    }
    #[getter]
    fn pair_weight_sum(&self) -> f64 {
        self.inner.pair_weight_sum()
    }

    fn get_state<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        acc_state_to_dict(py, &self.inner.state())
    }

    #[staticmethod]
    fn from_state(state: &Bound<'_, PyDict>) -> PyResult<Self> {
        let s = acc_state_from_dict(state)?;
        Ok(PyStatistics { inner: guard(|| Accumulator::from_state(&s))? })
    }

    fn __repr__(&self) -> String {
        format!(
            "Statistics(dim={}, n_samples={}, n_pairs={})",
            self.inner.dim(),
            self.inner.n_samples(),
            self.inner.n_pairs()
        )
    }
}
