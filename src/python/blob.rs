//! `BlobField`: the Python class over the core's blob field.

use super::convert::{
    field_gradients, field_values, matrices, matrices_to_py, points, points_to_py, values,
    values_to_py,
};
use crate::field::blob::anisotropy::AnisotropySettings;
use crate::field::blob::kernel::BlobKernel;
use crate::field::blob::particles::{self, ParticleSettings};
use crate::field::blob::{self, BlobField, PerPrimitive, Precision};
use glam::DVec3;
use pyo3::prelude::*;

/// A scalar (float) or one value per primitive (array-like of shape (N,)).
fn per_primitive(obj: &Bound<'_, PyAny>, name: &'static str) -> PyResult<Result<f64, Vec<f64>>> {
    if let Ok(v) = obj.extract::<f64>() {
        return Ok(Ok(v));
    }
    Ok(Err(values(obj, name)?))
}

fn as_per(v: &Result<f64, Vec<f64>>) -> PerPrimitive<'_> {
    match v {
        Ok(s) => PerPrimitive::All(*s),
        Err(a) => PerPrimitive::Each(a),
    }
}

/// A blob field: point primitives with a compact kernel, by default A·(1 − d²/R²)² (Triquet et
/// al.), surface at potential = ``threshold``; as a field, ``threshold − potential`` (negative
/// inside).
///
/// Parameters
/// ----------
/// centers : (N, 3) float64 or float32
///     Primitive positions (C or Fortran order; read as they are, without a copy in Python).
/// radii : float or (N,) float64
///     Radii of influence R (positive): the kernel's compact support.
/// strengths : float or (N,) float64
///     Scale factors A. Default 1.0.
/// threshold : float
///     Potential of the surface (positive). Default 0.5.
/// voxel_size : float, optional
///     Side of the acceleration voxels as a multiple of the mean radius (default 0.5, chosen
///     from the sweep in ``notebooks/triquet_blobs.ipynb``).
/// kernel : {"triquet", "cubic_spline", "wendland"}
///     The profile w(q), q = d/R, each 1 at the centre and 0 from q = 1 on: ``"triquet"``
///     (default) (1 − q²)²; ``"cubic_spline"`` the SPH cubic spline, 1 − 6q² + 6q³ up to
///     q = 1/2 and 2(1 − q)³ beyond; ``"wendland"`` Wendland C2, (1 − q)⁴(1 + 4q). The
///     potential is Σ A·w(d/R); the SPH kernels normalised to integral 1 are these times
///     8/(πR³) and 21/(2πR³). See :meth:`from_particles` for splashsurf's colour field.
/// precision : {"double", "single"}
///     The float type of the field's values: ``"double"`` (default) float64 throughout;
///     ``"single"`` sums the terms in float32 (as splashsurf does by default; the sparse
///     polygonizer splats twice as many values per vector). Evaluation, dense and sparse
///     polygonization all see the same float32 values (returned widened to float64); vertices
///     and normals stay float64. The mesh has the same faces as in double precision wherever no
///     lattice value lies within float32 rounding (about 1e-7 of the potential) of the
///     threshold.
/// shapes : (N, 3, 3) float64, optional
///     Ellipsoidal kernels: primitive i adds A·w(‖Sᵢ (x − cᵢ)‖/Rᵢ) with Sᵢ its shape
///     (invertible, singular values within a factor 10⁴; the identity gives the round kernel).
///     :meth:`from_particles` with ``anisotropic=True`` makes them. Default None (round).
#[pyclass(name = "BlobField", module = "implicitmesh")]
pub struct PyBlobField {
    pub inner: BlobField,
}

