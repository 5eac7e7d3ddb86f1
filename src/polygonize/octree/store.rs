//! The block-sparse store of the values of one call and of what is known at each lattice point.

use super::block::{block_offset, CENTRE};
use super::state::{atomic_states, PointState};
use crate::error::Result;
use crate::field::Field;
use crate::lattice::Lattice;
use crate::polygonize::bits::set_bits;
use crate::polygonize::bricks::Grid;
use crate::polygonize::{evaluate, Settings, Stats};
use glam::DVec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering::Relaxed};

/// `v` as atomics, for writes from several threads (the exclusive borrow guarantees that no
/// one else reads it meanwhile).
pub(super) fn atomic_u32s(v: &mut [u32]) -> &[AtomicU32] {
    // SAFETY: AtomicU32 has u32's size and alignment, and the exclusive borrow means every
    // access for its lifetime goes through the atomics.
    unsafe { &*(v as *mut [u32] as *const [AtomicU32]) }
}

/// Lattice points per side of a brick of the value store, as a power of two: 8.
const BRICK_BITS: u32 = 3;
const BRICK: u32 = 1 << BRICK_BITS;
const BRICK_POINTS: usize = 1 << (3 * BRICK_BITS);
/// The bricks of the value store on the lattice.
type Bricks = Grid<BRICK>;
/// Offsets within a brick of the block points, when the whole block lies in one brick.
const BLOCK_SLOTS: [usize; 27] = {
    let mut t = [0; 27];
    let mut p = 0;
    while p < 27 {
        t[p] = (p % 3) | ((p / 3) % 3) << BRICK_BITS | (p / 9) << (2 * BRICK_BITS);
        p += 1;
    }
    t
};
/// Working memory per output triangle at its peak (after the leaf corners are evaluated): slots
/// and their states, values, leaves with their corner indices, edge vertices, and the brick
/// table (an upper estimate on the shared meshes at 64³ to 256³).
pub(super) const BYTES_PER_TRIANGLE_STORE: u64 = 192;
/// An empty brick-table entry, slot or edge.
pub(super) const NONE: u32 = u32::MAX;
/// A leaf corner with a negative sign inferred and no value (in place of a value index).
pub(super) const NEGATIVE: u32 = u32::MAX - 1;
/// A leaf corner with a positive sign inferred and no value (in place of a value index).
pub(super) const POSITIVE: u32 = u32::MAX - 2;
/// Value indices stay below this (the codes above are not indices).
const MAX_VALUES: usize = (u32::MAX - 2) as usize;
/// The value of a leaf corner from its index (see [`NEGATIVE`], [`POSITIVE`]).
#[inline]
pub(super) fn corner_value(values: &[f64], i: u32) -> f64 {
    match i {
        NEGATIVE => f64::NEG_INFINITY,
        POSITIVE => f64::INFINITY,
        _ => values[i as usize],
    }
}
/// Bricks whose slots, states and values [`Store::new`] reserves address space for (32³, a
/// 256³ lattice's: 13 bytes per point, 218 MB of address space, of which only the pages of the
/// bricks used are touched).
const RESERVED_BRICKS: usize = 1 << 15;

/// The slot offset within its brick of the point at `(x, y, z)` in the brick (x fastest).
#[inline(always)]
fn local_offset(x: u32, y: u32, z: u32) -> usize {
    (x | y << BRICK_BITS | z << (2 * BRICK_BITS)) as usize
}

/// Whether the block of 2 × 2 × 2 cells with lower corner `o` lies in one brick (the brick of
/// `o`), so that its points' slots are those of `o` plus [`BLOCK_SLOTS`].
#[inline]
fn in_one_brick(o: [u32; 3]) -> bool {
    o.iter().all(|&c| c & (BRICK - 1) <= BRICK - 3)
}

