//! Subsampled copies of the constraints, for the patches of leaves with few constraints in
//! their support (the leaves away from the data).
//!
//! Such a patch must interpolate the few constraints inside its support, but any other
//! constraints may complete its system: the blend's exactness only needs the ones inside. Its
//! nearest constraints would be one small cluster, and a fit to a small cluster extrapolates
//! badly over a support many times its size; so the system is completed with constraints spread
//! over a ball reaching one support radius past the nearest data, taken from the finest of
//! these levels where they fit the patch's budget. Level `L` keeps every data point `j` (with
//! its normal constraint) whose hash is divisible by 2^L: about one in 2^L, wherever it is, and
//! each level is a subset of the one before. Patches that see the data only near the edge of their
//! support, whose completion must carry the surface over the rest of it, choose among all
//! levels, as do patches with constraints inside their support; the others among the levels
//! 3, 6, 9, … (one in 8^k).

use super::octree::Octree;
use crate::field::constraints::Constraints;
use glam::DVec3;
use rayon::prelude::*;

/// One subsampled level: its constraints' indices and an octree over their points (which
/// keeps the only copy of them).
pub struct Level {
    /// Indices of the kept constraints.
    pub index: Vec<u32>,
    tree: Octree,
}

impl Level {
    /// Its constraints within the closed ball (`c`, `r`), counted up to `limit` (more than
    /// `limit` when there are more).
    pub fn count_within_up_to(&self, c: DVec3, r: f64, limit: usize) -> usize {
        self.tree.count_within_up_to(&[], c, r, limit)
    }

    /// Its constraints within the closed ball (`c`, `r`).
    pub fn count_within(&self, c: DVec3, r: f64) -> usize {
        self.count_within_up_to(c, r, usize::MAX)
    }

    /// Calls `visit(i, p)` for each of its constraints within the closed ball (`c`, `r`), with
    /// `i` the constraint's index and `p` its point.
    pub fn for_each_within(&self, c: DVec3, r: f64, mut visit: impl FnMut(u32, DVec3)) {
        self.tree
            .for_each_within_ranked(&[], c, r, |i, _, p| visit(self.index[i as usize], p));
    }
}

fn splitmix(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// Levels 1, 2, … of the constraints `c` (constraint `i` kept with its data point,
/// [`Constraints::data_point`]), down to the first level 3k with at most `smallest` points, each
/// with an octree over the cube (`centre`, `half`). Errors with
/// [`crate::error::Error::Interrupted`] when the calling thread's token is set (checked per
/// level).
pub fn levels(
    c: &Constraints,
    smallest: usize,
    centre: DVec3,
    half: f64,
    max_per_leaf: usize,
) -> crate::error::Result<Vec<Level>> {
    let points = &c.points;
    let hashes: Vec<u64> = (0..points.len())
        .into_par_iter()
        .map(|i| splitmix(c.data_point(i) as u64))
        .collect();
    let mut out = Vec::new();
    let mut step = 1u64;
    let mut size = points.len();
    while (size > smallest || !out.len().is_multiple_of(3)) && step < 1 << 60 {
        crate::cancel::check()?;
        step *= 2;
        let index: Vec<u32> = (0..points.len() as u32)
            .into_par_iter()
            .filter(|&i| hashes[i as usize].is_multiple_of(step))
            .collect();
        let pts: Vec<DVec3> = index.par_iter().map(|&i| points[i as usize]).collect();
        let tree = Octree::new(&pts, centre, half, max_per_leaf);
        size = pts.len();
        out.push(Level { index, tree });
    }
    Ok(out)
}
