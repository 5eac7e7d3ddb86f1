//! A partition-of-unity surface cut to a box: only the patches that values and gradients at
//! points of the box can use, so that a task polygonizing one tile of a lattice receives those
//! alone.

use super::{patches, PartitionSurface};
use glam::DVec3;

impl PartitionSurface {
    /// The surface with only the patches covering the octree leaves that points of the box
    /// `[lo, hi]` fall in (a point is blended from the patches of the leaf holding it clamped
    /// into the root cube), in their order: at every point of the box it
    /// evaluates to the same bits, values and gradients, as `self`. The octree and the
    /// constraints are kept whole (the octree is built from the constraints).
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
        let (cover_start, cover) = patches::cover(&self.tree, &patches);
        PartitionSurface {
            settings: self.settings,
            constraints: self.constraints.clone(),
            tree: self.tree.clone(),
            patches,
            cover_start,
            cover,
            residual: self.residual,
        }
    }
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
