//! k nearest neighbours over a point set, and what they give: unoriented normals by principal
//! component analysis of each point's neighbourhood.
//!
//! [`PointTree`] is a balanced binary tree of boxes over the points: every node splits its
//! points at their median along its box's longest side, down to one depth at which every leaf
//! holds at most [`LEAF`] points, so that the tree is implicit (node `i` has children `2i + 1`
//! and `2i + 2`) and only the boxes are stored. The points are kept in leaf order; queries about
//! the points themselves ([`PointTree::k_nearest_of_points`], [`pca_normals`]) run in that order,
//! so that consecutive queries read the same leaves, and each first offers the points of the few
//! leaves around its own, so that its bound is close from its first step. A query
//! allocates nothing: each parallel job of [`BATCH`] queries reuses one buffer of `k`
//! neighbours.

use crate::error::{Error, Result};
use glam::DVec3;
use rayon::prelude::*;

/// Most points in a leaf.
pub const LEAF: usize = 8;
/// Queries per parallel job.
pub const BATCH: usize = 1024;
/// The traversal stack's depth: more than the tree's depth for 2³² points (32 levels).
const STACK: usize = 40;

/// A balanced tree of boxes over a point set (see the module's documentation).
pub struct PointTree {
    /// The points in leaf order.
    sorted: Vec<DVec3>,
    /// The caller's index of each point, in leaf order.
    order: Vec<u32>,
    /// Each node's box (`lo`, `hi`), nodes numbered level by level from the root.
    boxes: Vec<(DVec3, DVec3)>,
    /// The leaves' ranges in leaf order: leaf `j` holds `starts[j]..starts[j + 1]`.
    starts: Vec<u32>,
    /// The depth of the leaves (the root's is 0).
    depth: u32,
}

/// The `k` nearest points found so far, sorted by increasing squared distance (ties by index).
struct Nearest<'a> {
    found: &'a mut [(f64, u32)],
    len: usize,
    /// The squared distance beyond which no point is offered.
    limit: f64,
}

impl Nearest<'_> {
    /// The squared distance a point must beat to enter (the limit until `k` are found).
    #[inline]
    fn bound(&self) -> f64 {
        if self.len == self.found.len() {
            self.found[self.len - 1].0
        } else {
            self.limit
        }
    }

    #[inline]
    fn offer(&mut self, d: f64, j: u32) {
        let k = self.found.len();
        if self.len == k && (d, j) >= self.found[k - 1] {
            return;
        }
        let mut at = if self.len < k {
            self.len += 1;
            self.len - 1
        } else {
            k - 1
        };
        while at > 0 && self.found[at - 1] > (d, j) {
            self.found[at] = self.found[at - 1];
            at -= 1;
        }
        self.found[at] = (d, j);
    }
}

#[inline]
fn box_distance_squared(p: DVec3, (lo, hi): (DVec3, DVec3)) -> f64 {
    (lo - p).max(p - hi).max(DVec3::ZERO).length_squared()
}

fn bounds(points: &[DVec3]) -> (DVec3, DVec3) {
    points.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    )
}

/// Sorts `items` (point, index) into leaf order: `levels` median splits along the longest side.
fn sort_into_leaves(items: &mut [(DVec3, u32)], levels: u32) {
    if levels == 0 || items.len() < 2 {
        return;
    }
    let (lo, hi) = items.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), (p, _)| (lo.min(*p), hi.max(*p)),
    );
    let e = hi - lo;
    let axis = if e.x >= e.y && e.x >= e.z {
        0
    } else if e.y >= e.z {
        1
    } else {
        2
    };
    let m = items.len() / 2;
    items.select_nth_unstable_by(m, |a, b| {
        a.0[axis].total_cmp(&b.0[axis]).then(a.1.cmp(&b.1))
    });
    let (l, r) = items.split_at_mut(m);
    if l.len() > 4096 {
        rayon::join(
            || sort_into_leaves(l, levels - 1),
            || sort_into_leaves(r, levels - 1),
        );
    } else {
        sort_into_leaves(l, levels - 1);
        sort_into_leaves(r, levels - 1);
    }
}

