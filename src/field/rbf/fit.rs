//! The fit's choice between one global system and a partition of unity ([`FitMethod`]), made
//! by [`Fit`] for each fit from the number of constraints, and the fitted surface either way
//! ([`Fitted`], a [`Field`]).
//!
//! ```
//! use glam::DVec3;
//! use implicitmesh::field::rbf::{Fit, FitData, FitMethod, FitSettings};
//!
//! // The eight corners of a cube with outward normals: 16 constraints, a global fit.
//! let points: Vec<DVec3> = (0..8)
//!     .map(|i| DVec3::new((i & 1) as f64, (i >> 1 & 1) as f64, (i >> 2) as f64) * 2.0 - 1.0)
//!     .collect();
//! let normals: Vec<DVec3> = points.iter().map(|p| p.normalize()).collect();
//! let data = FitData::Normals { points: &points, normals: &normals };
//! let fit = Fit::new(FitMethod::Auto, FitSettings::default());
//! assert_eq!(fit.chosen(&data), FitMethod::Global);
//! let surface = fit.run(&data).unwrap();
//! assert_eq!(surface.method(), FitMethod::Global);
//! assert!(surface.residual() < 1e-9);
//! ```

use super::constraints::{ConstraintSettings, Constraints};
use super::kernel::Kernel;
use super::partition::{PartitionSettings, PartitionSurface};
use super::reduction::{self, Reduction, ReductionSettings};
use super::{FitSettings, VariationalSurface};
use crate::error::{Error, Result};
use crate::field::scan::{self, ScanSettings, ScanSurface};
use crate::field::{DynBlockField, Field, Starts};
use crate::knn::PointTree;
use crate::lattice::Lattice;
use crate::normals::{estimate_normals, NormalSettings, Viewpoints};
use glam::DVec3;
use rayon::prelude::*;
use std::borrow::Cow;
use std::sync::Arc;

/// Constraints from which [`FitMethod::Auto`] fits a partition of unity instead of one global
/// system (2 per data point for points with normals and meshes, 1 per point for values): about
/// where the partition fit becomes the faster, at the same distance to the sampled surface
/// (see benchmarks/bench_partition.py, `crossover`).
pub const AUTO_PARTITION_CONSTRAINTS: usize = 2000;

/// Which fit: one dense system over every constraint, a partition of unity of patches, or the
/// one of the two the number of constraints calls for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FitMethod {
    /// [`FitMethod::Global`] below [`AUTO_PARTITION_CONSTRAINTS`] constraints,
    /// [`FitMethod::Partition`] from there on.
    #[default]
    Auto,
    /// One dense system over all constraints ([`VariationalSurface`]).
    Global,
    /// Overlapping patches, each fitted the same way, blended ([`PartitionSurface`]).
    Partition,
}

impl FitMethod {
    /// The fit made for `constraints` constraints: [`FitMethod::Global`] or
    /// [`FitMethod::Partition`].
    pub fn resolve(self, constraints: usize) -> FitMethod {
        match self {
            FitMethod::Auto if constraints >= AUTO_PARTITION_CONSTRAINTS => FitMethod::Partition,
            FitMethod::Auto => FitMethod::Global,
            m => m,
        }
    }

    /// `"auto"`, `"global"` or `"partition"`.
    pub fn name(self) -> &'static str {
        match self {
            FitMethod::Auto => "auto",
            FitMethod::Global => "global",
            FitMethod::Partition => "partition",
        }
    }
}

/// The data a surface is fitted to.
#[derive(Clone, Copy, Debug)]
pub enum FitData<'a> {
    /// Points on the surface with outward normals: a boundary and a normal constraint per
    /// point ([`VariationalSurface::fit`]).
    Normals {
        /// The points.
        points: &'a [DVec3],
        /// One normal per point.
        normals: &'a [DVec3],
    },
    /// The vertices of a triangle mesh, with area-weighted normals: a boundary and a normal
    /// constraint per vertex ([`VariationalSurface::from_mesh`]).
    Mesh {
        /// The vertices.
        vertices: &'a [DVec3],
        /// Vertex indices of each triangle, counter-clockwise seen from outside.
        faces: &'a [[u32; 3]],
    },
    /// Values at points: one constraint per point ([`VariationalSurface::interpolate`]).
    Values {
        /// The points.
        points: &'a [DVec3],
        /// One value per point.
        values: &'a [f64],
    },
}

