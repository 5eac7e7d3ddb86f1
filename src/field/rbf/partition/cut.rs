//! A partition-of-unity surface cut to a box: only what values and gradients at points of the
//! box use, so that a task polygonizing one tile of a lattice receives that alone and its bytes
//! follow the tile: the patches covering the octree leaves the box meets, the octree split only
//! where it meets the box (it travels with the cut, see [`PartitionSurface::parts`]), and the
//! constraints the kept patches' centres are, renumbered.

use super::{patches, Constraints, PartitionSurface};
use crate::field::rbf::constraints::bulk_bounding_box;
use crate::field::rbf::PatchCentres;
use glam::DVec3;

impl PartitionSurface {
    /// The surface with only the patches covering the octree leaves that points of the box
    /// `[lo, hi]` fall in (a point is blended from the patches of the leaf holding it clamped
    /// into the root cube), in their order, the octree pruned to the box
    /// ([`super::octree::Octree::pruned_to_box`]), and the constraints the kept patches' centres
    /// are (which hold those inside their supports), in their order and renumbered (at least one
    /// data point, for its bounds): at every point of the box it evaluates to the same bits,
    /// values and gradients, as `self`.
    pub fn cut(&self, lo: DVec3, hi: DVec3) -> PartitionSurface {
        // Points are clamped into the root cube before their leaf is looked up.
        let (clo, chi) = self.tree.cube();
        let (blo, bhi) = (lo.clamp(clo, chi), hi.clamp(clo, chi));
        // The patches covering the leaves the box meets, in increasing order.
        let mut seen = vec![false; self.patches.len()];
        let mut ids: Vec<u32> = Vec::new();
        self.tree.for_each_leaf_meeting_box(blo, bhi, |k| {
            let l = self.tree.leaf_slot[k as usize] as usize;
            for &i in &self.cover[self.cover_start[l] as usize..self.cover_start[l + 1] as usize] {
                if !std::mem::replace(&mut seen[i as usize], true) {
                    ids.push(i);
                }
            }
        });
        ids.sort_unstable();
        let mut patches: Vec<_> = ids
            .iter()
            .map(|&i| self.patches[i as usize].clone())
            .collect();
        let constraints = self.constraints_indexed(&mut patches);
        let tree = self.tree.pruned_to_box(blo, bhi);
        let (cover_start, cover) = patches::cover(&tree, &patches);
        PartitionSurface {
            settings: self.settings,
            centres: constraints.points.clone(),
            data_box: bulk_bounding_box(&constraints.points[..constraints.boundary]),
            constraints,
            tree,
            cut: true,
            patches,
            cover_start,
            cover,
            residual: self.residual,
        }
    }

    /// Constraint `i`'s point (a search of the octree's order for a whole surface, which keeps
    /// its points in that order only).
    fn constraint_point(&self, i: u32) -> DVec3 {
        if self.constraints.points.len() == self.centres.len() {
            return self.constraints.points[i as usize];
        }
        let k = self.tree.order.iter().position(|&j| j == i);
        self.centres[k.expect("every constraint has a position")]
    }

    /// The constraints the centres of `patches` are, in their order (data points first, as in
    /// every [`Constraints`]; the first data point when none of them is), with the patches'
    /// indices renumbered into them (a cut's patches index its constraints, see
    /// [`PartitionSurface::constraint_at`]).
    fn constraints_indexed(&self, patches: &mut [patches::Patch]) -> Constraints {
        let c = &self.constraints;
        // The positions (in the points the patches index) the patches use, each once, and
        // then the new index of each: a map over all positions of which only those the cut
        // uses are written (its zeroed pages cost nothing until then), so the work follows the
        // cut, not the whole surface.
        let mut new = vec![0u32; self.centres.len()];
        let mut used: Vec<u32> = Vec::new();
        for p in patches.iter() {
            if let PatchCentres::Shared(index) = p.fit.centres() {
                for &k in index {
                    if std::mem::replace(&mut new[k as usize], 1) == 0 {
                        used.push(k);
                    }
                }
            }
        }
        // The constraints at those positions in their order, with their positions.
        let mut kept: Vec<(u32, u32)> = used.iter().map(|&k| (self.constraint_at(k), k)).collect();
        kept.sort_unstable();
        // At least one data point (the first), for the cut's bounds: it comes first.
        let first = usize::from(kept.first().is_none_or(|e| e.0 as usize >= c.boundary));
        for (next, &(_, k)) in kept.iter().enumerate() {
            new[k as usize] = (first + next) as u32;
        }
        for p in patches.iter_mut() {
            p.fit.renumber(&new);
        }
        let order: Vec<usize> = std::iter::repeat_n(0, first)
            .chain(kept.iter().map(|e| e.0 as usize))
            .collect();
        // The points, from the patches' copy: at the positions kept, and the first data
        // point's wherever it is.
        let first_point = (first == 1).then(|| self.constraint_point(0));
        let points = first_point
            .into_iter()
            .chain(kept.iter().map(|e| self.centres[e.1 as usize]))
            .collect();
        Constraints {
            points,
            values: order.iter().map(|&i| c.values[i]).collect(),
            offsets: order
                .iter()
                .filter(|&&i| i < c.offsets.len())
                .map(|&i| c.offsets[i])
                .collect(),
            boundary: order.iter().filter(|&&i| i < c.boundary).count(),
            normal_of: vec![],
            merged: c.merged,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::Field;
    use crate::testing::random_points;

    /// Values and gradients in the box are the whole surface's bits, with fewer patches.
    #[test]
    fn a_cut_surface_evaluates_to_the_same_bits_in_its_box() {
        let s = crate::field::rbf::partition::tests::torus_surface();
        let (lo, hi) = (DVec3::new(-1.2, -0.3, 0.1), DVec3::new(-0.2, 0.4, 1.3));
        let cut = s.cut(lo, hi);
        assert!(cut.patches.len() < s.patches.len() && !cut.patches.is_empty());
        assert!(cut.tree.nodes.len() < s.tree.nodes.len());
        let c = &cut.constraints;
        let all = s.constraint_points();
        assert!(c.points.len() < all.len() && c.boundary > 0);
        assert!(c.points.iter().all(|p| all.contains(p)));
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
