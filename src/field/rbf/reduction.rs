//! Fitting a subset of the data points within a tolerance: greedy centre reduction (Carr et al.
//! 2001, §4).
//!
//! A scan of 10⁶ points holds far more points than its surface needs: a surface fitted to a
//! well-spread fraction of them passes close to the rest. [`fit_within`] fits one point per
//! cube a few spacings wide, evaluates the fit at every data point, adds the points whose value
//! is farther than `tolerance` from their target, and fits again, until every point is within
//! the tolerance or [`ReductionSettings::max_rounds`] fits are done. The result interpolates
//! the points it used exactly and approximates the others within the tolerance when the rounds
//! sufficed ([`Reduction::outside`] says).

use crate::cancel;
use crate::error::{Error, Result};
use crate::field::rbf::duplicates::typical_spacing;
use crate::field::Field;
use crate::spatial::Grid;
use glam::DVec3;
use rayon::prelude::*;

/// Settings of [`fit_within`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReductionSettings {
    /// Largest |f(p) − target| accepted at a data point that is not fitted exactly.
    pub tolerance: f64,
    /// The first fit takes one point per cube of this many typical spacings (median
    /// nearest-neighbour distance).
    pub first_cell_over_spacing: f64,
    /// Fits at most.
    pub max_rounds: usize,
}

impl Default for ReductionSettings {
    fn default() -> Self {
        ReductionSettings {
            tolerance: 0.0,
            first_cell_over_spacing: 8.0,
            max_rounds: 4,
        }
    }
}

impl ReductionSettings {
    /// Errors unless the tolerance is finite and positive.
    pub fn check(&self) -> Result<()> {
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(Error::invalid(
                "tolerance",
                format!("must be finite and positive, got {}", self.tolerance),
            ));
        }
        Ok(())
    }
}

/// What [`fit_within`] did.
#[derive(Clone, Debug, PartialEq)]
pub struct Reduction {
    /// Fits made.
    pub rounds: usize,
    /// Data points in the last fit.
    pub used: usize,
    /// Largest |f(p) − target| over all data points, for the last fit.
    pub largest_residual: f64,
    /// Data points farther than the tolerance for the last fit (0 when the rounds sufficed).
    pub outside: usize,
}

/// Points per batch of residual evaluations (the call checks for interruption between batches).
const BATCH: usize = 1 << 16;

