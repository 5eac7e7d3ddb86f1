//! A fitted surface near the data and the winding number's inside and outside away from it:
//!
//! ```text
//! g(x) = s(d) f(x) + (1 − s(d)) · far · (1 − 2 w(x))
//! ```
//!
//! with `d` the distance from `x` to the nearest data point, `s` a smooth step from 1 at
//! `d ≤ near` to 0 at `d ≥ far` (`t²(3 − 2t)`, `t = (far − d)/(far − near)`), `f` the fit and `w`
//! the data's [`WindingNumber`]. Within `near` of the data the surface is the fit's; beyond
//! `far` it is where the winding number crosses ½, which closes regions no scan saw smoothly
//! and leaves no surface elsewhere: an interpolant's stray sheets and bubbles away from the data
//! are gone. Both terms are negative inside, and `far · |1 − 2w| ≤ far` stays below the distance
//! to the data beyond `far`, as the octree's rejection test needs.

use super::occupancy::OccupiedCells;
use super::winding::WindingNumber;
use crate::field::{Field, Starts};
use crate::knn::PointTree;
use glam::DVec3;
use rayon::prelude::*;
use std::sync::Arc;

/// Points per rayon task.
const CHUNK: usize = 256;

/// The data's side of the guard: its winding number, its points for distances, and the bands.
pub struct Guard {
    winding: WindingNumber,
    tree: PointTree,
    points: Vec<DVec3>,
    normals: Vec<DVec3>,
    areas: Vec<f64>,
    spacing: f64,
    near: f64,
    far: f64,
    /// Cells of side `near/√3` holding a data point: a query in one is within `near`.
    near_cells: Option<OccupiedCells>,
}

impl Guard {
    /// The guard of `points` (over `tree`, built on them, `spacing` apart) with their unit
    /// `normals`, `areas` and `winding` number: the fit alone within `near` of the data, the
    /// winding number alone beyond `far`.
    pub fn new(
        winding: WindingNumber,
        tree: PointTree,
        (points, normals, areas): (Vec<DVec3>, Vec<DVec3>, Vec<f64>),
        spacing: f64,
        (near, far): (f64, f64),
    ) -> Self {
        debug_assert!(0.0 <= near && near < far && spacing > 0.0);
        // The side, rounded down, keeps the cell's diagonal within `near`.
        let near_cells = OccupiedCells::new(&points, near / 3f64.sqrt() * (1.0 - 1e-9));
        Guard {
            near_cells,
            winding,
            tree,
            points,
            normals,
            areas,
            spacing,
            near,
            far,
        }
    }

    /// The data's spacing: the median distance from a point to its 6th nearest neighbour.
    pub fn spacing(&self) -> f64 {
        self.spacing
    }

    /// The winding number of the data.
    pub fn winding(&self) -> &WindingNumber {
        &self.winding
    }

    /// The data points.
    pub fn points(&self) -> &[DVec3] {
        &self.points
    }

    /// The data points' unit normals.
    pub fn normals(&self) -> &[DVec3] {
        &self.normals
    }

    /// The area each data point stands for.
    pub fn areas(&self) -> &[f64] {
        &self.areas
    }

    /// The distances within which the fit alone, and beyond which the winding number alone,
    /// make the field.
    pub fn bands(&self) -> (f64, f64) {
        (self.near, self.far)
    }

    /// The distance from `x` to the nearest data point.
    pub fn distance_to_data(&self, x: DVec3) -> f64 {
        self.nearest(x).0
    }

    fn nearest(&self, x: DVec3) -> (f64, DVec3) {
        let mut found = [(0.0, 0u32)];
        self.tree.k_nearest_into(x, &mut found);
        let p = self.points[found[0].1 as usize];
        (found[0].0.sqrt(), p)
    }

    fn blend(&self, x: DVec3) -> Blend {
        if self.near_cells.as_ref().is_some_and(|c| c.contains(x)) {
            return Blend {
                s: 1.0,
                ds: DVec3::ZERO,
            };
        }
        let Some((d, j)) = self.tree.nearest_within(x, self.far) else {
            return Blend::default();
        };
        let p = self.points[j as usize];
        if d <= self.near {
            return Blend {
                s: 1.0,
                ds: DVec3::ZERO,
            };
        }
        if d >= self.far {
            return Blend::default();
        }
        let width = self.far - self.near;
        let t = (self.far - d) / width;
        let s = t * t * (3.0 - 2.0 * t);
        // ∇t = −∇d / width, ∇d = (x − p)/d.
        let ds = (6.0 * t * (1.0 - t)) * (-(x - p) / (d * width));
        Blend { s, ds }
    }

    /// The winding term `far · (1 − 2w)` and its gradient.
    fn outer(&self, x: DVec3) -> (f64, DVec3) {
        let (w, g) = self.winding.value_gradient(x);
        (self.far * (1.0 - 2.0 * w), -2.0 * self.far * g)
    }

    fn blends(&self, points: &[DVec3]) -> Vec<Blend> {
        let mut b = vec![Blend::default(); points.len()];
        b.par_chunks_mut(CHUNK)
            .zip(points.par_chunks(CHUNK))
            .for_each(|(b, p)| {
                for (b, p) in b.iter_mut().zip(p) {
                    *b = self.blend(*p);
                }
            });
        b
    }
}

