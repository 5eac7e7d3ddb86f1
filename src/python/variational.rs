//! `VariationalSurface`: the Python class over the core's fitted surface.

use super::convert::{
    field_gradients, field_values, points_arg, points_to_py, triangles, values, values_to_py,
};
use super::errors::value_error;
use crate::field::rbf::constraints;
use crate::field::rbf::kernel::Kernel;
use crate::field::rbf::partition;
use crate::field::rbf::reduction::{Reduction, ReductionSettings};
use crate::field::rbf::{self, Fit, FitData, FitMethod, Fitted};
use crate::field::scan::ScanSettings;
use crate::normals::Viewpoints;
use glam::DVec3;
use numpy::PyArray1;
use pyo3::exceptions::PyUserWarning;
use pyo3::prelude::*;
use pyo3::types::PyDict;

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

fn parse_method(method: &str) -> PyResult<FitMethod> {
    match method {
        "global" => Ok(FitMethod::Global),
        "partition" => Ok(FitMethod::Partition),
        "auto" => Ok(FitMethod::Auto),
        _ => Err(value_error(
            "method",
            format!("unknown method {method:?}; use \"auto\", \"global\" or \"partition\""),
        )),
    }
}

/// The keyword arguments that `fit`, `from_mesh` and `interpolate` share, converted and checked
/// in this order: `method`, then `kernel`, `smoothing` and `memory_limit`, then
/// `partition_options`, then `merge_distance`; with the progress report.
struct FitOptions<'a, 'py> {
    fit: Fit,
    progress: Option<&'a Bound<'py, PyAny>>,
}

/// [`FitOptions`] from the Python arguments (`d` and `w` place the normal constraints).
#[allow(clippy::too_many_arguments)]
fn fit_options<'a, 'py>(
    method: &str,
    kernel: &str,
    smoothing: f64,
    memory_limit: Option<u64>,
    progress: Option<&'a Bound<'py, PyAny>>,
    partition_options: Option<&Bound<'_, PyDict>>,
    merge_distance: Option<f64>,
    (d, w): (Option<f64>, Option<f64>),
) -> PyResult<FitOptions<'a, 'py>> {
    let method = parse_method(method)?;
    let settings = fit_settings(kernel, smoothing, memory_limit)?;
    let partition = partition_settings(partition_options)?;
    let merge_distance = constraints::check_merge_distance(merge_distance)?;
    Ok(FitOptions {
        fit: Fit {
            method,
            settings,
            partition,
            placement: constraints::ConstraintSettings {
                d,
                w,
                merge_distance,
                ..Default::default()
            },
        },
        progress,
    })
}

impl<'a, 'py> FitOptions<'a, 'py> {
    /// The scan fit of `points` with `normals` ([`Fit::run_scan`]) with the GIL released, the
    /// cleaned points fitted with `tolerance` only as much as it needs; warns when every normal
    /// was turned outward, or the rounds did not suffice.
    fn run_scan(
        self,
        py: Python<'py>,
        points: &[DVec3],
        normals: Option<&[DVec3]>,
        viewpoints: Viewpoints<'_>,
        tolerance: Option<f64>,
    ) -> PyResult<PyVariationalSurface> {
        let fit = self.fit;
        let reduction = tolerance.map(|tolerance| ReductionSettings {
            tolerance,
            ..Default::default()
        });
        if let Some(r) = &reduction {
            r.check()?;
        }
        let scan = ScanSettings::default();
        let (report, end) = reporter(py, self.progress, "fit (scan)")?;
        let fitted = super::interrupt::run(py, report.as_ref(), false, || {
            fit.run_scan(points, normals, viewpoints, &scan, reduction.as_ref())
        });
        end.call0()?;
        let (inner, r) = fitted?;
        warn_merged(py, inner.merged())?;
        if inner.scan().is_some_and(|s| s.report.turned_outward) {
            let message = c"normals: most normals pointed into the body the points enclose; \
                            all were turned outward (see VariationalSurface.report)";
            PyErr::warn(py, &py.get_type::<PyUserWarning>(), message, 1)?;
        }
        if let (Some(r), Some(t)) = (&r, tolerance) {
            warn_beyond_tolerance(py, r, t, points.len())?;
        }
        Ok(PyVariationalSurface {
            inner,
            reduction: r,
        })
    }

