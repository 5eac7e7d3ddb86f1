//! The patches of a partition-of-unity fit: one per octree leaf, a ball around the leaf's centre
//! of radius `overlap` × the leaf's half-diagonal, fitted to **every** constraint inside the
//! ball, so that every patch whose weight is non-zero at a constraint interpolates it. When the
//! ball holds fewer than `min_points` constraints, or the leaf fewer than [`SPARSE_LEAF`], or
//! (in fits with normals) the ball holds data points but none of their normal constraints, the
//! system is completed with constraints outside it, spread over a larger ball (see
//! [`super::coarse`]): up to max(`max_patch` − inside, `max_patch` / 2) for a patch that sees the
//! data only near the edge of its support ([`FAR_DATA`]), up to `max_patch` /
//! [`BLIND_BUDGET_DIVISOR`] for one whose ball holds data points but no normal constraint, up to
//! `max_patch` / [`NEAR_BUDGET_DIVISOR`] for the others. A patch with no constraint in its ball
//! only carries the field's sign away from the data: in fits with normal constraints it is a
//! plane ([`super::empty`]), otherwise completed with up to `min_points` / 2.

use super::coarse::Levels;
use super::empty;
use super::octree::Octree;
use super::PartitionSettings;
use crate::error::{Error, Result};
use crate::field::rbf::constraints::Constraints;
use crate::field::rbf::{self, PatchFit, VariationalSurface};
use faer::Par;
use glam::DVec3;
use rayon::prelude::*;
use std::sync::Mutex;

/// One fitted patch.
#[derive(Clone, Debug)]
pub struct Patch {
    /// Centre of the support.
    pub centre: DVec3,
    /// Support radius: the patch's weight is zero from this distance on.
    pub radius: f64,
    /// Number of constraints inside the support (all interpolated).
    pub inside: usize,
    /// Number of constraints it interpolates (`inside`, and those completing a small system).
    pub size: usize,
    /// Its interpolant, whose centres are indices into the surface's constraints.
    pub fit: PatchFit,
}

/// Where a patch's system comes from.
#[derive(Clone, Copy, Debug)]
pub struct Support {
    /// Centre of the support.
    pub centre: DVec3,
    /// Support radius.
    pub radius: f64,
    /// Constraints within `radius`.
    pub inside: usize,
    /// For small systems: the level (index into the coarse levels) and the radius of the ball
    /// whose constraints outside `radius` complete the system, and how many they are.
    pub extra: Option<(usize, f64, usize)>,
}

impl Support {
    /// Whether the patch is the plane of [`empty`]: no constraint inside, no completion.
    pub fn is_plane(&self) -> bool {
        self.inside == 0 && self.extra.is_none()
    }

    /// Constraints in the patch's system.
    pub fn size(&self) -> usize {
        if self.is_plane() {
            return empty::PLANE_POINTS;
        }
        self.inside + self.extra.map_or(0, |e| e.2)
    }
}

/// Leaves holding fewer constraints than this have their patch's system completed (see
/// [`super::coarse`]).
pub const SPARSE_LEAF: usize = 16;

/// Patches that see data near their centre complete their system with at most
/// `max_patch / NEAR_BUDGET_DIVISOR` constraints: their own constraints already carry the
/// surface across most of the support, and the completion only has to keep the field's shape
/// over the rest of it.
pub const NEAR_BUDGET_DIVISOR: usize = 8;

/// Patches whose support holds data points but no constraint off the surface complete their
/// system with at most `max_patch / BLIND_BUDGET_DIVISOR` constraints: the completion must
/// bring the constraints off the surface that give the field its slope.
pub const BLIND_BUDGET_DIVISOR: usize = 4;

/// Patches whose nearest constraint lies further from their centre than this fraction of
/// their radius see the data only near the edge of their support: they complete their system
/// from any coarse level, as do patches with constraints inside; the others from one in 8^k
/// (see [`super::coarse`]).
pub const FAR_DATA: f64 = 0.95;

/// How the constraints of a fit with normal constraints lie: the boundary constraints (value 0)
/// are `0..first_off`, the others off the surface, at most `largest_offset` from their data
/// point.
#[derive(Clone, Copy, Debug)]
pub struct Oriented {
    /// Index of the first constraint off the surface.
    pub first_off: usize,
    /// Largest distance of a constraint off the surface from its data point.
    pub largest_offset: f64,
}

