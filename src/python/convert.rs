//! numpy in, numpy out: conversions and shape checks. Inputs are converted with
//! `numpy.asarray(x, dtype=float64)` (so lists, float32 and Fortran-ordered arrays are accepted)
//! and copied row by row through a strided view, never reinterpreted in place.

use super::errors::value_error;
use glam::DVec3;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

fn asarray<'py>(obj: &Bound<'py, PyAny>, dtype: &str) -> PyResult<Bound<'py, PyAny>> {
    let py = obj.py();
    let np = py.import("numpy")?;
    let kwargs = PyDict::new(py);
    kwargs.set_item("dtype", dtype)?;
    np.call_method("asarray", (obj,), Some(&kwargs))
}

/// An (N, 3) array of points, as float64.
pub fn points(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<DVec3>> {
    let arr = asarray(obj, "float64")
        .map_err(|e| value_error(name, format!("not convertible to a float64 array ({e})")))?;
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    if shape.len() != 2 || shape[1] != 3 {
        return Err(value_error(
            name,
            format!("expected an array of shape (N, 3), got shape {shape:?}"),
        ));
    }
    let a: PyReadonlyArray2<f64> = arr.extract()?;
    let view = a.as_array();
    Ok(view
        .rows()
        .into_iter()
        .map(|r| DVec3::new(r[0], r[1], r[2]))
        .collect())
}

/// An (N,) array of float64 values.
pub fn values(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<f64>> {
    let arr = asarray(obj, "float64")
        .map_err(|e| value_error(name, format!("not convertible to a float64 array ({e})")))?;
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    if shape.len() != 1 {
        return Err(value_error(
            name,
            format!("expected an array of shape (N,), got shape {shape:?}"),
        ));
    }
    let a: PyReadonlyArray1<f64> = arr.extract()?;
    Ok(a.as_array().iter().copied().collect())
}

/// An (F, 3) array of vertex indices, checked non-negative and below 2³².
pub fn triangles(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<[u32; 3]>> {
    let py = obj.py();
    let raw = py.import("numpy")?.call_method1("asarray", (obj,))?;
    let kind: String = raw.getattr("dtype")?.getattr("kind")?.extract()?;
    match kind.as_str() {
        "i" | "u" => {}
        "f" => {
            let all_integral: bool = py
                .import("numpy")?
                .call_method1(
                    "all",
                    (raw.call_method1("__eq__", (raw.call_method0("round")?,))?,),
                )?
                .extract()?;
            if !all_integral {
                return Err(value_error(name, "vertex indices must be integers"));
            }
        }
        _ => {
            return Err(value_error(
                name,
                format!("vertex indices must be integers, got dtype kind {kind:?}"),
            ))
        }
    }
    let arr = asarray(&raw, "int64")
        .map_err(|e| value_error(name, format!("not convertible to an integer array ({e})")))?;
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    if shape.len() != 2 || shape[1] != 3 {
        return Err(value_error(
            name,
            format!("expected an array of shape (F, 3), got shape {shape:?}"),
        ));
    }
    let a: PyReadonlyArray2<i64> = arr.extract()?;
    let view = a.as_array();
    let mut out = Vec::with_capacity(shape[0]);
    for (k, r) in view.rows().into_iter().enumerate() {
        let mut t = [0u32; 3];
        for c in 0..3 {
            let v = r[c];
            if v < 0 || v > u32::MAX as i64 {
                return Err(value_error(name, format!("face {k} has invalid index {v}")));
            }
            t[c] = v as u32;
        }
        out.push(t);
    }
    Ok(out)
}

/// (N, 3) float64 array from points.
pub fn points_to_py<'py>(py: Python<'py>, p: Vec<DVec3>) -> PyResult<Bound<'py, PyAny>> {
    let n = p.len();
    let flat: Vec<f64> = bytemuck::cast_slice::<DVec3, f64>(&p).to_vec();
    Ok(PyArray1::from_vec(py, flat).reshape([n, 3])?.into_any())
}

/// (F, 3) int64 array from triangles.
pub fn triangles_to_py<'py>(py: Python<'py>, t: &[[u32; 3]]) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<i64> = t.iter().flatten().map(|&v| v as i64).collect();
    Ok(PyArray1::from_vec(py, flat)
        .reshape([t.len(), 3])?
        .into_any())
}

/// (N,) float64 array.
pub fn values_to_py<'py>(py: Python<'py>, v: Vec<f64>) -> Bound<'py, PyAny> {
    PyArray1::from_vec(py, v).into_any()
}
