//! The generalized winding number of oriented points (Barill et al. 2018, "Fast winding numbers
//! for soups and clouds"): each point `p_i` with unit normal `n_i` and area `a_i` is a small
//! oriented disc, and
//!
//! ```text
//! w(q) = Σ_i a_i (p_i − q)·n_i / (4π |p_i − q|³)
//! ```
//!
//! is close to 1 inside the surface the points sample and close to 0 outside, also across holes
//! in the sampling, and with a minority of wrong normals or stray points. It is smooth away from
//! the points.
//!
//! The sum is evaluated by Barnes–Hut over a [`PointTree`]: a node whose points all lie within
//! `r` of their area-weighted centre `c` is summed as one dipole `Σ a_i n_i` at `c` when
//! `|q − c| > ACCEPT · r`, and its points one by one otherwise. Every distance is regularised,
//! |p − q|² + ε², with ε a fraction of the points' spacing, so that the sum stays finite at the
//! points themselves.

use crate::error::Result;
use crate::knn::PointTree;
use glam::DVec3;

/// A node is summed as one dipole when the query is farther than `ACCEPT` times the node's
/// radius from its centre: the dipole's relative error is then at most about 1/ACCEPT².
pub const ACCEPT: f64 = 3.0;

/// The traversal stack's depth: more than the tree's depth for 2³² points.
const STACK: usize = 40;

/// The winding number of a set of oriented points (see the module's documentation).
pub struct WindingNumber {
    /// The points in the tree's leaf order.
    points: Vec<DVec3>,
    /// `a_i n_i` of each point, in leaf order.
    dipoles: Vec<DVec3>,
    /// The leaves' ranges: leaf `j` holds `starts[j]..starts[j + 1]`.
    starts: Vec<u32>,
    /// The leaves' depth; node `i` has children `2i + 1`, `2i + 2`.
    depth: u32,
    /// Per node: area-weighted centre, summed dipole, squared acceptance radius (`ACCEPT · r`)².
    nodes: Vec<Node>,
    /// The squared regularisation length ε².
    eps2: f64,
}

#[derive(Clone, Copy, Debug, Default)]
struct Node {
    centre: DVec3,
    dipole: DVec3,
    accept2: f64,
}

/// The contribution of one dipole `d` at `p` to the value and gradient at `q`, with `ε²`.
#[inline(always)]
fn dipole_at(p: DVec3, d: DVec3, q: DVec3, eps2: f64) -> (f64, DVec3) {
    let r = p - q;
    let rho2 = r.length_squared() + eps2;
    let inv = 1.0 / rho2;
    let inv3 = inv * inv.sqrt();
    let rd = r.dot(d);
    // ∂/∂q of r·d/ρ³ with r = p − q: −d/ρ³ + 3 (r·d) r/ρ⁵.
    (rd * inv3, (3.0 * rd * inv) * inv3 * r - d * inv3)
}

