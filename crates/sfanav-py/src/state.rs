//! Node and statistics states <-> Python dicts (the layout of the model
//! files: scalars, lists and 1-D float64 arrays; docs/model-format.md).
//! Hand-written rather than through serde: the arrays must be NumPy arrays
//! both ways, and a bad field is named in the error.

use crate::arrays::vec1;
use numpy::{PyArray1, PyArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use sfa_core::{AccumulatorState, NodeConfig, NodeState, SolutionState, StageState};

pub(crate) fn get<'py, T: for<'a> FromPyObject<'a, 'py>>(d: &Bound<'py, PyDict>, key: &str) -> PyResult<T>
where
    for<'a> <T as FromPyObject<'a, 'py>>::Error: Into<PyErr>,
{
    match d.get_item(key)? {
        Some(v) => v.extract::<T>().map_err(|_| {
            let got = v.repr().map_or_else(|_| "?".to_string(), |r| r.to_string());
            let got: String =
                if got.chars().count() > 60 { got.chars().take(60).chain("...".chars()).collect() } else { got };
            PyValueError::new_err(format!("invalid model state: field '{key}' must be {}, got {got}", expected::<T>()))
        }),
        None => Err(PyValueError::new_err(format!("invalid model state: missing field '{key}'"))),
    }
}

/// What a field of Rust type `T` must be, in Python's words.
fn expected<T>() -> &'static str {
    let name = std::any::type_name::<T>();
    match name {
        "usize" | "u64" | "u32" => "a non-negative integer",
        "f64" => "a number",
        "bool" => "a bool",
        _ if name.contains("Option<usize>") => "a non-negative integer or None",
        _ if name.contains("(usize, usize)") => "a pair of non-negative integers",
        _ => "of another type",
    }
}

pub(crate) fn get_bool_or(d: &Bound<'_, PyDict>, key: &str, default: bool) -> PyResult<bool> {
    match d.get_item(key)? {
        Some(v) => v
            .extract::<bool>()
            .map_err(|_| PyValueError::new_err(format!("invalid model state: field '{key}' must be a bool"))),
        None => Ok(default),
    }
}

pub(crate) fn get_vec(d: &Bound<'_, PyDict>, key: &str) -> PyResult<Vec<f64>> {
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

pub(crate) fn acc_state_to_dict<'py>(py: Python<'py>, s: &AccumulatorState) -> PyResult<Bound<'py, PyDict>> {
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

pub(crate) fn acc_state_from_dict(d: &Bound<'_, PyDict>) -> PyResult<AccumulatorState> {
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

pub(crate) fn node_state_to_dict<'py>(py: Python<'py>, s: &NodeState) -> PyResult<Bound<'py, PyDict>> {
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

pub(crate) fn opt_dict<'py>(d: &Bound<'py, PyDict>, key: &str) -> PyResult<Option<Bound<'py, PyDict>>> {
    match d.get_item(key)? {
        None => Ok(None),
        Some(v) if v.is_none() => Ok(None),
        Some(v) => Ok(Some(v.cast_into::<PyDict>().map_err(|_| {
            PyValueError::new_err(format!("invalid model state: field '{key}' must be a dict or None"))
        })?)),
    }
}

pub(crate) fn node_state_from_dict(d: &Bound<'_, PyDict>) -> PyResult<NodeState> {
    let config = NodeConfig {
        n_components: get(d, "n_components")?,
        degree: get(d, "degree")?,
        reduce_to: get(d, "reduce_to")?,
        tol: get(d, "tol")?,
        mixed_precision: get_bool_or(d, "mixed_precision", false)?,
    };
    let list =
        d.get_item("stages")?.ok_or_else(|| PyValueError::new_err("invalid model state: missing field 'stages'"))?;
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
    Ok(NodeState { config, n_features: get(d, "n_features")?, training_stage: get(d, "training_stage")?, stages })
}
