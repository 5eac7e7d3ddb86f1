//! From raw scan points to the points a fit may interpolate: the data's spacing and noise
//! estimated from the points themselves, outliers found and left out, normals made consistent
//! with their neighbourhood, and every point moved onto the plane fitted to its neighbours
//! (a moving-least-squares projection), which averages noise and misregistered sheets into one.
//!
//! Each step reads the `k` nearest neighbours of every point (a [`PointTree`]):
//!
//! 1. **Spacing and isolation.** The spacing is the median distance to the 6th neighbour. A
//!    point whose 10th neighbour is farther than [`ScanSettings::isolation`] times the median
//!    of that distance stands alone: an outlier. So is a point whose 3rd neighbour is farther
//!    than [`LOCAL_RATIO`] times the median of its neighbours' own such distances: it lies off
//!    the surface they sample.
//! 2. **Local planes and noise.** Principal component analysis of each point's neighbours (the
//!    point itself left out) gives a normal, the plane through the neighbourhood's mean, and the root-mean-square distance of
//!    the neighbourhood from that plane; the data's noise is the median of the latter. A point
//!    farther from its plane than `3·spread + 6·median offset + 3·noise` is an outlier too, the
//!    spread being 1.4826 times the median distance of the neighbours from their plane (robust
//!    to a few stray points among them).
//!    Where the noise exceeds [`ScanSettings::coarsening`] times the spacing, the neighbourhood
//!    is a slab rather than a disc: the valid points are averaged in cells two spacings wide,
//!    each side of a thin part apart ([`mod@super::coarsen`]), and the averages are cleaned in
//!    their place (each point is kept when its average is).
//! 3. **Normals.** Each point takes its neighbourhood's normal, with the sign of its own normal.
//!    Then, for [`ScanSettings::voting_rounds`] rounds, a point whose neighbours mostly face the
//!    other way (more than 1.5 times as many) turns around.
//!    If the normals, made consistent, point into the body the points enclose (their flux
//!    about the points' mean is negative), all are turned.
//! 4. **Projection.** Each point moves onto the quadric height field fitted over its
//!    neighbourhood's plane, with Gaussian weights of width
//!    `h = projection_width · max(spacing, 2 · noise)`, to itself and the neighbours that face
//!    its way (normals within 60°, so that the two sides of a thin part stay apart); the
//!    quadric's normal there is the point's new normal. Where the noise exceeds a tenth of the
//!    spacing, the neighbourhood is [`ScanSettings::projection_neighbours`] points, so that
//!    the quadric's six coefficients average the noise.

use super::{coarsen, ScanSettings};
use crate::error::{Error, Result};
use crate::knn::{smallest_eigenvector, Neighbourhoods, PointTree};
use glam::DVec3;
use rayon::prelude::*;

/// The neighbour whose distance measures the spacing (the nearest is 1).
const SPACING_NEIGHBOUR: usize = 6;
/// The neighbour whose distance measures isolation.
const ISOLATION_NEIGHBOUR: usize = 10;
/// The neighbour whose distance, against its neighbours' own, tells a point off the surface.
const LOCAL_NEIGHBOUR: usize = 3;
/// How many times farther than its neighbours' own that distance may be.
pub const LOCAL_RATIO: f64 = 3.0;
/// The neighbour whose distance gives a point's area, π r² / AREA_NEIGHBOUR.
const AREA_NEIGHBOUR: usize = 8;
/// The side of the cells points are averaged in, in spacings ([`mod@super::coarsen`]).
const AVERAGING_CELL: f64 = 2.0;
/// Noise above this fraction of the spacing is projected over
/// [`ScanSettings::projection_neighbours`] neighbours.
const NOISY: f64 = 0.1;
/// Averagings at most, one after the other, while the noise stays large against the spacing.
const MAX_AVERAGINGS: usize = 3;
/// The points are averaged only when that leaves fewer than this fraction of them.
const AVERAGING_GAIN: f64 = 0.7;

