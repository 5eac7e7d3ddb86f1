//! A partition-of-unity surface cut to a box: only what values and gradients at points of the
//! box use, so that a task polygonizing one tile of a lattice receives that alone and its bytes
//! follow the tile: the patches covering the octree leaves the box meets, the octree split only
//! where it meets the box (it travels with the cut, see [`PartitionSurface::parts`]), and the
//! constraints inside the kept patches' supports.

use super::{patches, Constraints, PartitionSurface};
use glam::DVec3;

impl PartitionSurface {
    /// The surface with only the patches covering the octree leaves that points of the box
    /// `[lo, hi]` fall in (a point is blended from the patches of the leaf holding it clamped
    /// into the root cube), in their order, the octree pruned to the box
    /// ([`super::octree::Octree::pruned_to_box`]), and the constraints inside the kept
    /// patches' supports, in their order (at least one data point, for its bounds): at every
    /// point of the box it evaluates to the same bits, values and gradients, as `self`.
    pub fn cut(&self, lo: DVec3, hi: DVec3) -> PartitionSurface {
        // Points are clamped into the root cube before their leaf is looked up.
        let (clo, chi) = self.tree.cube();
        let (blo, bhi) = (lo.clamp(clo, chi), hi.clamp(clo, chi));
        let mut keep = vec![false; self.patches.len()];
        self.tree.for_each_leaf_meeting_box(blo, bhi, |k| {
            let l = self.tree.leaf_slot[k as usize] as usize;
            let cover = &self.cover[self.cover_start[l] as usize..self.cover_start[l + 1] as usize];
            for &i in cover {
                keep[i as usize] = true;
            }
        });
        let patches: Vec<_> = self
            .patches
            .iter()
            .zip(&keep)
            .filter(|(_, &k)| k)
            .map(|(p, _)| p.clone())
            .collect();
        let tree = self.tree.pruned_to_box(blo, bhi);
        let (cover_start, cover) = patches::cover(&tree, &patches);
        PartitionSurface {
            settings: self.settings,
            constraints: self.constraints_within(&patches),
            tree,
            cut: true,
            patches,
            cover_start,
            cover,
            residual: self.residual,
        }
    }

    /// The constraints inside the supports of `patches`, in their order (data points first, as
    /// in every [`Constraints`]); the first data point when none of them is.
    fn constraints_within(&self, patches: &[patches::Patch]) -> Constraints {
        let c = &self.constraints;
        let mut keep = vec![false; c.points.len()];
        // A cut's octree has no points; its constraints are kept whole by the cuts made from it.
        if self.tree.order.is_empty() {
            keep.fill(true);
        }
        for p in patches {
            let r2 = p.radius * p.radius;
            self.tree.for_each_leaf_meeting(p.centre, p.radius, |k| {
                let n = &self.tree.nodes[k as usize];
                for &i in &self.tree.order[n.start as usize..n.end as usize] {
                    if c.points[i as usize].distance_squared(p.centre) <= r2 {
                        keep[i as usize] = true;
                    }
                }
            });
        }
        if !keep[..c.boundary].contains(&true) {
            keep[0] = true;
        }
        Constraints {
            points: kept(&c.points, &keep),
            values: kept(&c.values, &keep),
            offsets: kept(&c.offsets, &keep),
            boundary: keep[..c.boundary].iter().filter(|&&k| k).count(),
            merged: c.merged,
        }
    }
}

/// The elements of `all` that `keep` marks, in their order.
fn kept<T: Copy>(all: &[T], keep: &[bool]) -> Vec<T> {
    all.iter()
        .zip(keep)
        .filter(|(_, &k)| k)
        .map(|(x, _)| *x)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::testing::random_points;
    use crate::field::Field;

    /// Values and gradients in the box are the whole surface's bits, with fewer patches.
    #[test]
    fn a_cut_surface_evaluates_to_the_same_bits_in_its_box() {
        let s = super::super::tests::torus_surface();
        let (lo, hi) = (DVec3::new(-1.2, -0.3, 0.1), DVec3::new(-0.2, 0.4, 1.3));
        let cut = s.cut(lo, hi);
        assert!(cut.patches.len() < s.patches.len() && !cut.patches.is_empty());
        assert!(cut.tree.nodes.len() < s.tree.nodes.len());
        let c = &cut.constraints;
        assert!(c.points.len() < s.constraints.points.len() && c.boundary > 0);
        assert!(c.points.iter().all(|p| s.constraints.points.contains(p)));
        // Its parts carry its octree: the surface they give is the same, bit for bit.
        let cut = PartitionSurface::from_parts(cut.parts()).unwrap();
        let points: Vec<DVec3> = random_points(2000, 0.0, 1.0, 11)
            .into_iter()
            .map(|q| lo + (hi - lo) * q)
            .chain([lo, hi])
            .collect();
        let (mut a, mut b) = (vec![0.0; points.len()], vec![0.0; points.len()]);
        s.values(&points, &mut a);
        cut.values(&points, &mut b);
        assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
        let (mut ga, mut gb) = (
            vec![DVec3::ZERO; points.len()],
            vec![DVec3::ZERO; points.len()],
        );
        s.gradients(&points, &mut ga);
        cut.gradients(&points, &mut gb);
        assert_eq!(ga, gb);
    }
}
