//! `_core.weld_tiles`: the tiles' numpy arrays read in place, the GIL released around the weld.

use super::convert::{check_rows_of_three, flat_faces, flatten_points, MeshBuffers};
use super::errors::value_error;
use super::interrupt::run;
use crate::lattice::Lattice;
use crate::polygonize::weld::rows::{room, write as rows_write, Rows};
use crate::polygonize::weld::{weld, Seams, StreamedWeld, Tile, TilePlan, WeldPlan, Welded};
use glam::DVec3;
use numpy::{
    IntoPyArray, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyReadwriteArray2,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

/// `numpy.require(obj, dtype, "CA")`: C-contiguous and aligned, copied only when it is not.
fn required<'py>(
    obj: &Bound<'py, PyAny>,
    dtype: &str,
    name: &'static str,
) -> PyResult<Bound<'py, PyAny>> {
    let np = obj.py().import("numpy")?;
    np.call_method1("require", (obj, dtype, "CA"))
        .map_err(|e| value_error(name, format!("not convertible to a {dtype} array ({e})")))
}

/// [`required`] as an `(N, 3)` array borrowed read-only.
fn rows<'py, T: numpy::Element>(
    obj: &Bound<'py, PyAny>,
    dtype: &str,
    name: &'static str,
) -> PyResult<PyReadonlyArray2<'py, T>> {
    let a = required(obj, dtype, name)?;
    check_rows_of_three(&a, name)?;
    a.extract()
}

/// [`required`] as a one-dimensional array borrowed read-only.
fn column<'py, T: numpy::Element>(
    obj: &Bound<'py, PyAny>,
    dtype: &str,
    name: &'static str,
) -> PyResult<PyReadonlyArray1<'py, T>> {
    let a = required(obj, dtype, name)?;
    a.extract().map_err(|_| {
        value_error(
            name,
            format!("expected a one-dimensional array, got shape {}", shape(&a)),
        )
    })
}

/// A tile's triangles as the weld reads them: a uint32 array in place, any other integer
/// array converted (an index outside `0..2³²` refused naming `faces`).
enum Faces<'py> {
    Borrowed(PyReadonlyArray2<'py, u32>),
    Converted(Vec<[u32; 3]>),
}

impl<'py> Faces<'py> {
    fn new(obj: &Bound<'py, PyAny>) -> PyResult<Self> {
        let np = obj.py().import("numpy")?;
        let a = np
            .call_method1("asarray", (obj,))
            .map_err(|e| value_error("faces", format!("not an array ({e})")))?;
        if a.getattr("dtype")?.eq(np.getattr("uint32")?)? {
            return Ok(Faces::Borrowed(rows::<u32>(&a, "uint32", "faces")?));
        }
        let wide = rows::<i64>(&a, "int64", "faces")?;
        let flat = wide.as_slice()?;
        if let Some(bad) = flat.iter().find(|&&i| u32::try_from(i).is_err()) {
            return Err(value_error(
                "faces",
                format!("vertex index {bad} is outside 0..2³²"),
            ));
        }
        Ok(Faces::Converted(
            flat.chunks_exact(3)
                .map(|t| [t[0] as u32, t[1] as u32, t[2] as u32])
                .collect(),
        ))
    }

    fn rows(&self) -> PyResult<&[[u32; 3]]> {
        Ok(match self {
            Faces::Borrowed(a) => bytemuck::cast_slice(a.as_slice()?),
            Faces::Converted(v) => v,
        })
    }
}

/// `obj.shape` as Python prints it.
fn shape(obj: &Bound<'_, PyAny>) -> String {
    obj.getattr("shape")
        .map_or_else(|_| "?".into(), |s| s.to_string())
}

/// The whole lattice from ``cells``, ``origin`` and ``cell`` (as :func:`lattice` gives them),
/// checked by [`Lattice::from_cells`].
fn whole_lattice(cells: [u32; 3], origin: [f64; 3], cell: [f64; 3]) -> PyResult<Lattice> {
    Ok(Lattice::from_cells(
        DVec3::from(origin),
        DVec3::from(cell),
        cells,
    )?)
}

/// One tile's arrays as the weld reads them (numpy arrays borrowed in place, converted only
/// where their type or layout is not the weld's).
type TileArrays<'py> = (
    [[u32; 3]; 2],
    PyReadonlyArray2<'py, f64>,
    Faces<'py>,
    PyReadonlyArray2<'py, f64>,
    PyReadonlyArray1<'py, u32>,
    PyReadonlyArray1<'py, u64>,
);