/// Scan points made ready for a fit (see the module's documentation).
#[derive(Clone, Debug)]
pub struct Cleaned {
    /// The kept points, projected onto their local planes.
    pub points: Vec<DVec3>,
    /// Their unit normals, consistent with their neighbours'.
    pub normals: Vec<DVec3>,
    /// The area each kept point stands for (for the winding number).
    pub areas: Vec<f64>,
    /// The indices of the caller's points that were kept (not outliers), increasing.
    pub kept: Vec<u32>,
    /// For each of the caller's points, the kept point that stands for it (itself, projected,
    /// or the average of its cell, see [`mod@super::coarsen`]); `u32::MAX` for an outlier.
    pub representative: Vec<u32>,
    /// The indices of the points left out as outliers, increasing.
    pub outliers: Vec<u32>,
    /// The median distance from a cleaned point to its 6th nearest neighbour (from an average
    /// to its 6th, where the points were averaged).
    pub spacing: f64,
    /// The estimated noise: the median root-mean-square distance of a neighbourhood from its
    /// plane.
    pub noise: f64,
    /// Kept points whose normal now points against the one they were given.
    pub normals_corrected: usize,
    /// Whether the normals, made consistent, pointed into the body the points enclose (a
    /// negative flux Σ aᵢ (pᵢ − c)·nᵢ about the points' mean c) and all were turned.
    pub turned_outward: bool,
}

impl Cleaned {
    /// This cleaning of points that stand for groups of the caller's points (`group_of`, one
    /// per caller's point, `u32::MAX` for a point left out), as a cleaning of the caller's
    /// points with their `normals`: a point is kept when its group is, and a normal counts as
    /// corrected when its group's cleaned normal points against it.
    fn standing_for(mut self, group_of: &[u32], normals: &[DVec3]) -> Cleaned {
        let representative: Vec<u32> = group_of
            .iter()
            .map(|&g| match g {
                u32::MAX => u32::MAX,
                g => self.representative[g as usize],
            })
            .collect();
        self.kept = (0..group_of.len() as u32)
            .filter(|&i| representative[i as usize] != u32::MAX)
            .collect();
        self.outliers = (0..group_of.len() as u32)
            .filter(|&i| representative[i as usize] == u32::MAX)
            .collect();
        self.normals_corrected = self
            .kept
            .iter()
            .filter(|&&i| {
                let r = representative[i as usize] as usize;
                self.normals[r].dot(normals[i as usize]) < 0.0
            })
            .count();
        self.representative = representative;
        self
    }
}

/// What principal component analysis tells about one point's neighbourhood.
#[derive(Clone, Copy, Debug, Default)]
struct Local {
    normal: DVec3,
    rms: f64,
    /// 1.4826 × the median distance of the neighbours from their plane: their spread, robust
    /// to a few stray points among them.
    spread: f64,
    offset: f64,
}

/// The mean and covariance of weighted points, and the smallest eigenvector with its variance.
fn weighted_plane(items: impl Iterator<Item = (DVec3, f64)> + Clone) -> (DVec3, DVec3, f64) {
    let (sum, w) = items
        .clone()
        .fold((DVec3::ZERO, 0.0), |(s, w), (p, wi)| (s + p * wi, w + wi));
    let mean = sum / w;
    let mut c = [[0.0; 3]; 3];
    for (p, wi) in items {
        let d = p - mean;
        for i in 0..3 {
            for j in i..3 {
                c[i][j] += wi * d[i] * d[j];
            }
        }
    }
    for row in c.iter_mut() {
        for v in row.iter_mut() {
            *v /= w;
        }
    }
    c[1][0] = c[0][1];
    c[2][0] = c[0][2];
    c[2][1] = c[1][2];
    let n = smallest_eigenvector(c);
    let m = DVec3::new(
        c[0][0] * n.x + c[0][1] * n.y + c[0][2] * n.z,
        c[1][0] * n.x + c[1][1] * n.y + c[1][2] * n.z,
        c[2][0] * n.x + c[2][1] * n.y + c[2][2] * n.z,
    );
    (mean, n, n.dot(m).max(0.0))
}

