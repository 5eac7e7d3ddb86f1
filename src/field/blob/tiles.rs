//! Which primitives of a blob field each tile of a lattice needs, for tiled polygonization: those
//! whose sphere of influence, its radius widened by a relative margin, meets the tile's box. A
//! tile's blob field of those primitives, in their order ([`BlobField::subset`]), has the whole
//! field's values and gradients in the box.

use super::{BlobField, PerPrimitive};
use crate::cancel;
use crate::error::{Error, Result};
use glam::DVec3;
use rayon::prelude::*;

/// A lattice of `cells` cells of side `cell` from `origin`, cut into tiles of `tile` cells per
/// axis (the last tile along an axis holds what is left), numbered x fastest, then y, then z.
#[derive(Clone, Copy, Debug)]
pub struct TileGrid {
    /// Corner of the lattice with the smallest coordinates.
    pub origin: DVec3,
    /// Size of one cell along each axis.
    pub cell: DVec3,
    /// Cells per axis of the lattice.
    pub cells: [u64; 3],
    /// Cells per axis of a tile.
    pub tile: [u64; 3],
}

impl TileGrid {
    /// Tiles per axis.
    pub fn counts(&self) -> [u64; 3] {
        std::array::from_fn(|a| self.cells[a].div_ceil(self.tile[a]))
    }

    /// The corners of tile `t` (its indices per axis), computed as lattice points are: one
    /// product and one sum per coordinate.
    pub fn tile_box(&self, t: [u64; 3]) -> (DVec3, DVec3) {
        let lo: [u64; 3] = std::array::from_fn(|a| t[a] * self.tile[a]);
        let hi: [u64; 3] = std::array::from_fn(|a| (lo[a] + self.tile[a]).min(self.cells[a]));
        let corner = |i: [u64; 3]| {
            self.origin + DVec3::new(i[0] as f64, i[1] as f64, i[2] as f64) * self.cell
        };
        (corner(lo), corner(hi))
    }
}

/// Whether the sphere (`c`, `reach`) meets the closed box `[lo, hi]`.
pub fn sphere_meets_box(c: DVec3, reach: f64, lo: DVec3, hi: DVec3) -> bool {
    let near = (lo - c).max(c - hi).max(DVec3::ZERO);
    near.x * near.x + near.y * near.y + near.z * near.z <= reach * reach
}

/// Primitives per task of the tiling.
const CHUNK: usize = 1 << 16;

impl BlobField {
    /// For each tile of `grid` (in its numbering), the primitives whose radius × (1 +
    /// `margin`) reaches its box ([`sphere_meets_box`]), in increasing order: `(index, start)`,
    /// tile `t`'s primitives being `index[start[t]..start[t + 1]]`. Each primitive is tested
    /// against the tiles its sphere's bounding box meets (widened by a millionth of a tile
    /// against rounding). Errors with [`Error::Interrupted`] when the calling thread's token is
    /// set, and naming `tile` for a tile of no cells or more than 2³² − 1 tiles or primitives.
    pub fn primitives_by_tile(
        &self,
        grid: &TileGrid,
        margin: f64,
    ) -> Result<(Vec<u32>, Vec<usize>)> {
        if grid.tile.contains(&0) {
            return Err(Error::invalid(
                "tile",
                format!("cells per tile edge must be positive, got {:?}", grid.tile),
            ));
        }
        let counts = grid.counts();
        let tiles = counts.iter().product::<u64>();
        if tiles > u64::from(u32::MAX) || self.centers().len() > u32::MAX as usize {
            return Err(Error::invalid(
                "tile",
                format!(
                    "{tiles} tiles of {} primitives: at most 2³² − 1 of each",
                    self.centers().len()
                ),
            ));
        }
        let side = DVec3::new(
            grid.tile[0] as f64,
            grid.tile[1] as f64,
            grid.tile[2] as f64,
        ) * grid.cell;
        let last = DVec3::new(counts[0] as f64, counts[1] as f64, counts[2] as f64) - 1.0;
        let token = cancel::current();
        let pairs: Vec<Vec<(u32, u32)>> = self
            .centers()
            .par_chunks(CHUNK)
            .zip(self.radii().par_chunks(CHUNK))
            .enumerate()
            .map(|(k, (centers, radii))| {
                if token.as_ref().is_some_and(|t| t.stopped()) {
                    return vec![];
                }
                let mut out = Vec::new();
                for (j, (&c, &r)) in centers.iter().zip(radii).enumerate() {
                    let reach = r * (1.0 + margin);
                    let first = (((c - reach - grid.origin) / side) - 1e-6)
                        .floor()
                        .clamp(DVec3::ZERO, last);
                    let end = (((c + reach - grid.origin) / side) + 1e-6)
                        .floor()
                        .clamp(DVec3::ZERO, last);
                    let i = (k * CHUNK + j) as u32;
                    for tz in first.z as u64..=end.z as u64 {
                        for ty in first.y as u64..=end.y as u64 {
                            for tx in first.x as u64..=end.x as u64 {
                                let (lo, hi) = grid.tile_box([tx, ty, tz]);
                                if sphere_meets_box(c, reach, lo, hi) {
                                    out.push((((tz * counts[1] + ty) * counts[0] + tx) as u32, i));
                                }
                            }
                        }
                    }
                }
                out
            })
            .collect();
        cancel::check()?;
        // A counting sort by tile, stable: each tile's primitives stay in increasing order.
        let tiles = tiles as usize;
        let mut start = vec![0usize; tiles + 1];
        for &(t, _) in pairs.iter().flatten() {
            start[t as usize + 1] += 1;
        }
        for t in 0..tiles {
            start[t + 1] += start[t];
        }
        let mut next = start.clone();
        let mut index = vec![0u32; start[tiles]];
        for &(t, i) in pairs.iter().flatten() {
            index[next[t as usize]] = i;
            next[t as usize] += 1;
        }
        Ok((index, start))
    }

