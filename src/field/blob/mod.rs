//! Blob fields of point primitives (Triquet et al. §4.2): the potential
//! F(p) = Σ A_i w(d_i/R_i), with w a compact profile ([`BlobKernel`]: by default Triquet's
//! (1 − q²)², else the SPH cubic spline or Wendland C2) that is 0 for d_i ≥ R_i, and the surface
//! F = threshold. The field the polygonizers see is `threshold − F`, negative inside. With the
//! default profile its gradient is −∇F = Σ (4A_i/R_i²)(1 − d_i²/R_i²)(p − c_i) (the paper's eq. 2
//! has the wrong factor and sign).
//!
//! Evaluation looks only at the primitives listed in the point's voxel ([`VoxelGrid`], built on
//! the first point query: the sparse polygonizer without normals never needs it). The
//! hand-written vector paths serve the default profile; the others run the generic loops.

pub mod anisotropy;
pub mod densities;
pub mod ellipsoids;
mod hints;
mod interior;
mod kept;
pub mod kernel;
pub mod particles;
mod single;
pub mod tiles;
pub mod voxels;

use hints::{Hints, Proof, ONE_SIGN_FRAMES};
pub use single::Precision;

use super::{Block, BlockField, BlockSign, Field, BLOCK_POINTS, PAR_CHUNK};
use crate::error::{check_finite_points, Error, Result};
#[cfg(target_arch = "x86_64")]
use crate::field::blob::kernel::LaneProfile;
use crate::field::blob::kernel::{with_profile, BlobKernel, Profile, Real, Triquet};
use crate::field::blob::voxels::VoxelGrid;
use crate::lattice::Lattice;
#[cfg(target_arch = "x86_64")]
use crate::simd::lanes::{F64s, Lanes};
use crate::simd::Isa;
use glam::DVec3;
use rayon::prelude::*;
use std::ops::Range;
use std::sync::Arc;

/// Settings of a blob field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlobSettings {
    /// Voxel side as a multiple of the mean radius of influence (default 0.5; the trade-off
    /// is in `notebooks/triquet_blobs.ipynb`). Smaller voxels give evaluations fewer primitives
    /// to look at and the grid more list entries to hold.
    pub voxel_size: f64,
    /// The profile every primitive sums (default [`BlobKernel::Triquet`]).
    pub kernel: BlobKernel,
    /// The float type of the field's values (default [`Precision::Double`]): point queries,
    /// lattice values and block values all use it. Gradients are f64 in both.
    pub precision: Precision,
}

impl Default for BlobSettings {
    fn default() -> Self {
        BlobSettings {
            voxel_size: 0.5,
            kernel: BlobKernel::Triquet,
            precision: Precision::Double,
        }
    }
}

/// A blob field: point primitives with compact polynomial kernels.
#[derive(Clone, Debug, Default)]
pub struct BlobField {
    centers: Vec<DVec3>,
    radii: Vec<f64>,
    /// 1 / R² per primitive.
    inv_r2: Vec<f64>,
    strengths: Vec<f64>,
    /// The same numbers packed per primitive for point queries (one cache line each), built on
    /// the first point query ([`BlobField::packed`]) and refilled in place once built: block
    /// values and gradients read the arrays above.
    packed: std::sync::OnceLock<Vec<Packed>>,
    threshold: f64,
    settings: BlobSettings,
    /// The voxel lists, built by [`BlobField::grid`] on first use and rebuilt in place by
    /// [`BlobField::update`] once built.
    grid: std::sync::OnceLock<VoxelGrid>,
    /// Block lists kept from one polygonization to the next on the same lattice (an
    /// animation's frames): see the `kept` module.
    kept: kept::Kept,
    /// Ellipsoidal kernels (the `ellipsoids` module), when the field has them.
    shapes: Option<Arc<ellipsoids::Shapes>>,
}

/// One primitive as point queries read it.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(64))]
struct Packed {
    center: DVec3,
    /// 1 / R².
    inv_r2: f64,
    /// A.
    strength: f64,
}

/// A scalar or one value per primitive.
#[derive(Clone, Debug)]
pub enum PerPrimitive<'a> {
    /// The same value for every primitive.
    All(f64),
    /// One value per primitive, in the primitives' order.
    Each(&'a [f64]),
}

impl PerPrimitive<'_> {
    fn fill(&self, name: &'static str, n: usize, out: &mut Vec<f64>, positive: bool) -> Result<()> {
        out.clear();
        match self {
            PerPrimitive::All(v) => out.resize(n, *v),
            PerPrimitive::Each(v) => {
                if v.len() != n {
                    return Err(Error::invalid(
                        name,
                        format!(
                            "need one value per center or a scalar: {} values for {n} centers",
                            v.len()
                        ),
                    ));
                }
                out.extend_from_slice(v);
            }
        }
        if let Some(i) = out
            .iter()
            .position(|v| !v.is_finite() || (positive && *v <= 0.0))
        {
            return Err(Error::invalid(
                name,
                format!(
                    "entry {i} is {}; must be finite{}",
                    out[i],
                    if positive { " and positive" } else { "" }
                ),
            ));
        }
        // Radii: the kernels compare squared distances with r², so 1/r² must be a normal float64.
        if positive {
            if let Some(i) = out.iter().position(|v| !(1.0 / (v * v)).is_normal()) {
                return Err(Error::invalid(
                    name,
                    format!(
                        "entry {i} is {:e}; must lie between 1e-154 and 1e154 (its square a normal float64)",
                        out[i]
                    ),
                ));
            }
        }
        Ok(())
    }
}

impl BlobField {
    /// A blob field with primitives at `centers`, radii of influence `radii`, strengths
    /// (the paper's A_i) `strengths`, and the surface at potential `threshold`.
    pub fn new(
        centers: &[DVec3],
        radii: PerPrimitive,
        strengths: PerPrimitive,
        threshold: f64,
        settings: BlobSettings,
    ) -> Result<Self> {
        if !(threshold.is_finite() && threshold > 0.0) {
            return Err(Error::invalid(
                "threshold",
                format!("must be positive and finite, got {threshold}"),
            ));
        }
        if !(settings.voxel_size.is_finite() && settings.voxel_size > 0.0) {
            return Err(Error::invalid(
                "voxel_size",
                format!("must be positive and finite, got {}", settings.voxel_size),
            ));
        }
        let mut b = BlobField {
            threshold,
            settings,
            ..Default::default()
        };
        b.update(centers, Some(radii), Some(strengths))?;
        Ok(b)
    }

    /// Moves the primitives (and optionally changes radii and strengths), then rebuilds the voxel
    /// lists in place. The number of primitives may change; when it does not, nothing is
    /// reallocated.
    pub fn update(
        &mut self,
        centers: &[DVec3],
        radii: Option<PerPrimitive>,
        strengths: Option<PerPrimitive>,
    ) -> Result<()> {
        if self.shapes.is_some() {
            return self.update_shaped(centers, radii, strengths);
        }
        self.update_primitives(centers, radii, strengths)
    }

