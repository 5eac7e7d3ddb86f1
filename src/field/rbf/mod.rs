//! Variational implicit surfaces (Turk & O'Brien; Cuno et al. §3–4.2; Jin et al. §2):
//! f(x) = Σ_j λ_j φ(|x − c_j|) + a + b·x, fitted so that f(c_i) = v_i exactly.
//!
//! The fit works in normalised coordinates (data centred on its bounding box and scaled so its
//! largest half-side is 1), which keeps the system's entries of order one whatever the units of
//! the data; the interpolant is similarity-equivariant, so this changes nothing but the rounding.
//!
//! Two fits: [`VariationalSurface`] solves one dense system over every constraint,
//! [`partition::PartitionSurface`] blends patches fitted the same way. [`Fit`] chooses between
//! them by the number of constraints ([`FitMethod::Auto`], [`AUTO_PARTITION_CONSTRAINTS`]) and
//! gives either as a [`Fitted`] surface; [`Fit::run_within`] fits only as many points as a
//! tolerance needs ([`reduction`]), choosing again for each round.

pub mod constraints;
pub mod duplicates;
mod fit;
pub mod kernel;
pub mod partition;
mod parts;
mod patch;
pub mod reduction;
pub mod thin;

pub use fit::{Fit, FitData, FitMethod, Fitted, AUTO_PARTITION_CONSTRAINTS};
pub(crate) use parts::bad_state;
pub use parts::SurfaceParts;
pub use patch::{PatchCentres, PatchFit};

use super::Field;
use crate::error::{Error, Result};
use crate::field::rbf::kernel::{
    block_gradients, block_values, block_values_gradients, values_by_point,
    values_gradients_by_point, Arithmetic, Biharmonic, Block, Centres, Kernel, RadialFn, ThinPlate,
    Triharmonic, LANES,
};
use crate::linalg::saddle::SaddleSolver;
use constraints::{bounding_box, Constraints};
use faer::Par;
use glam::DVec3;
use rayon::prelude::*;

/// How a variational surface is fitted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitSettings {
    /// The radial basis function φ.
    pub kernel: Kernel,
    /// Added to the diagonal of the kernel block: 0 interpolates exactly, > 0 smooths noisy data.
    pub smoothing: f64,
    /// Refuse systems whose dense matrix would need more than this many bytes.
    pub memory_limit: u64,
}

impl Default for FitSettings {
    fn default() -> Self {
        FitSettings {
            kernel: Kernel::Triharmonic,
            smoothing: 0.0,
            memory_limit: crate::memory::DEFAULT_MEMORY_LIMIT,
        }
    }
}

/// A fitted variational implicit surface: negative inside, positive outside (when the normals
/// given point out of the solid).
#[derive(Clone, Debug)]
pub struct VariationalSurface {
    kernel: Kernel,
    /// Centres in the caller's coordinates.
    centers: Vec<DVec3>,
    /// Weights λ_j in the caller's coordinates.
    weights: Vec<f64>,
    /// Linear polynomial a + b·x in the caller's coordinates: [a, bx, by, bz].
    poly: [f64; 4],
    /// Normalisation x' = (x − shift) · scale.
    shift: DVec3,
    scale: f64,
    /// Centres (normalised) and weights (of the normalised problem) for evaluation.
    soa: Centres,
    /// Polynomial of the normalised problem.
    npoly: [f64; 4],
    constraints: Constraints,
    residual: f64,
    factorization: &'static str,
}

fn dispatch_values(kernel: Kernel, c: &Centres, blocks: &[Block], out: &mut [[f64; LANES]]) {
    match kernel {
        Kernel::Triharmonic => block_values::<Triharmonic>(c, blocks, out),
        Kernel::Biharmonic => block_values::<Biharmonic>(c, blocks, out),
        Kernel::ThinPlate => block_values::<ThinPlate>(c, blocks, out),
    }
}

