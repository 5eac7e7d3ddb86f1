//! `BlobField`: the Python class over the core's blob field.

use super::convert::{field_gradients, field_values, points, points_to_py, values, values_to_py};
use crate::field::blob::{self, BlobField, PerPrimitive};
use glam::DVec3;
use pyo3::prelude::*;

/// A scalar (float) or one value per primitive (array-like of shape (N,)).
fn per_primitive(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Result<f64, Vec<f64>>> {
    if let Ok(v) = obj.extract::<f64>() {
        return Ok(Ok(v));
    }
    Ok(Err(values(obj, name)?))
}

fn as_per(v: &Result<f64, Vec<f64>>) -> PerPrimitive<'_> {
    match v {
        Ok(s) => PerPrimitive::All(*s),
        Err(a) => PerPrimitive::Each(a),
    }
}

/// A blob field: point primitives with the compact kernel A·(1 − d²/R²)² (Triquet et al.),
/// surface at potential = ``threshold``; as a field, ``threshold − potential`` (negative inside).
///
/// Parameters
/// ----------
/// centers : (N, 3) float64
///     Primitive positions.
/// radii : float or (N,) float64
///     Radii of influence R (positive).
/// strengths : float or (N,) float64
///     Scale factors A. Default 1.0.
/// threshold : float
///     Potential of the surface (positive). Default 0.5.
/// voxel_size : float, optional
///     Side of the acceleration voxels as a multiple of the mean radius (default 0.5, chosen
///     from the sweep in ``notebooks/triquet_blobs.ipynb``).
#[pyclass(name = "BlobField", module = "implicitmesh")]
pub struct PyBlobField {
    pub inner: BlobField,
}

#[pymethods]
impl PyBlobField {
    #[new]
    #[pyo3(signature = (centers, radii, strengths=None, threshold=0.5, *, voxel_size=None))]
    fn new(
        py: Python<'_>,
        centers: &Bound<'_, PyAny>,
        radii: &Bound<'_, PyAny>,
        strengths: Option<&Bound<'_, PyAny>>,
        threshold: f64,
        voxel_size: Option<f64>,
    ) -> PyResult<Self> {
        let c = points(centers, "centers")?;
        let r = per_primitive(radii, "radii")?;
        let a = match strengths {
            Some(s) => per_primitive(s, "strengths")?,
            None => Ok(1.0),
        };
        let settings = blob::BlobSettings {
            voxel_size: voxel_size.unwrap_or(blob::BlobSettings::default().voxel_size),
        };
        let inner =
            py.detach(|| BlobField::new(&c, as_per(&r), as_per(&a), threshold, settings))?;
        Ok(PyBlobField { inner })
    }

    /// Moves the primitives; optionally new radii and strengths (required when the number of
    /// centers changes). Rebuilds the voxel lists in place, without reallocating when the
    /// number of primitives stays the same.
    ///
    /// Parameters
    /// ----------
    /// centers : (N, 3) float64
    /// radii, strengths : float or (N,) float64, optional
    #[pyo3(signature = (centers, radii=None, strengths=None))]
    fn update(
        &mut self,
        py: Python<'_>,
        centers: &Bound<'_, PyAny>,
        radii: Option<&Bound<'_, PyAny>>,
        strengths: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let c = points(centers, "centers")?;
        let r = radii.map(|r| per_primitive(r, "radii")).transpose()?;
        let a = strengths
            .map(|a| per_primitive(a, "strengths"))
            .transpose()?;
        let inner = &mut self.inner;
        py.detach(|| inner.update(&c, r.as_ref().map(as_per), a.as_ref().map(as_per)))?;
        Ok(())
    }

    /// ``threshold − potential`` at points: (N, 3) float64 → (N,) float64.
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        field_values(py, &self.inner, points)
    }

    /// The potential Σ A (1 − d²/R²)² at points: (N, 3) float64 → (N,) float64.
    fn potential<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let p = self::points(points, "points")?;
        crate::error::check_finite_points("points", &p)?;
        let b = &self.inner;
        let out = py.detach(|| p.iter().map(|q| b.potential(*q)).collect::<Vec<f64>>());
        Ok(values_to_py(py, out))
    }

    /// Gradient of ``threshold − potential``: (N, 3) float64 → (N, 3) float64.
    fn gradient<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        field_gradients(py, &self.inner, points)
    }

    fn __call__<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.evaluate(py, points)
    }

    /// (N, 3) float64: the primitive positions.
    #[getter]
    fn centers<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        points_to_py(py, self.inner.centers().to_vec())
    }
    /// (N,) float64: radii of influence.
    #[getter]
    fn radii<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        values_to_py(py, self.inner.radii().to_vec())
    }
    /// (N,) float64: strengths A.
    #[getter]
    fn strengths<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        values_to_py(py, self.inner.strengths().to_vec())
    }
    /// float: the potential of the surface.
    #[getter]
    fn threshold(&self) -> f64 {
        self.inner.threshold()
    }
    /// float: side of the acceleration voxels (absolute).
    #[getter]
    fn voxel_size(&self) -> f64 {
        self.inner.grid().voxel_size()
    }
    /// (3,) int: voxels per axis.
    #[getter]
    fn voxel_dims(&self) -> [u32; 3] {
        self.inner.grid().dims()
    }
    /// (2, 3) float64: a cube holding every sphere of influence with a 5 % margin (the surface
    /// lies strictly inside it, so meshes over it are closed).
    #[getter]
    fn bounds<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let (lo, hi) = self
            .inner
            .bounding_box()
            .unwrap_or((DVec3::splat(-1.0), DVec3::splat(1.0)));
        let c = (lo + hi) * 0.5;
        let half = DVec3::splat(0.5 * 1.1 * (hi - lo).max_element());
        points_to_py(py, vec![c - half, c + half])
    }
    /// Pickling: the constructor's arguments, which rebuild the same field.
    #[allow(clippy::type_complexity)]
    fn __getnewargs_ex__<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(
        (Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>, f64),
        Bound<'py, pyo3::types::PyDict>,
    )> {
        let kwargs = pyo3::types::PyDict::new(py);
        kwargs.set_item("voxel_size", self.inner.settings().voxel_size)?;
        Ok((
            (
                self.centers(py)?,
                self.radii(py),
                self.strengths(py),
                self.threshold(),
            ),
            kwargs,
        ))
    }
    fn __len__(&self) -> usize {
        self.inner.centers().len()
    }
    fn __repr__(&self) -> String {
        format!(
            "BlobField(primitives={}, threshold={})",
            self.inner.centers().len(),
            self.inner.threshold()
        )
    }
}