/// The values of one call, in evaluation order, and what is known at each lattice point: the
/// lattice points are split into bricks of 8³, a dense table (one entry per brick) gives each
/// brick touched its block of slots, and a slot holds the index of the point's value in `values`
/// (or `NONE`) and a byte of state (unknown, queued, sign inferred, value; the sign in it). So
/// finding, claiming or reading a point is array indexing, and memory grows with the bricks the
/// kept blocks touch and with the evaluations, not with the lattice (the table has one `u32`
/// per 512 lattice points). The states of a block's 27 points lie in three cache lines.
pub(super) struct Store {
    /// The bricks of the lattice's points.
    bricks: Bricks,
    /// Brick position → brick number (its slots start at number × 512), or `NONE`.
    pub(super) table: Vec<u32>,
    /// Per brick, a slot per lattice point (x fastest): the index of its value, or `NONE`.
    pub(super) slots: Vec<u32>,
    /// Per slot, the point's state.
    pub(super) state: Vec<PointState>,
    /// Every value evaluated, in evaluation order.
    pub(super) values: Vec<f64>,
    /// The slots of the points claimed and not yet evaluated, in claiming order.
    pub(super) queued: Vec<u32>,
}

impl Store {
    /// The bricks of a lattice's points.
    fn bricks(lattice: &Lattice) -> Bricks {
        Grid::new(lattice.points_per_axis())
    }

    /// Bytes of the brick table of a lattice.
    pub(super) fn table_bytes(lattice: &Lattice) -> u64 {
        Self::bricks(lattice).len() as u64 * 4
    }

    pub(super) fn new(lattice: &Lattice) -> Self {
        let bricks = Self::bricks(lattice);
        let table = vec![NONE; bricks.len()];
        // Room for the slots of every brick (up to RESERVED_BRICKS): they never move as bricks
        // are handed out (no copies, whose pages would be faulted in afresh), and only the pages
        // of bricks handed out are touched.
        let room = table.len().min(RESERVED_BRICKS) * BRICK_POINTS;
        Store {
            bricks,
            table,
            slots: crate::memory::reserve_huge(room),
            state: crate::memory::reserve_huge(room),
            // A slot gets at most one index into `values`; besides those, only rejected
            // centres have values.
            values: crate::memory::reserve_huge(room),
            queued: Vec::new(),
        }
    }

    /// Table entry and offset within its brick of lattice point `p`.
    #[inline]
    pub(super) fn locate(&self, p: [u32; 3]) -> (usize, usize) {
        let (t, [x, y, z]) = self.bricks.locate(p);
        (t, local_offset(x, y, z))
    }

    /// Gives slots to the bricks of the points of the block of 2 × 2 × 2 cells with lower
    /// corner `o` (those in the lattice of `cells`), so that [`Store::block_slots`] can find them.
    pub(super) fn give_block_bricks(&mut self, o: [u32; 3], cells: [u32; 3]) {
        // Per axis, the block's lowest coordinate, and its highest where that is in the next
        // brick: one point per brick the block touches.
        let ends: [([u32; 2], usize); 3] = std::array::from_fn(|a| {
            let hi = (o[a] + 2).min(cells[a]);
            (
                [o[a], hi],
                1 + (hi >> BRICK_BITS != o[a] >> BRICK_BITS) as usize,
            )
        });
        let [(xs, nx), (ys, ny), (zs, nz)] = ends;
        for &z in &zs[..nz] {
            for &y in &ys[..ny] {
                for &x in &xs[..nx] {
                    self.slot_mut([x, y, z]);
                }
            }
        }
    }

