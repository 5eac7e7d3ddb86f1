//! Block-sparse, time-stamped storage for the tracking polygonizer's caches (Triquet et al.
//! §4.1 and §4.7): the lattice is split into bricks of 8 × 8 × 8 lattice points; a small dense
//! table maps each brick position to a brick of the pool, handed out on first touch in a call.
//! Each table entry carries the stamp of the call that handed its brick out, so bricks from
//! earlier calls are simply stale: nothing is cleared between calls (only a brick's marks, 320
//! bytes, when it is handed out again), bricks are recycled from call to call, and memory grows
//! with the number of bricks the surface touches, not with the lattice.
//!
//! The bricks of the tracking caches and the blocks of [`super::sparse`] lie on the lattice
//! alike: a [`Grid`] numbers them (x fastest) and locates a lattice point or cell in them.
//!
//! Within a brick, the marks (value claimed, cell queued, edge vertex made) are bit sets, one
//! 64-bit word per z-plane of the brick (bit `x + 8y`), kept apart from the values and vertex
//! indices: the marks of a brick fill five cache lines, which stay hot while its cells are
//! visited, and the eight corners of a cell are claimed with two word operations.

use super::bits::for_each_set_bit;
use super::cell::Corner;

/// Lattice points per brick side.
pub const SIDE: u32 = 8;
const LOCAL: usize = (SIDE * SIDE * SIDE) as usize;
const NONE: u32 = u32::MAX;

/// The bricks (or blocks) of a lattice, `SIDE` lattice steps per axis each, numbered x fastest:
/// a brick's index and position, and the brick and local coordinates of a lattice point or
/// cell.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Grid<const SIDE: u32> {
    /// Bricks per axis.
    pub(crate) dims: [u32; 3],
}

impl<const SIDE: u32> Grid<SIDE> {
    /// The bricks covering `extent` lattice points (or cells) per axis.
    pub(crate) fn new(extent: [u32; 3]) -> Self {
        Grid {
            dims: extent.map(|e| e.div_ceil(SIDE)),
        }
    }

    /// Number of bricks.
    pub(crate) fn len(&self) -> usize {
        self.dims.iter().map(|&d| d as usize).product()
    }

    /// Index of the brick at position `b`.
    #[inline(always)]
    pub(crate) fn index(&self, b: [u32; 3]) -> usize {
        let d = self.dims.map(|v| v as usize);
        b[0] as usize + d[0] * (b[1] as usize + d[1] * b[2] as usize)
    }

    /// Position of the brick with index `i`.
    #[inline(always)]
    pub(crate) fn position(&self, i: u32) -> [u32; 3] {
        let d = self.dims;
        [i % d[0], (i / d[0]) % d[1], i / (d[0] * d[1])]
    }

    /// The lattice coordinates of the lower corner of the brick at position `b`.
    #[inline(always)]
    pub(crate) fn origin(&self, b: [u32; 3]) -> [u32; 3] {
        b.map(|v| v * SIDE)
    }

    /// Index of the brick holding `p`, and `p`'s coordinates within it.
    #[inline(always)]
    pub(crate) fn locate(&self, p: [u32; 3]) -> (usize, [u32; 3]) {
        (self.index(p.map(|v| v / SIDE)), p.map(|v| v % SIDE))
    }
}

/// One brick of 8³ lattice points.
#[derive(Clone)]
struct Brick {
    /// Per point (bit `x + 8y` of word `z`): its value is claimed (and, once evaluated,
    /// written) in this call.
    claimed: [u64; 8],
    /// Per cell, by its lower corner: the cell is queued in this call.
    queued: [u64; 8],
    /// Per point and axis: the vertex on the edge from the point along the axis is made.
    made: [[u64; 8]; 3],
    values: [f64; LOCAL],
    /// Per axis and point: the vertex index on the edge from the point along the axis.
    edges: [[u32; LOCAL]; 3],
}

impl Brick {
    fn new() -> Box<Self> {
        Box::new(Brick {
            claimed: [0; 8],
            queued: [0; 8],
            made: [[0; 8]; 3],
            values: [0.0; LOCAL],
            edges: [[NONE; LOCAL]; 3],
        })
    }

    /// Forgets the marks of an earlier call.
    fn clear_marks(&mut self) {
        self.claimed = [0; 8];
        self.queued = [0; 8];
        self.made = [[0; 8]; 3];
    }
}

