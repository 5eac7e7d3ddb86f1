//! The patches of leaves whose support holds no constraint, for fits with normal constraints:
//! a plane that carries the sign of space there, instead of an interpolant of far constraints.
//!
//! Such a patch has zero weight at every constraint, so it cannot change the interpolation; it
//! only decides the sign of f away from the data. An interpolant of constraints gathered from
//! further away extrapolates over the whole support, and where the data on one side is a thin
//! part (a leg under a table) it turns negative far outside the body: spurious components. The
//! plane is f_e(x) = σ ρ (x − q)·u, with q the data point nearest to the patch's centre c,
//! u = (c − q)/|c − q|, ρ = |w_q/d_q| (the slope of q's normal constraint) and σ the side of the
//! surface c is on: the sign of Σ_j sign(w_j) (c − q_j)·n_j / |c − q_j| over the [`NEAREST`] data
//! points nearest to c. Every point of the support is further than its radius from q along u, so
//! f_e has the sign σ throughout, and grows with the distance from the data as the fitted field
//! does. (On the support, (x − q)·u ≥ |c − q| − R > 0, since q lies outside it.)

use super::octree::Octree;
use crate::field::rbf::constraints::Constraints;
use glam::DVec3;

/// Data points that vote on the side of the surface a patch is on.
pub const NEAREST: usize = 8;

/// Points a plane patch interpolates.
pub const PLANE_POINTS: usize = 5;

/// Whether `c` holds normal constraints: data points `0..boundary`, then their normal
/// constraints ([`Constraints::normal_of`]), with the data points' offsets.
pub fn oriented(c: &Constraints) -> bool {
    c.boundary > 0
        && c.offsets.len() == c.boundary
        && !c.normal_of.is_empty()
        && c.points.len() >= c.boundary + c.normal_of.len()
}

/// For each data point of `c`, the position of its normal constraint among the normal
/// constraints (`u32::MAX` for those without one).
pub fn normal_slots(c: &Constraints) -> Vec<u32> {
    let mut slot = vec![u32::MAX; c.boundary];
    for (k, &j) in c.normal_of.iter().enumerate() {
        slot[j as usize] = k as u32;
    }
    slot
}

/// The points and values, a linear function of position, whose interpolant (with a linear
/// polynomial) is the plane of the empty patch around `centre` with support `radius`. `c` must
/// be [`oriented`] (its points are not read: they are read from the copy of `tree`, its octree,
/// which must have one, through `rank`, the position of each constraint in the tree's order),
/// `slots` its [`normal_slots`]. The data points that vote are those with a normal constraint.
pub fn plane(
    c: &Constraints,
    slots: &[u32],
    tree: &Octree,
    rank: &[u32],
    centre: DVec3,
    radius: f64,
) -> (Vec<DVec3>, Vec<f64>) {
    assert!(
        tree.has_copy(),
        "the octree reads its own copy of the points"
    );
    let point = |j: usize| tree.point_at(rank[j] as usize);
    let b = c.boundary;
    let normals = c.normal_of.len();
    // The 2 NEAREST nearest constraints hold about NEAREST data points with normal constraints
    // when every data point has one (a normal constraint lies near its data point); more where
    // inner constraints crowd them out or only some data points have one.
    let mut k = 2 * NEAREST;
    let mut data: Vec<usize> = Vec::with_capacity(k);
    while data.is_empty() {
        k = k.min(c.values.len());
        let reach = tree.kth_nearest_distance(&[], centre, k);
        tree.for_each_within(&[], centre, reach, |i| {
            let i = i as usize;
            if i < b && slots[i] != u32::MAX {
                data.push(i);
            } else if (b..b + normals).contains(&i) {
                data.push(c.normal_of[i - b] as usize);
            }
        });
        k *= 2;
    }
    let distance = |j: usize| (point(j) - centre).length();
    data.sort_unstable_by(|&a, &e| distance(a).total_cmp(&distance(e)).then(a.cmp(&e)));
    data.dedup();
    data.truncate(NEAREST);
    let nearest = data[0];
    let normal = |j: usize| b + slots[j] as usize;
    let slope = |j: usize| c.values[normal(j)] / c.offsets[j];
    let vote: f64 = data
        .iter()
        .map(|&j| {
            let (q, n) = (point(j), (point(normal(j)) - point(j)).normalize_or_zero());
            slope(j).signum() * (centre - q).normalize_or_zero().dot(n)
        })
        .sum();
    let side = if vote < 0.0 { -1.0 } else { 1.0 };
    let q = point(nearest);
    let u = (centre - q).normalize_or_zero();
    let gradient = u * (side * slope(nearest).abs());
    // A tetrahedron around the centre and the centre: the interpolant of linear values at
    // five points in general position is that linear function.
    let h = 0.5 * radius / 3f64.sqrt();
    let points: Vec<DVec3> = [
        DVec3::ZERO,
        DVec3::new(1.0, 1.0, 1.0),
        DVec3::new(1.0, -1.0, -1.0),
        DVec3::new(-1.0, 1.0, -1.0),
        DVec3::new(-1.0, -1.0, 1.0),
    ]
    .iter()
    .map(|t| centre + *t * h)
    .collect();
    let values = points.iter().map(|x| gradient.dot(*x - q)).collect();
    (points, values)
}