/// The leaves' starts of a tree of `levels` median splits of `n` points (the left half of a node
/// of `m` points holds `m / 2`).
fn leaf_starts(n: usize, levels: u32) -> Vec<u32> {
    let mut starts = vec![0u32];
    fn walk(start: usize, len: usize, levels: u32, out: &mut Vec<u32>) {
        if levels == 0 {
            out.push((start + len) as u32);
            return;
        }
        let m = len / 2;
        walk(start, m, levels - 1, out);
        walk(start + m, len - m, levels - 1, out);
    }
    walk(0, n, levels, &mut starts);
    starts
}

impl PointTree {
    /// The tree over `points`. Errors name `points`: a point that is not finite, or 2³² or more
    /// points.
    pub fn new(points: &[DVec3]) -> Result<PointTree> {
        crate::error::check_finite_points("points", points)?;
        let n = points.len();
        if n >= u32::MAX as usize {
            return Err(Error::invalid("points", "2³² or more points"));
        }
        // The depth at which every leaf holds at most LEAF points (the larger half of a node of m
        // points holds ⌈m/2⌉).
        let mut depth = 0u32;
        let mut largest = n;
        while largest > LEAF {
            largest = largest.div_ceil(2);
            depth += 1;
        }
        let mut items: Vec<(DVec3, u32)> = points
            .par_iter()
            .enumerate()
            .map(|(i, p)| (*p, i as u32))
            .collect();
        sort_into_leaves(&mut items, depth);
        let starts = leaf_starts(n, depth);
        let (sorted, order): (Vec<DVec3>, Vec<u32>) = items.into_par_iter().unzip();
        // The leaves' boxes, then each level's from the level below.
        let leaves = 1usize << depth;
        let mut boxes =
            vec![(DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)); 2 * leaves - 1];
        boxes[leaves - 1..]
            .par_iter_mut()
            .enumerate()
            .for_each(|(j, b)| *b = bounds(&sorted[starts[j] as usize..starts[j + 1] as usize]));
        for level in (0..depth).rev() {
            let first = (1usize << level) - 1;
            let (upper, lower) = boxes.split_at_mut(2 * first + 1);
            upper[first..]
                .par_iter_mut()
                .enumerate()
                .for_each(|(i, b)| {
                    let (l, r) = (lower[2 * i], lower[2 * i + 1]);
                    *b = (l.0.min(r.0), l.1.max(r.1));
                });
        }
        Ok(PointTree {
            sorted,
            order,
            boxes,
            starts,
            depth,
        })
    }

    /// The number of points.
    pub fn len(&self) -> usize {
        self.sorted.len()
    }

    /// Whether the tree holds no points.
    pub fn is_empty(&self) -> bool {
        self.sorted.is_empty()
    }

    /// The tree's layout, for structures that annotate its nodes: the points in leaf order, the
    /// caller's index of each, the leaves' starts (leaf `j` holds `starts[j]..starts[j + 1]`)
    /// and the leaves' depth (node `i` has children `2i + 1` and `2i + 2`; leaf `j` is node
    /// `2^depth − 1 + j`).
    pub(crate) fn layout(&self) -> (&[DVec3], &[u32], &[u32], u32) {
        (&self.sorted, &self.order, &self.starts, self.depth)
    }

    /// The `out.len()` nearest points to `p`, nearest first (ties by smaller index), as
    /// (squared distance, the caller's index) into `out`, which must not be longer than the
    /// point set.
    pub fn k_nearest_into(&self, p: DVec3, out: &mut [(f64, u32)]) {
        self.search(p, out, 0..0, f64::INFINITY);
    }

    /// The nearest point to `p` within `radius` of it, as (distance, the caller's index), or
    /// `None` when there is none. Cheaper than [`PointTree::k_nearest_into`] far from the
    /// points: no node farther than `radius` is opened.
    pub fn nearest_within(&self, p: DVec3, radius: f64) -> Option<(f64, u32)> {
        let mut found = [(0.0, 0u32)];
        let n = self.search(p, &mut found, 0..0, radius * radius);
        (n == 1).then(|| (found[0].0.sqrt(), found[0].1))
    }

    /// The leaves offered first to the query of the point at leaf position `s`: the subtree of
    /// the fewest levels above its leaf whose leaves hold `k` points or more when each holds
    /// LEAF / 2 (a leaf holds at least LEAF / 2 points unless the set has LEAF or fewer).
    fn seed_leaves(&self, s: usize, k: usize) -> std::ops::Range<usize> {
        let leaf = self.starts.partition_point(|&x| x as usize <= s) - 1;
        let mut levels = 0;
        while levels < self.depth && (1usize << levels) * (LEAF / 2) < k {
            levels += 1;
        }
        let first = (leaf >> levels) << levels;
        first..first + (1 << levels)
    }

    /// [`PointTree::k_nearest_into`] among the points within squared distance `limit`,
    /// offering the points of the leaves `seed` first; returns how many were found.
    fn search(
        &self,
        p: DVec3,
        out: &mut [(f64, u32)],
        seed: std::ops::Range<usize>,
        limit: f64,
    ) -> usize {
        if out.is_empty() {
            return 0;
        }
        let mut near = Nearest {
            found: out,
            len: 0,
            limit,
        };
        if !seed.is_empty() {
            let (a, b) = (
                self.starts[seed.start] as usize,
                self.starts[seed.end] as usize,
            );
            for (q, &i) in self.sorted[a..b].iter().zip(&self.order[a..b]) {
                let d = (*q - p).length_squared();
                if d <= near.bound() {
                    near.offer(d, i);
                }
            }
        }
        let first_leaf = (1usize << self.depth) - 1;
        let mut stack = [(0u32, 0.0f64); STACK];
        stack[0] = (0, box_distance_squared(p, self.boxes[0]));
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let (node, d) = stack[top];
            if d > near.bound() {
                continue;
            }
            let node = node as usize;
            if node >= first_leaf {
                let j = node - first_leaf;
                if seed.contains(&j) {
                    continue;
                }
                let (a, b) = (self.starts[j] as usize, self.starts[j + 1] as usize);
                for (q, &i) in self.sorted[a..b].iter().zip(&self.order[a..b]) {
                    let d = (*q - p).length_squared();
                    if d <= near.bound() {
                        near.offer(d, i);
                    }
                }
                continue;
            }
            let (l, r) = (2 * node + 1, 2 * node + 2);
            let dl = box_distance_squared(p, self.boxes[l]);
            let dr = box_distance_squared(p, self.boxes[r]);
            let ((a, da), (b, db)) = if dl <= dr {
                ((l, dl), (r, dr))
            } else {
                ((r, dr), (l, dl))
            };
            // The nearer child is popped first; a child beyond the bound is not pushed.
            let bound = near.bound();
            if db <= bound {
                stack[top] = (b as u32, db);
                top += 1;
            }
            if da <= bound {
                stack[top] = (a as u32, da);
                top += 1;
            }
        }
        near.len
    }

    fn check_k(&self, k: usize) -> Result<()> {
        if k == 0 || k > self.len() {
            return Err(Error::invalid(
                "k",
                format!(
                    "must be between 1 and the number of points ({}), got {k}",
                    self.len()
                ),
            ));
        }
        Ok(())
    }

    /// The `k` nearest points of each query, nearest first: (indices, distances), each flat,
    /// `k` per query. Errors name the argument: `k` of 0 or above the number of points, a query
    /// that is not finite.
    pub fn k_nearest(&self, queries: &[DVec3], k: usize) -> Result<(Vec<u32>, Vec<f64>)> {
        self.check_k(k)?;
        crate::error::check_finite_points("queries", queries)?;
        let mut idx = vec![0u32; queries.len() * k];
        let mut dist = vec![0.0; queries.len() * k];
        idx.par_chunks_mut(BATCH * k)
            .zip(dist.par_chunks_mut(BATCH * k))
            .zip(queries.par_chunks(BATCH))
            .for_each(|((idx, dist), q)| {
                let mut found = vec![(0.0, 0u32); k];
                for ((p, i), d) in q.iter().zip(idx.chunks_mut(k)).zip(dist.chunks_mut(k)) {
                    self.k_nearest_into(*p, &mut found);
                    for ((f, i), d) in found.iter().zip(i).zip(d) {
                        *i = f.1;
                        *d = f.0.sqrt();
                    }
                }
            });
        crate::cancel::check()?;
        Ok((idx, dist))
    }

    /// For each point of the set in its caller's order, `per_point(neighbours)` with its `k`
    /// nearest points (itself among them, at distance 0), computed in leaf order on rayon's
    /// threads.
    pub fn map_neighbourhoods<T: Send + Sync + Copy + Default>(
        &self,
        k: usize,
        per_point: impl Fn(&[(f64, u32)]) -> T + Sync,
    ) -> Result<Vec<T>> {
        let in_leaf_order =
            self.map_neighbourhoods_in_leaf_order(k, |_, found| per_point(found))?;
        let mut out = vec![T::default(); self.len()];
        out.par_iter_mut()
            .zip(self.positions().par_iter())
            .for_each(|(o, &s)| *o = in_leaf_order[s as usize]);
        Ok(out)
    }

    /// The leaf position of each point of the set, in the caller's order: the point at leaf
    /// position `s` is the caller's `order[s]` ([`PointTree::layout`]).
    pub(crate) fn positions(&self) -> Vec<u32> {
        let mut position = vec![0u32; self.len()];
        for (s, &i) in self.order.iter().enumerate() {
            position[i as usize] = s as u32;
        }
        position
    }

    /// `per_point(s, neighbours)` of the point at each leaf position `s`, with its `k` nearest
    /// points (the caller's indices, itself among them), in leaf order, on rayon's threads.
    /// Reports each batch of points done to the caller's token ([`crate::cancel`]).
    pub(crate) fn map_neighbourhoods_in_leaf_order<T: Send + Sync + Copy + Default>(
        &self,
        k: usize,
        per_point: impl Fn(usize, &[(f64, u32)]) -> T + Sync,
    ) -> Result<Vec<T>> {
        self.check_k(k)?;
        let token = crate::cancel::current();
        let mut in_leaf_order = vec![T::default(); self.len()];
        in_leaf_order
            .par_chunks_mut(BATCH)
            .zip(self.sorted.par_chunks(BATCH))
            .enumerate()
            .try_for_each(|(c, (out, p))| {
                let mut found = vec![(0.0, 0u32); k];
                for (s, (o, p)) in (c * BATCH..).zip(out.iter_mut().zip(p)) {
                    self.search(*p, &mut found, self.seed_leaves(s, k), f64::INFINITY);
                    *o = per_point(s, &found);
                }
                match &token {
                    Some(t) => t.advance(p.len() as u64),
                    None => Ok(()),
                }
            })?;
        crate::cancel::check()?;
        Ok(in_leaf_order)
    }

    /// The `k` nearest points of each point of the set, as [`Self::k_nearest_of_points`] finds
    /// them, without their distances: `k` indices per point, stored in leaf order (4 bytes per
    /// neighbour and one index per point, nothing more).
    pub fn neighbourhoods(&self, k: usize) -> Result<Neighbourhoods> {
        self.check_k(k)?;
        let n = self.len();
        let mut indices = vec![0u32; n * k];
        indices
            .par_chunks_mut(BATCH * k)
            .zip(self.sorted.par_chunks(BATCH))
            .enumerate()
            .for_each(|(c, (idx, q))| {
                let mut found = vec![(0.0, 0u32); k];
                for (s, (p, i)) in (c * BATCH..).zip(q.iter().zip(idx.chunks_mut(k))) {
                    self.search(*p, &mut found, self.seed_leaves(s, k), f64::INFINITY);
                    for (f, i) in found.iter().zip(i) {
                        *i = f.1;
                    }
                }
            });
        crate::cancel::check()?;
        Ok(Neighbourhoods {
            indices,
            position: self.positions(),
            k,
        })
    }

    /// The `k` nearest points of each point of the set (itself first, at distance 0, unless
    /// another point coincides with it and has a smaller index): (indices, distances), flat, `k`
    /// per point, in the caller's order.
    pub fn k_nearest_of_points(&self, k: usize) -> Result<(Vec<u32>, Vec<f64>)> {
        let near = self.neighbourhoods(k)?;
        let n = self.len();
        let mut points = vec![DVec3::ZERO; n];
        for (p, &i) in self.sorted.iter().zip(&self.order) {
            points[i as usize] = *p;
        }
        let mut idx = vec![0u32; n * k];
        let mut dist = vec![0.0; n * k];
        idx.par_chunks_mut(k)
            .zip(dist.par_chunks_mut(k))
            .enumerate()
            .for_each(|(i, (row, d))| {
                row.copy_from_slice(near.of(i));
                for (d, &j) in d.iter_mut().zip(row.iter()) {
                    *d = (points[j as usize] - points[i]).length();
                }
            });
        Ok((idx, dist))
    }
}