impl FitData<'_> {
    /// The data points (or vertices).
    pub fn data_points(&self) -> usize {
        match self {
            FitData::Normals { points, .. } | FitData::Values { points, .. } => points.len(),
            FitData::Mesh { vertices, .. } => vertices.len(),
        }
    }

    /// The constraints a fit of all the data has (before merging): what
    /// [`FitMethod::Auto`] decides by.
    pub fn constraints(&self) -> usize {
        match self {
            FitData::Values { .. } => self.data_points(),
            _ => 2 * self.data_points(),
        }
    }
}

/// How to fit: the method, the fit's kernel and system, the partition's patches and the
/// constraints' placement. [`Fit::run`] fits all the data, [`Fit::run_within`] only as much as
/// a tolerance needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fit {
    /// Global, partition, or chosen by the number of constraints.
    pub method: FitMethod,
    /// Kernel, smoothing and memory limit, of the global system or of each patch.
    pub settings: FitSettings,
    /// The partition fit's patches; its `fit` is [`Fit::settings`] whatever it holds.
    pub partition: PartitionSettings,
    /// Where normal constraints go, and which points are merged (`merge_distance` also for
    /// [`FitData::Values`]).
    pub placement: ConstraintSettings,
}

impl Default for Fit {
    fn default() -> Self {
        Fit::new(FitMethod::Auto, FitSettings::default())
    }
}

impl Fit {
    /// A fit by `method` with `settings`, the default patches and placement.
    pub fn new(method: FitMethod, settings: FitSettings) -> Self {
        Fit {
            method,
            settings,
            partition: PartitionSettings::default(),
            placement: ConstraintSettings::default(),
        }
    }

    /// The fit [`Fit::run`] makes of `data`: [`FitMethod::Global`] or [`FitMethod::Partition`].
    pub fn chosen(&self, data: &FitData) -> FitMethod {
        self.method.resolve(data.constraints())
    }

    /// The partition fit's settings: [`Fit::partition`] with [`Fit::settings`].
    fn partition_settings(&self) -> PartitionSettings {
        PartitionSettings {
            fit: self.settings,
            ..self.partition
        }
    }

    /// Fits a surface to all of `data`, by the fit [`Fit::chosen`] names.
    pub fn run(&self, data: &FitData) -> Result<Fitted> {
        self.fit_as(self.chosen(data), data)
    }

    /// Fits `data` by `method` (global or partition).
    fn fit_as(&self, method: FitMethod, data: &FitData) -> Result<Fitted> {
        let (pl, merge) = (&self.placement, self.placement.merge_distance);
        if method == FitMethod::Partition {
            let s = &self.partition_settings();
            let surface = match *data {
                FitData::Normals { points, normals } => {
                    PartitionSurface::fit(points, normals, pl, s)
                }
                FitData::Mesh { vertices, faces } => {
                    PartitionSurface::from_mesh(vertices, faces, pl, s)
                }
                FitData::Values { points, values } => {
                    PartitionSurface::interpolate(points, values, merge, s)
                }
            };
            return Ok(Fitted::Partition(Arc::new(surface?)));
        }
        let s = &self.settings;
        let surface = match *data {
            FitData::Normals { points, normals } => VariationalSurface::fit(points, normals, pl, s),
            FitData::Mesh { vertices, faces } => {
                VariationalSurface::from_mesh(vertices, faces, pl, s)
            }
            FitData::Values { points, values } => {
                VariationalSurface::interpolate(points, values, merge, s)
            }
        };
        Ok(Fitted::Global(Arc::new(surface?)))
    }

