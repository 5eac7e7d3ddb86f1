//! A uniform grid over a point set, for fixed-radius neighbour queries: the points are sorted by
//! cell (in parallel), so that the points of a cell are one contiguous run of indices, and
//! queries read them from a copy in that order. Queries issued in [`Grid::order`] find their
//! neighbours in memory the previous query read.
//!
//! The number of cells is capped at about eight per point, so a query radius far below the
//! spacing of the points (a duplicate tolerance) still gives a grid of bounded size; queries
//! then visit one cell and its neighbours and test the distances.

use glam::DVec3;
use rayon::prelude::*;

/// Cells per parallel job when the cells' starts are found.
const CELLS_PER_RUN: usize = 1 << 16;

/// The side of the cells of a grid over `n` points whose bounding box has sides `extent`:
/// `cell`, or larger when `cell` would give more than about eight cells per point (or is not
/// positive and finite).
fn cell_side(extent: DVec3, n: usize, cell: f64) -> f64 {
    let max_cells = (8 * n).max(64) as f64;
    let mut cell = if cell.is_finite() && cell > 0.0 {
        cell
    } else {
        f64::INFINITY
    };
    let cells_for = |c: f64| -> f64 {
        (0..3)
            .map(|k| (extent[k] / c).floor() + 1.0)
            .product::<f64>()
    };
    let largest = extent.max_element();
    if !cell.is_finite() || cells_for(cell) > max_cells {
        // Grow the cell until the grid is small enough (the ratio is applied per axis).
        cell = if largest > 0.0 {
            largest / max_cells.cbrt().floor().max(1.0)
        } else {
            1.0
        };
        while cells_for(cell) > max_cells {
            cell *= 1.25;
        }
    }
    cell
}

/// Points binned into cubic cells.
pub struct Grid<'a> {
    points: &'a [DVec3],
    lo: DVec3,
    extent: DVec3,
    cell: f64,
    dims: [usize; 3],
    /// `start[c]..start[c + 1]` indexes `order` for the points of cell `c`.
    start: Vec<u32>,
    /// Point indices, sorted by cell and, within a cell, increasing.
    order: Vec<u32>,
    /// The points in the order of `order`.
    sorted: Vec<DVec3>,
}

