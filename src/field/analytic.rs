//! Analytic fields with exact gradients: the shapes the tests and the demo use.

use super::Field;
use glam::DVec3;

/// Signed distance to a sphere.
#[derive(Clone, Copy, Debug)]
pub struct Sphere {
    /// Centre of the sphere.
    pub center: DVec3,
    /// Radius of the sphere.
    pub radius: f64,
}

impl Field for Sphere {
    fn value(&self, p: DVec3) -> f64 {
        (p - self.center).length() - self.radius
    }
    fn gradient(&self, p: DVec3) -> DVec3 {
        (p - self.center).normalize_or_zero()
    }
}

/// Signed distance to a torus around the z axis: `major` is the distance from the centre to the
/// tube's centre line, `minor` the tube radius.
#[derive(Clone, Copy, Debug)]
pub struct Torus {
    /// Centre of the torus (its axis is z).
    pub center: DVec3,
    /// Distance from the centre to the tube's centre line.
    pub major: f64,
    /// Radius of the tube.
    pub minor: f64,
}

impl Field for Torus {
    fn value(&self, p: DVec3) -> f64 {
        let q = p - self.center;
        let rho = (q.x * q.x + q.y * q.y).sqrt();
        ((rho - self.major).powi(2) + q.z * q.z).sqrt() - self.minor
    }
    fn gradient(&self, p: DVec3) -> DVec3 {
        let q = p - self.center;
        let rho = (q.x * q.x + q.y * q.y).sqrt();
        if rho == 0.0 {
            return DVec3::ZERO;
        }
        let a = rho - self.major;
        let s = (a * a + q.z * q.z).sqrt();
        if s == 0.0 {
            return DVec3::ZERO;
        }
        DVec3::new(a * q.x / (rho * s), a * q.y / (rho * s), q.z / s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::*;

    #[test]
    fn gradients_match_differences() {
        let pts = random_points(200, -1.5, 1.5, 7);
        let s = Sphere {
            center: DVec3::new(0.1, -0.2, 0.3),
            radius: 0.7,
        };
        assert!(gradient_error(&s, &pts, 1e-6) < 1e-6);
        let t = Torus {
            center: DVec3::ZERO,
            major: 0.6,
            minor: 0.25,
        };
        assert!(gradient_error(&t, &pts, 1e-6) < 1e-6);
    }
}