/// Kernel sums at a few points (see [`values_by_point`]).
fn dispatch_by_point(kernel: Kernel, c: &Centres, q: &[[f64; 3]], out: &mut [f64]) {
    match kernel {
        Kernel::Triharmonic => values_by_point::<Triharmonic>(c, q, out),
        Kernel::Biharmonic => values_by_point::<Biharmonic>(c, q, out),
        Kernel::ThinPlate => values_by_point::<ThinPlate>(c, q, out),
    }
}

/// Kernel sums and gradients at a few points (see [`values_gradients_by_point`]).
fn dispatch_gradients_by_point(kernel: Kernel, c: &Centres, q: &[[f64; 3]], out: &mut [[f64; 4]]) {
    match kernel {
        Kernel::Triharmonic => values_gradients_by_point::<Triharmonic>(c, q, out),
        Kernel::Biharmonic => values_gradients_by_point::<Biharmonic>(c, q, out),
        Kernel::ThinPlate => values_gradients_by_point::<ThinPlate>(c, q, out),
    }
}

/// Kernel sums and gradients of a run of blocks; with `values` false, only the gradients.
fn dispatch_values_gradients(
    kernel: Kernel,
    c: &Centres,
    blocks: &[Block],
    out: &mut [[[f64; LANES]; 4]],
    values: bool,
) {
    match (kernel, values) {
        (Kernel::Triharmonic, true) => block_values_gradients::<Triharmonic>(c, blocks, out),
        (Kernel::Biharmonic, true) => block_values_gradients::<Biharmonic>(c, blocks, out),
        (Kernel::ThinPlate, true) => block_values_gradients::<ThinPlate>(c, blocks, out),
        (Kernel::Triharmonic, false) => block_gradients::<Triharmonic>(c, blocks, out),
        (Kernel::Biharmonic, false) => block_gradients::<Biharmonic>(c, blocks, out),
        (Kernel::ThinPlate, false) => block_gradients::<ThinPlate>(c, blocks, out),
    }
}

/// Values, and gradients when `gradients` is given, at normalised points `q`, by point: the
/// kernel sums of [`values_by_point`] over the centres `c` plus the normalised polynomial
/// `npoly` (gradients in the caller's coordinates, through `scale`).
fn sums_by_point(
    kernel: Kernel,
    c: &Centres,
    npoly: [f64; 4],
    scale: f64,
    q: &[[f64; 3]],
    values: &mut [f64],
    gradients: Option<&mut [DVec3]>,
) {
    let [a, bx, by, bz] = npoly;
    let poly = |s: f64, p: &[f64; 3]| s + a + bx * p[0] + by * p[1] + bz * p[2];
    match gradients {
        None => {
            dispatch_by_point(kernel, c, q, values);
            for (v, p) in values.iter_mut().zip(q) {
                *v = poly(*v, p);
            }
        }
        Some(g) => {
            let mut sums = vec![[0.0; 4]; q.len()];
            dispatch_gradients_by_point(kernel, c, q, &mut sums);
            for (((v, g), s), p) in values.iter_mut().zip(g.iter_mut()).zip(&sums).zip(q) {
                *v = poly(s[0], p);
                *g = DVec3::new(s[1] + bx, s[2] + by, s[3] + bz) * scale;
            }
        }
    }
}

/// Points per rayon task when evaluating (a multiple of LANES).
const EVAL_CHUNK: usize = 256;

/// The factorized system for `points` (normalised) with `kernel`: null-space Cholesky with the
/// LBLᵀ fallback, or LBLᵀ of the whole system when `whole`. One instance per kernel, so that
/// the assembly's inner loop has no branch on it.
fn saddle_solver(
    kernel: Kernel,
    points: &[DVec3],
    smoothing: f64,
    par: Par,
    whole: bool,
) -> Result<SaddleSolver> {
    fn make<K: RadialFn>(
        points: &[DVec3],
        smoothing: f64,
        sign: f64,
        par: Par,
        whole: bool,
    ) -> Result<SaddleSolver> {
        let phi = Arithmetic::<K>::default();
        if whole {
            SaddleSolver::full(points, phi, smoothing, par)
        } else {
            SaddleSolver::with_parallelism(points, phi, smoothing, sign, par)
        }
    }
    let sign = kernel.cpd_sign();
    match kernel {
        Kernel::Triharmonic => make::<Triharmonic>(points, smoothing, sign, par, whole),
        Kernel::Biharmonic => make::<Biharmonic>(points, smoothing, sign, par, whole),
        Kernel::ThinPlate => make::<ThinPlate>(points, smoothing, sign, par, whole),
    }
}

