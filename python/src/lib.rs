//! `mesoflow._native`, the extension module under the `mesoflow` Python package: the engine's
//! catalog, validation, runs and Python node kinds. The Python layer (`pysrc/mesoflow/`) builds
//! graphs, converts arguments and raises the package's exceptions; this crate only bridges.

mod cli;
mod convert;
mod observe;
mod plan;
mod pynode;
mod session;
mod sweep;
mod wait;

use pyo3::prelude::*;

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(session::catalog, m)?)?;
    m.add_function(wrap_pyfunction!(session::validate, m)?)?;
    m.add_function(wrap_pyfunction!(session::register_node, m)?)?;
    m.add_function(wrap_pyfunction!(session::run, m)?)?;
    m.add_function(wrap_pyfunction!(plan::plan, m)?)?;
    m.add_function(wrap_pyfunction!(plan::plan_truth, m)?)?;
    m.add_function(wrap_pyfunction!(sweep::sweep, m)?)?;
    m.add_function(wrap_pyfunction!(cli::cli, m)?)?;
    m.add_class::<convert::ArrayBuffer>()?;
    m.add_class::<convert::Opaque>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