    /// [`BlobField::update`] of the primitives' arrays (`radii`: the spheres' radii).
    fn update_primitives(
        &mut self,
        centers: &[DVec3],
        radii: Option<PerPrimitive>,
        strengths: Option<PerPrimitive>,
    ) -> Result<()> {
        check_finite_points("centers", centers)?;
        crate::spatial::check_far("centers", centers)?;
        let n = centers.len();
        let mut r = std::mem::take(&mut self.radii);
        let mut a = std::mem::take(&mut self.strengths);
        let res = (|| {
            match radii {
                Some(p) => p.fill("radii", n, &mut r, true)?,
                None if r.len() != n => {
                    return Err(Error::invalid(
                        "radii",
                        format!(
                            "{n} centers but {} radii: pass radii when the count changes",
                            r.len()
                        ),
                    ))
                }
                None => {}
            }
            match strengths {
                Some(p) => p.fill("strengths", n, &mut a, false)?,
                None if a.len() != n => {
                    return Err(Error::invalid(
                        "strengths",
                        format!(
                            "{n} centers but {} strengths: pass strengths when the count changes",
                            a.len()
                        ),
                    ))
                }
                None => {}
            }
            // The voxel grid spans the spheres of influence: their box must be a finite size.
            let (lo, hi) = centers.iter().zip(&r).fold(
                (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
                |(lo, hi), (c, r)| (lo.min(*c - *r), hi.max(*c + *r)),
            );
            if n > 0 && !(hi - lo).is_finite() {
                return Err(Error::invalid(
                    "radii",
                    format!(
                        "the primitives' spheres span from {} to {}, wider than a float64 can hold",
                        crate::spatial::short(lo),
                        crate::spatial::short(hi)
                    ),
                ));
            }
            Ok(())
        })();
        self.radii = r;
        self.strengths = a;
        res?;
        self.centers.clear();
        self.centers.extend_from_slice(centers);
        self.inv_r2.clear();
        self.inv_r2.extend(self.radii.iter().map(|r| 1.0 / (r * r)));
        self.repack();
        let side = self.voxel_side();
        if let Some(grid) = self.grid.get_mut() {
            grid.rebuild(&self.centers, &self.radii, side);
        }
        Ok(())
    }

    /// The voxels' side: [`BlobSettings::voxel_size`] times the mean radius.
    fn voxel_side(&self) -> f64 {
        let n = self.radii.len();
        let mean_r = if n > 0 {
            self.radii.iter().sum::<f64>() / n as f64
        } else {
            1.0
        };
        self.settings.voxel_size * mean_r
    }

    /// Replaces the strengths (one per primitive or a scalar), keeping centres, radii and the
    /// voxel lists.
    pub fn set_strengths(&mut self, strengths: PerPrimitive) -> Result<()> {
        let mut a = std::mem::take(&mut self.strengths);
        let res = strengths.fill("strengths", self.centers.len(), &mut a, false);
        if res.is_ok() {
            self.strengths = a;
            self.repack();
        } else {
            self.strengths = a;
        }
        res
    }

    /// Refills [`BlobField::packed`] in place from the per-primitive arrays when it is built.
    fn repack(&mut self) {
        if let Some(packed) = self.packed.get_mut() {
            packed.clear();
            packed.extend((0..self.centers.len()).map(|i| Packed {
                center: self.centers[i],
                inv_r2: self.inv_r2[i],
                strength: self.strengths[i],
            }));
        }
    }

    /// The primitives packed for point queries, built on the first call.
    fn packed(&self) -> &[Packed] {
        self.packed.get_or_init(|| {
            (0..self.centers.len())
                .map(|i| Packed {
                    center: self.centers[i],
                    inv_r2: self.inv_r2[i],
                    strength: self.strengths[i],
                })
                .collect()
        })
    }

    /// Potential F(p) by brute force over all primitives (the reference for tests).
    pub fn potential_brute_force(&self, p: DVec3) -> f64 {
        if let Some(s) = &self.shapes {
            return self.shaped_potential_brute_force(s, p);
        }
        let packed = self.packed();
        with_profile!(self.settings.kernel, K => packed.iter().map(|q| term::<K>(q, p)).sum())
    }

    /// Centre, 1/R², A and R of primitive `i`.
    #[inline(always)]
    fn primitive(&self, i: u32) -> (DVec3, f64, f64, f64) {
        let i = i as usize;
        (
            self.centers[i],
            self.inv_r2[i],
            self.strengths[i],
            self.radii[i],
        )
    }

    /// c·A / R² of primitive `i` (c: the profile's [`Profile::GRADIENT_SCALE`]), the factor of
    /// its gradient.
    #[inline(always)]
    fn gradient_factor<K: Profile>(&self, i: usize) -> f64 {
        K::GRADIENT_SCALE * self.strengths[i] * self.inv_r2[i]
    }

    /// ∇f(p) = −∇F(p) from the voxel lists.
    #[inline(always)]
    fn gradient_at(&self, p: DVec3) -> DVec3 {
        with_profile!(self.settings.kernel, K => self.gradient_over::<K>(self.grid().candidates(p), p))
    }

    /// ∇f(p) summed over the primitives `list` (in index order: the same terms, in the same
    /// order, as any other list that holds every primitive reaching `p`).
    #[inline(always)]
    fn gradient_over<K: Profile>(&self, list: &[u32], p: DVec3) -> DVec3 {
        if let Some(s) = &self.shapes {
            return self.shaped_gradient::<K>(s, list, p);
        }
        let mut g = DVec3::ZERO;
        for &i in list {
            let i = i as usize;
            let d = p - self.centers[i];
            let s = K::slope(1.0 - d.length_squared() * self.inv_r2[i]);
            g += d * (self.gradient_factor::<K>(i) * s);
        }
        g
    }

    /// Potential F(p) from the voxel lists (the same terms in the same order as
    /// [`BlobField::potential_brute_force`] minus those that cannot reach `p`); in single
    /// precision the f32 sum, widened.
    #[inline(always)]
    pub fn potential(&self, p: DVec3) -> f64 {
        if let Some(s) = &self.shapes {
            return self.shaped_potential(s, p);
        }
        match self.settings.precision {
            Precision::Double => {
                with_profile!(self.settings.kernel, K => self.potential_with::<K>(p))
            }
            Precision::Single => {
                with_profile!(self.settings.kernel, K => self.potential_single::<K>(p) as f64)
            }
        }
    }

    /// [`BlobField::potential`] with the profile `K`.
    #[inline(always)]
    fn potential_with<K: Profile>(&self, p: DVec3) -> f64 {
        let packed = self.packed();
        let mut f = 0.0;
        for &i in self.grid().candidates(p) {
            f += term::<K>(&packed[i as usize], p);
        }
        f
    }

    /// Fills one z-plane of lattice values (`xs`, `ys`: the lattice's coordinates; `z`: the
    /// plane's) by splatting every primitive that reaches the plane, row by row over the
    /// x-range its sphere covers.
    #[inline(always)]
    fn splat_plane<K: Profile>(
        &self,
        lattice: &Lattice,
        xs: &[f64],
        ys: &[f64],
        z: f64,
        slab: &mut [f64],
    ) {
        self.splat_plane_with(lattice, xs, ys, z, slab, splat_row::<K>)
    }

    /// [`BlobField::splat_plane`] with the row loop given (a vector build of [`splat_row`]).
    #[inline(always)]
    fn splat_plane_with<T: Real>(
        &self,
        lattice: &Lattice,
        xs: &[f64],
        ys: &[f64],
        z: f64,
        slab: &mut [T],
        row_fn: impl Fn(&mut [T], &[f64], &RowTerm),
    ) {
        let (px, py) = (xs.len(), ys.len());
        slab.fill(T::of(0.0));
        let inv_h = DVec3::ONE / lattice.cell();
        let range = index_range;
        for i in 0..self.centers.len() {
            let (c, r, inv, a) = (
                self.centers[i],
                self.radii[i],
                self.inv_r2[i],
                self.strengths[i],
            );
            let dz = z - c.z;
            let dz2 = dz * dz;
            // dy² + dz² ≥ dz² in floating point too, so no point of the plane is reached when
            // this is not positive.
            if 1.0 - dz2 * inv <= 0.0 {
                continue;
            }
            let Some((y0, y1)) = range(c.y, r, lattice.origin().y, inv_h.y, py) else {
                continue;
            };
            for y in y0..=y1 {
                let Some(term) = RowTerm::new(c, inv, a, ys[y], dz2) else {
                    continue;
                };
                // Half the chord, from k = 1 − (dy² + dz²)/R² (the exact test is t > 0 in the
                // row loop; `range` adds a point of margin).
                let half = r * term.k.max(0.0).sqrt();
                let Some((x0, x1)) = range(c.x, half, lattice.origin().x, inv_h.x, px) else {
                    continue;
                };
                row_fn(&mut slab[y * px + x0..=y * px + x1], &xs[x0..=x1], &term);
            }
        }
        let threshold = T::of(self.threshold);
        for v in slab.iter_mut() {
            *v = threshold - *v;
        }
    }

    /// [`BlobField::splat_plane`] with AVX-512 rows (the default profile only).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn splat_plane_avx512(
        &self,
        l: &Lattice,
        xs: &[f64],
        ys: &[f64],
        z: f64,
        s: &mut [f64],
    ) {
        // SAFETY: this function only runs where AVX-512F is available.
        self.splat_plane_with(l, xs, ys, z, s, |r, x, t| unsafe {
            splat_row_avx512(r, x, t)
        })
    }