    /// The primitives whose radius × (1 + `margin`) reaches the box `[lo, hi]`
    /// ([`sphere_meets_box`], the test of [`BlobField::primitives_by_tile`]), in increasing
    /// order.
    pub fn reaching(&self, lo: DVec3, hi: DVec3, margin: f64) -> Vec<u32> {
        let (centers, radii) = (self.centers(), self.radii());
        (0..centers.len() as u32)
            .filter(|&i| {
                let i = i as usize;
                sphere_meets_box(centers[i], radii[i] * (1.0 + margin), lo, hi)
            })
            .collect()
    }

    /// What the box `[lo, hi]` needs of the field: the [`BlobField::subset`] of the primitives
    /// [`BlobField::reaching`] it, with the field's values and gradients in the box; `None` when
    /// no primitive reaches it (the field is positive there).
    pub fn cut(&self, lo: DVec3, hi: DVec3, margin: f64) -> Result<Option<BlobField>> {
        let keep = self.reaching(lo, hi, margin);
        if keep.is_empty() {
            return Ok(None);
        }
        self.subset(&keep).map(Some)
    }

    /// The blob field of the primitives `keep` (indices, in the order given) with this field's
    /// threshold and settings: the field the same primitives make when passed to
    /// [`BlobField::new`]. Errors naming `index` for an index that is no primitive.
    pub fn subset(&self, keep: &[u32]) -> Result<BlobField> {
        let n = self.centers().len();
        if let Some(&i) = keep.iter().find(|&&i| i as usize >= n) {
            return Err(Error::invalid(
                "index",
                format!("{i} is not a primitive of a field of {n}"),
            ));
        }
        let centers: Vec<DVec3> = keep.iter().map(|&i| self.centers()[i as usize]).collect();
        let radii: Vec<f64> = keep.iter().map(|&i| self.radii()[i as usize]).collect();
        let strengths: Vec<f64> = keep.iter().map(|&i| self.strengths()[i as usize]).collect();
        if let Some((shapes, radii)) = self.shapes_of(keep) {
            return BlobField::with_shapes(
                &centers,
                PerPrimitive::Each(&radii),
                PerPrimitive::Each(&strengths),
                self.threshold(),
                self.settings(),
                &shapes,
            );
        }
        BlobField::new(
            &centers,
            PerPrimitive::Each(&radii),
            PerPrimitive::Each(&strengths),
            self.threshold(),
            self.settings(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::blob::BlobSettings;
    use crate::testing::random_points;

    /// Every tile's primitives are those a test of every primitive against its box finds (and
    /// those a cut to its box keeps), for uneven tiles and spheres from a tenth of a tile to
    /// several tiles.
    #[test]
    fn each_tile_gets_the_primitives_that_reach_it() {
        let centers: Vec<DVec3> = random_points(500, -1.3, 1.3, 4);
        let radii: Vec<f64> = (0..500)
            .map(|i| 0.02 + 0.6 * ((i * 37 % 101) as f64 / 101.0))
            .collect();
        let field = BlobField::new(
            &centers,
            PerPrimitive::Each(&radii),
            PerPrimitive::All(1.0),
            0.5,
            BlobSettings::default(),
        )
        .unwrap();
        let grid = TileGrid {
            origin: DVec3::new(-1.0, -1.0, -1.0),
            cell: DVec3::splat(2.0 / 23.0),
            cells: [23, 23, 23],
            tile: [5, 7, 23],
        };
        let margin = 1e-6;
        let (index, start) = field.primitives_by_tile(&grid, margin).unwrap();
        let counts = grid.counts();
        assert_eq!(start.len() as u64, counts[0] * counts[1] * counts[2] + 1);
        let mut t = 0;
        for tz in 0..counts[2] {
            for ty in 0..counts[1] {
                for tx in 0..counts[0] {
                    let (lo, hi) = grid.tile_box([tx, ty, tz]);
                    let expected: Vec<u32> = (0..centers.len() as u32)
                        .filter(|&i| {
                            sphere_meets_box(
                                centers[i as usize],
                                radii[i as usize] * (1.0 + margin),
                                lo,
                                hi,
                            )
                        })
                        .collect();
                    assert_eq!(&index[start[t]..start[t + 1]], &expected[..]);
                    assert_eq!(field.reaching(lo, hi, margin), expected);
                    let cut = field.cut(lo, hi, margin).unwrap();
                    assert_eq!(cut.map_or(0, |c| c.centers().len()), expected.len());
                    t += 1;
                }
            }
        }
        // A subset has the primitives asked for, in that order.
        let keep = &index[start[3]..start[4]];
        let part = field.subset(keep).unwrap();
        assert_eq!(part.centers().len(), keep.len());
        assert!(keep
            .iter()
            .zip(part.radii())
            .all(|(&i, &r)| r == radii[i as usize]));
        // Bad input is an error, not a panic.
        assert!(field.subset(&[0, 500]).is_err());
        let no_cells = TileGrid {
            tile: [5, 0, 5],
            ..grid
        };
        assert!(field.primitives_by_tile(&no_cells, margin).is_err());
    }
}
