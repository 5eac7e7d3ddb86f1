//! Blob fields with ellipsoidal kernels: primitive i adds Aᵢ·w(|Sᵢ (p − cᵢ)|/Rᵢ), with Sᵢ an
//! invertible 3×3 matrix per primitive (its shape; the identity gives the round kernel), so the
//! term reaches the ellipsoid (p − c)ᵀ Q (p − c) < 1, Q = SᵀS/R².
//!
//! Everything else of the blob field stays: the block lists, voxel lists, tiles and kept lists
//! are made with each ellipsoid's bounding sphere (its reach, R/s_min with s_min the smallest
//! singular value of S, stored as the field's radius), so they hold every primitive that
//! reaches a point. Every evaluation (point, lattice plane, block) computes
//! t = k − (Qxx·dx + b)·dx with k = 1 − ((Qyy·dy)·dy + (2Qyz·dy)·dz + (Qzz·dz)·dz) and
//! b = 2Qxy·dy + 2Qxz·dz, then A·w(t) (w of t = 1 − q², [`Profile::value`]), with the same
//! operations in the same order, and sums in index order, so dense, sparse and point values are
//! the same bits. In single precision t is rounded to f32 and the profile, the product and the
//! sum are f32.
//!
//! Block bounds: a term lies between its values at t = 1 − near²/reach² (the box's nearest
//! point) and t = 1 − far²·λ_max(Q) (its farthest), both with a relative margin of 1e-7 on
//! the eigenvalues. The round kernels' proof for blocks inside the fluid (pairs of points,
//! separable per axis) has no counterpart here: bounds per cell of two points per axis lost
//! half the potential inside a slab (0.48 where it is 0.95, against a threshold of 0.6), and
//! per pair along x they proved blocks at three times the cost of splatting them; such blocks
//! are splatted.

use super::block::BlockCoords;
use super::kernel::{with_profile, Profile, Real};
use super::{BlobField, PerPrimitive, Precision, BLOCK_POINTS};
use crate::error::{Error, Result};
use crate::knn::symmetric_eigen;
use crate::lattice::Lattice;
use crate::simd::Isa;
use glam::DVec3;
use std::sync::Arc;

/// The largest ratio of a shape's largest singular value to its smallest.
pub const MAX_CONDITION: f64 = 1e4;

/// Relative margin on the eigenvalues of Q (far above their rounding for shapes within
/// [`MAX_CONDITION`]).
const MARGIN: f64 = 1e-7;

/// The shapes of a field's primitives, as given and as evaluated.
#[derive(Clone, Debug, Default)]
pub struct Shapes {
    /// Sᵢ as given, row-major.
    given: Vec<[f64; 9]>,
    /// Rᵢ as given.
    radii: Vec<f64>,
    forms: Vec<Form>,
}

/// One primitive's quadratic form Q = SᵀS/R² and its bounds.
#[derive(Clone, Copy, Debug, Default)]
struct Form {
    /// Qxx, Qxy, Qxz, Qyy, Qyz, Qzz.
    q: [f64; 6],
    /// Half the side of the ellipsoid's bounding box per axis, √(Q⁻¹)ₐₐ, with the margin.
    extent: DVec3,
    /// λ_max(Q) with the margin (1/R² of the farthest bound).
    far_inv: f64,
    /// R/s_min with the margin: the bounding sphere's radius.
    reach: f64,
}