    /// The scan fit of `points` with `normals` ([`crate::field::scan`]), or with normals
    /// estimated from the points and `viewpoints` when `None` ([`estimate_normals`], over
    /// `scan.neighbours` neighbours): the points cleaned by `scan`, fitted by this fit (within `reduction`, when given, [`Fit::run_within`]), and
    /// guarded by their winding number. Errors name the argument, as [`scan::clean()`]'s and the
    /// fit's do.
    pub fn run_scan(
        &self,
        points: &[DVec3],
        normals: Option<&[DVec3]>,
        viewpoints: Viewpoints<'_>,
        scan: &ScanSettings,
        reduction: Option<&ReductionSettings>,
    ) -> Result<(Fitted, Option<Reduction>)> {
        let estimated;
        let was_estimated = normals.is_none();
        let normals = match normals {
            Some(n) => n,
            None => {
                let settings = NormalSettings {
                    neighbours: scan.neighbours,
                    ..NormalSettings::default()
                };
                estimated = estimate_normals(points, viewpoints, &settings)?.normals;
                &estimated
            }
        };
        let cleaned = scan::clean(points, normals, scan)?;
        let centres =
            scan::centres::separated(&cleaned.points, scan.centre_separation * cleaned.spacing);
        let (p, n): (Vec<DVec3>, Vec<DVec3>) = centres
            .iter()
            .map(|&i| (cleaned.points[i as usize], cleaned.normals[i as usize]))
            .unzip();
        let data = FitData::Normals {
            points: &p,
            normals: &n,
        };
        let (fitted, r) = match reduction {
            Some(settings) => {
                let (f, r) = self.run_within(&data, settings)?;
                (f, Some(r))
            }
            None => (self.run(&data)?, None),
        };
        let mut surface = ScanSurface::new(fitted, &cleaned, scan, points)?;
        surface.report.normals_estimated = was_estimated;
        Ok((Fitted::Scan(Arc::new(surface)), r))
    }

    /// Greedy fits to growing subsets of the points of `data` until every point is within
    /// `reduction.tolerance` ([`reduction::fit_within`]); each fit global or partition as
    /// [`Fit::method`] and the subset's constraints decide.
    ///
    /// Errors (naming `tolerance`) for [`FitData::Mesh`], whose vertices are not fitted apart
    /// from their faces, and for a tolerance that is not finite and positive.
    pub fn run_within(
        &self,
        data: &FitData,
        reduction: &ReductionSettings,
    ) -> Result<(Fitted, Reduction)> {
        let pick = |a: &[DVec3], used: &[u32]| -> Vec<DVec3> {
            used.iter().map(|&i| a[i as usize]).collect()
        };
        match *data {
            FitData::Normals { points, normals } => reduction::fit_within(
                points,
                None,
                reduction,
                |used| {
                    let (p, n) = (pick(points, used), pick(normals, used));
                    let subset = FitData::Normals {
                        points: &p,
                        normals: &n,
                    };
                    self.run(&subset)
                },
                Fitted::as_field,
            ),
            FitData::Values { points, values } => reduction::fit_within(
                points,
                Some(values),
                reduction,
                |used| {
                    let p = pick(points, used);
                    let v: Vec<f64> = used.iter().map(|&i| values[i as usize]).collect();
                    let subset = FitData::Values {
                        points: &p,
                        values: &v,
                    };
                    self.run(&subset)
                },
                Fitted::as_field,
            ),
            FitData::Mesh { .. } => Err(Error::invalid(
                "tolerance",
                "a fit within a tolerance takes points with normals or values, not a mesh",
            )),
        }
    }
}

/// A fitted surface: one global system, or a partition of unity. A [`Field`] either way.
#[derive(Clone, Debug)]
pub enum Fitted {
    /// One dense system over all constraints.
    Global(Arc<VariationalSurface>),
    /// Overlapping patches, blended.
    Partition(Arc<PartitionSurface>),
    /// A global or partition fit of cleaned scan points, guarded by their winding number
    /// ([`crate::field::scan`]); everything but its field is the inner fit's.
    Scan(Arc<ScanSurface<Fitted>>),
}