/// Whether a solution (weights and polynomial) is finite.
fn all_finite(lam: &[f64], a: &[f64; 4]) -> bool {
    lam.iter().chain(a.iter()).all(|x| x.is_finite())
}

impl VariationalSurface {
    /// Fits a surface to `points` with outward `normals` (Cuno §4.1): boundary constraints at the
    /// points, normal constraints at `q + d n`.
    pub fn fit(
        points: &[DVec3],
        normals: &[DVec3],
        placement: &constraints::ConstraintSettings,
        settings: &FitSettings,
    ) -> Result<Self> {
        check_system_memory(2 * points.len(), settings.memory_limit)?;
        let c = constraints::place(points, normals, placement)?;
        Self::solve(c, settings, faer::get_global_parallelism(), false)
            .map_err(|e| constraints::diagnose_far("points", points, e))
    }

    /// Fits a surface to the vertices of a triangle mesh, with area-weighted vertex normals
    /// (faces counter-clockwise seen from outside). Exact duplicate vertices are merged first.
    pub fn from_mesh(
        vertices: &[DVec3],
        faces: &[[u32; 3]],
        placement: &constraints::ConstraintSettings,
        settings: &FitSettings,
    ) -> Result<Self> {
        let (v, f, n) = constraints::mesh_vertices_normals(vertices, faces)?;
        check_system_memory(2 * v.len(), settings.memory_limit)?;
        let caps = constraints::crease_caps(&v, &f, &n);
        let c = constraints::place_capped(&v, &n, placement, Some(&caps))?;
        Self::solve(c, settings, faer::get_global_parallelism(), false)
            .map_err(|e| constraints::diagnose_far("vertices", &v, e))
    }

    /// Interpolates arbitrary values at arbitrary points (no normal constraints added).
    /// Points at most `merge_distance` apart are merged, their values averaged (`None`: the
    /// default tolerance of [`constraints::ConstraintSettings::merge_distance`]).
    pub fn interpolate(
        points: &[DVec3],
        values: &[f64],
        merge_distance: Option<f64>,
        settings: &FitSettings,
    ) -> Result<Self> {
        check_system_memory(points.len(), settings.memory_limit)?;
        let c = constraints::interpolation_data(points, values, merge_distance)?;
        Self::solve(c, settings, faer::get_global_parallelism(), false)
            .map_err(|e| constraints::diagnose_far("points", points, e))
    }

