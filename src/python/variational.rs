//! `VariationalSurface`: the Python class over the core's fitted surface.

use super::convert::{
    field_gradients, field_values, points_arg, points_to_py, triangles, values, values_to_py,
};
use super::errors::value_error;
use crate::error::Result;
use crate::field::rbf::constraints::{self, Constraints};
use crate::field::rbf::kernel::Kernel;
use crate::field::rbf::partition::{self, PartitionSurface};
use crate::field::rbf::{self, VariationalSurface};
use crate::field::rbf::reduction::{self, Reduction, ReductionSettings};
use crate::field::Field;
use glam::DVec3;
use numpy::PyArray1;
use pyo3::exceptions::PyUserWarning;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::borrow::Cow;
use std::sync::Arc;

/// Constraints (2 per data point for `fit` and `from_mesh`) from which `method="auto"` fits a
/// partition of unity instead of one global system: about where the partition fit becomes the
/// faster, at the same distance to the sampled surface (see benchmarks/bench_partition.py,
/// `crossover`).
pub const AUTO_PARTITION_CONSTRAINTS: usize = 2000;

/// The fitted surface behind the Python class: one global system, or a partition of unity.
#[derive(Clone)]
pub enum Fitted {
    Global(Arc<VariationalSurface>),
    Partition(Arc<PartitionSurface>),
}

impl Fitted {
    /// The surface as a core field.
    pub fn as_field(&self) -> &(dyn Field + '_) {
        match self {
            Fitted::Global(s) => s.as_ref(),
            Fitted::Partition(s) => s.as_ref(),
        }
    }
    /// The constraints (for a partition fit, its points gathered into the constraints' order).
    pub fn constraints(&self) -> Cow<'_, Constraints> {
        match self {
            Fitted::Global(s) => Cow::Borrowed(s.constraints()),
            Fitted::Partition(s) => s.constraints(),
        }
    }
    fn constraint_count(&self) -> usize {
        match self {
            Fitted::Global(s) => s.constraints().points.len(),
            Fitted::Partition(s) => s.constraint_count(),
        }
    }
    fn kernel(&self) -> Kernel {
        match self {
            Fitted::Global(s) => s.kernel(),
            Fitted::Partition(s) => s.kernel(),
        }
    }
    fn residual(&self) -> f64 {
        match self {
            Fitted::Global(s) => s.residual(),
            Fitted::Partition(s) => s.residual(),
        }
    }
    fn merged(&self) -> usize {
        match self {
            Fitted::Global(s) => s.constraints().merged,
            Fitted::Partition(s) => s.merged(),
        }
    }
    fn data_bounding_box(&self) -> (DVec3, DVec3) {
        match self {
            Fitted::Global(s) => s.data_bounding_box(),
            Fitted::Partition(s) => s.data_bounding_box(),
        }
    }
    fn method(&self) -> &'static str {
        match self {
            Fitted::Global(_) => "global",
            Fitted::Partition(_) => "partition",
        }
    }
}

/// The progress callback and the function that ends the report, from `progress` as users pass
/// it (False, True or a callable; see `implicitmesh._progress.reporter`).
fn reporter<'py>(
    py: Python<'py>,
    progress: Option<&Bound<'py, PyAny>>,
    what: &str,
) -> PyResult<(Option<Bound<'py, PyAny>>, Bound<'py, PyAny>)> {
    let r = py.import("implicitmesh._progress")?.call_method1(
        "reporter",
        (progress, what, py.None(), "constraints fitted"),
    )?;
    let (callback, end): (Bound<'py, PyAny>, Bound<'py, PyAny>) = r.extract()?;
    Ok(((!callback.is_none()).then_some(callback), end))
}

/// How to fit: `"global"`, `"partition"`, or `"auto"` (decided by the number of constraints).
#[derive(Clone, Copy, PartialEq)]
enum Method {
    Global,
    Partition,
    Auto,
}

fn parse_method(method: &str) -> PyResult<Method> {
    match method {
        "global" => Ok(Method::Global),
        "partition" => Ok(Method::Partition),
        "auto" => Ok(Method::Auto),
        _ => Err(value_error(
            "method",
            format!("unknown method {method:?}; use \"auto\", \"global\" or \"partition\""),
        )),
    }
}

