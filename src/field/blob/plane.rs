//! Lattice values plane by plane (the dense polygonizer's [`Field::lattice_values`](crate::field::Field::lattice_values)): every
//! primitive is splatted into the points of its sphere of influence, row by row over the x-range
//! the sphere covers ([`RowTerm`], [`splat_row`]), with the arithmetic and order of the point
//! queries, so the same bits.

use super::kernel::{with_profile, Profile, Real};
use super::point::is_triquet;
use super::{BlobField, Precision};
use crate::lattice::Lattice;
use crate::simd::Isa;
use glam::DVec3;
use rayon::prelude::*;

impl BlobField {
    /// [`Field::lattice_values`](crate::field::Field::lattice_values) of z-planes `z0..z1` into `out`, the planes in parallel.
    pub(super) fn splat_lattice(&self, lattice: &Lattice, z0: u32, z1: u32, out: &mut [f64]) {
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
    pub(super) fn splat_plane_with<T: Real>(
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
}

/// One primitive's term along one lattice row: x-centre, k = 1 − (dy² + dz²)/R², 1/R², A.
pub(super) struct RowTerm {
    pub(super) cx: f64,
    pub(super) k: f64,
    pub(super) inv: f64,
    pub(super) a: f64,
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

/// Adds the term A·w(t), t = k − dx²/R² (see [`unit_t`](super::point::unit_t)), to each value of a row (`row[i]` at
/// x = `xs[i]`). The order of operations is that of [`BlobField::potential`], without fused
/// multiply-adds, so the values are bit-identical to point evaluation.
#[inline(always)]
pub(super) fn splat_row<K: Profile>(row: &mut [f64], xs: &[f64], q: &RowTerm) {
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
    use super::*;
    use crate::field::blob::kernel::BlobKernel;
    use crate::field::Field;
    use crate::testing::sized_blobs;

    #[test]
    fn splatted_lattice_values_are_bit_identical() {
        for kernel in BlobKernel::ALL {
            for precision in [Precision::Double, Precision::Single] {
                splatted_lattice_values_are_bit_identical_with(kernel, precision);
            }
        }
    }

    fn splatted_lattice_values_are_bit_identical_with(kernel: BlobKernel, precision: Precision) {
        let mut b = sized_blobs(120, 31, kernel);
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
}
