//! `_core.estimate_normals`: [`crate::normals::estimate_normals`] on numpy arrays, with the GIL
//! released, Ctrl-C and progress (one unit per point of the local step).

use super::convert::{points_arg, points_to_py};
use super::errors::value_error;
use super::interrupt::{call, run};
use crate::normals::{estimate_normals as core_estimate, NormalSettings, Viewpoints};
use glam::DVec3;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

/// Unit normals of ``points``, consistently oriented and outward, and what the estimate found:
/// ``(normals, info)``, (N, 3) float64 and a dict (``patches``, ``bodies``, ``large_bodies``,
/// ``significant``, ``facing_away``). ``viewpoints`` is None, one (3,) point or (N, 3).
#[pyfunction]
#[pyo3(signature = (points, neighbours=20, viewpoints=None, progress=None))]
pub fn estimate_normals<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    neighbours: i64,
    viewpoints: Option<&Bound<'py, PyAny>>,
    progress: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let _call = call("estimate_normals");
    let neighbours = usize::try_from(neighbours).map_err(|_| {
        value_error(
            "neighbours",
            format!("must be at least 3, got {neighbours}"),
        )
    })?;
    let p = points_arg(points, "points")?;
    let views = viewpoints_arg(viewpoints)?;
    let settings = NormalSettings {
        neighbours,
        ..NormalSettings::default()
    };
    let p = p.as_slice();
    let views = views.as_viewpoints();
    let e = run(py, progress, false, || core_estimate(p, views, &settings))?;
    let info = PyDict::new(py);
    info.set_item("patches", e.patches)?;
    info.set_item("bodies", e.bodies)?;
    info.set_item("large_bodies", e.large_bodies)?;
    info.set_item("significant", e.significant)?;
    info.set_item("facing_away", e.facing_away)?;
    PyTuple::new(py, [points_to_py(py, e.normals)?, info.into_any()])
}

/// Viewpoints as given: none, one, or one per point.
pub enum ViewpointsArg<'py> {
    /// None given.
    None,
    /// One (3,) point.
    One(DVec3),
    /// One per point.
    PerPoint(super::convert::PointsArg<'py>),
}

impl ViewpointsArg<'_> {
    /// The core's view of them.
    pub fn as_viewpoints(&self) -> Viewpoints<'_> {
        match self {
            ViewpointsArg::None => Viewpoints::None,
            ViewpointsArg::One(v) => Viewpoints::One(*v),
            ViewpointsArg::PerPoint(v) => Viewpoints::PerPoint(v.as_slice()),
        }
    }
}

/// `viewpoints` as the user gives it: None, a (3,) point or (N, 3) points.
pub fn viewpoints_arg<'py>(v: Option<&Bound<'py, PyAny>>) -> PyResult<ViewpointsArg<'py>> {
    let Some(v) = v else {
        return Ok(ViewpointsArg::None);
    };
    let shape: Option<Vec<usize>> = v.getattr("shape").ok().and_then(|s| s.extract().ok());
    if shape.is_none() || shape.as_deref() == Some(&[3]) {
        match v.extract::<[f64; 3]>() {
            Ok(c) => return Ok(ViewpointsArg::One(DVec3::from_array(c))),
            Err(_) if shape.is_some() => {
                return Err(value_error("viewpoints", "expected (3,) or (N, 3) float64"))
            }
            Err(_) => {}
        }
    }
    Ok(ViewpointsArg::PerPoint(points_arg(v, "viewpoints")?))
}

/// Adds this file's functions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(estimate_normals, m)?)?;
    Ok(())
}
