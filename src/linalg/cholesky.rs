//! Cholesky factorization of the small dense systems of partition-of-unity patches (a few
//! hundred unknowns each, thousands per fit, one per rayon task).
//!
//! Left-looking by blocks of 8 columns: each block of columns is first updated with the
//! columns already factorized, A[j.., J] −= L[j.., ..j] L[J, ..j]ᵀ (all of the flops, in a
//! kernel that keeps a tile of the result in registers: 16 rows × 8 columns with AVX-512, 8 × 4
//! twice with AVX2 and FMA), then factorized as a narrow panel. At these sizes this is faster
//! than a general blocked factorization, whose recursion and packing cost more than the flops
//! of a 200 × 200 system. Every entry is updated by the same operations in the same order on
//! both instruction sets (one fused multiply-add per k, in increasing k, then one subtraction),
//! so the two give the same bits.

use faer::MatMut;

/// Columns per block (one broadcast per column and row of the kernel's tile).
const NB: usize = 8;
/// Largest order factorized here; larger systems go to faer's blocked factorization.
pub const MAX_ORDER: usize = 1024;

/// Factorizes in place the lower triangle of the symmetric positive definite `a` as L Lᵀ (the
/// strict upper triangle is neither read nor written). `None` when this does not apply (neither
/// AVX-512 nor AVX2 with FMA, a row stride other than 1, or an order above [`MAX_ORDER`]): the
/// caller factorizes another way. `Some(false)` when `a` is not positive definite (a pivot that
/// is not positive and finite); `a` is then partly overwritten.
pub fn factor_lower(a: MatMut<'_, f64>) -> Option<bool> {
    factor_lower_on(crate::simd::Isa::detect(), a)
}

/// [`factor_lower`] with the kernel of instruction set `isa` (which the CPU must have).
#[cfg_attr(not(target_arch = "x86_64"), allow(unused_variables))]
fn factor_lower_on(isa: crate::simd::Isa, a: MatMut<'_, f64>) -> Option<bool> {
    let m = a.nrows();
    if m != a.ncols() || m > MAX_ORDER || (m > 1 && a.row_stride() != 1) {
        return None;
    }
    if m == 0 {
        return Some(true);
    }
    let ld = if m > 1 { a.col_stride() } else { 1 };
    if ld < m as isize {
        return None;
    }
    let (p, ld) = (a.as_ptr_mut(), ld as usize);
    // SAFETY (both kernels): the CPU has the instruction set (`isa` is detected or listed as
    // available); `a` is an m × m view with unit row stride and column stride ld ≥ m, so every
    // (i, j) with i, j < m is at offset i + j·ld of `p`, and the view is borrowed mutably for
    // the call.
    match isa {
        #[cfg(target_arch = "x86_64")]
        crate::simd::Isa::Avx512 => Some(unsafe { avx512::factor(p, ld, m) }),
        #[cfg(target_arch = "x86_64")]
        crate::simd::Isa::Avx2 => Some(unsafe { avx2::factor(p, ld, m) }),
        _ => None,
    }
}

/// The left-looking factorization of the m × m matrix at `p` (column `j` at `p + j·ld`):
/// `update(i, j0, nb, pack)` subtracts from rows i..i + mr (those below m) of columns
/// j0..j0 + nb, on or below the diagonal, the products of the columns before j0, given
/// pack[k·NB + c] = L[j0 + c, k] (zero for c ≥ nb).
///
/// # Safety
/// `p`, `ld` and `m` as for `factor_lower_on`; `update` writes only that tile.
#[inline(always)]
unsafe fn by_blocks(
    p: *mut f64,
    ld: usize,
    m: usize,
    mr: usize,
    mut update: impl FnMut(usize, usize, usize, &[f64]),
) -> bool {
    let mut pack = vec![0.0f64; NB * m];
    let mut j0 = 0;
    while j0 < m {
        let nb = NB.min(m - j0);
        if j0 > 0 {
            for k in 0..j0 {
                for c in 0..NB {
                    // SAFETY: rows j0 + c < m of column k < m.
                    pack[k * NB + c] = if c < nb {
                        unsafe { *p.add(j0 + c + k * ld) }
                    } else {
                        0.0
                    };
                }
            }
            let mut i = j0;
            while i < m {
                update(i, j0, nb, &pack);
                i += mr;
            }
        }
        // SAFETY: as above.
        if !unsafe { panel(p, ld, m, j0, nb) } {
            return false;
        }
        j0 += nb;
    }
    true
}

