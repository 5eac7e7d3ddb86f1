//! The seed walks both engines use (Triquet et al., Fig. 1): from the cell holding a start
//! point, walk along +x to the first cell the surface crosses, at most `max_walk` cells; when
//! the walk meets the side of the lattice first (a primitive cut by the box), start again from
//! the same cell along −x, then ±y, ±z. Points outside the lattice start from the nearest cell.
//! All walks advance together, one step per wave of evaluation.

use crate::lattice::Lattice;
use glam::DVec3;

/// Neighbour offsets across the six faces (face f = 2·axis + side).
pub(in crate::polygonize) const FACE_STEP: [(usize, i64); 6] =
    [(0, -1), (0, 1), (1, -1), (1, 1), (2, -1), (2, 1)];

/// The directions a seed walk tries, in order, as faces: +x first (Triquet's Fig. 1), then −x,
/// ±y, ±z.
const WALK_ORDER: [usize; 6] = [1, 0, 3, 2, 5, 4];

/// A seed walk: its current cell, the cell it started from, the index into [`WALK_ORDER`] of
/// its direction and the steps taken in that direction.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(super) struct Walker {
    pub(super) cell: [u32; 3],
    start: [u32; 3],
    direction: u8,
    steps: u32,
}

impl Walker {
    /// Moves to the next cell of the walk (its current cell is not crossed): along its
    /// direction, or, when the walk meets the side of a lattice with `cells` per axis, to the
    /// first cell from the start along the next direction. False when the walk is over: out of
    /// directions, or `max_steps` taken (the surface is farther than the walk may go, deep
    /// inside a cluster, which other walks reach; only a walk cut by the box tries the next
    /// direction).
    pub(super) fn advance(&mut self, cells: [u32; 3], max_steps: u32) -> bool {
        loop {
            let (axis, step) = FACE_STEP[WALK_ORDER[self.direction as usize]];
            let n = self.cell[axis] as i64 + step;
            if self.steps >= max_steps {
                return false;
            }
            if n >= 0 && n < cells[axis] as i64 {
                self.cell[axis] = n as u32;
                self.steps += 1;
                return true;
            }
            if self.direction as usize + 1 == WALK_ORDER.len() {
                return false;
            }
            self.direction += 1;
            self.cell = self.start;
            self.steps = 0;
        }
    }
}

/// The walks from `starts` (finite ones): each from the cell holding it, or the nearest cell
/// for points outside the lattice; sorted, each once.
pub(super) fn start_walkers(starts: &[DVec3], lattice: &Lattice) -> Vec<Walker> {
    let cells = lattice.cells();
    let mut walkers: Vec<Walker> = starts
        .iter()
        .filter(|p| p.is_finite())
        .map(|p| {
            let q = (*p - lattice.origin()) / lattice.cell();
            let c = [0, 1, 2].map(|k| q[k].floor().clamp(0.0, (cells[k] - 1) as f64) as u32);
            Walker {
                cell: c,
                start: c,
                direction: 0,
                steps: 0,
            }
        })
        .collect();
    walkers.sort_unstable();
    walkers.dedup();
    walkers
}

/// One step of every walk: keeps the walkers for which `step` returns true (it may move them),
/// sorted, each once (walks that meet go on as one).
pub(super) fn step_walkers(walkers: &mut Vec<Walker>, mut step: impl FnMut(&mut Walker) -> bool) {
    let mut keep = 0;
    for i in 0..walkers.len() {
        let mut w = walkers[i];
        if step(&mut w) {
            walkers[keep] = w;
            keep += 1;
        }
    }
    walkers.truncate(keep);
    walkers.sort_unstable();
    walkers.dedup();
}