impl Form {
    /// The form of shape `s` (row-major) and radius `r`, or why it is refused.
    fn new(s: &[f64; 9], r: f64) -> std::result::Result<Form, String> {
        if s.iter().any(|v| !v.is_finite()) {
            return Err("has a non-finite entry".into());
        }
        let inv = 1.0 / (r * r);
        let col = |a: usize, b: usize| (0..3).map(|k| s[3 * k + a] * s[3 * k + b]).sum::<f64>();
        let m = [
            [col(0, 0), col(0, 1), col(0, 2)],
            [col(0, 1), col(1, 1), col(1, 2)],
            [col(0, 2), col(1, 2), col(2, 2)],
        ];
        let (values, v) = symmetric_eigen(m);
        let hi = values.iter().fold(f64::NEG_INFINITY, |a, &x| a.max(x));
        let lo = values.iter().fold(f64::INFINITY, |a, &x| a.min(x));
        if !(lo > 0.0 && hi <= lo * MAX_CONDITION * MAX_CONDITION) {
            return Err(format!(
                "must be invertible with singular values within a factor {MAX_CONDITION:e} (their squares span {lo:e} to {hi:e})"
            ));
        }
        let extent = DVec3::from_array(std::array::from_fn(|a| {
            let d: f64 = (0..3).map(|k| v[a][k] * v[a][k] / values[k]).sum();
            r * d.sqrt() * (1.0 + MARGIN)
        }));
        let q = [m[0][0], m[0][1], m[0][2], m[1][1], m[1][2], m[2][2]].map(|x| x * inv);
        let reach = r / lo.sqrt() * (1.0 + MARGIN);
        let far_inv = hi * inv * (1.0 + MARGIN);
        if !(reach.is_finite() && (1.0 / (reach * reach)).is_normal() && far_inv.is_finite()) {
            return Err(format!("gives a reach {reach:e} out of range"));
        }
        Ok(Form {
            q,
            extent,
            far_inv,
            reach,
        })
    }

    /// k and b of the row at offsets `dy`, `dz` from the centre (see the module docs).
    #[inline(always)]
    fn row(&self, dy: f64, dz: f64) -> (f64, f64) {
        let [_, xy, xz, yy, yz, zz] = self.q;
        let k = 1.0 - (((yy * dy) * dy + ((2.0 * yz) * dy) * dz) + (zz * dz) * dz);
        let b = (2.0 * xy) * dy + (2.0 * xz) * dz;
        (k, b)
    }

    /// t at offset `d` from the centre (unclamped).
    #[inline(always)]
    fn t(&self, d: DVec3) -> f64 {
        let (k, b) = self.row(d.y, d.z);
        k - (self.q[0] * d.x + b) * d.x
    }

    /// Q·d.
    #[inline(always)]
    fn apply(&self, d: DVec3) -> DVec3 {
        let [xx, xy, xz, yy, yz, zz] = self.q;
        DVec3::new(
            xx * d.x + xy * d.y + xz * d.z,
            xy * d.x + yy * d.y + yz * d.z,
            xz * d.x + yz * d.y + zz * d.z,
        )
    }
}

/// Whether every t = k − (Qxx·dx + b)·dx of a row, |dx| ≤ `far`, is provably negative as
/// computed: the exact maximum k + b²/(4Qxx) is below zero by more than a bound on the rounding
/// (10⁻¹⁴ of the magnitudes involved, far above the few roundings of each step).
#[inline(always)]
fn row_misses(k: f64, b: f64, qxx: f64, far: f64) -> bool {
    let top = b * b / (4.0 * qxx);
    k + top + 1e-14 * (k.abs() + top + qxx * far * far + b.abs() * far) < 0.0
}

impl Shapes {
    /// The shapes `given` (one per radius) with their forms, or an error naming `shapes`.
    fn new(given: Vec<[f64; 9]>, radii: Vec<f64>) -> Result<Shapes> {
        if given.len() != radii.len() {
            return Err(Error::invalid(
                "shapes",
                format!("need one per center: {} for {}", given.len(), radii.len()),
            ));
        }
        let forms = given
            .iter()
            .zip(&radii)
            .enumerate()
            .map(|(i, (s, &r))| {
                Form::new(s, r).map_err(|e| Error::invalid("shapes", format!("shape {i} {e}")))
            })
            .collect::<Result<Vec<Form>>>()?;
        Ok(Shapes {
            given,
            radii,
            forms,
        })
    }

    /// Each primitive's reach (the bounding sphere's radius).
    fn reaches(&self) -> Vec<f64> {
        self.forms.iter().map(|f| f.reach).collect()
    }
}

