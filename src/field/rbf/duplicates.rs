//! Near-duplicate data points, merged before a fit.
//!
//! Two data points much closer than the data's spacing add nothing to the surface, but they
//! make the interpolation system nearly singular (two almost equal rows), and Cuno's offset rule
//! shrinks their normal constraints to the same tiny distance. Points closer than
//! [`MERGE_FRACTION`] × the data's [`typical_spacing`] (or an explicit tolerance) are therefore
//! merged: each group of points linked by such pairs becomes its smallest-indexed point, whose
//! position is kept exactly (the fit interpolates it); the group's normals are summed, its values
//! averaged.

use crate::spatial::Grid;
use glam::DVec3;
use rayon::prelude::*;

/// Points closer than this fraction of [`typical_spacing`] are merged by default.
pub const MERGE_FRACTION: f64 = 1e-3;

/// Points at most this fraction of the data's largest side apart are always merged.
pub const COINCIDENT: f64 = 1e-9;

/// How many points [`typical_spacing`] measures at most.
const SPACING_SAMPLE: usize = 4096;

/// The groups of merged points: for each point, the index of the point it merges into.
#[derive(Clone, Debug, PartialEq)]
pub struct Merge {
    /// `into[i]` is the smallest index of `i`'s group (`i` itself for a kept point).
    pub into: Vec<u32>,
    /// Indices of the kept points, increasing.
    pub kept: Vec<u32>,
}

impl Merge {
    /// Number of points merged into others.
    pub fn merged(&self) -> usize {
        self.into.len() - self.kept.len()
    }

    /// The kept points.
    pub fn points(&self, points: &[DVec3]) -> Vec<DVec3> {
        self.kept.iter().map(|&k| points[k as usize]).collect()
    }

    /// For each kept point, the normalised sum of its group's unit normals, or its own where
    /// they cancel.
    pub fn normals(&self, normals: &[DVec3]) -> Vec<DVec3> {
        let sums = self.sums(normals, DVec3::ZERO);
        self.kept
            .iter()
            .zip(sums)
            .map(|(&k, s)| {
                if s.length() > 1e-6 {
                    s.normalize()
                } else {
                    normals[k as usize]
                }
            })
            .collect()
    }

    /// For each kept point, the mean of its group's values.
    pub fn means(&self, values: &[f64]) -> Vec<f64> {
        let sums = self.sums(values, 0.0);
        let counts = self.sums(&vec![1.0; values.len()], 0.0);
        sums.iter().zip(counts).map(|(s, c)| s / c).collect()
    }

    /// For each kept point, the smallest of its group's values.
    pub fn minima(&self, values: &[f64]) -> Vec<f64> {
        let slot = self.slots();
        let mut out = vec![f64::INFINITY; self.kept.len()];
        for (i, &g) in self.into.iter().enumerate() {
            let s = slot[g as usize] as usize;
            out[s] = out[s].min(values[i]);
        }
        out
    }

    fn sums<T: Copy + std::ops::AddAssign>(&self, values: &[T], zero: T) -> Vec<T> {
        let slot = self.slots();
        let mut out = vec![zero; self.kept.len()];
        for (i, &g) in self.into.iter().enumerate() {
            out[slot[g as usize] as usize] += values[i];
        }
        out
    }

    /// Position of each kept point among the kept ones (indexed by point; others unused).
    fn slots(&self) -> Vec<u32> {
        let mut slot = vec![u32::MAX; self.into.len()];
        for (s, &k) in self.kept.iter().enumerate() {
            slot[k as usize] = s as u32;
        }
        slot
    }
}

/// The median distance from a point to its nearest other point, over up to 4096 points taken
/// at a fixed stride; 0 for fewer than two points or when most points have a coincident twin.
pub fn typical_spacing(points: &[DVec3], grid: &Grid) -> f64 {
    let n = points.len();
    if n < 2 {
        return 0.0;
    }
    let side = crate::field::rbf::constraints::largest_side(points);
    if side <= 0.0 {
        return 0.0;
    }
    let stride = n.div_ceil(SPACING_SAMPLE);
    // Points on a surface of area about side² lie about side/√n apart.
    let start = side / (n as f64).sqrt();
    let mut nearest: Vec<f64> = (0..n)
        .into_par_iter()
        .step_by(stride)
        .map(|i| {
            let p = points[i];
            let mut r = start;
            loop {
                let mut best = f64::INFINITY;
                grid.for_each_within_points(p, r, |j, q| {
                    if j as usize != i {
                        best = best.min((q - p).length());
                    }
                });
                if best.is_finite() || r > 4.0 * side {
                    return best;
                }
                r *= 2.0;
            }
        })
        .collect();
    let mid = nearest.len() / 2;
    let (_, m, _) = nearest.select_nth_unstable_by(mid, f64::total_cmp);
    if m.is_finite() {
        *m
    } else {
        0.0
    }
}