/// Reads a tile's `[window, vertices, faces, normals, boundary, keys]`.
fn tile_arrays<'py>(parts: [&Bound<'py, PyAny>; 6]) -> PyResult<TileArrays<'py>> {
    let [window, vertices, faces, normals, boundary, keys] = parts;
    let window: [[u32; 3]; 2] = window
        .extract()
        .map_err(|_| value_error("window", "expected [[i0, j0, k0], [i1, j1, k1]] of cells"))?;
    Ok((
        window,
        rows::<f64>(vertices, "float64", "vertices")?,
        Faces::new(faces)?,
        rows::<f64>(normals, "float64", "normals")?,
        column::<u32>(boundary, "uint32", "boundary")?,
        column::<u64>(keys, "uint64", "keys")?,
    ))
}

/// The core's view of [`TileArrays`].
fn as_tile<'a>(a: &'a TileArrays<'_>) -> PyResult<Tile<'a>> {
    let (window, v, f, n, b, k) = a;
    Ok(Tile {
        window: *window,
        vertices: bytemuck::cast_slice(v.as_slice()?),
        faces: f.rows()?,
        normals: bytemuck::cast_slice(n.as_slice()?),
        boundary: b.as_slice()?,
        keys: k.as_slice()?,
    })
}

/// The welded arrays as numpy arrays (the buffers moved, not copied).
fn welded_tuple<'py>(py: Python<'py>, welded: Welded) -> PyResult<Bound<'py, PyTuple>> {
    let [v, f, n] = MeshBuffers {
        vertices: flatten_points(welded.vertices),
        faces: flat_faces(welded.faces),
        normals: flatten_points(welded.normals),
    }
    .into_py_arrays(py)?;
    PyTuple::new(py, [v, f, n])
}

/// Joins tile meshes made on windows of one lattice; see ``implicitmesh.distributed``.
///
/// ``tiles`` is a sequence of ``(window, vertices (V, 3) float64, faces (F, 3) uint32 (read in
/// place; other integer types are converted), normals
/// (V, 3) or (0, 3) float64, boundary (B,) uint32, keys (B,) uint64)``, ``window = [[i0, j0,
/// k0], [i1, j1, k1]]`` the tile's cells, ``boundary`` and ``keys`` as
/// ``polygonize(..., window=window, boundary=True)`` returns them; ``cells``, ``origin``,
/// ``cell`` the whole lattice (as :func:`lattice` returns them). Vertices with one edge key
/// are joined. The mesh is :class:`StreamedWeld`'s of the tiles added in turn.
/// ``progress`` is called with the tile vertices done.
///
/// Returns ``(vertices (V, 3) float64, faces (F, 3) int64, normals (V, 3) float64 or (0, 3))``.
#[pyfunction]
#[pyo3(signature = (tiles, cells, origin, cell, *, progress=None))]
pub fn weld_tiles<'py>(
    py: Python<'py>,
    tiles: Vec<Bound<'py, PyAny>>,
    cells: [u32; 3],
    origin: [f64; 3],
    cell: [f64; 3],
    progress: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let _call = super::interrupt::call("weld_tiles");
    let lattice = whole_lattice(cells, origin, cell)?;
    let mut arrays = Vec::with_capacity(tiles.len());
    for t in &tiles {
        let parts: [Bound<'py, PyAny>; 6] = t.extract().map_err(|_| {
            value_error(
                "tiles",
                "expected (window [[i0, j0, k0], [i1, j1, k1]], vertices, faces, normals, boundary, keys) per tile",
            )
        })?;
        arrays.push(tile_arrays(parts.each_ref())?);
    }
    let parts: Vec<Tile> = arrays.iter().map(as_tile).collect::<PyResult<_>>()?;
    let welded = run(py, progress, false, || weld(&parts, &lattice))?;
    welded_tuple(py, welded)
}

