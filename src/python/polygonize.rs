//! `_core.polygonize`: argument checks, the GIL released around the polygonizer, numpy out.

use super::convert::{flat_faces, points, MeshBuffers};
use super::errors::value_error;
use super::field::FieldArg;
use super::interrupt::run;
use crate::field::{Differences, Field};
use crate::lattice::Lattice;
use crate::polygonize::tracking::{Components, TrackingSettings};
use crate::polygonize::weld::boundary_edges;
use crate::polygonize::{
    difference_step, octree, tracking, Ambiguity, Method, Polygonized, Settings, Stats,
};
use numpy::PyArrayMethods;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyTuple};

pub fn parse_ambiguity(s: &str) -> PyResult<Ambiguity> {
    match s.to_ascii_lowercase().as_str() {
        "separate" => Ok(Ambiguity::Separate),
        "join" => Ok(Ambiguity::Join),
        _ => Err(value_error(
            "ambiguity",
            format!("expected \"separate\" or \"join\", got {s:?}"),
        )),
    }
}

/// Cells per axis from an int or a sequence of three ints.
pub fn parse_resolution(obj: &Bound<'_, PyAny>) -> PyResult<[u32; 3]> {
    let one = |o: &Bound<'_, PyAny>| -> PyResult<u32> {
        if o.is_instance_of::<PyBool>() {
            return Err(value_error("resolution", "must be an integer, got a bool"));
        }
        let v: i128 = o.extract().map_err(|_| {
            value_error(
                "resolution",
                format!("must be an integer or three integers, got {o}"),
            )
        })?;
        if v <= 0 {
            return Err(value_error(
                "resolution",
                format!("must be positive, got {v}"),
            ));
        }
        if v > crate::lattice::MAX_CELLS_PER_AXIS as i128 {
            return Err(value_error(
                "resolution",
                format!(
                    "{v} cells per axis is over the maximum of {}",
                    crate::lattice::MAX_CELLS_PER_AXIS
                ),
            ));
        }
        Ok(v as u32)
    };
    if let Ok(v) = one(obj) {
        return Ok([v; 3]);
    }
    if obj.is_instance_of::<pyo3::types::PyString>() {
        return Err(value_error(
            "resolution",
            "must be an integer or three integers",
        ));
    }
    let items: Vec<Bound<'_, PyAny>> = match obj.try_iter() {
        Ok(it) => it.collect::<PyResult<_>>()?,
        Err(_) => return one(obj).map(|v| [v; 3]),
    };
    if items.len() != 3 {
        return Err(value_error(
            "resolution",
            format!("expected one integer or three, got {} values", items.len()),
        ));
    }
    Ok([one(&items[0])?, one(&items[1])?, one(&items[2])?])
}

pub fn parse_lattice(
    bounds: &Bound<'_, PyAny>,
    resolution: &Bound<'_, PyAny>,
) -> PyResult<Lattice> {
    let b = points(bounds, "bounds").map_err(|_| {
        value_error(
            "bounds",
            "expected [[xmin, ymin, zmin], [xmax, ymax, zmax]] (shape (2, 3))",
        )
    })?;
    if b.len() != 2 {
        return Err(value_error(
            "bounds",
            format!("expected shape (2, 3), got ({}, 3)", b.len()),
        ));
    }
    let cells = parse_resolution(resolution)?;
    let single =
        resolution.is_instance_of::<pyo3::types::PyInt>() || resolution.extract::<i128>().is_ok();
    if single {
        Ok(Lattice::cubic(b[0], b[1], cells[0])?)
    } else {
        Ok(Lattice::new(b[0], b[1], cells)?)
    }
}

pub fn stats_to_py<'py>(
    py: Python<'py>,
    s: &Stats,
    lattice: &Lattice,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("evaluations", s.evaluations)?;
    d.set_item("normal_evaluations", s.normal_evaluations)?;
    d.set_item("projection_evaluations", s.projection_evaluations)?;
    d.set_item("lattice_points", s.lattice_points)?;
    d.set_item("evaluation_percent", s.evaluation_percent())?;
    d.set_item("cells_visited", s.cells_visited)?;
    d.set_item("cells_crossed", s.cells_crossed)?;
    d.set_item("cells_repaired", s.cells_repaired)?;
    d.set_item("cells_per_level", s.cells_per_level.clone())?;
    let secs = PyDict::new(py);
    for (k, v) in &s.seconds {
        secs.set_item(*k, *v)?;
    }
    secs.set_item("total", s.total_seconds())?;
    d.set_item("seconds", secs)?;
    d.set_item("resolution", PyTuple::new(py, lattice.cells())?)?;
    d.set_item(
        "bounds",
        [
            [lattice.origin().x, lattice.origin().y, lattice.origin().z],
            [lattice.max().x, lattice.max().y, lattice.max().z],
        ],
    )?;
    Ok(d)
}