/// The keyword arguments that `fit`, `from_mesh` and `interpolate` share, converted and checked
/// in this order: `method`, then `kernel`, `smoothing` and `memory_limit`, then
/// `partition_options`, then `merge_distance`.
struct FitOptions<'a, 'py> {
    method: Method,
    global: rbf::FitSettings,
    partition: partition::PartitionSettings,
    merge_distance: Option<f64>,
    progress: Option<&'a Bound<'py, PyAny>>,
}

/// [`FitOptions`] from the Python arguments.
fn fit_options<'a, 'py>(
    method: &str,
    kernel: &str,
    smoothing: f64,
    memory_limit: Option<u64>,
    progress: Option<&'a Bound<'py, PyAny>>,
    partition_options: Option<&Bound<'_, PyDict>>,
    merge_distance: Option<f64>,
) -> PyResult<FitOptions<'a, 'py>> {
    let method = parse_method(method)?;
    let global = fit_settings(kernel, smoothing, memory_limit)?;
    let partition = partition_settings(partition_options, global)?;
    let merge_distance = constraints::check_merge_distance(merge_distance)?;
    Ok(FitOptions {
        method,
        global,
        partition,
        merge_distance,
        progress,
    })
}

impl<'a, 'py> FitOptions<'a, 'py> {
    /// Runs the global or the partition fit (with the GIL released), as the method and the
    /// number of constraints decide.
    fn run(
        self,
        py: Python<'py>,
        constraints: usize,
        global: impl FnOnce(&rbf::FitSettings) -> Result<VariationalSurface> + Send,
        partition: impl FnOnce(&partition::PartitionSettings) -> Result<PartitionSurface> + Send,
    ) -> PyResult<PyVariationalSurface> {
        let use_partition = match self.method {
            Method::Global => false,
            Method::Partition => true,
            Method::Auto => constraints >= AUTO_PARTITION_CONSTRAINTS,
        };
        let (progress, ps, gs) = (self.progress, self.partition, self.global);
        let inner = if use_partition {
            let (report, end) = reporter(py, progress, "fit (partition)")?;
            let fitted = super::interrupt::run(py, report.as_ref(), false, move || partition(&ps));
            end.call0()?;
            Fitted::Partition(Arc::new(fitted?))
        } else {
            let (report, end) = reporter(py, progress, "fit (global)")?;
            let fitted = super::interrupt::run(py, report.as_ref(), false, move || global(&gs));
            end.call0()?;
            Fitted::Global(Arc::new(fitted?))
        };
        warn_merged(py, inner.merged())?;
        Ok(PyVariationalSurface {
            inner,
            reduction: None,
        })
    }

    /// Greedy fits to growing subsets of `points` until every point is within `tolerance`
    /// ([`reduction::fit_within`]), each fit global or partition as the method and the subset's
    /// constraints (`per_point` per point) decide; warns when the rounds did not suffice.
    #[allow(clippy::too_many_arguments)]
    fn run_within(
        self,
        py: Python<'py>,
        tolerance: f64,
        points: &[DVec3],
        targets: Option<&[f64]>,
        per_point: usize,
        global: impl Fn(&[u32], &rbf::FitSettings) -> Result<VariationalSurface> + Send,
        partition: impl Fn(&[u32], &partition::PartitionSettings) -> Result<PartitionSurface> + Send,
    ) -> PyResult<PyVariationalSurface> {
        let settings = ReductionSettings {
            tolerance,
            ..Default::default()
        };
        settings.check()?;
        let (method, ps, gs) = (self.method, self.partition, self.global);
        let (report, end) = reporter(py, self.progress, "fit (within tolerance)")?;
        let fitted = super::interrupt::run(py, report.as_ref(), false, move || {
            let fit = |used: &[u32]| -> Result<Fitted> {
                let use_partition = match method {
                    Method::Global => false,
                    Method::Partition => true,
                    Method::Auto => per_point * used.len() >= AUTO_PARTITION_CONSTRAINTS,
                };
                Ok(if use_partition {
                    Fitted::Partition(Arc::new(partition(used, &ps)?))
                } else {
                    Fitted::Global(Arc::new(global(used, &gs)?))
                })
            };
            reduction::fit_within(points, targets, &settings, fit, Fitted::as_field)
        });
        end.call0()?;
        let (inner, r) = fitted?;
        warn_merged(py, inner.merged())?;
        if r.outside > 0 {
            let message = std::ffi::CString::new(format!(
                "{} of {} data points are farther than tolerance={tolerance:e} from the surface \
                 after {} fits (largest {:.3e}); see VariationalSurface.reduction",
                r.outside,
                points.len(),
                r.rounds,
                r.largest_residual
            ))
            .expect("no NUL in the message");
            PyErr::warn(py, &py.get_type::<PyUserWarning>(), &message, 1)?;
        }
        Ok(PyVariationalSurface {
            inner,
            reduction: Some(r),
        })
    }
}

