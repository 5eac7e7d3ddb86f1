//! `VariationalSurface`: the Python class over the core's fitted surface.

use super::convert::{
    field_gradients, field_values, points, points_to_py, triangles, values, values_to_py,
};
use super::errors::value_error;
use crate::field::constraints;
use crate::field::kernel::Kernel;
use crate::field::rbf::{self, VariationalSurface};
use glam::DVec3;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::Arc;

/// A variational implicit surface f(x) = Σ λ_j φ(‖x − c_j‖) + a + b·x fitted to constraints;
/// negative inside, positive outside.
///
/// Create one with :meth:`fit` (points with normals), :meth:`from_mesh` (a triangle mesh) or
/// :meth:`interpolate` (values at points). Evaluate with :meth:`evaluate` / :meth:`gradient` or by
/// calling it; polygonize it with :func:`implicitmesh.polygonize`.
#[pyclass(name = "VariationalSurface", module = "implicitmesh", frozen)]
pub struct PyVariationalSurface {
    pub inner: Arc<VariationalSurface>,
}

fn fit_settings(
    kernel: &str,
    smoothing: f64,
    memory_limit: Option<u64>,
) -> PyResult<rbf::Settings> {
    let d = rbf::Settings::default();
    Ok(rbf::Settings {
        kernel: Kernel::parse(kernel)?,
        smoothing,
        memory_limit: memory_limit.unwrap_or(d.memory_limit),
    })
}

fn placement(d: Option<f64>, w: Option<f64>) -> constraints::Settings {
    constraints::Settings {
        d,
        w,
        ..Default::default()
    }
}

#[pymethods]
impl PyVariationalSurface {
    /// Fits a surface to points with outward normals.
    ///
    /// Every point ``q_i`` becomes a boundary constraint (f = 0) and ``q_i + d_i n_i`` a normal
    /// constraint (f = w_i), with ``d_i`` shrunk (halved) until no other point is nearer to the
    /// normal constraint than ``q_i`` (Cuno et al. §4.1), and ``w_i = (w / d) d_i``.
    ///
    /// Parameters
    /// ----------
    /// points : (N, 3) float64
    ///     Points on the surface; N ≥ 4, not all in one plane, no duplicates.
    /// normals : (N, 3) float64
    ///     Outward normals, any non-zero length (they are normalised).
    /// d : float, optional
    ///     Offset of the normal constraints. Default: 0.0075 × the largest side of the points'
    ///     bounding box (0.015 for data spanning [-1, 1]³, as in the papers).
    /// w : float, optional
    ///     Value at the normal constraints. Default: 0.75 × d (Cuno's w/d = 3/4).
    /// kernel : {"triharmonic", "biharmonic", "thin_plate"}
    ///     Radial basis function: r³ (default), r, or r² log r.
    /// smoothing : float
    ///     Added to the diagonal for noisy data; 0 (default) interpolates exactly.
    /// memory_limit : int, optional
    ///     Refuse fits whose dense system needs more bytes than this (default 8 GiB).
    ///
    /// Returns
    /// -------
    /// VariationalSurface
    ///
    /// Raises
    /// ------
    /// ValueError
    ///     For wrong shapes, NaN/inf, fewer than 4 points, coplanar or duplicate points,
    ///     zero-length normals, a singular system or a system over the memory limit.
    #[staticmethod]
    #[pyo3(signature = (points, normals, *, d=None, w=None, kernel="triharmonic", smoothing=0.0, memory_limit=None))]
    #[allow(clippy::too_many_arguments)]
    fn fit(
        py: Python<'_>,
        points: &Bound<'_, PyAny>,
        normals: &Bound<'_, PyAny>,
        d: Option<f64>,
        w: Option<f64>,
        kernel: &str,
        smoothing: f64,
        memory_limit: Option<u64>,
    ) -> PyResult<Self> {
        let p = self::points(points, "points")?;
        let n = self::points(normals, "normals")?;
        if n.len() != p.len() {
            return Err(value_error(
                "normals",
                format!(
                    "need one normal per point: {} normals for {} points",
                    n.len(),
                    p.len()
                ),
            ));
        }
        let s = fit_settings(kernel, smoothing, memory_limit)?;
        let pl = placement(d, w);
        let surface = py.detach(move || VariationalSurface::fit(&p, &n, &pl, &s))?;
        Ok(PyVariationalSurface {
            inner: Arc::new(surface),
        })
    }

