//! Scan points averaged in cells, for noise as large as the spacing.
//!
//! A neighbourhood of a few tens of points is a disc about two spacings wide. Where the noise
//! along the rays is a sizeable fraction of that, the neighbourhood is a slab rather than a
//! disc: its principal-component normal, its votes and its projection no longer tell where the
//! surface is. Averaging the points of each cell a few spacings wide divides the noise by the
//! square root of their number while the spacing grows to the cell's side; the averaged points
//! are then cleaned as a scan whose noise is small against its spacing. Only points whose given
//! normals share a dominant axis and its sign are averaged together, so that the two sides of a
//! part thinner than a cell are not.

use glam::DVec3;
use rayon::prelude::*;

/// Points averaged per cell and side (see the module's documentation).
#[derive(Clone, Debug, Default)]
pub struct Averaged {
    /// The mean of each group's points.
    pub points: Vec<DVec3>,
    /// The normalised sum of each group's normals.
    pub normals: Vec<DVec3>,
    /// For each of the caller's points, its group (`u32::MAX` for a point left out).
    pub group_of: Vec<u32>,
}

/// The side of a normal: its dominant axis and that component's sign, `0..6`.
fn side_of(n: DVec3) -> u8 {
    let a = n.abs();
    let axis = if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    };
    2 * axis + (n[axis as usize] < 0.0) as u8
}

/// The points `used` (one flag per point) grouped by cells of side `side` (> 0) and by the
/// side of their normal, each group averaged. Groups are ordered by cell, then side.
pub fn average(points: &[DVec3], normals: &[DVec3], used: &[bool], side: f64) -> Averaged {
    let lo = points
        .iter()
        .zip(used)
        .filter(|(_, &u)| u)
        .fold(DVec3::INFINITY, |a, (p, _)| a.min(*p));
    let inverse = 1.0 / side;
    let mut keyed: Vec<([i64; 3], u8, u32)> = (0..points.len())
        .into_par_iter()
        .filter(|&i| used[i])
        .map(|i| {
            let c = ((points[i] - lo) * inverse).floor();
            (
                [c.x as i64, c.y as i64, c.z as i64],
                side_of(normals[i]),
                i as u32,
            )
        })
        .collect();
    keyed.par_sort_unstable_by_key(|&(c, s, i)| ([c[2], c[1], c[0]], s, i));
    let mut out = Averaged {
        group_of: vec![u32::MAX; points.len()],
        ..Averaged::default()
    };
    let mut start = 0;
    while start < keyed.len() {
        let key = (keyed[start].0, keyed[start].1);
        let end = start
            + keyed[start..]
                .iter()
                .take_while(|&&(c, s, _)| (c, s) == key)
                .count();
        let group = out.points.len() as u32;
        let (mut p, mut n) = (DVec3::ZERO, DVec3::ZERO);
        for &(_, _, i) in &keyed[start..end] {
            p += points[i as usize];
            n += normals[i as usize];
            out.group_of[i as usize] = group;
        }
        out.points.push(p / (end - start) as f64);
        let first = normals[keyed[start].2 as usize];
        out.normals.push(n.try_normalize().unwrap_or(first));
        start = end;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::fibonacci_sphere;

    #[test]
    fn averages_stay_on_their_side_and_cover_every_used_point() {
        // A thin shell: two spheres 0.01 apart, normals facing away from each other.
        let outer = fibonacci_sphere(4_000);
        let mut points: Vec<DVec3> = outer.clone();
        let mut normals = outer.clone();
        points.extend(outer.iter().map(|p| *p * 0.99));
        normals.extend(outer.iter().map(|p| -*p));
        let mut used = vec![true; points.len()];
        used[17] = false;
        let a = average(&points, &normals, &used, 0.2);
        assert!(a.points.len() < points.len() / 4, "{}", a.points.len());
        assert_eq!(a.group_of[17], u32::MAX);
        for (i, &g) in a.group_of.iter().enumerate() {
            if i == 17 {
                continue;
            }
            let g = g as usize;
            assert!(a.points[g].distance(points[i]) < 0.2 * 3f64.sqrt());
            // A group holds one side only: its normal agrees with each member's.
            assert!(a.normals[g].dot(normals[i]) > 0.3);
        }
        // Outer groups stay near and within the outer sheet, inner groups within the inner one.
        for (p, n) in a.points.iter().zip(&a.normals) {
            let r = p.length();
            if n.dot(*p) > 0.0 {
                assert!(r > 0.97 && r <= 1.0 + 1e-12, "{r}");
            } else {
                assert!(r <= 0.99 + 1e-12, "{r}");
            }
        }
    }
}
