//! Module-level functions: polynomial expansion and the generalized
//! eigenproblem.

use crate::arrays::{arr2, mat_to_py, out2, vec1, view_of, Arr};
use crate::error::{guard, run};
use numpy::PyUntypedArrayMethods;
use pyo3::prelude::*;

/// expand(x, degree) -> ndarray: all monomials of degree 1..=degree.
#[pyfunction]
pub(crate) fn expand<'py>(py: Python<'py>, x: &Bound<'py, PyAny>, degree: usize) -> PyResult<Bound<'py, PyAny>> {
    let a = arr2(x, "X")?;
    match &a {
        Arr::F64(a) => {
            let v = view_of(a);
            let e = guard(|| sfa_core::Expansion::new(v.ncols(), degree))?;
            let od = e.out_dim();
            let n = v.nrows();
            let out = run(py, || e.expand(v))?;
            out2(py, out, n, od)
        }
        Arr::F32(a) => {
            let v = view_of(a);
            let e = guard(|| sfa_core::Expansion::new(v.ncols(), degree))?;
            let od = e.out_dim();
            let n = v.nrows();
            let out = run(py, || e.expand(v))?;
            out2(py, out, n, od)
        }
    }
}

/// expanded_dim(n_features, degree) -> int: C(n + d, d) - 1.
#[pyfunction]
pub(crate) fn expanded_dim(n_features: usize, degree: usize) -> PyResult<usize> {
    guard(|| sfa_core::expanded_dim(n_features, degree))
}

/// solve_generalized(a, b, n, tol) -> (values, vectors, rank, dropped)
#[pyfunction]
pub(crate) fn solve_generalized<'py>(
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

/// The owned inputs of the warping's scores and their sizes, checked:
/// `(pairs, rows, width, groups, n_shifts, a, b, columns, shifts)`.
type WarpInputs = (usize, usize, usize, usize, usize, Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>);

fn warp_inputs(
    name: &str,
    a: &numpy::PyReadonlyArray3<'_, f64>,
    b: &numpy::PyReadonlyArray3<'_, f64>,
    columns: &numpy::PyReadonlyArray2<'_, f64>,
    shifts: &numpy::PyReadonlyArray2<'_, f64>,
    group: usize,
) -> PyResult<WarpInputs> {
    let (sa, sb) = (a.shape().to_vec(), b.shape().to_vec());
    if sa != sb {
        return Err(pyo3::exceptions::PyValueError::new_err(format!(
            "{name}: a has shape {sa:?} and b {sb:?}; they must match"
        )));
    }
    let (pairs, rows, width) = (sa[0], sa[1], sa[2]);
    if columns.shape()[1] != width {
        return Err(pyo3::exceptions::PyValueError::new_err(format!(
            "{name}: columns has {} columns for images {width} wide",
            columns.shape()[1]
        )));
    }
    if shifts.shape()[0] != pairs {
        return Err(pyo3::exceptions::PyValueError::new_err(format!(
            "{name}: shifts has {} rows for {pairs} pairs",
            shifts.shape()[0]
        )));
    }
    // the group count gives the output's shape: a zero would divide by zero before the core's own check
    if group == 0 || columns.shape()[0] % group != 0 {
        return Err(pyo3::exceptions::PyValueError::new_err(format!(
            "{name}: {} hypotheses do not split into groups of {group}",
            columns.shape()[0]
        )));
    }
    let own = |x: numpy::ndarray::ArrayViewD<'_, f64>| x.iter().copied().collect::<Vec<f64>>();
    Ok((
        pairs,
        rows,
        width,
        columns.shape()[0] / group,
        shifts.shape()[1],
        own(a.as_array().into_dyn()),
        own(b.as_array().into_dyn()),
        own(columns.as_array().into_dyn()),
        own(shifts.as_array().into_dyn()),
    ))
}

fn scores3<'py>(py: Python<'py>, shape: (usize, usize, usize), v: Vec<f64>) -> PyResult<Bound<'py, PyAny>> {
    let arr = numpy::ndarray::Array3::from_shape_vec(shape, v)
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
    Ok(numpy::PyArray3::from_owned_array(py, arr).into_any())
}