#[pymethods]
impl PyBlobField {
    #[new]
    #[pyo3(signature = (centers, radii, strengths=None, threshold=0.5, *, voxel_size=None, kernel="triquet", precision="double", shapes=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        centers: &Bound<'_, PyAny>,
        radii: &Bound<'_, PyAny>,
        strengths: Option<&Bound<'_, PyAny>>,
        threshold: f64,
        voxel_size: Option<f64>,
        kernel: &str,
        precision: &str,
        shapes: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let _call = super::interrupt::call("BlobField");
        let c = points(centers, "centers")?;
        let r = per_primitive(radii, "radii")?;
        let a = match strengths {
            Some(s) => per_primitive(s, "strengths")?,
            None => Ok(1.0),
        };
        let settings = blob::BlobSettings {
            voxel_size: voxel_size.unwrap_or(blob::BlobSettings::default().voxel_size),
            kernel: BlobKernel::parse(kernel)?,
            precision: Precision::parse(precision)?,
        };
        let shapes = shapes.map(|s| matrices(s, "shapes")).transpose()?;
        let inner = super::interrupt::detach(py, || match &shapes {
            None => BlobField::new(&c, as_per(&r), as_per(&a), threshold, settings),
            Some(s) => BlobField::with_shapes(&c, as_per(&r), as_per(&a), threshold, settings, s),
        })?;
        Ok(PyBlobField { inner })
    }

    /// splashsurf's surface of SPH particles: the colour field Σᵢ (m/ρᵢ) W(‖x − xᵢ‖, H) with
    /// densities ρᵢ = Σⱼ m W(‖xᵢ − xⱼ‖, H) computed from the particles, as a blob field of
    /// support H per particle and strengths m/ρᵢ·W(0, H).
    ///
    /// The arguments are splashsurf's: ``pysplashsurf.reconstruct_surface(particles,
    /// particle_radius=r, smoothing_length=ℓ, iso_surface_threshold=T, cube_size=c)`` and
    /// ``polygonize(BlobField.from_particles(particles, r, smoothing_length=ℓ,
    /// iso_surface_threshold=T), bounds, cells)`` with cells of side c·r give the same level set
    /// (pysplashsurf 0.14 reads ``smoothing_length`` and ``cube_size`` relative to the particle
    /// radius). The particle mass (2r)³ρ₀ and the rest density ρ₀ cancel out of the field, so
    /// neither is an argument.
    ///
    /// Parameters
    /// ----------
    /// particles : (N, 3) float64 or float32
    ///     Particle positions (C or Fortran order; read as they are).
    /// particle_radius : float
    ///     r: half the particle spacing (positive).
    /// smoothing_length : float
    ///     ℓ, relative to ``particle_radius``: the kernel's compact support is H = 2ℓr. Default
    ///     2.0.
    /// iso_surface_threshold : float
    ///     The colour field's value on the surface (positive; about 1 inside the fluid). Default
    ///     0.6. The field's :attr:`threshold`.
    /// kernel : {"cubic_spline", "wendland", "triquet"}
    ///     W (see the class docstring). Default ``"cubic_spline"``, splashsurf's.
    /// voxel_size : float, optional
    ///     Side of the acceleration voxels as a multiple of H (default 0.5).
    /// precision : {"double", "single"}
    ///     The float type of the field's values (see the class docstring); the densities are
    ///     computed in float64 either way. Default ``"double"``.
    /// anisotropic : bool or AnisotropyOptions
    ///     Anisotropic kernels (Yu & Turk 2013): each particle's kernel stretched along the
    ///     principal axes of its neighbours (weighted covariance), flattened at the surface, its
    ///     strength times det Sᵢ and its centre moved towards its neighbours' mean, so flat water
    ///     comes out flat. ``True`` takes the defaults of :class:`AnisotropyOptions`. Default
    ///     False (round kernels: splashsurf's field).
    /// progress : bool or callable, optional
    ///     ``True``: show the particle densities computed so far (a tqdm bar when tqdm is
    ///     installed, else a line on standard error); a callable gets that count (an int) about
    ///     every 50 ms.
    ///
    /// Returns
    /// -------
    /// BlobField
    ///     Radii H, strengths m/ρᵢ·W(0, H) = 1/Σⱼ w(‖xᵢ − xⱼ‖/H), threshold ``iso_surface_threshold``.
    ///
    /// Raises
    /// ------
    /// KeyboardInterrupt
    ///     On Ctrl-C, between chunks of 65,536 particles.
    /// ValueError
    ///     For a wrong shape, NaN/inf positions, a non-positive radius, smoothing length,
    ///     threshold or voxel size, or an unknown kernel or precision.
    #[staticmethod]
    #[pyo3(signature = (particles, particle_radius, *, smoothing_length=2.0, iso_surface_threshold=0.6, kernel="cubic_spline", voxel_size=None, precision="double", anisotropic=None, progress=None))]
    #[allow(clippy::too_many_arguments)]
    fn from_particles(
        py: Python<'_>,
        particles: &Bound<'_, PyAny>,
        particle_radius: f64,
        smoothing_length: f64,
        iso_surface_threshold: f64,
        kernel: &str,
        voxel_size: Option<f64>,
        precision: &str,
        anisotropic: Option<&Bound<'_, PyAny>>,
        progress: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let _call = super::interrupt::call("BlobField.from_particles");
        let anisotropy = anisotropy_settings(anisotropic)?;
        let p = points(particles, "particles")?;
        let settings = ParticleSettings {
            smoothing_length,
            iso_surface_threshold,
            kernel: BlobKernel::parse(kernel)?,
            voxel_size: voxel_size.unwrap_or(ParticleSettings::default().voxel_size),
            precision: Precision::parse(precision)?,
            anisotropy,
        };
        let steps = if anisotropy.is_some() { 2 } else { 1 };
        let r = py.import("implicitmesh._progress")?.call_method1(
            "reporter",
            (progress, "from_particles", steps * p.len(), "particles"),
        )?;
        let (report, end): (Bound<'_, PyAny>, Bound<'_, PyAny>) = r.extract()?;
        let report = (!report.is_none()).then_some(report);
        let inner = super::interrupt::run(py, report.as_ref(), false, || {
            particles::colour_field(&p, particle_radius, &settings)
        });
        end.call0()?;
        Ok(PyBlobField { inner: inner? })
    }

    /// Moves the primitives; optionally new radii and strengths (required when the number of
    /// centers changes). Rebuilds the voxel lists in place, without reallocating when the
    /// number of primitives stays the same.
    ///
    /// For animation: from the second polygonization over the same lattice on (``"sparse"``,
    /// ``"tracking"`` or a :class:`Tessellator`), a field of up to 2²⁰ primitives keeps the
    /// lists of primitives per block of the lattice, made with radii grown by an eighth of the
    /// largest, and after ``update`` relists only the blocks that primitives moved beyond that
    /// reach (the z-layers they reach, when more than a quarter of the primitives did); it also
    /// keeps how each block's sign was proved, and tries that proof first in the next frame.
    /// The meshes are those of a new field, bit for bit.
    ///
    /// Parameters
    /// ----------
    /// centers : (N, 3) float64
    /// radii, strengths : float or (N,) float64, optional
    #[pyo3(signature = (centers, radii=None, strengths=None))]
    fn update(
        &mut self,
        py: Python<'_>,
        centers: &Bound<'_, PyAny>,
        radii: Option<&Bound<'_, PyAny>>,
        strengths: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let _call = super::interrupt::call("BlobField.update");
        let c = points(centers, "centers")?;
        let r = radii.map(|r| per_primitive(r, "radii")).transpose()?;
        let a = strengths
            .map(|a| per_primitive(a, "strengths"))
            .transpose()?;
        let inner = &mut self.inner;
        super::interrupt::detach(py, || {
            inner.update(&c, r.as_ref().map(as_per), a.as_ref().map(as_per))
        })?;
        Ok(())
    }

    /// ``threshold − potential`` at points: (N, 3) float64 → (N,) float64.
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let _call = super::interrupt::call("BlobField.evaluate");
        field_values(py, &self.inner, points)
    }

    /// The potential Σ A (1 − d²/R²)² at points: (N, 3) float64 → (N,) float64.
    fn potential<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let _call = super::interrupt::call("BlobField.potential");
        let p = self::points(points, "points")?;
        crate::error::check_finite_points("points", &p)?;
        let b = &self.inner;
        let out = py.detach(|| p.iter().map(|q| b.potential(*q)).collect::<Vec<f64>>());
        Ok(values_to_py(py, out))
    }

    /// Gradient of ``threshold − potential``: (N, 3) float64 → (N, 3) float64.
    fn gradient<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let _call = super::interrupt::call("BlobField.gradient");
        field_gradients(py, &self.inner, points)
    }

    fn __call__<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let _call = super::interrupt::call("BlobField.__call__");
        self.evaluate(py, points)
    }

    /// Which primitives each tile of a lattice cut into tiles needs (``implicitmesh.distributed``):
    /// those whose radius × (1 + ``margin``) reaches the tile's box. Returns ``(index, start)``,
    /// (K,) uint32 and (T + 1,) int64: tile ``t``'s primitives, in increasing order, are
    /// ``index[start[t]:start[t + 1]]``, the tiles of ``tile`` cells (the last along an axis
    /// holds what is left) numbered x fastest, then y, then z. ``origin`` and ``cell`` (3,)
    /// float, ``cells`` and ``tile`` (3,) int.
    fn _tile_primitives<'py>(
        &self,
        py: Python<'py>,
        origin: [f64; 3],
        cell: [f64; 3],
        cells: [u64; 3],
        tile: [u64; 3],
        margin: f64,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let _call = super::interrupt::call("BlobField._tile_primitives");
        let grid = blob::tiles::TileGrid {
            origin: DVec3::from_array(origin),
            cell: DVec3::from_array(cell),
            cells,
            tile,
        };
        let (index, start) = super::interrupt::run(py, None, false, || {
            self.inner.primitives_by_tile(&grid, margin)
        })?;
        let start: Vec<i64> = start.into_iter().map(|s| s as i64).collect();
        Ok((
            numpy::PyArray1::from_vec(py, index).into_any(),
            numpy::PyArray1::from_vec(py, start).into_any(),
        ))
    }

    /// The blob field of the primitives whose radius × (1 + ``margin``) reaches the box
    /// ``bounds`` ((2, 3) array_like), in their order (the same values and gradients in the box
    /// as this field's), or None when none does (the field is positive there). What
    /// :func:`implicitmesh.distributed.cut_blobs` sends a tile.
    fn _cut(
        &self,
        py: Python<'_>,
        bounds: &Bound<'_, PyAny>,
        margin: f64,
    ) -> PyResult<Option<Self>> {
        let _call = super::interrupt::call("BlobField._cut");
        let (lo, hi) = super::convert::finite_box(bounds, "bounds")?;
        let inner = super::interrupt::detach(py, || self.inner.cut(lo, hi, margin))?;
        Ok(inner.map(|inner| PyBlobField { inner }))
    }

    /// The blob field of the primitives ``index`` ((K,) uint32, in that order) with this field's
    /// threshold and settings: the field ``BlobField(centers[index], radii[index],
    /// strengths[index], threshold, **settings)`` is.
    fn _subset(&self, py: Python<'_>, index: numpy::PyReadonlyArray1<'_, u32>) -> PyResult<Self> {
        let _call = super::interrupt::call("BlobField._subset");
        let keep = index.as_array().to_vec();
        let inner = super::interrupt::detach(py, || self.inner.subset(&keep))?;
        Ok(PyBlobField { inner })
    }

    /// (N, 3) float64: the primitive positions.
    #[getter]
    fn centers<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        points_to_py(py, self.inner.centers().to_vec())
    }
    /// (N,) float64: radii of influence R (as given, with or without shapes).
    #[getter]
    fn radii<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        let r = match self.inner.shapes() {
            Some((_, r)) => r,
            None => self.inner.radii(),
        };
        values_to_py(py, r.to_vec())
    }
    /// (N,) float64: the radius of a sphere about each centre holding its kernel's support
    /// (the radii without shapes).
    #[getter]
    fn reaches<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        values_to_py(py, self.inner.radii().to_vec())
    }
    /// (N, 3, 3) float64 or None: the kernels' shapes Sᵢ (see the class docstring).
    #[getter]
    fn shapes<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.inner
            .shapes()
            .map(|(s, _)| matrices_to_py(py, s))
            .transpose()
    }
    /// (N,) float64: strengths A.
    #[getter]
    fn strengths<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        values_to_py(py, self.inner.strengths().to_vec())
    }
    /// str: the kernel's name (``"triquet"``, ``"cubic_spline"`` or ``"wendland"``).
    #[getter]
    fn kernel(&self) -> &'static str {
        self.inner.settings().kernel.name()
    }
    /// str: the float type of the field's values (``"double"`` or ``"single"``).
    #[getter]
    fn precision(&self) -> &'static str {
        self.inner.settings().precision.name()
    }
    /// float: the potential of the surface.
    #[getter]
    fn threshold(&self) -> f64 {
        self.inner.threshold()
    }
    /// float: side of the acceleration voxels (absolute).
    #[getter]
    fn voxel_size(&self) -> f64 {
        self.inner.grid().voxel_size()
    }
    /// (3,) int: voxels per axis.
    #[getter]
    fn voxel_dims(&self) -> [u32; 3] {
        self.inner.grid().dims()
    }
    /// (2, 3) float64: a cube holding every sphere of influence with a 5 % margin (the surface
    /// lies strictly inside it, so meshes over it are closed).
    #[getter]
    fn bounds<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let (lo, hi) = self
            .inner
            .bounding_box()
            .unwrap_or((DVec3::splat(-1.0), DVec3::splat(1.0)));
        let c = (lo + hi) * 0.5;
        let half = DVec3::splat(0.5 * 1.1 * (hi - lo).max_element());
        points_to_py(py, vec![c - half, c + half])
    }
    /// Pickling: the constructor's arguments, which rebuild the same field.
    #[allow(clippy::type_complexity)]
    fn __getnewargs_ex__<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(
        (Bound<'py, PyAny>, Bound<'py, PyAny>, Bound<'py, PyAny>, f64),
        Bound<'py, pyo3::types::PyDict>,
    )> {
        let kwargs = pyo3::types::PyDict::new(py);
        kwargs.set_item("voxel_size", self.inner.settings().voxel_size)?;
        kwargs.set_item("kernel", self.kernel())?;
        kwargs.set_item("precision", self.precision())?;
        kwargs.set_item("shapes", self.shapes(py)?)?;
        Ok((
            (
                self.centers(py)?,
                self.radii(py),
                self.strengths(py),
                self.threshold(),
            ),
            kwargs,
        ))
    }
    fn __len__(&self) -> usize {
        self.inner.centers().len()
    }
    fn __repr__(&self) -> String {
        format!(
            "BlobField(primitives={}, threshold={}, kernel={:?}, precision={:?})",
            self.inner.centers().len(),
            self.inner.threshold(),
            self.kernel(),
            self.precision()
        )
    }
}

