//! numpy in, numpy out: conversions and shape checks. Inputs are converted with
//! `numpy.asarray(x, dtype=float64)` (so lists, float32 and Fortran-ordered arrays are accepted)
//! and copied row by row through a strided view; only the points of a fit ([`PointsArg`]) are
//! read in place, when they are a C-contiguous, aligned float64 array.

use super::errors::value_error;
use glam::DVec3;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// `numpy.asarray(obj, dtype=dtype)`, refusing complex input (whose imaginary part the cast
/// would drop).
fn asarray<'py>(obj: &Bound<'py, PyAny>, dtype: &str) -> PyResult<Bound<'py, PyAny>> {
    let py = obj.py();
    let np = py.import("numpy")?;
    let raw = np.call_method1("asarray", (obj,))?;
    let kind: String = raw.getattr("dtype")?.getattr("kind")?.extract()?;
    if kind == "c" {
        return Err(pyo3::exceptions::PyTypeError::new_err(
            "complex values are not supported",
        ));
    }
    let kwargs = PyDict::new(py);
    kwargs.set_item("dtype", dtype)?;
    np.call_method("asarray", (raw,), Some(&kwargs))
}

/// A shape as Python prints it: `(5, 2)`, `(7,)`.
pub fn python_shape(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|n| n.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// An (N, 3) array of points, as float64. float64 and float32 numpy arrays in native byte order
/// are read as they are (any strides, no copy in Python); anything else goes through
/// `numpy.asarray(x, dtype=float64)`.
pub fn points(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<DVec3>> {
    if let Some(p) = points_in_place::<f64>(obj).or_else(|| points_in_place::<f32>(obj)) {
        return Ok(p);
    }
    let arr = asarray(obj, "float64")
        .map_err(|e| value_error(name, format!("not convertible to a float64 array ({e})")))?;
    check_rows_of_three(&arr, name)?;
    let a: PyReadonlyArray2<f64> = arr.extract()?;
    let view = a.as_array();
    Ok(view
        .rows()
        .into_iter()
        .map(|r| DVec3::new(r[0], r[1], r[2]))
        .collect())
}

/// A box `[[xmin, ymin, zmin], [xmax, ymax, zmax]]` of finite numbers ((2, 3) array_like),
/// as its lowest and highest corner; an error names the argument `name`.
pub fn finite_box(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<(DVec3, DVec3)> {
    let b = points(obj, name)?;
    if b.len() != 2 || !b.iter().all(|p| p.is_finite()) {
        return Err(value_error(
            name,
            "expected finite [[xmin, ymin, zmin], [xmax, ymax, zmax]]",
        ));
    }
    Ok((b[0], b[1]))
}

/// The (N, 3) points of a fit: read in place from a C-contiguous, aligned float64 numpy array
/// (whose readonly borrow it holds), converted as [`points`] otherwise.
pub enum PointsArg<'py> {
    InPlace(PyReadonlyArray2<'py, f64>),
    Copied(Vec<DVec3>),
}

impl PointsArg<'_> {
    /// The points. Take them while holding the GIL: the array's layout was checked then.
    pub fn as_slice(&self) -> &[DVec3] {
        match self {
            PointsArg::InPlace(a) => bytemuck::cast_slice(
                a.as_slice()
                    .expect("a C-contiguous array, checked when the argument was read"),
            ),
            PointsArg::Copied(p) => p,
        }
    }
}

/// [`points`], read in place when `obj` is a C-contiguous, aligned (N, 3) float64 array.
pub fn points_arg<'py>(obj: &Bound<'py, PyAny>, name: &'static str) -> PyResult<PointsArg<'py>> {
    if let Ok(a) = obj.cast::<numpy::PyArray2<f64>>() {
        if let Ok(r) = a.try_readonly() {
            // `as_slice` also takes Fortran order: C order is checked apart.
            let fits = r.as_array().ncols() == 3
                && r.as_array().is_standard_layout()
                && r.as_slice()
                    .is_ok_and(|s| bytemuck::try_cast_slice::<f64, DVec3>(s).is_ok());
            if fits {
                return Ok(PointsArg::InPlace(r));
            }
        }
    }
    Ok(PointsArg::Copied(points(obj, name)?))
}

/// A ValueError naming `name` unless the array `arr` has shape (N, 3).
pub fn check_rows_of_three(arr: &Bound<'_, PyAny>, name: &str) -> PyResult<()> {
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    if shape.len() != 2 || shape[1] != 3 {
        return Err(value_error(
            name,
            format!(
                "expected an array of shape (N, 3), got shape {}",
                python_shape(&shape)
            ),
        ));
    }
    Ok(())
}

/// The rows of `obj` when it is an (N, 3) numpy array of `T` (None otherwise, or when it is
/// borrowed mutably).
fn points_in_place<T: numpy::Element + Copy + Into<f64>>(
    obj: &Bound<'_, PyAny>,
) -> Option<Vec<DVec3>> {
    let a = obj.cast::<numpy::PyArray2<T>>().ok()?;
    let a = a.try_readonly().ok()?;
    let view = a.as_array();
    if view.ncols() != 3 {
        return None;
    }
    Some(
        view.rows()
            .into_iter()
            .map(|r| DVec3::new(r[0].into(), r[1].into(), r[2].into()))
            .collect(),
    )
}

/// An (N,) array of float64 values.
pub fn values(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<f64>> {
    let arr = asarray(obj, "float64")
        .map_err(|e| value_error(name, format!("not convertible to a float64 array ({e})")))?;
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    if shape.len() != 1 {
        return Err(value_error(
            name,
            format!(
                "expected an array of shape (N,), got shape {}",
                python_shape(&shape)
            ),
        ));
    }
    let a: PyReadonlyArray1<f64> = arr.extract()?;
    Ok(a.as_array().iter().copied().collect())
}

/// An (N, 3, 3) array of float64 matrices, each row-major.
pub fn matrices(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Vec<[f64; 9]>> {
    let arr = asarray(obj, "float64")
        .map_err(|e| value_error(name, format!("not convertible to a float64 array ({e})")))?;
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    if shape.len() != 3 || shape[1] != 3 || shape[2] != 3 {
        return Err(value_error(
            name,
            format!(
                "expected an array of shape (N, 3, 3), got shape {}",
                python_shape(&shape)
            ),
        ));
    }
    let a: numpy::PyReadonlyArray3<f64> = arr.extract()?;
    let a = a.as_array();
    Ok((0..shape[0])
        .map(|i| std::array::from_fn(|k| a[[i, k / 3, k % 3]]))
        .collect())
}

/// (N, 3, 3) float64 from row-major matrices.
pub fn matrices_to_py<'py>(py: Python<'py>, m: &[[f64; 9]]) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<f64> = m.iter().flatten().copied().collect();
    Ok(numpy::PyArray1::from_vec(py, flat)
        .reshape([m.len(), 3, 3])?
        .into_any())
}

/// A mesh of (V, 3) ``vertices`` and (F, 3) ``faces`` arrays, without normals (each checked as
/// [`points`] and [`triangles`] check it; the indices are not checked against V).
pub fn mesh_arg(
    vertices: &Bound<'_, PyAny>,
    faces: &Bound<'_, PyAny>,
) -> PyResult<crate::mesh::Mesh> {
    Ok(crate::mesh::Mesh {
        vertices: points(vertices, "vertices")?,
        triangles: triangles(faces, "faces")?,
        normals: Vec::new(),
    })
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
            format!(
                "expected an array of shape (F, 3), got shape {}",
                python_shape(&shape)
            ),
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

/// Points given from Python, checked, then `eval(points, out)` without the GIL.
fn batch<T: Clone + Default + Send>(
    py: Python<'_>,
    obj: &Bound<'_, PyAny>,
    eval: impl Fn(&[DVec3], &mut [T]) + Sync,
) -> PyResult<Vec<T>> {
    /// Points per call of `eval`; a batch of more stops on Ctrl-C between them.
    const CHUNK: usize = 1 << 16;
    let p = points(obj, "points")?;
    crate::error::check_finite_points("points", &p)?;
    let n = p.len();
    let work = || -> crate::Result<Vec<T>> {
        let mut out = vec![T::default(); n];
        for (pc, oc) in p.chunks(CHUNK).zip(out.chunks_mut(CHUNK)) {
            crate::cancel::check()?;
            eval(pc, oc);
            crate::cancel::advance(pc.len() as u64)?;
        }
        Ok(out)
    };
    if n <= CHUNK {
        super::interrupt::detach(py, work)
    } else {
        super::interrupt::run(py, None, false, work)
    }
}

/// `field.values` at points given from Python: (N, 3) → (N,) float64.
pub fn field_values<'py, F: crate::field::Field + ?Sized>(
    py: Python<'py>,
    field: &F,
    obj: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    Ok(values_to_py(py, batch(py, obj, |p, o| field.values(p, o))?))
}

/// `field.gradients` at points given from Python: (N, 3) → (N, 3) float64.
pub fn field_gradients<'py, F: crate::field::Field + ?Sized>(
    py: Python<'py>,
    field: &F,
    obj: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    points_to_py(py, batch(py, obj, |p, o| field.gradients(p, o))?)
}

/// (N, 3) float64 array from points (the buffer is handed to numpy, not copied).
pub fn points_to_py<'py>(py: Python<'py>, p: Vec<DVec3>) -> PyResult<Bound<'py, PyAny>> {
    let n = p.len();
    let flat = flatten_points(p);
    Ok(PyArray1::from_vec(py, flat).reshape([n, 3])?.into_any())
}

