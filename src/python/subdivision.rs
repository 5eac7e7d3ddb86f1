//! `_core.subdivide` and `_core.butterfly`: argument checks, the GIL released around the core's
//! subdivision, one (vertices, faces, normals[, stats]) tuple per level out. The field may be any
//! the binding accepts (see [`FieldArg`]): a callable gets difference gradients.

use super::convert::{points, points_to_py, triangles, triangles_to_py};
use super::errors::value_error;
use super::field::FieldArg;
use super::interrupt::run;
use super::variational::Fitted;
use crate::mesh::Mesh;
use crate::polygonize::subdivision::{self, Settings, SubdivisionStats, MAX_LEVELS};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};

fn parse_levels(levels: i64) -> PyResult<usize> {
    if levels < 0 || levels > MAX_LEVELS as i64 {
        return Err(value_error(
            "levels",
            format!("must be between 0 and {MAX_LEVELS}, got {levels}"),
        ));
    }
    Ok(levels as usize)
}

fn control_mesh(vertices: &Bound<'_, PyAny>, faces: &Bound<'_, PyAny>) -> PyResult<Mesh> {
    Ok(Mesh {
        vertices: points(vertices, "vertices")?,
        triangles: triangles(faces, "faces")?,
        normals: vec![],
    })
}

fn stats_to_py<'py>(py: Python<'py>, s: &SubdivisionStats) -> PyResult<Bound<'py, PyDict>> {
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
    stats: Option<&SubdivisionStats>,
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
/// level 0..levels.
#[pyfunction]
#[pyo3(signature = (field, vertices, faces, levels, *, tolerance=None, max_steps=None, step=None))]
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
) -> PyResult<Bound<'py, PyList>> {
    let field = FieldArg::extract(field)?;
    let levels = parse_levels(levels)?;
    let control = control_mesh(vertices, faces)?;
    let mut settings = Settings::default();
    if let Some(t) = tolerance {
        settings.tolerance = t;
    }
    if let Some(m) = max_steps {
        if !(1..=10_000).contains(&m) {
            return Err(value_error(
                "max_steps",
                format!("must be between 1 and 10000, got {m}"),
            ));
        }
        settings.max_iterations = m as u32;
    }
    if let Some(h) = step {
        if !(h.is_finite() && h > 0.0) {
            return Err(value_error(
                "step",
                format!("must be finite and positive, got {h}"),
            ));
        }
        if !field.is_callable() {
            return Err(value_error(
                "step",
                "applies to callables only (the other fields have exact gradients)",
            ));
        }
    }
    let result = match &field {
        FieldArg::Variational(Fitted::Global(s)) => {
            let s = s.clone();
            run(py, None, false, move || {
                subdivision::subdivide_surface(&s, &control, levels, &settings)
            })
        }
        FieldArg::Variational(Fitted::Partition(_)) | FieldArg::Blob(_) => {
            let f = field.as_field();
            run(py, None, false, || {
                subdivision::subdivide(f, &control, levels, &settings)
            })
        }
        FieldArg::Callable(_) => {
            let f = field.as_field();
            run(py, None, true, || {
                subdivision::subdivide_by_differences(f, &control, levels, &settings, step)
            })
        }
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
/// per level 0..levels.
#[pyfunction]
#[pyo3(signature = (vertices, faces, levels, w))]
pub fn butterfly<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    levels: i64,
    w: f64,
) -> PyResult<Bound<'py, PyList>> {
    let levels = parse_levels(levels)?;
    let control = control_mesh(vertices, faces)?;
    let result = run(py, None, false, move || {
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