    /// [`BlobField::splat_plane`] compiled for AVX2 (the compiler's vectors; no fused
    /// multiply-adds, so the same bits).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn splat_plane_avx2<K: Profile>(
        &self,
        l: &Lattice,
        xs: &[f64],
        ys: &[f64],
        z: f64,
        s: &mut [f64],
    ) {
        self.splat_plane::<K>(l, xs, ys, z, s)
    }

    /// Fills a block of values (see [`BlockField::block_values`]) by splatting the primitives of
    /// `list` row by row: the dense splat's arithmetic and order, so the same bits. Rows are
    /// always eight wide (lanes beyond the lattice repeat its last point and are never read);
    /// `row_fn` adds one primitive's terms to a row from dx²/R² per lane (computed once per
    /// primitive), the row's k = 1 − (dy² + dz²)/R² and A (see [`unit_t`] and [`Profile::value`]).
    ///
    /// In f32 (`T`), each of dx²/R², k and A is computed in f64 and rounded to f32, then t and
    /// the term in f32 ([`single::term`]).
    #[inline(always)]
    fn splat_block_with<T: Real>(
        &self,
        list: &[u32],
        block: &BlockCoords,
        out: &mut [T; 512],
        row_fn: impl Fn(&mut [T; 8], &[T; 8], T, T),
    ) {
        let BlockCoords { xs, ys, zs, n, .. } = block;
        let ny = n[1] as usize;
        out.fill(T::of(0.0));
        for &i in list {
            let (c, inv, a, r) = self.primitive(i);
            // dx²/R² per lane, once per primitive (see `unit_t`).
            let qx: [f64; 8] = std::array::from_fn(|l| ((xs[l] - c.x) * (xs[l] - c.x)) * inv);
            let qt: [T; 8] = qx.map(T::of);
            let at = T::of(a);
            let dy2: [f64; 8] = std::array::from_fn(|j| (ys[j] - c.y) * (ys[j] - c.y));
            // The lane nearest the centre has a row's largest term (the rounded steps are
            // monotone), so where its term is zero the whole row gains exactly zero: only the
            // rows where it is positive are splatted (the chords of the sphere that reach the
            // block), found per plane as a bit mask without a branch per row.
            let near = qx.iter().fold(f64::INFINITY, |m, &d| m.min(d));
            let in_block = (1u32 << ny) - 1;
            let planes = block.planes(c.z, r);
            #[allow(clippy::needless_range_loop)] // k also indexes `out`
            for k in planes {
                let dz = zs[k] - c.z;
                let dz2 = dz * dz;
                let ks: [f64; 8] = std::array::from_fn(|j| 1.0 - (dy2[j] + dz2) * inv);
                let mut rows =
                    (0..8).fold(0u32, |m, j| m | ((ks[j] - near > 0.0) as u32) << j) & in_block;
                while rows != 0 {
                    let j = rows.trailing_zeros() as usize;
                    rows &= rows - 1;
                    let row: &mut [T; 8] = (&mut out[8 * j + 64 * k..8 * j + 64 * k + 8])
                        .try_into()
                        .unwrap();
                    row_fn(row, &qt, T::of(ks[j]), at);
                }
            }
        }
        let threshold = T::of(self.threshold);
        for v in out.iter_mut() {
            *v = threshold - *v;
        }
    }

    /// [`BlobField::splat_block_with`] written for AVX-512: per primitive, dx²/R² is one vector
    /// and per plane the rows' k = 1 − (dy² + dz²)/R² another, compared with the nearest lane's
    /// dx²/R² at once for the mask of rows to splat. The same operations on each value as
    /// [`unit_t`] and [`Profile::value`], in the same order, so the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn splat_block_avx512(&self, list: &[u32], block: &BlockCoords, out: &mut [f64; 512]) {
        use std::arch::x86_64::*;
        let BlockCoords { xs, ys, zs, n, .. } = block;
        let in_block = ((1u32 << n[1]) - 1) as __mmask8;
        out.fill(0.0);
        // SAFETY: the coordinate arrays hold eight f64 each.
        let (vx, vy) = unsafe { (_mm512_loadu_pd(xs.as_ptr()), _mm512_loadu_pd(ys.as_ptr())) };
        let (one, zero) = (_mm512_set1_pd(1.0), _mm512_setzero_pd());
        for &i in list {
            let (c, inv, a, r) = self.primitive(i);
            let vinv = _mm512_set1_pd(inv);
            let dx = _mm512_sub_pd(vx, _mm512_set1_pd(c.x));
            let qx = _mm512_mul_pd(_mm512_mul_pd(dx, dx), vinv);
            let near = _mm512_set1_pd(_mm512_reduce_min_pd(qx));
            let dy = _mm512_sub_pd(vy, _mm512_set1_pd(c.y));
            let dy2 = _mm512_mul_pd(dy, dy);
            let va = _mm512_set1_pd(a);
            let planes = block.planes(c.z, r);
            #[allow(clippy::needless_range_loop)] // k also indexes `out`
            for k in planes {
                let dz = zs[k] - c.z;
                let ks = _mm512_sub_pd(
                    one,
                    _mm512_mul_pd(_mm512_add_pd(dy2, _mm512_set1_pd(dz * dz)), vinv),
                );
                // Rows whose nearest lane has a positive term (see `splat_block_with`).
                let mut rows = _mm512_mask_cmp_pd_mask::<_CMP_GT_OQ>(in_block, ks, near) as u32;
                if rows == 0 {
                    continue;
                }
                let mut kv = [0.0f64; 8];
                // SAFETY: eight f64.
                unsafe { _mm512_storeu_pd(kv.as_mut_ptr(), ks) };
                while rows != 0 {
                    let j = rows.trailing_zeros() as usize;
                    rows &= rows - 1;
                    let t = _mm512_max_pd(_mm512_sub_pd(_mm512_set1_pd(kv[j]), qx), zero);
                    let at = _mm512_mul_pd(va, _mm512_mul_pd(t, t));
                    // SAFETY: 8j + 64k + 8 ≤ 512 (j, k < 8).
                    unsafe {
                        let p = out.as_mut_ptr().add(8 * j + 64 * k);
                        _mm512_storeu_pd(p, _mm512_add_pd(_mm512_loadu_pd(p), at));
                    }
                }
            }
        }
        let th = _mm512_set1_pd(self.threshold);
        for row in out.chunks_exact_mut(8) {
            // SAFETY: eight f64.
            unsafe {
                let p = row.as_mut_ptr();
                _mm512_storeu_pd(p, _mm512_sub_pd(th, _mm512_loadu_pd(p)));
            }
        }
    }

    /// Fills a block's values (see [`BlockField::block_values`]) from the primitives of `list`
    /// with the vector path of `isa` (which the CPU must have): the same bits on every path.
    fn splat_block(&self, isa: Isa, list: &[u32], block: &BlockCoords, out: &mut [f64; 512]) {
        if let Some(s) = &self.shapes {
            return self.shaped_block(isa, s, list, block, out);
        }
        if self.settings.precision == Precision::Single {
            return self.splat_block_single(isa, list, block, out);
        }
        with_profile!(self.settings.kernel, K => match isa {
            // SAFETY: the caller passes an instruction set the CPU has.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 if is_triquet::<K>() => unsafe { self.splat_block_avx512(list, block, out) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 if is_triquet::<K>() => unsafe { self.splat_block_avx2(list, block, out) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => unsafe { self.splat_block_lanes_avx512::<K>(list, block, out) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe {
                self.splat_block_lanes_avx2::<K, std::arch::x86_64::__m256d>(list, block, out)
            },
            Isa::Generic => self.splat_block_generic::<K, f64>(list, block, out),
        })
    }

    /// [`BlobField::splat_block_generic`] with each row's terms `V::LANES` at a time
    /// ([`LaneProfile::value_lanes`]), in f64 or f32: the same operations in the same order, so
    /// the same bits.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn splat_block_lanes<K: LaneProfile, V: Lanes>(
        &self,
        list: &[u32],
        block: &BlockCoords,
        out: &mut [V::Elem; 512],
    ) where
        V::Elem: Real,
    {
        self.splat_block_with(list, block, out, |row, qx, k, a| {
            // SAFETY: the caller runs where V's feature is; a row holds 8 values, a multiple of
            // V::LANES.
            unsafe {
                let (k, a) = (V::splat(k), V::splat(a));
                for h in (0..BLOCK_POINTS).step_by(V::LANES) {
                    let t = k.sub(V::load(&qx[h..]));
                    let v = V::load(&row[h..]).add(a.mul(K::value_lanes(t)));
                    v.store(&mut row[h..]);
                }
            }
        })
    }

    /// [`BlobField::splat_block_lanes`] with AVX-512, a row per vector.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn splat_block_lanes_avx512<K: LaneProfile>(
        &self,
        list: &[u32],
        block: &BlockCoords,
        out: &mut [f64; 512],
    ) {
        // SAFETY: AVX-512F is enabled here.
        unsafe { self.splat_block_lanes::<K, std::arch::x86_64::__m512d>(list, block, out) }
    }

    /// [`BlobField::splat_block_lanes`] with AVX2 vectors `V`: a row per two `__m256d`, or per
    /// `__m256` in f32.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn splat_block_lanes_avx2<K: LaneProfile, V: Lanes>(
        &self,
        list: &[u32],
        block: &BlockCoords,
        out: &mut [V::Elem; 512],
    ) where
        V::Elem: Real,
    {
        // SAFETY: AVX2 is enabled here (and V needs no more).
        unsafe { self.splat_block_lanes::<K, V>(list, block, out) }
    }

    /// [`BlobField::splat_block_with`] with the profile's scalar row loop (in f64 or f32).
    #[inline(always)]
    fn splat_block_generic<K: Profile, T: Real>(
        &self,
        list: &[u32],
        block: &BlockCoords,
        out: &mut [T; 512],
    ) {
        self.splat_block_with(list, block, out, |row, qx, k, a| {
            for (v, &q) in row.iter_mut().zip(qx) {
                *v = *v + a * K::value(k - q);
            }
        })
    }

    /// [`BlobField::gradient_over`] at each point, with the vector path of `isa` (which the CPU
    /// must have) for whole vectors of points: the same bits on every path.
    fn gradients_over(&self, isa: Isa, list: &[u32], points: &[DVec3], out: &mut [DVec3]) {
        if self.shapes.is_some() {
            return with_profile!(self.settings.kernel, K => map_points(points, out, |p| {
                self.gradient_over::<K>(list, p)
            }));
        }
        with_profile!(self.settings.kernel, K => self.gradients_over_with::<K>(isa, list, points, out))
    }

    /// [`BlobField::gradients_over`] with the profile `K` (vector paths for the default one).
    #[inline(always)]
    fn gradients_over_with<K: Profile>(
        &self,
        isa: Isa,
        list: &[u32],
        points: &[DVec3],
        out: &mut [DVec3],
    ) {
        let done = match isa {
            #[cfg(target_arch = "x86_64")]
            _ if !is_triquet::<K>() => 0,
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => {
                let full = points.len() / 8 * 8;
                // SAFETY: the caller passes an instruction set the CPU has.
                unsafe { self.gradients8_avx512(list, &points[..full], &mut out[..full]) };
                full
            }
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => {
                let full = points.len() / 4 * 4;
                // SAFETY: as above.
                unsafe { self.gradients4_avx2(list, &points[..full], &mut out[..full]) };
                full
            }
            Isa::Generic => 0,
        };
        for (p, o) in points[done..].iter().zip(&mut out[done..]) {
            *o = self.gradient_over::<K>(list, *p);
        }
    }

    /// [`BlobField::splat_block_avx512`] for AVX2: each row of eight as two vectors of four. The
    /// same operations on each value as [`unit_t`] and [`Profile::value`], in the same order, so the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn splat_block_avx2(&self, list: &[u32], block: &BlockCoords, out: &mut [f64; 512]) {
        use std::arch::x86_64::*;
        let BlockCoords { xs, ys, zs, n, .. } = block;
        let in_block = (1u32 << n[1]) - 1;
        out.fill(0.0);
        // SAFETY: the coordinate arrays hold eight f64 each.
        let vx = unsafe { [0, 4].map(|h| _mm256_loadu_pd(xs.as_ptr().add(h))) };
        let vy = unsafe { [0, 4].map(|h| _mm256_loadu_pd(ys.as_ptr().add(h))) };
        let (one, zero) = (_mm256_set1_pd(1.0), _mm256_setzero_pd());
        for &i in list {
            let (c, inv, a, r) = self.primitive(i);
            let vinv = _mm256_set1_pd(inv);
            let qx = vx.map(|x| {
                let dx = _mm256_sub_pd(x, _mm256_set1_pd(c.x));
                _mm256_mul_pd(_mm256_mul_pd(dx, dx), vinv)
            });
            // The smallest lane (min is exact, so the generic fold's value).
            let m = _mm256_min_pd(qx[0], qx[1]);
            let m = _mm_min_pd(_mm256_castpd256_pd128(m), _mm256_extractf128_pd::<1>(m));
            let near = _mm256_set1_pd(_mm_cvtsd_f64(_mm_min_sd(m, _mm_unpackhi_pd(m, m))));
            let dy2 = vy.map(|y| {
                let dy = _mm256_sub_pd(y, _mm256_set1_pd(c.y));
                _mm256_mul_pd(dy, dy)
            });
            let va = _mm256_set1_pd(a);
            let planes = block.planes(c.z, r);
            #[allow(clippy::needless_range_loop)] // k also indexes `out`
            for k in planes {
                let dz = zs[k] - c.z;
                let dz2 = _mm256_set1_pd(dz * dz);
                let ks =
                    dy2.map(|d| _mm256_sub_pd(one, _mm256_mul_pd(_mm256_add_pd(d, dz2), vinv)));
                // Rows whose nearest lane has a positive term (see `splat_block_with`).
                let gt =
                    ks.map(|k| _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(k, near)) as u32);
                let mut rows = (gt[0] | gt[1] << 4) & in_block;
                if rows == 0 {
                    continue;
                }
                let mut kv = [0.0f64; 8];
                // SAFETY: eight f64.
                unsafe {
                    _mm256_storeu_pd(kv.as_mut_ptr(), ks[0]);
                    _mm256_storeu_pd(kv.as_mut_ptr().add(4), ks[1]);
                }
                while rows != 0 {
                    let j = rows.trailing_zeros() as usize;
                    rows &= rows - 1;
                    let kj = _mm256_set1_pd(kv[j]);
                    for (h, q) in qx.iter().enumerate() {
                        let t = _mm256_max_pd(_mm256_sub_pd(kj, *q), zero);
                        let at = _mm256_mul_pd(va, _mm256_mul_pd(t, t));
                        // SAFETY: 8j + 64k + 4h + 4 ≤ 512 (j, k < 8, h < 2).
                        unsafe {
                            let p = out.as_mut_ptr().add(8 * j + 64 * k + 4 * h);
                            _mm256_storeu_pd(p, _mm256_add_pd(_mm256_loadu_pd(p), at));
                        }
                    }
                }
            }
        }
        let th = _mm256_set1_pd(self.threshold);
        for row in out.chunks_exact_mut(4) {
            // SAFETY: four f64.
            unsafe {
                let p = row.as_mut_ptr();
                _mm256_storeu_pd(p, _mm256_sub_pd(th, _mm256_loadu_pd(p)));
            }
        }
    }

    /// [`BlobField::gradient_over`] for `V::LANES` points per step (`points.len()` a multiple
    /// of it). The same operations in the same order, so the same bits.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn gradients_lanes<V: F64s>(&self, list: &[u32], points: &[DVec3], out: &mut [DVec3]) {
        // SAFETY (every vector operation below): the caller runs where V's feature is.
        unsafe {
            let (one, zero) = (V::splat(1.0), V::splat(0.0));
            for (pc, oc) in points
                .chunks_exact(V::LANES)
                .zip(out.chunks_exact_mut(V::LANES))
            {
                let (mut x, mut y, mut z) = ([0.0; 8], [0.0; 8], [0.0; 8]);
                for (k, p) in pc.iter().enumerate() {
                    (x[k], y[k], z[k]) = (p.x, p.y, p.z);
                }
                let (px, py, pz) = (V::load(&x), V::load(&y), V::load(&z));
                let (mut gx, mut gy, mut gz) = (zero, zero, zero);
                for &i in list {
                    let i = i as usize;
                    let c = self.centers[i];
                    let dx = px.sub(V::splat(c.x));
                    let dy = py.sub(V::splat(c.y));
                    let dz = pz.sub(V::splat(c.z));
                    let s = dx.mul(dx).add(dy.mul(dy)).add(dz.mul(dz));
                    let t = one.sub(s.mul(V::splat(self.inv_r2[i]))).max(zero);
                    let k = V::splat(self.gradient_factor::<Triquet>(i)).mul(t);
                    gx = gx.add(dx.mul(k));
                    gy = gy.add(dy.mul(k));
                    gz = gz.add(dz.mul(k));
                }
                gx.store(&mut x);
                gy.store(&mut y);
                gz.store(&mut z);
                for (k, o) in oc.iter_mut().enumerate() {
                    *o = DVec3::new(x[k], y[k], z[k]);
                }
            }
        }
    }

    /// [`BlobField::gradients_lanes`] with AVX-512, eight points per step.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn gradients8_avx512(&self, list: &[u32], points: &[DVec3], out: &mut [DVec3]) {
        // SAFETY: AVX-512F is enabled here.
        unsafe { self.gradients_lanes::<std::arch::x86_64::__m512d>(list, points, out) }
    }

    /// [`BlobField::gradients_lanes`] with AVX2, four points per step.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn gradients4_avx2(&self, list: &[u32], points: &[DVec3], out: &mut [DVec3]) {
        // SAFETY: AVX2 is enabled here.
        unsafe { self.gradients_lanes::<std::arch::x86_64::__m256d>(list, points, out) }
    }

    /// The primitives' centres.
    pub fn centers(&self) -> &[DVec3] {
        &self.centers
    }
    /// The primitives' radii (each primitive acts up to this distance from its centre).
    pub fn radii(&self) -> &[f64] {
        &self.radii
    }
    /// The primitives' strengths.
    pub fn strengths(&self) -> &[f64] {
        &self.strengths
    }
    /// The threshold: the surface is where the summed potential equals it.
    pub fn threshold(&self) -> f64 {
        self.threshold
    }
    /// The voxel lists of the primitives, built on the first call.
    pub fn grid(&self) -> &VoxelGrid {
        self.grid.get_or_init(|| {
            let mut grid = VoxelGrid::default();
            grid.rebuild(&self.centers, &self.radii, self.voxel_side());
            grid
        })
    }
    /// The settings the field was made with.
    pub fn settings(&self) -> BlobSettings {
        self.settings
    }
    /// Sets the precision of the field's values ([`BlobSettings::precision`]).
    pub fn set_precision(&mut self, precision: Precision) {
        self.settings.precision = precision;
    }

    /// Bounding box of the spheres of influence (None when there are no primitives).
    pub fn bounding_box(&self) -> Option<(DVec3, DVec3)> {
        if self.centers.is_empty() {
            return None;
        }
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for (c, r) in self.centers.iter().zip(&self.radii) {
            lo = lo.min(*c - DVec3::splat(*r));
            hi = hi.max(*c + DVec3::splat(*r));
        }
        Some((lo, hi))
    }
}

