//! The leaf cells below the blocks of 2 × 2 × 2 cells the levels kept: which of them the surface
//! crosses, with their corners' value indices.

use super::block::{cell_inside, CENTRE, LEAF_CORNERS, LEAF_POINTS};
use super::run::Run;
use super::store::{corner_value, Store, NONE};
use crate::error::Result;
use crate::field::Field;
use crate::polygonize::bits::set_bits;
use crate::polygonize::cell::{case_index, Corner};
use rayon::prelude::*;

/// A leaf cell the surface crosses: its lowest lattice point, the value indices of its corners
/// (or [`NEGATIVE`](super::store::NEGATIVE) / [`POSITIVE`](super::store::POSITIVE) for corners with a sign only) and its case.
pub(super) struct CrossedLeaf {
    pub(super) origin: [u32; 3],
    pub(super) corners: [u32; 8],
    pub(super) case: u8,
}

impl<F: Field + ?Sized> Run<'_, F> {
    /// The crossed leaves, in leaf order: settled by the signs of their corners with the corner
    /// test (see [`super::settle`]), or from the values of all their corners (the paper's way).
    pub(super) fn crossed_leaves(&mut self) -> Result<Vec<CrossedLeaf>> {
        self.leaf_masks();
        let leaves = if self.settings.corner_test && self.levels > 0 {
            self.settle_by_signs()?;
            self.leaves_by_signs()
        } else {
            self.leaves_by_values()?
        };
        self.masks = Vec::new();
        self.points = Vec::new();
        Ok(leaves)
    }

    /// `masks`: per block of leaves, its children inside the lattice, in case-bit order; they
    /// are the cells tested.
    fn leaf_masks(&mut self) {
        let cells = self.lattice.cells();
        self.masks = self
            .blocks
            .par_iter()
            .with_min_len(4096)
            .map(|o| {
                Corner::ALL
                    .into_iter()
                    .filter(|d| cell_inside(d.of_cell(*o), cells))
                    .fold(0, |m, d| m | 1 << d.index())
            })
            .collect();
        let tested: u64 = self.masks.iter().map(|m| m.count_ones() as u64).sum();
        self.stats.cells_per_level.push(tested);
        self.stats.cells_visited = tested;
    }

    /// The crossed leaves in `masks` once settled: every corner has a value or a sign, read in
    /// parallel straight into place (the blocks' masks count their crossed leaves).
    fn leaves_by_signs(&self) -> Vec<CrossedLeaf> {
        let (store, blocks, masks, centres) =
            (&self.store, &self.blocks, &self.masks, &self.centres);
        let values = &store.values;
        let counts: Vec<u32> = masks.iter().map(|m| m.count_ones()).collect();
        let mut leaves = crate::memory::collect_counted(&counts, |i| {
            let (o, m, c) = (blocks[i], masks[i], centres[i]);
            let (mut idx, mut negative) =
                store.block_indices(o, Store::stored(LEAF_POINTS[m as usize], c));
            if c != NONE && m != 0 {
                idx[CENTRE] = c;
                negative |= ((values[c as usize] < 0.0) as u32) << CENTRE;
            }
            set_bits(m).map(move |d| {
                // The case from the signs gathered (the same as from the corners' values).
                let case = LEAF_CORNERS[d]
                    .iter()
                    .enumerate()
                    .fold(0u8, |c, (k, &p)| c | (((negative >> p) & 1) as u8) << k);
                let corners = LEAF_CORNERS[d].map(|p| idx[p as usize]);
                debug_assert_eq!(case, case_index(&corners.map(|i| corner_value(values, i))));
                CrossedLeaf {
                    origin: Corner::new(d).of_cell(o),
                    corners,
                    case,
                }
            })
        });
        // Where the premise failed, a value may have undone a leaf's crossing.
        if leaves.iter().any(|l| l.case == 0 || l.case == 255) {
            leaves.retain(|l| l.case != 0 && l.case != 255);
        }
        leaves
    }

    /// The crossed leaves in `masks`, with all their corners not yet known evaluated in one
    /// batch; the leaves of a block claim its points at once.
    fn leaves_by_values(&mut self) -> Result<Vec<CrossedLeaf>> {
        let n: usize = self.masks.iter().map(|m| m.count_ones() as usize).sum();
        let mut indices = Vec::with_capacity(self.blocks.len());
        self.points.clear();
        self.points.reserve(2 * n);
        for ((&o, &m), &c) in self.blocks.iter().zip(&self.masks).zip(&self.centres) {
            if m == 0 {
                continue;
            }
            let wanted = Store::stored(LEAF_POINTS[m as usize], c);
            let mut idx = self
                .store
                .claim_block(o, wanted, self.lattice, &mut self.points);
            if c != NONE {
                idx[CENTRE] = c;
            }
            indices.push((o, m, idx));
        }
        self.evaluate_points()?;
        let values = &self.store.values;
        let crossed_leaf = move |o: [u32; 3], d: usize, idx: &[u32; 27]| {
            let corners = LEAF_CORNERS[d].map(|p| idx[p as usize]);
            let case = case_index(&corners.map(|i| values[i as usize]));
            (case != 0 && case != 255).then_some(CrossedLeaf {
                origin: Corner::new(d).of_cell(o),
                corners,
                case,
            })
        };
        Ok(indices
            .par_iter()
            .with_min_len(256)
            .flat_map_iter(|(o, m, idx)| set_bits(*m).filter_map(move |d| crossed_leaf(*o, d, idx)))
            .collect())
    }
}