/// warp_scores(a, b, columns, shifts, group=1) -> ndarray (pairs,
/// hypotheses / group, shifts): the warping method's scores of pairs of
/// panoramas (`a`, `b`: (pairs, rows, width) float64; `columns`:
/// (hypotheses, width); `shifts`: (pairs, n_shifts)), computed in parallel
/// with the GIL released; `group` > 1: min-warping over consecutive groups
/// of that many hypotheses (each column's best hypothesis of its group).
#[pyfunction]
#[pyo3(signature = (a, b, columns, shifts, group = 1))]
pub(crate) fn warp_scores<'py>(
    py: Python<'py>,
    a: numpy::PyReadonlyArray3<'py, f64>,
    b: numpy::PyReadonlyArray3<'py, f64>,
    columns: numpy::PyReadonlyArray2<'py, f64>,
    shifts: numpy::PyReadonlyArray2<'py, f64>,
    group: usize,
) -> PyResult<Bound<'py, PyAny>> {
    let (pairs, rows, width, groups, n_shifts, va, vb, vc, vs) =
        warp_inputs("warp_scores", &a, &b, &columns, &shifts, group)?;
    let out = run(py, || sfa_core::min_warp_scores(&va, &vb, pairs, rows, width, &vc, group, &vs, n_shifts))?;
    scores3(py, (pairs, groups, n_shifts), out)
}

/// warp_and_min_warp_scores(a, b, columns, shifts, group) -> (ndarray
/// (pairs, hypotheses, shifts), ndarray (pairs, hypotheses / group,
/// shifts)): the warping's and min-warping's scores from one pass (what
/// `warp_scores` returns with `group=1` and with `group`), for about 1.2x
/// the cost of either.
#[pyfunction]
pub(crate) fn warp_and_min_warp_scores<'py>(
    py: Python<'py>,
    a: numpy::PyReadonlyArray3<'py, f64>,
    b: numpy::PyReadonlyArray3<'py, f64>,
    columns: numpy::PyReadonlyArray2<'py, f64>,
    shifts: numpy::PyReadonlyArray2<'py, f64>,
    group: usize,
) -> PyResult<Bound<'py, PyAny>> {
    let (pairs, rows, width, groups, n_shifts, va, vb, vc, vs) =
        warp_inputs("warp_and_min_warp_scores", &a, &b, &columns, &shifts, group)?;
    let (each, mins) =
        run(py, || sfa_core::warp_and_min_warp_scores(&va, &vb, pairs, rows, width, &vc, group, &vs, n_shifts))?;
    let hyps = groups * group;
    let out = (scores3(py, (pairs, hyps, n_shifts), each)?, scores3(py, (pairs, groups, n_shifts), mins)?);
    Ok(pyo3::types::PyTuple::new(py, [out.0, out.1])?.into_any())
}

/// set_memory_limit(bytes): the limit (bytes) that the core checks its
/// large requests against; 0 restores the automatic limit.
#[pyfunction]
pub(crate) fn set_memory_limit(bytes: usize) {
    sfa_core::memory::set_limit(bytes);
}

/// get_memory_limit() -> int: the limit the core checks against now
/// (bytes).
#[pyfunction]
pub(crate) fn get_memory_limit() -> usize {
    sfa_core::memory::limit()
}

/// _test_panic(pooled): panics inside the core's error wrapper, with the
/// GIL released in the worker pool (`pooled`) or held; for the tests that
/// check a panic becomes a RuntimeError instead of crossing into Python.
#[pyfunction]
pub(crate) fn _test_panic(py: Python<'_>, pooled: bool) -> PyResult<()> {
    if pooled {
        run(py, || -> sfa_core::Result<()> {
            use rayon::prelude::*;
            (0..4).into_par_iter().for_each(|i| {
                if i == 3 {
                    panic!("test panic in a worker")
                }
            });
            Ok(())
        })
    } else {
        guard(|| -> sfa_core::Result<()> { panic!("test panic") })
    }
}