impl BlobField {
    /// A blob field whose primitive i adds Aᵢ·w(|Sᵢ (p − cᵢ)|/Rᵢ) (see the module docs):
    /// [`BlobField::new`] with a shape per primitive (`shapes`, row-major 3×3, invertible, with
    /// singular values within a factor [`MAX_CONDITION`]).
    pub fn with_shapes(
        centers: &[DVec3],
        radii: PerPrimitive,
        strengths: PerPrimitive,
        threshold: f64,
        settings: super::BlobSettings,
        shapes: &[[f64; 9]],
    ) -> Result<Self> {
        let mut r = Vec::new();
        radii.fill("radii", centers.len(), &mut r, true)?;
        let shapes = Shapes::new(shapes.to_vec(), r)?;
        let reach = shapes.reaches();
        let mut field = BlobField::new(
            centers,
            PerPrimitive::Each(&reach),
            strengths,
            threshold,
            settings,
        )?;
        field.shapes = Some(Arc::new(shapes));
        Ok(field)
    }

    /// The shapes Sᵢ (row-major) and radii Rᵢ as given, for a field made by
    /// [`BlobField::with_shapes`] ([`BlobField::radii`] are then the bounding spheres' radii).
    pub fn shapes(&self) -> Option<(&[[f64; 9]], &[f64])> {
        self.shapes.as_ref().map(|s| (&s.given[..], &s.radii[..]))
    }

    /// [`BlobField::update`] of a field with shapes: the shapes stay with their primitives, so
    /// the number of centers cannot change; new radii give new forms.
    pub(super) fn update_shaped(
        &mut self,
        centers: &[DVec3],
        radii: Option<PerPrimitive>,
        strengths: Option<PerPrimitive>,
    ) -> Result<()> {
        let shapes = self.shapes.clone().unwrap_or_default();
        if centers.len() != shapes.given.len() {
            return Err(Error::invalid(
                "centers",
                format!(
                    "{} centers for a field of {} shaped primitives: the count cannot change",
                    centers.len(),
                    shapes.given.len()
                ),
            ));
        }
        let Some(radii) = radii else {
            return self.update_primitives(centers, None, strengths);
        };
        let mut r = Vec::new();
        radii.fill("radii", centers.len(), &mut r, true)?;
        let shapes = Shapes::new(shapes.given.clone(), r)?;
        let reach = shapes.reaches();
        self.update_primitives(centers, Some(PerPrimitive::Each(&reach)), strengths)?;
        self.shapes = Some(Arc::new(shapes));
        Ok(())
    }

    /// The subset `keep` of the shapes (for [`BlobField::subset`]).
    pub(super) fn shapes_of(&self, keep: &[u32]) -> Option<(Vec<[f64; 9]>, Vec<f64>)> {
        self.shapes.as_ref().map(|s| {
            (
                keep.iter().map(|&i| s.given[i as usize]).collect(),
                keep.iter().map(|&i| s.radii[i as usize]).collect(),
            )
        })
    }

    /// 1/R² of primitive `i` at the farthest point of a box (the round kernel's 1/R², or
    /// λ_max(Q) with its margin).
    #[inline(always)]
    pub(super) fn far_inv(&self, i: usize) -> f64 {
        match &self.shapes {
            None => self.inv_r2[i],
            Some(s) => s.forms[i].far_inv,
        }
    }

    /// A bound on |∇f| over all space (see [`crate::field::Field::gradient_bound`]): one
    /// term's gradient is at most |A|·max|w′|·√λ_max(Q).
    pub(super) fn shaped_gradient_bound(&self, s: &Shapes) -> f64 {
        let k = self.settings.kernel.max_slope();
        self.grid().max_list_sum(|i| {
            k * self.strengths[i as usize].abs() * s.forms[i as usize].far_inv.sqrt()
        })
    }

    /// The potential at `p` over the primitives `list` (every one reaching `p`, in index order),
    /// in `T`.
    #[inline(always)]
    fn shaped_sum<K: Profile, T: Real>(&self, s: &Shapes, list: &[u32], p: DVec3) -> T {
        let mut f = T::of(0.0);
        for &i in list {
            let i = i as usize;
            let t = s.forms[i].t(p - self.centers[i]);
            f = f + T::of(self.strengths[i]) * K::value(T::of(t));
        }
        f
    }

    /// The potential at `p` from the voxel lists, in the field's precision (widened).
    pub(super) fn shaped_potential(&self, s: &Shapes, p: DVec3) -> f64 {
        let list = self.grid().candidates(p);
        with_profile!(self.settings.kernel, K => match self.settings.precision {
            Precision::Double => self.shaped_sum::<K, f64>(s, list, p),
            Precision::Single => self.shaped_sum::<K, f32>(s, list, p) as f64,
        })
    }

