//! Kernel sums Σⱼ w(|xᵢ − xⱼ|/H) of a particle set at its own particles (the SPH density pass of
//! [`crate::field::blob::particles`]), over a cell list: the particles sorted by cells of side H (or more),
//! each particle's neighbours read from the nine runs of cells (three x-neighbours each) around
//! its own, contiguous in memory.

use crate::error::Result;
use crate::field::blob::kernel::{with_profile, BlobKernel, Profile};
use glam::DVec3;
use rayon::prelude::*;

/// Largest number of cells of the list (the cell side grows to stay under it).
const MAX_CELLS: f64 = (1u64 << 24) as f64;

/// Sorted particles per step (the call stops between steps when told to).
const STEP: usize = 1 << 16;

/// Sorted particles per unit of parallel work.
const CHUNK: usize = 1 << 10;

/// The particles sorted by cell, z slowest, then y, then x.
pub(super) struct CellList {
    origin: DVec3,
    inv_side: f64,
    dims: [usize; 3],
    /// `start[c]..start[c + 1]`: the sorted particles of cell c.
    start: Vec<u32>,
    /// Positions in cell order.
    pub(super) sorted: Vec<DVec3>,
    /// The index among the caller's particles of each sorted one.
    pub(super) order: Vec<u32>,
}

impl CellList {
    /// Cells of side `side` at least, over the bounding box of `points` (finite, not empty).
    pub(super) fn new(points: &[DVec3], side: f64) -> Self {
        let (lo, hi) = points.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), &p| (lo.min(p), hi.max(p)),
        );
        let extent = hi - lo;
        let mut side = side;
        // Counted in floats: a far point's (e / s) exceeds usize.
        let cells = |s: f64| extent.to_array().map(|e| (e / s).floor() + 1.0);
        while cells(side).iter().product::<f64>() > MAX_CELLS && side.is_finite() {
            side *= 1.25;
        }
        let dims = cells(side).map(|c| if c.is_finite() { c as usize } else { 1 });
        let inv_side = 1.0 / side;
        let mut list = CellList {
            origin: lo,
            inv_side,
            dims,
            start: Vec::new(),
            sorted: Vec::new(),
            order: Vec::new(),
        };
        let cell: Vec<u32> = points.par_iter().map(|&p| list.cell_of(p) as u32).collect();
        let mut start = vec![0u32; dims.iter().product::<usize>() + 1];
        for &c in &cell {
            start[c as usize + 1] += 1;
        }
        for c in 1..start.len() {
            start[c] += start[c - 1];
        }
        let mut cursor = start.clone();
        let mut order = vec![0u32; points.len()];
        for (i, &c) in cell.iter().enumerate() {
            order[cursor[c as usize] as usize] = i as u32;
            cursor[c as usize] += 1;
        }
        list.sorted = order.par_iter().map(|&i| points[i as usize]).collect();
        list.start = start;
        list.order = order;
        list
    }

    /// The cell coordinates of `p` (inside the box).
    fn coords(&self, p: DVec3) -> [usize; 3] {
        let q = (p - self.origin) * self.inv_side;
        // Truncation is floor here (q ≥ 0); a point on the box's upper faces can round to the
        // cell past them.
        let c = [q.x, q.y, q.z].map(|v| v as usize);
        [0, 1, 2].map(|k| c[k].min(self.dims[k] - 1))
    }

    fn cell_of(&self, p: DVec3) -> usize {
        let [x, y, z] = self.coords(p);
        x + self.dims[0] * (y + self.dims[1] * z)
    }

    /// The nine runs of sorted particles in the cells next to `p`'s (its own included): per
    /// (y, z) neighbour row, the cells x − 1 ..= x + 1 in the box.
    fn runs(&self, p: DVec3, f: impl FnMut(&[DVec3])) {
        self.runs_within(p, 1, f)
    }

    /// The runs of sorted particles in the cells within `m` cells of `p`'s along each axis
    /// (its own included): per (y, z) neighbour row, the cells x − m ..= x + m in the box.
    pub(super) fn runs_within(&self, p: DVec3, m: usize, mut f: impl FnMut(&[DVec3])) {
        let [x, y, z] = self.coords(p);
        let [dx, dy, dz] = self.dims;
        let (x0, x1) = (x.saturating_sub(m), (x + m).min(dx - 1));
        for zz in z.saturating_sub(m)..=(z + m).min(dz - 1) {
            for yy in y.saturating_sub(m)..=(y + m).min(dy - 1) {
                let row = dx * (yy + dy * zz);
                let (a, b) = (self.start[row + x0], self.start[row + x1 + 1]);
                f(&self.sorted[a as usize..b as usize]);
            }
        }
    }
}

