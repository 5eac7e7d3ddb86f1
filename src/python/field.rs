//! Fields the binding accepts: the core's own field classes, or any Python callable taking
//! (N, 3) float64 points and returning N values. A callable is only ever called from the thread
//! that called the polygonizer (never from a rayon worker), with the GIL re-acquired for the call.

use super::blob::PyBlobField;
use super::variational::PyVariationalSurface;
use crate::field::rbf::Fitted;
use crate::field::Field;
use glam::DVec3;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::{Arc, Mutex};

/// A Python callable as a field. The first exception it raises is kept and re-raised by the
/// binding; later calls then return NaN without calling Python, which stops the polygonizer.
pub struct CallableField {
    func: Py<PyAny>,
    error: Mutex<Option<PyErr>>,
}

impl CallableField {
    pub fn new(func: Py<PyAny>) -> Self {
        CallableField {
            func,
            error: Mutex::new(None),
        }
    }

    /// The exception raised by the callable, if any.
    pub fn take_error(&self) -> Option<PyErr> {
        self.error.lock().map(|mut e| e.take()).unwrap_or(None)
    }

    fn call(&self, py: Python<'_>, points: &[DVec3], out: &mut [f64]) -> PyResult<()> {
        let n = points.len();
        let flat: &[f64] = bytemuck::cast_slice(points);
        let arr = PyArray1::from_slice(py, flat).reshape([n, 3])?;
        let result = self.func.bind(py).call1((arr,))?;
        let np = py.import("numpy")?;
        let kwargs = PyDict::new(py);
        kwargs.set_item("dtype", "float64")?;
        let r = np.call_method("asarray", (result,), Some(&kwargs))?;
        let shape: Vec<usize> = r.getattr("shape")?.extract()?;
        let ok = (shape.len() == 1 && shape[0] == n)
            || (shape.len() == 2 && shape[0] == n && shape[1] == 1);
        if !ok {
            return Err(PyValueError::new_err(format!(
                "field: the callable must return one value per point, shape ({n},); got shape {} for {n} points",
                super::convert::python_shape(&shape)
            )));
        }
        let r = r.call_method1("reshape", (n,))?;
        let a: PyReadonlyArray1<f64> = r.extract()?;
        for (o, v) in out.iter_mut().zip(a.as_array().iter()) {
            *o = *v;
        }
        Ok(())
    }
}

impl Field for CallableField {
    fn value(&self, p: DVec3) -> f64 {
        let mut o = [0.0];
        self.values(&[p], &mut o);
        o[0]
    }

    fn values(&self, points: &[DVec3], out: &mut [f64]) {
        if points.is_empty() {
            return;
        }
        if self.error.lock().map(|e| e.is_some()).unwrap_or(true) {
            out.fill(f64::NAN);
            return;
        }
        let res = Python::attach(|py| self.call(py, points, out));
        if let Err(e) = res {
            if let Ok(mut slot) = self.error.lock() {
                slot.get_or_insert(e);
            }
            out.fill(f64::NAN);
        }
    }

    fn gradients(&self, points: &[DVec3], out: &mut [DVec3]) {
        crate::field::gradients_by_differences(self, points, 1e-6, out);
    }
}

/// A field argument resolved to something the core can run with the GIL released: take
/// [`FieldArg::as_field`] before `py.detach` and use only that reference inside.
pub enum FieldArg<'py> {
    Variational(Fitted),
    Blob(PyRef<'py, PyBlobField>),
    Callable(Arc<CallableField>),
}

impl<'py> FieldArg<'py> {
    pub fn extract(obj: &Bound<'py, PyAny>) -> PyResult<Self> {
        if let Ok(v) = obj.cast::<PyVariationalSurface>() {
            return Ok(FieldArg::Variational(v.get().inner.clone()));
        }
        if let Ok(b) = obj.cast::<PyBlobField>() {
            return Ok(FieldArg::Blob(b.try_borrow()?));
        }
        if obj.is_callable() {
            return Ok(FieldArg::Callable(Arc::new(CallableField::new(
                obj.clone().unbind(),
            ))));
        }
        Err(PyTypeError::new_err(format!(
            "field: expected a VariationalSurface, a BlobField or a callable taking (N, 3) float64 points and returning (N,) values, got {}",
            obj.get_type().name()?
        )))
    }

    /// The field as a core field (Sync, so the reference may cross `py.detach`).
    pub fn as_field(&self) -> &(dyn Field + '_) {
        match self {
            FieldArg::Variational(v) => v.as_field(),
            FieldArg::Blob(b) => &b.inner,
            FieldArg::Callable(c) => c.as_ref(),
        }
    }

    pub fn is_callable(&self) -> bool {
        matches!(self, FieldArg::Callable(_))
    }

    /// The exception a callable raised, to be raised instead of the core's error.
    pub fn take_error(&self) -> Option<PyErr> {
        match self {
            FieldArg::Callable(c) => c.take_error(),
            _ => None,
        }
    }
}
