//! Closing the octree's mesh where its premise failed.
//!
//! The rejection test and the signs inferred from balls both assume that no surface lies within
//! |f(x)| / safety of a point x whose value is known. A fitted field may break that near the
//! surface (|f| growing faster than the distance), and then a dropped block can hold surface, or
//! a sign inferred can be wrong. Either shows in the leaves the octree kept:
//!
//! - a crossed leaf has a crossed face whose neighbour lies in a dropped block (the surface goes
//!   on into a block nobody triangulates), or
//! - a value evaluated later contradicts a sign inferred for the same point, or two blocks
//!   inferred different signs for one point (the cells around it were decided with a sign the
//!   store no longer has).
//!
//! From these cells the repair walks the surface as tracking does: every corner of a cell it
//! visits gets a value (an inferred sign is replaced by the value, and a contradiction sends the
//! cells around that point back to be visited), the cell is triangulated from its values, and
//! the walk goes on through each crossed face into neighbours that lie in dropped blocks or that
//! a contradiction touched. The leaves it visits replace those of the levels. When the premise
//! holds, nothing is found and the only cost is the scan of the crossed leaves' faces.

use super::decided::DecidedBlocks;
use super::leaves::CrossedLeaf;
use super::run::Run;
use super::state::PointState;
use super::store::NONE;
use crate::error::Result;
use crate::field::Field;
use crate::polygonize::cell::{case_index, Corner};
use crate::polygonize::tracking::FACE_STEP;
use crate::polygonize::CaseTable;
use rayon::prelude::*;
use std::collections::HashSet;

/// Where the levels' and leaves' decisions may have been wrong, found while settling.
#[derive(Default)]
pub(super) struct Suspects {
    /// Lattice points whose value contradicted the sign inferred for them.
    pub points: Vec<[u32; 3]>,
    /// Blocks of 2 × 2 × 2 cells (lower corners) whose leaves were decided with a sign for a
    /// point that another block inferred the other way.
    pub blocks: Vec<[u32; 3]>,
}

/// The neighbour of cell `o` across face `f`, when it lies in a lattice of `cells`.
fn neighbour(o: [u32; 3], f: usize, cells: [u32; 3]) -> Option<[u32; 3]> {
    let (axis, step) = FACE_STEP[f];
    let n = o[axis] as i64 + step;
    (n >= 0 && n < cells[axis] as i64).then(|| {
        let mut c = o;
        c[axis] = n as u32;
        c
    })
}

/// The cells with corner `p` inside a lattice of `cells`.
fn cells_around(p: [u32; 3], cells: [u32; 3]) -> impl Iterator<Item = [u32; 3]> {
    (0..8).filter_map(move |k| {
        let c: [i64; 3] = std::array::from_fn(|a| p[a] as i64 - ((k >> a) & 1) as i64);
        (0..3)
            .all(|a| c[a] >= 0 && c[a] < cells[a] as i64)
            .then(|| c.map(|x| x as u32))
    })
}

/// The cells next to crossed leaves, across crossed faces, that lie in blocks the levels
/// dropped: the surface goes on there, and no leaf holds it. Sorted, each once.
fn cells_beyond_crossed_faces(
    table: &CaseTable,
    dropped: &DecidedBlocks,
    leaves: &[CrossedLeaf],
    cells: [u32; 3],
) -> Vec<[u32; 3]> {
    let mut found: Vec<[u32; 3]> = leaves
        .par_iter()
        .with_min_len(4096)
        .flat_map_iter(|l| {
            let faces = table.crossed_faces(l.case);
            (0..6).filter_map(move |f| {
                if faces & (1 << f) == 0 {
                    return None;
                }
                neighbour(l.origin, f, cells).filter(|&n| dropped.dropped(n))
            })
        })
        .collect();
    found.par_sort_unstable();
    found.dedup();
    found
}