/// The term A·w(t) of the packed primitive `q` at `p`.
#[inline(always)]
fn term<K: Profile>(q: &Packed, p: DVec3) -> f64 {
    q.strength * K::value(unit_t(p - q.center, q.inv_r2))
}

/// Block lists longer than this take the voxel lists for gradients, when they are built.
const LONG_BLOCK_LIST: usize = 64;

/// Point batches smaller than this are evaluated on the calling thread (about 0.1 ms of work).
const SERIAL_BELOW: usize = 2048;

/// `out[i] = f(points[i])`, in parallel chunks. Batches below [`SERIAL_BELOW`] points run on the
/// calling thread: handing them to the pool costs more than it saves (the tracking
/// polygonizer's waves are often that small).
#[inline(always)]
fn map_points<T: Send>(points: &[DVec3], out: &mut [T], f: impl Fn(DVec3) -> T + Sync) {
    assert_eq!(points.len(), out.len());
    let run = |p: &[DVec3], o: &mut [T]| {
        for (pi, oi) in p.iter().zip(o.iter_mut()) {
            *oi = f(*pi);
        }
    };
    if points.len() < SERIAL_BELOW {
        return run(points, out);
    }
    points
        .par_chunks(PAR_CHUNK)
        .zip(out.par_chunks_mut(PAR_CHUNK))
        .for_each(|(p, o)| run(p, o));
}

/// t = (1 − (dy² + dz²)/R²) − dx²/R² of one primitive at offset `d` from its centre (1/R²
/// `inv`), unclamped, which [`Profile::value`] turns into the term: the order every evaluation of
/// the potential uses (point, plane and block), so that all give the same bits. Grouping
/// dy² + dz² first lets a lattice row share 1 − (dy² + dz²)/R² and a block share dx²/R² per
/// primitive; both rounded steps are monotone, so t never grows with any |d_i|.
#[inline(always)]
fn unit_t(d: DVec3, inv: f64) -> f64 {
    (1.0 - (d.y * d.y + d.z * d.z) * inv) - (d.x * d.x) * inv
}

/// Whether `K` is the default profile, the one the hand-written vector paths compute.
#[inline(always)]
fn is_triquet<K: Profile>() -> bool {
    std::any::TypeId::of::<K>() == std::any::TypeId::of::<Triquet>()
}

/// One primitive's term along one lattice row: x-centre, k = 1 − (dy² + dz²)/R², 1/R², A.
struct RowTerm {
    cx: f64,
    k: f64,
    inv: f64,
    a: f64,
}

impl RowTerm {
    /// The term of the primitive at `c` (1/R² `inv`, strength `a`) along the row at `y` in a
    /// plane at squared z-distance `dz2`; None when it reaches no point of the row
    /// (k − dx²/R² ≤ k ≤ 0 in floating point too).
    #[inline(always)]
    fn new(c: DVec3, inv: f64, a: f64, y: f64, dz2: f64) -> Option<RowTerm> {
        let dy = y - c.y;
        let k = 1.0 - (dy * dy + dz2) * inv;
        (k > 0.0).then_some(RowTerm { cx: c.x, k, inv, a })
    }
}

/// Adds the term A·w(t), t = k − dx²/R² (see [`unit_t`]), to each value of a row (`row[i]` at
/// x = `xs[i]`). The order of operations is that of [`BlobField::potential`], without fused
/// multiply-adds, so the values are bit-identical to point evaluation.
#[inline(always)]
fn splat_row<K: Profile>(row: &mut [f64], xs: &[f64], q: &RowTerm) {
    for (v, &x) in row.iter_mut().zip(xs) {
        let dx = x - q.cx;
        *v += q.a * K::value(q.k - (dx * dx) * q.inv);
    }
}

/// [`splat_row`] of the default profile eight lanes at a time with masked loads and stores for the tail (rows are
/// short: a sphere of 16 cells' radius spans at most 33 points). The same operations in the
/// same order, so the same bits.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn splat_row_avx512(row: &mut [f64], xs: &[f64], q: &RowTerm) {
    use std::arch::x86_64::*;
    let n = row.len().min(xs.len());
    let (cx, k) = (_mm512_set1_pd(q.cx), _mm512_set1_pd(q.k));
    let (inv, a) = (_mm512_set1_pd(q.inv), _mm512_set1_pd(q.a));
    let zero = _mm512_setzero_pd();
    let mut i = 0;
    while i < n {
        let m: __mmask8 = if n - i >= 8 {
            0xff
        } else {
            (1u8 << (n - i)) - 1
        };
        // SAFETY: lanes outside the mask are neither read nor written, and the masked lanes
        // are i..min(i + 8, n), within both slices.
        let x = _mm512_maskz_loadu_pd(m, xs.as_ptr().add(i));
        let v = _mm512_maskz_loadu_pd(m, row.as_ptr().add(i));
        let dx = _mm512_sub_pd(x, cx);
        let t = _mm512_max_pd(
            _mm512_sub_pd(k, _mm512_mul_pd(_mm512_mul_pd(dx, dx), inv)),
            zero,
        );
        let r = _mm512_add_pd(v, _mm512_mul_pd(a, _mm512_mul_pd(t, t)));
        _mm512_mask_storeu_pd(row.as_mut_ptr().add(i), m, r);
        i += 8;
    }
}