impl WindingNumber {
    /// The winding number of `points` with unit `normals` and `areas` (all of one length), over
    /// `tree` (built on the same points), with regularisation length `eps`.
    pub fn new(
        tree: &PointTree,
        points: &[DVec3],
        normals: &[DVec3],
        areas: &[f64],
        eps: f64,
    ) -> Result<WindingNumber> {
        let (sorted, order, starts, depth) = tree.layout();
        debug_assert_eq!(sorted.len(), points.len());
        let dipoles: Vec<DVec3> = order
            .iter()
            .map(|&i| normals[i as usize] * areas[i as usize])
            .collect();
        let weight: Vec<f64> = order.iter().map(|&i| areas[i as usize]).collect();
        let leaves = 1usize << depth;
        let first_leaf = leaves - 1;
        let mut nodes = vec![Node::default(); 2 * leaves - 1];
        // Area and radius per node, bottom-up; the radius bounds every point's distance from the
        // node's centre.
        let mut area = vec![0.0f64; nodes.len()];
        let mut radius = vec![0.0f64; nodes.len()];
        for j in 0..leaves {
            let (a, b) = (starts[j] as usize, starts[j + 1] as usize);
            let node = first_leaf + j;
            let (mut c, mut d, mut w) = (DVec3::ZERO, DVec3::ZERO, 0.0);
            for s in a..b {
                c += sorted[s] * weight[s];
                d += dipoles[s];
                w += weight[s];
            }
            let centre = if w > 0.0 {
                c / w
            } else if b > a {
                sorted[a..b].iter().copied().sum::<DVec3>() / (b - a) as f64
            } else {
                DVec3::ZERO
            };
            let r = sorted[a..b]
                .iter()
                .map(|p| (*p - centre).length())
                .fold(0.0, f64::max);
            nodes[node].centre = centre;
            nodes[node].dipole = d;
            area[node] = w;
            radius[node] = r;
        }
        for node in (0..first_leaf).rev() {
            let (l, r) = (2 * node + 1, 2 * node + 2);
            let w = area[l] + area[r];
            let centre = if w > 0.0 {
                (nodes[l].centre * area[l] + nodes[r].centre * area[r]) / w
            } else {
                (nodes[l].centre + nodes[r].centre) * 0.5
            };
            let reach = |c: usize| {
                if starts_empty(starts, depth, c) {
                    0.0
                } else {
                    (nodes[c].centre - centre).length() + radius[c]
                }
            };
            let r_node = reach(l).max(reach(r));
            nodes[node].centre = centre;
            nodes[node].dipole = nodes[l].dipole + nodes[r].dipole;
            area[node] = w;
            radius[node] = r_node;
        }
        for (c, (n, r)) in nodes.iter_mut().zip(&radius).enumerate() {
            // An empty node is always accepted, and its zero dipole skipped.
            n.accept2 = if starts_empty(starts, depth, c) {
                -1.0
            } else {
                (ACCEPT * r) * (ACCEPT * r)
            };
        }
        Ok(WindingNumber {
            points: sorted.to_vec(),
            dipoles,
            starts: starts.to_vec(),
            depth,
            nodes,
            eps2: eps * eps,
        })
    }

    /// The winding number at `q`.
    pub fn value(&self, q: DVec3) -> f64 {
        self.value_gradient(q).0
    }

    /// The winding number and its gradient at `q`.
    pub fn value_gradient(&self, q: DVec3) -> (f64, DVec3) {
        let first_leaf = (1usize << self.depth) - 1;
        let (mut w, mut g) = (0.0, DVec3::ZERO);
        let mut stack = [0u32; STACK];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = stack[top] as usize;
            let n = &self.nodes[node];
            if (n.centre - q).length_squared() > n.accept2 {
                if n.dipole == DVec3::ZERO {
                    continue;
                }
                let (v, d) = dipole_at(n.centre, n.dipole, q, self.eps2);
                w += v;
                g += d;
            } else if node >= first_leaf {
                let j = node - first_leaf;
                let (a, b) = (self.starts[j] as usize, self.starts[j + 1] as usize);
                for (p, d) in self.points[a..b].iter().zip(&self.dipoles[a..b]) {
                    let (v, dg) = dipole_at(*p, *d, q, self.eps2);
                    w += v;
                    g += dg;
                }
            } else {
                stack[top] = (2 * node + 1) as u32;
                stack[top + 1] = (2 * node + 2) as u32;
                top += 2;
            }
        }
        let s = 1.0 / (4.0 * std::f64::consts::PI);
        (w * s, g * s)
    }
}