/// Σⱼ w(|xᵢ − xⱼ|/H) over the particles j within H of particle i (itself included: each sum is
/// at least 1), for every particle i, with `kernel`'s profile w read through t = 1 − d²/H² as
/// the blob field evaluates it. Parallel; stops between steps when the caller's
/// [`crate::cancel`] token is set, and reports particles done.
pub fn kernel_sums(points: &[DVec3], support: f64, kernel: BlobKernel) -> Result<Vec<f64>> {
    check_support("support", support)?;
    if points.is_empty() {
        return Ok(Vec::new());
    }
    let list = CellList::new(points, support);
    let inv = 1.0 / (support * support);
    let mut sorted_sums = vec![0.0; points.len()];
    for (step, out) in sorted_sums.chunks_mut(STEP).enumerate() {
        crate::cancel::check()?;
        let first = step * STEP;
        let own = &list.sorted[first..first + out.len()];
        with_profile!(kernel, K => {
            out.par_chunks_mut(CHUNK)
                .zip(own.par_chunks(CHUNK))
                .for_each(|(o, p)| {
                    for (o, &p) in o.iter_mut().zip(p) {
                        *o = sum_at::<K>(&list, p, inv);
                    }
                })
        });
        crate::cancel::advance(out.len() as u64)?;
    }
    let mut sums = vec![0.0; points.len()];
    for (&i, &s) in list.order.iter().zip(&sorted_sums) {
        sums[i as usize] = s;
    }
    Ok(sums)
}

/// Errors (naming `name`) unless `support` is positive with a square and an inverse square that
/// are normal float64 numbers: the sums compare squared distances with it.
pub fn check_support(name: &'static str, support: f64) -> Result<()> {
    let inv = 1.0 / (support * support);
    if !(support > 0.0 && inv.is_finite() && inv >= f64::MIN_POSITIVE) {
        return Err(crate::error::Error::invalid(
            name,
            format!(
                "the compact support H = 2 · smoothing_length · particle_radius = {support:e} must lie between 1e-154 and 1e154 (its square must be a normal float64)"
            ),
        ));
    }
    Ok(())
}

/// Σ w over the particles of the runs around `p` (1/H² `inv`); the particles at H or beyond,
/// whose w is +0.0, are skipped.
#[inline(always)]
fn sum_at<K: Profile>(list: &CellList, p: DVec3, inv: f64) -> f64 {
    let mut s = 0.0;
    list.runs(p, |run| {
        for &c in run {
            let d = p - c;
            let t = (1.0 - (d.y * d.y + d.z * d.z) * inv) - (d.x * d.x) * inv;
            if t > 0.0 {
                s += K::value(t);
            }
        }
    });
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::random_points;

    /// The sums against the direct double loop, for each kernel, with particles on the box's
    /// faces and a spread that makes the cells grow.
    #[test]
    fn equal_the_direct_sums() {
        let mut p = random_points(2000, -0.5, 0.5, 7);
        p.push(DVec3::splat(0.5));
        p.push(DVec3::splat(-0.5));
        for h in [0.05, 0.2, 1e-6] {
            for kernel in [
                BlobKernel::Triquet,
                BlobKernel::CubicSpline,
                BlobKernel::Wendland,
            ] {
                let sums = kernel_sums(&p, h, kernel).unwrap();
                for (a, s) in p.iter().zip(&sums) {
                    let want: f64 = p.iter().map(|b| kernel.value((*a - *b).length(), h)).sum();
                    assert!(
                        (s - want).abs() <= 1e-12 * want,
                        "{kernel:?} h {h}: {s} vs {want}"
                    );
                    assert!(*s >= 1.0);
                }
            }
        }
        assert!(kernel_sums(&[], 0.1, BlobKernel::CubicSpline)
            .unwrap()
            .is_empty());
    }

    /// A particle far from the rest (which the colour field refuses, but the sums take): the
    /// cell list stays within its cap and the sums are the direct ones.
    #[test]
    fn a_far_particle_keeps_the_cell_list_bounded() {
        let mut p = random_points(500, -1.0, 1.0, 5);
        p.push(DVec3::new(1e200, 0.0, 0.0));
        let h = 0.01;
        let sums = kernel_sums(&p, h, BlobKernel::CubicSpline).unwrap();
        for (a, s) in p.iter().zip(&sums) {
            let want: f64 = p
                .iter()
                .map(|b| BlobKernel::CubicSpline.value((*a - *b).length(), h))
                .sum();
            assert!((s - want).abs() <= 1e-12 * want && *s >= 1.0);
        }
        assert!(kernel_sums(&p, 1e-160, BlobKernel::CubicSpline).is_err());
    }
}