impl<F: Field + ?Sized> Run<'_, F> {
    /// Completes the crossed `leaves` where the premise failed (see the module docs): from the
    /// cells beyond crossed faces in dropped blocks and from the `suspects`, and counts the cells
    /// visited as repaired.
    pub(super) fn repair(&mut self, leaves: &mut Vec<CrossedLeaf>) -> Result<()> {
        let beyond =
            cells_beyond_crossed_faces(self.table, &self.decided, leaves, self.lattice.cells());
        let suspects = std::mem::take(&mut self.suspects);
        let repaired = self.close(beyond, suspects, leaves)?;
        self.stats.cells_repaired = repaired;
        self.stats.cells_visited += repaired;
        Ok(())
    }

    /// Walks the surface from the `suspects` and from `start` (cells, see the module docs) and
    /// updates `leaves`: the leaves visited are replaced by what their values give, and the
    /// crossed cells found in dropped blocks are added. The centres of the kept blocks of leaves
    /// (kept beside the blocks, not in the store, until here) go into the store. Returns the
    /// number of cells visited.
    fn close(
        &mut self,
        start: Vec<[u32; 3]>,
        suspects: Suspects,
        leaves: &mut Vec<CrossedLeaf>,
    ) -> Result<u64> {
        let (lattice, table) = (self.lattice, self.table);
        let (store, dropped) = (&mut self.store, &self.decided);
        let cells = lattice.cells();
        let mut wave = start;
        for &p in &suspects.points {
            wave.extend(cells_around(p, cells));
        }
        for &o in &suspects.blocks {
            wave.extend(
                Corner::ALL
                    .into_iter()
                    .map(|d| d.of_cell(o))
                    .filter(|c| (0..3).all(|a| c[a] < cells[a])),
            );
        }
        if wave.is_empty() {
            return Ok(0);
        }
        // Every corner of a cell visited is read from the store, the kept blocks' centres too.
        for (&o, &c) in self.blocks.iter().zip(&self.centres) {
            if c != NONE {
                let s = store.slot_mut([o[0] + 1, o[1] + 1, o[2] + 1]);
                store.slots[s] = c;
                store.state[s] = PointState::of_value(store.values[c as usize]);
            }
        }
        let levels_leaves = leaves.len();
        let mut visited: HashSet<[u32; 3]> = HashSet::new();
        let mut found: Vec<CrossedLeaf> = Vec::new();
        let mut points = Vec::new();
        while !wave.is_empty() {
            wave.sort_unstable();
            wave.dedup();
            wave.retain(|c| visited.insert(*c));
            // Every corner without a value is evaluated, inferred signs included.
            points.clear();
            let mut inferred: Vec<(usize, bool, [u32; 3])> = Vec::new();
            for &o in &wave {
                for k in Corner::ALL {
                    let p = k.of_cell(o);
                    let s = store.slot_mut(p);
                    let state = store.state[s];
                    if state == PointState::UNKNOWN || state.is_inferred() {
                        if state.is_inferred() {
                            inferred.push((s, state.is_negative(), p));
                        }
                        store.slots[s] = (store.values.len() + points.len()) as u32;
                        store.state[s] = PointState::QUEUED;
                        store.queued.push(s as u32);
                        points.push(lattice.point(p));
                    }
                }
            }
            store.evaluate(self.field, &points, &self.settings.common, &mut self.stats)?;
            let mut next = Vec::new();
            // A value against its inferred sign: the cells around the point were decided wrongly.
            for &(s, negative, p) in &inferred {
                if store.state[s].is_negative() != negative {
                    next.extend(cells_around(p, cells));
                }
            }
            for &o in &wave {
                let corners: [u32; 8] = Corner::ALL.map(|k| {
                    let s = store.slot_mut(k.of_cell(o));
                    debug_assert!(store.state[s].has_value());
                    store.slots[s]
                });
                let case = case_index(&corners.map(|i| store.values[i as usize]));
                if case == 0 || case == 255 {
                    continue;
                }
                found.push(CrossedLeaf {
                    origin: o,
                    corners,
                    case,
                });
                let faces = table.crossed_faces(case);
                next.extend((0..6).filter_map(|f| {
                    (faces & (1 << f) != 0)
                        .then(|| neighbour(o, f, cells))
                        .flatten()
                        .filter(|&n| dropped.dropped(n))
                }));
            }
            wave = next;
        }
        // The leaves visited are replaced by what their values give.
        let mut i = 0;
        leaves.retain(|l| {
            i += 1;
            i > levels_leaves || !visited.contains(&l.origin)
        });
        leaves.extend(found);
        Ok(visited.len() as u64)
    }
}
