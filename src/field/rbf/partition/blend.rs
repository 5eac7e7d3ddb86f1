//! Blending the patches: f(x) = Σ_i w_i(x) f_i(x) / Σ_i w_i(x) with the compactly supported C²
//! weight w_i(x) = (1 − |x − c_i|²/R_i²)³₊, and ∇f by the quotient rule,
//! ∇f = (Σ_i (w_i ∇f_i + f_i ∇w_i) − f Σ_i ∇w_i) / Σ_i w_i.
//!
//! A batch is sorted by the octree leaf of each point and cut into groups of at most
//! `GROUP` (256) points of one leaf; rayon runs the groups, and each group evaluates the leaf's
//! covering patches, in increasing order, with the vectorised kernel sums of
//! [`PatchFit`](crate::field::rbf::PatchFit), each patch's centres gathered from the surface's
//! constraints (and normalised) once for the consecutive groups of a rayon job that use it. Every sum is per point and the
//! patches are added in a fixed order, so a point's value has the same bits whatever the batch,
//! its grouping or the number of threads.
//!
//! Outside the octree's cube the field is its value at the nearest point of the cube,
//! f(x) = f(π(x)) (π clamps each coordinate), and its gradient that of f ∘ π (the components
//! along the clamped axes are zero). Every point of the cube lies inside the support of its
//! leaf's patch (a patch's radius exceeds its leaf's half-diagonal), so the blend is defined
//! there, and f keeps outside the cube the sign it has on the cube's faces: no surface appears
//! away from the data, and |f(x)| ≤ |f(π(x))| stays below the distance to a surface inside the
//! cube wherever it does at π(x), since π does not lengthen distances to points of the cube.

use super::PartitionSurface;
use crate::field::rbf::kernel::Centres;
use glam::DVec3;
use rayon::prelude::*;
use std::collections::HashMap;

/// Most points a group holds.
const GROUP: usize = 256;

/// The weight (1 − t)³₊, t = |x − c|²/R², and its gradient.
#[inline]
pub fn weight(x: DVec3, c: DVec3, r: f64) -> (f64, DVec3) {
    let d = x - c;
    let t = d.length_squared() / (r * r);
    if t >= 1.0 {
        return (0.0, DVec3::ZERO);
    }
    let u = 1.0 - t;
    (u * u * u, d * (-6.0 * u * u / (r * r)))
}

/// Patches gathered at once by one rayon job of a blend.
const GATHERED: usize = 64;

/// The centres of the patches one rayon job of a blend evaluated last (at most [`GATHERED`]),
/// gathered once: its groups come in leaf order, and neighbouring leaves share most of their
/// patches. The buffers are reused when it starts again.
#[derive(Default)]
struct Gathered {
    /// Where each kept patch's centres are in `centres`.
    slot: HashMap<u32, usize>,
    centres: Vec<Centres>,
}

impl Gathered {
    /// Patch `i` of `s`'s centres, gathered now unless they are kept.
    fn of(&mut self, s: &PartitionSurface, i: u32) -> &Centres {
        if let Some(&k) = self.slot.get(&i) {
            return &self.centres[k];
        }
        if self.slot.len() == GATHERED {
            self.slot.clear();
        }
        let k = self.slot.len();
        if k == self.centres.len() {
            self.centres.push(Centres::default());
        }
        s.patches[i as usize]
            .fit
            .gather(&s.centres, &mut self.centres[k]);
        self.slot.insert(i, k);
        &self.centres[k]
    }
}