impl Fitted {
    /// The surface as the field it holds.
    pub fn as_field(&self) -> &(dyn Field + '_) {
        match self {
            Fitted::Global(s) => s.as_ref(),
            Fitted::Partition(s) => s.as_ref(),
            Fitted::Scan(s) => &s.surface,
        }
    }
    /// The scan fit's cleaning, guard and report, for a scan fit.
    pub fn scan(&self) -> Option<&ScanSurface<Fitted>> {
        match self {
            Fitted::Scan(s) => Some(s),
            _ => None,
        }
    }
    /// The interpolating fit: the fit itself, or a scan fit's fit of its cleaned points.
    pub fn interpolant(&self) -> &Fitted {
        match self {
            Fitted::Scan(s) => s.surface.fit().interpolant(),
            f => f,
        }
    }
    /// [`FitMethod::Global`] or [`FitMethod::Partition`].
    pub fn method(&self) -> FitMethod {
        match self {
            Fitted::Global(_) => FitMethod::Global,
            Fitted::Partition(_) => FitMethod::Partition,
            Fitted::Scan(s) => s.surface.fit().method(),
        }
    }
    /// The constraints (for a partition fit, its points gathered into the constraints' order).
    pub fn constraints(&self) -> Cow<'_, Constraints> {
        match self {
            Fitted::Global(s) => Cow::Borrowed(s.constraints()),
            Fitted::Partition(s) => s.constraints(),
            Fitted::Scan(s) => s.surface.fit().constraints(),
        }
    }
    /// The RBF centres: the constraint points, in the constraints' order.
    pub fn centers(&self) -> Cow<'_, [DVec3]> {
        match self {
            Fitted::Global(s) => Cow::Borrowed(&s.constraints().points),
            Fitted::Partition(s) => s.constraint_points(),
            Fitted::Scan(s) => s.surface.fit().centers(),
        }
    }
    /// The number of constraints.
    pub fn constraint_count(&self) -> usize {
        match self {
            Fitted::Global(s) => s.constraints().points.len(),
            Fitted::Partition(s) => s.constraint_count(),
            Fitted::Scan(s) => s.surface.fit().constraint_count(),
        }
    }
    /// The kernel.
    pub fn kernel(&self) -> Kernel {
        match self {
            Fitted::Global(s) => s.kernel(),
            Fitted::Partition(s) => s.kernel(),
            Fitted::Scan(s) => s.surface.fit().kernel(),
        }
    }
    /// Largest |f(c_i) − v_i| over the constraints after the fit (for a partition fit, over
    /// the patches and their constraints).
    pub fn residual(&self) -> f64 {
        match self {
            Fitted::Global(s) => s.residual(),
            Fitted::Partition(s) => s.residual(),
            Fitted::Scan(s) => s.surface.fit().residual(),
        }
    }
    /// Data points merged into others before the fit.
    pub fn merged(&self) -> usize {
        match self {
            Fitted::Global(s) => s.constraints().merged,
            Fitted::Partition(s) => s.merged(),
            Fitted::Scan(s) => s.surface.fit().merged(),
        }
    }
    /// The bounding box of the data.
    pub fn data_bounding_box(&self) -> (DVec3, DVec3) {
        match self {
            Fitted::Global(s) => s.data_bounding_box(),
            Fitted::Partition(s) => s.data_bounding_box(),
            Fitted::Scan(s) => s.surface.fit().data_bounding_box(),
        }
    }
    /// The distance from each of `points` to the nearest data point: a scan fit's kept points,
    /// or the data points of a fit (its boundary constraints). Errors name `points` (not
    /// finite).
    pub fn distances_to_data(&self, points: &[DVec3]) -> Result<Vec<f64>> {
        crate::error::check_finite_points("points", points)?;
        if let Fitted::Scan(s) = self {
            let guard = s.surface.guard();
            return Ok(points
                .par_iter()
                .map(|p| guard.distance_to_data(*p))
                .collect());
        }
        let c = self.constraints();
        let tree = PointTree::new(&c.points[..c.boundary])?;
        let (_, d) = tree.k_nearest(points, 1)?;
        Ok(d)
    }
    /// Whether each vertex of `mesh`, a polygonization of this surface, is kept, and the number
    /// of bodies dropped: for a scan fit, every vertex used by a body its data does not disown
    /// ([`crate::field::scan::bodies`]); for an exact fit, every vertex a triangle uses.
    pub fn owned_vertices(&self, mesh: &crate::mesh::Mesh) -> Result<(Vec<bool>, usize)> {
        crate::error::check_finite_points("vertices", &mesh.vertices)?;
        if let Some(t) = mesh
            .triangles
            .iter()
            .flatten()
            .find(|&&v| v as usize >= mesh.vertices.len())
        {
            return Err(crate::error::Error::invalid(
                "faces",
                format!(
                    "vertex index {t} out of range for {} vertices",
                    mesh.vertices.len()
                ),
            ));
        }
        if let Fitted::Scan(s) = self {
            return Ok(crate::field::scan::bodies::owned_vertices(
                s.surface.guard(),
                mesh,
            ));
        }
        let mut used = vec![false; mesh.vertices.len()];
        for &v in mesh.triangles.iter().flatten() {
            used[v as usize] = true;
        }
        Ok((used, 0))
    }
    /// The surface as seen from the box `lo..hi`: for a partition fit, only the patches that
    /// values and gradients in the box use ([`PartitionSurface::cut`], the same bits there); a
    /// global fit as it is.
    pub fn cut(&self, lo: DVec3, hi: DVec3) -> Fitted {
        match self {
            Fitted::Global(_) => self.clone(),
            Fitted::Partition(s) => Fitted::Partition(Arc::new(s.cut(lo, hi))),
            Fitted::Scan(s) => Fitted::Scan(Arc::new(ScanSurface::from_parts(
                s.surface.fit().cut(lo, hi),
                s.surface.guard().clone(),
                s.report.clone(),
            ))),
        }
    }
}