/// The weld of tile meshes added one at a time, in window order, as a tiled run's tiles arrive
/// (each tile can be freed once added); ``result()`` is the mesh :func:`weld_tiles` makes of
/// the tiles added, array for array.
///
/// ``StreamedWeld(tiles, cells, origin, cell, normals=None, memory_limit=None)``: ``tiles`` the
/// number of tiles that will be added (for the estimate of the output's size), ``cells``,
/// ``origin``, ``cell`` the whole lattice (as :func:`lattice` returns them), ``normals`` whether
/// the tiles carry normals (None: as the first tile with vertices does), ``memory_limit`` the
/// bytes the welded mesh may hold (None: :func:`polygonize`'s default, 8 GiB); a tile that would
/// take it over is refused with a ValueError naming ``memory_limit``.
#[pyclass(name = "StreamedWeld", module = "implicitmesh._core")]
pub struct PyStreamedWeld {
    lattice: Lattice,
    /// None once the result is taken.
    weld: Option<StreamedWeld>,
}

#[pymethods]
impl PyStreamedWeld {
    #[new]
    #[pyo3(signature = (tiles, cells, origin, cell, normals=None, memory_limit=None))]
    fn new(
        tiles: usize,
        cells: [u32; 3],
        origin: [f64; 3],
        cell: [f64; 3],
        normals: Option<bool>,
        memory_limit: Option<u64>,
    ) -> PyResult<Self> {
        let limit = limit_of(memory_limit)?;
        Ok(PyStreamedWeld {
            lattice: whole_lattice(cells, origin, cell)?,
            weld: Some(StreamedWeld::new(tiles, normals).with_memory_limit(limit)),
        })
    }

    /// Adds the next tile: ``window`` its cells ``[[i0, j0, k0], [i1, j1, k1]]``, ``vertices``
    /// (V, 3) float64, ``faces`` (F, 3) uint32, ``normals`` (V, 3) or (0, 3) float64,
    /// ``boundary`` (B,) uint32 and ``keys`` (B,) uint64 as ``polygonize(..., window=window,
    /// boundary=True)`` returns them. The arrays are read in place (the GIL released, except
    /// for tiles of fewer than 4,096 triangles and vertices, which take microseconds).
    ///
    /// Raises ValueError naming the argument at fault (the weld is then unchanged), and
    /// KeyboardInterrupt on Ctrl-C.
    #[allow(clippy::too_many_arguments)]
    fn add(
        &mut self,
        py: Python<'_>,
        window: &Bound<'_, PyAny>,
        vertices: &Bound<'_, PyAny>,
        faces: &Bound<'_, PyAny>,
        normals: &Bound<'_, PyAny>,
        boundary: &Bound<'_, PyAny>,
        keys: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let _call = super::interrupt::call("StreamedWeld.add");
        let arrays = tile_arrays([window, vertices, faces, normals, boundary, keys])?;
        let tile = as_tile(&arrays)?;
        let lattice = &self.lattice;
        let weld = self.weld.as_mut().ok_or_else(|| {
            pyo3::exceptions::PyRuntimeError::new_err("StreamedWeld: result() was taken")
        })?;
        let rows = tile.faces.len() + tile.vertices.len();
        if rows < crate::polygonize::weld::TINY_TILE {
            return weld.add(&tile, lattice).map_err(PyErr::from);
        }
        if rows < crate::polygonize::weld::SMALL_TILE {
            // Done before Ctrl-C would be looked at: no task to poll.
            return super::interrupt::detach(py, || weld.add(&tile, lattice));
        }
        run(py, None, false, || weld.add(&tile, lattice))
    }

    /// Tiles added so far.
    #[getter]
    fn added(&self) -> usize {
        self.weld.as_ref().map_or(0, StreamedWeld::added)
    }

    /// Vertices welded so far.
    #[getter]
    fn vertices(&self) -> usize {
        self.weld.as_ref().map_or(0, StreamedWeld::vertices)
    }

    /// ``(vertices (V, 3) float64, faces (F, 3) int64, normals (V, 3) float64 or (0, 3))``,
    /// the welded mesh (taken: the weld is empty afterwards).
    fn result<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        let weld = self.weld.take().ok_or_else(|| {
            pyo3::exceptions::PyRuntimeError::new_err("StreamedWeld: result() was taken")
        })?;
        welded_tuple(py, weld.finish())
    }
}