    /// Fits the constraints; `by_point` for a patch of a partition fit, whose residuals are
    /// measured with the sums its evaluation uses ([`PatchFit::eval_on_this_thread`]).
    fn solve(c: Constraints, settings: &FitSettings, par: Par, by_point: bool) -> Result<Self> {
        if !(settings.smoothing.is_finite() && settings.smoothing >= 0.0) {
            return Err(Error::invalid(
                "smoothing",
                format!(
                    "must be finite and non-negative, got {}",
                    settings.smoothing
                ),
            ));
        }
        let kernel = settings.kernel;
        let (lo, hi) = bounding_box(&c.points);
        let shift = (lo + hi) * 0.5;
        let half = 0.5 * (hi - lo).max_element();
        let scale = 1.0 / half;
        let np: Vec<DVec3> = c.points.iter().map(|p| (*p - shift) * scale).collect();
        let n = np.len();

        // Symmetric indefinite saddle-point system: see `saddle.rs` for the factorization
        // (null-space Cholesky, falling back to Bunch–Kaufman LBLᵀ) and why.
        let smoothing = settings.smoothing * scale.powi(kernel.degree());
        let mut solver = saddle_solver(kernel, &np, smoothing, par, false)?;
        let (mut lam0, mut a0) = solver.solve(&c.values, [0.0; 4]);
        // A null-space factor of a nearly degenerate system can pass its pivot checks and
        // still give a solution that is not finite: solve the whole system instead.
        if !all_finite(&lam0, &a0) && solver.method() == "cholesky" {
            solver = saddle_solver(kernel, &np, smoothing, par, true)?;
            (lam0, a0) = solver.solve(&c.values, [0.0; 4]);
        }
        let mut x = (lam0, a0);

        let mut s = VariationalSurface {
            kernel,
            centers: c.points.clone(),
            weights: vec![],
            poly: [0.0; 4],
            shift,
            scale,
            soa: Centres {
                x: np.iter().map(|p| p.x).collect(),
                y: np.iter().map(|p| p.y).collect(),
                z: np.iter().map(|p| p.z).collect(),
                w: vec![0.0; n],
            },
            npoly: [0.0; 4],
            constraints: c,
            residual: f64::INFINITY,
            factorization: "",
        };
        let target = 1e-13
            * s.constraints
                .values
                .iter()
                .fold(1.0, |a: f64, v| a.max(v.abs()));
        // (residual, (weights, polynomial)) of the best solution so far.
        type Solution = (Vec<f64>, [f64; 4]);
        let mut best: Option<(f64, Solution)> = None;
        for _ in 0..4 {
            crate::cancel::check()?;
            s.set_solution(&x.0, x.1);
            // Residual of the system measured with our own evaluator (what users will see).
            let mut fvals = vec![0.0; n];
            if by_point {
                let q: Vec<[f64; 3]> = np.iter().map(|p| p.to_array()).collect();
                s.sums_by_point(&q, &mut fvals, None);
            } else {
                s.values_normalised(&np, &mut fvals);
            }
            let rf: Vec<f64> = (0..n)
                .map(|i| s.constraints.values[i] - fvals[i] - smoothing * s.soa.w[i])
                .collect();
            // NaN is the worst residual (`f64::max` would drop it).
            let worst = rf.iter().fold(0.0, |a: f64, r| {
                if r.is_nan() || a.is_nan() {
                    f64::NAN
                } else {
                    a.max(r.abs())
                }
            });
            let mut rg = [0.0; 4];
            for i in 0..n {
                let w = s.soa.w[i];
                rg[0] -= w;
                rg[1] -= w * np[i].x;
                rg[2] -= w * np[i].y;
                rg[3] -= w * np[i].z;
            }
            if !worst.is_finite() {
                break;
            }
            if best.as_ref().is_none_or(|(b, _)| worst < *b) {
                best = Some((worst, x.clone()));
            }
            if worst <= target {
                break;
            }
            let (dl, da) = solver.solve(&rf, rg);
            for (xi, d) in x.0.iter_mut().zip(&dl) {
                *xi += d;
            }
            for k in 0..4 {
                x.1[k] += da[k];
            }
        }
        let (residual, xbest) = best.ok_or(Error::SingularSystem {
            residual: f64::INFINITY,
        })?;
        s.set_solution(&xbest.0, xbest.1);
        s.residual = residual;
        s.factorization = solver.method();
        let vscale = s
            .constraints
            .values
            .iter()
            .fold(0.0, |a: f64, v| a.max(v.abs()));
        // The fit is refused when its worst residual exceeds 1e-4 of the largest constraint
        // value (1e-6 at the data points for data spanning [-1, 1]³ with the default w).
        if settings.smoothing == 0.0 && residual > 1e-4 * vscale.max(1e-300) {
            return Err(Error::SingularSystem { residual });
        }
        Ok(s)
    }