/// Factorizes the panel of columns j0..j0 + nb (rows j0..m), already updated with the columns
/// before it; false at a pivot that is not positive and finite.
///
/// # Safety
/// As [`by_blocks`].
#[inline(always)]
unsafe fn panel(p: *mut f64, ld: usize, m: usize, j0: usize, nb: usize) -> bool {
    for c in 0..nb {
        let j = j0 + c;
        // SAFETY: column j, rows j..m, and columns j0..j (distinct, ld ≥ m apart).
        let dst = unsafe { std::slice::from_raw_parts_mut(p.add(j + j * ld), m - j) };
        for c2 in j0..j {
            let src = unsafe { std::slice::from_raw_parts(p.add(j + c2 * ld), m - j) };
            let l = src[0];
            for (d, s) in dst.iter_mut().zip(src) {
                *d -= s * l;
            }
        }
        let pivot = dst[0];
        if !(pivot > 0.0 && pivot.is_finite()) {
            return false;
        }
        let l = pivot.sqrt();
        dst[0] = l;
        let inv = 1.0 / l;
        dst[1..].iter_mut().for_each(|d| *d *= inv);
    }
    true
}

#[cfg(target_arch = "x86_64")]
mod avx512 {
    use super::NB;
    use std::arch::x86_64::*;

    /// Rows of the kernel's tile (two vectors of eight).
    const MR: usize = 16;

    /// [`super::by_blocks`] with the AVX-512 tile.
    #[target_feature(enable = "avx512f")]
    pub unsafe fn factor(p: *mut f64, ld: usize, m: usize) -> bool {
        // SAFETY: as `by_blocks`; `update_tile` writes only its tile.
        unsafe {
            super::by_blocks(p, ld, m, MR, |i, j0, nb, pack| {
                update_tile(p, ld, m, i, j0, nb, pack)
            })
        }
    }

    /// Mask of the first `n` lanes (n clamped to 0..=8).
    #[inline(always)]
    fn lanes(n: usize) -> __mmask8 {
        if n >= 8 {
            0xff
        } else {
            ((1u16 << n) - 1) as __mmask8
        }
    }

