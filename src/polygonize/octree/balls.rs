//! Signs inferred from the balls of known values: no surface lies within |f(p)| / safety of a
//! point p, so every point in that ball has the sign of f(p).

use glam::DVec3;

/// The block points within a distance of a block point: the ball of radius |f(p)| / safety
/// around point p holds the points `mask` of the last entry of `REACH[p]` whose `reach` is below
/// f(p)² (the distances, squared and times safety², in increasing order, each once).
#[derive(Clone, Copy)]
pub(super) struct Reach {
    pub(super) reach: f64,
    pub(super) mask: u32,
}

/// [`Reach`] lists for the 27 points of a block of cells of size `cell`: at most 26 entries
/// each (9 for cubic cells), ended by an entry of infinite reach.
pub(super) fn block_reach(cell: DVec3, safety: f64) -> Box<[[Reach; 27]; 27]> {
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

/// [`balls`] of the points of `known` with the values `v` (bits and indices as in
/// [`block_point`](super::block::block_point)).
#[cfg(test)]
pub(super) fn ball_masks(v: &[f64; 27], known: u32, reach: &[[Reach; 27]; 27]) -> (u32, u32) {
    balls(
        crate::polygonize::bits::set_bits(known).map(|p| (p, v[p])),
        reach,
    )
}

/// The block points inside the balls of the values known in the block, `known` as (block
/// point, value; NaN where there is none): (inside a ball of a negative value, inside a ball of
/// a positive value). No surface lies within |f(p)| / safety of a point p (the rejection test's
/// premise), so a point in that ball has the sign of f(p).
#[inline]
pub(super) fn balls(
    known: impl Iterator<Item = (usize, f64)>,
    reach: &[[Reach; 27]; 27],
) -> (u32, u32) {
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