/// The support of each leaf's patch. With `oriented` (fits with normal constraints), supports
/// holding no constraint get no completion (their patch is a plane, see [`empty`]), and
/// supports holding data points but no constraint off the surface are completed however many
/// they hold (fitted to zeros alone, a patch would be zero everywhere), from a ball reaching at
/// least the normal constraints of the data points inside. Errors with
/// [`crate::error::Error::Interrupted`] when the calling thread's token is set.
pub fn supports(
    tree: &Octree,
    points: &[DVec3],
    levels: &Levels,
    settings: &PartitionSettings,
    oriented: Option<Oriented>,
) -> Result<Vec<Support>> {
    let planes = oriented.is_some();
    let want = settings.min_points.min(points.len());
    let one = |scratch: &mut Vec<f64>, k: u32| -> Support {
        let n = &tree.nodes[k as usize];
        let r = settings.overlap * n.half_diagonal();
        let inside = tree.count_within(points, n.centre, r);
        let mut s = Support {
            centre: n.centre,
            radius: r,
            inside,
            extra: None,
        };
        // Leaves with (almost) no constraints of their own see the data only at the edge
        // of their support: those are completed too, however many constraints it holds.
        let own = (n.end - n.start) as usize;
        let off_surface =
            |o: Oriented| tree.any_within(points, n.centre, r, |i| i as usize >= o.first_off);
        let sees_off = || inside == 0 || oriented.is_none_or(off_surface);
        if (inside >= want && own >= SPARSE_LEAF && sees_off()) || (inside == 0 && planes) {
            return s;
        }
        // A ball reaching one support radius (or the largest offset of a normal
        // constraint, when larger) past the `want`-th nearest constraint, found from a
        // guess that takes the constraints to spread over a surface.
        let guess = r * (want as f64 / inside.max(1) as f64).sqrt().max(1.0) * 1.2;
        let (kth, nearest) = tree.nearest_distances(points, n.centre, want, guess, scratch);
        let reach = kth.max(r) + r.max(oriented.map_or(0.0, |o| o.largest_offset));
        let far = nearest > FAR_DATA * r;
        let budget = if inside == 0 {
            settings.min_points / 2
        } else if far {
            settings
                .max_patch
                .saturating_sub(inside)
                .max(settings.max_patch / 2)
        } else if !sees_off() {
            settings.max_patch / BLIND_BUDGET_DIVISOR
        } else {
            settings.max_patch / NEAR_BUDGET_DIVISOR
        };
        // Exact up to `budget`; more than `budget` when the ball holds more.
        let full = tree.count_within_up_to(points, n.centre, reach, budget + inside) - inside;
        // The levels this patch may take its completion from (see `coarse`): every level
        // for a far patch or one with constraints inside, so that a near patch's completion
        // holds between half its budget and its budget (a level of one in 8^k can leave it
        // a handful of constraints, too few to fit when its own lie in one plane); one in
        // 8^k for the others.
        let step = if far || inside > 0 { 1 } else { 3 };
        let candidates: Vec<usize> = (step - 1..levels.len()).step_by(step).collect();
        // The finest level whose share of the ball fits the budget; a finer one when that
        // leaves too few constraints for a fit.
        let mut choice = (usize::MAX, full);
        if full > budget {
            for (c, &l) in candidates.iter().enumerate() {
                let last = c + 1 == candidates.len();
                // The level's constraints between the two balls must fit the budget (the
                // count within `reach` is exact unless it exceeds the limit).
                let within_r = levels.count_within(l, n.centre, r);
                let limit = if last { usize::MAX } else { budget + within_r };
                let within_reach = levels.count_within_up_to(l, n.centre, reach, limit);
                if within_reach > limit {
                    continue;
                }
                let m = within_reach - within_r;
                if inside + m >= 16 {
                    choice = (l, m);
                } else if c > 0 {
                    let f = candidates[c - 1];
                    // The level's constraints between the two balls.
                    let m = levels.count_within(f, n.centre, reach)
                        - levels.count_within(f, n.centre, r);
                    choice = (f, m);
                }
                break;
            }
        }
        if choice.0 == usize::MAX && full > budget {
            // No level was chosen: the whole ball completes the system.
            choice.1 = tree.count_within(points, n.centre, reach) - inside;
        }
        s.extra = Some((choice.0, reach, choice.1));
        s
    };
    // The caller's token (rayon's threads do not see it): supports stop when it is set.
    let token = crate::cancel::current();
    tree.leaves
        .par_iter()
        .with_max_len(SUPPORT_RUN)
        .map_init(Vec::new, |scratch, &k| {
            if let Some(t) = &token {
                t.check()?;
            }
            Ok(one(scratch, k))
        })
        .collect()
}

