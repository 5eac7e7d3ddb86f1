//! Step 1: the local plane of every point. Principal component analysis of each point's `k`
//! nearest neighbours (itself included) gives an unoriented normal; the [`GRAPH`] nearest of
//! them (itself left out) are kept as the point's edges of the neighbour graph the later steps
//! walk, with the distance to the farthest of them, which measures the local spacing. Everything
//! is in the [`PointTree`]'s leaf order, so that neighbours are near in memory too.

use crate::error::Result;
use crate::knn::{pca_normal, PointTree};
use glam::DVec3;

/// Edges of the neighbour graph per point.
pub const GRAPH: usize = 12;

/// No neighbour (a point with fewer than [`GRAPH`] others).
pub const NONE: u32 = u32::MAX;

/// What the local step knows of one point.
#[derive(Clone, Copy, Debug)]
pub struct Local {
    /// The unit normal of the neighbourhood's plane, sign arbitrary.
    pub normal: DVec3,
    /// The leaf positions of the point's [`GRAPH`] nearest neighbours, nearest first; [`NONE`]
    /// past the end.
    pub next: [u32; GRAPH],
    /// The distance to the farthest of `next`.
    pub reach: f64,
}

impl Default for Local {
    fn default() -> Self {
        Local {
            normal: DVec3::Z,
            next: [NONE; GRAPH],
            reach: 0.0,
        }
    }
}

impl Local {
    /// The neighbours, as leaf positions.
    pub fn neighbours(&self) -> impl Iterator<Item = usize> + '_ {
        self.next
            .iter()
            .take_while(|&&j| j != NONE)
            .map(|&j| j as usize)
    }
}

/// The local plane of every point of `tree` (in leaf order) over its `k` nearest neighbours;
/// `position` maps the caller's indices to leaf positions (from the tree's leaf order).
pub fn local_planes(tree: &PointTree, position: &[u32], k: usize) -> Result<Vec<Local>> {
    let (sorted, ..) = tree.layout();
    tree.map_neighbourhoods_in_leaf_order(k, |s, found| {
        let normal = pca_normal(
            found
                .iter()
                .map(|&(_, j)| sorted[position[j as usize] as usize]),
        );
        let mut local = Local {
            normal,
            ..Local::default()
        };
        let others = found
            .iter()
            .map(|&(d, j)| (d, position[j as usize]))
            .filter(|&(_, t)| t as usize != s)
            .take(GRAPH);
        for (slot, (d, t)) in local.next.iter_mut().zip(others) {
            *slot = t;
            local.reach = d.sqrt();
        }
        local
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::fibonacci_sphere;

    #[test]
    fn a_sphere_has_radial_normals_and_near_neighbours() {
        let pts = fibonacci_sphere(5000);
        let tree = PointTree::new(&pts).unwrap();
        let position = tree.positions();
        let local = local_planes(&tree, &position, 16).unwrap();
        let (sorted, ..) = tree.layout();
        for (s, l) in local.iter().enumerate() {
            let p = sorted[s];
            assert!(l.normal.dot(p).abs() > 0.999);
            assert_eq!(l.neighbours().count(), GRAPH);
            for j in l.neighbours() {
                assert_ne!(j, s);
                assert!((sorted[j] - p).length() <= l.reach + 1e-15);
            }
            // Spacing of 5000 points on the unit sphere: about sqrt(4π / 5000) ≈ 0.05.
            assert!(l.reach < 0.15, "{}", l.reach);
        }
    }
}