    fn set_solution(&mut self, lam: &[f64], a: [f64; 4]) {
        self.soa.w.copy_from_slice(lam);
        self.npoly = a;
        // Back to the caller's coordinates: φ(|x − c|) = φ(|x' − c'|/scale) = scale^-k φ(...)
        // (plus, for the thin plate, terms that cancel by the orthogonality conditions).
        let k = self.kernel.degree();
        let s = self.scale;
        self.weights = self.soa.w.iter().map(|w| w * s.powi(k)).collect();
        let [a, bx, by, bz] = self.npoly;
        // p(x') = a + b·(x − shift)·scale.
        let b = DVec3::new(bx, by, bz) * s;
        let mut a0 = a - b.dot(self.shift);
        if self.kernel == Kernel::ThinPlate {
            // r'² log r' = s²(r² log r + r² log s): the extra Σλ_j' s² r_j² log s is the quadratic
            // Σλ' s² log s (|x|² − 2x·c_j + |c_j|²) whose |x|² and x terms vanish by orthogonality.
            let c: f64 = self
                .soa
                .w
                .iter()
                .zip(&self.centers)
                .map(|(w, cj)| w * cj.length_squared())
                .sum();
            a0 += c * s * s * s.ln();
        }
        self.poly = [a0, b.x, b.y, b.z];
    }

    /// Values at points already in normalised coordinates.
    fn values_normalised(&self, points: &[DVec3], out: &mut [f64]) {
        self.eval_chunks(points, out, |p| p);
    }

    fn eval_chunks(
        &self,
        points: &[DVec3],
        out: &mut [f64],
        to_norm: impl Fn(DVec3) -> DVec3 + Sync,
    ) {
        assert_eq!(points.len(), out.len());
        points
            .par_chunks(EVAL_CHUNK)
            .zip(out.par_chunks_mut(EVAL_CHUNK))
            .for_each(|(p, o)| self.values_chunk(p, o, &to_norm));
    }

    /// Values at up to [`EVAL_CHUNK`] points.
    fn values_chunk(&self, p: &[DVec3], o: &mut [f64], to_norm: &impl Fn(DVec3) -> DVec3) {
        let [a, bx, by, bz] = self.npoly;
        let nb = p.len().div_ceil(LANES);
        let mut blocks = [Block::default(); EVAL_CHUNK / LANES];
        for (k, b) in blocks[..nb].iter_mut().enumerate() {
            for l in 0..LANES {
                let q = to_norm(p[(k * LANES + l).min(p.len() - 1)]);
                b.x[l] = q.x;
                b.y[l] = q.y;
                b.z[l] = q.z;
            }
        }
        let mut sums = [[0.0; LANES]; EVAL_CHUNK / LANES];
        dispatch_values(self.kernel, &self.soa, &blocks[..nb], &mut sums[..nb]);
        for (i, oi) in o.iter_mut().enumerate() {
            let (k, l) = (i / LANES, i % LANES);
            let b = &blocks[k];
            *oi = sums[k][l] + a + bx * b.x[l] + by * b.y[l] + bz * b.z[l];
        }
    }

    /// Values, and gradients when `gradients` is given, at normalised points `q`, by point: the
    /// kernel sums of [`values_by_point`] plus the polynomial (gradients in the caller's
    /// coordinates).
    fn sums_by_point(&self, q: &[[f64; 3]], values: &mut [f64], gradients: Option<&mut [DVec3]>) {
        let (kernel, npoly, scale) = (self.kernel, self.npoly, self.scale);
        sums_by_point(kernel, &self.soa, npoly, scale, q, values, gradients);
    }

    /// Gradients at many points, and the values too when `values` is given (the gradients are
    /// the same bits either way).
    fn sums_gradients(
        &self,
        points: &[DVec3],
        values: Option<&mut [f64]>,
        gradients: &mut [DVec3],
    ) {
        assert_eq!(points.len(), gradients.len());
        let chunk =
            |p: &[DVec3], v: Option<&mut [f64]>, g: &mut [DVec3]| self.gradients_chunk(p, v, g);
        match values {
            Some(values) => points
                .par_chunks(EVAL_CHUNK)
                .zip(values.par_chunks_mut(EVAL_CHUNK))
                .zip(gradients.par_chunks_mut(EVAL_CHUNK))
                .for_each(|((p, v), g)| chunk(p, Some(v), g)),
            None => points
                .par_chunks(EVAL_CHUNK)
                .zip(gradients.par_chunks_mut(EVAL_CHUNK))
                .for_each(|(p, g)| chunk(p, None, g)),
        }
    }

