//! The pyo3 layer: converts numpy arrays and Python arguments, checks them, releases the GIL
//! around the core, and maps core errors to Python exceptions (`errors.rs`). No algorithm lives
//! here.

mod blob;
mod convert;
mod errors;
mod field;
mod fragments;
mod interrupt;
mod normals;
mod polygonize;
mod scan;
mod state;
mod subdivision;
mod variational;
mod weld;

use pyo3::prelude::*;

/// The extension's allocator for everything the core allocates (meshes handed to numpy
/// included). The system allocator returns large buffers to the OS when they are freed, so the
/// next call faults in fresh pages again; mimalloc 3 keeps freed memory for reuse by the next
/// call and returns it to the OS after its default purge delay (`MIMALLOC_PURGE_DELAY` sets
/// it). It is built without its own requests for transparent huge pages (`no_thp`): the fit's
/// many short-lived buffers then fault in 4 KiB pages instead of zeroing whole 2 MiB pages
/// after each purge (docs/variational.md, "Memory").
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

extern "C" {
    /// mimalloc's collection of the calling thread's free memory (in the linked mimalloc; its
    /// binding is behind the crate's `extended` feature).
    fn mi_collect(force: bool);
}

/// Returns the calling thread's free memory to the system now
/// ([`crate::memory::release_free_memory`]).
fn collect_free_memory() {
    // SAFETY: mi_collect only releases memory mimalloc holds and no live allocation.
    unsafe { mi_collect(true) }
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    crate::memory::set_release_hook(collect_free_memory);
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("DEFAULT_MEMORY_LIMIT", crate::memory::DEFAULT_MEMORY_LIMIT)?;
    m.add_class::<variational::PyVariationalSurface>()?;
    m.add_class::<blob::PyBlobField>()?;
    m.add_class::<polygonize::PyTessellator>()?;
    m.add_function(wrap_pyfunction!(polygonize::polygonize, m)?)?;
    m.add_function(wrap_pyfunction!(polygonize::lattice, m)?)?;
    m.add_function(wrap_pyfunction!(polygonize::project_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(fragments::small_bodies, m)?)?;
    m.add_function(wrap_pyfunction!(weld::weld_tiles, m)?)?;
    m.add_class::<weld::PyStreamedWeld>()?;
    m.add_class::<weld::PyWeldPlan>()?;
    m.add_function(wrap_pyfunction!(weld::write_welded_tile, m)?)?;
    subdivision::register(m)?;
    scan::register(m)?;
    normals::register(m)?;
    // For tests only: a panic in a worker must come back as a RuntimeError (tests/test_extreme.py).
    m.add_function(wrap_pyfunction!(interrupt::_panic_in_worker, m)?)?;
    Ok(())
}