impl<'a> Grid<'a> {
    /// Bins `points` (finite) into cells of side at least `cell` (larger when `cell` would give
    /// more than about eight cells per point).
    pub fn new(points: &'a [DVec3], cell: f64) -> Self {
        let (lo, hi) = points
            .par_iter()
            .fold(
                || (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
                |(lo, hi), p| (lo.min(*p), hi.max(*p)),
            )
            .reduce(
                || (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
                |(a, b), (c, d)| (a.min(c), b.max(d)),
            );
        let (lo, hi) = if points.is_empty() {
            (DVec3::ZERO, DVec3::ZERO)
        } else {
            (lo, hi)
        };
        let extent = (hi - lo).max(DVec3::splat(0.0));
        let cell = cell_side(extent, points.len(), cell);
        let dims = [0, 1, 2].map(|k| (extent[k] / cell).floor() as usize + 1);
        let ncells = dims[0] * dims[1] * dims[2];
        let key = |p: DVec3| -> usize {
            let c = |k: usize| (((p[k] - lo[k]) / cell).floor() as usize).min(dims[k] - 1);
            c(0) + dims[0] * (c(1) + dims[1] * c(2))
        };
        // The points sorted by (cell, index), in parallel: one key of both per point.
        let mut keyed: Vec<u64> = points
            .par_iter()
            .enumerate()
            .map(|(i, p)| ((key(*p) as u64) << 32) | i as u64)
            .collect();
        keyed.par_sort_unstable();
        let order: Vec<u32> = keyed.par_iter().map(|&k| k as u32).collect();
        // `start[c]`: the points in cells before c, found for runs of cells in parallel (each
        // run's first from a binary search, the rest by walking the sorted keys).
        let mut start = vec![0u32; ncells + 1];
        start
            .par_chunks_mut(CELLS_PER_RUN)
            .enumerate()
            .for_each(|(r, run)| {
                let c0 = (r * CELLS_PER_RUN) as u64;
                let mut at = keyed.partition_point(|&k| k >> 32 < c0);
                for (c, s) in (c0..).zip(run.iter_mut()) {
                    while at < keyed.len() && keyed[at] >> 32 < c {
                        at += 1;
                    }
                    *s = at as u32;
                }
            });
        drop(keyed);
        let sorted = order.par_iter().map(|&i| points[i as usize]).collect();
        Grid {
            points,
            lo,
            extent,
            cell,
            dims,
            start,
            order,
            sorted,
        }
    }

    /// Whether `Grid::new(points, cell)` over this grid's points gives this grid (the same
    /// cells).
    pub fn is_grid_of(&self, cell: f64) -> bool {
        cell_side(self.extent, self.points.len(), cell) == self.cell
    }

    /// The point indices sorted by cell (increasing within a cell): queries around the points
    /// in this order read memory that the query before read.
    pub fn order(&self) -> &[u32] {
        &self.order
    }

    /// The smallest index of each non-empty cell.
    pub fn first_of_each_cell(&self) -> Vec<u32> {
        self.start
            .windows(2)
            .filter(|w| w[1] > w[0])
            .map(|w| self.order[w[0] as usize])
            .collect()
    }

    /// Calls `visit(j)` for every point `j` with `|points[j] − p| ≤ radius`, cell by cell (z,
    /// then y, then x), increasing within a cell.
    pub fn for_each_within(&self, p: DVec3, radius: f64, mut visit: impl FnMut(u32)) {
        self.for_each_within_points(p, radius, |j, _| visit(j));
    }

    /// As [`Grid::for_each_within`], with the point: `visit(j, points[j])`.
    pub fn for_each_within_points(&self, p: DVec3, radius: f64, mut visit: impl FnMut(u32, DVec3)) {
        let r2 = radius * radius;
        self.for_each_cell_within(p, radius, |run, pts| {
            for (&j, q) in run.iter().zip(pts) {
                if (*q - p).length_squared() <= r2 {
                    visit(j, *q);
                }
            }
            false
        });
    }

    /// Calls `visit(indices, points)` with the points of each row of cells meeting the cube of
    /// half-side `radius` around `p` (z, then y), until it returns `true`.
    fn for_each_cell_within(
        &self,
        p: DVec3,
        radius: f64,
        mut visit: impl FnMut(&[u32], &[DVec3]) -> bool,
    ) {
        if self.points.is_empty() {
            return;
        }
        let range = |k: usize| -> Option<(usize, usize)> {
            let a = ((p[k] - radius - self.lo[k]) / self.cell).floor();
            let b = ((p[k] + radius - self.lo[k]) / self.cell).floor();
            let top = (self.dims[k] - 1) as f64;
            if b < 0.0 || a > top {
                return None;
            }
            Some((a.max(0.0) as usize, b.min(top) as usize))
        };
        let (Some(rx), Some(ry), Some(rz)) = (range(0), range(1), range(2)) else {
            return;
        };
        for z in rz.0..=rz.1 {
            for y in ry.0..=ry.1 {
                let row = self.dims[0] * (y + self.dims[1] * z);
                let (a, b) = (
                    self.start[row + rx.0] as usize,
                    self.start[row + rx.1 + 1] as usize,
                );
                if visit(&self.order[a..b], &self.sorted[a..b]) {
                    return;
                }
            }
        }
    }

    /// Whether `accept(j, points[j])` holds for some point `j` within `radius` of `p`; stops at
    /// the first.
    pub fn any_within(
        &self,
        p: DVec3,
        radius: f64,
        mut accept: impl FnMut(u32, DVec3) -> bool,
    ) -> bool {
        let mut found = false;
        self.for_each_cell_within(p, radius, |run, pts| {
            found = run
                .iter()
                .zip(pts)
                .any(|(&j, q)| (*q - p).length_squared() <= radius * radius && accept(j, *q));
            found
        });
        found
    }

    /// The indices of the points within `radius` of `p`, increasing.
    pub fn within(&self, p: DVec3, radius: f64) -> Vec<u32> {
        let mut out = Vec::new();
        self.for_each_within(p, radius, |j| out.push(j));
        out.sort_unstable();
        out
    }
}

/// Points farther than this many times the extent of their bulk ([`Bulk`]) from its centre are
/// refused by the structures sized from coordinates (voxel grids, cell lists, trees): such a
/// grid either has cells too large for the bulk or too many cells, and a fit's system cannot
/// hold both scales.
pub const FAR: f64 = 1e3;

/// The largest span of a point set along an axis that [`check_far`] lets through: squared
/// distances (sums of three squares) between its points stay finite.
pub const MAX_SPAN: f64 = 1e150;

/// Points farther than this many times the extent of their bulk from its centre lie outside
/// the bulk: a fit's default bounds leave them out ([`Bulk::bounding_box`]).
pub const OUTSIDE: f64 = 50.0;

/// Where most of a point set lies: the per-axis median and the largest per-axis spread between
/// the 5th and 95th percentiles, both over at most 2¹⁶ points taken at a fixed stride (so a
/// few far points move neither).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bulk {
    /// Per-axis median.
    pub centre: DVec3,
    /// Largest 5th–95th percentile spread over the three axes; when it is zero, the largest
    /// side of the bounding box (so that coincident bulks make no point far).
    pub extent: f64,
}

impl Bulk {
    /// The bulk of `points` (finite; `None` when empty).
    pub fn of(points: &[DVec3]) -> Option<Bulk> {
        if points.is_empty() {
            return None;
        }
        const SAMPLE: usize = 1 << 16;
        let step = points.len().div_ceil(SAMPLE);
        let mut axis = Vec::with_capacity(points.len().div_ceil(step));
        let (mut centre, mut extent) = (DVec3::ZERO, 0.0f64);
        for k in 0..3 {
            axis.clear();
            axis.extend(points.iter().step_by(step).map(|p| p[k]));
            let n = axis.len();
            let mut at = |q: f64| {
                let i = ((q * (n - 1) as f64).round() as usize).min(n - 1);
                *axis.select_nth_unstable_by(i, f64::total_cmp).1
            };
            centre[k] = at(0.5);
            extent = extent.max(at(0.95) - at(0.05));
        }
        if extent.is_nan() || extent <= 0.0 {
            let (lo, hi) = points.iter().fold(
                (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
                |(lo, hi), p| (lo.min(*p), hi.max(*p)),
            );
            extent = (hi - lo).max_element();
        }
        Some(Bulk { centre, extent })
    }

    /// The distance of `p` from the centre, in units of the extent (infinite for a bulk of one
    /// point repeated, unless `p` is that point).
    pub fn ratio(&self, p: DVec3) -> f64 {
        distance(p, self.centre) / self.extent
    }

    /// The bounding box of the points within [`OUTSIDE`] extents of the centre, and how many
    /// points lie beyond.
    pub fn bounding_box(&self, points: &[DVec3]) -> ((DVec3, DVec3), usize) {
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        let mut outside = 0;
        for p in points {
            if self.ratio(*p) > OUTSIDE {
                outside += 1;
            } else {
                (lo, hi) = (lo.min(*p), hi.max(*p));
            }
        }
        ((lo, hi), outside)
    }

    /// The points farther than `factor` extents from the centre: how many, and the farthest
    /// (index, distance, ratio).
    pub fn beyond(&self, points: &[DVec3], factor: f64) -> Option<Beyond> {
        let (count, far) = points
            .par_iter()
            .enumerate()
            .map(|(i, p)| (i, self.ratio(*p)))
            .filter(|&(_, r)| r > factor)
            .fold(
                || (0usize, None::<(usize, f64)>),
                |(n, best), (i, r)| (n + 1, pick(best, Some((i, r)))),
            )
            .reduce(|| (0, None), |(n, a), (m, b)| (n + m, pick(a, b)));
        far.map(|(index, ratio)| Beyond {
            count,
            index,
            distance: distance(points[index], self.centre),
            ratio,
            extent: self.extent,
        })
    }
}

/// The farther of two (index, ratio) pairs; the lower index on ties (so the result does not
/// depend on how the work was split).
fn pick(a: Option<(usize, f64)>, b: Option<(usize, f64)>) -> Option<(usize, f64)> {
    match (a, b) {
        (Some(x), Some(y)) => Some(if y.1 > x.1 || (y.1 == x.1 && y.0 < x.0) {
            y
        } else {
            x
        }),
        (x, None) => x,
        (None, y) => y,
    }
}

/// |a − b| without overflow for finite points anywhere in the range of f64 (infinite only when
/// the difference itself is).
fn distance(a: DVec3, b: DVec3) -> f64 {
    let d = a - b;
    let m = d.abs().max_element();
    if m == 0.0 || !m.is_finite() {
        m
    } else {
        m * (d / m).length()
    }
}

/// A point as `[x, y, z]` with four significant digits.
pub fn short(p: DVec3) -> String {
    format!("[{:.3e}, {:.3e}, {:.3e}]", p.x, p.y, p.z)
}

/// Points far from their bulk ([`Bulk::beyond`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Beyond {
    /// How many points lie beyond the factor.
    pub count: usize,
    /// The farthest one.
    pub index: usize,
    /// Its distance from the bulk's centre.
    pub distance: f64,
    /// That distance in units of the bulk's extent.
    pub ratio: f64,
    /// The bulk's extent.
    pub extent: f64,
}

impl std::fmt::Display for Beyond {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "entry {} lies {:.3e} from the median of the entries, {:.2e} times the extent of their bulk ({:.3e}, their largest 5th–95th percentile spread)",
            self.index, self.distance, self.ratio, self.extent
        )?;
        if self.count > 1 {
            write!(f, "; {} entries lie that far", self.count)?;
        }
        Ok(())
    }
}