/// The coordinates of points as one flat vector, reusing the allocation (a `DVec3` is three
/// `f64` with the same alignment).
pub fn flatten_points(p: Vec<DVec3>) -> Vec<f64> {
    match bytemuck::allocation::try_cast_vec::<DVec3, f64>(p) {
        Ok(v) => v,
        Err((_, p)) => bytemuck::cast_slice::<DVec3, f64>(&p).to_vec(),
    }
}

/// Triangles as int64 indices, flat (run without the GIL: it is a pass over the whole mesh).
pub fn flatten_triangles(t: &[[u32; 3]]) -> Vec<i64> {
    // Runs of 4096 triangles, converted in parallel.
    let runs = t.chunks(4096).collect::<Vec<_>>();
    flat_faces(crate::polygonize::gather_map(&runs, |t| t.map(i64::from)))
}

/// int64 triangles, flat (the same allocation).
pub fn flat_faces(t: Vec<[i64; 3]>) -> Vec<i64> {
    match bytemuck::allocation::try_cast_vec::<[i64; 3], i64>(t) {
        Ok(v) => v,
        Err((_, t)) => bytemuck::cast_slice::<[i64; 3], i64>(&t).to_vec(),
    }
}

/// A mesh as flat numpy-ready buffers: vertices, int64 faces, normals.
pub struct MeshBuffers {
    pub vertices: Vec<f64>,
    pub faces: Vec<i64>,
    pub normals: Vec<f64>,
}