    /// Fits all of `data` ([`Fit::run`]) with the GIL released, or with `tolerance` only as
    /// much as it needs ([`Fit::run_within`]), warning when the rounds did not suffice.
    fn run(
        self,
        py: Python<'py>,
        data: FitData<'_>,
        tolerance: Option<f64>,
    ) -> PyResult<PyVariationalSurface> {
        let fit = self.fit;
        let Some(tolerance) = tolerance else {
            let what = format!("fit ({})", fit.chosen(&data).name());
            let (report, end) = reporter(py, self.progress, &what)?;
            let fitted = super::interrupt::run(py, report.as_ref(), false, || fit.run(&data));
            end.call0()?;
            let inner = fitted?;
            warn_merged(py, inner.merged())?;
            return Ok(PyVariationalSurface {
                inner,
                reduction: None,
            });
        };
        let settings = ReductionSettings {
            tolerance,
            ..Default::default()
        };
        settings.check()?;
        let (report, end) = reporter(py, self.progress, "fit (within tolerance)")?;
        let fitted = super::interrupt::run(py, report.as_ref(), false, || {
            fit.run_within(&data, &settings)
        });
        end.call0()?;
        let (inner, r) = fitted?;
        warn_merged(py, inner.merged())?;
        warn_beyond_tolerance(py, &r, tolerance, data.data_points())?;
        Ok(PyVariationalSurface {
            inner,
            reduction: Some(r),
        })
    }
}

/// A `UserWarning` when points stayed farther than `tolerance` from a reduced fit.
fn warn_beyond_tolerance(
    py: Python<'_>,
    r: &Reduction,
    tolerance: f64,
    points: usize,
) -> PyResult<()> {
    if r.outside == 0 {
        return Ok(());
    }
    let message = std::ffi::CString::new(format!(
        "{} of {points} data points are farther than tolerance={tolerance:e} from the surface \
         after {} fits (largest {:.3e}); see VariationalSurface.reduction",
        r.outside, r.rounds, r.largest_residual
    ))
    .expect("no NUL in the message");
    PyErr::warn(py, &py.get_type::<PyUserWarning>(), &message, 1)
}