/// The partition fit's settings: the defaults, with the keys of `options` (a dict) in place.
fn partition_settings(
    options: Option<&Bound<'_, PyDict>>,
    fit: rbf::FitSettings,
) -> PyResult<partition::PartitionSettings> {
    let mut s = partition::PartitionSettings {
        fit,
        ..Default::default()
    };
    let Some(options) = options else {
        return Ok(s);
    };
    for (key, value) in options.iter() {
        let key: String = key
            .extract()
            .map_err(|_| value_error("partition_options", "keys must be strings"))?;
        let bad = |what: &str| {
            value_error(
                "partition_options",
                format!("{key:?} must be {what}, got {value}"),
            )
        };
        match key.as_str() {
            "max_per_leaf" => s.max_per_leaf = value.extract().map_err(|_| bad("an int"))?,
            "max_patch" => s.max_patch = value.extract().map_err(|_| bad("an int"))?,
            "min_points" => s.min_points = value.extract().map_err(|_| bad("an int"))?,
            "overlap" => s.overlap = value.extract().map_err(|_| bad("a float"))?,
            _ => {
                return Err(value_error(
                    "partition_options",
                    format!("unknown key {key:?}; use \"max_per_leaf\", \"max_patch\", \"min_points\" or \"overlap\""),
                ))
            }
        }
    }
    Ok(s)
}

/// A variational implicit surface f(x) = Σ λ_j φ(‖x − c_j‖) + a + b·x fitted to constraints;
/// negative inside, positive outside.
///
/// Create one with :meth:`fit` (points with normals), :meth:`from_mesh` (a triangle mesh) or
/// :meth:`interpolate` (values at points). Evaluate with :meth:`evaluate` / :meth:`gradient` or by
/// calling it; polygonize it with :func:`implicitmesh.polygonize`.
///
/// Two fits (``method``): ``"global"`` solves one dense system over all constraints (time
/// O(M³), memory O(M²) for M constraints: a few thousand points at most); ``"partition"`` splits
/// the constraints with an octree into overlapping patches of a few hundred, fits each patch
/// the same way and blends them, f = Σ w_i f_i / Σ w_i with compactly supported C² weights
/// w_i = (1 − ‖x − c_i‖²/R_i²)³₊. Every patch whose weight is non-zero at a constraint
/// interpolates it, so both fits interpolate every constraint; away from the data the partition
/// fit differs slightly from the global one (the global fit minimises the energy over all the
/// data at once). ``"auto"`` (default) uses the global fit below 2000 constraints (1000 points
/// for :meth:`fit` and :meth:`from_mesh`), about where the partition fit becomes the faster,
/// and the partition from there on. Attributes that
/// describe one global system (:attr:`weights`, :attr:`polynomial`) raise ``ValueError`` for a
/// partition fit, which has :attr:`patches` instead.
#[pyclass(name = "VariationalSurface", module = "implicitmesh", frozen)]
pub struct PyVariationalSurface {
    pub inner: Fitted,
    /// What a fit with `tolerance` did; `None` for exact fits and surfaces loaded from a state.
    pub reduction: Option<Reduction>,
}

fn fit_settings(
    kernel: &str,
    smoothing: f64,
    memory_limit: Option<u64>,
) -> PyResult<rbf::FitSettings> {
    let d = rbf::FitSettings::default();
    Ok(rbf::FitSettings {
        kernel: Kernel::parse(kernel)?,
        smoothing,
        memory_limit: memory_limit.unwrap_or(d.memory_limit),
    })
}

