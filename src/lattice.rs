//! The lattice every polygonizer works on: an axis-aligned box split into `cells[0] × cells[1] ×
//! cells[2]` cells. Lattice points are addressed by integer coordinates `[i, j, k]` with
//! `0 ≤ i ≤ cells[0]` and so on, and packed into one `u64` key. All polygonizers compute the position
//! of a lattice point and of an edge vertex with the same arithmetic, so that they produce
//! bit-identical vertices for the same field and lattice.
//!
//! A [`Lattice::window`] is the lattice of a box of cells of a larger lattice: its points are
//! numbered from its own corner, but their positions are computed from the larger lattice's
//! origin and indices, so a polygonizer run on a window makes the same vertices, bit for bit,
//! as on the whole lattice (tiled polygonization welds windows' meshes exactly).

use crate::error::{Error, Result};
use glam::DVec3;

/// Largest number of cells per axis accepted (keys pack three 21-bit coordinates).
pub const MAX_CELLS_PER_AXIS: u32 = (1 << 20) - 1;

/// Axis-aligned box with a regular grid of cells.
#[derive(Clone, Copy, Debug, PartialEq)]
///
/// Its fields are private: every lattice comes from a checked constructor ([`Lattice::new`],
/// [`Lattice::cubic`], [`Lattice::from_cells`], [`Lattice::window`]), so a lattice always has
/// finite corners, positive finite cells and 1 to [`MAX_CELLS_PER_AXIS`] cells per axis.
pub struct Lattice {
    /// Corner of the box with the smallest coordinates (lattice point `[0, 0, 0]`).
    origin: DVec3,
    /// Size of one cell along each axis.
    cell: DVec3,
    /// Number of cells along each axis.
    cells: [u32; 3],
    /// Origin of the whole lattice this one is a window of (`origin` itself when it is whole).
    base: DVec3,
    /// Indices in the whole lattice of this lattice's point `[0, 0, 0]` (zero when whole).
    offset: [u32; 3],
}

/// A point as Python writes a list of floats: `[1.0, -0.5, 2.0]`.
fn python_list(p: DVec3) -> String {
    format!("[{:?}, {:?}, {:?}]", p.x, p.y, p.z)
}

impl Lattice {
    /// A lattice over the box `min..max` with `cells` cells per axis.
    ///
    /// Errors when the box is empty or not finite, or a cell count is zero or too large.
    pub fn new(min: DVec3, max: DVec3, cells: [u32; 3]) -> Result<Self> {
        if !min.is_finite() || !max.is_finite() {
            return Err(Error::invalid("bounds", "must be finite"));
        }
        if !(max.cmpgt(min).all()) {
            return Err(Error::invalid(
                "bounds",
                format!(
                    "the second row (max) must exceed the first (min) on every axis, got [{}, {}]",
                    python_list(min),
                    python_list(max)
                ),
            ));
        }
        for &c in &cells {
            if c == 0 || c > MAX_CELLS_PER_AXIS {
                return Err(Error::invalid(
                    "resolution",
                    format!("cells per axis must be in 1..={MAX_CELLS_PER_AXIS}, got {c}"),
                ));
            }
        }
        let n = DVec3::new(cells[0] as f64, cells[1] as f64, cells[2] as f64);
        Ok(Lattice {
            origin: min,
            cell: (max - min) / n,
            cells,
            base: min,
            offset: [0; 3],
        })
    }

    /// The whole lattice of `cells` cells of size `cell` from `origin`: lattice point `[i, j, k]`
    /// is at `origin + [i, j, k] * cell` (one product and one sum per coordinate).
    ///
    /// Errors (naming `cells`, `origin` or `cell`) unless every cell count is in
    /// 1..=[`MAX_CELLS_PER_AXIS`], `origin` is finite and `cell` positive and finite on every
    /// axis.
    pub fn from_cells(origin: DVec3, cell: DVec3, cells: [u32; 3]) -> Result<Self> {
        if cells.iter().any(|&c| c == 0 || c > MAX_CELLS_PER_AXIS) {
            return Err(Error::invalid(
                "cells",
                format!("cells per axis must be in 1..={MAX_CELLS_PER_AXIS}, got {cells:?}"),
            ));
        }
        if !origin.is_finite() {
            return Err(Error::invalid("origin", "must be finite"));
        }
        if !(cell.is_finite() && cell.cmpgt(DVec3::ZERO).all()) {
            return Err(Error::invalid("cell", "must be positive and finite"));
        }
        Ok(Lattice {
            origin,
            cell,
            cells,
            base: origin,
            offset: [0; 3],
        })
    }

