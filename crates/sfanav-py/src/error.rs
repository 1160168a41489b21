//! Error mapping, GIL release and panic containment.

use crate::threads::current_pool;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use sfa_core::SfaError;
use std::panic::{catch_unwind, AssertUnwindSafe};

/// A core error as a Python ValueError (its message).
pub(crate) fn to_py(e: SfaError) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// Runs `f` with the GIL released, inside the configured thread pool, and
/// turns a Rust panic into a Python RuntimeError instead of letting it cross.
pub(crate) fn run<R: Send>(py: Python<'_>, f: impl FnOnce() -> sfa_core::Result<R> + Send) -> PyResult<R> {
    let pool = current_pool();
    py.detach(move || {
        contain(|| match pool {
            Some(p) => p.install(f),
            None => f(),
        })
    })
}

/// Runs a quick core call with the GIL held (constructors, state
/// restoring, merges), with the same error mapping and panic containment
/// as [`run`].
pub(crate) fn guard<R>(f: impl FnOnce() -> sfa_core::Result<R>) -> PyResult<R> {
    contain(f)
}

fn contain<R>(f: impl FnOnce() -> sfa_core::Result<R>) -> PyResult<R> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r.map_err(to_py),
        Err(p) => {
            let msg = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown panic".into());
            Err(PyRuntimeError::new_err(format!("internal error in sfanav's Rust core (please report): {msg}")))
        }
    }
}

/// Keeps the first Python exception raised in a callback that the core
/// called (an image iterator, a progress report), so that it can be raised
/// again, unchanged, once the core has returned; the core itself sees
/// [`SfaError::Interrupted`].
#[derive(Default)]
pub(crate) struct Raised(Option<PyErr>);

impl Raised {
    /// The core's view of `r`: a Python error is kept and becomes
    /// `Interrupted`.
    pub(crate) fn keep<T>(&mut self, r: PyResult<sfa_core::Result<T>>) -> sfa_core::Result<T> {
        match r {
            Ok(r) => r,
            Err(e) => {
                self.0.get_or_insert(e);
                Err(SfaError::Interrupted("a Python callback raised an exception".into()))
            }
        }
    }

    pub(crate) fn take(&mut self) -> Option<PyErr> {
        self.0.take()
    }
}