/// Bytes the fit keeps for patches of the given sizes, plus the largest dense systems that
/// `threads` workers factorize at once.
pub fn estimate_bytes(sizes: &[usize], threads: usize) -> u64 {
    let kept: u64 = sizes
        .iter()
        .map(|&m| PatchFit::bytes(m) + 4 * m as u64)
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

/// Most patches one rayon job fits. Patches cost from a few microseconds (planes) to
/// milliseconds (coarse levels), unevenly along the octree's order: short runs of them keep
/// every thread busy to the end.
const FIT_RUN: usize = 32;
/// Most leaves one rayon job finds the support of, or patches the leaves of (their costs vary
/// as unevenly).
const SUPPORT_RUN: usize = 256;

/// Fits one patch per support, in parallel; errors with the first failing patch's error (in
/// leaf order). Each patch's centres are indices into the constraint points in the tree's
/// order (`rank[i]` the position of constraint `i` in `tree.order`). The points are read from
/// the tree's copy (which it must have), not from `c`, whose `points` may be empty.
pub fn fit(
    tree: &Octree,
    c: &Constraints,
    levels: &Levels,
    supports: &[Support],
    settings: &PartitionSettings,
) -> Result<Vec<Patch>> {
    assert!(
        tree.has_copy(),
        "the octree reads its own copy of the points"
    );
    let rank = inverse(&tree.order);
    let slots = empty::normal_slots(c);
    let ranked_values: Vec<f64> = tree
        .order
        .par_iter()
        .map(|&i| c.values[i as usize])
        .collect();
    // The memory of all patches is checked before (see `check_memory`).
    let rbf_settings = rbf::FitSettings {
        memory_limit: u64::MAX,
        ..settings.fit
    };
    // The caller's token (rayon's threads do not see it): patches stop when it is set, and
    // count the constraints they fitted.
    let token = crate::cancel::current();
    let one = |s: &Support| -> Result<Patch> {
        if let Some(t) = &token {
            t.check()?;
        }
        let (centre, radius) = (s.centre, s.radius);
        if s.is_plane() {
            let (pts, vals) = empty::plane(c, &slots, tree, &rank, centre, radius);
            let fit = PatchFit::fit(None, pts, vals, &rbf_settings, Par::Seq)?;
            return Ok(Patch {
                centre,
                radius,
                inside: 0,
                size: empty::PLANE_POINTS,
                fit,
            });
        }
        // The constraints inside (index, position in the tree's order, point), read from
        // the tree's copy in leaf order; then those completing the system (index, point).
        let mut own: Vec<(u32, u32, DVec3)> = Vec::with_capacity(s.inside);
        tree.for_each_within_ranked(&[], centre, radius, |i, k, p| own.push((i, k, p)));
        let mut outside: Vec<(u32, DVec3)> = Vec::new();
        if let Some((l, reach, _)) = s.extra {
            let mut visit = |i: u32, p: DVec3| {
                if (p - centre).length_squared() > radius * radius {
                    outside.push((i, p));
                }
            };
            if l == usize::MAX {
                tree.for_each_within_ranked(&[], centre, reach, |i, _, p| visit(i, p));
            } else {
                levels.for_each_within(l, centre, reach, visit);
            }
        }
        own.sort_unstable_by_key(|e| e.0);
        outside.sort_unstable_by_key(|e| e.0);
        let inside = own.len();
        let size = inside + outside.len();
        let pts = own
            .iter()
            .map(|e| e.2)
            .chain(outside.iter().map(|e| e.1))
            .collect();
        let vals = own
            .iter()
            .map(|e| ranked_values[e.1 as usize])
            .chain(outside.iter().map(|e| c.values[e.0 as usize]))
            .collect();
        let index = own
            .iter()
            .map(|e| e.1)
            .chain(outside.iter().map(|e| rank[e.0 as usize]))
            .collect();
        let fit = PatchFit::fit(Some(index), pts, vals, &rbf_settings, Par::Seq)?;
        if let Some(t) = &token {
            t.advance(inside as u64)?;
        }
        Ok(Patch {
            centre,
            radius,
            inside,
            size,
            fit,
        })
    };
    // The first failing patch (in leaf order) and its error; a failed patch is `None`.
    let failure: Mutex<Option<(usize, Error)>> = Mutex::new(None);
    let fitted: Vec<Option<Patch>> = supports
        .par_iter()
        .enumerate()
        .with_max_len(FIT_RUN)
        .map(|(k, s)| {
            one(s)
                .map_err(|e| {
                    let mut first = failure.lock().unwrap_or_else(|p| p.into_inner());
                    if first.as_ref().is_none_or(|(j, _)| k < *j) {
                        *first = Some((k, e));
                    }
                })
                .ok()
        })
        .collect();
    if let Some((_, e)) = failure.into_inner().unwrap_or_else(|p| p.into_inner()) {
        return Err(e);
    }
    Ok(into_patches(fitted))
}

/// The patches of `fitted`, all fitted, in the memory of `fitted` (`Option<Patch>` has the
/// layout of `Patch`, and collecting through `filter_map` reuses it).
#[allow(clippy::filter_map_identity)]
pub(super) fn into_patches(fitted: Vec<Option<Patch>>) -> Vec<Patch> {
    fitted.into_iter().filter_map(|p| p).collect()
}

/// The inverse of the permutation `order`: `inverse(order)[order[k]] = k`.
pub fn inverse(order: &[u32]) -> Vec<u32> {
    let mut rank = vec![0u32; order.len()];
    for (k, &i) in order.iter().enumerate() {
        rank[i as usize] = k as u32;
    }
    rank
}

/// For each leaf (its position in `tree.leaves`), the patches whose support meets it, in
/// increasing order: `(start, list)` with leaf `l`'s patches at `list[start[l]..start[l + 1]]`.
pub fn cover(tree: &Octree, patches: &[Patch]) -> (Vec<u32>, Vec<u32>) {
    let per_patch: Vec<Vec<u32>> = patches
        .par_iter()
        .with_max_len(SUPPORT_RUN)
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
    crate::error::check_memory("points", bytes, limit)
}