/// The core's anisotropy settings from ``anisotropic`` (None or False: none; True: the
/// defaults; an object with the attributes of `AnisotropyOptions`: those, each None for the
/// default).
fn anisotropy_settings(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Option<AnisotropySettings>> {
    let Some(obj) = obj else { return Ok(None) };
    if obj.is_none() {
        return Ok(None);
    }
    if let Ok(b) = obj.cast::<pyo3::types::PyBool>() {
        return Ok(b.is_true().then(AnisotropySettings::default));
    }
    if !obj.hasattr("k_r")? {
        return Err(super::errors::value_error(
            "anisotropic",
            "expected a bool or an AnisotropyOptions",
        ));
    }
    let mut s = AnisotropySettings::default();
    let get = |name: &str| -> PyResult<Option<f64>> {
        obj.getattr(name)?.extract::<Option<f64>>().map_err(|_| {
            super::errors::value_error("anisotropic", format!("{name} must be a float"))
        })
    };
    if let Some(v) = get("neighbour_radius")? {
        s.neighbour_radius = v;
    }
    if let Some(v) = get("k_r")? {
        s.k_r = v;
    }
    if let Some(v) = get("k_s")? {
        s.k_s = v;
    }
    if let Some(v) = get("k_n")? {
        s.k_n = v;
    }
    if let Some(v) = get("smoothing")? {
        s.smoothing = v;
    }
    if let Some(v) = obj
        .getattr("min_neighbours")?
        .extract::<Option<i64>>()
        .map_err(|_| super::errors::value_error("anisotropic", "min_neighbours must be an int"))?
    {
        if v < 0 {
            return Err(super::errors::value_error(
                "min_neighbours",
                format!("must be non-negative, got {v}"),
            ));
        }
        s.min_neighbours = v as usize;
    }
    s.check()?;
    Ok(Some(s))
}