/// The `k` nearest points of every point of a set ([`PointTree::neighbourhoods`]).
#[derive(Clone, Debug)]
pub struct Neighbourhoods {
    /// `k` indices per point, nearest first, rows in the tree's leaf order.
    indices: Vec<u32>,
    /// The row of each point, in the caller's order.
    position: Vec<u32>,
    k: usize,
}

impl Neighbourhoods {
    /// The `k` nearest points of point `i` (the caller's index), nearest first: itself first
    /// unless another point coincides with it and has a smaller index.
    pub fn of(&self, i: usize) -> &[u32] {
        let s = self.position[i] as usize * self.k;
        &self.indices[s..s + self.k]
    }

    /// Neighbours per point.
    pub fn k(&self) -> usize {
        self.k
    }
}

/// The eigenvalues of the symmetric 3×3 matrix `a` and its unit eigenvectors (the columns of
/// the second: eigenvector m is `(v[0][m], v[1][m], v[2][m])`), by cyclic Jacobi rotations to
/// convergence.
pub fn symmetric_eigen(a: [[f64; 3]; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
    let mut a = a;
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _sweep in 0..32 {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        let diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
        if off <= 1e-30 * diag || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            // The rotation that zeroes a[p][q] (Golub & Van Loan, the symmetric Schur step).
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = c * akp - s * akq;
                a[k][q] = s * akp + c * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = c * apk - s * aqk;
                a[q][k] = s * apk + c * aqk;
            }
            for k in 0..3 {
                let (vkp, vkq) = (v[k][p], v[k][q]);
                v[k][p] = c * vkp - s * vkq;
                v[k][q] = s * vkp + c * vkq;
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2]], v)
}