    /// Fits a surface to the vertices of a triangle mesh.
    ///
    /// Vertex normals are the area-weighted average of the adjacent faces' normals (faces
    /// counter-clockwise seen from outside). Vertices at identical positions are merged first.
    /// At sharp creases the normal constraint value is lowered to
    /// ``w_i = d_i · min(w/d, 0.9 cos θ_i)``, θ_i the largest angle between the vertex normal and
    /// an adjacent face's normal, so that ``|f|`` stays below the distance to the surface (needed by
    /// the octree polygonizer); on smooth meshes this changes nothing.
    ///
    /// Parameters
    /// ----------
    /// vertices : (V, 3) float64
    /// faces : (F, 3) int
    ///     Vertex indices of each triangle.
    /// d, w, kernel, smoothing, memory_limit
    ///     As for :meth:`fit`.
    ///
    /// Raises
    /// ------
    /// ValueError
    ///     For out-of-range or repeated indices, unused vertices, and everything :meth:`fit` refuses.
    #[staticmethod]
    #[pyo3(signature = (vertices, faces, *, d=None, w=None, kernel="triharmonic", smoothing=0.0, memory_limit=None))]
    #[allow(clippy::too_many_arguments)]
    fn from_mesh(
        py: Python<'_>,
        vertices: &Bound<'_, PyAny>,
        faces: &Bound<'_, PyAny>,
        d: Option<f64>,
        w: Option<f64>,
        kernel: &str,
        smoothing: f64,
        memory_limit: Option<u64>,
    ) -> PyResult<Self> {
        let v = points(vertices, "vertices")?;
        let f = triangles(faces, "faces")?;
        let s = fit_settings(kernel, smoothing, memory_limit)?;
        let pl = placement(d, w);
        let surface = py.detach(move || VariationalSurface::from_mesh(&v, &f, &pl, &s))?;
        Ok(PyVariationalSurface {
            inner: Arc::new(surface),
        })
    }

    /// Interpolates values at points (no normal constraints): f(points[i]) = values[i].
    ///
    /// Parameters
    /// ----------
    /// points : (N, 3) float64
    /// values : (N,) float64
    /// kernel, smoothing, memory_limit
    ///     As for :meth:`fit`.
    #[staticmethod]
    #[pyo3(signature = (points, values, *, kernel="triharmonic", smoothing=0.0, memory_limit=None))]
    fn interpolate(
        py: Python<'_>,
        points: &Bound<'_, PyAny>,
        values: &Bound<'_, PyAny>,
        kernel: &str,
        smoothing: f64,
        memory_limit: Option<u64>,
    ) -> PyResult<Self> {
        let p = self::points(points, "points")?;
        let v = self::values(values, "values")?;
        let s = fit_settings(kernel, smoothing, memory_limit)?;
        let surface = py.detach(move || VariationalSurface::interpolate(&p, &v, &s))?;
        Ok(PyVariationalSurface {
            inner: Arc::new(surface),
        })
    }

    /// f at points.
    ///
    /// Parameters
    /// ----------
    /// points : (N, 3) float64
    ///
    /// Returns
    /// -------
    /// values : (N,) float64
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        field_values(py, self.inner.as_ref(), points)
    }

    /// ∇f at points.
    ///
    /// Parameters
    /// ----------
    /// points : (N, 3) float64
    ///
    /// Returns
    /// -------
    /// gradients : (N, 3) float64
    fn gradient<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        field_gradients(py, self.inner.as_ref(), points)
    }

    /// Same as :meth:`evaluate`, so that the surface can be used where a callable is expected.
    fn __call__<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.evaluate(py, points)
    }

    /// (M, 3) float64: the RBF centres (boundary constraints first, then normal constraints).
    #[getter]
    fn centers<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        points_to_py(py, self.inner.centers().to_vec())
    }

    /// (M,) float64: the weights λ_j.
    #[getter]
    fn weights<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        values_to_py(py, self.inner.weights().to_vec())
    }

    /// (4,) float64: the polynomial [a, bx, by, bz] of f = Σ λ φ + a + b·x.
    #[getter]
    fn polynomial<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        values_to_py(py, self.inner.polynomial().to_vec())
    }

    /// dict with ``points`` (M, 3), ``values`` (M,), ``d`` (N,) per-data-point offsets, and
    /// ``boundary`` (int, number of boundary constraints N).
    #[getter]
    fn constraints<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let c = self.inner.constraints();
        let d = PyDict::new(py);
        d.set_item("points", points_to_py(py, c.points.clone())?)?;
        d.set_item("values", values_to_py(py, c.values.clone()))?;
        d.set_item("d", values_to_py(py, c.offsets.clone()))?;
        d.set_item("boundary", c.boundary)?;
        Ok(d)
    }

    /// str: the kernel's name.
    #[getter]
    fn kernel(&self) -> &'static str {
        self.inner.kernel().name()
    }

    /// float: largest ``|f(c_i) − v_i|`` over the constraints after the fit.
    #[getter]
    fn residual(&self) -> f64 {
        self.inner.residual()
    }

    /// (2, 3) float64: a cube holding the surface — centred on the data's bounding box, with
    /// side 1.2 × its largest side (a 10 % margin). The default ``bounds`` of
    /// :func:`implicitmesh.polygonize` (the papers place their models in a cube too).
    #[getter]
    fn bounds<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let (lo, hi) = self.inner.data_bounding_box();
        let c = (lo + hi) * 0.5;
        let half = DVec3::splat(0.6 * (hi - lo).max_element());
        points_to_py(py, vec![c - half, c + half])
    }

    fn __len__(&self) -> usize {
        self.inner.centers().len()
    }

    fn __repr__(&self) -> String {
        format!(
            "VariationalSurface(kernel={:?}, centers={}, residual={:.2e})",
            self.inner.kernel().name(),
            self.inner.centers().len(),
            self.inner.residual()
        )
    }
}