impl MeshBuffers {
    /// Takes the mesh's buffers (no copy of the coordinates).
    pub fn new(mesh: crate::mesh::Mesh) -> Self {
        MeshBuffers {
            faces: flatten_triangles(&mesh.triangles),
            vertices: flatten_points(mesh.vertices),
            normals: flatten_points(mesh.normals),
        }
    }

    /// Takes a mesh's vertices and normals, with its faces already flat.
    pub fn with_faces(mesh: crate::mesh::Mesh, faces: Vec<i64>) -> Self {
        MeshBuffers {
            faces,
            vertices: flatten_points(mesh.vertices),
            normals: flatten_points(mesh.normals),
        }
    }

    /// (vertices (V, 3), faces (F, 3), normals (V, 3) or (0, 3)) numpy arrays.
    pub fn into_py_arrays<'py>(self, py: Python<'py>) -> PyResult<[Bound<'py, PyAny>; 3]> {
        let (nv, nf, nn) = (
            self.vertices.len() / 3,
            self.faces.len() / 3,
            self.normals.len() / 3,
        );
        Ok([
            PyArray1::from_vec(py, self.vertices)
                .reshape([nv, 3])?
                .into_any(),
            PyArray1::from_vec(py, self.faces)
                .reshape([nf, 3])?
                .into_any(),
            PyArray1::from_vec(py, self.normals)
                .reshape([nn, 3])?
                .into_any(),
        ])
    }
}

/// (F, 3) int64 array from triangles.
pub fn triangles_to_py<'py>(py: Python<'py>, t: &[[u32; 3]]) -> PyResult<Bound<'py, PyAny>> {
    let flat = flatten_triangles(t);
    Ok(PyArray1::from_vec(py, flat)
        .reshape([t.len(), 3])?
        .into_any())
}

/// (N,) float64 array.
pub fn values_to_py<'py>(py: Python<'py>, v: Vec<f64>) -> Bound<'py, PyAny> {
    PyArray1::from_vec(py, v).into_any()
}