impl Field for BlobField {
    /// The primitives' centres, each walking at most its largest radius in cells, plus 2.
    fn starts(&self, cell: f64) -> Option<crate::field::Starts> {
        let rmax = self.radii().iter().fold(0.0f64, |a, r| a.max(*r));
        Some(crate::field::Starts {
            points: self.centers().to_vec(),
            max_walk: (rmax / cell).ceil() as u32 + 2,
        })
    }
    /// A blob field bounds its values over blocks of the lattice.
    fn block_field(&self) -> Option<&dyn crate::field::DynBlockField> {
        Some(self)
    }
    /// An upper bound on |∇f| over all space: one primitive's gradient is at most
    /// A·max|w′| / R (for the default profile at d = R/√3, where it is 8A / (3√3 R)); near any
    /// point only the primitives of its voxel list act, so the bound is the largest sum over one
    /// list. With this as the octree's safety factor, its rejection test never rejects a block
    /// the surface crosses.
    fn gradient_bound(&self) -> Option<f64> {
        if let Some(s) = &self.shapes {
            return Some(self.shaped_gradient_bound(s));
        }
        let k = self.settings.kernel.max_slope();
        Some(
            self.grid()
                .max_list_sum(|i| k * self.strengths[i as usize].abs() / self.radii[i as usize]),
        )
    }

    /// Splats every primitive into the lattice points of its sphere of influence, plane by plane
    /// in parallel, row by row over the x-range the sphere covers. Each point accumulates the
    /// primitives in index order with the same arithmetic as [`BlobField::potential`] (terms
    /// that do not reach the point add +0.0, which changes nothing), so the values are
    /// bit-identical to [`Field::values`].
    fn lattice_values(
        &self,
        lattice: &Lattice,
        z0: u32,
        z1: u32,
        _points: &mut Vec<DVec3>,
        out: &mut [f64],
    ) {
        let [px, py, _] = lattice.points_per_axis();
        let plane = px as usize * py as usize;
        // Coordinates exactly as Lattice::point computes them.
        let xs: Vec<f64> = (0..px).map(|i| lattice.point([i, 0, 0]).x).collect();
        let ys: Vec<f64> = (0..py).map(|j| lattice.point([0, j, 0]).y).collect();
        let isa = Isa::detect();
        if let Some(s) = &self.shapes {
            return out
                .par_chunks_mut(plane)
                .enumerate()
                .for_each(|(dz, slab)| {
                    let z = lattice.point([0, 0, z0 + dz as u32]).z;
                    self.shaped_plane(s, lattice, [&xs, &ys], z, slab)
                });
        }
        with_profile!(self.settings.kernel, K => out.par_chunks_mut(plane)
        .enumerate()
        .for_each(|(dz, slab)| {
            let k = z0 + dz as u32;
            debug_assert!(k < z1);
            let z = lattice.point([0, 0, k]).z;
            match isa {
                _ if self.settings.precision == Precision::Single => {
                    self.splat_plane_single::<K>(lattice, [&xs, &ys], z, slab)
                }
                // SAFETY: the variant is only chosen when the CPU has the feature.
                #[cfg(target_arch = "x86_64")]
                Isa::Avx512 if is_triquet::<K>() => unsafe {
                    self.splat_plane_avx512(lattice, &xs, &ys, z, slab)
                },
                // SAFETY: as above (AVX-512 implies AVX2).
                #[cfg(target_arch = "x86_64")]
                Isa::Avx2 | Isa::Avx512 => unsafe {
                    self.splat_plane_avx2::<K>(lattice, &xs, &ys, z, slab)
                },
                Isa::Generic => self.splat_plane::<K>(lattice, &xs, &ys, z, slab),
            }
        }));
    }

    #[inline]
    fn value(&self, p: DVec3) -> f64 {
        if let Some(s) = &self.shapes {
            return self.shaped_value(s, p);
        }
        match self.settings.precision {
            Precision::Double => self.threshold - self.potential(p),
            Precision::Single => {
                with_profile!(self.settings.kernel, K => self.value_single::<K>(p))
            }
        }
    }

    #[inline]
    fn gradient(&self, p: DVec3) -> DVec3 {
        self.gradient_at(p)
    }

    /// The batch loops call the point functions inlined: a call per point (the trait's default)
    /// costs as much as the terms themselves here.
    fn values(&self, points: &[DVec3], out: &mut [f64]) {
        if let Some(s) = &self.shapes {
            return map_points(points, out, |p| self.shaped_value(s, p));
        }
        match self.settings.precision {
            Precision::Double => {
                with_profile!(self.settings.kernel, K => map_points(points, out, |p| {
                    self.threshold - self.potential_with::<K>(p)
                }))
            }
            Precision::Single => {
                with_profile!(self.settings.kernel, K => map_points(points, out, |p| {
                    self.value_single::<K>(p)
                }))
            }
        }
    }

    fn gradients(&self, points: &[DVec3], out: &mut [DVec3]) {
        with_profile!(self.settings.kernel, K => map_points(points, out, |p| {
            self.gradient_over::<K>(self.grid().candidates(p), p)
        }));
    }
}

/// Which primitives reach which block of a lattice (for [`BlockField`]): one compressed list per
/// z-layer of blocks, each block's primitives in index order; all layers
/// ([`BlockField::blocks`]) or a few at a time ([`BlockField::keep_layers`]).
pub struct BlockLists {
    /// Blocks per axis.
    dims: [u32; 3],
    /// The z-layer of `layers[0]`.
    first: u32,
    /// Per z-layer from `first`: `start` (one more than the layer's blocks) and `items`
    /// (shared with the lists the `kept` module keeps between calls, when they are those).
    layers: Arc<Vec<Layer>>,
    /// Whether `layers` holds every z-layer ([`BlockField::keep_layers`] then keeps them all).
    whole: bool,
    /// The primitives that may reach each z-layer (`layer_candidates`), kept while layers are
    /// still to be listed (empty once every layer is).
    candidates: (Vec<u32>, Vec<u32>),
    /// How each block's sign was found in the last call, with lists kept between calls.
    hints: Option<Arc<Hints>>,
}

impl BlockLists {
    /// The primitives that may reach block `b` (in a layer held), in index order.
    #[inline]
    pub fn list(&self, b: [u32; 3]) -> &[u32] {
        let (start, items) = &self.layers[(b[2] - self.first) as usize];
        let k = (b[0] + self.dims[0] * b[1]) as usize;
        &items[start[k] as usize..start[k + 1] as usize]
    }

    /// Total entries over the lists held.
    pub fn entries(&self) -> usize {
        self.layers.iter().map(|(_, i)| i.len()).sum()
    }

    /// Bytes held (capacities).
    pub fn bytes(&self) -> usize {
        let words = self.layers.iter().map(|(s, i)| s.capacity() + i.capacity());
        4 * (words.sum::<usize>() + self.candidates.0.capacity() + self.candidates.1.capacity())
    }
}

/// The lists of one z-layer of blocks: `start` (one more than the layer's blocks) and `items`.
type Layer = (Vec<u32>, Vec<u32>);

/// The lattice coordinates of a block's points per axis, and its points per axis.
struct BlockCoords {
    xs: [f64; BLOCK_POINTS],
    ys: [f64; BLOCK_POINTS],
    zs: [f64; BLOCK_POINTS],
    n: [u32; 3],
    /// 1 / the lattice's cell side per axis.
    inv_h: [f64; 3],
}

impl BlockCoords {
    /// The block of `n` points per axis from lattice point `lo`, its coordinates exactly as
    /// [`Lattice::point`] computes them (repeating the last point up to eight).
    fn new(lattice: &Lattice, lo: [u32; 3], n: [u32; 3]) -> BlockCoords {
        let coord = |a: usize| -> [f64; BLOCK_POINTS] {
            std::array::from_fn(|i| {
                let mut g = [0; 3];
                g[a] = lo[a] + (i as u32).min(n[a] - 1);
                lattice.point(g)[a]
            })
        };
        BlockCoords {
            xs: coord(0),
            ys: coord(1),
            zs: coord(2),
            n,
            inv_h: (DVec3::ONE / lattice.cell()).to_array(),
        }
    }

    /// The block's planes within [cz − r, cz + r], with a point of margin for rounding (the
    /// exact test is per row); empty when none.
    #[inline(always)]
    fn planes(&self, cz: f64, r: f64) -> std::ops::Range<usize> {
        let (first, inv_h, n) = (self.zs[0], self.inv_h[2], self.n[2] as usize);
        let lo = floor((cz - r - first) * inv_h) - 1.0;
        let hi = ceil((cz + r - first) * inv_h) + 1.0;
        if hi < 0.0 || lo > (n - 1) as f64 {
            return 0..0;
        }
        lo.max(0.0) as usize..(hi as usize).min(n - 1) + 1
    }
}

impl BlobField {
    /// The sign the field provably has on the box `[plo, phi]` (from each primitive of `list`,
    /// which must hold every primitive reaching the box: its term lies between its values at
    /// the nearest and the farthest point of the box), or [`BlockSign::Mixed`]. The margin,
    /// 1e-9 of the strengths' sum, is far above rounding.
    fn box_sign(&self, list: &[u32], plo: DVec3, phi: DVec3) -> BlockSign {
        with_profile!(self.settings.kernel, K => self.box_sign_with::<K>(list, plo, phi))
    }