/// Where each tile's rows go in the welded mesh, from each tile's counts and boundary vertices
/// alone: the bookkeeping of :class:`StreamedWeld`, for a tiled run whose workers write their
/// tiles' rows into the welded arrays themselves (:func:`write_welded_tile`).
///
/// ``WeldPlan(cells, origin, cell, normals, memory_limit=None)``: ``cells``, ``origin``,
/// ``cell`` the whole lattice (as :func:`lattice` returns them), ``normals`` whether the welded
/// mesh has normals, ``memory_limit`` the bytes the welded mesh may hold (None: 8 GiB); a tile
/// that would take it over is refused with a ValueError naming ``memory_limit``.
#[pyclass(name = "WeldPlan", module = "implicitmesh._core")]
pub struct PyWeldPlan {
    lattice: Lattice,
    plan: WeldPlan,
}

#[pymethods]
impl PyWeldPlan {
    #[new]
    #[pyo3(signature = (cells, origin, cell, normals, memory_limit=None))]
    fn new(
        cells: [u32; 3],
        origin: [f64; 3],
        cell: [f64; 3],
        normals: bool,
        memory_limit: Option<u64>,
    ) -> PyResult<Self> {
        Ok(PyWeldPlan {
            lattice: whole_lattice(cells, origin, cell)?,
            plan: WeldPlan::new(Some(normals)).with_memory_limit(limit_of(memory_limit)?),
        })
    }

    /// Adds the next tile: ``window`` its cells ``[[i0, j0, k0], [i1, j1, k1]]``, ``vertices``
    /// and ``faces`` its counts, ``boundary`` (B,) uint32 and ``keys`` (B,) uint64 as
    /// ``polygonize(..., window=window, boundary=True)`` returns them, ``positions`` (B, 3)
    /// float64 the boundary vertices' positions.
    ///
    /// Returns ``(first_vertex, first_face, joined)``: the welded index of the tile's first
    /// kept vertex (its kept vertices take the next, in order), the welded row of its first
    /// triangle, and ``joined`` (J, 2) uint32, its vertices joined to an earlier tile's (index
    /// in the tile, welded index), increasing. Raises ValueError naming the argument at fault
    /// (the plan is then unchanged).
    #[allow(clippy::too_many_arguments)]
    fn add<'py>(
        &mut self,
        py: Python<'py>,
        window: &Bound<'py, PyAny>,
        vertices: usize,
        faces: usize,
        boundary: &Bound<'py, PyAny>,
        keys: &Bound<'py, PyAny>,
        positions: &Bound<'py, PyAny>,
    ) -> PyResult<(usize, usize, Bound<'py, PyArray2<u32>>)> {
        let window: [[u32; 3]; 2] = window
            .extract()
            .map_err(|_| value_error("window", "expected [[i0, j0, k0], [i1, j1, k1]] of cells"))?;
        let boundary = column::<u32>(boundary, "uint32", "boundary")?;
        let keys = column::<u64>(keys, "uint64", "keys")?;
        let positions = rows::<f64>(positions, "float64", "positions")?;
        let seams = Seams {
            window,
            vertices,
            faces,
            // A tile's normals are checked where its rows are written.
            normals: self.plan.normals() == Some(true),
            boundary: boundary.as_slice()?,
            keys: keys.as_slice()?,
            positions: bytemuck::cast_slice(positions.as_slice()?),
        };
        let plan = self.plan.add(&seams, &self.lattice)?;
        let joined: Vec<[u32; 2]> = plan.joined.iter().map(|&(i, to)| [i, to]).collect();
        let joined = numpy::ndarray::Array2::from_shape_vec(
            (joined.len(), 2),
            joined.into_iter().flatten().collect(),
        )
        .expect("two columns per joined vertex");
        Ok((plan.first_vertex, plan.first_face, joined.into_pyarray(py)))
    }

    /// Tiles added so far.
    #[getter]
    fn added(&self) -> usize {
        self.plan.added()
    }

    /// Welded vertices so far.
    #[getter]
    fn vertices(&self) -> usize {
        self.plan.vertices()
    }

    /// Welded triangles so far.
    #[getter]
    fn faces(&self) -> usize {
        self.plan.faces()
    }
}

/// `memory_limit` as the weld takes it: None the polygonizers' default, 0 refused.
fn limit_of(memory_limit: Option<u64>) -> PyResult<u64> {
    if memory_limit == Some(0) {
        return Err(value_error(
            "memory_limit",
            "must be a positive integer, got 0",
        ));
    }
    Ok(memory_limit.unwrap_or(crate::memory::DEFAULT_MEMORY_LIMIT))
}

