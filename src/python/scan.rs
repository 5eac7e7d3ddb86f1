//! `_core.ray_cast`, `_core.closest_points`, `_core.k_nearest` and `_core.pca_normals`: the
//! queries of [`crate::bvh`] and [`crate::knn`] on numpy arrays. Points, queries, origins and
//! directions are read in place when they are C-contiguous float64 (N, 3) arrays and converted
//! otherwise ([`points_arg`]); the GIL is released around the core.

use super::convert::{points, points_arg, points_to_py, triangles, values_to_py};
use super::errors::value_error;
use super::interrupt::run;
use crate::bvh::Bvh;
use crate::knn::{pca_normals as core_pca_normals, PointTree};
use glam::DVec3;
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

/// `value` as a count of neighbours; the error names `k`.
fn count(k: i64) -> PyResult<usize> {
    usize::try_from(k).map_err(|_| value_error("k", format!("must be positive, got {k}")))
}

/// (N,) int64 array.
fn indices_to_py<'py>(py: Python<'py>, v: Vec<i64>) -> Bound<'py, PyAny> {
    PyArray1::from_vec(py, v).into_any()
}

/// The first hit of each ray ``origins[i] + t × directions[i]`` (t > 0) on the mesh
/// (``vertices``, ``faces``): ``(t, triangle)``, (N,) float64 and (N,) int64, with ``inf`` and
/// -1 for a ray that misses.
#[pyfunction]
pub fn ray_cast<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    origins: &Bound<'py, PyAny>,
    directions: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyTuple>> {
    let v = points(vertices, "vertices")?;
    let f = triangles(faces, "faces")?;
    let o = points_arg(origins, "origins")?;
    let d = points_arg(directions, "directions")?;
    let (o, d) = (o.as_slice(), d.as_slice());
    if o.len() != d.len() {
        return Err(value_error(
            "directions",
            format!(
                "expected {} rows (one per origin), got {}",
                o.len(),
                d.len()
            ),
        ));
    }
    crate::error::check_finite_points("origins", o)?;
    crate::error::check_finite_points("directions", d)?;
    if let Some(i) = d.iter().position(|d| *d == DVec3::ZERO) {
        return Err(value_error("directions", format!("row {i} is zero")));
    }
    let (t, tri) = run(py, None, false, || {
        let bvh = Bvh::new(&v, &f)?;
        let hits = bvh.cast_many(o, d)?;
        Ok(hits
            .iter()
            .map(|h| match h {
                Some(h) => (h.t, h.triangle as i64),
                None => (f64::INFINITY, -1),
            })
            .unzip::<f64, i64, Vec<_>, Vec<_>>())
    })?;
    PyTuple::new(py, [values_to_py(py, t), indices_to_py(py, tri)])
}

/// The closest point of the mesh (``vertices``, ``faces``) to each of ``points``:
/// ``(closest, distance, triangle)``, (N, 3) float64, (N,) float64 and (N,) int64.
#[pyfunction]
pub fn closest_points<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    points: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyTuple>> {
    let v = super::convert::points(vertices, "vertices")?;
    let f = triangles(faces, "faces")?;
    let p = points_arg(points, "points")?;
    let p = p.as_slice();
    let (c, d, t) = run(py, None, false, || {
        let bvh = Bvh::new(&v, &f)?;
        let found = bvh.closest_many(p)?;
        let c: Vec<DVec3> = found.iter().map(|c| c.point).collect();
        let d: Vec<f64> = found.iter().map(|c| c.distance).collect();
        let t: Vec<i64> = found.iter().map(|c| c.triangle as i64).collect();
        Ok((c, d, t))
    })?;
    PyTuple::new(
        py,
        [
            points_to_py(py, c)?,
            values_to_py(py, d),
            indices_to_py(py, t),
        ],
    )
}

/// The ``k`` nearest of ``points`` to each of ``queries`` (to each of ``points`` itself when
/// ``queries`` is None), nearest first, ties by smaller index: ``(indices, distances)``, (M, k)
/// int64 and (M, k) float64.
#[pyfunction]
#[pyo3(signature = (points, k, queries=None))]
pub fn k_nearest<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    k: i64,
    queries: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let k = count(k)?;
    let p = points_arg(points, "points")?;
    let q = queries.map(|q| points_arg(q, "queries")).transpose()?;
    let p = p.as_slice();
    let q = q.as_ref().map(|q| q.as_slice());
    let (idx, dist) = run(py, None, false, || {
        let tree = PointTree::new(p)?;
        match q {
            Some(q) => tree.k_nearest(q, k),
            None => tree.k_nearest_of_points(k),
        }
    })?;
    let rows = idx.len() / k.max(1);
    let idx: Vec<i64> = py.detach(|| idx.into_iter().map(i64::from).collect());
    let shape = [rows, k];
    let i = PyArray1::from_vec(py, idx).reshape(shape)?;
    let d = PyArray1::from_vec(py, dist).reshape(shape)?;
    PyTuple::new(py, [i.into_any(), d.into_any()])
}

/// Unoriented unit normals of ``points`` (N, 3): for each point the smallest eigenvector of the
/// covariance of its ``k`` nearest points (itself included); (N, 3) float64, sign arbitrary.
#[pyfunction]
#[pyo3(signature = (points, k=20))]
pub fn pca_normals<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    k: i64,
) -> PyResult<Bound<'py, PyAny>> {
    let k = count(k)?;
    let p = points_arg(points, "points")?;
    let p = p.as_slice();
    if p.is_empty() {
        return Err(value_error("points", "no points"));
    }
    let n = run(py, None, false, || core_pca_normals(p, k))?;
    points_to_py(py, n)
}

/// Adds this file's functions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(ray_cast, m)?)?;
    m.add_function(wrap_pyfunction!(closest_points, m)?)?;
    m.add_function(wrap_pyfunction!(k_nearest, m)?)?;
    m.add_function(wrap_pyfunction!(pca_normals, m)?)?;
    Ok(())
}