    /// Corner of the box with the smallest coordinates (lattice point `[0, 0, 0]`).
    #[inline]
    pub fn origin(&self) -> DVec3 {
        self.origin
    }

    /// Size of one cell along each axis.
    #[inline]
    pub fn cell(&self) -> DVec3 {
        self.cell
    }

    /// Number of cells along each axis.
    #[inline]
    pub fn cells(&self) -> [u32; 3] {
        self.cells
    }

    /// Origin of the whole lattice this one is a window of ([`Lattice::origin`] when whole).
    #[inline]
    pub fn base(&self) -> DVec3 {
        self.base
    }

    /// Indices in the whole lattice of this lattice's point `[0, 0, 0]` (zero when whole).
    #[inline]
    pub fn offset(&self) -> [u32; 3] {
        self.offset
    }

    /// The window of this lattice over the cells `lo[a] ≤ i < hi[a]` on each axis: a lattice of
    /// `hi − lo` cells whose point `[0, 0, 0]` is this lattice's point `lo`, and whose every
    /// point is at the same position, bit for bit, as the point of this lattice it stands for.
    ///
    /// Errors (naming `window`) unless `lo < hi ≤ cells` on every axis.
    pub fn window(&self, lo: [u32; 3], hi: [u32; 3]) -> Result<Self> {
        for a in 0..3 {
            if !(lo[a] < hi[a] && hi[a] <= self.cells[a]) {
                return Err(Error::invalid(
                    "window",
                    format!(
                        "cells [{lo:?}, {hi:?}) must satisfy lo < hi <= {:?} on every axis",
                        self.cells
                    ),
                ));
            }
        }
        Ok(Lattice {
            origin: self.point(lo),
            cell: self.cell,
            cells: std::array::from_fn(|a| hi[a] - lo[a]),
            base: self.base,
            offset: std::array::from_fn(|a| self.offset[a] + lo[a]),
        })
    }

    /// A lattice of cubic cells with `n` cells along the longest side of `min..max`; the other
    /// sides get the whole number of cells that covers them, and grow symmetrically to it.
    pub fn cubic(min: DVec3, max: DVec3, n: u32) -> Result<Self> {
        // Validate the box and n first with the general constructor.
        Lattice::new(min, max, [n, n, n])?;
        let extent = max - min;
        let h = extent.max_element() / n as f64;
        let mut cells = [n; 3];
        let mut lo = min;
        let mut hi = max;
        for k in 0..3 {
            let c = ((extent[k] / h) * (1.0 - 1e-12)).ceil().max(1.0) as u32;
            cells[k] = c.min(n);
            let centre = 0.5 * (min[k] + max[k]);
            let half = 0.5 * cells[k] as f64 * h;
            if cells[k] != n {
                lo[k] = centre - half;
                hi[k] = centre + half;
            }
        }
        Lattice::new(lo, hi, cells)
    }

    /// Lattice points per axis (cells + 1).
    #[inline]
    pub fn points_per_axis(&self) -> [u32; 3] {
        [self.cells[0] + 1, self.cells[1] + 1, self.cells[2] + 1]
    }

    /// Total number of lattice points, the number of evaluations plain marching cubes needs.
    pub fn num_points(&self) -> u64 {
        let p = self.points_per_axis();
        p[0] as u64 * p[1] as u64 * p[2] as u64
    }

    /// Total number of cells.
    pub fn num_cells(&self) -> u64 {
        self.cells[0] as u64 * self.cells[1] as u64 * self.cells[2] as u64
    }