/// The default merge tolerance: [`MERGE_FRACTION`] × [`typical_spacing`], at least
/// [`COINCIDENT`] × the largest side.
pub fn default_tolerance(points: &[DVec3], grid: &Grid) -> f64 {
    let floor = COINCIDENT * crate::field::rbf::constraints::largest_side(points);
    (MERGE_FRACTION * typical_spacing(points, grid)).max(floor)
}

/// Groups the points linked by pairs at most `tolerance` apart (`None`: [`default_tolerance`]).
pub fn merge(points: &[DVec3], tolerance: Option<f64>) -> Merge {
    let grid = Grid::new(points, tolerance.unwrap_or(0.0));
    let tol = tolerance.unwrap_or_else(|| default_tolerance(points, &grid));
    // Each point's neighbours with smaller indices; almost all lists are empty. Points are
    // taken in the grid's order (each query reads the cells the one before read); the groups,
    // each under its smallest index, do not depend on the order of the pairs.
    let reach = tol * (1.0 + 1e-9) + f64::MIN_POSITIVE;
    let earlier: Vec<(u32, u32)> = grid
        .order()
        .par_iter()
        .flat_map_iter(|&i| {
            let p = points[i as usize];
            let mut found = Vec::new();
            grid.for_each_within_points(p, reach, |j, q| {
                if j < i && (q - p).length() <= tol {
                    found.push((i, j));
                }
            });
            found
        })
        .collect();
    let mut parent: Vec<u32> = (0..points.len() as u32).collect();
    for (i, j) in earlier {
        union(&mut parent, i, j);
    }
    let into: Vec<u32> = (0..points.len() as u32)
        .map(|i| root(&mut parent, i))
        .collect();
    let kept = (0..points.len() as u32)
        .filter(|&i| into[i as usize] == i)
        .collect();
    Merge { into, kept }
}

fn root(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        let up = parent[parent[i as usize] as usize];
        parent[i as usize] = up;
        i = up;
    }
    i
}

/// Joins the groups of `a` and `b` under the smaller root.
fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (root(parent, a), root(parent, b));
    let (lo, hi) = (ra.min(rb), ra.max(rb));
    parent[hi as usize] = lo;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::random_points;

    #[test]
    fn spread_points_are_all_kept() {
        let p = random_points(2000, -1.0, 1.0, 3);
        let m = merge(&p, None);
        assert_eq!(m.merged(), 0);
        assert_eq!(m.kept.len(), 2000);
    }

    #[test]
    fn near_twins_and_chains_merge_into_the_smallest_index() {
        let mut p = random_points(1000, -1.0, 1.0, 5);
        let spacing = typical_spacing(&p, &Grid::new(&p, 0.0));
        assert!(spacing > 0.0);
        let e = DVec3::new(1.0, 0.0, 0.0) * 1e-4 * spacing;
        p.push(p[10] + e); // 1000 → 10
        p.push(p[1000] + e); // 1001 → 1000 → 10 (a chain)
        p.push(p[20]); // an exact twin
        p.push(p[30] + DVec3::new(0.0, 0.5 * spacing, 0.0)); // far enough to keep
        let m = merge(&p, None);
        assert_eq!(m.merged(), 3);
        assert_eq!(m.into[1000], 10);
        assert_eq!(m.into[1001], 10);
        assert_eq!(m.into[1002], 20);
        assert_eq!(m.into[1003], 1003);
        assert_eq!(m.points(&p)[10], p[10]);
        let values: Vec<f64> = (0..p.len()).map(|i| i as f64).collect();
        let means = m.means(&values);
        assert_eq!(means[10], (10.0 + 1000.0 + 1001.0) / 3.0);
        assert_eq!(m.minima(&values)[20], 20.0);
    }

    #[test]
    fn opposite_normals_keep_the_first() {
        let p = vec![DVec3::ZERO, DVec3::ZERO, DVec3::X];
        let n = vec![DVec3::Z, -DVec3::Z, DVec3::X];
        let m = merge(&p, Some(1e-9));
        assert_eq!(m.normals(&n), vec![DVec3::Z, DVec3::X]);
    }
}