    /// Gradients, and values when `v` is given, at up to [`EVAL_CHUNK`] points in the caller's
    /// coordinates.
    fn gradients_chunk(&self, p: &[DVec3], v: Option<&mut [f64]>, g: &mut [DVec3]) {
        let [a, bx, by, bz] = self.npoly;
        let (shift, scale) = (self.shift, self.scale);
        let nb = p.len().div_ceil(LANES);
        let mut blocks = [Block::default(); EVAL_CHUNK / LANES];
        for (k, b) in blocks[..nb].iter_mut().enumerate() {
            for l in 0..LANES {
                let q = (p[(k * LANES + l).min(p.len() - 1)] - shift) * scale;
                b.x[l] = q.x;
                b.y[l] = q.y;
                b.z[l] = q.z;
            }
        }
        let mut sums = [[[0.0; LANES]; 4]; EVAL_CHUNK / LANES];
        dispatch_values_gradients(
            self.kernel,
            &self.soa,
            &blocks[..nb],
            &mut sums[..nb],
            v.is_some(),
        );
        for (i, g) in g.iter_mut().enumerate() {
            let s = &sums[i / LANES];
            *g = DVec3::new(
                s[1][i % LANES] + bx,
                s[2][i % LANES] + by,
                s[3][i % LANES] + bz,
            ) * scale;
        }
        if let Some(v) = v {
            for (i, v) in v.iter_mut().enumerate() {
                let (k, l) = (i / LANES, i % LANES);
                let b = &blocks[k];
                *v = sums[k][0][l] + a + bx * b.x[l] + by * b.y[l] + bz * b.z[l];
            }
        }
    }

    /// Fits the interpolant of `points` and `values` as one patch of a partition-of-unity fit:
    /// as [`VariationalSurface::interpolate`] without its checks, with the given parallelism
    /// for the factorization, and keeping only what evaluation needs (the centres, weights and
    /// constraints read back empty; [`PatchFit`] keeps less).
    pub(crate) fn fit_patch(
        points: Vec<DVec3>,
        values: Vec<f64>,
        settings: &FitSettings,
        par: Par,
    ) -> Result<Self> {
        let boundary = points.len();
        let c = Constraints {
            points,
            values,
            offsets: vec![],
            boundary,
            normal_of: vec![],
            merged: 0,
        };
        let mut s = Self::solve(c, settings, par, true)?;
        s.centers = vec![];
        s.weights = vec![];
        s.constraints = Constraints::default();
        Ok(s)
    }

    /// Bytes the dense system of `n` constraints needs while it is solved.
    pub(crate) fn system_bytes(n: usize) -> u64 {
        let m = n as u64 + 4;
        2 * m * m * 8
    }

    /// The kernel.
    pub fn kernel(&self) -> Kernel {
        self.kernel
    }
    /// Centres c_j (the constraint points), in the caller's coordinates.
    pub fn centers(&self) -> &[DVec3] {
        &self.centers
    }
    /// Weights λ_j, in the caller's coordinates.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }
    /// Linear polynomial [a, bx, by, bz] of f(x) = Σ λ_j φ(|x − c_j|) + a + b·x.
    pub fn polynomial(&self) -> [f64; 4] {
        self.poly
    }
    /// The constraints the surface interpolates.
    pub fn constraints(&self) -> &Constraints {
        &self.constraints
    }
    /// Largest |f(c_i) − v_i| at the constraints, as measured after the fit.
    pub fn residual(&self) -> f64 {
        self.residual
    }
    /// The factorization the fit used: `"cholesky"` (null space) or `"lblt"` (see `saddle.rs`).
    pub fn factorization(&self) -> &'static str {
        self.factorization
    }
    /// Bounding box of the centres.
    pub fn bounding_box(&self) -> (DVec3, DVec3) {
        bounding_box(&self.centers)
    }
    /// Bounding box of the boundary constraints (the data points) within
    /// [`crate::spatial::OUTSIDE`] extents of their bulk ([`constraints::bulk_bounding_box`]).
    pub fn data_bounding_box(&self) -> (DVec3, DVec3) {
        constraints::bulk_bounding_box(&self.centers[..self.constraints.boundary])
    }
}

