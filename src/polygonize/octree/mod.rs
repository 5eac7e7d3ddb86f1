//! Hierarchical space sampling with the pseudo-Euclidean rejection test (Cuno et al. §4.3).
//!
//! The lattice is covered by a root cube of 2^L cells per side. Level by level, every surviving
//! block of `s × s × s` cells is tested at its centre `c` (a lattice point): when
//! `|f(c)| > safety × r`, with `r` the block's circumradius, the surface cannot reach the block
//! — provided `|f|` under-estimates the distance to the surface there, which the normal
//! constraints of a variational surface with w < d arrange (Cuno's property (6)), and which holds
//! for any exact or conservative signed distance. Otherwise the block splits into 8. Blocks of two
//! cells that survive split into leaf cells, whose corners are evaluated and triangulated with the
//! shared case table and edge vertices — so wherever nothing was rejected wrongly, the mesh is
//! exactly the dense mesh.
//!
//! Beyond the paper (on by default, see [`Settings::corner_test`]), values already known do
//! more of the work, by the same argument (no surface lies within |f(x)| / safety of x): a
//! block covered by the balls around its known corners is dropped unevaluated; every point of a
//! block dropped either way has its sign, which the leaves' corners on its faces take; and the
//! leaves are settled by signs, not values. Marching cubes needs only the signs of a cell's
//! corners, and values at the ends of its crossed edges; a corner inside the ball of a known
//! value has that value's sign. So signs are first inferred from the balls of the values the
//! levels left, then the leaves' corners still without one are evaluated, then signs are
//! inferred again; a leaf whose corners all have one sign is done without evaluating the
//! others, and the ends of crossed edges that only have a sign are evaluated last.
//!
//! The centres of one level are evaluated in one batched field call, the leaves' corners in
//! one more and the ends of crossed edges in a last; no point is evaluated twice (coarse
//! centres are corners of leaf cells). The values live in a block-sparse store: a dense table
//! of bricks of 8³ lattice points, each brick an array of indices into the values and one of
//! the points' states (a byte: unknown, queued, sign inferred, value; the sign in it), so
//! finding, claiming and reading a point is array indexing, and memory grows with the surface,
//! not with the lattice (besides the brick table, 4 bytes per 512 points, and the decided
//! blocks' signs, a byte per 8 cells: 262 kB at 128³, 134 MB at 1024³). Leaves are
//! triangulated in parallel, each edge vertex indexed through the value index of the edge's
//! lower end and numbered as a serial sweep over the leaves would (first use).

mod repair;
mod state;

use state::{atomic_states, PointState};

use super::cell::{case_index, corner_offset};
use super::table::{EDGES, EDGE_AXIS};
use super::{check_memory, compute_normals, estimate_triangles, evaluate, CaseTable, Stats};
use crate::error::Result;
use crate::field::Field;
use crate::lattice::{edge_crossing, Lattice};
use crate::mesh::Mesh;
use glam::DVec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, AtomicU8, Ordering::Relaxed};
use std::time::Instant;

// The store's states and indices are written in parallel through atomic views of its vectors.

/// `v` as atomics, for writes from several threads (the exclusive borrow guarantees that no
/// one else reads it meanwhile).
fn atomic_u8s(v: &mut [u8]) -> &[AtomicU8] {
    // SAFETY: AtomicU8 has u8's size and alignment, and the exclusive borrow means every
    // access for its lifetime goes through the atomics.
    unsafe { &*(v as *mut [u8] as *const [AtomicU8]) }
}

/// `v` as atomics, as [`atomic_u8s`].
fn atomic_u32s(v: &mut [u32]) -> &[AtomicU32] {
    // SAFETY: AtomicU32 has u32's size and alignment, and the exclusive borrow means every
    // access for its lifetime goes through the atomics.
    unsafe { &*(v as *mut [u32] as *const [AtomicU32]) }
}

/// Octree-specific settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Level of the first rejection test: 1 tests the root's 8 octants (the paper's
    /// r = √3/2 for a [-1, 1]³ root), 2 the 64 blocks below them (r = √3/4), and so on. Levels
    /// above it are split without evaluating anything. `None`: the first level whose blocks
    /// span at most 1/8 of the lattice's longest side. Measured on the shared meshes at 24³ to
    /// 128³: starting at coarser blocks (the paper's r = √3/2) rejected cells wrongly at some
    /// resolutions, because far from the surface |f| stops under-estimating distance (Cuno's
    /// Fig. 2c and Table 1); testing from 1/8 costs at most 8³·(root/lattice)³ extra centres.
    pub start_level: Option<u32>,
    /// Multiplies the circumradius in the test |f(c)| > safety × r. Values above 1 keep more
    /// blocks (safer for fields that over-estimate distance, more evaluations).
    pub safety: f64,
    /// Tests beyond the paper that decide with values already known, each by the rejection
    /// test's premise (no surface within |f(x)| / safety of x):
    /// - a block whose known corners have balls of radius |f| / safety that together cover it
    ///   is dropped without evaluating its centre (the known corners are the centres of its
    ///   parent and of ancestors further up, two at most, at opposite corners, where covering
    ///   is decided exactly);
    /// - a block dropped (by its centre's ball, which holds the whole block, or by its corners')
    ///   holds one sign, so the leaves' corners on its faces, edges and corners have that sign
    ///   without evaluation (a map of one byte per block of 2 × 2 × 2 cells records them);
    /// - leaf cells are settled by the signs of their corners: a corner in the ball of a known
    ///   value has its sign, so only the corners still without a sign after the levels are
    ///   evaluated, a leaf whose corners all have one sign needs no more, and of a crossed leaf
    ///   only the ends of its crossed edges need values.
    ///
    /// The mesh is the same. On the shared meshes at 128³ over [-1, 1]³ this evaluates about
    /// half the points the paper's test alone does (torus2 2.41 % of the lattice instead of
    /// 5.33 %, icosahedron 6.50 % instead of 14.60 %). `false` gives §4.3 exactly.
    pub corner_test: bool,
}

impl Default for Settings {
    fn default() -> Self {
        // Measured on the shared meshes (d = 0.015, w/d = 3/4, 24³ to 128³): see
        // notebooks/cuno_tables.ipynb and BENCHMARKS.md.
        Settings {
            start_level: None,
            safety: 1.0,
            corner_test: true,
        }
    }
}

/// Number of levels L: the root cube has 2^L cells per side, enough to cover the lattice.
pub fn levels(lattice: &Lattice) -> u32 {
    let n = *lattice.cells.iter().max().unwrap();
    n.next_power_of_two().trailing_zeros()
}