/// Whether node `c` of a tree of leaves at `depth` with `starts` holds no point.
fn starts_empty(starts: &[u32], depth: u32, c: usize) -> bool {
    // The leaves under node c at level L (c in 2^L − 1 .. 2^(L+1) − 1) are a contiguous range.
    let level = usize::BITS - 1 - (c + 1).leading_zeros();
    let first = (c + 1 - (1usize << level)) << (depth - level);
    let count = 1usize << (depth - level);
    starts[first] == starts[first + count]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::fibonacci_sphere;

    /// Points on a unit sphere with outward normals and equal areas summing to 4π.
    fn sphere(n: usize) -> (Vec<DVec3>, Vec<DVec3>, Vec<f64>) {
        let p = fibonacci_sphere(n);
        let a = vec![4.0 * std::f64::consts::PI / n as f64; n];
        (p.clone(), p, a)
    }

    fn brute(p: &[DVec3], n: &[DVec3], a: &[f64], q: DVec3, eps2: f64) -> (f64, DVec3) {
        let (mut w, mut g) = (0.0, DVec3::ZERO);
        for i in 0..p.len() {
            let (v, d) = dipole_at(p[i], n[i] * a[i], q, eps2);
            w += v;
            g += d;
        }
        let s = 1.0 / (4.0 * std::f64::consts::PI);
        (w * s, g * s)
    }

    #[test]
    fn one_inside_and_zero_outside_a_sampled_sphere() {
        let (p, n, a) = sphere(20_000);
        let tree = PointTree::new(&p).unwrap();
        let wn = WindingNumber::new(&tree, &p, &n, &a, 0.0).unwrap();
        for q in [
            DVec3::ZERO,
            DVec3::new(0.3, -0.2, 0.5),
            DVec3::new(0.0, 0.0, 0.8),
        ] {
            assert!(
                (wn.value(q) - 1.0).abs() < 0.02,
                "inside {q}: {}",
                wn.value(q)
            );
        }
        for q in [
            DVec3::new(1.5, 0.0, 0.0),
            DVec3::new(2.0, 2.0, -1.0),
            DVec3::splat(10.0),
        ] {
            assert!(wn.value(q).abs() < 0.02, "outside {q}: {}", wn.value(q));
        }
    }

    #[test]
    fn barnes_hut_is_close_to_the_direct_sum_and_its_gradient_to_differences() {
        let (p, n, a) = sphere(3_000);
        let tree = PointTree::new(&p).unwrap();
        let eps = 0.02;
        let wn = WindingNumber::new(&tree, &p, &n, &a, eps).unwrap();
        // Queries a few spacings (about 0.065) or more from the points, where the guard reads
        // the winding number.
        let queries = crate::testing::random_points(600, -2.0, 2.0, 5);
        for q in queries
            .into_iter()
            .filter(|q| (q.length() - 1.0).abs() > 0.2)
        {
            let (w, g) = wn.value_gradient(q);
            let (wb, gb) = brute(&p, &n, &a, q, eps * eps);
            assert!((w - wb).abs() < 0.02, "{q}: {w} against {wb}");
            // The dipoles' first-order expansion bounds the gradient's error more loosely.
            assert!(
                (g - gb).length() < 0.1 * (1.0 + gb.length()),
                "{q}: {g} against {gb}"
            );
            let h = 1e-5;
            let fd = DVec3::new(
                wn.value(q + DVec3::X * h) - wn.value(q - DVec3::X * h),
                wn.value(q + DVec3::Y * h) - wn.value(q - DVec3::Y * h),
                wn.value(q + DVec3::Z * h) - wn.value(q - DVec3::Z * h),
            ) / (2.0 * h);
            // Away from a change of the traversal, the gradient is the sum's own derivative.
            assert!(
                (fd - g).length() < 1e-4 * (1.0 + g.length()),
                "{q}: {g} against {fd}"
            );
        }
    }

    #[test]
    fn a_hole_in_the_sampling_stays_inside() {
        // The sphere without its cap z > 0.6: the winding number still tells the centre inside
        // and a point above the hole outside.
        let (p, n, a) = sphere(20_000);
        let keep: Vec<usize> = (0..p.len()).filter(|&i| p[i].z < 0.6).collect();
        let p: Vec<DVec3> = keep.iter().map(|&i| p[i]).collect();
        let n: Vec<DVec3> = keep.iter().map(|&i| n[i]).collect();
        let a: Vec<f64> = keep.iter().map(|&i| a[i]).collect();
        let tree = PointTree::new(&p).unwrap();
        let wn = WindingNumber::new(&tree, &p, &n, &a, 0.0).unwrap();
        assert!(wn.value(DVec3::ZERO) > 0.8);
        assert!(wn.value(DVec3::new(0.0, 0.0, 1.5)) < 0.2);
    }
}