    /// The potential at `p` over every primitive (the reference for tests).
    pub(super) fn shaped_potential_brute_force(&self, s: &Shapes, p: DVec3) -> f64 {
        let all: Vec<u32> = (0..self.centers.len() as u32).collect();
        with_profile!(self.settings.kernel, K => match self.settings.precision {
            Precision::Double => self.shaped_sum::<K, f64>(s, &all, p),
            Precision::Single => self.shaped_sum::<K, f32>(s, &all, p) as f64,
        })
    }

    /// threshold − F at `p`, in the field's precision (widened).
    pub(super) fn shaped_value(&self, s: &Shapes, p: DVec3) -> f64 {
        let list = self.grid().candidates(p);
        with_profile!(self.settings.kernel, K => match self.settings.precision {
            Precision::Double => self.threshold - self.shaped_sum::<K, f64>(s, list, p),
            Precision::Single => {
                (self.threshold as f32 - self.shaped_sum::<K, f32>(s, list, p)) as f64
            }
        })
    }

    /// ∇f(p) = −∇F(p) over the primitives `list`: each term's gradient is
    /// −GRADIENT_SCALE·A·g(t)·Q(p − c) ([`Profile::slope`]).
    #[inline(always)]
    pub(super) fn shaped_gradient<K: Profile>(&self, s: &Shapes, list: &[u32], p: DVec3) -> DVec3 {
        let mut g = DVec3::ZERO;
        for &i in list {
            let i = i as usize;
            let form = &s.forms[i];
            let d = p - self.centers[i];
            let slope = K::slope(form.t(d));
            g += form.apply(d) * (K::GRADIENT_SCALE * self.strengths[i] * slope);
        }
        g
    }

    /// One z-plane of lattice values (`xs`, `ys`: the lattice's coordinates, `z` the plane's)
    /// by splatting every primitive whose box reaches the plane, row by row over the chord of
    /// the ellipse (with a point of margin: the exact test is t > 0).
    pub(super) fn shaped_plane(
        &self,
        s: &Shapes,
        lattice: &Lattice,
        [xs, ys]: [&[f64]; 2],
        z: f64,
        slab: &mut [f64],
    ) {
        with_profile!(self.settings.kernel, K => match self.settings.precision {
            Precision::Double => self.shaped_plane_with::<K, f64>(s, lattice, [xs, ys], z, slab),
            Precision::Single => {
                let mut v = vec![0.0f32; slab.len()];
                self.shaped_plane_with::<K, f32>(s, lattice, [xs, ys], z, &mut v);
                for (o, v) in slab.iter_mut().zip(&v) {
                    *o = *v as f64;
                }
            }
        })
    }

    /// [`BlobField::shaped_plane`] in `T`.
    fn shaped_plane_with<K: Profile, T: Real>(
        &self,
        s: &Shapes,
        lattice: &Lattice,
        [xs, ys]: [&[f64]; 2],
        z: f64,
        slab: &mut [T],
    ) {
        let (px, py) = (xs.len(), ys.len());
        slab.fill(T::of(0.0));
        let (o, inv_h) = (lattice.origin(), DVec3::ONE / lattice.cell());
        let range = super::plane::index_range;
        for (i, form) in s.forms.iter().enumerate() {
            let c = self.centers[i];
            let dz = z - c.z;
            if dz.abs() > form.extent.z {
                continue;
            }
            let Some((y0, y1)) = range(c.y, form.extent.y, o.y, inv_h.y, py) else {
                continue;
            };
            let a = T::of(self.strengths[i]);
            let qxx = form.q[0];
            for y in y0..=y1 {
                let (k, b) = form.row(ys[y] - c.y, dz);
                // The chord where t > 0: around x₀ = −b/(2Qxx), half √(t_max/Qxx).
                let mid = c.x - b / (2.0 * qxx);
                let top = k + b * b / (4.0 * qxx);
                let half = (top.max(0.0) / qxx).sqrt();
                let Some((x0, x1)) = range(mid, half, o.x, inv_h.x, px) else {
                    continue;
                };
                let row = &mut slab[y * px + x0..=y * px + x1];
                for (v, &x) in row.iter_mut().zip(&xs[x0..=x1]) {
                    let dx = x - c.x;
                    *v = *v + a * K::value(T::of(k - (qxx * dx + b) * dx));
                }
            }
        }
        let threshold = T::of(self.threshold);
        for v in slab.iter_mut() {
            *v = threshold - *v;
        }
    }