/// Cells a tracking walk from a data point goes at most ([`Field::starts`]): the data points
/// lie on the surface, so a short walk reaches it.
pub const STARTS_MAX_WALK: u32 = 16;

/// Tracking starts of a fit: its boundary constraints (the data points).
fn boundary_starts(c: &Constraints) -> crate::field::Starts {
    crate::field::Starts {
        points: c.points[..c.boundary].to_vec(),
        max_walk: STARTS_MAX_WALK,
    }
}

/// Errors when the dense system for `n` constraints would exceed `limit` bytes.
fn check_system_memory(n: usize, limit: u64) -> Result<()> {
    // The assembled matrix and the factor's copy.
    crate::error::check_memory("points", VariationalSurface::system_bytes(n), limit)
}

impl Field for VariationalSurface {
    /// The boundary constraints (the data points), each walking at most
    /// [`STARTS_MAX_WALK`] cells.
    fn starts(&self, _cell: f64) -> Option<crate::field::Starts> {
        Some(boundary_starts(self.constraints()))
    }
    fn value(&self, p: DVec3) -> f64 {
        let mut out = [0.0];
        self.values(&[p], &mut out);
        out[0]
    }

    fn gradient(&self, p: DVec3) -> DVec3 {
        let mut g = [DVec3::ZERO];
        self.sums_gradients(&[p], None, &mut g);
        g[0]
    }

    fn values(&self, points: &[DVec3], out: &mut [f64]) {
        let (shift, scale) = (self.shift, self.scale);
        self.eval_chunks(points, out, move |p| (p - shift) * scale);
    }

    fn gradients(&self, points: &[DVec3], out: &mut [DVec3]) {
        self.sums_gradients(points, None, out);
    }