/// Sets bit `l` of a brick's bit set; returns whether it was clear.
#[inline(always)]
fn mark(bits: &mut [u64; 8], l: usize) -> bool {
    let (w, b) = (l >> 6, 1u64 << (l & 63));
    let new = bits[w] & b == 0;
    bits[w] |= b;
    new
}

/// Offsets within a brick of the eight corners of a cell, in case-bit order (x fastest).
const CORNER_OFFSETS: [usize; 8] = [0, 1, 8, 9, 64, 65, 72, 73];

/// The caches of one tracking call and the next.
#[derive(Default)]
pub struct Bricks {
    stamp: u32,
    /// The bricks of the current lattice.
    grid: Grid<SIDE>,
    /// Brick position → (stamp, pool index).
    table: Vec<(u32, u32)>,
    pool: Vec<Box<Brick>>,
    /// Bricks handed out in this call.
    used: usize,
}

impl Bricks {
    /// Starts a call on a lattice with `points` lattice points per axis.
    pub fn begin(&mut self, points: [u32; 3]) {
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            // After 2³² calls, wipe the table's stamps once so that none can match by accident.
            self.table.iter_mut().for_each(|e| e.0 = 0);
            self.stamp = 1;
        }
        let grid = Grid::new(points);
        if grid != self.grid {
            self.grid = grid;
            self.table.clear();
            self.table.resize(grid.len(), (0, NONE));
        }
        self.used = 0;
    }

    /// Bricks in use in this call and in the pool.
    #[cfg(test)]
    pub fn counts(&self) -> (usize, usize) {
        (self.used, self.pool.len())
    }

    /// Bytes held (capacities).
    pub fn capacity_bytes(&self) -> usize {
        self.table.capacity() * 8
            + self.pool.capacity() * 8
            + self.pool.len() * std::mem::size_of::<Brick>()
    }

    /// Pool index of the brick holding `p` (handed out, with its marks cleared, on first touch
    /// in this call) and `p`'s index within it.
    #[inline]
    fn brick(&mut self, p: [u32; 3]) -> (usize, usize) {
        let (t, l) = self.grid.locate(p);
        let l = (l[0] + SIDE * (l[1] + SIDE * l[2])) as usize;
        let e = &mut self.table[t];
        if e.0 != self.stamp {
            if self.used == self.pool.len() {
                self.pool.push(Brick::new());
            } else {
                self.pool[self.used].clear_marks();
            }
            *e = (self.stamp, self.used as u32);
            self.used += 1;
        }
        (e.1 as usize, l)
    }

    /// Claims the corners of the cell with lower corner `o` whose values are neither known nor
    /// claimed in this call, calling `claimed` with each corner claimed now and its [`Slot`]
    /// for [`Bricks::set_slot`].
    #[inline]
    pub fn claim_cell(&mut self, o: [u32; 3], mut claimed: impl FnMut([u32; 3], Slot)) {
        if let Some((b, l)) = self.cell_in_brick(o) {
            // The four corners of each of the cell's two z-planes, as bits of that plane's word.
            let bits = &mut self.pool[b].claimed;
            let (w, shift) = (l >> 6, l & 63);
            for (dz, word) in [(0, w), (1, w + 1)] {
                let cell = 0x303u64 << shift;
                let new = cell & !bits[word];
                bits[word] |= cell;
                for_each_set_bit(new, |bit| {
                    let bit = bit as usize;
                    let (dx, dy) = ((bit - shift) & 1, (bit - shift) >> 3);
                    let k = Corner::new(dx | dy << 1 | dz << 2);
                    claimed(k.of_cell(o), Slot::new(b, l + CORNER_OFFSETS[k.index()]));
                });
            }
        } else {
            for k in Corner::ALL {
                let c = k.of_cell(o);
                let (b, l) = self.brick(c);
                if mark(&mut self.pool[b].claimed, l) {
                    claimed(c, Slot::new(b, l));
                }
            }
        }
    }

    /// Writes the value of a claimed point.
    #[inline]
    pub fn set_slot(&mut self, slot: Slot, v: f64) {
        let (b, l) = slot.get();
        self.pool[b].values[l] = v;
    }

    /// The value at `p`, which must have been written in this call.
    #[inline]
    fn known(&mut self, p: [u32; 3]) -> f64 {
        let (b, l) = self.brick(p);
        let brick = &self.pool[b];
        debug_assert!(brick.claimed[l >> 6] & 1 << (l & 63) != 0);
        brick.values[l]
    }

    /// The values at the eight corners of the cell with lower corner `o` (all written in this
    /// call), in case-bit order.
    #[inline]
    pub fn cell_values(&mut self, o: [u32; 3]) -> [f64; 8] {
        if let Some((b, l)) = self.cell_in_brick(o) {
            let values = &self.pool[b].values;
            CORNER_OFFSETS.map(|off| values[l + off])
        } else {
            Corner::ALL.map(|k| self.known(k.of_cell(o)))
        }
    }

    /// Brick and local index of `o` when the whole cell with lower corner `o` lies in one brick.
    #[inline]
    fn cell_in_brick(&mut self, o: [u32; 3]) -> Option<(usize, usize)> {
        if o.iter().all(|&c| c % SIDE < SIDE - 1) {
            Some(self.brick(o))
        } else {
            None
        }
    }

    /// The vertex on the edge from `p` along `axis`, creating it with `make` on first use.
    #[inline]
    pub fn edge(&mut self, p: [u32; 3], axis: u8, make: impl FnOnce() -> u32) -> u32 {
        let (b, l) = self.brick(p);
        let a = axis as usize;
        if !mark(&mut self.pool[b].made[a], l) {
            return self.pool[b].edges[a][l];
        }
        let v = make();
        self.pool[b].edges[a][l] = v;
        v
    }

    /// Marks cell `c` as queued; false when it already was in this call.
    #[inline]
    pub fn queue(&mut self, c: [u32; 3]) -> bool {
        let (b, l) = self.brick(c);
        mark(&mut self.pool[b].queued, l)
    }
}