impl Field for Fitted {
    fn value(&self, p: DVec3) -> f64 {
        self.as_field().value(p)
    }
    fn gradient(&self, p: DVec3) -> DVec3 {
        self.as_field().gradient(p)
    }
    fn fd_step(&self) -> f64 {
        self.as_field().fd_step()
    }
    fn gradient_bound(&self) -> Option<f64> {
        self.as_field().gradient_bound()
    }
    fn values(&self, points: &[DVec3], out: &mut [f64]) {
        self.as_field().values(points, out)
    }
    fn gradients(&self, points: &[DVec3], out: &mut [DVec3]) {
        self.as_field().gradients(points, out)
    }
    fn values_gradients(&self, points: &[DVec3], values: &mut [f64], gradients: &mut [DVec3]) {
        self.as_field().values_gradients(points, values, gradients)
    }
    fn values_per_value_gradient(&self) -> u64 {
        self.as_field().values_per_value_gradient()
    }
    fn values_per_gradient(&self) -> u64 {
        self.as_field().values_per_gradient()
    }
    fn lattice_values(
        &self,
        lattice: &Lattice,
        z0: u32,
        z1: u32,
        points: &mut Vec<DVec3>,
        out: &mut [f64],
    ) {
        self.as_field().lattice_values(lattice, z0, z1, points, out)
    }
    fn starts(&self, cell: f64) -> Option<Starts> {
        self.as_field().starts(cell)
    }
    fn block_field(&self) -> Option<&dyn DynBlockField> {
        self.as_field().block_field()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_chooses_by_the_number_of_constraints() {
        let n = AUTO_PARTITION_CONSTRAINTS;
        assert_eq!(FitMethod::Auto.resolve(n - 1), FitMethod::Global);
        assert_eq!(FitMethod::Auto.resolve(n), FitMethod::Partition);
        assert_eq!(FitMethod::Global.resolve(n), FitMethod::Global);
        assert_eq!(FitMethod::Partition.resolve(1), FitMethod::Partition);
        let p = vec![DVec3::ZERO; n / 2];
        let data = FitData::Normals {
            points: &p,
            normals: &p,
        };
        assert_eq!(data.constraints(), n);
        assert_eq!(Fit::default().chosen(&data), FitMethod::Partition);
        let v = vec![0.0; n / 2];
        let values = FitData::Values {
            points: &p,
            values: &v,
        };
        assert_eq!(Fit::default().chosen(&values), FitMethod::Global);
    }

    #[test]
    fn a_mesh_is_not_fitted_within_a_tolerance() {
        let data = FitData::Mesh {
            vertices: &[],
            faces: &[],
        };
        let r = ReductionSettings {
            tolerance: 1e-3,
            ..Default::default()
        };
        assert!(matches!(
            Fit::default().run_within(&data, &r),
            Err(Error::InvalidArgument {
                name: "tolerance",
                ..
            })
        ));
    }
}
