//! A field that only has values (such as a Python callable), with gradients by central
//! differences of batched values.

use super::{gradients_by_differences, Field};
use crate::error::{Error, Result};
use glam::DVec3;

/// `field` with gradients by central differences with step `step`: every batch of gradients is
/// one [`Field::values`] call on 6 points per point (± `step` along x, y and z), which
/// [`Field::values_per_gradient`] reports, and every batch of values with gradients one call on
/// 7 (the point, then the same 6), which [`Field::values_per_value_gradient`] reports.
///
/// Values, lattice values and [`Field::starts`] are the wrapped field's; it has no gradient
/// bound and no block bounds (its gradients are differences, not the field's own).
pub struct Differences<F> {
    /// The field whose values are differenced.
    pub field: F,
    /// The step of the central differences, in field units.
    pub step: f64,
}

impl<F: Field> Differences<F> {
    /// `field` with central differences of step `step` (finite and positive; the error names
    /// `step`).
    pub fn new(field: F, step: f64) -> Result<Self> {
        if !(step.is_finite() && step > 0.0) {
            return Err(Error::invalid(
                "step",
                format!("must be finite and positive, got {step}"),
            ));
        }
        Ok(Differences { field, step })
    }
}

impl<F: Field> Field for Differences<F> {
    fn value(&self, p: DVec3) -> f64 {
        self.field.value(p)
    }
    fn gradient(&self, p: DVec3) -> DVec3 {
        let mut g = [DVec3::ZERO];
        gradients_by_differences(&self.field, &[p], self.step, &mut g);
        g[0]
    }
    fn fd_step(&self) -> f64 {
        self.step
    }
    fn values(&self, points: &[DVec3], out: &mut [f64]) {
        self.field.values(points, out)
    }
    fn gradients(&self, points: &[DVec3], out: &mut [DVec3]) {
        gradients_by_differences(&self.field, points, self.step, out)
    }
    fn values_gradients(&self, points: &[DVec3], values: &mut [f64], gradients: &mut [DVec3]) {
        let h = self.step;
        let mut probes = Vec::with_capacity(points.len() * 7);
        for &x in points {
            probes.push(x);
            for e in [DVec3::X, DVec3::Y, DVec3::Z] {
                probes.push(x + e * h);
                probes.push(x - e * h);
            }
        }
        let mut out = vec![0.0; probes.len()];
        self.field.values(&probes, &mut out);
        for (i, s) in out.chunks_exact(7).enumerate() {
            values[i] = s[0];
            gradients[i] = DVec3::new(s[1] - s[2], s[3] - s[4], s[5] - s[6]) / (2.0 * h);
        }
    }
    fn values_per_value_gradient(&self) -> u64 {
        7
    }
    fn values_per_gradient(&self) -> u64 {
        6
    }
    fn lattice_values(
        &self,
        lattice: &crate::lattice::Lattice,
        z0: u32,
        z1: u32,
        points: &mut Vec<DVec3>,
        out: &mut [f64],
    ) {
        self.field.lattice_values(lattice, z0, z1, points, out)
    }
    fn starts(&self, cell: f64) -> Option<super::Starts> {
        self.field.starts(cell)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::analytic::Sphere;

    #[test]
    fn differences_match_the_analytic_gradient_in_one_batch() {
        let sphere = Sphere {
            center: DVec3::new(0.1, -0.2, 0.05),
            radius: 0.7,
        };
        let d = Differences::new(&sphere, 1e-6).unwrap();
        let pts = crate::testing::random_points(50, -1.0, 1.0, 9);
        let (mut v, mut g, mut h) = (vec![0.0; 50], vec![DVec3::ZERO; 50], vec![DVec3::ZERO; 50]);
        d.values_gradients(&pts, &mut v, &mut g);
        d.gradients(&pts, &mut h);
        for i in 0..50 {
            assert_eq!(v[i], sphere.value(pts[i]));
            assert!((g[i] - sphere.gradient(pts[i])).length() < 1e-8);
            assert!((g[i] - h[i]).length() < 1e-8);
            assert_eq!(d.gradient(pts[i]), h[i]);
        }
        assert_eq!(d.values_per_value_gradient(), 7);
        assert_eq!(d.values_per_gradient(), 6);
        for bad in [0.0, -1e-6, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                Differences::new(&sphere, bad),
                Err(Error::InvalidArgument { name: "step", .. })
            ));
        }
    }
}
