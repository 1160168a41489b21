//! NumPy <-> Rust conversion: borrowed 2-D float arrays, borrowed image
//! batches of any pixel type, and output arrays.

use numpy::ndarray::Array2;
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArrayDyn, PyArrayMethods, PyReadonlyArray1, PyReadonlyArrayDyn,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use sfa_core::{Pixels, View};
use std::borrow::Cow;

/// A borrowed 2-D float array of either precision.
pub(crate) enum Arr<'py> {
    F32(numpy::PyReadonlyArray2<'py, f32>),
    F64(numpy::PyReadonlyArray2<'py, f64>),
}

pub(crate) fn arr2<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<Arr<'py>> {
    if let Ok(a) = obj.cast::<PyArray2<f64>>() {
        return Ok(Arr::F64(a.try_readonly().map_err(|e| PyValueError::new_err(format!("{name}: {e}")))?));
    }
    if let Ok(a) = obj.cast::<PyArray2<f32>>() {
        return Ok(Arr::F32(a.try_readonly().map_err(|e| PyValueError::new_err(format!("{name}: {e}")))?));
    }
    Err(PyTypeError::new_err(format!("{name} must be a 2-D float32 or float64 NumPy array")))
}

pub(crate) fn view_of<'a, T: numpy::Element + sfa_core::Sample>(a: &'a numpy::PyReadonlyArray2<'_, T>) -> View<'a, T> {
    let v = a.as_array();
    let (n, d) = v.dim();
    let s = v.strides();
    // SAFETY: the readonly borrow keeps the array alive and unaliased by
    // Rust writers for the view's lifetime; strides are in elements.
    unsafe { View::from_raw_parts(v.as_ptr(), n, d, s[0], s[1]) }
}

pub(crate) fn out2<'py, T: numpy::Element>(
    py: Python<'py>,
    v: Vec<T>,
    n: usize,
    m: usize,
) -> PyResult<Bound<'py, PyAny>> {
    let a =
        Array2::from_shape_vec((n, m), v).map_err(|e| PyRuntimeError::new_err(format!("internal shape error: {e}")))?;
    Ok(a.into_pyarray(py).into_any())
}

pub(crate) fn mat_to_py<'py>(py: Python<'py>, m: faer::Mat<f64>) -> PyResult<Bound<'py, PyAny>> {
    let (r, c) = (m.nrows(), m.ncols());
    let v: Vec<f64> = (0..r).flat_map(|i| (0..c).map(move |j| (i, j))).map(|(i, j)| m[(i, j)]).collect();
    out2(py, v, r, c)
}

pub(crate) fn vec1<'py>(py: Python<'py>, v: Vec<f64>) -> Bound<'py, PyAny> {
    PyArray1::from_vec(py, v).into_any()
}

pub(crate) fn opt_weights(w: Option<PyReadonlyArray1<'_, f64>>) -> PyResult<Option<Vec<f64>>> {
    match w {
        None => Ok(None),
        Some(w) => Ok(Some(w.as_array().iter().copied().collect())),
    }
}

/// A borrowed batch of images `(N, H, W)` or `(N, H, W, C)` of uint8,
/// float32 or float64.
pub(crate) struct Images<'py> {
    arr: ImageArr<'py>,
    /// `[N, H, W, C]` (C = 1 for 3-D arrays).
    pub(crate) shape: [usize; 4],
}

enum ImageArr<'py> {
    U8(PyReadonlyArrayDyn<'py, u8>),
    F32(PyReadonlyArrayDyn<'py, f32>),
    F64(PyReadonlyArrayDyn<'py, f64>),
}

/// Pixel data of an [`Images`] batch: the NumPy buffer itself when it is
/// C-contiguous, else a contiguous copy.
pub(crate) enum ImageData<'a> {
    U8(Cow<'a, [u8]>),
    F32(Cow<'a, [f32]>),
    F64(Cow<'a, [f64]>),
}

impl ImageData<'_> {
    pub(crate) fn pixels(&self) -> Pixels<'_> {
        match self {
            ImageData::U8(s) => Pixels::U8(s),
            ImageData::F32(s) => Pixels::F32(s),
            ImageData::F64(s) => Pixels::F64(s),
        }
    }
}

fn contiguous<'a, T: numpy::Element + Copy>(a: &'a PyReadonlyArrayDyn<'_, T>) -> Cow<'a, [T]> {
    match a.as_slice() {
        Ok(s) => Cow::Borrowed(s),
        Err(_) => Cow::Owned(a.as_array().iter().copied().collect()),
    }
}

impl<'py> Images<'py> {
    /// Borrows `obj` (a NumPy array of uint8, float32 or float64 of 3 or 4
    /// dimensions).
    pub(crate) fn borrow(obj: &Bound<'py, PyAny>) -> PyResult<Self> {
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
        macro_rules! try_type {
            ($t:ty, $v:ident) => {
                if let Ok(a) = obj.cast::<PyArrayDyn<$t>>() {
                    let r = a.try_readonly().map_err(|e| PyValueError::new_err(format!("images: {e}")))?;
                    let shape = shape4(r.shape())?;
                    return Ok(Images { arr: ImageArr::$v(r), shape });
                }
            };
        }
        try_type!(f64, F64);
        try_type!(f32, F32);
        try_type!(u8, U8);
        Err(PyTypeError::new_err("images must be a NumPy array of float32, float64 or uint8"))
    }

    pub(crate) fn data(&self) -> ImageData<'_> {
        match &self.arr {
            ImageArr::U8(a) => ImageData::U8(contiguous(a)),
            ImageArr::F32(a) => ImageData::F32(contiguous(a)),
            ImageArr::F64(a) => ImageData::F64(contiguous(a)),
        }
    }
}
