//! Inner constraints in thin parts of a body: where a data point `q_i` has another sheet of the
//! surface behind it (an opposite-facing data point at depth `t_i` along `−n_i`, nearer than
//! the reach), a constraint at the middle, `q_i − (t_i/2) n_i`, with value `−(w/d) t_i/2`.
//!
//! Cuno's normal constraints all lie outside the body. Inside a leg or a plate a few offsets
//! thick, the fit then has nothing that holds f below zero between the data points, and f turns
//! positive there: the part breaks or gets holes (extra components, handles). The middle is
//! `t_i/2` from both sheets where they are parallel (and on the axis of a round leg), so the
//! value's magnitude stays below the distance to the surface, as the normal constraints' does.

use crate::spatial::Grid;
use glam::DVec3;
use rayon::prelude::*;

/// Depth `t_i` of the nearest other sheet behind each point (`INFINITY` where there is none
/// within `reach`): the smallest `(q_i − q_j)·n_i > 0` over the points `q_j` within `reach` of
/// `q_i` whose normal faces the other way (`n_j·n_i < facing_cos`) and whose offset across the
/// normal is below that depth. `normals` are unit vectors.
pub fn depths_behind(points: &[DVec3], normals: &[DVec3], reach: f64, facing_cos: f64) -> Vec<f64> {
    let grid = Grid::new(points, reach);
    (0..points.len())
        .into_par_iter()
        .map(|i| {
            let (q, n) = (points[i], normals[i]);
            let mut depth = f64::INFINITY;
            grid.for_each_within(q, reach, |j| {
                let j = j as usize;
                if j == i || normals[j].dot(n) >= facing_cos {
                    return;
                }
                let v = q - points[j];
                let t = v.dot(n);
                if t > 0.0 && t < depth && (v - n * t).length() < t {
                    depth = t;
                }
            });
            depth
        })
        .collect()
}

/// The points that get an inner constraint, increasing: those with a finite depth whose middle
/// `c_i = q_i − (t_i/2) n_i` has no data point nearer than `t_i/4` and no middle of a point
/// `j < i` nearer than `min(t_i, t_j)/4` (two points facing each other across a leg share one
/// middle; one constraint there is enough and two would make the system singular).
pub fn inner_points(points: &[DVec3], normals: &[DVec3], depths: &[f64]) -> Vec<usize> {
    let candidates: Vec<usize> = (0..points.len())
        .filter(|&i| depths[i].is_finite())
        .collect();
    if candidates.is_empty() {
        return candidates;
    }
    let middle = |i: usize| points[i] - normals[i] * (0.5 * depths[i]);
    let middles: Vec<DVec3> = candidates.iter().map(|&i| middle(i)).collect();
    let largest = candidates.iter().map(|&i| depths[i]).fold(0.0, f64::max);
    let data = Grid::new(points, 0.25 * largest);
    let others = Grid::new(&middles, 0.25 * largest);
    let keep: Vec<bool> = (0..candidates.len())
        .into_par_iter()
        .map(|a| {
            let i = candidates[a];
            let c = middles[a];
            let r = 0.25 * depths[i];
            let crowded = data.any_within(c, r, |_, q| (q - c).length() < r)
                || others.any_within(c, r, |b, m| {
                    let j = candidates[b as usize];
                    j < i && (m - c).length() < 0.25 * depths[i].min(depths[j])
                });
            !crowded
        })
        .collect();
    candidates
        .into_iter()
        .zip(keep)
        .filter_map(|(i, k)| k.then_some(i))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on a cylinder of radius `r` along z with outward normals.
    fn cylinder(r: f64, rings: usize, around: usize) -> (Vec<DVec3>, Vec<DVec3>) {
        let mut p = Vec::new();
        let mut n = Vec::new();
        for k in 0..rings {
            for a in 0..around {
                let phi = std::f64::consts::TAU * (a as f64 + 0.5 * (k % 2) as f64) / around as f64;
                let dir = DVec3::new(phi.cos(), phi.sin(), 0.0);
                p.push(dir * r + DVec3::Z * (0.02 * k as f64));
                n.push(dir);
            }
        }
        (p, n)
    }

    #[test]
    fn a_thin_leg_gets_inner_constraints_near_its_axis() {
        let (p, n) = cylinder(0.02, 10, 8);
        let t = depths_behind(&p, &n, 0.09, -0.5);
        // The opposite point of the ring or one up to 45° from it (nearer, and facing enough).
        assert!(t.iter().all(|t| (0.03..=0.04 + 1e-12).contains(t)), "{t:?}");
        let keep = inner_points(&p, &n, &t);
        assert!(keep.len() >= 10, "{}", keep.len());
        let middles: Vec<DVec3> = keep.iter().map(|&i| p[i] - n[i] * (0.5 * t[i])).collect();
        for (a, c) in middles.iter().enumerate() {
            assert!(c.truncate().length() < 0.005, "middle off the axis");
            for (b, e) in middles.iter().enumerate().take(a) {
                let (i, j) = (keep[a], keep[b]);
                assert!((*c - *e).length() >= 0.25 * t[i].min(t[j]), "{i} {j}");
            }
        }
    }

    #[test]
    fn a_thick_body_gets_none() {
        let (p, n) = cylinder(0.2, 10, 40);
        let t = depths_behind(&p, &n, 0.09, -0.5);
        assert!(t.iter().all(|t| t.is_infinite()));
        assert!(inner_points(&p, &n, &t).is_empty());
    }
}