impl PartitionSurface {
    /// Values, and gradients when `gradients` is given, at `points`.
    pub(super) fn blend(
        &self,
        points: &[DVec3],
        values: &mut [f64],
        gradients: Option<&mut [DVec3]>,
    ) {
        assert_eq!(points.len(), values.len());
        let n = points.len();
        if n == 0 {
            return;
        }
        let leaf: Vec<u32> = points.par_iter().map(|p| self.tree.leaf_of(*p)).collect();
        let mut order: Vec<u32> = (0..n as u32).collect();
        order.par_sort_unstable_by_key(|&i| (leaf[i as usize], i));
        let mut groups = Vec::new();
        let mut s = 0;
        while s < n {
            let l = leaf[order[s] as usize];
            let mut e = s + 1;
            while e < n && e - s < GROUP && leaf[order[e] as usize] == l {
                e += 1;
            }
            groups.push((l, s, e));
            s = e;
        }
        let with_gradients = gradients.is_some();
        let results: Vec<(Vec<f64>, Vec<DVec3>)> = groups
            .par_iter()
            .map_init(Gathered::default, |gathered, &(l, s, e)| {
                let pts: Vec<DVec3> = order[s..e].iter().map(|&i| points[i as usize]).collect();
                self.blend_group(l, &pts, with_gradients, gathered)
            })
            .collect();
        for (&(_, s, _), (v, _)) in groups.iter().zip(&results) {
            for (k, &vk) in v.iter().enumerate() {
                values[order[s + k] as usize] = vk;
            }
        }
        if let Some(g) = gradients {
            assert_eq!(g.len(), n);
            for (&(_, s, _), (_, gr)) in groups.iter().zip(&results) {
                for (k, &gk) in gr.iter().enumerate() {
                    g[order[s + k] as usize] = gk;
                }
            }
        }
    }

    /// The patches covering leaf `l` (by its position in the octree's leaves).
    fn covering(&self, l: u32) -> &[u32] {
        let l = l as usize;
        &self.cover[self.cover_start[l] as usize..self.cover_start[l + 1] as usize]
    }

    /// Blend at points all in leaf `l` (as clamped into the cube).
    fn blend_group(
        &self,
        l: u32,
        pts: &[DVec3],
        with_gradients: bool,
        gathered: &mut Gathered,
    ) -> (Vec<f64>, Vec<DVec3>) {
        let m = pts.len();
        let (lo, hi) = self.tree.cube();
        let clamped: Vec<DVec3> = pts.iter().map(|p| p.clamp(lo, hi)).collect();
        let mut sum = vec![0.0; m];
        let mut wsum = vec![0.0; m];
        let mut gsum = vec![DVec3::ZERO; if with_gradients { m } else { 0 }];
        let mut gw = vec![DVec3::ZERO; if with_gradients { m } else { 0 }];
        let mut sub_idx = Vec::with_capacity(m);
        let mut sub_pts = Vec::with_capacity(m);
        let mut sub_w = Vec::with_capacity(m);
        let mut fv = vec![0.0; m];
        let mut fg = vec![DVec3::ZERO; m];

        for &i in self.covering(l) {
            let patch = &self.patches[i as usize];
            sub_idx.clear();
            sub_pts.clear();
            sub_w.clear();
            for (k, p) in clamped.iter().enumerate() {
                let (w, dw) = weight(*p, patch.centre, patch.radius);
                if w > 0.0 {
                    sub_idx.push(k);
                    sub_pts.push(*p);
                    sub_w.push((w, dw));
                }
            }
            if sub_idx.is_empty() {
                continue;
            }
            let q = sub_idx.len();
            let g = with_gradients.then_some(&mut fg[..q]);
            let centres = gathered.of(self, i);
            patch.fit.eval_gathered(centres, &sub_pts, &mut fv[..q], g);
            for (j, &k) in sub_idx.iter().enumerate() {
                let (w, dw) = sub_w[j];
                sum[k] += w * fv[j];
                wsum[k] += w;
                if with_gradients {
                    gsum[k] += fg[j] * w + dw * fv[j];
                    gw[k] += dw;
                }
            }
        }
        // Every clamped point lies inside its leaf's own support: wsum > 0.
        let values: Vec<f64> = (0..m).map(|k| sum[k] / wsum[k]).collect();
        let mut grads = vec![DVec3::ZERO; if with_gradients { m } else { 0 }];
        if with_gradients {
            for k in 0..m {
                let g = (gsum[k] - gw[k] * values[k]) / wsum[k];
                // f ∘ π does not change along the axes where π moved the point.
                let moved = pts[k].cmpne(clamped[k]);
                grads[k] = DVec3::select(moved, DVec3::ZERO, g);
            }
        }
        (values, grads)
    }
}
