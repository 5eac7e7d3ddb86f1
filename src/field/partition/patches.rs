//! The patches of a partition-of-unity fit: one per octree leaf, a ball around the leaf's centre
//! whose radius is `overlap` × the leaf's half-diagonal, or the distance to the centre's
//! `min_points`-th nearest constraint when that is larger, fitted to **every** constraint inside
//! the ball, so that every patch whose weight is non-zero at a constraint interpolates it.

use super::octree::Octree;
use super::Settings;
use crate::error::{Error, Result};
use crate::field::constraints::Constraints;
use crate::field::rbf::{self, VariationalSurface};
use faer::Par;
use glam::DVec3;
use rayon::prelude::*;

/// One fitted patch.
#[derive(Clone, Debug)]
pub struct Patch {
    pub centre: DVec3,
    /// Support radius: the patch's weight is zero from this distance on.
    pub radius: f64,
    /// Number of constraints it interpolates.
    pub size: usize,
    pub fit: VariationalSurface,
}

/// Ball (centre, radius) and constraint count of each leaf's patch.
pub fn supports(tree: &Octree, points: &[DVec3], settings: &Settings) -> Vec<(DVec3, f64, usize)> {
    let want = settings.min_points.min(points.len());
    tree.leaves
        .par_iter()
        .map(|&k| {
            let n = &tree.nodes[k as usize];
            let mut r = settings.overlap * n.half_diagonal();
            let mut count = tree.count_within(points, n.centre, r);
            if count < want {
                r = r.max(tree.kth_nearest_distance(points, n.centre, want));
                count = tree.count_within(points, n.centre, r);
                // The square of the rounded square root may fall short of the squared distance.
                while count < want {
                    r = r.next_up();
                    count = tree.count_within(points, n.centre, r);
                }
            }
            (n.centre, r, count)
        })
        .collect()
}

/// Bytes the fit keeps for patches of the given sizes, plus the largest dense systems that
/// `threads` workers factorize at once.
pub fn estimate_bytes(sizes: &[usize], threads: usize) -> u64 {
    let kept: u64 = sizes
        .iter()
        .map(|&m| VariationalSurface::patch_bytes(m) + 4 * m as u64)
        .sum();
    let mut largest: Vec<usize> = sizes.to_vec();
    largest.sort_unstable_by(|a, b| b.cmp(a));
    let solving: u64 = largest
        .iter()
        .take(threads.max(1))
        .map(|&m| VariationalSurface::system_bytes(m) + 64 * m as u64)
        .sum();
    kept + solving
}

/// Fits one patch per support, in parallel; errors with the first failing patch's error (in
/// leaf order).
pub fn fit(
    tree: &Octree,
    c: &Constraints,
    supports: &[(DVec3, f64, usize)],
    settings: &Settings,
) -> Result<Vec<Patch>> {
    let rbf_settings = rbf::Settings {
        kernel: settings.kernel,
        smoothing: settings.smoothing,
        memory_limit: u64::MAX,
    };
    let fitted: Vec<Result<Patch>> = supports
        .par_iter()
        .map(|&(centre, radius, size)| {
            let mut idx = Vec::with_capacity(size);
            tree.for_each_within(&c.points, centre, radius, |i| idx.push(i));
            idx.sort_unstable();
            let pts: Vec<DVec3> = idx.iter().map(|&i| c.points[i as usize]).collect();
            let vals: Vec<f64> = idx.iter().map(|&i| c.values[i as usize]).collect();
            let fit = VariationalSurface::fit_patch(pts, vals, &rbf_settings, Par::Seq)?;
            Ok(Patch {
                centre,
                radius,
                size: idx.len(),
                fit,
            })
        })
        .collect();
    fitted.into_iter().collect()
}

/// For each leaf (its position in `tree.leaves`), the patches whose support meets it, in
/// increasing order: `(start, list)` with leaf `l`'s patches at `list[start[l]..start[l + 1]]`.
pub fn cover(tree: &Octree, patches: &[Patch]) -> (Vec<u32>, Vec<u32>) {
    let per_patch: Vec<Vec<u32>> = patches
        .par_iter()
        .map(|p| {
            let mut leaves = Vec::new();
            tree.for_each_leaf_meeting(p.centre, p.radius, |k| {
                leaves.push(tree.leaf_slot[k as usize])
            });
            leaves
        })
        .collect();
    let nl = tree.leaves.len();
    let mut start = vec![0u32; nl + 1];
    for leaves in &per_patch {
        for &l in leaves {
            start[l as usize + 1] += 1;
        }
    }
    for l in 0..nl {
        start[l + 1] += start[l];
    }
    let mut fill = start.clone();
    let mut list = vec![0u32; start[nl] as usize];
    // Patches in increasing order: each leaf's list comes out sorted.
    for (i, leaves) in per_patch.iter().enumerate() {
        for &l in leaves {
            list[fill[l as usize] as usize] = i as u32;
            fill[l as usize] += 1;
        }
    }
    (start, list)
}

/// Errors when `bytes` exceeds `limit`.
pub fn check_memory(bytes: u64, limit: u64) -> Result<()> {
    if bytes > limit {
        return Err(Error::TooMuchMemory {
            name: "points",
            needed_mib: bytes.div_ceil(1 << 20),
            limit_mib: limit >> 20,
        });
    }
    Ok(())
}