/// Fits `fit(indices)` to growing subsets of `points` until every point `i` has
/// `|f(points[i]) − targets[i]| ≤ tolerance` (targets 0 when `None`), as the module says. `fit`
/// receives the indices of the subset, increasing; `field` gives the fitted surface as a field.
pub fn fit_within<S>(
    points: &[DVec3],
    targets: Option<&[f64]>,
    settings: &ReductionSettings,
    mut fit: impl FnMut(&[u32]) -> Result<S>,
    field: impl Fn(&S) -> &(dyn Field + '_),
) -> Result<(S, Reduction)> {
    settings.check()?;
    let mut used = first_subset(points, settings.first_cell_over_spacing);
    let mut rounds = 0;
    loop {
        rounds += 1;
        let surface = fit(&used)?;
        let residuals = residuals(field(&surface), points, targets)?;
        let outside: Vec<u32> = (0..points.len() as u32)
            .into_par_iter()
            .filter(|&i| residuals[i as usize] > settings.tolerance)
            .collect();
        // Points already used are interpolated (outside only by rounding): adding them again
        // changes nothing.
        let new: Vec<u32> = outside
            .iter()
            .copied()
            .filter(|i| used.binary_search(i).is_err())
            .collect();
        if new.is_empty() || rounds >= settings.max_rounds {
            let report = Reduction {
                rounds,
                used: used.len(),
                largest_residual: residuals.par_iter().copied().reduce(|| 0.0, f64::max),
                outside: outside.len(),
            };
            return Ok((surface, report));
        }
        used = union(&used, &new);
    }
}

/// One point per cube `cell_over_spacing` typical spacings wide (see [`first_in_each_cell`]);
/// all points when there are too few to reduce.
fn first_subset(points: &[DVec3], cell_over_spacing: f64) -> Vec<u32> {
    let spacing = typical_spacing(points, &Grid::new(points, 0.0));
    if spacing <= 0.0 || points.len() < 64 {
        return (0..points.len() as u32).collect();
    }
    first_in_each_cell(points, cell_over_spacing * spacing)
}

/// The smallest index of the points in each occupied cube of side `cell`, increasing.
fn first_in_each_cell(points: &[DVec3], cell: f64) -> Vec<u32> {
    let lo = points
        .iter()
        .fold(DVec3::splat(f64::INFINITY), |a, p| a.min(*p));
    // 21 bits per axis; cubes farther out wrap onto others' keys, which only merges cubes.
    let key = |p: DVec3| -> u64 {
        let c = ((p - lo) / cell).floor();
        let k = |x: f64| (x as u64) & ((1 << 21) - 1);
        k(c.x) | (k(c.y) << 21) | (k(c.z) << 42)
    };
    let mut keyed: Vec<(u64, u32)> = points
        .par_iter()
        .enumerate()
        .map(|(i, p)| (key(*p), i as u32))
        .collect();
    keyed.par_sort_unstable();
    let mut first: Vec<u32> = keyed
        .iter()
        .enumerate()
        .filter(|(k, (key, _))| *k == 0 || keyed[k - 1].0 != *key)
        .map(|(_, (_, i))| *i)
        .collect();
    first.par_sort_unstable();
    first
}

/// `|f(points[i]) − targets[i]|` for every point, in batches; infinity where f is not finite.
fn residuals(field: &dyn Field, points: &[DVec3], targets: Option<&[f64]>) -> Result<Vec<f64>> {
    let mut r = vec![0.0; points.len()];
    for (k, (p, out)) in points.chunks(BATCH).zip(r.chunks_mut(BATCH)).enumerate() {
        cancel::check()?;
        field.values(p, out);
        let t = targets.map(|t| &t[k * BATCH..k * BATCH + p.len()]);
        out.par_iter_mut().enumerate().for_each(|(i, v)| {
            let target = t.map_or(0.0, |t| t[i]);
            *v = if v.is_finite() {
                (*v - target).abs()
            } else {
                f64::INFINITY
            };
        });
    }
    Ok(r)
}

/// The sorted union of two sorted, disjoint index lists.
fn union(a: &[u32], b: &[u32]) -> Vec<u32> {
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() || j < b.len() {
        if j == b.len() || (i < a.len() && a[i] < b[j]) {
            out.push(a[i]);
            i += 1;
        } else {
            out.push(b[j]);
            j += 1;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 0 at the points it was fitted to, 1 elsewhere.
    struct AtPoints(Vec<DVec3>);
    impl Field for AtPoints {
        fn value(&self, p: DVec3) -> f64 {
            if self.0.contains(&p) {
                0.0
            } else {
                1.0
            }
        }
    }

    fn grid_points(n: usize) -> Vec<DVec3> {
        (0..n * n)
            .map(|i| DVec3::new((i % n) as f64, (i / n) as f64, 0.0) * 0.25)
            .collect()
    }

    #[test]
    fn first_in_each_cell_keeps_the_smallest_index_per_cube() {
        let p = grid_points(10);
        // Cubes of 0.5: 2 × 2 points each, the smallest index at even x and y.
        let first = first_in_each_cell(&p, 0.5);
        assert_eq!(first.len(), 25);
        for &i in &first {
            assert_eq!((i % 10) % 2, 0);
            assert_eq!((i / 10) % 2, 0);
        }
        assert!(first.windows(2).all(|w| w[0] < w[1]));
    }

    #[test]
    fn rounds_add_the_points_outside_until_none_is() {
        let p = grid_points(40);
        let settings = ReductionSettings {
            tolerance: 0.5,
            ..Default::default()
        };
        let mut sizes = Vec::new();
        let (s, r) = fit_within(
            &p,
            None,
            &settings,
            |used| {
                sizes.push(used.len());
                Ok(AtPoints(used.iter().map(|&i| p[i as usize]).collect()))
            },
            |s| s as &dyn Field,
        )
        .unwrap();
        assert_eq!(r.rounds, 2);
        assert!(sizes[0] < p.len() / 4, "{sizes:?}");
        assert_eq!((r.used, r.outside, r.largest_residual), (p.len(), 0, 0.0));
        assert_eq!(s.0, p);
        // One round only: the points outside are reported.
        let one = ReductionSettings {
            max_rounds: 1,
            ..settings
        };
        let (_, r) = fit_within(
            &p,
            Some(&vec![1.0; p.len()]),
            &one,
            |used| Ok(AtPoints(used.iter().map(|&i| p[i as usize]).collect())),
            |s| s as &dyn Field,
        )
        .unwrap();
        assert_eq!((r.rounds, r.outside, r.largest_residual), (1, r.used, 1.0));
    }

    #[test]
    fn union_merges_sorted_lists() {
        assert_eq!(
            union(&[1, 4, 9], &[0, 5, 10, 11]),
            vec![0, 1, 4, 5, 9, 10, 11]
        );
        assert_eq!(union(&[], &[2]), vec![2]);
    }

    #[test]
    fn tolerance_must_be_positive_and_finite() {
        for t in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let s = ReductionSettings {
                tolerance: t,
                ..Default::default()
            };
            assert!(s.check().is_err());
        }
    }
}