fn placement(
    d: Option<f64>,
    w: Option<f64>,
    merge_distance: Option<f64>,
) -> constraints::ConstraintSettings {
    constraints::ConstraintSettings {
        d,
        w,
        merge_distance,
        ..Default::default()
    }
}

/// A `UserWarning` saying how many data points were merged, when any were.
fn warn_merged(py: Python<'_>, merged: usize) -> PyResult<()> {
    if merged == 0 {
        return Ok(());
    }
    let (noun, verb) = if merged == 1 {
        ("point", "was")
    } else {
        ("points", "were")
    };
    let message = std::ffi::CString::new(format!(
        "{merged} data {noun} lay within merge_distance of another and {verb} merged into it \
         (see VariationalSurface.merged_points)"
    ))
    .expect("no NUL in the message");
    PyErr::warn(py, &py.get_type::<PyUserWarning>(), &message, 1)
}

/// Warns when some of `points` (argument `name`) lie more than [`crate::spatial::OUTSIDE`] times
/// their bulk's extent from it: the default bounds leave them out.
fn warn_outside(py: Python<'_>, name: &str, points: &[DVec3]) -> PyResult<()> {
    let bulk = crate::spatial::Bulk::of(points);
    let Some(b) = bulk.and_then(|k| k.beyond(points, crate::spatial::OUTSIDE)) else {
        return Ok(());
    };
    if b.ratio > crate::spatial::FAR {
        // The fit refuses them (crate::spatial::check_far).
        return Ok(());
    }
    let message = std::ffi::CString::new(format!(
        "{name}: {b}, more than {} times; the default bounds (VariationalSurface.bounds) cover the other points only: pass bounds= to polygonize to include the far ones",
        crate::spatial::OUTSIDE
    ))
    .expect("no NUL in the message");
    PyErr::warn(py, &py.get_type::<PyUserWarning>(), &message, 1)
}