/// Refuses points (finite) that span more than [`MAX_SPAN`] along an axis, or of which any lies
/// more than [`FAR`] extents from their bulk, naming argument `name`: grids and trees sized from
/// such points would have cells too coarse for the bulk or too many cells, and comparisons of
/// squared distances would overflow.
pub fn check_far(name: &'static str, points: &[DVec3]) -> crate::Result<()> {
    let Some(bulk) = Bulk::of(points) else {
        return Ok(());
    };
    if let Some(b) = bulk.beyond(points, FAR) {
        return Err(crate::Error::invalid(
            name,
            format!(
                "{b} (more than {FAR:.0} times is refused: one grid or tree cannot hold both scales); remove or move the far entries, or handle them separately"
            ),
        ));
    }
    let (lo, hi) = points.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let span = (hi - lo).max_element();
    if span.is_nan() || span > MAX_SPAN {
        return Err(crate::Error::invalid(
            name,
            format!(
                "the entries span from {} to {}, more than {MAX_SPAN:e} along an axis: squared distances between them overflow float64",
                short(lo),
                short(hi)
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::random_points;

    #[test]
    fn far_points_are_named_and_left_out_of_the_bulk_box() {
        let mut p = random_points(1000, -1.0, 1.0, 3);
        assert_eq!(check_far("points", &p), Ok(()));
        let bulk = Bulk::of(&p).unwrap();
        assert!(bulk.extent > 1.5 && bulk.extent < 2.0, "{bulk:?}");
        // Within FAR: accepted, but outside the bulk's box.
        p.push(DVec3::new(100.0, 0.0, 0.0));
        assert_eq!(check_far("points", &p), Ok(()));
        let (b, outside) = Bulk::of(&p).unwrap().bounding_box(&p);
        assert_eq!(outside, 1);
        assert_eq!(b, Bulk::of(&p[..1000]).unwrap().bounding_box(&p[..1000]).0);
        // Beyond FAR, at any magnitude up to the largest float: refused, naming the entry.
        for far in [1e6, 1e200, f64::MAX] {
            p[1000].x = far;
            let e = check_far("points", &p).unwrap_err().to_string();
            assert!(
                e.starts_with(&format!(
                    "points: entry 1000 lies {far:.3e} from the median"
                )),
                "{e}"
            );
        }
        // Spans whose squares overflow: refused whatever the bulk.
        let two = [
            DVec3::ZERO,
            DVec3::ZERO,
            DVec3::splat(1e200),
            DVec3::splat(1e200),
        ];
        assert!(check_far("points", &two)
            .unwrap_err()
            .to_string()
            .contains("squared distances"));
        // A bulk of one point repeated makes no point far.
        let same = [
            DVec3::ONE,
            DVec3::ONE,
            DVec3::ONE,
            DVec3::new(1.0, 2.0, 1.0),
        ];
        assert_eq!(check_far("points", &same), Ok(()));
        assert_eq!(check_far("points", &[]), Ok(()));
    }

    #[test]
    fn finds_the_same_neighbours_as_brute_force() {
        let pts = random_points(500, -1.0, 1.0, 5);
        for (cell, radius) in [(0.2, 0.2), (0.05, 0.3), (1e-12, 0.1), (10.0, 0.25)] {
            let g = Grid::new(&pts, cell);
            for p in pts.iter().step_by(7).chain([DVec3::splat(3.0)].iter()) {
                let brute: Vec<u32> = (0..pts.len() as u32)
                    .filter(|&j| (pts[j as usize] - *p).length_squared() <= radius * radius)
                    .collect();
                assert_eq!(g.within(*p, radius), brute, "cell {cell}, radius {radius}");
            }
        }
        assert!(Grid::new(&[], 0.1).within(DVec3::ZERO, 1.0).is_empty());
    }

    /// Cells hold their points in increasing order, cell after cell (z, then y, then x), as a
    /// sequential counting sort puts them; and a grid knows the cell sides that give it.
    #[test]
    fn points_are_sorted_by_cell_then_index() {
        let pts = random_points(3000, -1.0, 1.0, 4);
        for cell in [0.0, 0.03, 0.3, 5.0] {
            let g = Grid::new(&pts, cell);
            let key = |i: u32| {
                let p = pts[i as usize];
                let c =
                    |k: usize| (((p[k] - g.lo[k]) / g.cell).floor() as usize).min(g.dims[k] - 1);
                c(0) + g.dims[0] * (c(1) + g.dims[1] * c(2))
            };
            let mut want: Vec<u32> = (0..pts.len() as u32).collect();
            want.sort_by_key(|&i| (key(i), i));
            assert_eq!(g.order, want);
            for (c, w) in g.start.windows(2).enumerate() {
                assert!(g.order[w[0] as usize..w[1] as usize]
                    .iter()
                    .all(|&i| key(i) == c));
            }
            assert_eq!(*g.start.last().unwrap() as usize, pts.len());
            assert!(g.is_grid_of(cell));
        }
        // Any cell side below the capped one gives the capped grid; a larger one another grid.
        let capped = Grid::new(&pts, 0.0);
        assert!(capped.is_grid_of(1e-9) && !capped.is_grid_of(0.5));
    }

    #[test]
    fn any_within_agrees_with_brute_force() {
        let pts = random_points(400, -1.0, 1.0, 9);
        let g = Grid::new(&pts, 0.1);
        for (i, p) in pts.iter().enumerate().step_by(3) {
            for radius in [0.01, 0.05, 0.2] {
                // Another point nearer than `radius`; the grid's query stops at the first.
                let brute = (0..pts.len())
                    .any(|j| j != i && (pts[j] - *p).length_squared() <= radius * radius);
                assert_eq!(g.any_within(*p, radius, |j, _| j as usize != i), brute);
            }
        }
    }
}