    /// A block's values from the primitives of `list` (see [`super::BlockField::block_values`]):
    /// each primitive over the rows of the planes its box reaches, eight lanes a row, in the
    /// field's precision, with the vector path of `isa` (which the CPU must have; the compiler's
    /// vectors, no fused multiply-adds, so the same bits on every path).
    pub(super) fn shaped_block(
        &self,
        isa: Isa,
        s: &Shapes,
        list: &[u32],
        block: &BlockCoords,
        out: &mut [f64; 512],
    ) {
        if self.settings.precision == Precision::Single {
            let mut v = [0.0f32; 512];
            with_profile!(self.settings.kernel, K => match isa {
                // SAFETY: the caller passes an instruction set the CPU has.
                #[cfg(target_arch = "x86_64")]
                Isa::Avx512 | Isa::Avx2 => unsafe {
                    self.shaped_block_avx2::<K, f32>(s, list, block, &mut v)
                },
                _ => self.shaped_block_with::<K, f32>(s, list, block, &mut v),
            });
            for (o, v) in out.iter_mut().zip(v) {
                *o = v as f64;
            }
            return;
        }
        with_profile!(self.settings.kernel, K => match isa {
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => unsafe { self.shaped_block_avx512::<K>(s, list, block, out) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe { self.shaped_block_avx2::<K, f64>(s, list, block, out) },
            _ => self.shaped_block_with::<K, f64>(s, list, block, out),
        })
    }

    /// [`BlobField::shaped_block_with`] compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn shaped_block_avx2<K: Profile, T: Real>(
        &self,
        s: &Shapes,
        list: &[u32],
        block: &BlockCoords,
        out: &mut [T; 512],
    ) {
        self.shaped_block_with::<K, T>(s, list, block, out)
    }

    /// [`BlobField::shaped_block_with`] compiled for AVX-512.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn shaped_block_avx512<K: Profile>(
        &self,
        s: &Shapes,
        list: &[u32],
        block: &BlockCoords,
        out: &mut [f64; 512],
    ) {
        self.shaped_block_with::<K, f64>(s, list, block, out)
    }

    /// [`BlobField::shaped_block`] in `T`: rows are always eight wide (lanes beyond the lattice
    /// repeat its last point and are never read).
    #[inline(always)]
    fn shaped_block_with<K: Profile, T: Real>(
        &self,
        s: &Shapes,
        list: &[u32],
        block: &BlockCoords,
        out: &mut [T; 512],
    ) {
        let BlockCoords { xs, ys, zs, n, .. } = block;
        let ny = n[1] as usize;
        out.fill(T::of(0.0));
        for &i in list {
            let i = i as usize;
            let (form, c) = (&s.forms[i], self.centers[i]);
            let a = T::of(self.strengths[i]);
            let qxx = form.q[0];
            let dx: [f64; BLOCK_POINTS] = std::array::from_fn(|l| xs[l] - c.x);
            let u: [f64; BLOCK_POINTS] = dx.map(|d| qxx * d);
            let far = dx[0].abs().max(dx[BLOCK_POINTS - 1].abs());
            for k in block.planes(c.z, form.extent.z) {
                let dz = zs[k] - c.z;
                for j in 0..ny {
                    let dy = ys[j] - c.y;
                    if dy.abs() > form.extent.y {
                        continue;
                    }
                    let (kk, b) = form.row(dy, dz);
                    if row_misses(kk, b, qxx, far) {
                        continue;
                    }
                    let row = &mut out[8 * j + 64 * k..8 * j + 64 * k + 8];
                    for l in 0..BLOCK_POINTS {
                        let t = kk - (u[l] + b) * dx[l];
                        row[l] = row[l] + a * K::value(T::of(t));
                    }
                }
            }
        }
        let threshold = T::of(self.threshold);
        for v in out.iter_mut() {
            *v = threshold - *v;
        }
    }
}
