//! A fitted variational surface as plain numbers and back, bit for bit: for saving, pickling and
//! sending a surface to other processes without fitting it again.

use super::VariationalSurface;
use crate::error::{Error, Result};
use crate::field::rbf::constraints::Constraints;
use crate::field::rbf::kernel::{Centres, Kernel};
use glam::DVec3;

/// Everything a [`VariationalSurface`] holds, as [`VariationalSurface::parts`] gives it and
/// [`VariationalSurface::from_parts`] takes it back.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfaceParts {
    /// The radial basis function φ.
    pub kernel: Kernel,
    /// Centres and weights in the caller's coordinates (empty for a partition fit's patches).
    pub centers: Vec<DVec3>,
    /// One weight per centre.
    pub weights: Vec<f64>,
    /// [a, bx, by, bz] in the caller's coordinates.
    pub polynomial: [f64; 4],
    /// The normalisation x' = (x − shift) · scale.
    pub shift: DVec3,
    /// The normalisation's scale (see `shift`).
    pub scale: f64,
    /// Centres (normalised) and weights of the normalised problem: what evaluation reads.
    pub normalized_centers: Vec<DVec3>,
    /// The weights of the normalised problem.
    pub normalized_weights: Vec<f64>,
    /// [a, bx, by, bz] of the normalised problem.
    pub normalized_polynomial: [f64; 4],
    /// The constraints (empty for a partition fit's patches).
    pub constraints: Constraints,
    /// Largest |f(c_i) − v_i| over the constraints after the fit.
    pub residual: f64,
    /// `"cholesky"` or `"lblt"`.
    pub factorization: String,
}

/// An error naming the saved state, for parts that cannot come from a fit.
pub(crate) fn bad_state(what: impl std::fmt::Display) -> Error {
    Error::invalid("state", format!("not a saved surface: {what}"))
}

/// The factorization name as the surface keeps it.
fn factorization(name: &str) -> Result<&'static str> {
    match name {
        "cholesky" => Ok("cholesky"),
        "lblt" => Ok("lblt"),
        other => Err(bad_state(format!("unknown factorization {other:?}"))),
    }
}

impl VariationalSurface {
    /// The surface as plain numbers (see [`SurfaceParts`]).
    pub fn parts(&self) -> SurfaceParts {
        let c = &self.soa;
        SurfaceParts {
            kernel: self.kernel,
            centers: self.centers.clone(),
            weights: self.weights.clone(),
            polynomial: self.poly,
            shift: self.shift,
            scale: self.scale,
            normalized_centers: (0..c.w.len())
                .map(|i| DVec3::new(c.x[i], c.y[i], c.z[i]))
                .collect(),
            normalized_weights: c.w.clone(),
            normalized_polynomial: self.npoly,
            constraints: self.constraints.clone(),
            residual: self.residual,
            factorization: self.factorization.to_string(),
        }
    }

    /// The surface [`VariationalSurface::parts`] gave: it evaluates to the same bits. Errors
    /// (naming `state`) for parts no fit makes: lengths that disagree, non-finite numbers, an
    /// unknown factorization.
    pub fn from_parts(p: SurfaceParts) -> Result<Self> {
        let n = p.normalized_centers.len();
        let c = &p.constraints;
        if p.normalized_weights.len() != n {
            return Err(bad_state("normalized weights and centres differ in length"));
        }
        if p.centers.len() != p.weights.len() || !(p.centers.is_empty() || p.centers.len() == n) {
            return Err(bad_state("centres and weights differ in length"));
        }
        if c.values.len() != c.points.len() || c.boundary > c.points.len() {
            return Err(bad_state("constraint points and values differ in length"));
        }
        let finite = p
            .centers
            .iter()
            .chain(&p.normalized_centers)
            .all(|v| v.is_finite())
            && p.weights
                .iter()
                .chain(&p.normalized_weights)
                .all(|v| v.is_finite())
            && p.polynomial
                .iter()
                .chain(&p.normalized_polynomial)
                .all(|v| v.is_finite())
            && c.points.iter().all(|v| v.is_finite())
            && c.values.iter().chain(&c.offsets).all(|v| v.is_finite())
            && p.shift.is_finite()
            && p.scale.is_finite()
            && p.scale > 0.0;
        if !finite {
            return Err(bad_state("non-finite numbers"));
        }
        let factorization = factorization(&p.factorization)?;
        let nc = &p.normalized_centers;
        Ok(VariationalSurface {
            kernel: p.kernel,
            centers: p.centers,
            weights: p.weights,
            poly: p.polynomial,
            shift: p.shift,
            scale: p.scale,
            soa: Centres {
                x: nc.iter().map(|v| v.x).collect(),
                y: nc.iter().map(|v| v.y).collect(),
                z: nc.iter().map(|v| v.z).collect(),
                w: p.normalized_weights,
            },
            npoly: p.normalized_polynomial,
            constraints: p.constraints,
            residual: p.residual,
            factorization,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::rbf::constraints::ConstraintSettings;
    use crate::field::rbf::FitSettings;
    use crate::field::Field;
    use crate::testing::fibonacci_sphere;

    #[test]
    fn parts_give_back_the_same_surface() {
        let p = fibonacci_sphere(200);
        let n: Vec<DVec3> = p.iter().map(|x| x.normalize()).collect();
        for kernel in [Kernel::Triharmonic, Kernel::ThinPlate] {
            let settings = FitSettings {
                kernel,
                ..Default::default()
            };
            let s =
                VariationalSurface::fit(&p, &n, &ConstraintSettings::default(), &settings).unwrap();
            let back = VariationalSurface::from_parts(s.parts()).unwrap();
            assert_eq!(back.parts(), s.parts());
            let q: Vec<DVec3> = p.iter().map(|x| *x * 0.7 + DVec3::splat(0.1)).collect();
            let (mut a, mut b) = (vec![0.0; q.len()], vec![0.0; q.len()]);
            s.values(&q, &mut a);
            back.values(&q, &mut b);
            assert_eq!(
                a.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                b.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
            );
        }
    }

    #[test]
    fn parts_no_fit_makes_are_refused() {
        let p = fibonacci_sphere(50);
        let n: Vec<DVec3> = p.iter().map(|x| x.normalize()).collect();
        let s = VariationalSurface::fit(&p, &n, &Default::default(), &Default::default()).unwrap();
        let mut bad = s.parts();
        bad.normalized_weights.pop();
        assert!(VariationalSurface::from_parts(bad).is_err());
        let mut bad = s.parts();
        bad.scale = f64::NAN;
        assert!(VariationalSurface::from_parts(bad).is_err());
        let mut bad = s.parts();
        bad.factorization = "qr".into();
        assert!(VariationalSurface::from_parts(bad).is_err());
    }
}