/// The unit eigenvector of the symmetric 3×3 matrix `a` with the smallest eigenvalue
/// ([`symmetric_eigen`]). A matrix with a repeated smallest eigenvalue gives one unit vector of
/// that eigenspace.
pub fn smallest_eigenvector(a: [[f64; 3]; 3]) -> DVec3 {
    let (values, v) = symmetric_eigen(a);
    let m = (0..3)
        .min_by(|&i, &j| values[i].total_cmp(&values[j]))
        .unwrap_or(0);
    DVec3::new(v[0][m], v[1][m], v[2][m]).normalize_or(DVec3::Z)
}

/// The normal of a neighbourhood: the smallest eigenvector of its covariance about its mean.
pub fn pca_normal(points: impl Iterator<Item = DVec3> + Clone) -> DVec3 {
    let (sum, n) = points
        .clone()
        .fold((DVec3::ZERO, 0usize), |(s, n), p| (s + p, n + 1));
    if n == 0 {
        return DVec3::Z;
    }
    let mean = sum / n as f64;
    let mut c = [[0.0; 3]; 3];
    for p in points {
        let d = p - mean;
        for i in 0..3 {
            for j in i..3 {
                c[i][j] += d[i] * d[j];
            }
        }
    }
    c[1][0] = c[0][1];
    c[2][0] = c[0][2];
    c[2][1] = c[1][2];
    smallest_eigenvector(c)
}

