//! The fit of one patch of a partition-of-unity surface (see [`crate::field::rbf::partition`]): a
//! variational interpolant of some of the surface's constraints that keeps them as indices into
//! the surface's constraint points, with its weights, and normalises them when it is evaluated,
//! with the arithmetic of its fit, so that its values have the bits of the fitted interpolant.

use super::{bad_state, sums_by_point, FitSettings, SurfaceParts, VariationalSurface};
use crate::error::Result;
use crate::field::rbf::kernel::{Centres, Kernel};
use faer::Par;
use glam::DVec3;

/// Where a patch's centres come from.
#[derive(Clone, Debug, PartialEq)]
pub enum PatchCentres {
    /// Indices into the surface's constraint points (the caller's coordinates).
    Shared(Vec<u32>),
    /// Centres of its own, normalised: a plane patch's points, which are no constraints (see
    /// [`crate::field::rbf::partition::empty`]), or a patch of a state saved in format 1.
    Own(Vec<DVec3>),
}

/// One patch's interpolant: f(x) = Σ_j λ_j φ(|x' − c'_j|) + a + b·x' in the normalised
/// coordinates x' = (x − shift) · scale of its fit.
#[derive(Clone, Debug)]
pub struct PatchFit {
    kernel: Kernel,
    centres: PatchCentres,
    /// Weights λ_j of the normalised problem.
    weights: Vec<f64>,
    /// Linear polynomial in the caller's coordinates: [a, bx, by, bz].
    poly: [f64; 4],
    shift: DVec3,
    scale: f64,
    /// Polynomial of the normalised problem.
    npoly: [f64; 4],
    residual: f64,
    factorization: &'static str,
}

impl PatchFit {
    /// Fits the interpolant of `points` and `values` (see [`VariationalSurface::fit_patch`]),
    /// keeping `index` for its centres (where `points` are in the points it will be evaluated
    /// with), or its normalised centres when `index` is `None` (points that are no constraints).
    pub(crate) fn fit(
        index: Option<Vec<u32>>,
        points: Vec<DVec3>,
        values: Vec<f64>,
        settings: &FitSettings,
        par: Par,
    ) -> Result<Self> {
        let s = VariationalSurface::fit_patch(points, values, settings, par)?;
        let centres = match index {
            Some(index) => PatchCentres::Shared(index),
            None => own_centres(&s),
        };
        Ok(Self::keeping(s, centres))
    }

    /// What the patch keeps of its fitted surface `s`, its centres being `centres`.
    fn keeping(s: VariationalSurface, centres: PatchCentres) -> Self {
        PatchFit {
            kernel: s.kernel,
            centres,
            weights: s.soa.w,
            poly: s.poly,
            shift: s.shift,
            scale: s.scale,
            npoly: s.npoly,
            residual: s.residual,
            factorization: s.factorization,
        }
    }

    /// Bytes a patch of `n` shared centres keeps.
    pub(crate) fn bytes(n: usize) -> u64 {
        (std::mem::size_of::<Self>() + 12 * n) as u64
    }

    /// Its centres: indices into the constraint points, or its own.
    pub fn centres(&self) -> &PatchCentres {
        &self.centres
    }
    /// Weights of the normalised problem.
    pub fn normalized_weights(&self) -> &[f64] {
        &self.weights
    }
    /// Largest |f(c_i) − v_i| at its constraints, as measured after the fit.
    pub fn residual(&self) -> f64 {
        self.residual
    }

    /// Its indices mapped through `new` (`new[i]` the index that constraint `i` takes).
    pub(crate) fn renumber(&mut self, new: &[u32]) {
        if let PatchCentres::Shared(index) = &mut self.centres {
            index.iter_mut().for_each(|i| *i = new[*i as usize]);
        }
    }

    /// The normalised centres and weights, into `into` (its contents replaced): the constraint
    /// points the patch indexes in `points`, as (c − shift) · scale, or its own.
    pub(crate) fn gather(&self, points: &[DVec3], into: &mut Centres) {
        let n = self.weights.len();
        for v in [&mut into.x, &mut into.y, &mut into.z] {
            v.clear();
            v.resize(n, 0.0);
        }
        into.w.clear();
        into.w.extend_from_slice(&self.weights);
        let (shift, scale) = (self.shift, self.scale);
        let centre = |j: usize| match &self.centres {
            PatchCentres::Shared(index) => (points[index[j] as usize] - shift) * scale,
            PatchCentres::Own(own) => own[j],
        };
        let (x, y, z) = (&mut into.x[..n], &mut into.y[..n], &mut into.z[..n]);
        for j in 0..n {
            let q = centre(j);
            (x[j], y[j], z[j]) = (q.x, q.y, q.z);
        }
    }

