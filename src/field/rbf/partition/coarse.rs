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
//!
//! The finest [`SHARED_LEVELS`] levels hold most of the levels' constraints (7/8 of them for
//! three): they are read from the fit's own octree, keeping the constraints whose hash is
//! divisible by 2^L, so that they cost one byte per constraint instead of a copy of the points
//! and an octree. Each coarser level has an octree over its own points.

use super::octree::Octree;
use crate::field::rbf::constraints::Constraints;
use glam::DVec3;
use rayon::prelude::*;

/// The finest levels, read from the fit's octree: a query on level `L` counts the nodes inside
/// its ball whole, and reads every point of the leaves the ball cuts, about 2^L for each
/// constraint of the level there.
pub const SHARED_LEVELS: usize = 3;

/// A coarse level: its constraints' indices and an octree over their points (which keeps the
/// only copy of them).
struct Level {
    /// Indices of the kept constraints.
    index: Vec<u32>,
    tree: Octree,
}

/// The levels 1, 2, … of a fit's constraints (index `l` is level `L = l + 1`).
pub struct Levels<'t> {
    /// The fit's octree, with its copy of the points.
    tree: &'t Octree,
    /// For each position `k` of `tree.order`, the number of trailing zeros of its constraint's
    /// hash: the constraint is in level `L` when this is at least `L`.
    depth: Vec<u8>,
    /// For each node of `tree`, its constraints in each shared level.
    node_counts: Vec<[u32; SHARED_LEVELS]>,
    /// Number of levels.
    count: usize,
    /// Levels `SHARED_LEVELS + 1`, … (index `l − SHARED_LEVELS`).
    own: Vec<Level>,
}

impl Levels<'_> {
    /// Number of levels.
    pub fn len(&self) -> usize {
        self.count
    }

    /// Whether there is no level.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// The constraints of level index `l` within the closed ball (`c`, `r`), counted up to
    /// `limit` (more than `limit` when there are more).
    pub fn count_within_up_to(&self, l: usize, c: DVec3, r: f64, limit: usize) -> usize {
        match l.checked_sub(SHARED_LEVELS) {
            Some(o) => self.own[o].tree.count_within_up_to(&[], c, r, limit),
            None => {
                let least = l as u8 + 1;
                self.tree.count_kept_within_up_to(
                    c,
                    r,
                    limit,
                    |j| self.node_counts[j as usize][l] as usize,
                    |k| self.depth[k] >= least,
                )
            }
        }
    }

    /// The constraints of level index `l` within the closed ball (`c`, `r`).
    pub fn count_within(&self, l: usize, c: DVec3, r: f64) -> usize {
        self.count_within_up_to(l, c, r, usize::MAX)
    }

    /// Calls `visit(i, p)` for each constraint of level index `l` within the closed ball
    /// (`c`, `r`), with `i` the constraint's index and `p` its point.
    pub fn for_each_within(&self, l: usize, c: DVec3, r: f64, mut visit: impl FnMut(u32, DVec3)) {
        match l.checked_sub(SHARED_LEVELS) {
            Some(o) => {
                let level = &self.own[o];
                level
                    .tree
                    .for_each_within_ranked(&[], c, r, |i, _, p| visit(level.index[i as usize], p))
            }
            None => {
                let least = l as u8 + 1;
                self.tree
                    .for_each_kept_within(c, r, |k| self.depth[k] >= least, visit)
            }
        }
    }
}