/// Unoriented unit normals of `points` by principal component analysis: for each point, the
/// smallest eigenvector of the covariance of its `k` nearest points (itself included). Their
/// sign is arbitrary. Errors name the argument: a point that is not finite, `k` below 3 or above
/// the number of points.
pub fn pca_normals(points: &[DVec3], k: usize) -> Result<Vec<DVec3>> {
    if k < 3 {
        return Err(Error::invalid("k", format!("must be at least 3, got {k}")));
    }
    let tree = PointTree::new(points)?;
    tree.map_neighbourhoods(k, |found| {
        pca_normal(found.iter().map(|&(_, j)| points[j as usize]))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{fibonacci_sphere, random_points};

    fn brute(points: &[DVec3], p: DVec3, k: usize) -> Vec<(f64, u32)> {
        let mut all: Vec<(f64, u32)> = points
            .iter()
            .enumerate()
            .map(|(j, q)| ((*q - p).length_squared(), j as u32))
            .collect();
        all.sort_by(|a, b| a.partial_cmp(b).unwrap());
        all.truncate(k);
        all
    }

    #[test]
    fn k_nearest_agrees_with_brute_force() {
        for (n, seed) in [(1, 1), (7, 2), (9, 3), (1000, 4), (5000, 5)] {
            let pts = random_points(n, -1.0, 1.0, seed);
            let tree = PointTree::new(&pts).unwrap();
            let queries = random_points(200, -1.3, 1.3, seed + 20);
            for k in [1, 5, 20] {
                let k = k.min(n);
                let (idx, dist) = tree.k_nearest(&queries, k).unwrap();
                for (q, (i, d)) in queries.iter().zip(idx.chunks(k).zip(dist.chunks(k))) {
                    let b = brute(&pts, *q, k);
                    assert_eq!(i, b.iter().map(|x| x.1).collect::<Vec<_>>());
                    for (d, b) in d.iter().zip(&b) {
                        assert!((d - b.0.sqrt()).abs() < 1e-15);
                    }
                }
            }
        }
    }

    #[test]
    fn nearest_within_a_radius_is_the_nearest_or_none() {
        let pts = fibonacci_sphere(3_000);
        let tree = PointTree::new(&pts).unwrap();
        for (i, q) in random_points(2_000, -1.5, 1.5, 9).into_iter().enumerate() {
            let radius = 0.02 + 0.3 * (i % 7) as f64 / 7.0;
            let (d2, j) = brute(&pts, q, 1)[0];
            match tree.nearest_within(q, radius) {
                Some((d, k)) => {
                    assert!(d <= radius);
                    assert_eq!((d, k), (d2.sqrt(), j));
                }
                None => assert!(d2.sqrt() > radius),
            }
        }
    }

    #[test]
    fn k_nearest_of_points_finds_each_point_first_in_the_callers_order() {
        // Points on a surface (a sphere), where a grid of the bounding box would be mostly empty,
        // plus exact duplicates.
        let mut pts: Vec<DVec3> = fibonacci_sphere(3000);
        pts.extend_from_within(..50);
        let tree = PointTree::new(&pts).unwrap();
        let k = 12;
        let (idx, dist) = tree.k_nearest_of_points(k).unwrap();
        for (i, p) in pts.iter().enumerate() {
            let b = brute(&pts, *p, k);
            assert_eq!(
                &idx[i * k..(i + 1) * k],
                b.iter().map(|x| x.1).collect::<Vec<_>>()
            );
            assert_eq!(dist[i * k], 0.0);
        }
        let near = tree.neighbourhoods(k).unwrap();
        for i in 0..pts.len() {
            assert_eq!(near.of(i), &idx[i * k..(i + 1) * k]);
        }
        // The duplicates: the smaller index of the two comes first.
        assert_eq!(idx[3000 * k], 0);
        assert_eq!(idx[3000 * k + 1], 3000);
    }

    #[test]
    fn bad_k_and_points_are_refused_naming_the_argument() {
        let pts = random_points(10, -1.0, 1.0, 1);
        let tree = PointTree::new(&pts).unwrap();
        for k in [0, 11] {
            assert!(matches!(
                tree.k_nearest(&pts, k),
                Err(Error::InvalidArgument { name: "k", .. })
            ));
        }
        assert!(matches!(
            pca_normals(&pts, 2),
            Err(Error::InvalidArgument { name: "k", .. })
        ));
        let mut bad = pts.clone();
        bad[4].y = f64::INFINITY;
        assert!(matches!(
            PointTree::new(&bad),
            Err(Error::NotFinite {
                name: "points",
                index: 4
            })
        ));
        assert!(matches!(
            tree.k_nearest(&bad, 3),
            Err(Error::NotFinite {
                name: "queries",
                index: 4
            })
        ));
        assert!(PointTree::new(&[]).unwrap().is_empty());
    }

    #[test]
    fn pca_normals_of_a_plane_and_a_sphere() {
        // A tilted plane: every normal is the plane's, up to sign.
        let n = DVec3::new(1.0, -2.0, 0.5).normalize();
        let u = n.any_orthonormal_vector();
        let w = n.cross(u);
        let pts: Vec<DVec3> = random_points(2000, -1.0, 1.0, 3)
            .iter()
            .map(|p| u * p.x + w * p.y + DVec3::new(0.3, 0.1, -0.2))
            .collect();
        for m in pca_normals(&pts, 20).unwrap() {
            assert!((m.length() - 1.0).abs() < 1e-12);
            assert!(m.dot(n).abs() > 1.0 - 1e-10);
        }
        // A dense sphere: normals are radial to within the neighbourhood's curvature.
        let pts = fibonacci_sphere(20000);
        for (m, p) in pca_normals(&pts, 20).unwrap().iter().zip(&pts) {
            assert!(m.dot(*p).abs() > 0.999);
        }
    }

    #[test]
    fn smallest_eigenvector_of_known_matrices() {
        // Diagonal, and a rotated diagonal with eigenvalues 3, 2, 0.5.
        assert_eq!(
            smallest_eigenvector([[3.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 2.0]]).abs(),
            DVec3::Y
        );
        let r =
            glam::DMat3::from_quat(glam::DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 0.7));
        let a = r * glam::DMat3::from_diagonal(DVec3::new(3.0, 2.0, 0.5)) * r.transpose();
        let m = [0, 1, 2].map(|i| [0, 1, 2].map(|j| a.col(j)[i]));
        let v = smallest_eigenvector(m);
        assert!(v.dot(r.col(2)).abs() > 1.0 - 1e-12);
        // The zero matrix (coincident points): some unit vector.
        assert!((smallest_eigenvector([[0.0; 3]; 3]).length() - 1.0).abs() < 1e-12);
    }
}
