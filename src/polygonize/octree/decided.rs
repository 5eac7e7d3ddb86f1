//! The signs of the blocks that the levels decided hold no surface.

use crate::lattice::Lattice;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU8, Ordering::Relaxed};

/// `v` as atomics, for writes from several threads (the exclusive borrow guarantees that no
/// one else reads it meanwhile).
fn atomic_u8s(v: &mut [u8]) -> &[AtomicU8] {
    // SAFETY: AtomicU8 has u8's size and alignment, and the exclusive borrow means every
    // access for its lifetime goes through the atomics.
    unsafe { &*(v as *mut [u8] as *const [AtomicU8]) }
}

/// `SHARED[k]`: the points of a block of 2 × 2 × 2 cells (bits as in [`block_point`](super::block::block_point)) that it
/// shares with its neighbour at offset `d` ∈ {−1, 0, 1}³, `k = (d.x + 1) + 3 (d.y + 1) +
/// 9 (d.z + 1)`: along an axis with offset −1 its points at 0, with +1 those at 2.
pub(super) const SHARED: [u32; 27] = {
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

/// A block of [`DecidedBlocks`] that the levels kept.
const KEPT: u8 = 0;
/// A block dropped whose points are all negative.
const NEGATIVE: u8 = 1;
/// A block dropped whose points are all zero or positive.
const POSITIVE: u8 = 2;
/// A block dropped whose known corners disagreed in sign (which the premise rules out).
const NO_SIGN: u8 = 3;

/// The signs of the blocks of 2 × 2 × 2 cells that the levels decided hold no surface: inside a
/// block rejected by its centre's value (whose ball, of radius |f| / safety beyond the block's
/// circumradius, holds the whole block) or covered by its corners' balls, at any level. Every
/// lattice point of such a block has the sign decided, so the leaves' corners on the faces,
/// edges and corners they share with decided neighbours need no evaluation. Two bits per block,
/// four blocks per byte in x order (a 1024³ lattice: 34 MB): [`KEPT`], [`NEGATIVE`],
/// [`POSITIVE`] or [`NO_SIGN`]. The repair reads which blocks were dropped
/// ([`DecidedBlocks::dropped`]).
#[derive(Default)]
pub(super) struct DecidedBlocks {
    pub(super) dims: [usize; 3],
    /// Block `i`'s code in bits `2 (i mod 4)` and up of byte `i / 4`.
    bits: Vec<u8>,
}

/// Byte and shift of block `i`'s code.
#[inline(always)]
fn place(i: usize) -> (usize, u32) {
    (i >> 2, 2 * (i & 3) as u32)
}

impl DecidedBlocks {
    fn dims(lattice: &Lattice) -> [usize; 3] {
        lattice.cells().map(|c| c.div_ceil(2) as usize)
    }

    pub(super) fn bytes(lattice: &Lattice) -> u64 {
        Self::dims(lattice)
            .iter()
            .map(|&d| d as u64)
            .product::<u64>()
            .div_ceil(4)
    }

    /// The map of `lattice`, all kept.
    pub(super) fn new(lattice: &Lattice) -> Self {
        let dims = Self::dims(lattice);
        DecidedBlocks {
            dims,
            bits: vec![KEPT; dims.iter().product::<usize>().div_ceil(4)],
        }
    }

    /// Number of blocks.
    #[cfg(test)]
    pub(super) fn len(&self) -> usize {
        self.dims.iter().product()
    }

    /// The code of block `i` (x fastest).
    #[inline(always)]
    pub(super) fn get(&self, i: usize) -> u8 {
        let (byte, shift) = place(i);
        (self.bits[byte] >> shift) & 3
    }

    /// Sets the code of block `i` to `v`.
    #[inline(always)]
    pub(super) fn set(&mut self, i: usize, v: u8) {
        let (byte, shift) = place(i);
        self.bits[byte] = (self.bits[byte] & !(3 << shift)) | (v << shift);
    }

    /// Sets the codes of blocks `start..end` to `v`: whole bytes at once, their ends one by one.
    fn fill(&mut self, start: usize, end: usize, v: u8) {
        let first_whole = start.next_multiple_of(4).min(end);
        let last_whole = (end & !3).max(first_whole);
        for i in (start..first_whole).chain(last_whole..end) {
            self.set(i, v);
        }
        self.bits[first_whole >> 2..last_whole >> 2].fill(v * 0b0101_0101);
    }

    /// The code of a block dropped with sign `sign` (`None`: unknown).
    #[inline]
    fn code(sign: Option<bool>) -> u8 {
        match sign {
            Some(true) => NEGATIVE,
            Some(false) => POSITIVE,
            None => NO_SIGN,
        }
    }

    /// Whether cell `o` of the lattice lies in a block the levels dropped.
    #[inline]
    pub(super) fn dropped(&self, o: [u32; 3]) -> bool {
        let b = o.map(|c| (c / 2) as usize);
        self.get(b[0] + self.dims[0] * (b[1] + self.dims[1] * b[2])) != KEPT
    }

    /// Marks the block of `s` cells per side (s ≥ 2) with lower corner `o` (clipped to the
    /// lattice) as dropped, holding points of sign `negative` only (`None`: unknown).
    #[inline]
    pub(super) fn mark(&mut self, o: [u32; 3], s: u32, negative: Option<bool>) {
        let lo = o.map(|c| (c / 2) as usize);
        let v = Self::code(negative);
        if s == 2 {
            // One entry: most marks are of the last level's blocks.
            if (0..3).all(|a| lo[a] < self.dims[a]) {
                self.set(lo[0] + self.dims[0] * (lo[1] + self.dims[1] * lo[2]), v);
            }
            return;
        }
        let hi: [usize; 3] = std::array::from_fn(|a| (lo[a] + (s / 2) as usize).min(self.dims[a]));
        for z in lo[2]..hi[2] {
            for y in lo[1]..hi[1] {
                let row = self.dims[0] * (y + self.dims[1] * z);
                if lo[0] < hi[0] {
                    self.fill(row + lo[0], row + hi[0], v);
                }
            }
        }
    }

    /// Marks `blocks[i]` (blocks of `s` cells per side) as [`DecidedBlocks::mark`] does with
    /// `negative` where `sign(i)` is `Some(negative)` (the block dropped); in parallel for the
    /// last level's blocks (s = 2, one byte each, and most of the marks).
    pub(super) fn mark_blocks(
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
        let map = atomic_u8s(&mut self.bits);
        blocks
            .par_iter()
            .enumerate()
            .with_min_len(4096)
            .for_each(|(i, &o)| {
                if let Some(negative) = sign(i) {
                    let b = o.map(|c| (c / 2) as usize);
                    if (0..3).all(|a| b[a] < dims[a]) {
                        // Other threads write only the other codes of the byte.
                        let (byte, shift) = place(b[0] + dims[0] * (b[1] + dims[1] * b[2]));
                        map[byte].fetch_and(!(3 << shift), Relaxed);
                        map[byte].fetch_or(Self::code(negative) << shift, Relaxed);
                    }
                }
            });
    }

    /// The points of the block of 2 × 2 × 2 cells with lower corner `o` that lie in decided
    /// neighbours: (negative, positive), bits as in [`block_point`](super::block::block_point).
    #[inline]
    pub(super) fn masks(&self, o: [u32; 3]) -> (u32, u32) {
        let b = o.map(|c| (c / 2) as usize);
        let (mut neg, mut pos) = (0, 0);
        if (0..3).all(|a| b[a] >= 1 && b[a] + 1 < self.dims[a]) {
            // All 26 neighbours in the map: three rows of three per plane, without branches.
            let (dx, dxy) = (self.dims[0], self.dims[0] * self.dims[1]);
            let first = (b[0] - 1) + dx * (b[1] - 1) + dxy * (b[2] - 1);
            for z in 0..3 {
                for y in 0..3 {
                    let at = first + dx * y + dxy * z;
                    for x in 0..3 {
                        let v = self.get(at + x);
                        let shared = SHARED[x + 3 * y + 9 * z];
                        neg |= shared & 0u32.wrapping_sub((v == NEGATIVE) as u32);
                        pos |= shared & 0u32.wrapping_sub((v == POSITIVE) as u32);
                    }
                }
            }
            return (neg, pos);
        }
        self.masks_at_edge(o)
    }

    /// [`DecidedBlocks::masks`] for any block, neighbours beyond the map included (none).
    pub(super) fn masks_at_edge(&self, o: [u32; 3]) -> (u32, u32) {
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
                    match self.get(row + x) {
                        NEGATIVE => neg |= shared,
                        POSITIVE => pos |= shared,
                        _ => {}
                    }
                }
            }
        }
        (neg, pos)
    }
}
