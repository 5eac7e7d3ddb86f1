//! The points a scan fit interpolates: a subset of the cleaned points, no two nearer than a
//! given distance.
//!
//! The cleaning projects every point onto a surface that is smooth over a few spacings
//! ([`ScanSettings::projection_width`](super::ScanSettings::projection_width) of them); an
//! interpolant of points about one spacing apart on it follows it as closely as one of all of
//! them, and its fit costs in proportion to the points it interpolates. Dense scans hold
//! several points per spacing (the spacing is the distance to the 6th neighbour): the fit of
//! the subset is the cheaper by about that factor. The guard's winding number and the
//! distances to the data still use every cleaned point.

use crate::spatial::Grid;
use glam::DVec3;

/// Indices (increasing) of a subset of `points` in which no two lie within `separation` of each
/// other and every point lies within `separation` of one of the subset: points taken greedily
/// in the order of a grid of cells `separation` wide, each kept when no kept point is that
/// near. Deterministic. All points for a `separation` that is not positive.
pub fn separated(points: &[DVec3], separation: f64) -> Vec<u32> {
    if separation.is_nan() || separation <= 0.0 || points.is_empty() {
        return (0..points.len() as u32).collect();
    }
    let grid = Grid::new(points, separation);
    let mut kept = vec![false; points.len()];
    for &i in grid.order() {
        let p = points[i as usize];
        if !grid.any_within(p, separation, |j, _| kept[j as usize]) {
            kept[i as usize] = true;
        }
    }
    (0..points.len() as u32)
        .filter(|&i| kept[i as usize])
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::random_points;

    #[test]
    fn kept_points_are_apart_and_cover_the_rest() {
        let points = random_points(5_000, -1.0, 1.0, 3);
        let r = 0.15;
        let kept = separated(&points, r);
        assert!(
            kept.len() > 10 && kept.len() < points.len() / 4,
            "{}",
            kept.len()
        );
        assert!(kept.windows(2).all(|w| w[0] < w[1]));
        for (a, &i) in kept.iter().enumerate() {
            for &j in &kept[a + 1..] {
                assert!(points[i as usize].distance(points[j as usize]) > r);
            }
        }
        for p in &points {
            assert!(kept.iter().any(|&i| points[i as usize].distance(*p) <= r));
        }
        assert_eq!(separated(&points, 0.0).len(), points.len());
    }
}