fn global_only(name: &str) -> PyErr {
    value_error(
        name,
        "only defined for a global fit (method=\"global\"); a partition fit has one per patch",
    )
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
    ///     Points on the surface; N ≥ 4, not all in one plane. Points closer together than
    ///     ``merge_distance`` are merged (with a ``UserWarning``): the first keeps its position,
    ///     the normals are summed. C-contiguous float64 arrays (here and in ``normals``) are read
    ///     in place, not copied: do not change them from another thread during the fit.
    /// normals : (N, 3) float64
    ///     Outward normals, any non-zero length (they are normalised).
    /// d : float, optional
    ///     Offset of the normal constraints. Default: 0.0075 × the largest side of the points'
    ///     bounding box, leaving out points more than 50 × the extent of their bulk away
    ///     (0.015 for data spanning [-1, 1]³, as in the papers), at most 6 × the
    ///     median distance between nearest data points (from 10,000 points on).
    /// w : float, optional
    ///     Value at the normal constraints. Default: 0.75 × d (Cuno's w/d = 3/4).
    /// kernel : {"triharmonic", "biharmonic", "thin_plate"}
    ///     Radial basis function: r³ (default), r, or r² log r.
    /// smoothing : float
    ///     Added to the diagonal for noisy data; 0 (default) interpolates exactly.
    /// memory_limit : int, optional
    ///     Refuse fits whose dense system (``"global"``) or patches and the systems being solved
    ///     at once (``"partition"``) need more bytes than this (default 8 GiB).
    /// method : {"auto", "global", "partition"}
    ///     One dense system, or a partition of unity of patches (see the class docstring);
    ///     ``"auto"`` (default): global below 1000 points, partition from 1000 on.
    /// progress : bool or callable, optional
    ///     ``True``: show the constraints fitted so far (a tqdm bar when tqdm is installed, else
    ///     a line on standard error); a callable gets that count (an int) about every 50 ms. The
    ///     partition fit counts patch by patch; the global fit counts the columns of its system
    ///     factorized, in steps of 2048.
    /// partition_options : dict, optional
    ///     The partition fit's patches: ``"max_per_leaf"`` (int, default 64: the octree splits
    ///     leaves holding more constraints), ``"max_patch"`` (int, default 256: and leaves whose
    ///     patch would hold more), ``"min_points"`` (int, default 128: smaller patches complete
    ///     their system with constraints from further away; patches with no data in reach are
    ///     planes that carry the sign of space, or for :meth:`interpolate` complete with half as
    ///     many) and ``"overlap"`` (float, default
    ///     1.15: a patch's radius over its leaf's half-diagonal). Smaller patches fit faster and
    ///     risk spurious surface away from sparse data.
    /// merge_distance : float, optional
    ///     Data points at most this far apart are merged into the one with the smallest index
    ///     (:attr:`merged_points` counts them). Default: 0.1 % of the data's typical spacing (the
    ///     median distance from a point to its nearest neighbour): repeated samples, as where
    ///     scans overlap, are merged and the rest kept. Raise it when a fit is refused as
    ///     ill-conditioned.
    /// tolerance : float, optional
    ///     Fit only as many data points as needed to pass within ``tolerance`` of every point
    ///     (in the points' units; near the data f is about the distance to the surface), by
    ///     greedy reduction (Carr et al. 2001): fit one point per cube of 8 typical spacings,
    ///     add the points farther than the tolerance, fit again, at most 4 fits. The points
    ///     used are interpolated exactly, the others approximated; :attr:`reduction` says how
    ///     many were used and how far the farthest is, and a ``UserWarning`` is raised when
    ///     points stay outside the tolerance after the last fit. For scans with many more
    ///     points than the surface needs (10⁶ points meshed at 256 cells): each fit is of a
    ///     fraction of the points, plus one evaluation per point. Default ``None``: every point
    ///     is interpolated.
    ///
    /// Returns
    /// -------
    /// VariationalSurface
    ///
    /// Raises
    /// ------
    /// KeyboardInterrupt
    ///     On Ctrl-C: the partition fit stops between patches, the global fit between steps of
    ///     its factorization.
    /// ValueError
    ///     For wrong shapes, NaN/inf, fewer than 4 points, coplanar points, a negative
    ///     ``merge_distance``, zero-length normals, a singular system, a system over the memory limit or an unknown
    ///     method.
    #[staticmethod]
    #[pyo3(signature = (points, normals, *, d=None, w=None, kernel="triharmonic", smoothing=0.0, memory_limit=None, method="auto", progress=None, partition_options=None, merge_distance=None, tolerance=None))]
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
        method: &str,
        progress: Option<&Bound<'_, PyAny>>,
        partition_options: Option<&Bound<'_, PyDict>>,
        merge_distance: Option<f64>,
        tolerance: Option<f64>,
    ) -> PyResult<Self> {
        let _call = super::interrupt::call("VariationalSurface.fit");
        let fit = fit_options(
            method,
            kernel,
            smoothing,
            memory_limit,
            progress,
            partition_options,
            merge_distance,
        )?;
        let (p, n) = (
            points_arg(points, "points")?,
            points_arg(normals, "normals")?,
        );
        let (p, n) = (p.as_slice(), n.as_slice());
        warn_outside(py, "points", p)?;
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
        let pl = placement(d, w, fit.merge_distance);
        if let Some(tolerance) = tolerance {
            let subset = |used: &[u32]| -> (Vec<DVec3>, Vec<DVec3>) {
                let pick = |a: &[DVec3]| used.iter().map(|&i| a[i as usize]).collect();
                (pick(p), pick(n))
            };
            return fit.run_within(
                py,
                tolerance,
                p,
                None,
                2,
                |used, s| {
                    let (q, m) = subset(used);
                    VariationalSurface::fit(&q, &m, &pl, s)
                },
                |used, s| {
                    let (q, m) = subset(used);
                    PartitionSurface::fit(&q, &m, &pl, s)
                },
            );
        }
        fit.run(
            py,
            2 * p.len(),
            |s| VariationalSurface::fit(p, n, &pl, s),
            |s| PartitionSurface::fit(p, n, &pl, s),
        )
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
    ///     Read in place when C-contiguous float64, as ``points`` in :meth:`fit`.
    /// faces : (F, 3) int
    ///     Vertex indices of each triangle.
    /// d, w, kernel, smoothing, memory_limit, method, progress, partition_options, merge_distance
    ///     As for :meth:`fit` (``"auto"``: global below 1000 vertices).
    ///
    /// Raises
    /// ------
    /// ValueError
    ///     For out-of-range or repeated indices, unused vertices, and everything :meth:`fit` refuses.
    #[staticmethod]
    #[pyo3(signature = (vertices, faces, *, d=None, w=None, kernel="triharmonic", smoothing=0.0, memory_limit=None, method="auto", progress=None, partition_options=None, merge_distance=None))]
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
        method: &str,
        progress: Option<&Bound<'_, PyAny>>,
        partition_options: Option<&Bound<'_, PyDict>>,
        merge_distance: Option<f64>,
    ) -> PyResult<Self> {
        let _call = super::interrupt::call("VariationalSurface.from_mesh");
        let fit = fit_options(
            method,
            kernel,
            smoothing,
            memory_limit,
            progress,
            partition_options,
            merge_distance,
        )?;
        let v = points_arg(vertices, "vertices")?;
        let v = v.as_slice();
        warn_outside(py, "vertices", v)?;
        let f = triangles(faces, "faces")?;
        let pl = placement(d, w, fit.merge_distance);
        fit.run(
            py,
            2 * v.len(),
            |s| VariationalSurface::from_mesh(v, &f, &pl, s),
            |s| PartitionSurface::from_mesh(v, &f, &pl, s),
        )
    }

    /// Interpolates values at points (no normal constraints): f(points[i]) = values[i].
    ///
    /// Parameters
    /// ----------
    /// points : (N, 3) float64
    ///     Read in place when C-contiguous float64, as in :meth:`fit`.
    /// values : (N,) float64
    /// kernel, smoothing, memory_limit, method, progress, partition_options, merge_distance, tolerance
    ///     As for :meth:`fit` (``"auto"``: global below 2000 points); merged points get the
    ///     mean of their values; with ``tolerance``, every ``|f(points[i]) - values[i]|`` is
    ///     within it (when the fits sufficed).
    ///
    /// Returns
    /// -------
    /// VariationalSurface
    #[staticmethod]
    #[pyo3(signature = (points, values, *, kernel="triharmonic", smoothing=0.0, memory_limit=None, method="auto", progress=None, partition_options=None, merge_distance=None, tolerance=None))]
    #[allow(clippy::too_many_arguments)]
    fn interpolate(
        py: Python<'_>,
        points: &Bound<'_, PyAny>,
        values: &Bound<'_, PyAny>,
        kernel: &str,
        smoothing: f64,
        memory_limit: Option<u64>,
        method: &str,
        progress: Option<&Bound<'_, PyAny>>,
        partition_options: Option<&Bound<'_, PyDict>>,
        merge_distance: Option<f64>,
        tolerance: Option<f64>,
    ) -> PyResult<Self> {
        let _call = super::interrupt::call("VariationalSurface.interpolate");
        let fit = fit_options(
            method,
            kernel,
            smoothing,
            memory_limit,
            progress,
            partition_options,
            merge_distance,
        )?;
        let p = points_arg(points, "points")?;
        let p = p.as_slice();
        warn_outside(py, "points", p)?;
        let v = self::values(values, "values")?;
        let merge = fit.merge_distance;
        if let Some(tolerance) = tolerance {
            if v.len() != p.len() {
                return Err(value_error(
                    "values",
                    format!(
                        "need one value per point: {} values for {} points",
                        v.len(),
                        p.len()
                    ),
                ));
            }
            let subset = |used: &[u32]| -> (Vec<DVec3>, Vec<f64>) {
                (
                    used.iter().map(|&i| p[i as usize]).collect(),
                    used.iter().map(|&i| v[i as usize]).collect(),
                )
            };
            return fit.run_within(
                py,
                tolerance,
                p,
                Some(&v),
                1,
                |used, s| {
                    let (q, w) = subset(used);
                    VariationalSurface::interpolate(&q, &w, merge, s)
                },
                |used, s| {
                    let (q, w) = subset(used);
                    PartitionSurface::interpolate(&q, &w, merge, s)
                },
            );
        }
        fit.run(
            py,
            p.len(),
            |s| VariationalSurface::interpolate(p, &v, merge, s),
            |s| PartitionSurface::interpolate(p, &v, merge, s),
        )
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
        let _call = super::interrupt::call("VariationalSurface.evaluate");
        field_values(py, self.inner.as_field(), points)
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
        let _call = super::interrupt::call("VariationalSurface.gradient");
        field_gradients(py, self.inner.as_field(), points)
    }

    /// Same as :meth:`evaluate`, so that the surface can be used where a callable is expected.
    fn __call__<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let _call = super::interrupt::call("VariationalSurface.__call__");
        self.evaluate(py, points)
    }

    /// (M, 3) float64: the RBF centres (boundary constraints first, then normal constraints).
    /// For a partition fit, the centres of all patches together: the constraint points.
    #[getter]
    fn centers<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let points = match &self.inner {
            Fitted::Global(s) => s.constraints().points.clone(),
            Fitted::Partition(s) => s.constraint_points().into_owned(),
        };
        points_to_py(py, points)
    }

    /// (M,) float64: the weights λ_j. Global fits only: a partition fit has one set of weights
    /// per patch (ValueError).
    #[getter]
    fn weights<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        match &self.inner {
            Fitted::Global(s) => Ok(values_to_py(py, s.weights().to_vec())),
            Fitted::Partition(_) => Err(global_only("weights")),
        }
    }

    /// (4,) float64: the polynomial [a, bx, by, bz] of f = Σ λ φ + a + b·x. Global fits only: a
    /// partition fit has one polynomial per patch (ValueError).
    #[getter]
    fn polynomial<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        match &self.inner {
            Fitted::Global(s) => Ok(values_to_py(py, s.polynomial().to_vec())),
            Fitted::Partition(_) => Err(global_only("polynomial")),
        }
    }

    /// dict or None: for a fit with ``tolerance``, ``rounds`` (fits made), ``used`` (data
    /// points in the last fit, interpolated exactly), ``largest_residual`` (largest
    /// ``|f(p) - target|`` over all data points) and ``outside`` (data points farther than the
    /// tolerance, 0 when the rounds sufficed); None for exact fits and after loading or
    /// unpickling (the state keeps the field, not how it was fitted).
    #[getter]
    fn reduction<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(r) = &self.reduction else {
            return Ok(None);
        };
        let d = PyDict::new(py);
        d.set_item("rounds", r.rounds)?;
        d.set_item("used", r.used)?;
        d.set_item("largest_residual", r.largest_residual)?;
        d.set_item("outside", r.outside)?;
        Ok(Some(d))
    }

    /// str: ``"global"`` or ``"partition"``, the fit in use (what ``method="auto"`` chose).
    #[getter]
    fn method(&self) -> &'static str {
        self.inner.method()
    }

    /// dict describing the patches of a partition fit: ``centers`` (P, 3) float64, ``radii``
    /// (P,) float64 (support radii: a patch's weight is zero from there on), ``inside`` (P,)
    /// int64 (constraints inside each support, all of which the patch interpolates) and
    /// ``sizes`` (P,) int64 (constraints each patch interpolates: those inside, and for patches
    /// with few inside, constraints from around the support). Partition fits only (ValueError
    /// otherwise).
    #[getter]
    fn patches<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let Fitted::Partition(s) = &self.inner else {
            return Err(value_error(
                "patches",
                "only a partition fit (method=\"partition\") has patches",
            ));
        };
        let p = s.patches();
        let d = PyDict::new(py);
        d.set_item(
            "centers",
            points_to_py(py, p.iter().map(|q| q.centre).collect())?,
        )?;
        d.set_item(
            "radii",
            values_to_py(py, p.iter().map(|q| q.radius).collect()),
        )?;
        d.set_item(
            "inside",
            PyArray1::from_vec(py, p.iter().map(|q| q.inside as i64).collect()),
        )?;
        d.set_item(
            "sizes",
            PyArray1::from_vec(py, p.iter().map(|q| q.size as i64).collect()),
        )?;
        Ok(d)
    }

    /// dict with ``points`` (M, 3), ``values`` (M,) (the N boundary constraints, then the N
    /// normal constraints), ``d`` (N,) per-data-point offsets, and
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

    /// float: largest ``|f(c_i) − v_i|`` over the constraints after the fit (for a partition fit,
    /// the largest over the patches and their constraints, which bounds the blend's). With
    /// ``smoothing > 0`` it is the residual of the regularised system,
    /// ``|f(c_i) + smoothing · λ_i − v_i|``; the distance of f from the data is then larger, by
    /// design (evaluate f at the points to see it).
    #[getter]
    fn residual(&self) -> f64 {
        self.inner.residual()
    }

    /// int: how many data points were merged into a nearby point before the fit (points at most
    /// ``merge_distance`` apart; see :meth:`fit`). 0 when every point was kept.
    #[getter]
    fn merged_points(&self) -> usize {
        self.inner.merged()
    }

    /// (2, 3) float64: a cube holding the surface — centred on the data's bounding box, with
    /// side 1.2 × its largest side (a 10 % margin); the box leaves out data points more than 50 ×
    /// the extent of their bulk (the largest 5th–95th percentile spread) from their median,
    /// of which the fit warns. The default ``bounds`` of
    /// :func:`implicitmesh.polygonize` (the papers place their models in a cube too).
    #[getter]
    fn bounds<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let (lo, hi) = self.inner.data_bounding_box();
        let c = (lo + hi) * 0.5;
        let half = DVec3::splat(0.6 * (hi - lo).max_element());
        points_to_py(py, vec![c - half, c + half])
    }

    /// The fitted surface as a dict of numpy arrays and numbers, which
    /// :meth:`from_state` turns back into the same surface (it evaluates to the same bits).
    /// ``pickle`` and :func:`implicitmesh.save` use it.
    ///
    /// Returns
    /// -------
    /// dict
    ///     ``"format"`` (int), ``"method"`` (``"global"`` or ``"partition"``), the constraints
    ///     (``"constraint_points"`` (M, 3) float64, ...) and the fit's numbers.
    fn to_state<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let _call = super::interrupt::call("VariationalSurface.to_state");
        super::state::state(py, &self.inner)
    }

    /// The surface :meth:`to_state` gave, without fitting again.
    ///
    /// Parameters
    /// ----------
    /// state : dict
    ///
    /// Raises
    /// ------
    /// ValueError
    ///     For a dict that :meth:`to_state` did not make (missing keys, lengths that disagree,
    ///     non-finite numbers, another format version).
    #[staticmethod]
    fn from_state(state: &Bound<'_, PyDict>) -> PyResult<Self> {
        let _call = super::interrupt::call("VariationalSurface.from_state");
        Ok(PyVariationalSurface {
            inner: super::state::from_state(state)?,
            reduction: None,
        })
    }

    /// The surface as seen from the box ``bounds`` ((2, 3) array_like): for a partition fit,
    /// only the patches that values and gradients in the box use (the same bits there); a
    /// global fit as it is. What :func:`implicitmesh.distributed.polygonize` sends each tile.
    fn _cut(&self, py: Python<'_>, bounds: &Bound<'_, PyAny>) -> PyResult<Self> {
        let _call = super::interrupt::call("VariationalSurface._cut");
        let b = super::convert::points(bounds, "bounds")?;
        if b.len() != 2 || !b.iter().all(|p| p.is_finite()) {
            return Err(value_error(
                "bounds",
                "expected finite [[xmin, ymin, zmin], [xmax, ymax, zmax]]",
            ));
        }
        let inner = match &self.inner {
            Fitted::Global(_) => self.inner.clone(),
            Fitted::Partition(s) => {
                Fitted::Partition(std::sync::Arc::new(super::interrupt::detach(py, || Ok::<_, PyErr>(s.cut(b[0], b[1])))?))
            }
        };
        Ok(PyVariationalSurface {
            inner,
            reduction: self.reduction.clone(),
        })
    }

    /// Pickling: :meth:`from_state` of :meth:`to_state`.
    fn __reduce__<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyAny>, (Bound<'py, PyDict>,))> {
        let from_state = py
            .get_type::<PyVariationalSurface>()
            .getattr("from_state")?;
        Ok((from_state, (self.to_state(py)?,)))
    }

    fn __len__(&self) -> usize {
        self.inner.constraint_count()
    }

    fn __repr__(&self) -> String {
        let patches = match &self.inner {
            Fitted::Global(_) => String::new(),
            Fitted::Partition(s) => format!(", patches={}", s.patches().len()),
        };
        format!(
            "VariationalSurface(method={:?}, kernel={:?}, centers={}{patches}, residual={:.2e})",
            self.inner.method(),
            self.inner.kernel().name(),
            self.inner.constraint_count(),
            self.inner.residual()
        )
    }
}
