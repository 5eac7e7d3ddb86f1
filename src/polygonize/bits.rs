//! Sign bits of lattice points, and the bit tricks the polygonizers share.
//!
//! A row of lattice points is a bit set, bit `i` set when point `i` is inside (its value is
//! negative). A block of the sparse polygonizer and of tracking block by block holds 8³
//! points as eight 64-bit plane words, one per z-plane, bit `i + 8j` for point `(i, j)`:
//! shifting a plane word by 1 moves to the next point along x, by 8 along y. Cells and edges
//! are found a word at a time: a cell is crossed when its corners' bits are neither all clear
//! nor all set ([`mixed`]), an edge when its ends' bits differ.

/// Bits of a plane word at x = 0 (one per row).
pub(crate) const COLUMN_0: u64 = 0x0101_0101_0101_0101;
/// Bits of a plane word at y = 0.
pub(crate) const ROW_0: u64 = 0xff;
/// Every cell of a block, as plane words.
pub(crate) const ALL_CELLS: [u64; 8] = [!0; 8];

/// Bits `i + 8j` for `i < x` and `j < y` (a block's 8 × 8 plane).
#[inline]
pub(crate) fn plane_mask(x: u32, y: u32) -> u64 {
    let row = if x >= 8 { 0xff } else { (1u64 << x) - 1 };
    (0..y.min(8)).fold(0, |m, j| m | row << (8 * j))
}

/// The bits set in some of `words` and clear in others.
#[inline(always)]
pub(crate) fn mixed<const N: usize>(words: [u64; N]) -> u64 {
    let (mut any, mut all) = (0u64, !0u64);
    for w in words {
        any |= w;
        all &= w;
    }
    any & !all
}

/// The cells of the layer between plane words `lo` and `hi` whose corners have both signs
/// (bit `i + 8j` for the cell with lower corner (i, j); bits beyond the block's cells are to be
/// masked off).
#[inline(always)]
pub(crate) fn crossed_layer_cells(lo: u64, hi: u64) -> u64 {
    mixed([lo, lo >> 1, lo >> 8, lo >> 9, hi, hi >> 1, hi >> 8, hi >> 9])
}

/// The edges along `axis` from the points of plane `k` of `planes` whose ends differ in sign
/// (bit `i + 8j` for the edge from point (i, j)); along z, `k` must not be the last plane.
/// Bits beyond the block's edges are to be masked off.
#[inline(always)]
pub(crate) fn crossed_edges(planes: &[u64; 8], k: usize, axis: usize) -> u64 {
    let w = planes[k];
    match axis {
        0 => w ^ (w >> 1),
        1 => w ^ (w >> 8),
        _ => w ^ planes[k + 1],
    }
}

/// Calls `f(cell, case)` for each crossed cell in `reach` (bit `i + 8j` of word `k` for cell
/// (i, j, k)) of a block with `signs` and `n` points per axis (`cell` = x + 8y + 64z of its
/// lower corner), eight cells of a row at a time.
#[inline(always)]
pub(crate) fn crossed_cells(
    signs: &[u64; 8],
    n: [u8; 3],
    reach: &[u64; 8],
    mut f: impl FnMut(usize, usize),
) {
    let cells = plane_mask(n[0] as u32 - 1, n[1] as u32 - 1);
    for k in 0..n[2] as usize - 1 {
        let (lo, hi) = (signs[k], signs[k + 1]);
        for_each_set_bit(crossed_layer_cells(lo, hi) & cells & reach[k], |c| {
            let case = (((lo >> c) & 3)
                | ((lo >> (c + 8)) & 3) << 2
                | ((hi >> c) & 3) << 4
                | ((hi >> (c + 8)) & 3) << 6) as usize;
            f(64 * k + c as usize, case);
        });
    }
}

/// Calls `f(i)` for every set bit `i` of `m`, lowest first.
#[inline(always)]
pub(crate) fn for_each_set_bit(mut m: u64, mut f: impl FnMut(u32)) {
    while m != 0 {
        f(m.trailing_zeros());
        m &= m - 1;
    }
}

/// The set bits of `m`, lowest first: [`for_each_set_bit`] as an iterator.
#[inline]
pub(crate) fn set_bits(m: impl Into<u64>) -> impl Iterator<Item = usize> {
    let mut m = m.into();
    std::iter::from_fn(move || {
        (m != 0).then(|| {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            i
        })
    })
}

