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

/// The extension's allocator for everything the core allocates (meshes handed to numpy
/// included). The system allocator returns large buffers to the OS when they are freed, and a
/// fresh page costs a fault (measured here: 1.7 µs per 4 KiB page, about 8 % of a 256³ blob
/// polygonization); mimalloc keeps freed memory for reuse by the next call and returns it
/// after a delay (see [`PURGE_DELAY_MS`]).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// mimalloc's `mi_option_purge_delay` (its index in mimalloc 3's `mi_option_e`, which
/// libmimalloc-sys does not name).
const MI_OPTION_PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;
/// Milliseconds before freed memory goes back to the OS (mimalloc's default is 10, and 10 times
/// this for its arenas, where large buffers live): long enough for a loop of calls with other
/// work between them (a benchmark, an animation) to reuse its buffers, as jemalloc's default
/// decay of 10 s does.
const PURGE_DELAY_MS: std::ffi::c_long = 1000;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // SAFETY: reads and sets a plain integer option (read at each purge). Only mimalloc's own
    // default (10 ms) is replaced: a delay the user set (MIMALLOC_PURGE_DELAY) stays, and should
    // the option's index ever name another option, its value is not 10 and nothing changes.
    unsafe {
        if libmimalloc_sys::mi_option_get(MI_OPTION_PURGE_DELAY) == 10 {
            libmimalloc_sys::mi_option_set(MI_OPTION_PURGE_DELAY, PURGE_DELAY_MS);
        }
    }
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<variational::PyVariationalSurface>()?;
    m.add_class::<blob::PyBlobField>()?;
    m.add_class::<polygonize::PyTessellator>()?;
    m.add_function(wrap_pyfunction!(polygonize::polygonize, m)?)?;
    subdivision::register(m)?;
    Ok(())
}