/// A writable C-contiguous `(rows, 3)` array, borrowed.
fn room_of<'py, T: numpy::Element>(
    obj: &Bound<'py, PyAny>,
    rows: usize,
    name: &'static str,
) -> PyResult<PyReadwriteArray2<'py, T>> {
    let a: PyReadwriteArray2<'py, T> = obj.extract().map_err(|_| {
        value_error(
            name,
            format!(
                "expected a writable {} array, got {}",
                std::any::type_name::<T>(),
                obj.get_type()
                    .name()
                    .map_or_else(|_| "?".into(), |n| n.to_string())
            ),
        )
    })?;
    if a.shape() != [rows, 3] || !a.is_c_contiguous() {
        return Err(value_error(
            name,
            format!(
                "expected a C-contiguous ({rows}, 3) array, got shape {}",
                shape(obj)
            ),
        ));
    }
    Ok(a)
}

/// Writes one tile's rows into the welded arrays where its :class:`WeldPlan` puts them:
/// ``vertices`` (V, 3) float64, ``faces`` (F, 3) uint32 (other integer types are converted),
/// ``normals`` (V, 3) or (0, 3) float64 the tile's arrays; ``first_vertex`` and ``joined``
/// (J, 2) uint32 as :meth:`WeldPlan.add` returned them; ``out_vertices`` (V − J, 3) float64,
/// ``out_faces`` (F, 3) int64 and ``out_normals`` (V − J, 3) float64 or None, writable
/// C-contiguous arrays, the rows of the welded arrays from ``first_vertex`` and
/// ``first_face`` on (memory maps of the welded mesh's files, in a tiled run). The GIL is
/// released.
///
/// Raises ValueError naming the argument at fault.
#[pyfunction]
#[pyo3(signature = (vertices, faces, normals, first_vertex, joined, out_vertices, out_faces, out_normals=None))]
#[allow(clippy::too_many_arguments)]
pub fn write_welded_tile<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    normals: &Bound<'py, PyAny>,
    first_vertex: usize,
    joined: &Bound<'py, PyAny>,
    out_vertices: &Bound<'py, PyAny>,
    out_faces: &Bound<'py, PyAny>,
    out_normals: Option<&Bound<'py, PyAny>>,
) -> PyResult<()> {
    let v = rows::<f64>(vertices, "float64", "vertices")?;
    let f = Faces::new(faces)?;
    let n = rows::<f64>(normals, "float64", "normals")?;
    let j = required(joined, "uint32", "joined")?;
    let j: PyReadonlyArray2<'py, u32> = j
        .extract()
        .ok()
        .filter(|a: &PyReadonlyArray2<'py, u32>| a.shape()[1] == 2)
        .ok_or_else(|| {
            value_error(
                "joined",
                format!("expected a (J, 2) array, got shape {}", shape(joined)),
            )
        })?;
    let plan = TilePlan {
        vertices: v.shape()[0],
        faces: f.rows()?.len(),
        first_vertex,
        first_face: 0,
        joined: j
            .as_slice()?
            .chunks_exact(2)
            .map(|p| (p[0], p[1]))
            .collect(),
    };
    if plan.joined.len() > plan.vertices {
        return Err(value_error(
            "joined",
            format!(
                "{} joined vertices of a tile of {}",
                plan.joined.len(),
                plan.vertices
            ),
        ));
    }
    let kept = plan.kept();
    let mut ov = room_of::<f64>(out_vertices, kept, "out_vertices")?;
    let mut of = room_of::<i64>(out_faces, plan.faces, "out_faces")?;
    let mut on = out_normals
        .map(|o| room_of::<f64>(o, kept, "out_normals"))
        .transpose()?;
    let vs: &[DVec3] = bytemuck::cast_slice(v.as_slice()?);
    let ns: &[DVec3] = bytemuck::cast_slice(n.as_slice()?);
    let fs = f.rows()?;
    let out = Rows {
        vertices: room(bytemuck::cast_slice_mut::<f64, DVec3>(ov.as_slice_mut()?)),
        normals: match on.as_mut() {
            Some(a) => Some(room(bytemuck::cast_slice_mut::<f64, DVec3>(
                a.as_slice_mut()?,
            ))),
            None => None,
        },
        faces: room(bytemuck::cast_slice_mut::<i64, [i64; 3]>(
            of.as_slice_mut()?,
        )),
    };
    run(py, None, false, || rows_write(vs, ns, fs, &plan, out))
}