/// The sign word of up to 64 values: bit `i` set when `values[i] < 0` (NaN is never inside).
#[inline(always)]
pub(crate) fn sign_word(values: &[f64]) -> u64 {
    let mut w = 0u64;
    for (b, v) in values.iter().enumerate() {
        w |= ((*v < 0.0) as u64) << b;
    }
    w
}

/// The plane words of a block's `values` (point (i, j, k) at `i + 8j + 64k`): bit `i + 8j` of
/// word `k` set when the value is negative, for the first `planes` planes.
#[inline]
pub(crate) fn plane_words(values: &[f64; 512], planes: usize) -> [u64; 8] {
    plane_words_with(crate::simd::Isa::detect(), values, planes)
}

/// [`plane_words`] with the vector path of `isa`, which the CPU must have.
#[inline]
fn plane_words_with(isa: crate::simd::Isa, values: &[f64; 512], planes: usize) -> [u64; 8] {
    #[cfg(target_arch = "x86_64")]
    match isa {
        // SAFETY: the caller passes an instruction set the CPU has.
        crate::simd::Isa::Avx512 => return unsafe { plane_words_avx512(values, planes) },
        // SAFETY: as above.
        crate::simd::Isa::Avx2 => return unsafe { plane_words_avx2(values, planes) },
        crate::simd::Isa::Generic => {}
    }
    let _ = isa; // (only x86-64 has vector paths)
    let mut signs = [0u64; 8];
    for (k, s) in signs.iter_mut().enumerate().take(planes) {
        for (j, row) in values[64 * k..64 * k + 64].chunks_exact(8).enumerate() {
            *s |= sign_word(row) << (8 * j);
        }
    }
    signs
}

/// [`plane_words`] `V::LANES` values at a time.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn plane_words_lanes<V: crate::simd::lanes::F64s>(
    values: &[f64; 512],
    planes: usize,
) -> [u64; 8] {
    let zero = unsafe { V::splat(0.0) };
    let mut signs = [0u64; 8];
    for (k, s) in signs.iter_mut().enumerate().take(planes) {
        for (q, v) in values[64 * k..64 * k + 64]
            .chunks_exact(V::LANES)
            .enumerate()
        {
            // SAFETY: the caller runs where V's feature is; a chunk holds V::LANES values.
            let m = unsafe { V::load(v).lt(zero) } as u64;
            *s |= m << (V::LANES * q);
        }
    }
    signs
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn plane_words_avx512(values: &[f64; 512], planes: usize) -> [u64; 8] {
    // SAFETY: AVX-512F is enabled here.
    unsafe { plane_words_lanes::<std::arch::x86_64::__m512d>(values, planes) }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn plane_words_avx2(values: &[f64; 512], planes: usize) -> [u64; 8] {
    // SAFETY: AVX2 is enabled here.
    unsafe { plane_words_lanes::<std::arch::x86_64::__m256d>(values, planes) }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every vector path gives the plain loop's plane words.
    #[test]
    fn plane_words_agree_on_every_vector_path() {
        let mut values = [0.0; 512];
        for (i, v) in values.iter_mut().enumerate() {
            // Negative, positive, ±0 and NaN (never inside) in an irregular pattern.
            *v = match (i * 7919) % 11 {
                0 => -0.0,
                1 => 0.0,
                2 => f64::NAN,
                k => (k as f64 - 6.5) * (1.0 + i as f64),
            };
        }
        for planes in [0, 1, 5, 8] {
            let want = plane_words_with(crate::simd::Isa::Generic, &values, planes);
            assert_eq!(want[planes..], [0; 8][planes..]);
            assert!(planes == 0 || want[0] != 0);
            for isa in crate::simd::Isa::available() {
                assert_eq!(plane_words_with(isa, &values, planes), want, "{isa:?}");
            }
        }
    }

    #[test]
    fn set_bits_come_lowest_first() {
        let mut seen = vec![];
        for_each_set_bit(0x8000_0000_0000_0105, |b| seen.push(b));
        assert_eq!(seen, [0, 2, 8, 63]);
    }
}
