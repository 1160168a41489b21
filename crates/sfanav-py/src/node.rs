//! `_core.SfaNode`: the SFA node.

use crate::arrays::{arr2, out2, vec1, view_of, Arr};
use crate::error::{guard, run};
use crate::state::{node_state_from_dict, node_state_to_dict};
use crate::statistics::PyStatistics;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use sfa_core::{NodeConfig, SfaNode};

/// The SFA node (see sfa_core::node); wrapped by sfanav.SFA.
#[pyclass(name = "SfaNode", module = "sfanav._core")]
#[derive(Clone)]
pub(crate) struct PySfaNode {
    pub(crate) inner: SfaNode,
}

#[pymethods]
impl PySfaNode {
    #[new]
    #[pyo3(signature = (n_components, degree=1, reduce_to=None, tol=sfa_core::DEFAULT_TOL, mixed_precision=false))]
    fn new(
        n_components: usize,
        degree: usize,
        reduce_to: Option<usize>,
        tol: f64,
        mixed_precision: bool,
    ) -> PyResult<Self> {
        let inner = guard(|| SfaNode::new(NodeConfig { n_components, degree, reduce_to, tol, mixed_precision }))?;
        Ok(PySfaNode { inner })
    }

    #[pyo3(signature = (x, new_sequence=false))]
    fn partial_fit(&mut self, py: Python<'_>, x: &Bound<'_, PyAny>, new_sequence: bool) -> PyResult<()> {
        let node = &mut self.inner;
        match arr2(x, "X")? {
            Arr::F64(a) => {
                let v = view_of(&a);
                run(py, || node.partial_fit(v, new_sequence))
            }
            Arr::F32(a) => {
                let v = view_of(&a);
                run(py, || node.partial_fit(v, new_sequence))
            }
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
            Arr::F64(a) => {
                let v = view_of(&a);
                let n = v.nrows();
                let y = run(py, || node.transform(v))?;
                out2(py, y, n, m)
            }
            Arr::F32(a) => {
                let v = view_of(&a);
                let n = v.nrows();
                let y = run(py, || node.transform(v))?;
                out2(py, y, n, m)
            }
        }
    }

    #[getter]
    fn delta_values<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(vec1(py, guard(|| self.inner.delta_values().map(<[f64]>::to_vec))?))
    }

    #[getter]
    fn n_features(&self) -> Option<usize> {
        self.inner.n_features()
    }
    #[getter]
    fn n_stages(&self) -> usize {
        self.inner.n_stages()
    }
    #[getter]
    fn training_stage(&self) -> usize {
        self.inner.training_stage()
    }
    #[getter]
    fn is_solved(&self) -> bool {
        self.inner.is_solved()
    }
    #[getter]
    fn rank_deficits(&self) -> Vec<usize> {
        self.inner.rank_deficits()
    }
    #[getter]
    fn stage_outputs(&self) -> Vec<usize> {
        self.inner.stage_outputs()
    }

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
        Ok(PySfaNode { inner: guard(|| SfaNode::from_state(&s))? })
    }

    fn copy(&self) -> Self {
        self.clone()
    }
}
