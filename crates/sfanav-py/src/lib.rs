//! Thin pyo3 bindings of `sfa-core`, importable as `sfanav._core`.
//!
//! One file per Python class (`statistics.rs`, `node.rs`, `network.rs`,
//! `trainer.rs`),
//! with the glue beside them: error mapping, GIL release and panic
//! containment (`error.rs`), NumPy conversion (`arrays.rs`), model-state
//! dicts (`state.rs`), worker threads (`threads.rs`) and the module-level
//! functions (`functions.rs`). The bindings validate, convert, release the
//! GIL and map errors; numerics live in `sfa-core`.

mod arrays;
mod error;
mod functions;
mod network;
mod node;
mod state;
mod statistics;
mod threads;
mod trainer;

use pyo3::prelude::*;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("DEFAULT_TOL", sfa_core::DEFAULT_TOL)?;
    m.add_function(wrap_pyfunction!(functions::expand, m)?)?;
    m.add_function(wrap_pyfunction!(functions::expanded_dim, m)?)?;
    m.add_function(wrap_pyfunction!(functions::solve_generalized, m)?)?;
    m.add_function(wrap_pyfunction!(functions::warp_scores, m)?)?;
    m.add_function(wrap_pyfunction!(functions::warp_and_min_warp_scores, m)?)?;
    m.add_function(wrap_pyfunction!(functions::set_memory_limit, m)?)?;
    m.add_function(wrap_pyfunction!(functions::get_memory_limit, m)?)?;
    m.add_function(wrap_pyfunction!(functions::_test_panic, m)?)?;
    m.add_function(wrap_pyfunction!(threads::set_num_threads, m)?)?;
    m.add_function(wrap_pyfunction!(threads::get_num_threads, m)?)?;
    m.add_class::<statistics::PyStatistics>()?;
    m.add_class::<node::PySfaNode>()?;
    m.add_class::<network::PyNetwork>()?;
    m.add_class::<trainer::PyLayerTrainer>()?;
    Ok(())
}