    /// [`BlobField::box_sign`] with the profile `K`.
    #[inline(always)]
    fn box_sign_with<K: Profile>(&self, list: &[u32], plo: DVec3, phi: DVec3) -> BlockSign {
        let (mut fmin, mut fmax, mut scale) = (0.0f64, 0.0f64, self.threshold.abs());
        let mut terms = 0.0f64;
        for &i in list {
            let i = i as usize;
            let (c, inv, a) = (self.centers[i], self.inv_r2[i], self.strengths[i]);
            let (near, far) = box_distances2(c, plo, phi);
            let (big, small) = (
                a * K::value(1.0 - near * inv),
                a * K::value(1.0 - far * self.far_inv(i)),
            );
            fmax += big.max(small);
            fmin += big.min(small);
            terms += big.abs().max(small.abs());
            scale += a.abs();
        }
        let margin = 1e-9 * scale
            + match self.settings.precision {
                Precision::Double => 0.0,
                Precision::Single => single::rounding(
                    self.threshold,
                    scale - self.threshold.abs(),
                    terms,
                    list.len(),
                ),
            };
        if fmax < self.threshold - margin {
            BlockSign::Outside
        } else if fmin > self.threshold + margin {
            BlockSign::Inside
        } else {
            BlockSign::Mixed
        }
    }
}

impl BlobField {
    /// The sign of `block` as [`BlockField::block_sign`] proves it, and the proof that did
    /// ([`Proof::Unknown`]: the box bounds, or none). The proof `hint` names goes first and
    /// alone: [`Proof::Crossed`] tries none.
    fn block_sign_by(
        &self,
        blocks: &BlockLists,
        lattice: &Lattice,
        block: &Block,
        hint: Proof,
    ) -> (BlockSign, Proof) {
        let Block { index: b, lo, n } = *block;
        let list = blocks.list(b);
        let inside = |coords: &BlockCoords| {
            if self.block_inside(Isa::detect(), list, coords) {
                (BlockSign::Inside, Proof::Pairs)
            } else {
                (BlockSign::Mixed, Proof::Unknown)
            }
        };
        let octants = || {
            if self.octants_outside(list, lattice, lo, n) {
                (BlockSign::Outside, Proof::Octants)
            } else {
                (BlockSign::Mixed, Proof::Unknown)
            }
        };
        match hint {
            Proof::Crossed | Proof::OneSign { .. } => return (BlockSign::Mixed, Proof::Unknown),
            Proof::Pairs => return inside(&BlockCoords::new(lattice, lo, n)),
            Proof::Octants => return octants(),
            Proof::Unknown => {}
        }
        let (plo, phi) = block_box(lattice, b);
        let sign = self.box_sign(list, plo, phi);
        if sign != BlockSign::Mixed {
            return (sign, Proof::Unknown);
        }
        // Inside the surface, the bounds over boxes of many points are loose (each term's
        // smallest value is at the box's farthest corner): bound pairs of points instead, when
        // the potential is above the threshold at the block's eight corners (most blocks the
        // surface crosses have a corner outside, found at the cost of a term per primitive and
        // corner).
        let coords = BlockCoords::new(lattice, lo, n);
        if self.corners_inside(Isa::detect(), list, &coords) {
            return inside(&coords);
        }
        octants()
    }

    /// Whether the bounds over each of the block's eight octants (points 0..=3 and 4..=7 per
    /// axis) prove it outside: outside the surface the bounds over the whole block are loose
    /// where many terms overlap. Stops at the first octant that may be crossed; false for a
    /// block of at most four points along an axis.
    fn octants_outside(&self, list: &[u32], lattice: &Lattice, lo: [u32; 3], n: [u32; 3]) -> bool {
        if !n.iter().all(|&v| v > 4) {
            return false;
        }
        let half = |a: usize, s: u32| -> (u32, u32) {
            if s == 0 {
                (lo[a], lo[a] + 3)
            } else {
                (lo[a] + 4, lo[a] + n[a] - 1)
            }
        };
        (0..8u32).all(|o| {
            let (x, y, z) = (half(0, o & 1), half(1, (o >> 1) & 1), half(2, o >> 2));
            let (plo, phi) = (
                lattice.point([x.0, y.0, z.0]),
                lattice.point([x.1, y.1, z.1]),
            );
            self.box_sign(list, plo, phi) == BlockSign::Outside
        })
    }
}

/// The hint a block leaves for the next frame: the `proof` of its `sign`, or when it was
/// splatted, [`Proof::Crossed`] if its values have both signs (`crossed`), else
/// [`Proof::OneSign`] after proofs (for [`ONE_SIGN_FRAMES`] frames, counted down by the splats
/// without proofs that follow), and [`Proof::Unknown`] after a splat without proofs that ends
/// the count or follows a crossed frame: the next frame proves it again.
fn splatted_proof(
    sign: BlockSign,
    proof: Proof,
    hint: Proof,
    crossed: impl FnOnce() -> bool,
) -> Proof {
    if sign != BlockSign::Mixed {
        proof
    } else if crossed() {
        Proof::Crossed
    } else {
        match hint {
            Proof::Crossed | Proof::OneSign { frames: 0 } => Proof::Unknown,
            Proof::OneSign { frames } => Proof::OneSign { frames: frames - 1 },
            _ => Proof::OneSign {
                frames: ONE_SIGN_FRAMES - 1,
            },
        }
    }
}

/// Whether the values of a block of `n` points per axis have both signs (inside: below zero).
fn both_signs(values: &[f64; 512], n: [u32; 3]) -> bool {
    let (mut inside, mut outside) = (false, false);
    for plane in values.chunks_exact(64).take(n[2] as usize) {
        for row in plane.chunks_exact(8).take(n[1] as usize) {
            for &v in &row[..n[0] as usize] {
                inside |= v < 0.0;
                outside |= v >= 0.0;
            }
        }
    }
    inside && outside
}

/// The primitives per z-layer of blocks, in index order, as compressed rows (`start` has one
/// more entry than there are `layers`): primitive i in every layer of `layers_of(i)`, a range
/// holding every layer its sphere may reach.
fn layer_candidates(
    layers: u32,
    primitives: usize,
    layers_of: impl Fn(usize) -> std::ops::Range<u32>,
) -> (Vec<u32>, Vec<u32>) {
    let mut start = vec![0u32; layers as usize + 1];
    for i in 0..primitives {
        for z in layers_of(i) {
            start[z as usize + 1] += 1;
        }
    }
    for z in 0..layers as usize {
        start[z + 1] += start[z];
    }
    let mut cursor = start.clone();
    let mut items = vec![0u32; start[layers as usize] as usize];
    for i in 0..primitives {
        for z in layers_of(i) {
            items[cursor[z as usize] as usize] = i as u32;
            cursor[z as usize] += 1;
        }
    }
    (start, items)
}

/// `x.floor()`, inlined (the baseline x86-64 target has no rounding instruction, and `floor`
/// is then a call into the C library): the truncation of `x`, less one below a negative
/// non-integer. Values of 2⁵² and more in magnitude (integers), and NaN, go to `f64::floor`.
#[inline(always)]
fn floor(x: f64) -> f64 {
    if x.abs() < 4_503_599_627_370_496.0 {
        let t = x as i64 as f64;
        if t > x {
            t - 1.0
        } else {
            t
        }
    } else {
        x.floor()
    }
}

/// `x.ceil()`, inlined as [`floor`] is: −floor(−x).
#[inline(always)]
fn ceil(x: f64) -> f64 {
    -floor(-x)
}

/// A primitive's radius with the relative margin every block-list test uses.
#[inline(always)]
fn margin(r: f64) -> f64 {
    r * (1.0 + 1e-9)
}

/// Candidate blocks along axis `a` for a sphere at `c` of radius `rm` (one more on each side
/// for rounding), for the exact sphere-box test; `dims` blocks per axis.
fn block_range(lattice: &Lattice, dims: [u32; 3], c: DVec3, rm: f64, a: usize) -> Range<u32> {
    let span = lattice.cell()[a] * (BLOCK_POINTS - 1) as f64;
    let lo = floor((c[a] - rm - lattice.origin()[a]) / span) - 1.0;
    let hi = floor((c[a] + rm - lattice.origin()[a]) / span) + 1.0;
    let hi = hi.min((dims[a] - 1) as f64);
    if hi < 0.0 || lo > hi {
        return 0..0;
    }
    lo.max(0.0) as u32..hi as u32 + 1
}

impl BlobField {
    /// The lists of z-layer `bz` of blocks (`start`, one more than the layer's blocks, and
    /// `items`) from the primitives `here` that may reach it, each at its position in
    /// `centers` with its radius grown by `slack`; `sides` are the blocks' box coordinates per
    /// axis.
    #[allow(clippy::too_many_arguments)]
    fn layer_lists(
        &self,
        lattice: &Lattice,
        dims: [u32; 3],
        sides: &[Vec<(f64, f64)>; 3],
        bz: u32,
        here: &[u32],
        (centers, slack): (&[DVec3], f64),
    ) -> Layer {
        let per_layer = (dims[0] * dims[1]) as usize;
        let mut pairs: Vec<(u32, u32)> = Vec::new();
        for &i in here {
            let (c, rm) = (centers[i as usize], margin(self.radii[i as usize] + slack));
            blocks_reached(lattice, dims, sides, bz, (c, rm), |k| pairs.push((k, i)));
        }
        // Counting sort by block, stable: each list stays in index order.
        let mut start = vec![0u32; per_layer + 1];
        for &(k, _) in &pairs {
            start[k as usize + 1] += 1;
        }
        for k in 0..per_layer {
            start[k + 1] += start[k];
        }
        let mut items = vec![0u32; pairs.len()];
        let mut cursor = start.clone();
        for &(k, i) in &pairs {
            items[cursor[k as usize] as usize] = i;
            cursor[k as usize] += 1;
        }
        (start, items)
    }
}

