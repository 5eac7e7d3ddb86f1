//! Surfaces from real scans: points with noise along the sensor's rays, views that do not quite
//! line up, regions no view saw, normals estimated from neighbours (some flipped) and stray
//! points.
//!
//! An interpolant of such points is wrong where the data is: noise becomes ripples, a flipped
//! normal a bubble, an outlier a spike or a body of its own, two misregistered views two sheets;
//! and where no view saw the surface it may place sheets and bodies anywhere. The scan fit
//! works in three steps:
//!
//! 1. [`mod@clean`]: spacing and noise are estimated from the data, outliers found and left out,
//!    normals made consistent with their neighbours, and every point projected onto the plane
//!    of its neighbourhood — the points the fit interpolates lie on the data's mean surface.
//! 2. The variational fit of the cleaned points about one spacing apart ([`centres`]; global
//!    or partition of unity).
//! 3. [`guard`] ([`ScanSurface`]): beyond a few spacings from the data the field is the data's
//!    [`winding::WindingNumber`], which closes unseen regions and has no surface elsewhere.

pub mod bodies;
pub mod centres;
pub mod clean;
pub mod coarsen;
pub mod guard;
pub mod occupancy;
pub mod surface;
pub mod winding;

pub use clean::{clean, Cleaned};
pub use guard::{Guard, Guarded};
pub use surface::{ScanReport, ScanSurface};
pub use winding::WindingNumber;

/// Settings of the scan fit's cleaning and guard.
#[derive(Clone, Debug, PartialEq)]
pub struct ScanSettings {
    /// Neighbours per point for the local planes, the votes and the projection (at least 10).
    pub neighbours: usize,
    /// A point whose 10th neighbour is farther than this multiple of the median such distance
    /// is an outlier.
    pub isolation: f64,
    /// Neighbours of the projection where the noise exceeds a tenth of the spacing.
    pub projection_neighbours: usize,
    /// Rounds of the normals' vote.
    pub voting_rounds: usize,
    /// The projection's Gaussian width, in multiples of max(spacing, 2 · noise).
    pub projection_width: f64,
    /// Within this many spacings of the data, the field is the fit's.
    pub near: f64,
    /// Beyond this many spacings of the data, the field is the winding number's.
    pub far: f64,
    /// Where the estimated noise exceeds this fraction of the spacing, the points are averaged
    /// in cells two spacings wide and those are cleaned ([`coarsen`]).
    pub coarsening: f64,
    /// The fit interpolates a subset of the cleaned points no two of which are nearer than
    /// this many spacings ([`centres::separated`]); 0 fits them all.
    pub centre_separation: f64,
}

impl Default for ScanSettings {
    fn default() -> Self {
        ScanSettings {
            neighbours: 20,
            projection_neighbours: 40,
            isolation: 5.0,
            voting_rounds: 3,
            projection_width: 2.0,
            near: 6.0,
            far: 12.0,
            coarsening: 0.25,
            centre_separation: 1.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::rbf::constraints::ConstraintSettings;
    use crate::field::rbf::partition::{PartitionSettings, PartitionSurface};
    use crate::lattice::Lattice;
    use crate::polygonize::octree;
    use crate::testing::{fibonacci_sphere, random_points};
    use glam::DVec3;

    /// A sphere "scanned" without its bottom cap, with noise, flipped normals and outliers.
    fn scanned_sphere() -> (Vec<DVec3>, Vec<DVec3>, Vec<u32>) {
        let all = fibonacci_sphere(12_000);
        let jitter = random_points(all.len(), -1.0, 1.0, 11);
        let mut p = Vec::new();
        let mut n = Vec::new();
        for (q, j) in all.iter().zip(&jitter) {
            if q.z < -0.7 {
                continue;
            }
            p.push(*q * (1.0 + 0.003 * j.x));
            n.push(if j.y > 0.98 { -*q } else { *q });
        }
        let far = random_points(30, -1.5, 1.5, 12);
        let mut outliers = Vec::new();
        for (k, f) in far.iter().enumerate() {
            if f.length() > 1.25 {
                let i = k * 300 + 7;
                p[i] = *f;
                outliers.push(i as u32);
            }
        }
        (p, n, outliers)
    }

    #[test]
    fn a_noisy_open_scan_with_outliers_gives_one_closed_sphere() {
        let (p, n, outliers) = scanned_sphere();
        let settings = ScanSettings::default();
        let cleaned = clean(&p, &n, &settings).unwrap();
        for o in &outliers {
            assert!(cleaned.outliers.contains(o), "outlier {o} kept");
        }
        let fit = PartitionSurface::fit(
            &cleaned.points,
            &cleaned.normals,
            &ConstraintSettings::default(),
            &PartitionSettings::default(),
        )
        .unwrap();
        let scan = ScanSurface::new(fit, &cleaned, &settings, &p).unwrap();
        assert_eq!(scan.report.outliers, cleaned.outliers);
        assert!(scan.report.distance_p99 < 0.01, "{:?}", scan.report);
        let field = &scan.surface;
        let lattice = Lattice::new(DVec3::splat(-1.5), DVec3::splat(1.5), [48, 48, 48]).unwrap();
        let mesh = octree::polygonize(field, &lattice, &octree::OctreeSettings::default())
            .unwrap()
            .mesh;
        assert!(mesh.is_closed_oriented());
        assert_eq!(mesh.euler_characteristic(), 2, "one sphere");
        // Where the scan saw the sphere the surface is on it; the unseen cap is closed near it.
        for v in &mesh.vertices {
            if v.z > -0.6 {
                assert!((v.length() - 1.0).abs() < 0.03, "vertex {v}");
            } else {
                assert!(v.length() < 1.3 && v.z > -1.3, "vertex {v}");
            }
        }
    }
}