    /// The slots of the points in `wanted` of the block of 2 × 2 × 2 cells with lower corner
    /// `o`, whose bricks have slots (see [`Store::give_block_bricks`]), in increasing order of
    /// block point, with the block point.
    #[inline]
    pub(super) fn block_slots(
        &self,
        o: [u32; 3],
        wanted: u32,
    ) -> impl Iterator<Item = (usize, usize)> + '_ {
        let base = in_one_brick(o).then(|| {
            let (t, l) = self.locate(o);
            self.table[t] as usize * BRICK_POINTS + l
        });
        set_bits(wanted).map(move |p| {
            let s = match base {
                Some(b) => b + BLOCK_SLOTS[p],
                None => {
                    let (t, l) = self.locate(block_offset(o, p));
                    self.table[t] as usize * BRICK_POINTS + l
                }
            };
            (s, p)
        })
    }

    /// [`Store::claim_block`] for many blocks at once, in parallel, with nothing queued before:
    /// `wanted[i]` are the points of block `blocks[i]`, whose bricks have slots (see
    /// [`Store::give_block_bricks`]); returns the points claimed, to evaluate next. Which of two
    /// blocks claims a point they share is left to the threads; what is claimed is not (every
    /// wanted point still unknown, once).
    pub(super) fn claim_blocks(
        &mut self,
        blocks: &[[u32; 3]],
        wanted: &[u32],
        lattice: &Lattice,
    ) -> Vec<DVec3> {
        debug_assert!(self.queued.is_empty());
        // `state` out of the store while its atomic view lives (the rest is only read).
        let mut state_owned = std::mem::take(&mut self.state);
        // Per block, the points it claimed.
        let mut claimed = Vec::new();
        {
            let (store, state) = (&*self, atomic_states(&mut state_owned));
            blocks
                .par_iter()
                .zip(wanted.par_iter())
                .with_min_len(512)
                .map(|(&o, &w)| {
                    store
                        .block_slots(o, w)
                        .fold(0u32, |mine, (s, p)| mine | (state[s].claim() as u32) << p)
                })
                .collect_into_vec(&mut claimed);
        }
        self.state = state_owned;
        // In block order, then block point order.
        let counts: Vec<u32> = claimed.iter().map(|m| m.count_ones()).collect();
        let queued = crate::memory::collect_counted(&counts, |i| {
            self.block_slots(blocks[i], claimed[i])
                .map(|(s, _)| s as u32)
        });
        let points = crate::memory::collect_counted(&counts, |i| {
            let o = blocks[i];
            self.block_slots(o, claimed[i])
                .map(move |(_, p)| lattice.point(block_offset(o, p)))
        });
        let start = self.values.len() as u32;
        let slots = atomic_u32s(&mut self.slots);
        queued
            .par_iter()
            .enumerate()
            .with_min_len(4096)
            .for_each(|(k, &s)| slots[s as usize].store(start + k as u32, Relaxed));
        self.queued = queued;
        points
    }

    /// Index in `slots` of lattice point `p`, giving its brick slots on first touch.
    #[inline]
    pub(super) fn slot_mut(&mut self, p: [u32; 3]) -> usize {
        let (t, l) = self.locate(p);
        let mut b = self.table[t];
        if b == NONE {
            b = (self.slots.len() / BRICK_POINTS) as u32;
            self.table[t] = b;
            self.slots.resize(self.slots.len() + BRICK_POINTS, NONE);
            self.state.resize(self.slots.len(), PointState::UNKNOWN);
        }
        b as usize * BRICK_POINTS + l
    }

    /// Queues lattice point `p`, whose slot is `s`, for evaluation unless its value or sign is
    /// known or it is queued already (returns `NONE` for a sign without a value): its value
    /// will be `values[values.len() + points.len()]` once `points` are evaluated.
    #[inline]
    fn claim_slot(
        &mut self,
        s: usize,
        p: [u32; 3],
        lattice: &Lattice,
        points: &mut Vec<DVec3>,
    ) -> u32 {
        if self.state[s] == PointState::UNKNOWN {
            self.slots[s] = (self.values.len() + points.len()) as u32;
            self.state[s] = PointState::QUEUED;
            self.queued.push(s as u32);
            points.push(lattice.point(p));
        }
        self.slots[s]
    }

    /// [`Store::claim_slot`] for the points in `wanted` (bits, as in [`block_point`](super::block::block_point)) of the block
    /// of 2 × 2 × 2 cells with lower corner `o`, in increasing order; returns their indices in
    /// `values` (those of the other points are `NONE`).
    #[inline]
    pub(super) fn claim_block(
        &mut self,
        o: [u32; 3],
        wanted: u32,
        lattice: &Lattice,
        points: &mut Vec<DVec3>,
    ) -> [u32; 27] {
        let mut idx = [NONE; 27];
        // The slots of the whole block, when it lies in the brick of `o`.
        let base = in_one_brick(o).then(|| self.slot_mut(o));
        for p in set_bits(wanted) {
            let q = match base {
                Some(b) => b + BLOCK_SLOTS[p],
                None => self.slot_mut(block_offset(o, p)),
            };
            idx[p] = self.claim_slot(q, block_offset(o, p), lattice, points);
        }
        idx
    }

    /// Stores a sign inferred in slot `s` unless it has a value or a sign already; returns
    /// whether the slot's sign is now the one given (`negative` or not).
    #[inline]
    pub(super) fn set_sign(&mut self, s: usize, negative: bool) -> bool {
        let state = &mut self.state[s];
        if *state == PointState::UNKNOWN {
            *state = PointState::inferred(negative);
        }
        state.is_negative() == negative
    }

    /// [`Store::set_sign`] for the points in `neg` (negative) and then those in `pos` of the
    /// block of 2 × 2 × 2 cells with lower corner `o` (bits as in [`block_point`](super::block::block_point)); returns
    /// whether every point's sign is now the one given.
    #[inline]
    pub(super) fn set_block_signs(&mut self, o: [u32; 3], neg: u32, pos: u32) -> bool {
        // The slots of the whole block, when it lies in the brick of `o`.
        let base = in_one_brick(o).then(|| self.slot_mut(o));
        let mut agreed = true;
        for (m, negative) in [(neg, true), (pos, false)] {
            for p in set_bits(m) {
                let s = match base {
                    Some(b) => b + BLOCK_SLOTS[p],
                    None => self.slot_mut(block_offset(o, p)),
                };
                agreed &= self.set_sign(s, negative);
            }
        }
        agreed
    }

    /// The indices in `values` of the points in `wanted` of the block of 2 × 2 × 2 cells with
    /// lower corner `o`, all of which must have a value or an inferred sign ([`NEGATIVE`] or
    /// [`POSITIVE`] for those; the other points get `NONE`), and the points of `wanted` that
    /// are negative (bit per point).
    #[inline]
    pub(super) fn block_indices(&self, o: [u32; 3], wanted: u32) -> ([u32; 27], u32) {
        let mut idx = [NONE; 27];
        let mut negative = 0;
        if wanted == 0 {
            // (The brick of `o` may have no slots.)
            return (idx, negative);
        }
        for (s, p) in self.block_slots(o, wanted) {
            // A value or an inferred sign.
            let state = self.state[s];
            debug_assert!(state.has_sign());
            let below = state.is_negative();
            negative |= (below as u32) << p;
            idx[p] = match self.slots[s] {
                NONE if below => NEGATIVE,
                NONE => POSITIVE,
                i => i,
            };
        }
        debug_assert!((0..27).all(|p| wanted & 1 << p == 0 || idx[p] != NONE));
        (idx, negative)
    }

    /// The value at lattice point `p` when it has been evaluated (None beyond the lattice, or
    /// when unknown, only queued, or only its sign is known).
    #[inline]
    pub(super) fn known(&self, p: [u32; 3], cells: [u32; 3]) -> Option<f64> {
        if p[0] > cells[0] || p[1] > cells[1] || p[2] > cells[2] {
            return None;
        }
        let (t, l) = self.locate(p);
        let b = self.table[t];
        let s = b as usize * BRICK_POINTS + l;
        (b != NONE && self.state[s].has_value()).then(|| self.values[self.slots[s] as usize])
    }

    /// `read(slot)` for the 27 points of the block of 2 × 2 × 2 cells with lower corner `o`
    /// (`outside` for points beyond the lattice or in bricks without slots).
    #[inline(always)]
    pub(super) fn block_map<T: Copy>(
        &self,
        o: [u32; 3],
        cells: [u32; 3],
        outside: T,
        read: impl Fn(usize) -> T,
    ) -> [T; 27] {
        let whole = in_one_brick(o) && (0..3).all(|a| o[a] + 2 <= cells[a]);
        let (t, l) = self.locate(o);
        let b = self.table[t];
        if whole && b != NONE {
            // The whole block in the brick of `o`.
            let s = b as usize * BRICK_POINTS + l;
            return std::array::from_fn(|p| read(s + BLOCK_SLOTS[p]));
        }
        // Across bricks: per axis, the brick and offset of the block's three coordinates (None
        // beyond the lattice), then one table lookup per brick touched.
        let axis = |a: usize| -> [Option<(u32, u32)>; 3] {
            std::array::from_fn(|i| {
                let c = o[a] + i as u32;
                (c <= cells[a]).then_some((c / BRICK, c % BRICK))
            })
        };
        let (ax, ay, az) = (axis(0), axis(1), axis(2));
        let mut v = [outside; 27];
        for (k, z) in az.iter().enumerate() {
            let Some((bz, lz)) = *z else { continue };
            for (j, y) in ay.iter().enumerate() {
                let Some((by, ly)) = *y else { continue };
                let row = self.bricks.index([0, by, bz]);
                let lrow = local_offset(0, ly, lz);
                for (i, x) in ax.iter().enumerate() {
                    let Some((bx, lx)) = *x else { continue };
                    let b = self.table[row + bx as usize];
                    if b != NONE {
                        v[i + 3 * j + 9 * k] =
                            read(b as usize * BRICK_POINTS + (lrow | lx as usize));
                    }
                }
            }
        }
        v
    }

    /// The states of the 27 points of a block of leaves (lower corner `o`; [`PointState::UNKNOWN`] beyond
    /// the lattice) whose centre has the value with index `centre` (kept with the block, not in
    /// the store; `NONE` when not evaluated).
    #[inline]
    pub(super) fn leaf_block_states(
        &self,
        o: [u32; 3],
        centre: u32,
        cells: [u32; 3],
    ) -> [PointState; 27] {
        let mut v = self.block_map(o, cells, PointState::UNKNOWN, |s| self.state[s]);
        if centre != NONE {
            v[CENTRE] = PointState::of_value(self.values[centre as usize]);
        }
        v
    }

    /// The values known at the 27 points of a block of leaves, as [`Store::leaf_block_states`]
    /// (NaN where no value is known).
    pub(super) fn leaf_block_values(&self, o: [u32; 3], centre: u32, cells: [u32; 3]) -> [f64; 27] {
        let mut v = self.block_map(o, cells, f64::NAN, |s| {
            if self.state[s].has_value() {
                self.values[self.slots[s] as usize]
            } else {
                f64::NAN
            }
        });
        if centre != NONE {
            v[CENTRE] = self.values[centre as usize];
        }
        v
    }

    /// The points of `wanted` of a block of leaves that the store has to give (the centre is
    /// kept with the block when it was evaluated, see [`Store::leaf_block_states`]).
    #[inline]
    pub(super) fn stored(wanted: u32, centre: u32) -> u32 {
        if centre != NONE {
            wanted & !(1 << CENTRE)
        } else {
            wanted
        }
    }

    /// Errors unless `more` values fit beside those stored (value indices stay below
    /// [`MAX_VALUES`]).
    pub(super) fn check_room(&self, more: usize) -> Result<()> {
        let n = self.values.len() + more;
        if n >= MAX_VALUES {
            return Err(crate::Error::TooMuchMemory {
                name: "resolution",
                needed_mib: (n as u64 * 8).div_ceil(1 << 20),
                limit_mib: (MAX_VALUES as u64 * 8) >> 20,
            });
        }
        Ok(())
    }

    /// Evaluates `points` (queued by [`Store::claim_slot`]) in batches and appends their values.
    pub(super) fn evaluate<F: Field + ?Sized>(
        &mut self,
        field: &F,
        points: &[DVec3],
        settings: &Settings,
        stats: &mut Stats,
    ) -> Result<()> {
        let start = self.values.len();
        self.check_room(points.len())?;
        self.values.resize(start + points.len(), 0.0);
        evaluate(field, points, &mut self.values[start..], settings.batch)?;
        // Points claimed get their values in their slots too (level centres are given slots
        // by the caller, when kept).
        debug_assert!(self.queued.is_empty() || self.queued.len() == points.len());
        for (&s, &v) in self.queued.iter().zip(&self.values[start..]) {
            self.state[s as usize] = PointState::of_value(v);
        }
        self.queued.clear();
        stats.evaluations += points.len() as u64;
        Ok(())
    }
}