/// Calls `reached(bx + dims[0]·by)` for each block of z-layer `bz` whose box the sphere at `c`
/// of radius `rm` reaches (the test every block list is made with), in ascending order; `sides`
/// are the blocks' box coordinates per axis ([`block_sides`]).
#[inline]
fn blocks_reached(
    lattice: &Lattice,
    dims: [u32; 3],
    sides: &[Vec<(f64, f64)>; 3],
    bz: u32,
    (c, rm): (DVec3, f64),
    mut reached: impl FnMut(u32),
) {
    let (zlo, zhi) = sides[2][bz as usize];
    if c.z + rm < zlo || c.z - rm > zhi {
        return;
    }
    let xs = block_range(lattice, dims, c, rm, 0);
    let ys = block_range(lattice, dims, c, rm, 1);
    let r2 = rm * rm;
    // The squared distance to each block's box as `box_distances2` sums it, (x² + y²) + z²,
    // from the gaps per axis; a row whose y² + z² exceeds r² has no block within reach (the
    // rounded sums are monotone).
    let gz2 = gap2(c.z, sides[2][bz as usize]);
    for by in ys {
        let gy2 = gap2(c.y, sides[1][by as usize]);
        if gy2 + gz2 > r2 {
            continue;
        }
        for bx in xs.clone() {
            let gx2 = gap2(c.x, sides[0][bx as usize]);
            if (gx2 + gy2) + gz2 <= r2 {
                reached(bx + dims[0] * by);
            }
        }
    }
}

/// The lowest and highest coordinate of the blocks' boxes per axis ([`block_box`]).
fn block_sides(lattice: &Lattice, dims: [u32; 3]) -> [Vec<(f64, f64)>; 3] {
    std::array::from_fn(|a| {
        (0..dims[a])
            .map(|k| {
                let (lo, hi) = block_box(lattice, [k; 3]);
                (lo[a], hi[a])
            })
            .collect()
    })
}

/// Box of the lattice points of a block: its lowest point and its highest.
fn block_box(lattice: &Lattice, b: [u32; 3]) -> (DVec3, DVec3) {
    let step = (BLOCK_POINTS - 1) as u32;
    let last = lattice.cells();
    let lo = [b[0] * step, b[1] * step, b[2] * step];
    let hi = std::array::from_fn(|a| (lo[a] + step).min(last[a]));
    (lattice.point(lo), lattice.point(hi))
}

/// The squared gap between `c` and the interval `(lo, hi)` along one axis, as
/// [`box_distances2`] computes it (0 inside).
#[inline(always)]
fn gap2(c: f64, (lo, hi): (f64, f64)) -> f64 {
    let g = (lo - c).max(c - hi).max(0.0);
    g * g
}

/// Squared distances from `c` to the nearest and the farthest point of the box `[lo, hi]`.
#[inline(always)]
fn box_distances2(c: DVec3, lo: DVec3, hi: DVec3) -> (f64, f64) {
    let near = (lo - c).max(c - hi).max(DVec3::ZERO);
    let far = (c - lo).abs().max((hi - c).abs());
    (near.length_squared(), far.length_squared())
}

impl BlockField for BlobField {
    type Blocks = BlockLists;

    /// Lists, per block, the primitives whose sphere of influence reaches its box (with a
    /// relative margin of 1e-9 on R², so that rounding never leaves out a primitive that adds
    /// a non-zero term at one of its points). Built per z-layer of blocks in parallel, each
    /// layer from the primitives whose candidate layers hold it (`layer_candidates`).
    fn blocks(&self, lattice: &Lattice, dims: [u32; 3]) -> BlockLists {
        let mut lists = self.blocks_by_layers(lattice, dims);
        if lists.whole {
            return lists;
        }
        self.keep_layers(&mut lists, lattice, 0..dims[2]);
        lists.candidates = Default::default();
        lists
    }

    /// The candidates of each z-layer (4 bytes for each layer a primitive's sphere may reach),
    /// no lists yet.
    ///
    /// From the second call on one lattice on, the lists of every layer, kept for the next
    /// call and remade only where primitives moved far (the `kept` module).
    fn blocks_by_layers(&self, lattice: &Lattice, dims: [u32; 3]) -> BlockLists {
        if let Some((layers, hints)) = self.kept_lists(lattice, dims) {
            return BlockLists {
                dims,
                first: 0,
                layers,
                whole: true,
                candidates: Default::default(),
                hints: Some(hints),
            };
        }
        let candidates = layer_candidates(dims[2], self.centers.len(), |i| {
            block_range(lattice, dims, self.centers[i], margin(self.radii[i]), 2)
        });
        BlockLists {
            dims,
            first: 0,
            layers: Default::default(),
            whole: false,
            candidates,
            hints: None,
        }
    }

    /// Lists the blocks of `layers`, in parallel over the layers, after releasing the lists
    /// held (nothing to do when the lists hold every layer).
    fn keep_layers(&self, blocks: &mut BlockLists, lattice: &Lattice, layers: Range<u32>) {
        if blocks.whole {
            return;
        }
        blocks.layers = Default::default();
        blocks.first = layers.start;
        let dims = blocks.dims;
        let sides = block_sides(lattice, dims);
        let (start, candidates) = &blocks.candidates;
        let at = (&self.centers[..], 0.0);
        blocks.layers = Arc::new(
            layers
                .into_par_iter()
                .map(|bz| {
                    let here =
                        &candidates[start[bz as usize] as usize..start[bz as usize + 1] as usize];
                    self.layer_lists(lattice, dims, &sides, bz, here, at)
                })
                .collect(),
        );
    }

    /// Bounds F over the block from each listed primitive's nearest and farthest distance to
    /// the block's box; when the bounds leave the threshold out (by a margin of 1e-9 of the
    /// strengths' sum, far above rounding), the block has one sign.
    fn block_sign(&self, blocks: &BlockLists, lattice: &Lattice, block: &Block) -> BlockSign {
        self.block_sign_by(blocks, lattice, block, Proof::Unknown).0
    }

    /// The sign of [`BlockField::block_sign`] when it is one; otherwise splats the listed
    /// primitives row by row, with the same arithmetic and order as the dense splat. With lists
    /// kept between calls, the proof that settled the block in the last call goes first, and
    /// a block crossed then is splatted at once (the `hints` module).
    fn block_values(
        &self,
        blocks: &BlockLists,
        lattice: &Lattice,
        block: &Block,
        out: &mut [f64; 512],
    ) -> BlockSign {
        let Block { index: b, lo, n } = *block;
        let k = (b[0] + blocks.dims[0] * (b[1] + blocks.dims[1] * b[2])) as usize;
        let hint = blocks.hints.as_ref().map_or(Proof::Unknown, |h| h.get(k));
        let (sign, proof) = self.block_sign_by(blocks, lattice, block, hint);
        if sign == BlockSign::Mixed {
            let list = blocks.list(b);
            self.splat_block(Isa::detect(), list, &BlockCoords::new(lattice, lo, n), out);
        }
        if let Some(h) = &blocks.hints {
            h.set(k, splatted_proof(sign, proof, hint, || both_signs(out, n)));
        }
        sign
    }

    /// Eight points at a time over the block's list with AVX-512, four with AVX2 (the same
    /// operations in the same order as [`Field::gradient`], so the same bits).
    fn block_gradients(
        &self,
        blocks: &BlockLists,
        block: &Block,
        points: &[DVec3],
        out: &mut [DVec3],
    ) {
        let list = blocks.list(block.index);
        // A block much larger than the primitives (a coarse lattice) lists far more of them than
        // reach any one point: the voxel lists are shorter then (the same terms, the same bits),
        // when they are built (they are not built for this: at particle scale they take several
        // times the memory of the block lists).
        if list.len() > LONG_BLOCK_LIST && self.grid.get().is_some() {
            self.gradients(points, out);
            return;
        }
        self.gradients_over(Isa::detect(), list, points, out);
    }
}

/// The index range of the lattice points in `[c − r, c + r]` along an axis (origin `o`, inverse
/// cell side `inv_h`, `n` points), with a point of margin for rounding (the exact test is made
/// per point); `None` when the interval misses the lattice.
pub(crate) fn index_range(c: f64, r: f64, o: f64, inv_h: f64, n: usize) -> Option<(usize, usize)> {
    let lo = ((c - r - o) * inv_h).floor() - 1.0;
    let hi = ((c + r - o) * inv_h).ceil() + 1.0;
    if hi < 0.0 || lo > (n - 1) as f64 {
        return None;
    }
    Some((lo.max(0.0) as usize, (hi as usize).min(n - 1)))
}

#[cfg(test)]
mod tests {
    use super::super::testing::*;
    use super::*;

    #[test]
    fn inlined_floor_and_ceil_are_the_library_ones() {
        let mut xs = vec![
            0.0, -0.0, 0.5, -0.5, 1.0, -1.0, 2.5, -2.5, 1e300, -1e300, 4.5e15,
        ];
        xs.extend([
            f64::MAX,
            f64::MIN,
            4_503_599_627_370_495.5,
            -4_503_599_627_370_495.5,
        ]);
        xs.extend((0..2000).map(|k| (k as f64 - 1000.0) * 0.37 + 1e-9 * k as f64));
        for x in xs {
            assert_eq!(floor(x), x.floor(), "{x}");
            assert_eq!(ceil(x), x.ceil(), "{x}");
        }
        assert!(floor(f64::NAN).is_nan());
    }

    #[test]
    fn every_vector_path_gives_the_same_bits() {
        for kernel in BlobKernel::ALL {
            for precision in [Precision::Double, Precision::Single] {
                every_vector_path_gives_the_same_bits_with(kernel, precision);
            }
        }
    }

    fn every_vector_path_gives_the_same_bits_with(kernel: BlobKernel, precision: Precision) {
        let mut f = random_blobs_with(300, 17, kernel);
        f.set_precision(precision);
        let lattice = Lattice::new(DVec3::splat(-1.0), DVec3::splat(1.0), [37, 30, 45]).unwrap();
        let all: Vec<u32> = (0..300).collect();
        let points = random_points(23, -0.9, 0.9, 5);
        let isas = Isa::available();
        // A whole block, and blocks cut by the lattice's upper sides.
        for (lo, n) in [
            ([0, 0, 0], [8, 8, 8]),
            ([32, 24, 40], [6, 7, 6]),
            ([8, 16, 0], [8, 3, 1]),
        ] {
            let block = BlockCoords::new(&lattice, lo, n);
            let mut want = [0.0; 512];
            f.splat_block(Isa::Generic, &all, &block, &mut want);
            // The block's points (the values beyond them are not read).
            let inside: Vec<usize> = (0..512)
                .filter(|i| {
                    i % 8 < n[0] as usize && i / 8 % 8 < n[1] as usize && i / 64 < n[2] as usize
                })
                .collect();
            for &isa in &isas {
                let mut got = [1.0; 512];
                f.splat_block(isa, &all, &block, &mut got);
                assert!(
                    inside
                        .iter()
                        .all(|&i| want[i].to_bits() == got[i].to_bits()),
                    "{isa:?} {precision:?}"
                );
            }
            // The values at the block's points (single: f32 values, widened).
            let pts: Vec<DVec3> = (0..512)
                .map(|i| DVec3::new(block.xs[i % 8], block.ys[i / 8 % 8], block.zs[i / 64]))
                .collect();
            let mut v = vec![0.0; 512];
            f.values(&pts, &mut v);
            assert!(inside.iter().all(|&i| want[i].to_bits() == v[i].to_bits()));
            if precision == Precision::Single {
                assert!(want.iter().all(|w| *w as f32 as f64 == *w));
            }
        }
        let mut want = vec![DVec3::ZERO; points.len()];
        f.gradients_over(Isa::Generic, &all, &points, &mut want);
        assert!(want.iter().any(|g| *g != DVec3::ZERO));
        for &isa in &isas {
            let mut got = vec![DVec3::ONE; points.len()];
            f.gradients_over(isa, &all, &points, &mut got);
            assert_eq!(want, got, "{isa:?}");
        }
    }