/// The lattice :func:`polygonize` builds from ``bounds`` and ``resolution``, as
/// ``(cells (3,) int, origin (3,) float, cell (3,) float)``: lattice point ``[i, j, k]`` is at
/// ``origin + [i, j, k] * cell`` (each coordinate one product and one sum, as the core computes
/// it).
#[pyfunction]
pub fn lattice(
    bounds: &Bound<'_, PyAny>,
    resolution: &Bound<'_, PyAny>,
) -> PyResult<([u32; 3], [f64; 3], [f64; 3])> {
    let l = parse_lattice(bounds, resolution)?;
    Ok((l.cells(), l.base().to_array(), l.cell().to_array()))
}

/// Cell range `[[i0, j0, k0], [i1, j1, k1]]` of a window (checked against the lattice by
/// [`Lattice::window`]).
fn parse_window(obj: &Bound<'_, PyAny>) -> PyResult<[[u32; 3]; 2]> {
    let bad = || {
        value_error(
            "window",
            "expected cell indices [[i0, j0, k0], [i1, j1, k1]] (non-negative integers)",
        )
    };
    let rows: Vec<Vec<i128>> = obj.extract().map_err(|_| bad())?;
    if rows.len() != 2 || rows.iter().any(|r| r.len() != 3) {
        return Err(bad());
    }
    let mut out = [[0u32; 3]; 2];
    for (o, r) in out.iter_mut().zip(&rows) {
        for (oa, &v) in o.iter_mut().zip(r) {
            *oa = u32::try_from(v).map_err(|_| bad())?;
        }
    }
    Ok(out)
}

/// Settings shared by every method, from the Python arguments.
fn shared_settings(
    ambiguity: &str,
    normals: bool,
    project: bool,
    batch_size: usize,
    memory_limit: Option<u64>,
) -> PyResult<Settings> {
    if batch_size == 0 {
        return Err(value_error("batch_size", "must be positive"));
    }
    let defaults = Settings::default();
    Ok(Settings {
        ambiguity: parse_ambiguity(ambiguity)?,
        normals,
        project,
        batch: batch_size,
        memory_limit: memory_limit.unwrap_or(defaults.memory_limit),
        ..defaults
    })
}

/// The field as the polygonizers take it: a callable only has values, so its normals come from
/// central differences with the core's step for `lattice` ([`difference_step`]).
fn polygonizer_field<'a>(field: &'a FieldArg, lattice: &Lattice) -> PyResult<Box<dyn Field + 'a>> {
    let f = field.as_field();
    Ok(if field.is_callable() {
        Box::new(Differences::new(f, difference_step(lattice))?)
    } else {
        Box::new(f)
    })
}

/// Tracking settings: `common`, and the seeds given (``seeds``, (N, 3) points) or the field's
/// own, as [`TrackingSettings::for_field`] decides.
fn tracking_settings(
    f: &dyn Field,
    seeds: Option<&Bound<'_, PyAny>>,
    lattice: &Lattice,
    common: Settings,
) -> PyResult<TrackingSettings> {
    let seeds = seeds.map(|s| points(s, "seeds")).transpose()?;
    Ok(TrackingSettings::for_field(f, lattice, common, seeds)?)
}

/// Triangles as a flat vector, without a copy when the allocation allows it.
fn flat_u32(t: Vec<[u32; 3]>) -> Vec<u32> {
    match bytemuck::allocation::try_cast_vec::<[u32; 3], u32>(t) {
        Ok(v) => v,
        Err((_, t)) => bytemuck::cast_slice::<[u32; 3], u32>(&t).to_vec(),
    }
}

fn mesh_to_py<'py>(
    py: Python<'py>,
    mesh: MeshBuffers,
    stats: &Stats,
    lattice: &Lattice,
    method: &str,
) -> PyResult<Bound<'py, PyTuple>> {
    let stats_py = stats_to_py(py, stats, lattice)?;
    stats_py.set_item("method", method)?;
    let [v, f, n] = mesh.into_py_arrays(py)?;
    PyTuple::new(py, [v, f, n, stats_py.into_any()])
}

/// Methods of [`polygonize`].
const METHODS: [&str; 4] = ["dense", "sparse", "octree", "tracking"];

fn unknown_method(method: &str) -> PyErr {
    value_error(
        "method",
        format!(
            "unknown method {method:?}; available: {}",
            METHODS.map(|m| format!("{m:?}")).join(", ")
        ),
    )
}

