//! The pyo3 layer: converts numpy arrays and Python arguments, checks them, releases the GIL
//! around the core, and maps core errors to Python exceptions (`errors.rs`). No algorithm lives
//! here.

mod blob;
mod convert;
mod errors;
mod field;
mod polygonize;
mod subdivision;
mod variational;

use pyo3::prelude::*;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<variational::PyVariationalSurface>()?;
    m.add_class::<blob::PyBlobField>()?;
    m.add_class::<polygonize::PyTessellator>()?;
    m.add_function(wrap_pyfunction!(polygonize::polygonize, m)?)?;
    subdivision::register(m)?;
    Ok(())
}