    /// Upper corner of the box.
    pub fn max(&self) -> DVec3 {
        self.point([self.cells[0], self.cells[1], self.cells[2]])
    }

    /// Position of the lattice point with integer coordinates `i`, computed from the whole
    /// lattice's origin and indices (for a window, `offset + i`).
    #[inline]
    pub fn point(&self, i: [u32; 3]) -> DVec3 {
        let [x, y, z] = std::array::from_fn(|a| (self.offset[a] + i[a]) as f64);
        DVec3::new(
            self.base.x + x * self.cell.x,
            self.base.y + y * self.cell.y,
            self.base.z + z * self.cell.z,
        )
    }

    /// Packs integer coordinates (each below 2²¹) into one key.
    #[inline]
    pub fn key(i: [u32; 3]) -> u64 {
        (i[0] as u64) | ((i[1] as u64) << 21) | ((i[2] as u64) << 42)
    }

    /// Inverse of [`Lattice::key`].
    #[inline]
    pub fn unkey(key: u64) -> [u32; 3] {
        let m = (1u64 << 21) - 1;
        [
            (key & m) as u32,
            ((key >> 21) & m) as u32,
            ((key >> 42) & m) as u32,
        ]
    }

    /// Key of the lattice edge that starts at lattice point `i` and runs along `axis` (0, 1, 2).
    #[inline]
    pub fn edge_key(i: [u32; 3], axis: u8) -> u64 {
        (Self::key(i) << 2) | axis as u64
    }

    /// Key of the lattice edge that starts at this lattice's point `i` and runs along `axis`
    /// (0, 1, 2), in the whole lattice's numbering (for a window, from the point `offset + i`):
    /// 20 bits per coordinate (no index exceeds [`MAX_CELLS_PER_AXIS`]) above the axis in the
    /// lowest two bits. Windows of one lattice give one edge the same key.
    #[inline]
    pub fn whole_edge_key(&self, i: [u32; 3], axis: u8) -> u64 {
        let [x, y, z] = std::array::from_fn(|a| (self.offset[a] + i[a]) as u64);
        (x | (y << 20) | (z << 40)) << 2 | axis as u64
    }

    /// Inverse of [`Lattice::whole_edge_key`]: the edge's lower end in the whole lattice, and
    /// its axis.
    #[inline]
    pub fn unkey_whole_edge(key: u64) -> ([u32; 3], u8) {
        let m = (1u64 << 20) - 1;
        let p = key >> 2;
        (
            [
                (p & m) as u32,
                ((p >> 20) & m) as u32,
                ((p >> 40) & m) as u32,
            ],
            (key & 3) as u8,
        )
    }

    /// Half the diagonal of a block of `n × n × n` cells: the circumradius of such a cube.
    pub fn block_radius(&self, n: u32) -> f64 {
        0.5 * (self.cell * n as f64).length()
    }
}

/// Hasher for packed lattice keys (splitmix64 finaliser): keys are already unique integers, they
/// only need their bits mixed so that both ends of the hash are well spread.
#[derive(Default, Clone, Copy)]
pub struct KeyHasher(u64);

impl std::hash::Hasher for KeyHasher {
    #[inline]
    fn finish(&self) -> u64 {
        self.0
    }
    #[inline]
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(self.0 ^ b as u64);
        }
    }
    #[inline]
    fn write_u64(&mut self, i: u64) {
        let mut z = i.wrapping_add(0x9e37_79b9_7f4a_7c15);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        self.0 = z ^ (z >> 31);
    }
}

/// Hash map keyed by packed lattice keys.
pub type KeyMap<V> = std::collections::HashMap<u64, V, std::hash::BuildHasherDefault<KeyHasher>>;