/// Low-level polygonizer entry point; use :func:`implicitmesh.polygonize`.
///
/// ``window=[[i0, j0, k0], [i1, j1, k1]]`` polygonizes only the cells ``i0 <= i < i1`` (and so
/// on) of the lattice, with the vertices the whole lattice gives there, bit for bit (what
/// :func:`implicitmesh.distributed.polygonize` runs per tile).
///
/// ``boundary=True`` (any method; for ``"tracking"`` a :class:`BlobField`) returns a tile as
/// :func:`weld_tiles` takes it: the faces as ``uint32`` (a tile has fewer than 2³² vertices),
/// and also the vertices on lattice edges in the window's boundary faces (the whole lattice's
/// faces without ``window``), which the neighbouring windows share: their indices ``(B,)
/// uint32`` and their edges' keys ``(B,) uint64`` in the whole lattice's numbering, what
/// :func:`weld_tiles` joins them by.
///
/// Returns ``(vertices (V, 3) float64, faces (F, 3), normals (V, 3) float64 or (0, 3), stats
/// dict, boundary, keys)``: faces ``int64`` and ``boundary`` and ``keys`` None without
/// ``boundary``; with it, faces ``uint32``, ``boundary (B,) uint32`` and ``keys (B,) uint64``.
#[pyfunction]
#[pyo3(signature = (field, bounds, resolution, *, method="dense", ambiguity="separate", normals=true, project=false, batch_size=262144, memory_limit=None, start_level=None, safety=None, corner_test=None, seeds=None, progress=None, window=None, boundary=false))]
#[allow(clippy::too_many_arguments)]
pub fn polygonize<'py>(
    py: Python<'py>,
    field: &Bound<'py, PyAny>,
    bounds: &Bound<'py, PyAny>,
    resolution: &Bound<'py, PyAny>,
    method: &str,
    ambiguity: &str,
    normals: bool,
    project: bool,
    batch_size: usize,
    memory_limit: Option<u64>,
    start_level: Option<u32>,
    safety: Option<f64>,
    corner_test: Option<bool>,
    seeds: Option<&Bound<'py, PyAny>>,
    progress: Option<&Bound<'py, PyAny>>,
    window: Option<&Bound<'py, PyAny>>,
    boundary: bool,
) -> PyResult<Bound<'py, PyTuple>> {
    let _call = super::interrupt::call("polygonize");
    let field = FieldArg::extract(field)?;
    let mut lattice = parse_lattice(bounds, resolution)?;
    let mut cells = [[0; 3], lattice.cells()];
    if let Some(w) = window {
        cells = parse_window(w)?;
        lattice = lattice.window(cells[0], cells[1])?;
    }
    let settings = Settings {
        keys: boundary,
        ..shared_settings(ambiguity, normals, project, batch_size, memory_limit)?
    };
    let name = method.to_ascii_lowercase();
    if !METHODS.contains(&name.as_str()) {
        return Err(unknown_method(&name));
    }
    if name != "octree" {
        for (arg, given) in [
            ("start_level", start_level.is_some()),
            ("safety", safety.is_some()),
            ("corner_test", corner_test.is_some()),
        ] {
            if given {
                return Err(value_error(arg, "applies to method=\"octree\" only"));
            }
        }
    }
    if name != "tracking" && seeds.is_some() {
        return Err(value_error(
            "seeds",
            "seeds apply to method=\"tracking\" only",
        ));
    }
    let f = &*polygonizer_field(&field, &lattice)?;
    let method = match name.as_str() {
        "dense" => Method::Dense(settings),
        "sparse" => Method::Sparse(settings),
        "octree" => {
            let od = octree::OctreeSettings::default();
            Method::Octree(octree::OctreeSettings {
                common: settings,
                start_level: start_level.or(od.start_level),
                safety: safety.or(od.safety),
                corner_test: corner_test.unwrap_or(od.corner_test),
            })
        }
        _ => {
            let ts = tracking_settings(f, seeds, &lattice, settings)?;
            if boundary && ts.components != Components::All {
                return Err(value_error(
                    "boundary",
                    "with method=\"tracking\" needs a BlobField (whose every component is found)",
                ));
            }
            Method::Tracking(ts)
        }
    };
    let result = run(py, progress, field.is_callable(), || {
        crate::polygonize::polygonize(f, &lattice, &method)
    });
    if let Some(e) = field.take_error() {
        return Err(e);
    }
    let Polygonized {
        mut mesh,
        keys,
        stats,
    } = result?;
    let tile = keys.map(|keys| {
        let b = boundary_edges(&keys, cells);
        (flat_u32(std::mem::take(&mut mesh.triangles)), b)
    });
    let out = mesh_to_py(py, MeshBuffers::new(mesh), &stats, &lattice, method.name())?;
    let mut items: Vec<Bound<'py, PyAny>> = out.iter().collect();
    match tile {
        None => items.extend([py.None().into_bound(py), py.None().into_bound(py)]),
        Some((faces, (b, k))) => {
            let n = faces.len() / 3;
            items[1] = numpy::PyArray1::from_vec(py, faces)
                .reshape([n, 3])?
                .into_any();
            items.push(numpy::PyArray1::from_vec(py, b).into_any());
            items.push(numpy::PyArray1::from_vec(py, k).into_any());
        }
    }
    PyTuple::new(py, items)
}

