//! Whether the balls around a box's corners cover it: the corner test of the levels.

use crate::polygonize::bits::set_bits;
use crate::polygonize::cell::Corner;
use glam::DVec3;

/// Levels of octant splitting with which [`covered`] tries to prove a box free of the surface
/// (the finest pieces are 1/8 of the box per side).
const COVER_DEPTH: u32 = 3;

/// Whether the balls around the box's corners cover it: corner k (case-bit order) of the box
/// `[0, size]` carries a ball of radius `radius[k]` (NaN: no ball). Under the same assumption as
/// the rejection test (|f| under-estimates the distance to the surface, so no surface point lies
/// within |f(x)|/safety of x), a covered box holds no surface. Proven by splitting the box into
/// octants, down to [`COVER_DEPTH`] levels: a piece is covered when one ball holds all of it.
pub(super) fn covered(radius: &[f64; 8], size: DVec3) -> bool {
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
    for (k, &r) in Corner::ALL.iter().zip(radius) {
        if r > 0.0 {
            let d = k.offset();
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
    if !Corner::ALL.iter().all(|k| {
        let d = k.offset();
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
pub(super) fn covered_by_opposite_balls(r0: f64, r1: f64, size: DVec3) -> bool {
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
pub(super) fn covered_piece(
    balls: &[(DVec3, f64)],
    mask: u32,
    lo: DVec3,
    hi: DVec3,
    depth: u32,
) -> bool {
    let mid = 0.5 * (lo + hi);
    let (mut mid_covered, mut touching) = (false, 0u32);
    for i in set_bits(mask) {
        let (c, r2) = balls[i];
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
    Corner::ALL.iter().all(|k| {
        let d = k.offset();
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
