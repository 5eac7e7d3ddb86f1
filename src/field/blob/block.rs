//! Values of one block of 8³ lattice points ([`BlockField::block_values`](crate::field::BlockField::block_values) once the block may be
//! crossed): the primitives of the block's list splatted row by row, only into the rows their
//! sphere reaches, with the arithmetic and order of the point queries on every vector path
//! (scalar, AVX2, AVX-512), so the same bits.

#[cfg(target_arch = "x86_64")]
use super::kernel::LaneProfile;
use super::kernel::{with_profile, Profile, Real};
use super::lists::{ceil, floor};
use super::point::is_triquet;
use super::{BlobField, Precision};
use crate::field::BLOCK_POINTS;
use crate::lattice::Lattice;
#[cfg(target_arch = "x86_64")]
use crate::simd::lanes::Lanes;
use crate::simd::Isa;
use glam::DVec3;

/// The lattice coordinates of a block's points per axis, and its points per axis.
pub(super) struct BlockCoords {
    pub(super) xs: [f64; BLOCK_POINTS],
    pub(super) ys: [f64; BLOCK_POINTS],
    pub(super) zs: [f64; BLOCK_POINTS],
    pub(super) n: [u32; 3],
    /// 1 / the lattice's cell side per axis.
    pub(super) inv_h: [f64; 3],
}

impl BlockCoords {
    /// The block of `n` points per axis from lattice point `lo`, its coordinates exactly as
    /// [`Lattice::point`] computes them (repeating the last point up to eight).
    pub(super) fn new(lattice: &Lattice, lo: [u32; 3], n: [u32; 3]) -> BlockCoords {
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
    pub(super) fn planes(&self, cz: f64, r: f64) -> std::ops::Range<usize> {
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
    /// Fills a block's values (see [`BlockField::block_values`](crate::field::BlockField::block_values)) from the primitives of `list`
    /// with the vector path of `isa` (which the CPU must have): the same bits on every path.
    pub(super) fn splat_block(
        &self,
        isa: Isa,
        list: &[u32],
        block: &BlockCoords,
        out: &mut [f64; 512],
    ) {
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

    /// Fills a block of values (see [`BlockField::block_values`](crate::field::BlockField::block_values)) by splatting the primitives of
    /// `list` row by row: the dense splat's arithmetic and order, so the same bits. Rows are
    /// always eight wide (lanes beyond the lattice repeat its last point and are never read);
    /// `row_fn` adds one primitive's terms to a row from dx²/R² per lane (computed once per
    /// primitive), the row's k = 1 − (dy² + dz²)/R² and A (see [`unit_t`](super::point::unit_t) and [`Profile::value`]).
    ///
    /// In f32 (`T`), each of dx²/R², k and A is computed in f64 and rounded to f32, then t and
    /// the term in f32 ([`single::term`](super::single::term)).
    #[inline(always)]
    pub(super) fn splat_block_with<T: Real>(
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
    /// [`unit_t`](super::point::unit_t) and [`Profile::value`], in the same order, so the same bits.
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

    /// [`BlobField::splat_block_avx512`] for AVX2: each row of eight as two vectors of four. The
    /// same operations on each value as [`unit_t`](super::point::unit_t) and [`Profile::value`], in the same order, so the same bits.
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
    pub(super) unsafe fn splat_block_lanes_avx2<K: LaneProfile, V: Lanes>(
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
    pub(super) fn splat_block_generic<K: Profile, T: Real>(
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::blob::kernel::BlobKernel;
    use crate::field::Field;
    use crate::testing::{random_points, sized_blobs};

    #[test]
    fn every_vector_path_gives_the_same_bits() {
        for kernel in BlobKernel::ALL {
            for precision in [Precision::Double, Precision::Single] {
                every_vector_path_gives_the_same_bits_with(kernel, precision);
            }
        }
    }

    fn every_vector_path_gives_the_same_bits_with(kernel: BlobKernel, precision: Precision) {
        let mut f = sized_blobs(300, 17, kernel);
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
}
