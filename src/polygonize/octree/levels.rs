//! The levels: from the root cube down to blocks of 2 × 2 × 2 cells, each level's blocks tested
//! at their centres (and, with the corner test, by the balls of their known corners), the kept
//! ones split into their children.

use super::block::{block_point, cell_inside, CENTRE};
use super::cover::covered;
use super::run::Run;
use super::state::PointState;
use super::store::NONE;
use crate::error::Result;
use crate::field::Field;
use crate::lattice::Lattice;
use crate::polygonize::bits::set_bits;
use crate::polygonize::cell::Corner;
use rayon::prelude::*;
use std::time::Instant;

/// Number of levels L: the root cube has 2^L cells per side, enough to cover the lattice.
pub(super) fn levels(lattice: &Lattice) -> u32 {
    let n = *lattice.cells().iter().max().unwrap();
    n.next_power_of_two().trailing_zeros()
}

/// The items whose `kept` entry is 1 (the others' are 0), in order, gathered in parallel.
pub(super) fn kept_items<T: Copy + Send + Sync>(items: &[T], kept: &[u32]) -> Vec<T> {
    crate::memory::collect_counted(kept, |i| (kept[i] != 0).then_some(items[i]))
}

/// The values known at a block's corners during the levels: at most two, at opposite corners.
/// A centre lies inside its block, so the coarser centres on a block's corners are those of its
/// ancestors: its parent's centre, at the corner opposite to the one it shares with its parent,
/// and whatever the parent knew at that shared corner.
#[derive(Clone, Copy)]
pub(super) struct KnownCorners {
    /// The corner (case-bit order) shared with the parent.
    corner: u8,
    /// The indices of the values at `corner` and at the opposite corner, `7 - corner`
    /// (`NONE`: not known).
    values: [u32; 2],
}

impl KnownCorners {
    const NONE: Self = KnownCorners {
        corner: 0,
        values: [NONE; 2],
    };

    /// The index of the value at corner `k` (`NONE` when unknown).
    fn at(&self, k: usize) -> u32 {
        match k {
            _ if k == self.corner as usize => self.values[0],
            _ if k == 7 - self.corner as usize => self.values[1],
            _ => NONE,
        }
    }

    /// The values at `corner` and at the opposite corner (NaN when unknown).
    fn get(&self, values: &[f64]) -> [f64; 2] {
        self.values.map(|i| {
            if i == NONE {
                f64::NAN
            } else {
                values[i as usize]
            }
        })
    }

    /// The points of a block of 2 × 2 × 2 cells with these corners that may have a value (its
    /// centre and these two corners), with the value (NaN where not known); the centre's is in
    /// `values` at index `centre` (`NONE`: not evaluated).
    pub(super) fn block_points(&self, values: &[f64], centre: u32) -> [(usize, f64); 3] {
        let at = |k: usize| {
            let d = Corner::new(k).offset();
            block_point(2 * d[0] as usize, 2 * d[1] as usize, 2 * d[2] as usize)
        };
        let [a, b] = self.get(values);
        let c = if centre != NONE {
            values[centre as usize]
        } else {
            f64::NAN
        };
        [
            (at(self.corner as usize), a),
            (at(7 - self.corner as usize), b),
            (CENTRE, c),
        ]
    }

    /// Those of child `d` (octant, case-bit order) of a block with these and whose centre's
    /// value has index `centre`: the child's corner `d` is the block's, its opposite corner the
    /// block's centre.
    fn child(&self, d: usize, centre: u32) -> Self {
        KnownCorners {
            corner: d as u8,
            values: [self.at(d), centre],
        }
    }
}