    fn random_blobs(n: usize, seed: u64) -> BlobField {
        random_blobs_with(n, seed, BlobKernel::Triquet)
    }

    fn random_blobs_with(n: usize, seed: u64, kernel: BlobKernel) -> BlobField {
        let c = random_points(n, -0.8, 0.8, seed);
        let r: Vec<f64> = random_points(n, 0.1, 0.3, seed + 1)
            .iter()
            .map(|p| p.x)
            .collect();
        BlobField::new(
            &c,
            PerPrimitive::Each(&r),
            PerPrimitive::All(1.0),
            0.5,
            BlobSettings {
                kernel,
                ..Default::default()
            },
        )
        .unwrap()
    }

    #[test]
    fn voxel_evaluation_equals_brute_force() {
        for ((n, seed), kernel) in [(1, 3), (20, 5), (300, 7)]
            .into_iter()
            .flat_map(|c| BlobKernel::ALL.map(|k| (c, k)))
        {
            let b = random_blobs_with(n, seed, kernel);
            for p in random_points(2000, -1.2, 1.2, seed + 9) {
                assert!((b.potential(p) - b.potential_brute_force(p)).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn splatted_lattice_values_are_bit_identical() {
        for kernel in BlobKernel::ALL {
            for precision in [Precision::Double, Precision::Single] {
                splatted_lattice_values_are_bit_identical_with(kernel, precision);
            }
        }
    }

    fn splatted_lattice_values_are_bit_identical_with(kernel: BlobKernel, precision: Precision) {
        let mut b = random_blobs_with(120, 31, kernel);
        b.set_precision(precision);
        let l = Lattice::new(
            DVec3::new(-1.0, -0.9, -1.1),
            DVec3::new(1.1, 1.0, 0.9),
            [37, 41, 29],
        )
        .unwrap();
        let p = l.points_per_axis();
        let plane = (p[0] * p[1]) as usize;
        let mut out = vec![0.0; plane * 5];
        let mut scratch = vec![];
        b.lattice_values(&l, 10, 15, &mut scratch, &mut out);
        let mut pts = vec![];
        for z in 10..15 {
            for y in 0..p[1] {
                for x in 0..p[0] {
                    pts.push(l.point([x, y, z]));
                }
            }
        }
        let mut v = vec![0.0; pts.len()];
        b.values(&pts, &mut v);
        assert!(out.iter().zip(&v).all(|(a, b)| a.to_bits() == b.to_bits()));
    }

    #[test]
    fn gradient_bound_holds() {
        for ((n, seed), kernel) in [(1, 41), (50, 43), (400, 47)]
            .into_iter()
            .flat_map(|c| BlobKernel::ALL.map(|k| (c, k)))
        {
            let b = random_blobs_with(n, seed, kernel);
            let bound = b.gradient_bound().unwrap();
            let worst = random_points(20_000, -1.2, 1.2, seed + 1)
                .iter()
                .map(|p| b.gradient(*p).length())
                .fold(0.0, f64::max);
            assert!(
                worst > 0.0 && worst <= bound,
                "n={n}: |∇f| {worst} > bound {bound}"
            );
        }
        // One primitive: the bound is attained on the sphere d = R/√3.
        let one = BlobField::new(
            &[DVec3::ZERO],
            PerPrimitive::All(0.5),
            PerPrimitive::All(2.0),
            0.5,
            BlobSettings::default(),
        )
        .unwrap();
        let p = DVec3::new(0.5 / 3f64.sqrt(), 0.0, 0.0);
        assert!((one.gradient(p).length() - one.gradient_bound().unwrap()).abs() < 1e-12);
    }

    #[test]
    fn gradient_matches_differences() {
        for kernel in BlobKernel::ALL {
            let b = random_blobs_with(50, 11, kernel);
            let pts = random_points(300, -1.0, 1.0, 12);
            assert!(gradient_error(&b, &pts, 1e-6) < 1e-6, "{kernel:?}");
        }
    }

    /// The potential of one primitive of each profile at known distances.
    #[test]
    fn potential_follows_the_profile() {
        for kernel in BlobKernel::ALL {
            let b = BlobField::new(
                &[DVec3::new(0.1, 0.2, 0.3)],
                PerPrimitive::All(0.5),
                PerPrimitive::All(2.0),
                0.5,
                BlobSettings {
                    kernel,
                    ..Default::default()
                },
            )
            .unwrap();
            for d in [0.0, 0.1, 0.2, 0.25, 0.3, 0.49, 0.5, 0.7] {
                let p = DVec3::new(0.1, 0.2, 0.3) + DVec3::new(0.6, 0.0, 0.8) * d;
                let want = 2.0 * kernel.value(d, 0.5);
                assert!((b.potential(p) - want).abs() < 1e-12, "{kernel:?} d={d}");
            }
        }
    }

    /// Lists made a few z-layers at a time are the lists of the whole lattice, layer for
    /// layer, and only the layers asked for (and the candidates) are held.
    #[test]
    fn lists_by_layers_are_the_whole_lists() {
        let b = random_blobs(300, 5);
        let l = Lattice::new(DVec3::splat(-1.0), DVec3::splat(1.0), [45, 38, 100]).unwrap();
        let dims = crate::polygonize::sparse::block_grid(&l).dims;
        // On a clone (which keeps no lists): a second call on the same field and lattice would
        // get the kept lists of every layer.
        let whole = b.clone().blocks(&l, dims);
        assert!(whole.candidates.1.is_empty());
        let mut lists = b.blocks_by_layers(&l, dims);
        assert_eq!(lists.entries(), 0);
        for layers in [0..3, 3..4, 4..dims[2], 7..9] {
            b.keep_layers(&mut lists, &l, layers.clone());
            assert_eq!(lists.layers.len(), layers.len());
            if layers.len() == 1 {
                assert!(lists.bytes() < whole.bytes());
            }
            let mut entries = 0;
            for z in layers {
                for (x, y) in (0..dims[0]).flat_map(|x| (0..dims[1]).map(move |y| (x, y))) {
                    assert_eq!(lists.list([x, y, z]), whole.list([x, y, z]));
                    entries += whole.list([x, y, z]).len();
                }
            }
            assert!(entries > 0);
            assert_eq!(lists.entries(), entries);
        }
    }

    #[test]
    fn sparse_builds_neither_voxel_lists_nor_packed_primitives() {
        use crate::polygonize::{sparse, Settings};
        let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 40).unwrap();
        for normals in [false, true] {
            let b = random_blobs(60, 23);
            let settings = Settings {
                normals,
                ..Default::default()
            };
            let crate::polygonize::Polygonized {
                mesh: m, stats: _, ..
            } = sparse::polygonize(&b, &l, &settings).unwrap();
            assert!(!m.triangles.is_empty());
            assert_eq!(m.normals.len(), if normals { m.vertices.len() } else { 0 });
            assert!(b.grid.get().is_none() && b.packed.get().is_none());
            // Built on the first point query, the same lists as a field built with them.
            let p = DVec3::new(0.1, 0.2, 0.3);
            assert_eq!(b.potential(p), b.potential_brute_force(p));
            assert!(b.grid.get().is_some() && b.packed.get().is_some());
        }
    }

    #[test]
    fn update_moves_without_reallocating() {
        let mut b = random_blobs(200, 21);
        let before = b.grid().capacity_bytes();
        for k in 0..20 {
            let c: Vec<DVec3> = b
                .centers()
                .iter()
                .map(|p| *p + DVec3::splat(0.001 * k as f64))
                .collect();
            b.update(&c, None, None).unwrap();
        }
        // Capacity may settle after the first rebuilds but must not keep growing.
        let mid = b.grid().capacity_bytes();
        for k in 0..20 {
            let c: Vec<DVec3> = b
                .centers()
                .iter()
                .map(|p| *p - DVec3::splat(0.001 * k as f64))
                .collect();
            b.update(&c, None, None).unwrap();
        }
        assert!(b.grid().capacity_bytes() <= mid.max(before) * 2);
        for p in random_points(500, -1.0, 1.0, 2) {
            assert!((b.potential(p) - b.potential_brute_force(p)).abs() < 1e-12);
        }
    }

    #[test]
    fn bad_input_refused() {
        let c = [DVec3::ZERO];
        assert!(BlobField::new(
            &c,
            PerPrimitive::All(-1.0),
            PerPrimitive::All(1.0),
            0.5,
            BlobSettings::default()
        )
        .is_err());
        assert!(BlobField::new(
            &c,
            PerPrimitive::All(1.0),
            PerPrimitive::All(1.0),
            0.0,
            BlobSettings::default()
        )
        .is_err());
        assert!(BlobField::new(
            &c,
            PerPrimitive::Each(&[1.0, 2.0]),
            PerPrimitive::All(1.0),
            0.5,
            BlobSettings::default()
        )
        .is_err());
        assert!(BlobField::new(
            &[DVec3::NAN],
            PerPrimitive::All(1.0),
            PerPrimitive::All(1.0),
            0.5,
            BlobSettings::default()
        )
        .is_err());
    }
}
