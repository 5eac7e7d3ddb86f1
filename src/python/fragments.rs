//! `small_bodies`: the stray fragments of a particle surface (the core's `fragments` module).

use super::convert::points;
use pyo3::prelude::*;

/// The bodies of a mesh holding fewer than ``min_particles`` of ``particles`` (each particle
/// counts for the body of its nearest vertex).
///
/// Parameters
/// ----------
/// vertices : (V, 3) float64
/// faces : (F, 3) int
/// particles : (N, 3) float64 or float32
/// min_particles : int
///
/// Returns
/// -------
/// tuple
///     ``(keep, bodies, particles)``: (V,) bool, False on the vertices of a dropped body; the
///     number of bodies dropped and of the particles they held.
#[pyfunction]
pub fn small_bodies<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    particles: &Bound<'py, PyAny>,
    min_particles: usize,
) -> PyResult<(Bound<'py, PyAny>, usize, usize)> {
    let _call = super::interrupt::call("small_bodies");
    let mesh = super::convert::mesh_arg(vertices, faces)?;
    let p = points(particles, "particles")?;
    let r = super::interrupt::detach(py, || {
        crate::fragments::small_bodies(&mesh, &p, min_particles)
    })?;
    Ok((
        numpy::PyArray1::from_vec(py, r.keep).into_any(),
        r.bodies,
        r.particles,
    ))
}