/// Position of the surface crossing on the lattice edge from `a` (value `fa`) to `b` (value `fb`),
/// where `a` is the lower end of the edge. Linear interpolation; callers pass the ends in lattice
/// order so that every polygonizer gets the same bits.
#[inline]
pub fn edge_crossing(a: DVec3, b: DVec3, fa: f64, fb: f64) -> DVec3 {
    let t = (fa / (fa - fb)).clamp(0.0, 1.0);
    a + (b - a) * t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_edge_keys_round_trip_and_agree_across_windows() {
        let l = Lattice::new(DVec3::ZERO, DVec3::ONE, [MAX_CELLS_PER_AXIS, 9, 9]).unwrap();
        let w = l.window([5, 2, 3], [MAX_CELLS_PER_AXIS, 9, 9]).unwrap();
        for (i, axis) in [
            ([0, 0, 0], 0),
            ([7, 1, 2], 2),
            ([MAX_CELLS_PER_AXIS - 5, 6, 5], 1),
        ] {
            let key = w.whole_edge_key(i, axis);
            assert_eq!(key, l.whole_edge_key([5 + i[0], 2 + i[1], 3 + i[2]], axis));
            assert_eq!(
                Lattice::unkey_whole_edge(key),
                ([5 + i[0], 2 + i[1], 3 + i[2]], axis)
            );
        }
    }

    #[test]
    fn keys_round_trip() {
        for i in [
            [0, 0, 0],
            [1, 2, 3],
            [MAX_CELLS_PER_AXIS, 7, MAX_CELLS_PER_AXIS],
        ] {
            assert_eq!(Lattice::unkey(Lattice::key(i)), i);
        }
        assert_ne!(
            Lattice::edge_key([1, 0, 0], 0),
            Lattice::edge_key([1, 0, 0], 1)
        );
    }

    #[test]
    fn rejects_bad_boxes() {
        assert!(Lattice::new(DVec3::ZERO, DVec3::ONE, [0, 1, 1]).is_err());
        assert!(Lattice::new(DVec3::ONE, DVec3::ZERO, [1, 1, 1]).is_err());
        assert!(Lattice::new(DVec3::ZERO, DVec3::new(1.0, f64::NAN, 1.0), [1, 1, 1]).is_err());
        let l = Lattice::new(-DVec3::ONE, DVec3::ONE, [4, 4, 4]).unwrap();
        assert_eq!(l.num_points(), 125);
        assert_eq!(l.point([2, 2, 2]), DVec3::ZERO);
    }

    #[test]
    fn cubic_cells() {
        let l =
            Lattice::cubic(DVec3::new(-1.0, -0.5, -0.1), DVec3::new(1.0, 0.5, 0.1), 64).unwrap();
        assert_eq!(l.cells, [64, 32, 7]);
        assert!((l.cell.x - l.cell.y).abs() < 1e-15 && (l.cell.x - l.cell.z).abs() < 1e-15);
        assert!(l.origin.z <= -0.1 && l.max().z >= 0.1);
    }

    #[test]
    fn windows_keep_the_positions_of_the_whole_lattice() {
        let l = Lattice::cubic(DVec3::splat(-1.1), DVec3::new(0.7, 0.3, 0.9), 97).unwrap();
        let w = l.window([13, 5, 29], [50, 41, 54]).unwrap();
        assert_eq!(w.cells, [37, 36, 25]);
        assert_eq!(w.num_points(), 38 * 37 * 26);
        for i in [[0, 0, 0], [1, 2, 3], [37, 36, 25]] {
            let whole = l.point([13 + i[0], 5 + i[1], 29 + i[2]]);
            assert_eq!(
                w.point(i).to_array().map(f64::to_bits),
                whole.to_array().map(f64::to_bits)
            );
        }
        assert_eq!(w.origin, l.point([13, 5, 29]));
        let ww = w.window([1, 1, 1], [2, 2, 2]).unwrap();
        assert_eq!(ww.point([1, 1, 1]), l.point([15, 7, 31]));
        assert!(l.window([0, 0, 0], [98, 1, 1]).is_err());
        assert!(l.window([3, 0, 0], [3, 1, 1]).is_err());
    }

    #[test]
    fn crossing_is_on_the_edge() {
        let p = edge_crossing(DVec3::ZERO, DVec3::X, -1.0, 3.0);
        assert!((p - DVec3::new(0.25, 0.0, 0.0)).length() < 1e-15);
    }
}