impl<F: Field + ?Sized> Run<'_, F> {
    /// Tests the levels from the start level down and splits the kept blocks level by level,
    /// until `blocks` are the blocks of 2 × 2 × 2 cells that hold the leaves, with their
    /// `known` corners and `centres`. A block rejected holds no surface: its sign goes into
    /// `decided`.
    pub(super) fn test_levels(&mut self) -> Result<()> {
        let start_level = self.start_level();
        self.blocks = vec![[0, 0, 0]];
        self.known = vec![KnownCorners::NONE];
        for level in 0..self.levels {
            // Cells per side of this level's blocks.
            let s = 1u32 << (self.levels - level);
            if level >= start_level {
                let t = Instant::now();
                if self.settings.corner_test && level > start_level {
                    self.drop_covered_blocks(s);
                }
                self.test_centres(s)?;
                self.stats.add_time("sample", t);
            }
            self.stats.cells_per_level.push(self.blocks.len() as u64);
            if s == 2 {
                // Blocks of 2 × 2 × 2 cells: their children are the leaves.
                break;
            }
            self.split(s);
        }
        if self.centres.len() != self.blocks.len() {
            self.centres = vec![NONE; self.blocks.len()];
        }
        Ok(())
    }

    /// The level of the first test ([`super::OctreeSettings::start_level`]; by default the first
    /// whose blocks span at most 1/8 of the lattice's longest side).
    fn start_level(&self) -> u32 {
        let largest = *self.lattice.cells().iter().max().unwrap();
        let levels = self.levels;
        self.settings.start_level.unwrap_or_else(|| {
            (1..=levels)
                .find(|&l| 8 * (1u32 << (levels - l)) <= largest)
                .unwrap_or(levels)
        })
    }

    /// Drops the blocks (of `s` cells per side) that the balls of their known corners already
    /// cover: they need no centre of their own. A coarser centre lies inside its block, so the
    /// only ones on a block's corners are those of its ancestors, carried down with it (see
    /// [`KnownCorners`]): no lookups.
    fn drop_covered_blocks(&mut self, s: u32) {
        let size = self.lattice.cell() * s as f64;
        let (store, cells, safety) = (&self.store, self.lattice.cells(), self.safety);
        // Per block: kept (None), or covered, with whether its known corners are all negative
        // (its sign) or all positive (Some(None) where they differ, which the premise rules
        // out).
        let free: Vec<Option<Option<bool>>> = self
            .blocks
            .par_iter()
            .zip(&self.known)
            .with_min_len(1024)
            .map(|(o, k)| {
                debug_assert!((0..8).all(|j| store
                    .known(Corner::new(j).of_cube(*o, s), cells)
                    .is_none_or(|v| k.at(j) != NONE && v == store.values[k.at(j) as usize])));
                let [a, b] = k.get(&store.values);
                if a.is_nan() && b.is_nan() {
                    return None;
                }
                let mut radius = [f64::NAN; 8];
                radius[k.corner as usize] = a.abs() / safety;
                radius[7 - k.corner as usize] = b.abs() / safety;
                covered(&radius, size).then(|| {
                    let neg = [a, b].iter().all(|&v| v.is_nan() || v < 0.0);
                    let pos = [a, b].iter().all(|&v| v.is_nan() || v >= 0.0);
                    (neg != pos).then_some(neg)
                })
            })
            .collect();
        self.decided.mark_blocks(&self.blocks, s, |i| free[i]);
        let kept: Vec<u32> = free.iter().map(|f| f.is_none() as u32).collect();
        self.keep(&kept);
    }

    /// Evaluates the centres of the blocks (of `s` cells per side) in one batch and drops the
    /// blocks whose centre's value rejects them (|f(c)| > safety × r); `centres` become the
    /// kept centres' value indices.
    fn test_centres(&mut self, s: u32) -> Result<()> {
        // Centres are never shared: those of one level are distinct, and those of different
        // levels are odd multiples of different powers of two.
        let (h, lattice) = (s / 2, self.lattice);
        self.points.clear();
        self.blocks
            .par_iter()
            .with_min_len(4096)
            .map(|o| lattice.point([o[0] + h, o[1] + h, o[2] + h]))
            .collect_into_vec(&mut self.points);
        let base = self.store.values.len();
        self.evaluate_points()?;
        let r = self.safety * lattice.block_radius(s);
        let v = &self.store.values[base..];
        self.decided.mark_blocks(&self.blocks, s, |i| {
            (v[i].abs() > r).then_some(Some(v[i] < 0.0))
        });
        let kept: Vec<u32> = v
            .par_iter()
            .with_min_len(4096)
            .map(|x| (x.abs() <= r) as u32)
            .collect();
        self.keep(&kept);
        self.centres =
            crate::memory::collect_counted(&kept, |i| (kept[i] != 0).then_some((base + i) as u32));
        // Only kept blocks hold leaves, and a centre lies inside its own block, so only kept
        // centres can be leaf corners (those inside the lattice). The centre of a block of
        // 2 × 2 × 2 cells is a corner of its own leaves only, so it stays with the block
        // instead of in the store.
        if s != 2 {
            let cells = lattice.cells();
            for (o, &i) in self.blocks.iter().zip(&self.centres) {
                let c = [o[0] + h, o[1] + h, o[2] + h];
                if c[0] <= cells[0] && c[1] <= cells[1] && c[2] <= cells[2] {
                    let slot = self.store.slot_mut(c);
                    self.store.slots[slot] = i;
                    self.store.state[slot] = PointState::of_value(self.store.values[i as usize]);
                }
            }
        }
        Ok(())
    }

    /// Keeps the blocks whose `kept` entry is 1, with their known corners.
    fn keep(&mut self, kept: &[u32]) {
        self.blocks = kept_items(&self.blocks, kept);
        self.known = kept_items(&self.known, kept);
    }

    /// Splits the blocks (of `s` cells per side) into their children inside the lattice, in
    /// block order, then octant order; the children know their parent's centre at a corner.
    fn split(&mut self, s: u32) {
        let (h, cells) = (s / 2, self.lattice.cells());
        let child = |o: [u32; 3], d: usize| Corner::new(d).of_cube(o, h);
        self.centres.resize(self.blocks.len(), NONE);
        let children: Vec<u8> = self
            .blocks
            .par_iter()
            .with_min_len(4096)
            .map(|&o| (0..8).fold(0, |m, d| m | (cell_inside(child(o, d), cells) as u8) << d))
            .collect();
        let counts: Vec<u32> = children.iter().map(|m| m.count_ones()).collect();
        let (blocks, known, centres) = (&self.blocks, &self.known, &self.centres);
        let next = crate::memory::collect_counted(&counts, |i| {
            let o = blocks[i];
            set_bits(children[i]).map(move |d| child(o, d))
        });
        self.known = crate::memory::collect_counted(&counts, |i| {
            let (k, c) = (known[i], centres[i]);
            set_bits(children[i]).map(move |d| k.child(d, c))
        });
        self.blocks = next;
        self.centres.clear();
    }
}
