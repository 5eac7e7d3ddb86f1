//! A fit of cleaned scan points, guarded by their winding number, with what the cleaning and
//! the fit tell about the data ([`ScanReport`]).

use super::clean::Cleaned;
use super::guard::{Guard, Guarded};
use super::winding::WindingNumber;
use super::ScanSettings;
use crate::error::Result;
use crate::field::Field;
use crate::knn::PointTree;
use glam::DVec3;
use std::sync::Arc;

/// What a scan fit found in its data.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ScanReport {
    /// Points given.
    pub points: usize,
    /// Indices of the points left out as outliers, increasing.
    pub outliers: Vec<u32>,
    /// The median distance from a cleaned point to its 6th nearest neighbour (where very noisy
    /// points were averaged in cells, [`super::coarsen`], from an average to its 6th).
    pub spacing: f64,
    /// The estimated noise (see [`mod@super::clean`]).
    pub noise: f64,
    /// Kept points whose normal was turned to agree with its neighbours'.
    pub normals_corrected: usize,
    /// Whether the normals pointed into the body the points enclose, and all were turned.
    pub turned_outward: bool,
    /// Whether the points came without normals and the fit estimated them
    /// ([`crate::normals::estimate_normals`]).
    pub normals_estimated: bool,
    /// Mean distance from the kept points, as given, to the surface (|f| / |∇f|).
    pub distance_mean: f64,
    /// The 99th percentile of those distances.
    pub distance_p99: f64,
    /// The largest of those distances.
    pub distance_max: f64,
}

/// A scan fit: the fit `F` of the cleaned points, guarded by their winding number.
#[derive(Clone)]
pub struct ScanSurface<F> {
    /// The guarded fit: the field.
    pub surface: Guarded<F>,
    /// What the cleaning and the fit found.
    pub report: ScanReport,
}

impl<F: Field> ScanSurface<F> {
    /// Guards `fit`, a fit of `cleaned`'s points, by their winding number, with the bands of
    /// `settings` in multiples of the data's spacing; the report's distances are those of the
    /// kept points of `points` (the cleaning's input) to the guarded surface.
    pub fn new(
        fit: F,
        cleaned: &Cleaned,
        settings: &ScanSettings,
        points: &[DVec3],
    ) -> Result<Self> {
        let guard = guard_of(
            cleaned.points.clone(),
            cleaned.normals.clone(),
            cleaned.areas.clone(),
            cleaned.spacing,
            settings,
        )?;
        let surface = Guarded::new(fit, Arc::new(guard));
        let kept: Vec<DVec3> = cleaned.kept.iter().map(|&i| points[i as usize]).collect();
        let mut values = vec![0.0; kept.len()];
        let mut gradients = vec![DVec3::ZERO; kept.len()];
        surface.values_gradients(&kept, &mut values, &mut gradients);
        let mut distances: Vec<f64> = values
            .iter()
            .zip(&gradients)
            .map(|(v, g)| v.abs() / g.length().max(1e-300))
            .collect();
        let (mean, p99, max) = summary(&mut distances);
        let report = ScanReport {
            points: points.len(),
            outliers: cleaned.outliers.clone(),
            spacing: cleaned.spacing,
            noise: cleaned.noise,
            normals_corrected: cleaned.normals_corrected,
            turned_outward: cleaned.turned_outward,
            normals_estimated: false,
            distance_mean: mean,
            distance_p99: p99,
            distance_max: max,
        };
        Ok(ScanSurface { surface, report })
    }

    /// The scan surface of a fit and a guard kept apart (saved), with its report.
    pub fn from_parts(fit: F, guard: Arc<Guard>, report: ScanReport) -> Self {
        ScanSurface {
            surface: Guarded::new(fit, guard),
            report,
        }
    }
}

impl<F> std::fmt::Debug for ScanSurface<F> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ScanSurface")
            .field("report", &self.report)
            .finish_non_exhaustive()
    }
}

/// The guard of cleaned points with their normals and areas, `spacing` apart, with the bands of
/// `settings`.
pub fn guard_of(
    points: Vec<DVec3>,
    normals: Vec<DVec3>,
    areas: Vec<f64>,
    spacing: f64,
    settings: &ScanSettings,
) -> Result<Guard> {
    crate::error::check_finite_points("normals", &normals)?;
    if normals.len() != points.len() || areas.len() != points.len() {
        return Err(crate::error::Error::invalid(
            "normals",
            "points, normals and areas differ in length",
        ));
    }
    let tree = PointTree::new(&points)?;
    let winding = WindingNumber::new(&tree, &points, &normals, &areas, 0.5 * spacing)?;
    Ok(Guard::new(
        winding,
        tree,
        (points, normals, areas),
        spacing,
        (settings.near * spacing, settings.far * spacing),
    ))
}

/// Mean, 99th percentile and largest of `d` (reordered); zeros for none.
fn summary(d: &mut [f64]) -> (f64, f64, f64) {
    if d.is_empty() {
        return (0.0, 0.0, 0.0);
    }
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    let k = ((d.len() as f64 * 0.99).ceil() as usize).clamp(1, d.len()) - 1;
    let p99 = *d.select_nth_unstable_by(k, f64::total_cmp).1;
    let max = d.iter().copied().fold(0.0, f64::max);
    (mean, p99, max)
}