/// Projects the vertices of a mesh made over the lattice of ``bounds`` and ``resolution``
/// onto the field's zero set as ``polygonize(..., project=True)`` does (one Newton step of at
/// most half a cell), with normals at the moved vertices when ``normals``. What
/// :func:`implicitmesh.distributed.polygonize` runs on the welded mesh.
///
/// Returns ``(vertices (V, 3) float64, faces (F, 3) int64, normals (V, 3) float64 or (0, 3),
/// stats dict)``.
#[pyfunction]
#[pyo3(signature = (field, bounds, resolution, vertices, faces, *, normals=true, batch_size=262144, progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn project_mesh<'py>(
    py: Python<'py>,
    field: &Bound<'py, PyAny>,
    bounds: &Bound<'py, PyAny>,
    resolution: &Bound<'py, PyAny>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    normals: bool,
    batch_size: usize,
    progress: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let _call = super::interrupt::call("project_mesh");
    let field = FieldArg::extract(field)?;
    let lattice = parse_lattice(bounds, resolution)?;
    let settings = shared_settings("separate", normals, true, batch_size, None)?;
    let mut mesh = crate::mesh::Mesh {
        vertices: points(vertices, "vertices")?,
        triangles: super::convert::triangles(faces, "faces")?,
        normals: Vec::new(),
    };
    crate::error::check_finite_points("vertices", &mesh.vertices)?;
    let nv = mesh.vertices.len();
    if mesh.triangles.iter().flatten().any(|&i| i as usize >= nv) {
        return Err(value_error(
            "faces",
            format!("indices must be below the {nv} vertices"),
        ));
    }
    let f = &*polygonizer_field(&field, &lattice)?;
    let on_caller = field.is_callable();
    let result = run(py, progress, on_caller, || {
        let mut stats = Stats::default();
        crate::polygonize::finish_mesh(f, &mut mesh, &lattice, &settings, &mut stats)?;
        Ok((MeshBuffers::new(mesh), stats))
    });
    if let Some(e) = field.take_error() {
        return Err(e);
    }
    let (mesh, stats) = result?;
    mesh_to_py(py, mesh, &stats, &lattice, "project")
}

/// Surface tracking with caches kept between calls (Triquet et al.): for animation, move the
/// field and call :meth:`polygonize` again; in steady state nothing is reallocated.
#[pyclass(name = "Tessellator", module = "implicitmesh")]
pub struct PyTessellator {
    inner: tracking::Tessellator,
}

#[pymethods]
impl PyTessellator {
    #[new]
    fn new() -> Self {
        PyTessellator {
            inner: tracking::Tessellator::new(),
        }
    }

    /// Tracks the surface; see :meth:`implicitmesh.Tessellator.polygonize`.
    #[pyo3(signature = (field, bounds, resolution, *, seeds=None, ambiguity="separate", normals=true, batch_size=262144, memory_limit=None, blocks=true, progress=None))]
    #[allow(clippy::too_many_arguments)]
    fn polygonize<'py>(
        &mut self,
        py: Python<'py>,
        field: &Bound<'py, PyAny>,
        bounds: &Bound<'py, PyAny>,
        resolution: &Bound<'py, PyAny>,
        seeds: Option<&Bound<'py, PyAny>>,
        ambiguity: &str,
        normals: bool,
        batch_size: usize,
        memory_limit: Option<u64>,
        blocks: bool,
        progress: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let _call = super::interrupt::call("Tessellator.polygonize");
        let field = FieldArg::extract(field)?;
        let lattice = parse_lattice(bounds, resolution)?;
        let settings = shared_settings(ambiguity, normals, false, batch_size, memory_limit)?;
        let f = &*polygonizer_field(&field, &lattice)?;
        let ts = tracking_settings(f, seeds, &lattice, settings)?;
        let tess = &mut self.inner;
        let result = run(py, progress, field.is_callable(), || {
            tess.track::<_, i64>(f, &lattice, &ts, blocks)
                .map(|(mesh, faces, stats)| {
                    (MeshBuffers::with_faces(mesh, flat_faces(faces)), stats)
                })
        });
        if let Some(e) = field.take_error() {
            return Err(e);
        }
        let (mesh, stats) = result?;
        mesh_to_py(py, mesh, &stats, &lattice, "tracking")
    }

    /// Bytes held by the caches and buffers.
    #[getter]
    fn capacity_bytes(&self) -> usize {
        self.inner.capacity_bytes()
    }
}