    /// Values, and gradients when `gradients` is given, at `points` in the caller's coordinates,
    /// on the calling thread (as [`PatchFit::eval_gathered`]). `constraints` are the points its
    /// indices name; `scratch` receives the gathered centres.
    #[cfg(test)]
    pub(crate) fn eval_on_this_thread(
        &self,
        constraints: &[DVec3],
        scratch: &mut Centres,
        points: &[DVec3],
        values: &mut [f64],
        gradients: Option<&mut [DVec3]>,
    ) {
        self.gather(constraints, scratch);
        self.eval_gathered(scratch, points, values, gradients);
    }

    /// Values, and gradients when `gradients` is given, at `points` in the caller's coordinates,
    /// on the calling thread, by point (see [`crate::field::rbf::kernel::values_by_point`]), so that a
    /// point's value and gradient have the same bits whatever other points are evaluated with
    /// it. `centres` are its centres as [`PatchFit::gather`] gives them.
    pub(crate) fn eval_gathered(
        &self,
        centres: &Centres,
        points: &[DVec3],
        values: &mut [f64],
        gradients: Option<&mut [DVec3]>,
    ) {
        assert_eq!(points.len(), values.len());
        if let Some(g) = &gradients {
            assert_eq!(points.len(), g.len());
        }
        let (shift, scale) = (self.shift, self.scale);
        let q: Vec<[f64; 3]> = points
            .iter()
            .map(|p| ((*p - shift) * scale).to_array())
            .collect();
        sums_by_point(
            self.kernel,
            centres,
            self.npoly,
            scale,
            &q,
            values,
            gradients,
        );
    }

    /// The patch as plain numbers: its fit's numbers (its own normalised centres, if any) and
    /// its indices (empty for its own centres).
    pub fn parts(&self) -> (SurfaceParts, Vec<u32>) {
        let (own, index) = match &self.centres {
            PatchCentres::Shared(index) => (vec![], index.clone()),
            PatchCentres::Own(own) => (own.clone(), vec![]),
        };
        let parts = SurfaceParts {
            kernel: self.kernel,
            polynomial: self.poly,
            shift: self.shift,
            scale: self.scale,
            normalized_centers: own,
            normalized_weights: self.weights.clone(),
            normalized_polynomial: self.npoly,
            residual: self.residual,
            factorization: self.factorization.to_string(),
            ..Default::default()
        };
        (parts, index)
    }

    /// The patch [`PatchFit::parts`] gave, for a surface of `constraints` constraint points:
    /// its centres are the indices when `index` is not empty, else its own. Errors (naming
    /// `state`) for parts no fit makes.
    pub fn from_parts(p: SurfaceParts, index: Vec<u32>, constraints: usize) -> Result<Self> {
        let n = p.normalized_weights.len();
        let centres = if index.is_empty() {
            if p.normalized_centers.len() != n {
                return Err(bad_state("normalized weights and centres differ in length"));
            }
            PatchCentres::Own(vec![])
        } else {
            if index.len() != n || !p.normalized_centers.is_empty() {
                return Err(bad_state("a patch's indices and weights differ in length"));
            }
            if index.iter().any(|&i| i as usize >= constraints) {
                return Err(bad_state("a patch indexes a constraint that is not there"));
            }
            PatchCentres::Shared(index)
        };
        // The checks of a whole surface's parts, on the own centres or on stand-ins for the
        // shared ones.
        let own = matches!(centres, PatchCentres::Own(_));
        let checked = match own {
            true => p,
            false => SurfaceParts {
                normalized_centers: vec![DVec3::ZERO; n],
                ..p
            },
        };
        let s = VariationalSurface::from_parts(checked)?;
        let centres = match centres {
            PatchCentres::Own(_) => own_centres(&s),
            shared => shared,
        };
        Ok(Self::keeping(s, centres))
    }
}

/// The normalised centres of `s`, as a patch's own.
fn own_centres(s: &VariationalSurface) -> PatchCentres {
    let c = &s.soa;
    PatchCentres::Own(
        (0..c.w.len())
            .map(|i| DVec3::new(c.x[i], c.y[i], c.z[i]))
            .collect(),
    )
}