/// Solves the 6×6 system `a x = b` by Gaussian elimination with partial pivoting; `None` when a
/// pivot is below `1e-12` times the largest diagonal entry.
fn solve6(mut a: [[f64; 6]; 6], mut b: [f64; 6]) -> Option<[f64; 6]> {
    let scale = (0..6).map(|i| a[i][i].abs()).fold(0.0, f64::max);
    for c in 0..6 {
        let pivot = (c..6).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        let pivot_ok = a[pivot][c].abs() > 1e-12 * scale;
        if !pivot_ok {
            return None;
        }
        a.swap(c, pivot);
        b.swap(c, pivot);
        for r in c + 1..6 {
            let f = a[r][c] / a[c][c];
            for k in c..6 {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = [0.0; 6];
    for r in (0..6).rev() {
        let s: f64 = (r + 1..6).map(|k| a[r][k] * x[k]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    Some(x)
}

/// The frame of a quadric height field: an origin, the plane's unit vectors `u`, `v`, its unit
/// `normal`, and the inverse of the length unit.
struct QuadricFrame {
    origin: DVec3,
    u: DVec3,
    v: DVec3,
    normal: DVec3,
    inv: f64,
}

impl QuadricFrame {
    fn new(origin: DVec3, normal: DVec3, unit: f64) -> Self {
        let (u, v) = normal.any_orthonormal_pair();
        QuadricFrame {
            origin,
            u,
            v,
            normal,
            inv: 1.0 / unit,
        }
    }

    /// The quadric's terms `[1, x, y, x², xy, y²]` at `q` and its height `z`, in the frame.
    fn terms(&self, q: DVec3) -> ([f64; 6], f64) {
        let d = (q - self.origin) * self.inv;
        let (x, y) = (d.dot(self.u), d.dot(self.v));
        ([1.0, x, y, x * x, x * y, y * y], d.dot(self.normal))
    }

    /// The weighted least-squares coefficients of the heights of `items` (point, weight); `None`
    /// for fewer than six points of weight above 10⁻³, or a degenerate layout.
    fn fit(&self, items: impl Iterator<Item = (DVec3, f64)>) -> Option<[f64; 6]> {
        let mut ata = [[0.0; 6]; 6];
        let mut atb = [0.0; 6];
        let mut count = 0;
        for (q, w) in items {
            let (row, z) = self.terms(q);
            for r in 0..6 {
                for c in 0..6 {
                    ata[r][c] += w * row[r] * row[c];
                }
                atb[r] += w * row[r] * z;
            }
            count += (w > 1e-3) as usize;
        }
        if count < 6 {
            return None;
        }
        solve6(ata, atb)
    }
}

/// Moves `p` onto the weighted least-squares quadric height field over the plane through `mean`
/// with unit `normal` (heights z = c₀ + c₁x + c₂y + c₃x² + c₄xy + c₅y² in the plane's frame,
/// lengths in units of `h`), and returns the point and the quadric's unit normal there; the
/// plane itself where the quadric is not determined (fewer than six points of weight, or a
/// degenerate layout).
fn project_on_quadric(
    p: DVec3,
    mean: DVec3,
    normal: DVec3,
    items: impl Iterator<Item = (DVec3, f64)>,
    h: f64,
) -> (DVec3, DVec3) {
    let on_plane = (p - (p - mean).dot(normal) * normal, normal);
    if h.is_nan() || h <= 0.0 {
        return on_plane;
    }
    let frame = QuadricFrame::new(mean, normal, h);
    let Some(c) = frame.fit(items) else {
        return on_plane;
    };
    let (u, v) = (frame.u, frame.v);
    let d = (p - mean) * frame.inv;
    let (x, y) = (d.dot(u), d.dot(v));
    let z = c[0] + c[1] * x + c[2] * y + c[3] * x * x + c[4] * x * y + c[5] * y * y;
    let (zx, zy) = (
        c[1] + 2.0 * c[3] * x + c[4] * y,
        c[2] + c[4] * x + 2.0 * c[5] * y,
    );
    let moved = mean + (x * u + y * v + z * normal) * h;
    let n = (normal - zx * u - zy * v).normalize_or(normal);
    (moved, n)
}

/// Valid points, one in this many, whose quadrics measure the scatter ([`quadric_scatter`]).
const SCATTER_STRIDE: usize = 8;

/// The median, over every [`SCATTER_STRIDE`]th valid point, of the root-mean-square residual of
/// the least-squares quadric height field over its neighbourhood's plane (corrected for the
/// quadric's six coefficients): the noise, without the curvature that the planes' residuals
/// also hold.
fn quadric_scatter(
    points: &[DVec3],
    near: &Neighbourhoods,
    valid: &[bool],
    local: &[Local],
) -> f64 {
    let sampled: Vec<usize> = (0..points.len())
        .filter(|&i| valid[i])
        .step_by(SCATTER_STRIDE)
        .collect();
    let mut rms: Vec<f64> = sampled
        .par_iter()
        .filter_map(|&i| {
            let rows: Vec<DVec3> = near
                .of(i)
                .iter()
                .filter(|&&j| valid[j as usize])
                .map(|&j| points[j as usize])
                .collect();
            quadric_residual(&rows, points[i], local[i].normal)
        })
        .collect();
    median(&mut rms)
}

/// The root-mean-square residual of the least-squares quadric height field `z(x, y)` of `rows`
/// in the frame at `origin` with unit `normal`, times `sqrt(m / (m − 6))` for `m` rows; `None`
/// for fewer than 10 rows or a degenerate layout.
fn quadric_residual(rows: &[DVec3], origin: DVec3, normal: DVec3) -> Option<f64> {
    let m = rows.len();
    if m < 10 {
        return None;
    }
    let scale = rows
        .iter()
        .map(|q| (*q - origin).length())
        .fold(0.0, f64::max);
    if scale <= 0.0 {
        return None;
    }
    let frame = QuadricFrame::new(origin, normal, scale);
    let c = frame.fit(rows.iter().map(|q| (*q, 1.0)))?;
    let sum: f64 = rows
        .iter()
        .map(|q| {
            let (row, z) = frame.terms(*q);
            let fit: f64 = row.iter().zip(&c).map(|(a, b)| a * b).sum();
            (z - fit) * (z - fit)
        })
        .sum();
    Some(scale * (sum / (m - 6) as f64).sqrt())
}

/// For each point, whether its [`LOCAL_NEIGHBOUR`]th neighbour among the `valid` points (in its
/// neighbourhood, itself first) lies within [`LOCAL_RATIO`] times the median of the same distance
/// of its valid neighbours. A point with too few valid neighbours in its row passes.
fn crowded(points: &[DVec3], near: &Neighbourhoods, valid: &[bool]) -> Vec<bool> {
    let near_of = |i: usize| -> Option<f64> {
        let row = near.of(i)[1..].iter().filter(|&&j| valid[j as usize]);
        row.map(|&j| distance(points, i, j))
            .nth(LOCAL_NEIGHBOUR - 1)
    };
    let local: Vec<Option<f64>> = (0..valid.len()).into_par_iter().map(near_of).collect();
    (0..valid.len())
        .into_par_iter()
        .map(|i| {
            let Some(own) = local[i] else {
                return true;
            };
            let mut others: Vec<f64> = near.of(i)[1..]
                .iter()
                .filter(|&&j| valid[j as usize])
                .filter_map(|&j| local[j as usize])
                .collect();
            others.is_empty() || own <= LOCAL_RATIO * median(&mut others)
        })
        .collect()
}

/// The distance from point `i` to point `j`.
fn distance(points: &[DVec3], i: usize, j: u32) -> f64 {
    (points[j as usize] - points[i]).length()
}

/// The distance from each point to its `m`th neighbour (the first being itself).
fn nth_distances(points: &[DVec3], near: &Neighbourhoods, m: usize) -> Vec<f64> {
    (0..points.len())
        .into_par_iter()
        .map(|i| distance(points, i, near.of(i)[m]))
        .collect()
}

/// The median of `values` (which it reorders); 0 for none.
fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let m = values.len() / 2;
    *values.select_nth_unstable_by(m, f64::total_cmp).1
}

/// Cleans `points` with `normals` (see the module's documentation). Errors name the argument:
/// fewer points than `settings.neighbours + 1`, or a point or normal that is not finite.
pub fn clean(points: &[DVec3], normals: &[DVec3], settings: &ScanSettings) -> Result<Cleaned> {
    clean_at(points, normals, settings, 0)
}

/// [`clean`], `depth` averagings ([`mod@super::coarsen`]) away from the caller's points.
fn clean_at(
    points: &[DVec3],
    normals: &[DVec3],
    settings: &ScanSettings,
    depth: usize,
) -> Result<Cleaned> {
    let k = settings.neighbours;
    if k < ISOLATION_NEIGHBOUR {
        return Err(Error::invalid(
            "neighbours",
            format!("must be at least {ISOLATION_NEIGHBOUR}, got {k}"),
        ));
    }
    if points.len() <= k {
        return Err(Error::invalid(
            "points",
            format!(
                "a scan fit needs more than {k} points, got {}",
                points.len()
            ),
        ));
    }
    if normals.len() != points.len() {
        return Err(Error::invalid(
            "normals",
            format!("{} normals for {} points", normals.len(), points.len()),
        ));
    }
    crate::error::check_finite_points("normals", normals)?;
    let tree = PointTree::new(points)?;
    let near = tree.neighbourhoods(k + 1)?;
    let n = points.len();

    // 1. Spacing and isolation.
    let spacing = median(&mut nth_distances(points, &near, SPACING_NEIGHBOUR));
    let isolation = nth_distances(points, &near, ISOLATION_NEIGHBOUR);
    let isolation_limit = settings.isolation * median(&mut isolation.clone());
    let isolated: Vec<bool> = isolation.iter().map(|&d| d > isolation_limit).collect();
    drop(isolation);
    let areas = nth_distances(points, &near, AREA_NEIGHBOUR);

    // 2. Local planes and noise.
    let local: Vec<Local> = (0..n)
        .into_par_iter()
        .map(|i| {
            // The plane of the neighbours without the point itself, so that a stray point does
            // not pull the plane toward itself.
            let others = near.of(i).iter().filter(|&&j| j as usize != i);
            let (mean, normal, variance) =
                weighted_plane(others.clone().map(|&j| (points[j as usize], 1.0)));
            let mut residuals: Vec<f64> = others
                .map(|&j| (points[j as usize] - mean).dot(normal).abs())
                .collect();
            Local {
                normal,
                rms: variance.sqrt(),
                spread: 1.4826 * median(&mut residuals),
                offset: (points[i] - mean).dot(normal).abs(),
            }
        })
        .collect();
    crate::cancel::check()?;
    let bulk = |f: fn(&Local) -> f64| {
        median(
            &mut (0..n)
                .filter(|&i| !isolated[i])
                .map(|i| f(&local[i]))
                .collect::<Vec<_>>(),
        )
    };
    let noise = bulk(|l| l.rms);
    let typical_offset = bulk(|l| l.offset);
    // A point much farther from its own neighbours than they are from theirs (a local outlier
    // factor over the distance to the 3rd neighbour) lies off the surface they sample. The test
    // runs twice, the second time over the points the first kept, so that a few stray points
    // close together do not vouch for each other.
    let mut valid: Vec<bool> = (0..n)
        .map(|i| {
            !isolated[i]
                && local[i].offset <= 3.0 * local[i].spread + 6.0 * typical_offset + 3.0 * noise
        })
        .collect();
    for _ in 0..2 {
        let crowded = crowded(points, &near, &valid);
        for (v, c) in valid.iter_mut().zip(crowded) {
            *v &= c;
        }
    }

    // Noise large against the spacing: the points averaged in cells, and those cleaned.
    // The noise that curvature does not explain: what the neighbourhoods' quadrics leave.
    let scatter = quadric_scatter(points, &near, &valid, &local);
    if depth < MAX_AVERAGINGS && scatter > settings.coarsening * spacing {
        let averaged = coarsen::average(points, normals, &valid, AVERAGING_CELL * spacing);
        let used = valid.iter().filter(|&&v| v).count();
        if averaged.points.len() > settings.neighbours
            && (averaged.points.len() as f64) < AVERAGING_GAIN * used as f64
        {
            drop(near);
            let inner = clean_at(&averaged.points, &averaged.normals, settings, depth + 1)?;
            let mut cleaned = inner.standing_for(&averaged.group_of, normals);
            cleaned.noise = noise;
            return Ok(cleaned);
        }
    }

    // 3. Normals: the neighbourhood's, signed by the given one, then neighbours vote.
    let mut oriented: Vec<DVec3> = (0..n)
        .map(|i| {
            let m = local[i].normal;
            if m.dot(normals[i]) < 0.0 {
                -m
            } else {
                m
            }
        })
        .collect();
    for _ in 0..settings.voting_rounds {
        let flip: Vec<bool> = (0..n)
            .into_par_iter()
            .map(|i| {
                if !valid[i] {
                    return false;
                }
                let (mut agree, mut disagree) = (0usize, 0usize);
                for &j in &near.of(i)[1..] {
                    let j = j as usize;
                    if j == i || !valid[j] {
                        continue;
                    }
                    let c = oriented[i].dot(oriented[j]);
                    if c > 0.0 {
                        agree += 1;
                    } else if c < 0.0 {
                        disagree += 1;
                    }
                }
                2 * disagree > 3 * agree
            })
            .collect();
        if !flip.contains(&true) {
            break;
        }
        for (o, f) in oriented.iter_mut().zip(&flip) {
            if *f {
                *o = -*o;
            }
        }
    }
    crate::cancel::check()?;
    // Outward: the flux of the normals through the points' surface about their mean is the
    // enclosed volume (times 3) when they point out, negative when they point in.
    let kept_mean = (0..n)
        .filter(|&i| valid[i])
        .map(|i| points[i])
        .sum::<DVec3>()
        / (0..n).filter(|&i| valid[i]).count().max(1) as f64;
    let flux: f64 = (0..n)
        .filter(|&i| valid[i])
        .map(|i| {
            let r = areas[i];
            r * r * (points[i] - kept_mean).dot(oriented[i])
        })
        .sum();
    let turned_outward = flux < 0.0;
    if turned_outward {
        for o in oriented.iter_mut() {
            *o = -*o;
        }
    }

    // 4. Projection onto weighted planes of the neighbours facing the same way.
    let h = settings.projection_width * spacing.max(2.0 * noise);
    let inv_h2 = if h > 0.0 { 1.0 / (h * h) } else { 0.0 };
    let kept: Vec<u32> = (0..n as u32).filter(|&i| valid[i as usize]).collect();
    // Noisy data: more neighbours, so that the quadric's six coefficients average the noise.
    let wide;
    let rows = if scatter > NOISY * spacing && settings.projection_neighbours > k {
        drop(near);
        wide = tree.neighbourhoods((settings.projection_neighbours + 1).min(n))?;
        &wide
    } else {
        &near
    };
    let projected: Vec<(DVec3, DVec3)> = kept
        .par_iter()
        .map(|&i| {
            let i = i as usize;
            let own = oriented[i];
            let items = rows.of(i).iter().filter_map(|&j| {
                let dj = distance(points, i, j);
                let j = j as usize;
                (j == i || (valid[j] && own.dot(oriented[j]) > 0.5)).then(|| {
                    (
                        points[j],
                        if j == i {
                            1.0
                        } else {
                            (-dj * dj * inv_h2).exp()
                        },
                    )
                })
            });
            let (mean, mut normal, _) = weighted_plane(items.clone());
            if normal.dot(own) < 0.0 {
                normal = -normal;
            }
            project_on_quadric(points[i], mean, normal, items, h)
        })
        .collect();
    let projected: Vec<(DVec3, DVec3, f64)> = kept
        .iter()
        .zip(projected)
        .map(|(&i, (p, m))| {
            let r = areas[i as usize];
            (p, m, std::f64::consts::PI * r * r / AREA_NEIGHBOUR as f64)
        })
        .collect();
    crate::cancel::check()?;
    let normals_corrected = kept
        .iter()
        .zip(&projected)
        .filter(|(&i, (_, m, _))| m.dot(normals[i as usize]) < 0.0)
        .count();
    let outliers: Vec<u32> = (0..n as u32).filter(|&i| !valid[i as usize]).collect();
    let mut representative = vec![u32::MAX; n];
    for (k, &i) in kept.iter().enumerate() {
        representative[i as usize] = k as u32;
    }
    let mut out = Cleaned {
        representative,
        points: Vec::with_capacity(kept.len()),
        normals: Vec::with_capacity(kept.len()),
        areas: Vec::with_capacity(kept.len()),
        kept,
        outliers,
        spacing,
        noise,
        normals_corrected,
        turned_outward,
    };
    for (p, m, a) in projected {
        out.points.push(p);
        out.normals.push(m);
        out.areas.push(a);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{fibonacci_sphere, random_points};

    #[test]
    fn outliers_are_found_noise_is_measured_and_flipped_normals_turn_back() {
        let n = 20_000;
        let mut p = fibonacci_sphere(n);
        let mut normals = p.clone();
        // Noise along the normal: ±0.002 in a fixed pattern.
        let jitter = random_points(n, -1.0, 1.0, 3);
        for (q, j) in p.iter_mut().zip(&jitter) {
            *q *= 1.0 + 0.002 * j.x;
        }
        // Every 97th normal flipped, and 20 points far from the sphere.
        for i in (0..n).step_by(97) {
            normals[i] = -normals[i];
        }
        let far: Vec<DVec3> = random_points(200, -2.0, 2.0, 4)
            .into_iter()
            .filter(|f| f.length() > 1.3)
            .take(20)
            .collect();
        for (k, f) in far.iter().enumerate() {
            p[k * 1000 + 5] = *f;
        }
        let c = clean(&p, &normals, &ScanSettings::default()).unwrap();
        let expected: Vec<u32> = (0..far.len()).map(|k| (k * 1000 + 5) as u32).collect();
        assert_eq!(expected.len(), 20);
        for e in &expected {
            assert!(c.outliers.contains(e), "outlier {e} not found");
        }
        assert!(c.outliers.len() < 40, "{} outliers", c.outliers.len());
        // Every kept normal points outward; the flipped ones were corrected.
        for (q, m) in c.points.iter().zip(&c.normals) {
            assert!(q.normalize().dot(*m) > 0.9, "normal {m} at {q}");
        }
        assert!(c.normals_corrected >= n / 97 - 5);
        // The projected points lie closer to the sphere than the noisy ones did.
        let before: f64 = c
            .kept
            .iter()
            .map(|&i| (p[i as usize].length() - 1.0).abs())
            .sum::<f64>();
        let after: f64 = c
            .points
            .iter()
            .map(|q| (q.length() - 1.0).abs())
            .sum::<f64>();
        assert!(after < 0.6 * before, "{after} against {before}");
        assert!(c.noise > 0.0 && c.noise < 0.004, "noise {}", c.noise);
    }

    #[test]
    fn noise_as_large_as_the_spacing_is_averaged_in_cells() {
        // 40,000 points on the unit sphere (spacing about 0.02) with noise ±0.03 along the
        // normal, and a few far points.
        let n = 40_000;
        let mut p = fibonacci_sphere(n);
        let normals = p.clone();
        let jitter = random_points(n, -1.0, 1.0, 8);
        for (q, j) in p.iter_mut().zip(&jitter) {
            *q *= 1.0 + 0.03 * j.x;
        }
        for k in 0..10 {
            p[k * 3_001] *= 1.6;
        }
        let c = clean(&p, &normals, &ScanSettings::default()).unwrap();
        // Averaged: fewer cleaned points than kept ones, each kept point standing by one.
        assert!(
            c.points.len() < c.kept.len() / 2,
            "{} of {}",
            c.points.len(),
            c.kept.len()
        );
        assert_eq!(c.kept.len() + c.outliers.len(), n);
        for k in 0..10 {
            assert!(
                c.outliers.contains(&(k as u32 * 3_001)),
                "far point {k} kept"
            );
        }
        for (i, &r) in c.representative.iter().enumerate() {
            assert_eq!(r == u32::MAX, c.outliers.binary_search(&(i as u32)).is_ok());
            if r != u32::MAX {
                assert!(c.points[r as usize].distance(p[i]) < 0.2);
            }
        }
        // The averages lie much closer to the sphere than the noise, normals outward.
        let mean_error = c
            .points
            .iter()
            .map(|q| (q.length() - 1.0).abs())
            .sum::<f64>()
            / c.points.len() as f64;
        assert!(mean_error < 0.004, "{mean_error}");
        assert!(c
            .points
            .iter()
            .zip(&c.normals)
            .all(|(q, m)| q.dot(*m) > 0.9));
        assert_eq!(c.normals_corrected, 0);
    }

    #[test]
    fn normals_that_all_point_inward_are_turned_outward() {
        let p = fibonacci_sphere(5_000);
        let inward: Vec<DVec3> = p.iter().map(|q| -*q).collect();
        let c = clean(&p, &inward, &ScanSettings::default()).unwrap();
        assert!(c.turned_outward);
        assert_eq!(c.normals_corrected, p.len());
        for (q, m) in c.points.iter().zip(&c.normals) {
            assert!(q.dot(*m) > 0.9);
        }
        let c = clean(&p, &p, &ScanSettings::default()).unwrap();
        assert!(!c.turned_outward);
        assert_eq!(c.normals_corrected, 0);
    }

    #[test]
    fn refuses_too_few_points_and_mismatched_normals() {
        let p = fibonacci_sphere(15);
        let e = clean(&p, &p, &ScanSettings::default()).unwrap_err();
        assert!(e.to_string().contains("points"), "{e}");
        let p = fibonacci_sphere(100);
        let e = clean(&p, &p[..99], &ScanSettings::default()).unwrap_err();
        assert!(e.to_string().contains("normals"), "{e}");
    }
}
