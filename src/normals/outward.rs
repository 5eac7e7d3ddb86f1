//! Step 4: every body (a set of points whose normals the graph made consistent) turned
//! outward.
//!
//! - The mean over the body's points of the winding number of all points ([`WindingNumber`])
//!   is close to ½ on a closed surface whose normals point out and to −½ when they point in,
//!   whatever its shape; a body whose mean is beyond ±[`CLOSED`] is closed, and turns when
//!   the mean is negative — unless its viewpoints are inside it (a room scanned from within:
//!   the winding number's magnitude at them above ½), where it faces them as open bodies do.
//! - An open body (a terrain, a wall) with viewpoints faces them: its normals turn when the
//!   sum over its points of the cosine between the normal and the direction to the point's
//!   viewpoint is negative.
//! - An open body without viewpoints faces up (+z): its normals turn when their
//!   area-weighted z components sum to less than zero.
//!
//! The winding number is built on at most [`SAMPLE`] points (every `m`-th in leaf order, with
//! `m` times their area) and evaluated at up to [`PER_BODY`] points of each body.

use super::local::Local;
use crate::error::Result;
use crate::field::scan::WindingNumber;
use crate::knn::PointTree;
use glam::DVec3;
use rayon::prelude::*;

/// A body whose mean winding number lies within ± this is open.
pub const CLOSED: f64 = 0.15;
/// Most points the winding number is built on.
pub const SAMPLE: usize = 400_000;
/// Most points of a body the winding number is evaluated at.
pub const PER_BODY: usize = 2048;

/// Where the sensors were, for orienting open bodies.
#[derive(Clone, Copy, Debug)]
pub enum Viewpoints<'a> {
    /// Not known.
    None,
    /// One viewpoint for all points.
    One(DVec3),
    /// One per point, in the caller's order.
    PerPoint(&'a [DVec3]),
}

/// The area a point stands for: the disc through its farthest graph neighbour shared among
/// the neighbours.
pub fn area(local: &Local) -> f64 {
    let n = local.neighbours().count().max(1) as f64;
    std::f64::consts::PI * local.reach * local.reach / n
}

/// Whether each body (`body`: each point's body id, dense from 0, `count` of them) turns, from
/// `points` and `normals` in leaf order; `view(s)` is the viewpoint of the point at leaf
/// position `s`, if any.
pub fn outward(
    points: &[DVec3],
    normals: &[DVec3],
    local: &[Local],
    body: &[u32],
    count: usize,
    view: impl Fn(usize) -> Option<DVec3> + Sync,
) -> Result<Vec<bool>> {
    let n = points.len();
    // Toward the viewpoints, where known.
    let mut toward = vec![0.0; count];
    let mut seen = vec![false; count];
    for s in 0..n {
        if let Some(v) = view(s) {
            let d = (v - points[s]).normalize_or_zero();
            toward[body[s] as usize] += d.dot(normals[s]);
            seen[body[s] as usize] = true;
        }
    }
    // The winding number at up to PER_BODY points of every body, and at their viewpoints.
    let mut size = vec![0usize; count];
    for &b in body {
        size[b as usize] += 1;
    }
    let mut rank = vec![0usize; count];
    let probes: Vec<usize> = (0..n)
        .filter(|&s| {
            let b = body[s] as usize;
            let r = rank[b];
            rank[b] += 1;
            r.is_multiple_of(size[b].div_ceil(PER_BODY))
        })
        .collect();
    let mut mean = vec![0.0; count];
    let mut at_views = vec![0.0; count];
    let winding = sampled_winding(points, normals, local)?;
    let w: Vec<(f64, f64)> = probes
        .par_iter()
        .map(|&s| {
            let v = view(s).map_or(0.0, |v| winding.value(v).abs());
            (winding.value(points[s]), v)
        })
        .collect();
    let mut probed = vec![0usize; count];
    for (&s, (w, v)) in probes.iter().zip(&w) {
        mean[body[s] as usize] += w;
        at_views[body[s] as usize] += v;
        probed[body[s] as usize] += 1;
    }
    for ((m, v), &p) in mean.iter_mut().zip(&mut at_views).zip(&probed) {
        *m /= p.max(1) as f64;
        *v /= p.max(1) as f64;
    }
    let mut up = vec![0.0; count];
    for s in 0..n {
        up[body[s] as usize] += area(&local[s]) * normals[s].z;
    }
    Ok((0..count)
        .map(|b| {
            let closed = mean[b].abs() >= CLOSED;
            if seen[b] && !(closed && at_views[b] < 0.5) {
                toward[b] < 0.0
            } else if closed {
                mean[b] < 0.0
            } else {
                up[b] < 0.0
            }
        })
        .collect())
}

