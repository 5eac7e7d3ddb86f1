//! The lattice points of a block of 2 × 2 × 2 cells (the parent of eight leaves) as bits of a
//! mask, and the corners of cells and blocks.

/// The 3 × 3 × 3 lattice points of a block of 2 × 2 × 2 cells (a parent of leaves), numbered
/// x fastest: point `x + 3y + 9z`.
pub(super) const fn block_point(x: usize, y: usize, z: usize) -> usize {
    x + 3 * y + 9 * z
}
/// The block point at the block's centre.
pub(super) const CENTRE: usize = block_point(1, 1, 1);
/// `LEAF_CORNERS[d][k]`: the block point of corner k of child cell d (both in case-bit order).
pub(super) const LEAF_CORNERS: [[u8; 8]; 8] = {
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
pub(super) const LEAF_POINTS: [u32; 256] = {
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

/// Lattice point of block point `p` (see [`block_point`]) of the block with lower corner `o`.
#[inline]
pub(super) fn block_offset(o: [u32; 3], p: usize) -> [u32; 3] {
    [
        o[0] + (p % 3) as u32,
        o[1] + ((p / 3) % 3) as u32,
        o[2] + (p / 9) as u32,
    ]
}

/// Whether the cell (or block) with lower corner `o` lies in a lattice of `cells`.
#[inline]
pub(super) fn cell_inside(o: [u32; 3], cells: [u32; 3]) -> bool {
    o[0] < cells[0] && o[1] < cells[1] && o[2] < cells[2]
}