/// Where a point lies: its weight `s`, and `∇s` (zero where `s` is 0 or 1).
#[derive(Clone, Copy, Debug, Default)]
struct Blend {
    s: f64,
    ds: DVec3,
}

/// The fit `F` guarded by the winding number of its data (see the module's documentation).
#[derive(Clone)]
pub struct Guarded<F> {
    fit: F,
    guard: Arc<Guard>,
}

impl<F: Field> Guarded<F> {
    /// Guards `fit` by `guard`, made from the fit's data.
    pub fn new(fit: F, guard: Arc<Guard>) -> Self {
        Guarded { fit, guard }
    }

    /// The fit near the data.
    pub fn fit(&self) -> &F {
        &self.fit
    }

    /// The data's side of the guard.
    pub fn guard(&self) -> &Arc<Guard> {
        &self.guard
    }

    /// The points where the fit is needed (s > 0), and their positions in the batch.
    fn inner_points(points: &[DVec3], blends: &[Blend]) -> (Vec<u32>, Vec<DVec3>) {
        points
            .iter()
            .zip(blends)
            .enumerate()
            .filter(|(_, (_, b))| b.s > 0.0)
            .map(|(i, (p, _))| (i as u32, *p))
            .unzip()
    }
}

impl<F: Field> Field for Guarded<F> {
    fn value(&self, p: DVec3) -> f64 {
        let b = self.guard.blend(p);
        let f = if b.s > 0.0 { self.fit.value(p) } else { 0.0 };
        if b.s >= 1.0 {
            return f;
        }
        b.s * f + (1.0 - b.s) * self.guard.outer(p).0
    }

    fn gradient(&self, p: DVec3) -> DVec3 {
        let b = self.guard.blend(p);
        let (f, df) = if b.s > 0.0 {
            (self.fit.value(p), self.fit.gradient(p))
        } else {
            (0.0, DVec3::ZERO)
        };
        if b.s >= 1.0 {
            return df;
        }
        let (o, d_o) = self.guard.outer(p);
        b.s * df + (1.0 - b.s) * d_o + (f - o) * b.ds
    }

    fn values(&self, points: &[DVec3], out: &mut [f64]) {
        assert_eq!(points.len(), out.len());
        let blends = self.guard.blends(points);
        let (at, inner) = Self::inner_points(points, &blends);
        let mut f = vec![0.0; inner.len()];
        self.fit.values(&inner, &mut f);
        let mut fit_values = vec![0.0; points.len()];
        for (&i, v) in at.iter().zip(&f) {
            fit_values[i as usize] = *v;
        }
        out.par_chunks_mut(CHUNK)
            .zip(points.par_chunks(CHUNK))
            .zip(blends.par_chunks(CHUNK).zip(fit_values.par_chunks(CHUNK)))
            .for_each(|((o, p), (b, f))| {
                for (((o, p), b), f) in o.iter_mut().zip(p).zip(b).zip(f) {
                    *o = if b.s >= 1.0 {
                        *f
                    } else {
                        b.s * f + (1.0 - b.s) * self.guard.outer(*p).0
                    };
                }
            });
    }

    fn gradients(&self, points: &[DVec3], out: &mut [DVec3]) {
        let mut values = vec![0.0; points.len()];
        self.values_gradients(points, &mut values, out);
    }

    fn values_gradients(&self, points: &[DVec3], values: &mut [f64], gradients: &mut [DVec3]) {
        assert_eq!(points.len(), values.len());
        assert_eq!(points.len(), gradients.len());
        let blends = self.guard.blends(points);
        let (at, inner) = Self::inner_points(points, &blends);
        let mut f = vec![0.0; inner.len()];
        let mut df = vec![DVec3::ZERO; inner.len()];
        self.fit.values_gradients(&inner, &mut f, &mut df);
        let mut fit = vec![(0.0, DVec3::ZERO); points.len()];
        for (&i, (v, g)) in at.iter().zip(f.iter().zip(&df)) {
            fit[i as usize] = (*v, *g);
        }
        values
            .par_chunks_mut(CHUNK)
            .zip(gradients.par_chunks_mut(CHUNK))
            .zip(points.par_chunks(CHUNK))
            .zip(blends.par_chunks(CHUNK).zip(fit.par_chunks(CHUNK)))
            .for_each(|(((v, g), p), (b, fit))| {
                for ((((v, g), p), b), &(f, df)) in
                    v.iter_mut().zip(g.iter_mut()).zip(p).zip(b).zip(fit)
                {
                    if b.s >= 1.0 {
                        (*v, *g) = (f, df);
                    } else {
                        let (o, d_o) = self.guard.outer(*p);
                        *v = b.s * f + (1.0 - b.s) * o;
                        *g = b.s * df + (1.0 - b.s) * d_o + (f - o) * b.ds;
                    }
                }
            });
    }

    fn fd_step(&self) -> f64 {
        self.fit.fd_step()
    }

    fn starts(&self, cell: f64) -> Option<Starts> {
        self.fit.starts(cell)
    }

    fn values_per_value_gradient(&self) -> u64 {
        self.fit.values_per_value_gradient()
    }

    fn values_per_gradient(&self) -> u64 {
        self.fit.values_per_gradient()
    }
}