    /// A[i..i+MR, j0 + c] −= Σ_{k < j0} L[i.., k] L[j0 + c, k] for c < nb, on rows at or below the
    /// diagonal only.
    #[inline]
    #[target_feature(enable = "avx512f")]
    fn update_tile(p: *mut f64, ld: usize, m: usize, i: usize, j0: usize, nb: usize, pack: &[f64]) {
        let rows = (m - i).min(MR);
        let (m0, m1) = (lanes(rows), lanes(rows.saturating_sub(8)));
        let mut acc0 = [_mm512_setzero_pd(); NB];
        let mut acc1 = [_mm512_setzero_pd(); NB];
        for k in 0..j0 {
            // SAFETY: masked loads touch only rows i..i + rows < m of column k.
            let col = unsafe { p.add(i + k * ld) };
            let x0 = unsafe { _mm512_maskz_loadu_pd(m0, col) };
            let x1 = unsafe { _mm512_maskz_loadu_pd(m1, col.add(8)) };
            let b = &pack[k * NB..k * NB + NB];
            for c in 0..NB {
                let bc = _mm512_set1_pd(b[c]);
                acc0[c] = _mm512_fmadd_pd(x0, bc, acc0[c]);
                acc1[c] = _mm512_fmadd_pd(x1, bc, acc1[c]);
            }
        }
        for c in 0..nb {
            // Rows below the diagonal of column j0 + c: in the first tile (i = j0), rows ≥ c.
            let below = if i == j0 { !lanes(c) } else { 0xff };
            let (w0, w1) = (m0 & below, m1);
            // SAFETY: masked accesses to rows i..i + rows of column j0 + c < m.
            let col = unsafe { p.add(i + (j0 + c) * ld) };
            unsafe {
                let y0 = _mm512_maskz_loadu_pd(w0, col);
                _mm512_mask_storeu_pd(col, w0, _mm512_sub_pd(y0, acc0[c]));
                let y1 = _mm512_maskz_loadu_pd(w1, col.add(8));
                _mm512_mask_storeu_pd(col.add(8), w1, _mm512_sub_pd(y1, acc1[c]));
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::NB;
    use std::arch::x86_64::*;

    /// Vectors of four rows in the kernel's tile.
    const V: usize = 2;
    /// Rows of the kernel's tile; its columns are done four at a time.
    const MR: usize = 4 * V;
    /// Columns per pass over k (V · NC accumulators of the sixteen registers).
    const NC: usize = 4;

    /// [`super::by_blocks`] with the AVX2 tile.
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn factor(p: *mut f64, ld: usize, m: usize) -> bool {
        // SAFETY: as `by_blocks`; `update_tile` writes only its tile.
        unsafe {
            super::by_blocks(p, ld, m, MR, |i, j0, nb, pack| {
                update_tile(p, ld, m, i, j0, nb, pack)
            })
        }
    }

    /// Lanes l of a vector of four rows starting at row `first` of a tile with `lo ≤ first + l <
    /// hi`, as a mask of all-ones lanes.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn lanes(first: usize, lo: usize, hi: usize) -> __m256i {
        let row = _mm256_setr_epi64x(
            first as i64,
            first as i64 + 1,
            first as i64 + 2,
            first as i64 + 3,
        );
        let below_hi = _mm256_cmpgt_epi64(_mm256_set1_epi64x(hi as i64), row);
        let under_lo = _mm256_cmpgt_epi64(_mm256_set1_epi64x(lo as i64), row);
        _mm256_andnot_si256(under_lo, below_hi)
    }

    /// A[i..i+MR, j0 + c] −= Σ_{k < j0} L[i.., k] L[j0 + c, k] for c < nb, on rows at or below the
    /// diagonal only.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    fn update_tile(p: *mut f64, ld: usize, m: usize, i: usize, j0: usize, nb: usize, pack: &[f64]) {
        let rows = (m - i).min(MR);
        let masks: [__m256i; V] = std::array::from_fn(|v| lanes(4 * v, 0, rows));
        for c0 in (0..nb).step_by(NC) {
            let mut acc = [[_mm256_setzero_pd(); NC]; V];
            let mut step = |k: usize, x: [__m256d; V]| {
                let b = &pack[k * NB + c0..k * NB + c0 + NC];
                for c in 0..NC {
                    let bc = _mm256_set1_pd(b[c]);
                    for v in 0..V {
                        acc[v][c] = _mm256_fmadd_pd(x[v], bc, acc[v][c]);
                    }
                }
            };
            if rows == MR {
                for k in 0..j0 {
                    // SAFETY: rows i..i + MR ≤ m of column k.
                    let col = unsafe { p.add(i + k * ld) };
                    step(
                        k,
                        std::array::from_fn(|v| unsafe { _mm256_loadu_pd(col.add(4 * v)) }),
                    );
                }
            } else {
                for k in 0..j0 {
                    // SAFETY: masked loads touch only rows i..i + rows < m of column k.
                    let col = unsafe { p.add(i + k * ld) };
                    step(
                        k,
                        std::array::from_fn(|v| unsafe {
                            _mm256_maskload_pd(col.add(4 * v), masks[v])
                        }),
                    );
                }
            }
            for c in 0..NC.min(nb - c0) {
                let j = c0 + c;
                // Rows below the diagonal of column j0 + j: in the first tile (i = j0), rows ≥ j.
                let lo = if i == j0 { j } else { 0 };
                // SAFETY: masked accesses to rows i..i + rows of column j0 + j < m.
                let col = unsafe { p.add(i + (j0 + j) * ld) };
                for v in 0..V {
                    let w = lanes(4 * v, lo, rows);
                    unsafe {
                        let y = _mm256_maskload_pd(col.add(4 * v), w);
                        _mm256_maskstore_pd(col.add(4 * v), w, _mm256_sub_pd(y, acc[v][c]));
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::XorShift;
    use faer::Mat;

    /// A random symmetric positive definite matrix of order m, its lower triangle stored with
    /// column stride `ld` (and the strict upper triangle set to a marker).
    fn spd(m: usize, ld: usize, seed: u64) -> (Vec<f64>, Mat<f64>) {
        let mut rng = XorShift::new(seed);
        let mut r = || rng.uniform() - 0.5;
        let b = Mat::<f64>::from_fn(m, m, |_, _| r());
        let mut a = &b * b.transpose();
        for i in 0..m {
            a[(i, i)] += 0.1 * m as f64;
        }
        let mut store = vec![7.0; ld * m];
        for j in 0..m {
            for i in j..m {
                store[i + j * ld] = a[(i, j)];
            }
        }
        (store, a)
    }

    /// The instruction sets with a kernel here that this CPU has.
    fn kernels() -> Vec<crate::simd::Isa> {
        let isas = crate::simd::Isa::available();
        isas.into_iter()
            .filter(|&isa| isa != crate::simd::Isa::Generic)
            .collect()
    }

    #[test]
    fn factors_reproduce_the_matrix_and_leave_the_upper_triangle() {
        for isa in kernels() {
            for &m in &[
                1usize, 2, 3, 4, 5, 7, 8, 9, 12, 15, 16, 17, 31, 40, 100, 257,
            ] {
                let ld = m + 3;
                let (mut store, a) = spd(m, ld, 17 + m as u64);
                let view = MatMut::from_column_major_slice_with_stride_mut(&mut store, m, m, ld);
                assert_eq!(factor_lower_on(isa, view), Some(true), "m = {m}, {isa:?}");
                let l =
                    Mat::<f64>::from_fn(m, m, |i, j| if i >= j { store[i + j * ld] } else { 0.0 });
                let back = &l * l.transpose();
                let scale = (0..m).map(|i| a[(i, i)]).fold(0.0, f64::max);
                for j in 0..m {
                    for i in 0..m {
                        assert!(
                            (back[(i, j)] - a[(i, j)]).abs() <= 1e-13 * scale,
                            "m = {m}, {isa:?}"
                        );
                        if i < j {
                            assert_eq!(
                                store[i + j * ld],
                                7.0,
                                "upper triangle written, m = {m}, {isa:?}"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn the_same_bits_on_every_instruction_set() {
        let isas = kernels();
        for &m in &[3usize, 8, 13, 24, 61, 130] {
            let factors: Vec<Vec<f64>> = isas
                .iter()
                .map(|&isa| {
                    let (mut store, _) = spd(m, m, 5 + m as u64);
                    let view = MatMut::from_column_major_slice_mut(&mut store, m, m);
                    assert_eq!(factor_lower_on(isa, view), Some(true));
                    store
                })
                .collect();
            for (f, isa) in factors.iter().zip(&isas) {
                let same = f
                    .iter()
                    .zip(&factors[0])
                    .all(|(x, y)| x.to_bits() == y.to_bits());
                assert!(same, "m = {m}: {isa:?} differs from {:?}", isas[0]);
            }
        }
    }

    #[test]
    fn refuses_matrices_that_are_not_positive_definite() {
        for isa in kernels() {
            for &m in &[5usize, 20, 60] {
                let (mut store, _) = spd(m, m, 3);
                // A negative pivot in the middle, then NaN.
                store[(m / 2) * (m + 1)] = -1e6;
                let view = MatMut::from_column_major_slice_mut(&mut store, m, m);
                assert_eq!(factor_lower_on(isa, view), Some(false), "{isa:?}");
                let (mut store, _) = spd(m, m, 4);
                store[m - 1] = f64::NAN;
                let view = MatMut::from_column_major_slice_mut(&mut store, m, m);
                assert_eq!(factor_lower_on(isa, view), Some(false), "{isa:?}");
            }
        }
    }

    #[test]
    fn leaves_other_layouts_to_the_caller() {
        let mut store = vec![1.0; (MAX_ORDER + 1) * 2];
        let view = MatMut::from_column_major_slice_mut(&mut store, MAX_ORDER + 1, 2);
        assert_eq!(factor_lower(view), None);
        let mut store = vec![1.0; 16];
        let view = MatMut::from_column_major_slice_mut(&mut store, 4, 4);
        assert_eq!(factor_lower_on(crate::simd::Isa::Generic, view), None);
    }
}
