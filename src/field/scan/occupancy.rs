//! The cubic cells that hold a data point, for a test in constant time of whether a point lies
//! within a distance of the data: two points of one cell of side `c` are at most `c·√3` apart,
//! so a query in an occupied cell of side `r/√3` has a data point within `r`.
//!
//! The cells are kept in an open-addressed hash table of their packed coordinates (21 bits per
//! axis, from the data's lowest corner); the table holds at most one entry per data point.

use glam::DVec3;
use rayon::prelude::*;

/// Bits of each axis's cell coordinate in a packed key.
const AXIS_BITS: u32 = 21;
/// An empty slot of the table (no packed key has all 64 bits set).
const EMPTY: u64 = u64::MAX;

/// The occupied cells of a point set (see the module's documentation).
#[derive(Clone, Debug)]
pub struct OccupiedCells {
    lo: DVec3,
    inverse_side: f64,
    /// Slots of packed keys, a power of two of them, at most half full.
    table: Vec<u64>,
    shift: u32,
}

impl OccupiedCells {
    /// The cells of side `side` (> 0) holding at least one of `points` (finite), or `None` when
    /// the points span more than 2²¹ cells along an axis.
    pub fn new(points: &[DVec3], side: f64) -> Option<OccupiedCells> {
        if points.is_empty() || side.is_nan() || side <= 0.0 {
            return None;
        }
        let lo = points.iter().fold(DVec3::INFINITY, |a, p| a.min(*p));
        let hi = points.iter().fold(DVec3::NEG_INFINITY, |a, p| a.max(*p));
        let inverse_side = 1.0 / side;
        let span = ((hi - lo) * inverse_side).max_element();
        if span.is_nan() || span >= (1u64 << AXIS_BITS) as f64 - 2.0 {
            return None;
        }
        let mut keys: Vec<u64> = points
            .par_iter()
            .map(|p| pack(cell_of(*p, lo, inverse_side)))
            .collect();
        keys.par_sort_unstable();
        keys.dedup();
        let slots = (2 * keys.len()).next_power_of_two().max(2);
        let mut cells = OccupiedCells {
            lo,
            inverse_side,
            table: vec![EMPTY; slots],
            shift: 64 - slots.trailing_zeros(),
        };
        for k in keys {
            let mut at = cells.slot(k);
            while cells.table[at] != EMPTY {
                at = (at + 1) & (slots - 1);
            }
            cells.table[at] = k;
        }
        Some(cells)
    }

    fn slot(&self, key: u64) -> usize {
        (key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> self.shift) as usize
    }

    /// Whether the cell holding `x` holds a data point.
    pub fn contains(&self, x: DVec3) -> bool {
        let c = cell_of(x, self.lo, self.inverse_side);
        let limit = (1i64 << AXIS_BITS) - 1;
        if c.iter().any(|&v| v < 0 || v > limit) {
            return false;
        }
        let key = pack(c);
        let mask = self.table.len() - 1;
        let mut at = self.slot(key);
        loop {
            match self.table[at] {
                EMPTY => return false,
                k if k == key => return true,
                _ => at = (at + 1) & mask,
            }
        }
    }
}

/// The integer cell coordinates of `x` (saturating far outside).
fn cell_of(x: DVec3, lo: DVec3, inverse_side: f64) -> [i64; 3] {
    let c = ((x - lo) * inverse_side).floor();
    [c.x as i64, c.y as i64, c.z as i64]
}

/// Coordinates in `0..2²¹` packed into one key.
fn pack(c: [i64; 3]) -> u64 {
    (c[0] as u64) | ((c[1] as u64) << AXIS_BITS) | ((c[2] as u64) << (2 * AXIS_BITS))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::random_points;

    #[test]
    fn a_query_in_an_occupied_cell_is_near_a_point_and_every_point_is_found() {
        let points = random_points(2_000, -1.0, 1.0, 5);
        let side = 0.05;
        let cells = OccupiedCells::new(&points, side).unwrap();
        assert!(points.iter().all(|p| cells.contains(*p)));
        let queries = random_points(20_000, -1.5, 1.5, 6);
        let mut found = 0;
        for q in &queries {
            let nearest = points
                .iter()
                .map(|p| p.distance(*q))
                .fold(f64::INFINITY, f64::min);
            if cells.contains(*q) {
                found += 1;
                assert!(nearest <= side * 3f64.sqrt());
            }
            // A query sharing a cell with a point is found.
            let shares = points.iter().any(|p| {
                cell_of(*p, cells.lo, cells.inverse_side)
                    == cell_of(*q, cells.lo, cells.inverse_side)
            });
            assert_eq!(shares, cells.contains(*q));
        }
        assert!(found > 100, "{found}");
        assert!(OccupiedCells::new(&[DVec3::ZERO, DVec3::splat(1e9)], 1e-3).is_none());
    }
}
