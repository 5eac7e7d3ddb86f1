//! Blending the patches: f(x) = Σ_i w_i(x) f_i(x) / Σ_i w_i(x) with the compactly supported C²
//! weight w_i(x) = (1 − |x − c_i|²/R_i²)³₊, and ∇f by the quotient rule,
//! ∇f = (Σ_i (w_i ∇f_i + f_i ∇w_i) − f Σ_i ∇w_i) / Σ_i w_i.
//!
//! A batch is sorted by the octree leaf of each point and cut into groups of at most
//! `GROUP` (256) points of one leaf; rayon runs the groups, and each group evaluates the leaf's
//! covering patches, in increasing order, with the vectorised kernel sums of
//! [`VariationalSurface`](crate::field::rbf::VariationalSurface). Every sum is per point and the
//! patches are added in a fixed order, so a point's value has the same bits whatever the batch,
//! its grouping or the number of threads. Where no support reaches (outside the octree's cube),
//! the field is that of the patch, among those covering the point's nearest point of the cube,
//! with the smallest |x − c_i| − R_i (the first such patch on ties).

use super::PartitionSurface;
use glam::DVec3;
use rayon::prelude::*;

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
            .map(|&(l, s, e)| {
                let pts: Vec<DVec3> = order[s..e].iter().map(|&i| points[i as usize]).collect();
                self.blend_group(l, &pts, with_gradients)
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

    /// Blend at points all in leaf `l`.
    fn blend_group(&self, l: u32, pts: &[DVec3], with_gradients: bool) -> (Vec<f64>, Vec<DVec3>) {
        let m = pts.len();
        let mut sum = vec![0.0; m];
        let mut wsum = vec![0.0; m];
        let mut gsum = vec![DVec3::ZERO; if with_gradients { m } else { 0 }];
        let mut gw = vec![DVec3::ZERO; if with_gradients { m } else { 0 }];
        let mut sub_idx = Vec::with_capacity(m);
        let mut sub_pts = Vec::with_capacity(m);
        let mut sub_w = Vec::with_capacity(m);
        let mut fv = vec![0.0; m];
        let mut fg = vec![DVec3::ZERO; m];
        let cover = self.covering(l);
        for &i in cover {
            let patch = &self.patches[i as usize];
            sub_idx.clear();
            sub_pts.clear();
            sub_w.clear();
            for (k, p) in pts.iter().enumerate() {
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
            if with_gradients {
                patch
                    .fit
                    .eval_on_this_thread(&sub_pts, &mut fv[..q], Some(&mut fg[..q]));
            } else {
                patch.fit.eval_on_this_thread(&sub_pts, &mut fv[..q], None);
            }
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
        let mut values = vec![0.0; m];
        let mut grads = vec![DVec3::ZERO; if with_gradients { m } else { 0 }];
        for k in 0..m {
            if wsum[k] > 0.0 {
                let f = sum[k] / wsum[k];
                values[k] = f;
                if with_gradients {
                    grads[k] = (gsum[k] - gw[k] * f) / wsum[k];
                }
            } else {
                // Outside every support: the nearest patch alone.
                let p = pts[k];
                let near = cover
                    .iter()
                    .copied()
                    .min_by(|&a, &b| {
                        let g = |i: u32| {
                            let q = &self.patches[i as usize];
                            (p - q.centre).length() - q.radius
                        };
                        g(a).total_cmp(&g(b)).then(a.cmp(&b))
                    })
                    .expect("every leaf is covered by its own patch");
                let fit = &self.patches[near as usize].fit;
                let (mut v, mut g) = ([0.0], [DVec3::ZERO]);
                if with_gradients {
                    fit.eval_on_this_thread(&[p], &mut v, Some(&mut g));
                    grads[k] = g[0];
                } else {
                    fit.eval_on_this_thread(&[p], &mut v, None);
                }
                values[k] = v[0];
            }
        }
        (values, grads)
    }
}