    /// Values and gradients from one pass of the kernel sums (gradients in the caller's
    /// coordinates, the same bits as [`Field::gradients`]).
    fn values_gradients(&self, points: &[DVec3], values: &mut [f64], gradients: &mut [DVec3]) {
        assert_eq!(points.len(), values.len());
        self.sums_gradients(points, Some(values), gradients);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::*;

    /// A patch whose own constraints lie in one plane with value 0, completed by a few points
    /// off it (a near patch on a flat face): the fit is finite everywhere or refused, never a
    /// solution that is not finite.
    #[test]
    fn coplanar_patch_with_few_completions_is_finite_or_refused() {
        let mut pts: Vec<DVec3> = (0..81)
            .map(|k| DVec3::new((k % 9) as f64 * 0.01, (k / 9) as f64 * 0.01, 0.0))
            .collect();
        let mut vals = vec![0.0; pts.len()];
        for (i, q) in [
            DVec3::new(0.2, 0.1, 0.15),
            DVec3::new(-0.1, 0.3, 0.12),
            DVec3::new(0.05, -0.2, -0.1),
            DVec3::new(0.3, 0.3, 0.2),
        ]
        .into_iter()
        .enumerate()
        {
            pts.push(q);
            vals.push(0.01 * (i as f64 + 1.0) * q.z.signum());
        }
        match VariationalSurface::fit_patch(
            pts.clone(),
            vals.clone(),
            &FitSettings::default(),
            Par::Seq,
        ) {
            Ok(f) => {
                assert!(f.residual().is_finite());
                for (p, v) in pts.iter().zip(&vals) {
                    assert!((f.value(*p) - v).abs() <= 1e-6, "{p} {v}");
                }
                assert!(f.value(DVec3::new(0.04, 0.04, 0.05)).is_finite());
            }
            Err(e) => assert!(matches!(e, Error::SingularSystem { .. }), "{e}"),
        }
    }

    fn sphere_data(n: usize) -> (Vec<DVec3>, Vec<DVec3>) {
        let normals = fibonacci_sphere(n);
        (normals.iter().map(|u| 0.8 * *u).collect(), normals)
    }

    #[test]
    fn interpolates_exactly_all_kernels() {
        let (p, n) = sphere_data(300);
        for kernel in [Kernel::Triharmonic, Kernel::Biharmonic, Kernel::ThinPlate] {
            let s = VariationalSurface::fit(
                &p,
                &n,
                &Default::default(),
                &FitSettings {
                    kernel,
                    ..Default::default()
                },
            )
            .unwrap();
            let c = s.constraints();
            let mut v = vec![0.0; c.points.len()];
            s.values(&c.points, &mut v);
            let err = v
                .iter()
                .zip(&c.values)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(err < 1e-11, "{kernel:?}: {err}");
            // Inside negative, outside positive.
            assert!(s.value(DVec3::ZERO) < 0.0);
            assert!(s.value(DVec3::splat(0.9)) > 0.0);
            // Value via the caller-coordinate weights equals the fast path.
            let q = DVec3::new(0.3, -0.1, 0.2);
            let [a, bx, by, bz] = s.polynomial();
            let direct: f64 = s
                .centers()
                .iter()
                .zip(s.weights())
                .map(|(c, w)| w * kernel.phi((q - *c).length()))
                .sum::<f64>()
                + a
                + bx * q.x
                + by * q.y
                + bz * q.z;
            assert!((direct - s.value(q)).abs() < 1e-9, "{kernel:?}");
            let pts = random_points(100, -1.0, 1.0, 3);
            assert!(gradient_error(&s, &pts, 1e-6) < 1e-5, "{kernel:?}");
            // Gradients alone (normals) are the same bits as beside the values, one point at a
            // time or in a batch (and its ragged last block).
            let pts = random_points(203, -1.0, 1.0, 4);
            let (mut v, mut g, mut h) = (
                vec![0.0; 203],
                vec![DVec3::ZERO; 203],
                vec![DVec3::ZERO; 203],
            );
            s.values_gradients(&pts, &mut v, &mut g);
            s.gradients(&pts, &mut h);
            assert_eq!(g, h, "{kernel:?}");
            assert_eq!(s.gradient(pts[7]), g[7], "{kernel:?}");
            let mut w = vec![0.0; 203];
            s.values(&pts, &mut w);
            assert!(
                v.iter().zip(&w).all(|(a, b)| (a - b).abs() < 1e-12),
                "{kernel:?}"
            );
        }
    }

    #[test]
    fn scale_equivariant() {
        let (p, n) = sphere_data(100);
        let s1 = VariationalSurface::fit(&p, &n, &Default::default(), &Default::default()).unwrap();
        let p10: Vec<DVec3> = p.iter().map(|x| *x * 10.0 + DVec3::splat(5.0)).collect();
        let s10 =
            VariationalSurface::fit(&p10, &n, &Default::default(), &Default::default()).unwrap();
        let q = DVec3::new(0.2, 0.5, -0.4);
        assert!((s10.value(q * 10.0 + DVec3::splat(5.0)) - 10.0 * s1.value(q)).abs() < 1e-9);
    }

    #[test]
    fn memory_limit_refuses() {
        let (p, n) = sphere_data(100);
        let err = VariationalSurface::fit(
            &p,
            &n,
            &Default::default(),
            &FitSettings {
                memory_limit: 1000,
                ..Default::default()
            },
        )
        .unwrap_err();
        assert!(matches!(err, Error::TooMuchMemory { .. }));
    }
}