fn splitmix(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// The level of constraint `i` of `c`: the trailing zeros of its data point's hash.
fn depth_of(c: &Constraints, i: usize) -> u8 {
    splitmix(c.data_point(i) as u64).trailing_zeros() as u8
}

/// For each node of `tree`, the number of its points in each shared level (`depth` in the
/// tree's order): the leaves count their runs, the other nodes sum their children (which come
/// after them).
fn node_counts(tree: &Octree, depth: &[u8]) -> Vec<[u32; SHARED_LEVELS]> {
    let mut counts: Vec<[u32; SHARED_LEVELS]> = tree
        .nodes
        .par_iter()
        .map(|n| {
            let mut c = [0u32; SHARED_LEVELS];
            if n.is_leaf() {
                for &d in &depth[n.start as usize..n.end as usize] {
                    for (l, c) in c.iter_mut().enumerate() {
                        *c += (d as usize > l) as u32;
                    }
                }
            }
            c
        })
        .collect();
    for j in (0..tree.nodes.len()).rev() {
        let n = &tree.nodes[j];
        if !n.is_leaf() {
            let first = n.children as usize;
            let mut sum = [0u32; SHARED_LEVELS];
            for child in &counts[first..first + 8] {
                for (s, c) in sum.iter_mut().zip(child) {
                    *s += c;
                }
            }
            counts[j] = sum;
        }
    }
    counts
}

/// Levels 1, 2, … of the constraints `c` (constraint `i` kept with its data point,
/// [`Constraints::data_point`]), down to the first level 3k with at most `smallest` points;
/// those past [`SHARED_LEVELS`] each with an octree over the cube (`centre`, `half`). `tree` is
/// the fit's octree over `c.points`, with its copy of them. Errors with
/// [`crate::error::Error::Interrupted`] when the calling thread's token is set (checked per
/// level).
pub fn levels<'t>(
    tree: &'t Octree,
    c: &Constraints,
    smallest: usize,
    centre: DVec3,
    half: f64,
    max_per_leaf: usize,
) -> crate::error::Result<Levels<'t>> {
    assert!(
        tree.has_copy(),
        "the levels read the octree's copy of the points"
    );
    let points = &c.points;
    let depth: Vec<u8> = tree
        .order
        .par_iter()
        .map(|&i| depth_of(c, i as usize))
        .collect();
    let node_counts = node_counts(tree, &depth);
    // sizes[L] = constraints of level L (L ≤ 64; a hash of 0 is in every level).
    let mut histogram = [0usize; 65];
    depth.iter().for_each(|&d| histogram[d as usize] += 1);
    let mut count = 0usize;
    let mut size = points.len();
    while (size > smallest || !count.is_multiple_of(3)) && count < 60 {
        crate::cancel::check()?;
        count += 1;
        size -= histogram[count - 1];
    }
    let mut own: Vec<Level> = Vec::new();
    for l in SHARED_LEVELS..count {
        crate::cancel::check()?;
        let least = l as u8 + 1;
        let kept = |&i: &u32| depth_of(c, i as usize) >= least;
        // Each level is a subset of the one before.
        let index: Vec<u32> = match own.last() {
            None => (0..points.len() as u32)
                .into_par_iter()
                .filter(kept)
                .collect(),
            Some(finer) => finer.index.par_iter().copied().filter(kept).collect(),
        };
        let pts: Vec<DVec3> = index.par_iter().map(|&i| points[i as usize]).collect();
        let tree = Octree::new(&pts, centre, half, max_per_leaf);
        own.push(Level { index, tree });
    }
    Ok(Levels {
        tree,
        depth,
        node_counts,
        count,
        own,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::rbf::constraints;
    use crate::field::rbf::partition::{PartitionSettings, PartitionSurface};
    use crate::testing::random_points;

    /// Every level, read from the fit's octree or from its own, finds exactly the constraints
    /// of its hash within a ball, and counts them (up to a limit) as many.
    #[test]
    fn levels_find_the_constraints_of_their_hash() {
        // Points on a sphere, with a dense cluster, and their normal constraints.
        let mut p: Vec<DVec3> = random_points(6000, -1.0, 1.0, 21)
            .into_iter()
            .map(|q| 0.7 * q.normalize())
            .collect();
        p.extend(
            random_points(2000, 0.69, 0.71, 22)
                .into_iter()
                .map(|q| q * DVec3::new(1.0, 0.01, 0.01)),
        );
        let n: Vec<DVec3> = p.iter().map(|q| q.normalize()).collect();
        let c = constraints::place(&p, &n, &Default::default()).unwrap();
        let settings = PartitionSettings::default();
        let (centre, half) = PartitionSurface::cube(&c);
        let tree = PartitionSurface::tree(&c, &settings).unwrap();
        let levels = levels(&tree, &c, 16, centre, half, settings.max_per_leaf).unwrap();
        assert!(levels.len() > SHARED_LEVELS + 2, "{} levels", levels.len());
        let balls: Vec<(DVec3, f64)> = random_points(60, -0.9, 0.9, 23)
            .into_iter()
            .zip(random_points(60, 0.0, 1.0, 24))
            .map(|(q, r)| (q, 0.02 + 0.6 * r.x * r.x))
            .collect();
        for l in 0..levels.len() {
            let mut total = 0;
            for &(q, r) in &balls {
                let mut want: Vec<u32> = (0..c.points.len() as u32)
                    .filter(|&i| {
                        depth_of(&c, i as usize) as usize > l
                            && (c.points[i as usize] - q).length_squared() <= r * r
                    })
                    .collect();
                let mut got = Vec::new();
                levels.for_each_within(l, q, r, |i, x| {
                    assert_eq!(x, c.points[i as usize]);
                    got.push(i);
                });
                got.sort_unstable();
                want.sort_unstable();
                assert_eq!(got, want, "level {l}, ball {q} {r}");
                assert_eq!(levels.count_within(l, q, r), want.len());
                let limit = want.len() / 2;
                let capped = levels.count_within_up_to(l, q, r, limit);
                assert!(
                    capped > limit || want.is_empty(),
                    "level {l}: {capped} of {}",
                    want.len()
                );
                total += want.len();
            }
            assert!(total > 0, "level {l} finds nothing in any ball");
        }
    }
}
