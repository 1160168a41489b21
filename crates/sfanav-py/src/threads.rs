//! The worker threads of the Rust core.

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use std::sync::{Arc, Mutex};

static POOL: Mutex<Option<Arc<rayon::ThreadPool>>> = Mutex::new(None);

/// The pool set by `set_num_threads` (None: rayon's global pool).
pub(crate) fn current_pool() -> Option<Arc<rayon::ThreadPool>> {
    POOL.lock().map(|p| p.clone()).unwrap_or(None)
}

/// Sets the number of worker threads used by sfanav's Rust core (0 = one per
/// core, the default).
#[pyfunction]
pub(crate) fn set_num_threads(n: usize) -> PyResult<()> {
    let mut g = POOL.lock().map_err(|_| PyRuntimeError::new_err("thread pool lock poisoned"))?;
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
pub(crate) fn get_num_threads() -> usize {
    match current_pool() {
        Some(p) => p.current_num_threads(),
        None => rayon::current_num_threads(),
    }
}