/// Where a claimed point lives: brick and local index, packed.
#[derive(Clone, Copy, Debug)]
pub struct Slot(u32);

impl Slot {
    #[inline]
    fn new(brick: usize, local: usize) -> Self {
        debug_assert!(brick < 1 << 23 && local < LOCAL);
        Slot(((brick as u32) << 9) | local as u32)
    }
    #[inline]
    fn get(self) -> (usize, usize) {
        ((self.0 >> 9) as usize, (self.0 & 511) as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Claiming cells claims each corner once per call, in both the in-brick and the
    /// across-bricks paths, and a new call starts with nothing claimed, queued or made.
    #[test]
    fn claims_once_per_call_and_forgets_between_calls() {
        // Cells inside one brick, on brick faces, edges and corners (the first twice).
        const CELLS: [[u32; 3]; 7] = [
            [0, 0, 0],
            [1, 0, 0],
            [6, 6, 6],
            [7, 7, 7],
            [7, 0, 3],
            [8, 8, 8],
            [0, 0, 0],
        ];
        let mut b = Bricks::default();
        for call in 0..3u32 {
            b.begin([20, 20, 20]);
            let mut seen = std::collections::HashSet::new();
            for o in CELLS {
                b.claim_cell(o, |c, _| {
                    // A corner of the cell, not claimed before in this call.
                    assert!(
                        (0..3).all(|a| c[a] == o[a] || c[a] == o[a] + 1),
                        "{c:?} of {o:?}"
                    );
                    b_set(&mut seen, c);
                });
            }
            // Every corner of every cell, exactly once.
            let want: std::collections::HashSet<[u32; 3]> = CELLS
                .iter()
                .flat_map(|&o| Corner::ALL.map(|k| k.of_cell(o)))
                .collect();
            assert_eq!(seen, want, "call {call}");
            assert!(b.queue([7, 7, 7]) && !b.queue([7, 7, 7]));
            let mut made = 0;
            let v1 = b.edge([7, 3, 3], 0, || {
                made += 1;
                40 + call
            });
            let v2 = b.edge([7, 3, 3], 0, || {
                made += 1;
                99
            });
            assert_eq!((v1, v2, made), (40 + call, 40 + call, 1));
        }
        // Later calls reuse the bricks of the first.
        assert_eq!(b.counts().0, b.counts().1);
    }

    /// Records `c`, which must not have been claimed before in this call.
    fn b_set(seen: &mut std::collections::HashSet<[u32; 3]>, c: [u32; 3]) {
        assert!(seen.insert(c), "{c:?} claimed twice");
    }
}
