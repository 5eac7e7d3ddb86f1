//! `_core.subdivide` and `_core.butterfly`: arguments converted (their ranges are the core's to
//! check), the GIL released around the core's subdivision, one (vertices, faces, normals[,
//! stats]) tuple per level out. The field may be any the binding accepts (see [`FieldArg`]): a
//! callable is wrapped in [`Differences`] for its gradients.

use super::convert::{points, points_to_py, triangles, triangles_to_py};
use super::errors::value_error;
use super::field::FieldArg;
use super::interrupt::run;
use crate::field::Differences;
use crate::mesh::Mesh;
use crate::subdivision::{self, LevelStats, SubdivisionSettings};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};

/// `value` as an unsigned count of type `T`; the error names the argument.
fn unsigned<T: TryFrom<i64>>(name: &str, value: i64) -> PyResult<T> {
    T::try_from(value).map_err(|_| {
        let reason = if value < 0 {
            "must not be negative"
        } else {
            "is too large"
        };
        value_error(name, format!("{reason}, got {value}"))
    })
}

fn control_mesh(vertices: &Bound<'_, PyAny>, faces: &Bound<'_, PyAny>) -> PyResult<Mesh> {
    Ok(Mesh {
        vertices: points(vertices, "vertices")?,
        triangles: triangles(faces, "faces")?,
        normals: vec![],
    })
}

fn stats_to_py<'py>(py: Python<'py>, s: &LevelStats) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("level", s.level)?;
    d.set_item("projected", s.projected)?;
    d.set_item("iterations_mean", s.iterations_mean)?;
    d.set_item("iterations_max", s.iterations_max)?;
    d.set_item("evaluations", s.evaluations)?;
    d.set_item("batches", s.batches)?;
    d.set_item("fallbacks", s.fallbacks)?;
    d.set_item("not_converged", s.not_converged)?;
    d.set_item("not_converged_max_abs_value", s.not_converged_max_abs_value)?;
    d.set_item("max_abs_value", s.max_abs_value)?;
    d.set_item("seconds", s.seconds)?;
    Ok(d)
}

fn mesh_tuple<'py>(
    py: Python<'py>,
    m: Mesh,
    stats: Option<&LevelStats>,
) -> PyResult<Bound<'py, PyTuple>> {
    let f = triangles_to_py(py, &m.triangles)?;
    let v = points_to_py(py, m.vertices)?;
    let n = points_to_py(py, m.normals)?;
    match stats {
        Some(s) => PyTuple::new(py, [v, f, n, stats_to_py(py, s)?.into_any()]),
        None => PyTuple::new(py, [v, f, n]),
    }
}

/// Subdivides a control mesh onto the zero set of a field (a VariationalSurface, a BlobField or
/// a callable, whose gradients are then taken by central differences with step ``step``, default
/// 1e-6 × the control mesh's largest side); one tuple ``(vertices, faces, normals, stats)`` per
/// level 0..levels. ``progress``, when given, is called with the count of vertices placed.
#[pyfunction]
#[pyo3(signature = (field, vertices, faces, levels, *, tolerance=None, max_steps=None, step=None, progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn subdivide<'py>(
    py: Python<'py>,
    field: &Bound<'py, PyAny>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    levels: i64,
    tolerance: Option<f64>,
    max_steps: Option<i64>,
    step: Option<f64>,
    progress: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyList>> {
    let _call = super::interrupt::call("subdivide");
    let field = FieldArg::extract(field)?;
    let levels = unsigned("levels", levels)?;
    let control = control_mesh(vertices, faces)?;
    let defaults = SubdivisionSettings::default();
    let settings = SubdivisionSettings {
        tolerance: tolerance.unwrap_or(defaults.tolerance),
        max_iterations: match max_steps {
            Some(m) => unsigned("max_steps", m)?,
            None => defaults.max_iterations,
        },
        ..defaults
    };
    if step.is_some() && !field.is_callable() {
        return Err(value_error(
            "step",
            "applies to callables only (the other fields have exact gradients)",
        ));
    }
    let f = field.as_field();
    let result = if field.is_callable() {
        let step = step.unwrap_or_else(|| subdivision::difference_step(&control));
        let values_only = Differences::new(f, step)?;
        run(py, progress, true, || {
            subdivision::subdivide(&values_only, &control, levels, &settings)
        })
    } else {
        run(py, progress, false, || {
            subdivision::subdivide(f, &control, levels, &settings)
        })
    };
    if let Some(e) = field.take_error() {
        return Err(e);
    }
    let out = PyList::empty(py);
    for (m, st) in result? {
        out.append(mesh_tuple(py, m, Some(&st))?)?;
    }
    Ok(out)
}

/// Modified butterfly subdivision with tension ``w``; one tuple ``(vertices, faces, normals)``
/// per level 0..levels. ``progress``, when given, is called with the count of vertices placed.
#[pyfunction]
#[pyo3(signature = (vertices, faces, levels, w, *, progress=None))]
pub fn butterfly<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    levels: i64,
    w: f64,
    progress: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyList>> {
    let _call = super::interrupt::call("butterfly");
    let levels = unsigned("levels", levels)?;
    let control = control_mesh(vertices, faces)?;
    let result = run(py, progress, false, move || {
        subdivision::butterfly(&control, levels, w)
    })?;
    let out = PyList::empty(py);
    for m in result {
        out.append(mesh_tuple(py, m, None)?)?;
    }
    Ok(out)
}

/// Adds this module's functions to `_core`.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(subdivide, m)?)?;
    m.add_function(wrap_pyfunction!(butterfly, m)?)?;
    Ok(())
}