/// The partition fit's patches: the defaults, with the keys of `options` (a dict) in place
/// (their `fit` is the [`Fit`]'s settings).
fn partition_settings(
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<partition::PartitionSettings> {
    let mut s = partition::PartitionSettings::default();
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
    /// normals : (N, 3) float64, optional
    ///     Outward normals, any non-zero length (they are normalised). When None (points
    ///     alone), the scan fit estimates them (:func:`implicitmesh.estimate_normals`, with
    ///     ``viewpoints``) and its :attr:`report` says so; an exact fit needs them.
    /// viewpoints : (3,) or (N, 3) float64, optional
    ///     Where the sensor was, for estimating normals (see
    ///     :func:`implicitmesh.estimate_normals`); only with ``normals=None``.
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
    #[pyo3(signature = (points, normals=None, *, exact=false, viewpoints=None, d=None, w=None, kernel="triharmonic", smoothing=0.0, memory_limit=None, method="auto", progress=None, partition_options=None, merge_distance=None, tolerance=None))]
    #[allow(clippy::too_many_arguments)]
    fn fit(
        py: Python<'_>,
        points: &Bound<'_, PyAny>,
        normals: Option<&Bound<'_, PyAny>>,
        exact: bool,
        viewpoints: Option<&Bound<'_, PyAny>>,
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
            (d, w),
        )?;
        let p = points_arg(points, "points")?;
        let p = p.as_slice();
        warn_outside(py, "points", p)?;
        let Some(normals) = normals else {
            if exact {
                return Err(value_error(
                    "normals",
                    "an exact fit (exact=True) needs normals; leave exact=False to estimate them",
                ));
            }
            let views = super::normals::viewpoints_arg(viewpoints)?;
            let views = views.as_viewpoints();
            return fit.run_scan(py, p, None, views, tolerance);
        };
        if viewpoints.is_some() {
            return Err(value_error(
                "viewpoints",
                "only used to estimate normals (normals=None)",
            ));
        }
        let n = points_arg(normals, "normals")?;
        let n = n.as_slice();
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
        if !exact {
            return fit.run_scan(py, p, Some(n), Viewpoints::None, tolerance);
        }
        let data = FitData::Normals {
            points: p,
            normals: n,
        };
        fit.run(py, data, tolerance)
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
            (d, w),
        )?;
        let v = points_arg(vertices, "vertices")?;
        let v = v.as_slice();
        warn_outside(py, "vertices", v)?;
        let f = triangles(faces, "faces")?;
        let data = FitData::Mesh {
            vertices: v,
            faces: &f,
        };
        fit.run(py, data, None)
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
            (None, None),
        )?;
        let p = points_arg(points, "points")?;
        let p = p.as_slice();
        warn_outside(py, "points", p)?;
        let v = self::values(values, "values")?;
        if tolerance.is_some() && v.len() != p.len() {
            return Err(value_error(
                "values",
                format!(
                    "need one value per point: {} values for {} points",
                    v.len(),
                    p.len()
                ),
            ));
        }
        let data = FitData::Values {
            points: p,
            values: &v,
        };
        fit.run(py, data, tolerance)
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
        points_to_py(py, self.inner.centers().into_owned())
    }

    /// (M,) float64: the weights λ_j. Global fits only: a partition fit has one set of weights
    /// per patch (ValueError).
    #[getter]
    fn weights<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        match self.inner.interpolant() {
            Fitted::Global(s) => Ok(values_to_py(py, s.weights().to_vec())),
            _ => Err(global_only("weights")),
        }
    }

    /// (4,) float64: the polynomial [a, bx, by, bz] of f = Σ λ φ + a + b·x. Global fits only: a
    /// partition fit has one polynomial per patch (ValueError).
    #[getter]
    fn polynomial<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        match self.inner.interpolant() {
            Fitted::Global(s) => Ok(values_to_py(py, s.polynomial().to_vec())),
            _ => Err(global_only("polynomial")),
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

    /// The distance from each point to the nearest data point: the points a scan fit kept, or
    /// the data points of an exact fit (what ``polygonize(..., trim=)`` measures).
    ///
    /// Parameters
    /// ----------
    /// points : (N, 3) float64
    ///
    /// Returns
    /// -------
    /// (N,) float64
    fn distance_to_data<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let p = points_arg(points, "points")?;
        let (p, inner) = (p.as_slice(), &self.inner);
        let d = super::interrupt::run(py, None, false, || inner.distances_to_data(p))?;
        Ok(values_to_py(py, d))
    }

    /// Which vertices of a polygonization of this surface belong to a body its data owns.
    ///
    /// A scan fit may close a small bubble or void near a stray point; the data's winding number
    /// disowns such a body (see ``docs/scans.md``). :func:`implicitmesh.polygonize` drops them.
    ///
    /// Parameters
    /// ----------
    /// vertices : (V, 3) float64
    /// faces : (F, 3) int
    ///
    /// Returns
    /// -------
    /// keep : (V,) bool
    ///     True for a vertex of a kept body; for an exact fit, True for every vertex a face uses.
    /// dropped : int
    ///     The number of bodies disowned (0 for an exact fit).
    fn owned_vertices<'py>(
        &self,
        py: Python<'py>,
        vertices: &Bound<'py, PyAny>,
        faces: &Bound<'py, PyAny>,
    ) -> PyResult<(Bound<'py, PyAny>, usize)> {
        let mesh = super::convert::mesh_arg(vertices, faces)?;
        let inner = &self.inner;
        let (keep, dropped) =
            super::interrupt::run(py, None, false, || inner.owned_vertices(&mesh))?;
        Ok((PyArray1::from_vec(py, keep).into_any(), dropped))
    }

    /// (K,) int64 or None: the indices of the points a scan fit left out as outliers,
    /// increasing; None for an exact fit.
    #[getter]
    fn outliers<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        let scan = self.inner.scan()?;
        let o: Vec<i64> = scan.report.outliers.iter().map(|&i| i as i64).collect();
        Some(PyArray1::from_vec(py, o).into_any())
    }

    /// dict or None: what a scan fit found in its data. ``"points"`` given, ``"outliers"``
    /// (the number left out), ``"spacing"`` (median distance from a cleaned point to its 6th
    /// nearest neighbour; where very noisy points were averaged in cells, of the averages),
    /// ``"noise"`` (the estimated noise: the median root-mean-square distance of a
    /// neighbourhood from its plane, in the points' units), ``"normals_corrected"`` (kept points
    /// whose normal was turned to agree with its neighbours'), ``"turned_outward"`` (True when
    /// the normals pointed inward and all were turned), ``"normals_estimated"`` (True when the
    /// points came without normals), and the distance from the kept points,
    /// as given, to the surface: ``"distance_mean"``, ``"distance_p99"``,
    /// ``"distance_max"``. None for an exact fit.
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(scan) = self.inner.scan() else {
            return Ok(None);
        };
        let r = &scan.report;
        let d = PyDict::new(py);
        d.set_item("points", r.points)?;
        d.set_item("outliers", r.outliers.len())?;
        d.set_item("spacing", r.spacing)?;
        d.set_item("noise", r.noise)?;
        d.set_item("normals_corrected", r.normals_corrected)?;
        d.set_item("turned_outward", r.turned_outward)?;
        d.set_item("normals_estimated", r.normals_estimated)?;
        d.set_item("distance_mean", r.distance_mean)?;
        d.set_item("distance_p99", r.distance_p99)?;
        d.set_item("distance_max", r.distance_max)?;
        Ok(Some(d))
    }

    /// str: ``"global"`` or ``"partition"``, the fit in use (what ``method="auto"`` chose).
    #[getter]
    fn method(&self) -> &'static str {
        self.inner.method().name()
    }

    /// dict describing the patches of a partition fit: ``centers`` (P, 3) float64, ``radii``
    /// (P,) float64 (support radii: a patch's weight is zero from there on), ``inside`` (P,)
    /// int64 (constraints inside each support, all of which the patch interpolates) and
    /// ``sizes`` (P,) int64 (constraints each patch interpolates: those inside, and for patches
    /// with few inside, constraints from around the support). Partition fits only (ValueError
    /// otherwise).
    #[getter]
    fn patches<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let Fitted::Partition(s) = self.inner.interpolant() else {
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
        let (lo, hi) = super::convert::finite_box(bounds, "bounds")?;
        let inner = super::interrupt::detach(py, || Ok::<_, PyErr>(self.inner.cut(lo, hi)))?;
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
        let patches = match self.inner.interpolant() {
            Fitted::Partition(s) => format!(", patches={}", s.patches().len()),
            _ => String::new(),
        };
        let scan = match self.inner.scan() {
            Some(s) => format!(", scan=True, outliers={}", s.report.outliers.len()),
            None => String::new(),
        };
        format!(
            "VariationalSurface(method={:?}, kernel={:?}, centers={}{patches}, residual={:.2e}{scan})",
            self.inner.method().name(),
            self.inner.kernel().name(),
            self.inner.constraint_count(),
            self.inner.residual()
        )
    }
}