/// Lattice points per side of a brick of the value store, as a power of two: 8.
const BRICK_BITS: u32 = 3;
const BRICK: u32 = 1 << BRICK_BITS;
const BRICK_POINTS: usize = 1 << (3 * BRICK_BITS);
/// The 3 × 3 × 3 lattice points of a block of 2 × 2 × 2 cells (a parent of leaves), numbered
/// x fastest: point `x + 3y + 9z`.
const fn block_point(x: usize, y: usize, z: usize) -> usize {
    x + 3 * y + 9 * z
}
/// The block point at the block's centre.
const CENTRE: usize = block_point(1, 1, 1);
/// `LEAF_CORNERS[d][k]`: the block point of corner k of child cell d (both in case-bit order).
const LEAF_CORNERS: [[u8; 8]; 8] = {
    let mut t = [[0; 8]; 8];
    let mut d = 0;
    while d < 8 {
        let mut k = 0;
        while k < 8 {
            t[d][k] = block_point(
                (d & 1) + (k & 1),
                ((d >> 1) & 1) + ((k >> 1) & 1),
                ((d >> 2) & 1) + ((k >> 2) & 1),
            ) as u8;
            k += 1;
        }
        d += 1;
    }
    t
};
/// `LEAF_POINTS[m]`: the block points that the children in child mask `m` need (bit per
/// point): the union of their corners.
const LEAF_POINTS: [u32; 256] = {
    let mut t = [0; 256];
    let mut m = 0;
    while m < 256 {
        let mut d = 0;
        while d < 8 {
            if m & (1 << d) != 0 {
                let mut k = 0;
                while k < 8 {
                    t[m] |= 1 << LEAF_CORNERS[d][k];
                    k += 1;
                }
            }
            d += 1;
        }
        m += 1;
    }
    t
};
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
/// table. Measured on the shared meshes at 64³ to 256³ when the slots held 8-byte copies of the
/// values instead of a byte of state: 125 to 160 bytes (less now).
const BYTES_PER_TRIANGLE_STORE: u64 = 192;
/// An empty brick-table entry, slot or edge.
const NONE: u32 = u32::MAX;
/// A leaf corner with a negative sign inferred and no value (in place of a value index).
const NEGATIVE: u32 = u32::MAX - 1;
/// A leaf corner with a positive sign inferred and no value (in place of a value index).
const POSITIVE: u32 = u32::MAX - 2;
/// Value indices stay below this (the codes above are not indices).
const MAX_VALUES: usize = (u32::MAX - 2) as usize;
/// The value of a leaf corner from its index (see [`NEGATIVE`], [`POSITIVE`]).
#[inline]
fn corner_value(values: &[f64], i: u32) -> f64 {
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

/// The values of one call, in evaluation order, and what is known at each lattice point: the
/// lattice points are split into bricks of 8³, a dense table (one entry per brick) gives each
/// brick touched its block of slots, and a slot holds the index of the point's value in `values`
/// (or `NONE`) and a byte of state (unknown, queued, sign inferred, value; the sign in it). So
/// finding, claiming or reading a point is array indexing, and memory grows with the bricks the
/// kept blocks touch and with the evaluations, not with the lattice (the table has one `u32`
/// per 512 lattice points). The states of a block's 27 points lie in three cache lines.
struct Store {
    /// Bricks per axis.
    dims: [usize; 3],
    /// Brick position → brick number (its slots start at number × 512), or `NONE`.
    table: Vec<u32>,
    /// Per brick, a slot per lattice point (x fastest): the index of its value, or `NONE`.
    slots: Vec<u32>,
    /// Per slot, the point's state.
    state: Vec<PointState>,
    /// Every value evaluated, in evaluation order.
    values: Vec<f64>,
    /// The slots of the points claimed and not yet evaluated, in claiming order.
    queued: Vec<u32>,
}

impl Store {
    /// Bricks per axis of a lattice.
    fn dims(lattice: &Lattice) -> [usize; 3] {
        lattice
            .points_per_axis()
            .map(|p| p.div_ceil(BRICK) as usize)
    }

    /// Bytes of the brick table of a lattice.
    fn table_bytes(lattice: &Lattice) -> u64 {
        Self::dims(lattice)
            .iter()
            .map(|&d| d as u64)
            .product::<u64>()
            * 4
    }

    fn new(lattice: &Lattice) -> Self {
        let dims = Self::dims(lattice);
        let table = vec![NONE; dims.iter().product()];
        // Room for the slots of every brick (up to RESERVED_BRICKS): they never move as bricks
        // are handed out, and only the pages of bricks handed out are touched. Growing them
        // instead (copies, and each copy's pages faulted in afresh) took 7-9 % of the
        // icosahedron's octree at 128³ run alone.
        let room = table.len().min(RESERVED_BRICKS) * BRICK_POINTS;
        Store {
            dims,
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
    fn locate(&self, p: [u32; 3]) -> (usize, usize) {
        let b = p.map(|c| (c >> BRICK_BITS) as usize);
        let m = BRICK - 1;
        let l = (p[0] & m) as usize
            | ((p[1] & m) as usize) << BRICK_BITS
            | ((p[2] & m) as usize) << (2 * BRICK_BITS);
        (b[0] + self.dims[0] * (b[1] + self.dims[1] * b[2]), l)
    }

    /// Gives slots to the bricks of the points of the block of 2 × 2 × 2 cells with lower
    /// corner `o` (those in the lattice of `cells`), so that [`Store::block_slots`] can find them.
    fn give_block_bricks(&mut self, o: [u32; 3], cells: [u32; 3]) {
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
    fn block_slots(&self, o: [u32; 3], wanted: u32) -> impl Iterator<Item = (usize, usize)> + '_ {
        let base = o.iter().all(|&c| c & (BRICK - 1) <= BRICK - 3).then(|| {
            let (t, l) = self.locate(o);
            self.table[t] as usize * BRICK_POINTS + l
        });
        let mut m = wanted;
        std::iter::from_fn(move || {
            if m == 0 {
                return None;
            }
            let p = m.trailing_zeros() as usize;
            m &= m - 1;
            let s = match base {
                Some(b) => b + BLOCK_SLOTS[p],
                None => {
                    let (t, l) = self.locate(block_offset(o, p));
                    self.table[t] as usize * BRICK_POINTS + l
                }
            };
            Some((s, p))
        })
    }

    /// [`Store::claim_block`] for many blocks at once, in parallel, with nothing queued before:
    /// `wanted[i]` are the points of block `blocks[i]`, whose bricks have slots (see
    /// [`Store::give_block_bricks`]); returns the points claimed, to evaluate next. Which of two
    /// blocks claims a point they share is left to the threads; what is claimed is not (every
    /// wanted point still unknown, once).
    fn claim_blocks(
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
                    store.block_slots(o, w).fold(0u32, |mine, (s, p)| {
                        // (Most are known: a plain read first.)
                        let claims = state[s].load(Relaxed) == PointState::UNKNOWN.0
                            && state[s]
                                .compare_exchange(
                                    PointState::UNKNOWN.0,
                                    PointState::QUEUED.0,
                                    Relaxed,
                                    Relaxed,
                                )
                                .is_ok();
                        mine | (claims as u32) << p
                    })
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
    fn slot_mut(&mut self, p: [u32; 3]) -> usize {
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

    /// Queues `p` for evaluation unless its value or sign is known or it is queued already
    /// (returns `NONE` for a sign without a value): its value will be
    /// `values[values.len() + points.len()]` once `points` are evaluated.
    #[inline]
    fn claim(&mut self, p: [u32; 3], lattice: &Lattice, points: &mut Vec<DVec3>) -> u32 {
        let s = self.slot_mut(p);
        if self.state[s] == PointState::UNKNOWN {
            self.slots[s] = (self.values.len() + points.len()) as u32;
            self.state[s] = PointState::QUEUED;
            self.queued.push(s as u32);
            points.push(lattice.point(p));
        }
        self.slots[s]
    }

    /// [`Store::claim`] for the points in `wanted` (bits, as in [`block_point`]) of the block
    /// of 2 × 2 × 2 cells with lower corner `o`, in increasing order; returns their indices in
    /// `values` (those of the other points are `NONE`).
    #[inline]
    fn claim_block(
        &mut self,
        o: [u32; 3],
        wanted: u32,
        lattice: &Lattice,
        points: &mut Vec<DVec3>,
    ) -> [u32; 27] {
        let mut idx = [NONE; 27];
        let mut m = wanted;
        if o.iter().all(|&c| c & (BRICK - 1) <= BRICK - 3) {
            // The whole block in the brick of `o`.
            let s = self.slot_mut(o);
            while m != 0 {
                let p = m.trailing_zeros() as usize;
                m &= m - 1;
                let q = s + BLOCK_SLOTS[p];
                if self.state[q] == PointState::UNKNOWN {
                    self.slots[q] = (self.values.len() + points.len()) as u32;
                    self.state[q] = PointState::QUEUED;
                    self.queued.push(q as u32);
                    points.push(lattice.point(block_offset(o, p)));
                }
                idx[p] = self.slots[q];
            }
        } else {
            while m != 0 {
                let p = m.trailing_zeros() as usize;
                m &= m - 1;
                idx[p] = self.claim(block_offset(o, p), lattice, points);
            }
        }
        idx
    }

    /// Stores a sign inferred in slot `s` unless it has a value or a sign already; returns
    /// whether the slot's sign is now the one given (`negative` or not).
    #[inline]
    fn set_sign(&mut self, s: usize, negative: bool) -> bool {
        let state = &mut self.state[s];
        if *state == PointState::UNKNOWN {
            *state = PointState::inferred(negative);
        }
        state.is_negative() == negative
    }

    /// [`Store::set_sign`] for the points in `neg` (negative) and then those in `pos` of the
    /// block of 2 × 2 × 2 cells with lower corner `o` (bits as in [`block_point`]); returns
    /// whether every point's sign is now the one given.
    #[inline]
    fn set_block_signs(&mut self, o: [u32; 3], neg: u32, pos: u32) -> bool {
        // The slots of the whole block, when it lies in the brick of `o` (as in claim_block).
        let base = o
            .iter()
            .all(|&c| c & (BRICK - 1) <= BRICK - 3)
            .then(|| self.slot_mut(o));
        let mut agreed = true;
        for (m, negative) in [(neg, true), (pos, false)] {
            let mut m = m;
            while m != 0 {
                let p = m.trailing_zeros() as usize;
                m &= m - 1;
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
    fn block_indices(&self, o: [u32; 3], wanted: u32) -> ([u32; 27], u32) {
        let mut idx = [NONE; 27];
        let mut negative = 0;
        if wanted == 0 {
            // (The brick of `o` may have no slots.)
            return (idx, negative);
        }
        // The slots of the whole block, when it lies in the brick of `o` (as in claim_block).
        let base = o.iter().all(|&c| c & (BRICK - 1) <= BRICK - 3).then(|| {
            let (t, l) = self.locate(o);
            self.table[t] as usize * BRICK_POINTS + l
        });
        let mut m = wanted;
        while m != 0 {
            let p = m.trailing_zeros() as usize;
            m &= m - 1;
            let s = base.map_or_else(
                || {
                    let (t, l) = self.locate(block_offset(o, p));
                    self.table[t] as usize * BRICK_POINTS + l
                },
                |b| b + BLOCK_SLOTS[p],
            );
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
    fn known(&self, p: [u32; 3], cells: [u32; 3]) -> Option<f64> {
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
    fn block_map<T: Copy>(
        &self,
        o: [u32; 3],
        cells: [u32; 3],
        outside: T,
        read: impl Fn(usize) -> T,
    ) -> [T; 27] {
        let whole = (0..3).all(|a| o[a] & (BRICK - 1) <= BRICK - 3 && o[a] + 2 <= cells[a]);
        let (t, l) = self.locate(o);
        let b = self.table[t];
        if whole && b != NONE {
            // The whole block in the brick of `o` (as in claim_block).
            let s = b as usize * BRICK_POINTS + l;
            return std::array::from_fn(|p| read(s + BLOCK_SLOTS[p]));
        }
        // Across bricks: per axis, the brick and offset of the block's three coordinates (None
        // beyond the lattice), then one table lookup per brick touched.
        let axis = |a: usize| -> [Option<(usize, usize)>; 3] {
            std::array::from_fn(|i| {
                let c = o[a] + i as u32;
                (c <= cells[a]).then_some(((c >> BRICK_BITS) as usize, (c & (BRICK - 1)) as usize))
            })
        };
        let (ax, ay, az) = (axis(0), axis(1), axis(2));
        let mut v = [outside; 27];
        for (k, z) in az.iter().enumerate() {
            let Some((bz, lz)) = *z else { continue };
            for (j, y) in ay.iter().enumerate() {
                let Some((by, ly)) = *y else { continue };
                let row = self.dims[0] * (by + self.dims[1] * bz);
                let lrow = (ly << BRICK_BITS) | (lz << (2 * BRICK_BITS));
                for (i, x) in ax.iter().enumerate() {
                    let Some((bx, lx)) = *x else { continue };
                    let b = self.table[row + bx];
                    if b != NONE {
                        v[i + 3 * j + 9 * k] = read(b as usize * BRICK_POINTS + (lrow | lx));
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
    fn leaf_block_states(&self, o: [u32; 3], centre: u32, cells: [u32; 3]) -> [PointState; 27] {
        let mut v = self.block_map(o, cells, PointState::UNKNOWN, |s| self.state[s]);
        if centre != NONE {
            v[CENTRE] = PointState::of_value(self.values[centre as usize]);
        }
        v
    }

    /// The values known at the 27 points of a block of leaves, as [`Store::leaf_block_states`]
    /// (NaN where no value is known).
    fn leaf_block_values(&self, o: [u32; 3], centre: u32, cells: [u32; 3]) -> [f64; 27] {
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
    fn stored(wanted: u32, centre: u32) -> u32 {
        if centre != NONE {
            wanted & !(1 << CENTRE)
        } else {
            wanted
        }
    }

    /// Evaluates `points` (queued by [`Store::claim`]) in batches and appends their values.
    fn evaluate<F: Field + ?Sized>(
        &mut self,
        field: &F,
        points: &[DVec3],
        settings: &super::Settings,
        stats: &mut Stats,
    ) -> Result<()> {
        let start = self.values.len();
        if start + points.len() >= MAX_VALUES {
            return Err(crate::Error::TooMuchMemory {
                name: "resolution",
                needed_mib: ((start + points.len()) as u64 * 8).div_ceil(1 << 20),
                limit_mib: (MAX_VALUES as u64 * 8) >> 20,
            });
        }
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

/// The items whose `kept` entry is 1 (the others' are 0), in order, gathered in parallel.
fn kept_items<T: Copy + Send + Sync>(items: &[T], kept: &[u32]) -> Vec<T> {
    crate::memory::collect_counted(kept, |i| (kept[i] != 0).then_some(items[i]))
}

/// Lattice point of corner `k` of the cell with lower corner `o`.
#[inline]
fn corner(o: [u32; 3], k: usize) -> [u32; 3] {
    let d = corner_offset(k);
    [o[0] + d[0], o[1] + d[1], o[2] + d[2]]
}

/// Lattice point of corner `k` of the block of `s` cells per side with lower corner `o`.
#[inline]
fn corner_scaled(o: [u32; 3], k: usize, s: u32) -> [u32; 3] {
    let d = corner_offset(k);
    [o[0] + d[0] * s, o[1] + d[1] * s, o[2] + d[2] * s]
}

/// The set bits of a mask (of children, or of block points), in increasing order.
#[inline]
fn bits(m: impl Into<u32>) -> impl Iterator<Item = usize> {
    let mut m = m.into();
    std::iter::from_fn(move || {
        (m != 0).then(|| {
            let p = m.trailing_zeros() as usize;
            m &= m - 1;
            p
        })
    })
}

/// Lattice point of block point `p` (see [`block_point`]) of the block with lower corner `o`.
#[inline]
fn block_offset(o: [u32; 3], p: usize) -> [u32; 3] {
    [
        o[0] + (p % 3) as u32,
        o[1] + ((p / 3) % 3) as u32,
        o[2] + (p / 9) as u32,
    ]
}

/// Levels of octant splitting with which [`covered`] tries to prove a box free of the surface
/// (the finest pieces are 1/8 of the box per side).
const COVER_DEPTH: u32 = 3;

/// Whether the balls around the box's corners cover it: corner k (case-bit order) of the box
/// `[0, size]` carries a ball of radius `radius[k]` (NaN: no ball). Under the same assumption as
/// the rejection test (|f| under-estimates the distance to the surface, so no surface point lies
/// within |f(x)|/safety of x), a covered box holds no surface. Proven by splitting the box into
/// octants, down to [`COVER_DEPTH`] levels: a piece is covered when one ball holds all of it.
fn covered(radius: &[f64; 8], size: DVec3) -> bool {
    // The box's centre is as far as half the diagonal from every corner: without a ball that
    // reaches it, nothing is covered (the common case near the surface, decided here).
    let reach = radius
        .iter()
        .fold(0.0f64, |m, &r| if r > m { r } else { m });
    if reach * reach <= 0.25 * size.length_squared() {
        return false;
    }
    // The balls there are (NaN radius: none), as centres and squared radii.
    let mut balls = [(DVec3::ZERO, 0.0); 8];
    let mut n = 0;
    for (k, &r) in radius.iter().enumerate() {
        if r > 0.0 {
            let d = corner_offset(k);
            balls[n] = (
                DVec3::new(d[0] as f64, d[1] as f64, d[2] as f64) * size,
                r * r,
            );
            n += 1;
        }
    }
    let balls = &balls[..n];
    // Two balls at opposite corners (a leaf before its other corners are known: its parent
    // corner and its block's centre): decided exactly.
    if n == 2 {
        let k = (0..8).find(|&k| radius[k] > 0.0).unwrap();
        if radius[7 - k] > 0.0 {
            return covered_by_opposite_balls(radius[k], radius[7 - k], size);
        }
    }
    // Necessary: every corner of the box lies in a ball (the centre does, by the test above).
    let inside = |p: DVec3| balls.iter().any(|&(c, r2)| (p - c).length_squared() < r2);
    if !(0..8).all(|k| {
        let d = corner_offset(k);
        inside(DVec3::new(d[0] as f64, d[1] as f64, d[2] as f64) * size)
    }) {
        return false;
    }
    covered_piece(balls, (1u32 << n) - 1, DVec3::ZERO, size, COVER_DEPTH)
}

/// Whether the open balls of radius `r0` around the corner 0 of the box `[0, size]` and `r1`
/// around the opposite corner `size` cover the box, exactly. Outside the first ball, the point
/// of the box farthest from `size` lies on the first ball's sphere (moving any coordinate
/// towards 0 takes a point farther from `size`), and on the sphere's patch inside the box it
/// has at most one coordinate strictly between its bounds (along an arc between two such
/// coordinates the distance to `size` is largest at an end). So the candidates are the patch's
/// points with two coordinates at 0 or at `size`, the third from the sphere.
fn covered_by_opposite_balls(r0: f64, r1: f64, size: DVec3) -> bool {
    let far = size.length_squared();
    if far < r0 * r0 || far < r1 * r1 {
        return true;
    }
    let c = size.to_array();
    let mut worst = 0.0f64;
    for free in 0..3 {
        let (i, j) = ((free + 1) % 3, (free + 2) % 3);
        for (xi, xj) in [(0.0, 0.0), (c[i], 0.0), (0.0, c[j]), (c[i], c[j])] {
            let rest = r0 * r0 - xi * xi - xj * xj;
            if rest < 0.0 {
                continue;
            }
            let xf = rest.sqrt();
            if xf > c[free] {
                continue;
            }
            let d2 = (c[free] - xf).powi(2) + (c[i] - xi).powi(2) + (c[j] - xj).powi(2);
            worst = worst.max(d2);
        }
    }
    // A margin for the rounding above (the argument itself is exact).
    worst * (1.0 + 1e-9) < r1 * r1
}

/// Whether one of the balls in `mask` holds all of the piece `[lo, hi]`, or (splitting it,
/// `depth` more times) each of its octants is covered; balls that miss the piece are dropped
/// on the way down.
fn covered_piece(balls: &[(DVec3, f64)], mask: u32, lo: DVec3, hi: DVec3, depth: u32) -> bool {
    let mid = 0.5 * (lo + hi);
    let (mut mid_covered, mut touching) = (false, 0u32);
    let mut m = mask;
    while m != 0 {
        let i = m.trailing_zeros();
        m &= m - 1;
        let (c, r2) = balls[i as usize];
        let far = (hi - c).abs().max((lo - c).abs());
        if far.length_squared() < r2 {
            return true;
        }
        // The piece's point nearest to the ball's centre.
        if (c.clamp(lo, hi) - c).length_squared() < r2 {
            touching |= 1 << i;
            mid_covered |= (mid - c).length_squared() < r2;
        }
    }
    // The piece's centre not covered: the piece is not.
    if depth == 0 || !mid_covered {
        return false;
    }
    (0..8).all(|k| {
        let d = corner_offset(k);
        let pick = |a: usize| {
            if d[a] == 0 {
                (lo[a], mid[a])
            } else {
                (mid[a], hi[a])
            }
        };
        let (x, y, z) = (pick(0), pick(1), pick(2));
        covered_piece(
            balls,
            touching,
            DVec3::new(x.0, y.0, z.0),
            DVec3::new(x.1, y.1, z.1),
            depth - 1,
        )
    })
}

/// The values known at a block's corners during the levels: at most two, at opposite corners.
/// A centre lies inside its block, so the coarser centres on a block's corners are those of its
/// ancestors: its parent's centre, at the corner opposite to the one it shares with its parent,
/// and whatever the parent knew at that shared corner.
#[derive(Clone, Copy)]
struct KnownCorners {
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
    fn block_points(&self, values: &[f64], centre: u32) -> [(usize, f64); 3] {
        let at = |k: usize| {
            let d = corner_offset(k);
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

/// `SHARED[k]`: the points of a block of 2 × 2 × 2 cells (bits as in [`block_point`]) that it
/// shares with its neighbour at offset `d` ∈ {−1, 0, 1}³, `k = (d.x + 1) + 3 (d.y + 1) +
/// 9 (d.z + 1)`: along an axis with offset −1 its points at 0, with +1 those at 2.
const SHARED: [u32; 27] = {
    let mut t = [0; 27];
    let mut k = 0;
    while k < 27 {
        let d = [k % 3, (k / 3) % 3, k / 9];
        let mut p = 0;
        while p < 27 {
            let c = [p % 3, (p / 3) % 3, p / 9];
            let mut shared = true;
            let mut a = 0;
            while a < 3 {
                // Offset −1 (d = 0) shares coordinate 0; +1 (d = 2) coordinate 2.
                shared &= d[a] == 1 || (d[a] == 0 && c[a] == 0) || (d[a] == 2 && c[a] == 2);
                a += 1;
            }
            if shared {
                t[k] |= 1 << p;
            }
            p += 1;
        }
        k += 1;
    }
    t
};

/// The signs of the blocks of 2 × 2 × 2 cells that the levels decided hold no surface: inside a
/// block rejected by its centre's value (whose ball, of radius |f| / safety beyond the block's
/// circumradius, holds the whole block) or covered by its corners' balls, at any level. Every
/// lattice point of such a block has the sign decided, so the leaves' corners on the faces,
/// edges and corners they share with decided neighbours need no evaluation. One byte per block
/// (a 128³ lattice: 262 kB): 0 kept, 1 negative, 2 positive, 3 dropped without a sign (its
/// known corners disagreed, which the premise rules out). The repair reads which blocks were
/// dropped ([`DecidedBlocks::dropped`]).
struct DecidedBlocks {
    dims: [usize; 3],
    sign: Vec<u8>,
}

impl DecidedBlocks {
    fn dims(lattice: &Lattice) -> [usize; 3] {
        lattice.cells.map(|c| c.div_ceil(2) as usize)
    }

    fn bytes(lattice: &Lattice) -> u64 {
        Self::dims(lattice).iter().map(|&d| d as u64).product()
    }

    /// The map of `lattice`, all kept.
    fn new(lattice: &Lattice) -> Self {
        let dims = Self::dims(lattice);
        DecidedBlocks {
            dims,
            sign: vec![0; dims.iter().product()],
        }
    }

    /// The byte of a block dropped with sign `sign` (`None`: unknown).
    #[inline]
    fn code(sign: Option<bool>) -> u8 {
        match sign {
            Some(true) => 1,
            Some(false) => 2,
            None => 3,
        }
    }

    /// Whether cell `o` of the lattice lies in a block the levels dropped.
    #[inline]
    fn dropped(&self, o: [u32; 3]) -> bool {
        let b = o.map(|c| (c / 2) as usize);
        self.sign[b[0] + self.dims[0] * (b[1] + self.dims[1] * b[2])] != 0
    }

    /// Marks the block of `s` cells per side (s ≥ 2) with lower corner `o` (clipped to the
    /// lattice) as dropped, holding points of sign `negative` only (`None`: unknown).
    #[inline]
    fn mark(&mut self, o: [u32; 3], s: u32, negative: Option<bool>) {
        let lo = o.map(|c| (c / 2) as usize);
        let v = Self::code(negative);
        if s == 2 {
            // One entry: most marks are of the last level's blocks.
            if (0..3).all(|a| lo[a] < self.dims[a]) {
                self.sign[lo[0] + self.dims[0] * (lo[1] + self.dims[1] * lo[2])] = v;
            }
            return;
        }
        let hi: [usize; 3] = std::array::from_fn(|a| (lo[a] + (s / 2) as usize).min(self.dims[a]));
        for z in lo[2]..hi[2] {
            for y in lo[1]..hi[1] {
                let row = self.dims[0] * (y + self.dims[1] * z);
                if lo[0] < hi[0] {
                    self.sign[row + lo[0]..row + hi[0]].fill(v);
                }
            }
        }
    }

    /// Marks `blocks[i]` (blocks of `s` cells per side) as [`DecidedBlocks::mark`] does with
    /// `negative` where `sign(i)` is `Some(negative)` (the block dropped); in parallel for the
    /// last level's blocks (s = 2, one byte each, and most of the marks).
    fn mark_blocks(
        &mut self,
        blocks: &[[u32; 3]],
        s: u32,
        sign: impl Fn(usize) -> Option<Option<bool>> + Sync,
    ) {
        if s != 2 {
            for (i, &o) in blocks.iter().enumerate() {
                if let Some(negative) = sign(i) {
                    self.mark(o, s, negative);
                }
            }
            return;
        }
        let dims = self.dims;
        let map = atomic_u8s(&mut self.sign);
        blocks
            .par_iter()
            .enumerate()
            .with_min_len(4096)
            .for_each(|(i, &o)| {
                if let Some(negative) = sign(i) {
                    let b = o.map(|c| (c / 2) as usize);
                    if (0..3).all(|a| b[a] < dims[a]) {
                        let at = b[0] + dims[0] * (b[1] + dims[1] * b[2]);
                        map[at].store(Self::code(negative), Relaxed);
                    }
                }
            });
    }

    /// The points of the block of 2 × 2 × 2 cells with lower corner `o` that lie in decided
    /// neighbours: (negative, positive), bits as in [`block_point`].
    #[inline]
    fn masks(&self, o: [u32; 3]) -> (u32, u32) {
        let b = o.map(|c| (c / 2) as usize);
        let (mut neg, mut pos) = (0, 0);
        if (0..3).all(|a| b[a] >= 1 && b[a] + 1 < self.dims[a]) {
            // All 26 neighbours in the map: three rows of three per plane, without branches.
            let (dx, dxy) = (self.dims[0], self.dims[0] * self.dims[1]);
            let first = (b[0] - 1) + dx * (b[1] - 1) + dxy * (b[2] - 1);
            for z in 0..3 {
                for y in 0..3 {
                    let at = first + dx * y + dxy * z;
                    let row: &[u8; 3] = self.sign[at..at + 3].try_into().unwrap();
                    for (x, &v) in row.iter().enumerate() {
                        let shared = SHARED[x + 3 * y + 9 * z];
                        neg |= shared & 0u32.wrapping_sub((v == 1) as u32);
                        pos |= shared & 0u32.wrapping_sub((v == 2) as u32);
                    }
                }
            }
            return (neg, pos);
        }
        self.masks_at_edge(o)
    }

    /// [`DecidedBlocks::masks`] for any block, neighbours beyond the map included (none).
    fn masks_at_edge(&self, o: [u32; 3]) -> (u32, u32) {
        let b = o.map(|c| (c / 2) as usize);
        let (mut neg, mut pos) = (0, 0);
        for dz in 0..3 {
            let Some(z) = (b[2] + dz).checked_sub(1).filter(|&z| z < self.dims[2]) else {
                continue;
            };
            for dy in 0..3 {
                let Some(y) = (b[1] + dy).checked_sub(1).filter(|&y| y < self.dims[1]) else {
                    continue;
                };
                let row = self.dims[0] * (y + self.dims[1] * z);
                for dx in 0..3 {
                    let Some(x) = (b[0] + dx).checked_sub(1).filter(|&x| x < self.dims[0]) else {
                        continue;
                    };
                    let shared = SHARED[dx + 3 * dy + 9 * dz];
                    match self.sign[row + x] {
                        1 => neg |= shared,
                        2 => pos |= shared,
                        _ => {}
                    }
                }
            }
        }
        (neg, pos)
    }
}

/// The block points within a distance of a block point: the ball of radius |f(p)| / safety
/// around point p holds the points `mask` of the last entry of `REACH[p]` whose `reach` is below
/// f(p)² (the distances, squared and times safety², in increasing order, each once).
#[derive(Clone, Copy)]
struct Reach {
    reach: f64,
    mask: u32,
}

/// [`Reach`] lists for the 27 points of a block of cells of size `cell`: at most 26 entries
/// each (9 for cubic cells), ended by an entry of infinite reach.
fn block_reach(cell: DVec3, safety: f64) -> Box<[[Reach; 27]; 27]> {
    let at = |p: usize| DVec3::new((p % 3) as f64, ((p / 3) % 3) as f64, (p / 9) as f64) * cell;
    let end = Reach {
        reach: f64::INFINITY,
        mask: 0,
    };
    let mut t = Box::new([[end; 27]; 27]);
    for (p, row) in t.iter_mut().enumerate() {
        let mut others: Vec<(f64, usize)> = (0..27)
            .filter(|&q| q != p)
            .map(|q| (safety * safety * (at(p) - at(q)).length_squared(), q))
            .collect();
        others.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (mut n, mut mask) = (0, 0);
        for (i, &(reach, q)) in others.iter().enumerate() {
            mask |= 1 << q;
            // One entry per distance: the mask of all points up to it.
            if others.get(i + 1).is_none_or(|next| next.0 > reach) {
                row[n] = Reach { reach, mask };
                n += 1;
            }
        }
    }
    t
}

/// The block points whose sign is known (bit per point) from their states: (negative, zero or
/// positive, the signs inferred without a value).
#[inline]
fn sign_masks(states: &[PointState; 27]) -> (u32, u32, u32) {
    let (mut neg, mut pos, mut inferred) = (0, 0, 0);
    for (p, &x) in states.iter().enumerate() {
        neg |= (x.is_negative() as u32) << p;
        pos |= (x.is_positive() as u32) << p;
        inferred |= (x.is_inferred() as u32) << p;
    }
    (neg, pos, inferred)
}

/// [`balls`] of the points of `known` with the values `v` (bits and indices as in
/// [`block_point`]).
#[cfg(test)]
fn ball_masks(v: &[f64; 27], known: u32, reach: &[[Reach; 27]; 27]) -> (u32, u32) {
    balls(bits(known).map(|p| (p, v[p])), reach)
}

/// The block points inside the balls of the values known in the block, `known` as (block
/// point, value; NaN where there is none): (inside a ball of a negative value, inside a ball of
/// a positive value). No surface lies within |f(p)| / safety of a point p (the rejection test's
/// premise), so a point in that ball has the sign of f(p).
#[inline]
fn balls(known: impl Iterator<Item = (usize, f64)>, reach: &[[Reach; 27]; 27]) -> (u32, u32) {
    let (mut neg, mut pos) = (0, 0);
    for (p, x) in known {
        // Points without a value (NaN) have no ball.
        if !x.is_finite() {
            continue;
        }
        let r2 = x * x;
        let mut m = 0;
        for r in &reach[p] {
            if r2 <= r.reach {
                break;
            }
            m = r.mask;
        }
        if x < 0.0 {
            neg |= m;
        } else {
            pos |= m;
        }
    }
    (neg, pos)
}

/// The ends of the crossed edges of leaf `d` whose values are not known, only their signs
/// (bits of block points: `neg` the negative ones, `inferred` those with a sign only).
#[inline]
fn unknown_edge_ends(neg: u32, inferred: u32, d: usize) -> u32 {
    let (mut negative, mut only_sign) = (0, 0);
    for (k, &p) in LEAF_CORNERS[d].iter().enumerate() {
        negative |= (((neg >> p) & 1) as usize) << k;
        only_sign |= (((inferred >> p) & 1) as u8) << k;
    }
    bits(CROSSED_EDGE_ENDS[negative] & only_sign).fold(0, |need, k| need | 1 << LEAF_CORNERS[d][k])
}

/// `CROSSED_EDGE_ENDS[c]`: the corners of a cell with case `c` (bit k set: corner k negative)
/// that end a crossed edge (one whose ends differ in sign).
const CROSSED_EDGE_ENDS: [u8; 256] = {
    let mut t = [0; 256];
    let mut c = 0;
    while c < 256 {
        let mut e = 0;
        while e < 12 {
            let [a, b] = EDGES[e];
            if (c >> a) & 1 != (c >> b) & 1 {
                t[c] |= 1 << a | 1 << b;
            }
            e += 1;
        }
        c += 1;
    }
    t
};

/// The ends of crossed edges to evaluate, as (block, block points), and whether two blocks
/// inferred different signs for a point (the premise failing; the first sign is kept, so the
/// other block's leaves were decided with signs the store does not have).
#[derive(Default)]
struct Ends {
    blocks: Vec<(u32, u32)>,
    disagreed: bool,
    /// Where the premise failed, for the repair.
    suspects: repair::Suspects,
}

/// One settling step of the leaves: signs are inferred ([`balls`]) for the corners the undecided
/// leaves in `masks` need (a point in balls of both signs, where the premise fails, gets none),
/// then every leaf whose corners all have a sign leaves `masks`: into `crossed` when they have
/// both signs, nowhere when they have one. The signs inferred are stored in the points' states,
/// and the blocks of the leaves newly crossed are added to `ends` with the ends of their
/// crossed edges that have a sign but no value.
#[allow(clippy::too_many_arguments)]
fn settle_leaves(
    store: &mut Store,
    (blocks, centres): (&[[u32; 3]], &[u32]),
    masks: &mut [u8],
    crossed: &mut [u8],
    open: &mut [u32],
    reach: &[[Reach; 27]; 27],
    cells: [u32; 3],
    first: Option<(&DecidedBlocks, &[KnownCorners])>,
    ends: &mut Ends,
) {
    // Per block: the signs inferred (negative, positive) and the crossed edges' ends wanted.
    let found: Vec<(u32, u32, u32, u32)> = {
        let store = &*store;
        blocks
            .par_iter()
            .zip(masks.par_iter_mut().zip(crossed.par_iter_mut()))
            .zip(open.par_iter_mut())
            .enumerate()
            .with_min_len(256)
            .filter_map(|(i, ((&o, (m, x)), open))| {
                if *m == 0 {
                    return None;
                }
                // Before any leaf is settled, the store holds only the levels' values, which the
                // blocks carry (`known`: the centre and two corners at most); after, the
                // states are read from the store.
                let values = first.map(|(_, known)| {
                    let v = known[i].block_points(&store.values, centres[i]);
                    debug_assert!(v.iter().all(|&(p, x)| {
                        let y = store.leaf_block_values(o, centres[i], cells)[p];
                        x.to_bits() == y.to_bits() || y.is_nan()
                    }));
                    v
                });
                let (mut neg, mut pos, mut inferred) = match &values {
                    Some(v) => v.iter().fold((0, 0, 0), |(n, p, i), &(q, x)| {
                        (n | ((x < 0.0) as u32) << q, p | ((x >= 0.0) as u32) << q, i)
                    }),
                    None => sign_masks(&store.leaf_block_states(o, centres[i], cells)),
                };
                let unknown = LEAF_POINTS[*m as usize] & !(neg | pos);
                let (mut n, mut p) = (0, 0);
                if unknown != 0 {
                    let (mut bn, mut bp) = match &values {
                        Some(v) => balls(v.iter().copied(), reach),
                        // (After the first settling, every point without a sign was evaluated.)
                        None => {
                            let v = store.leaf_block_values(o, centres[i], cells);
                            balls(bits(neg | pos).map(|q| (q, v[q])), reach)
                        }
                    };
                    if let Some((decided, _)) = first {
                        let (dn, dp) = decided.masks(o);
                        (bn, bp) = (bn | dn, bp | dp);
                    }
                    (n, p) = (unknown & bn & !bp, unknown & bp & !bn);
                    neg |= n;
                    pos |= p;
                    inferred |= n | p;
                }
                let mut need = 0;
                for d in bits(*m) {
                    let corners = LEAF_POINTS[1 << d];
                    if corners & !(neg | pos) == 0 {
                        *m &= !(1 << d);
                        if corners & neg != 0 && corners & pos != 0 {
                            *x |= 1 << d;
                            need |= unknown_edge_ends(neg, inferred, d);
                        }
                    }
                }
                *open = LEAF_POINTS[*m as usize] & !(neg | pos);
                (n | p | need != 0).then_some((i as u32, n, p, need))
            })
            .collect()
    };
    // Stored in parallel. Two blocks infer different signs for a point only where the premise
    // fails; then the signs are stored again one block after another, the first sign kept (as
    // it would be whatever the threads do), and the edge ends are served again.
    let mut state_owned = std::mem::take(&mut store.state);
    let agreed = {
        let (st, state) = (&*store, atomic_states(&mut state_owned));
        found.par_iter().with_min_len(256).all(|&(i, neg, pos, _)| {
            let o = blocks[i as usize];
            let mut agreed = true;
            for (m, negative) in [(neg, true), (pos, false)] {
                let inferred = PointState::inferred(negative).0;
                let unknown = PointState::UNKNOWN.0;
                for (s, _) in st.block_slots(o, m) {
                    // Most points are shared: a plain read first spares the atomic write
                    // where a neighbour stored the sign already.
                    let mut v = state[s].load(Relaxed);
                    if v == unknown {
                        match state[s].compare_exchange(unknown, inferred, Relaxed, Relaxed) {
                            Ok(_) => continue,
                            Err(now) => v = now,
                        }
                    }
                    agreed &= PointState(v).is_negative() == negative;
                }
            }
            agreed
        })
    };
    store.state = state_owned;
    if !agreed {
        // Every point inferred here was unknown before.
        for &(i, neg, pos, _) in &found {
            let slots: Vec<usize> = store
                .block_slots(blocks[i as usize], neg | pos)
                .map(|(s, _)| s)
                .collect();
            for s in slots {
                store.state[s] = PointState::UNKNOWN;
            }
        }
        for &(i, neg, pos, _) in &found {
            let o = blocks[i as usize];
            if !store.set_block_signs(o, neg, pos) {
                ends.disagreed = true;
                ends.suspects.blocks.push(o);
            }
        }
    }
    ends.blocks.extend(
        found
            .iter()
            .filter(|f| f.3 != 0)
            .map(|&(i, _, _, need)| (i, need)),
    );
}

/// Evaluates the ends of the crossed leaves' crossed edges that have only an inferred sign
/// (edge vertices need both values): first those in `ends` (block, block points), which
/// [`settle_leaves`] listed. Should a value contradict its inferred sign, or two blocks have
/// inferred different signs (the premise failing either way), cases change, and the crossed
/// leaves (`leaves`: the blocks and their masks of crossed children) are searched for crossed
/// edges with an end still unknown, until none is left.
fn evaluate_crossed_edge_ends<F: Field + ?Sized>(
    field: &F,
    lattice: &Lattice,
    store: &mut Store,
    leaves: (&[[u32; 3]], &[u32], &[u8]),
    ends: Ends,
    settings: &super::Settings,
    stats: &mut Stats,
) -> Result<repair::Suspects> {
    let (cells, (blocks, centres, crossed)) = (lattice.cells, leaves);
    let (mut ends, mut disagreed, mut suspects) = (ends.blocks, ends.disagreed, ends.suspects);
    while !ends.is_empty() || disagreed {
        let mut taken = Vec::new();
        let mut points = Vec::new();
        for (i, need) in ends {
            let o = blocks[i as usize];
            let mut m = need;
            while m != 0 {
                let p = block_offset(o, m.trailing_zeros() as usize);
                m &= m - 1;
                let s = store.slot_mut(p);
                // A point two blocks share is taken once (queued until evaluated below).
                let state = store.state[s];
                if state.is_inferred() {
                    store.state[s] = PointState::QUEUED;
                    taken.push((s, state.is_negative(), p));
                    points.push(lattice.point(p));
                }
            }
        }
        let mut values = vec![0.0; points.len()];
        evaluate(field, &points, &mut values, settings.batch)?;
        stats.evaluations += points.len() as u64;
        if store.values.len() + values.len() >= MAX_VALUES {
            return Err(crate::Error::TooMuchMemory {
                name: "resolution",
                needed_mib: ((store.values.len() + values.len()) as u64 * 8).div_ceil(1 << 20),
                limit_mib: (MAX_VALUES as u64 * 8) >> 20,
            });
        }
        let mut contradicted = false;
        for (&(s, negative, p), v) in taken.iter().zip(values) {
            if (v < 0.0) != negative {
                contradicted = true;
                suspects.points.push(p);
            }
            store.state[s] = PointState::of_value(v);
            store.slots[s] = store.values.len() as u32;
            store.values.push(v);
        }
        // Without contradictions, the cases are those the ends were listed for.
        if !contradicted && !std::mem::take(&mut disagreed) {
            break;
        }
        let store = &*store;
        ends = blocks
            .par_iter()
            .zip(crossed.par_iter())
            .enumerate()
            .filter_map(|(i, (&o, &x))| {
                let (neg, _, inferred) = sign_masks(&store.leaf_block_states(o, centres[i], cells));
                let need = bits(x).fold(0, |n, d| n | unknown_edge_ends(neg, inferred, d));
                (need != 0).then_some((i as u32, need))
            })
            .collect();
    }
    Ok(suspects)
}

/// A leaf cell the surface crosses: its lowest lattice point, the value indices of its corners
/// (or [`NEGATIVE`] / [`POSITIVE`] for corners with a sign only) and its case.
struct CrossedLeaf {
    origin: [u32; 3],
    corners: [u32; 8],
    case: u8,
}

/// The triangles of the crossed leaves, with a vertex on each crossed edge, made in parallel
/// but numbered as the serial loop over the leaves would number them: each edge vertex in the
/// order of its first use (by leaf, then triangle, then edge). The first leaf that uses an edge
/// (found with `fetch_min` on the edge's entry, keyed by the value index of its lower end and
/// its axis) makes its vertex; the leaves' counts of vertices made give where each leaf's
/// vertices start.
fn triangulate(
    table: &CaseTable,
    lattice: &Lattice,
    values: &[f64],
    leaves: &[CrossedLeaf],
) -> Mesh {
    // The cell edges each case's triangles use.
    let used: [u16; 256] = std::array::from_fn(|c| {
        table
            .triangles(c as u8)
            .iter()
            .flatten()
            .fold(0, |m, &e| m | 1 << e)
    });
    let key = |l: &CrossedLeaf, e: usize| {
        3 * l.corners[EDGES[e][0] as usize] as usize + EDGE_AXIS[e] as usize
    };
    // Per edge: the first leaf that uses it, then (once the leaves have their vertices) its
    // vertex.
    let mut entries = vec![NONE; 3 * values.len()];
    let entry = atomic_u32s(&mut entries);
    leaves
        .par_iter()
        .enumerate()
        .with_min_len(1024)
        .for_each(|(i, l)| {
            let i = i as u32;
            let mut m = used[l.case as usize];
            while m != 0 {
                let e = m.trailing_zeros() as usize;
                m &= m - 1;
                let a = &entry[key(l, e)];
                if a.load(Relaxed) > i {
                    a.fetch_min(i, Relaxed);
                }
            }
        });
    // The edges each leaf makes the vertex of.
    let makes: Vec<u16> = leaves
        .par_iter()
        .enumerate()
        .with_min_len(1024)
        .map(|(i, l)| {
            let mut made = 0;
            let mut m = used[l.case as usize];
            while m != 0 {
                let e = m.trailing_zeros() as usize;
                m &= m - 1;
                if entry[key(l, e)].load(Relaxed) == i as u32 {
                    made |= 1 << e;
                }
            }
            made
        })
        .collect();
    // Where each leaf's vertices start, and how many vertices and triangles each makes.
    let mut start = Vec::with_capacity(leaves.len());
    let mut made_count = Vec::with_capacity(leaves.len());
    let mut n = 0u32;
    for m in &makes {
        start.push(n);
        made_count.push(m.count_ones());
        n += m.count_ones();
    }
    let triangle_count: Vec<u32> = leaves
        .iter()
        .map(|l| table.triangles(l.case).len() as u32)
        .collect();
    let vertices: Vec<DVec3> = crate::memory::collect_counted(&made_count, |i| {
        let (l, made, first) = (&leaves[i], makes[i], start[i]);
        // The vertices in order of first use in the leaf's triangles.
        let mut order = [0u8; 12];
        let (mut k, mut left) = (0, made);
        for t in table.triangles(l.case) {
            for &e in t {
                if left & 1 << e != 0 {
                    left &= !(1 << e);
                    order[k] = e;
                    entry[key(l, e as usize)].store(first + k as u32, Relaxed);
                    k += 1;
                }
            }
        }
        (0..k).map(move |j| {
            let [ka, kb] = EDGES[order[j] as usize].map(|k| k as usize);
            let (fa, fb) = (
                values[l.corners[ka] as usize],
                values[l.corners[kb] as usize],
            );
            edge_crossing(
                lattice.point(corner(l.origin, ka)),
                lattice.point(corner(l.origin, kb)),
                fa,
                fb,
            )
        })
    });
    let triangles: Vec<[u32; 3]> = crate::memory::collect_counted(&triangle_count, |i| {
        let l = &leaves[i];
        table
            .triangles(l.case)
            .iter()
            .map(move |t| t.map(|e| entry[key(l, e as usize)].load(Relaxed)))
    });
    Mesh {
        vertices,
        triangles,
        ..Default::default()
    }
}

/// Polygonizes `field` over `lattice` with hierarchical rejection; leaves are single cells.
pub fn polygonize<F: Field + ?Sized>(
    field: &F,
    lattice: &Lattice,
    settings: &super::Settings,
    octree: &Settings,
) -> Result<(Mesh, Stats)> {
    if !(octree.safety.is_finite() && octree.safety > 0.0) {
        return Err(crate::Error::invalid(
            "safety",
            format!("must be positive and finite, got {}", octree.safety),
        ));
    }
    // Output, working memory (see BYTES_PER_TRIANGLE_STORE), the brick table and the decided
    // blocks' signs.
    check_memory(
        estimate_triangles(lattice)
            .saturating_mul(super::BYTES_PER_TRIANGLE + BYTES_PER_TRIANGLE_STORE)
            .saturating_add(Store::table_bytes(lattice))
            .saturating_add(DecidedBlocks::bytes(lattice)),
        settings.memory_limit,
    )?;

    let table = CaseTable::get(settings.ambiguity);
    let mut stats = Stats {
        lattice_points: lattice.num_points(),
        ..Default::default()
    };
    let cells = lattice.cells;
    let inside = |o: [u32; 3]| o[0] < cells[0] && o[1] < cells[1] && o[2] < cells[2];
    let levels = levels(lattice);
    let mut store = Store::new(lattice);
    let mut points: Vec<DVec3> = Vec::new();
    let mut decided = DecidedBlocks::new(lattice);
    // The value indices of the kept blocks' centres at the last level (blocks of 2 × 2 × 2
    // cells), when that level was tested.
    let mut centres: Vec<u32> = Vec::new();

    // Blocks of the current level, by their lowest lattice corner.
    let largest = *cells.iter().max().unwrap();
    let start_level = octree.start_level.unwrap_or_else(|| {
        (1..=levels)
            .find(|&l| 8 * (1u32 << (levels - l)) <= largest)
            .unwrap_or(levels)
    });
    let mut blocks: Vec<[u32; 3]> = vec![[0, 0, 0]];
    // Per block: the values known at its corners, and (once tested) at its centre.
    let mut known = vec![KnownCorners::NONE];
    // The indices of the values of the kept blocks' centres, once tested.
    let mut centre_values: Vec<u32> = Vec::new();
    for level in 0..levels {
        let s = 1u32 << (levels - level);
        if level >= start_level {
            let t = Instant::now();
            if octree.corner_test && level > start_level {
                // Blocks that the balls of their known corners already cover need no centre of
                // their own. A coarser centre lies inside its block, so the only ones on a
                // block's corners are those of its ancestors, carried down with it (see
                // `KnownCorners`): no lookups.
                let size = lattice.cell * s as f64;
                // Per block: kept (None), or covered, with whether its known corners are all
                // negative (its sign) or all positive (Some(None) where they differ, which the
                // premise rules out).
                let free: Vec<Option<Option<bool>>> = blocks
                    .par_iter()
                    .zip(&known)
                    .with_min_len(1024)
                    .map(|(o, k)| {
                        debug_assert!((0..8).all(|j| store
                            .known(corner_scaled(*o, j, s), cells)
                            .is_none_or(
                                |v| k.at(j) != NONE && v == store.values[k.at(j) as usize]
                            )));
                        let [a, b] = k.get(&store.values);
                        if a.is_nan() && b.is_nan() {
                            return None;
                        }
                        let mut radius = [f64::NAN; 8];
                        radius[k.corner as usize] = a.abs() / octree.safety;
                        radius[7 - k.corner as usize] = b.abs() / octree.safety;
                        covered(&radius, size).then(|| {
                            let neg = [a, b].iter().all(|&v| v.is_nan() || v < 0.0);
                            let pos = [a, b].iter().all(|&v| v.is_nan() || v >= 0.0);
                            (neg != pos).then_some(neg)
                        })
                    })
                    .collect();
                decided.mark_blocks(&blocks, s, |i| free[i]);
                let kept: Vec<u32> = free.iter().map(|f| f.is_none() as u32).collect();
                blocks = kept_items(&blocks, &kept);
                known = kept_items(&known, &kept);
            }
            // Centres are never shared: those of one level are distinct, and those of different
            // levels are odd multiples of different powers of two.
            let h = s / 2;
            points.clear();
            blocks
                .par_iter()
                .with_min_len(4096)
                .map(|o| lattice.point([o[0] + h, o[1] + h, o[2] + h]))
                .collect_into_vec(&mut points);
            let base = store.values.len();
            store.evaluate(field, &points, settings, &mut stats)?;
            let r = octree.safety * lattice.block_radius(s);
            let v = &store.values[base..];
            decided.mark_blocks(&blocks, s, |i| (v[i].abs() > r).then_some(Some(v[i] < 0.0)));
            let kept: Vec<u32> = v
                .par_iter()
                .with_min_len(4096)
                .map(|x| (x.abs() <= r) as u32)
                .collect();
            blocks = kept_items(&blocks, &kept);
            known = kept_items(&known, &kept);
            centre_values = crate::memory::collect_counted(&kept, |i| {
                (kept[i] != 0).then_some((base + i) as u32)
            });
            // Only kept blocks hold leaves, and a centre lies inside its own block, so only
            // kept centres can be leaf corners (those inside the lattice). The centre of a
            // block of 2 × 2 × 2 cells is a corner of its own leaves only, so it stays with the
            // block instead of in the store.
            if s == 2 {
                centres = std::mem::take(&mut centre_values);
            } else {
                for (o, &i) in blocks.iter().zip(&centre_values) {
                    let c = [o[0] + h, o[1] + h, o[2] + h];
                    if c[0] <= cells[0] && c[1] <= cells[1] && c[2] <= cells[2] {
                        let slot = store.slot_mut(c);
                        store.slots[slot] = i;
                        store.state[slot] = PointState::of_value(store.values[i as usize]);
                    }
                }
            }
            stats.add_time("sample", t);
        }
        stats.cells_per_level.push(blocks.len() as u64);
        if s == 2 {
            // Blocks of 2 × 2 × 2 cells: their children, the leaves, are made below.
            break;
        }
        // The children inside the lattice, in block order, then octant order.
        let h = s / 2;
        let child = |o: [u32; 3], d: usize| {
            let off = corner_offset(d);
            [o[0] + off[0] * h, o[1] + off[1] * h, o[2] + off[2] * h]
        };
        centre_values.resize(blocks.len(), NONE);
        let children: Vec<u8> = blocks
            .par_iter()
            .with_min_len(4096)
            .map(|&o| (0..8).fold(0, |m, d| m | (inside(child(o, d)) as u8) << d))
            .collect();
        let counts: Vec<u32> = children.iter().map(|m| m.count_ones()).collect();
        let next = crate::memory::collect_counted(&counts, |i| {
            let o = blocks[i];
            bits(children[i]).map(move |d| child(o, d))
        });
        known = crate::memory::collect_counted(&counts, |i| {
            let (k, c) = (known[i], centre_values[i]);
            bits(children[i]).map(move |d| k.child(d, c))
        });
        blocks = next;
        centre_values.clear();
    }
    // `blocks` now holds the blocks of 2 × 2 × 2 cells that hold the leaves (or, for a lattice
    // of one cell, the root, whose only child inside is that cell): each with the mask of its
    // children inside the lattice, in case-bit order.
    let t = Instant::now();
    if centres.len() != blocks.len() {
        centres = vec![NONE; blocks.len()];
    }
    let mut masks: Vec<u8> = blocks
        .par_iter()
        .with_min_len(4096)
        .map(|o| {
            (0..8)
                .filter(|&d| inside(corner(*o, d)))
                .fold(0, |m, d| m | 1 << d)
        })
        .collect();
    let tested: u64 = masks.iter().map(|m| m.count_ones() as u64).sum();
    let mut suspects = repair::Suspects::default();
    if octree.corner_test && levels > 0 {
        // Marching cubes needs the signs of the leaves' corners, and values only at the ends of
        // crossed edges. Leaves are settled before and after evaluating the corners still
        // without a sign: signs are inferred from the balls of the values known (no surface
        // within |f| / safety), and leaves whose corners all have a sign are decided (one sign:
        // no triangle; both: crossed).
        let mut crossed = vec![0u8; blocks.len()];
        let reach = block_reach(lattice.cell, octree.safety);
        let reach = &*reach;
        let mut ends = Ends::default();
        // Per block, the points its undecided leaves need that had no sign when last settled.
        let mut open = vec![0u32; blocks.len()];
        // Every point the leaves may need, signs inferred or values, has slots from here on.
        for (&o, &m) in blocks.iter().zip(&masks) {
            if m != 0 {
                store.give_block_bricks(o, cells);
            }
        }
        let mut settle =
            |store: &mut Store,
             masks: &mut [u8],
             crossed: &mut [u8],
             open: &mut [u32],
             first: Option<(&DecidedBlocks, &[KnownCorners])>| {
                settle_leaves(
                    store,
                    (&blocks, &centres),
                    masks,
                    crossed,
                    open,
                    reach,
                    cells,
                    first,
                    &mut ends,
                )
            };
        // First with the signs of the blocks the levels decided, on the faces, edges and
        // corners the blocks share with them (only needed then: the leaves' corners without a
        // sign are never more than before).
        settle(
            &mut store,
            &mut masks,
            &mut crossed,
            &mut open,
            Some((&decided, &known)),
        );
        drop(known);
        // Then every corner still without a sign, in one batch. (Rounds — the blocks' corners
        // first, then the rest; or edge midpoints between them — saved 0.1–1.4 % of the
        // evaluations at 128³ but cost more in settling than they saved: 2–5 % of the time.)
        points = store.claim_blocks(&blocks, &open, lattice);
        store.evaluate(field, &points, settings, &mut stats)?;
        settle(&mut store, &mut masks, &mut crossed, &mut open, None);
        debug_assert!(masks.iter().all(|&m| m == 0));
        // The crossed edges need values at both ends, not only signs.
        suspects = evaluate_crossed_edge_ends(
            field,
            lattice,
            &mut store,
            (&blocks, &centres, &crossed),
            ends,
            settings,
            &mut stats,
        )?;
        masks = crossed;
    }
    // The crossed leaves, with the indices of their corners' values, in leaf order.
    let mut leaves: Vec<CrossedLeaf> = if octree.corner_test && levels > 0 {
        // Settled: every corner of a crossed leaf has a value or a sign, read in parallel
        // straight into place (the blocks' masks count their crossed leaves).
        let store = &store;
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
            bits(m).map(move |d| {
                // The case from the signs gathered (the same as from the corners' values).
                let case = LEAF_CORNERS[d]
                    .iter()
                    .enumerate()
                    .fold(0u8, |c, (k, &p)| c | (((negative >> p) & 1) as u8) << k);
                let corners = LEAF_CORNERS[d].map(|p| idx[p as usize]);
                debug_assert_eq!(case, case_index(&corners.map(|i| corner_value(values, i))));
                CrossedLeaf {
                    origin: corner(o, d),
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
    } else {
        // All their corners not yet known evaluated in one batch; the leaves of a block claim
        // its points at once.
        let n: usize = masks.iter().map(|m| m.count_ones() as usize).sum();
        let mut indices = Vec::with_capacity(blocks.len());
        points.clear();
        points.reserve(2 * n);
        for ((&o, &m), &c) in blocks.iter().zip(&masks).zip(&centres) {
            if m == 0 {
                continue;
            }
            let wanted = Store::stored(LEAF_POINTS[m as usize], c);
            let mut idx = store.claim_block(o, wanted, lattice, &mut points);
            if c != NONE {
                idx[CENTRE] = c;
            }
            indices.push((o, m, idx));
        }
        store.evaluate(field, &points, settings, &mut stats)?;
        let values = &store.values;
        let crossed_leaf = move |o: [u32; 3], d: usize, idx: &[u32; 27]| {
            let corners = LEAF_CORNERS[d].map(|p| idx[p as usize]);
            let case = case_index(&corners.map(|i| values[i as usize]));
            (case != 0 && case != 255).then_some(CrossedLeaf {
                origin: corner(o, d),
                corners,
                case,
            })
        };
        indices
            .par_iter()
            .with_min_len(256)
            .flat_map_iter(|(o, m, idx)| bits(*m).filter_map(move |d| crossed_leaf(*o, d, idx)))
            .collect()
    };
    drop((masks, points));
    stats.cells_per_level.push(tested);
    // Where the premise failed, the leaves are completed (see `repair`).
    let beyond = repair::cells_beyond_crossed_faces(table, &decided, &leaves, cells);
    stats.cells_repaired = repair::close(
        field,
        lattice,
        table,
        &mut store,
        &decided,
        (&blocks, &centres),
        beyond,
        suspects,
        &mut leaves,
        settings,
        &mut stats,
    )?;
    drop((blocks, centres, decided));
    stats.cells_visited = tested + stats.cells_repaired;
    stats.cells_crossed = leaves.len() as u64;
    stats.add_time("sample", t);

    let t = Instant::now();
    let values = std::mem::take(&mut store.values);
    drop(store);
    let mut mesh = triangulate(table, lattice, &values, &leaves);
    drop((values, leaves));
    stats.add_time("triangulate", t);
    compute_normals(field, lattice, &mut mesh, settings, &mut stats)?;
    Ok((mesh, stats))
}

#[cfg(test)]
mod tests;