/// The winding number of every `m`-th point (leaf order), `m` the least that keeps at most
/// [`SAMPLE`] points, each standing for `m` times its area.
fn sampled_winding(points: &[DVec3], normals: &[DVec3], local: &[Local]) -> Result<WindingNumber> {
    let m = points.len().div_ceil(SAMPLE).max(1);
    let keep: Vec<usize> = (0..points.len()).step_by(m).collect();
    let p: Vec<DVec3> = keep.iter().map(|&s| points[s]).collect();
    let n: Vec<DVec3> = keep.iter().map(|&s| normals[s]).collect();
    let a: Vec<f64> = keep.iter().map(|&s| area(&local[s]) * m as f64).collect();
    let mut reach: Vec<f64> = keep.iter().map(|&s| local[s].reach).collect();
    let mid = reach.len() / 2;
    let spacing = *reach.select_nth_unstable_by(mid, f64::total_cmp).1 * (m as f64).sqrt();
    let tree = PointTree::new(&p)?;
    WindingNumber::new(&tree, &p, &n, &a, 0.5 * spacing)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::normals::local::local_planes;
    use crate::testing::fibonacci_sphere;

    fn sphere_and_plane(inward: bool) -> (Vec<DVec3>, Vec<DVec3>, Vec<Local>, Vec<u32>) {
        let mut pts = fibonacci_sphere(4000);
        for i in 0..40 {
            for j in 0..40 {
                pts.push(DVec3::new(3.0 + i as f64 * 0.05, j as f64 * 0.05, 0.0));
            }
        }
        let tree = PointTree::new(&pts).unwrap();
        let local = local_planes(&tree, &tree.positions(), 12).unwrap();
        let (sorted, ..) = tree.layout();
        let body: Vec<u32> = sorted.iter().map(|p| u32::from(p.x > 2.0)).collect();
        let normals = sorted
            .iter()
            .map(|p| match (p.x > 2.0, inward) {
                (true, _) => -DVec3::Z,
                (false, false) => p.normalize(),
                (false, true) => -p.normalize(),
            })
            .collect();
        (sorted.to_vec(), normals, local, body)
    }

    #[test]
    fn a_closed_body_turns_outward_and_an_open_one_up() {
        for inward in [false, true] {
            let (p, n, l, b) = sphere_and_plane(inward);
            let turn = outward(&p, &n, &l, &b, 2, |_| None).unwrap();
            assert_eq!(turn, vec![inward, true]);
        }
    }

    #[test]
    fn viewpoints_decide_where_given() {
        let (p, n, l, b) = sphere_and_plane(false);
        // A viewpoint below the plane, and one inside the sphere (a room seen from within).
        let turn = outward(&p, &n, &l, &b, 2, |s| {
            Some(if p[s].x > 2.0 {
                DVec3::new(4.0, 1.0, -5.0)
            } else {
                DVec3::ZERO
            })
        })
        .unwrap();
        assert_eq!(turn, vec![true, false]);
        // One viewpoint above both, outside the closed sphere, which it sees half of: the
        // sphere outward still, the plane up.
        let (p, n, l, b) = sphere_and_plane(true);
        let turn = outward(&p, &n, &l, &b, 2, |_| Some(DVec3::new(0.0, 0.0, 5.0))).unwrap();
        assert_eq!(turn, vec![true, true]);
    }
}
