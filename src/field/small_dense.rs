//! Dense kernels for the small systems of partition-of-unity patches (a few hundred unknowns,
//! solved one per rayon task, see [`super::saddle`]): a symmetric matrix stored as its lower
//! triangle times four columns, a rank-8 update of a lower triangle, and the two triangular
//! solves with a Cholesky factor. At these sizes a call to a general matrix library costs more
//! in dispatch and packing than these loops do in flops.
//!
//! Sums run over fixed lanes of eight partial sums, added in one fixed order, so the
//! results are the same bits on every instruction set; the loops are compiled for AVX-512 and
//! for AVX2 as well, and run so when the CPU has them.
//!
//! Matrices are column-major with leading dimension `ld`: entry (i, j) at `i + j·ld`.

/// Partial sums per dot product.
const LANES: usize = 8;

use crate::simd::Isa;

/// Runs the function `$body` of the arguments, compiled for AVX-512 or AVX2 when `$isa` is
/// one of them (which the CPU must have). The compiler does not fuse a multiplication and an
/// addition into an FMA unless asked to, so every build computes the same bits.
macro_rules! on_isa {
    ($isa:expr, fn($($arg:ident: $ty:ty),*) $body:block) => {{
        #[inline(always)]
        fn generic($($arg: $ty),*) $body
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx512f,avx2,fma")]
        unsafe fn avx512($($arg: $ty),*) {
            generic($($arg),*)
        }
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn avx2($($arg: $ty),*) {
            generic($($arg),*)
        }
        match $isa {
            // SAFETY: `Isa::Avx512` is only detected (or listed as available) on CPUs with
            // AVX-512F, AVX2 and FMA, and `Isa::Avx2` on CPUs with AVX2 and FMA.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => unsafe { avx512($($arg),*) },
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe { avx2($($arg),*) },
            Isa::Generic => generic($($arg),*),
        }
    }};
}

/// Σ x_i y_i, by lanes of partial sums.
#[inline(always)]
fn dot(x: &[f64], y: &[f64]) -> f64 {
    let m = x.len().min(y.len());
    let (x, y) = (&x[..m], &y[..m]);
    let full = m / LANES * LANES;
    let mut acc = [0.0f64; LANES];
    for (xc, yc) in x[..full]
        .chunks_exact(LANES)
        .zip(y[..full].chunks_exact(LANES))
    {
        for l in 0..LANES {
            acc[l] += xc[l] * yc[l];
        }
    }
    let mut s = acc.iter().sum::<f64>();
    for i in full..m {
        s += x[i] * y[i];
    }
    s
}

/// W = A V for the symmetric n × n matrix A given by its lower triangle (`a`, leading
/// dimension n; the strict upper triangle is not read) and V n × 4 (`v`, leading dimension n);
/// W (`w`, n × 4, leading dimension n) is overwritten.
pub fn symmetric_times_four(a: &[f64], n: usize, v: &[f64], w: &mut [f64]) {
    symmetric_times_four_on(Isa::detect(), a, n, v, w)
}

fn symmetric_times_four_on(isa: Isa, a: &[f64], n: usize, v: &[f64], w: &mut [f64]) {
    assert!(a.len() >= n * n && v.len() >= 4 * n && w.len() >= 4 * n);
    on_isa!(isa, fn(a: &[f64], n: usize, v: &[f64], w: &mut [f64]) {
        w[..4 * n].fill(0.0);
        let (w0, rest) = w.split_at_mut(n);
        let (w1, rest) = rest.split_at_mut(n);
        let (w2, w3) = rest.split_at_mut(n);
        let vk = |k: usize| &v[k * n..(k + 1) * n];
        for j in 0..n {
            // Column j at and below the diagonal: A[i, j] for i in j..n.
            let col = &a[j * n + j..(j + 1) * n];
            let m = col.len();
            // Row i > j of W gains A[i, j] V[j, k] (and row j its diagonal term) ...
            let s = [vk(0)[j], vk(1)[j], vk(2)[j], vk(3)[j]];
            let (x0, x1, x2, x3) = (
                &mut w0[j..j + m],
                &mut w1[j..j + m],
                &mut w2[j..j + m],
                &mut w3[j..j + m],
            );
            for i in 0..m {
                let c = col[i];
                x0[i] += c * s[0];
                x1[i] += c * s[1];
                x2[i] += c * s[2];
                x3[i] += c * s[3];
            }
            // ... and row j gains Σ_{i > j} A[i, j] V[i, k].
            let below = &col[1..];
            w0[j] += dot(below, &vk(0)[j + 1..]);
            w1[j] += dot(below, &vk(1)[j + 1..]);
            w2[j] += dot(below, &vk(2)[j + 1..]);
            w3[j] += dot(below, &vk(3)[j + 1..]);
        }
    })
}

/// The lower triangle of the n × n `a` (leading dimension n) minus that of L Rᵀ, for L and R
/// n × 8 (leading dimension n); the strict upper triangle is left as it is.
pub fn subtract_lower_rank8(a: &mut [f64], n: usize, left: &[f64], right: &[f64]) {
    subtract_lower_rank8_on(Isa::detect(), a, n, left, right)
}

fn subtract_lower_rank8_on(isa: Isa, a: &mut [f64], n: usize, left: &[f64], right: &[f64]) {
    assert!(a.len() >= n * n && left.len() >= 8 * n && right.len() >= 8 * n);
    on_isa!(isa, fn(a: &mut [f64], n: usize, left: &[f64], right: &[f64]) {
        for j in 0..n {
            let r: [f64; 8] = std::array::from_fn(|k| right[k * n + j]);
            let col = &mut a[j * n + j..(j + 1) * n];
            let m = col.len();
            let l: [&[f64]; 8] = std::array::from_fn(|k| &left[k * n + j..k * n + j + m]);
            for i in 0..m {
                let mut s = l[0][i] * r[0];
                s += l[1][i] * r[1];
                s += l[2][i] * r[2];
                s += l[3][i] * r[3];
                s += l[4][i] * r[4];
                s += l[5][i] * r[5];
                s += l[6][i] * r[6];
                s += l[7][i] * r[7];
                col[i] -= s;
            }
        }
    })
}

/// Solves L Lᵀ x = b in place (`x` holds b on entry), for the m × m lower triangular factor L
/// at `l` with leading dimension `ld` (its strict upper triangle is not read).
pub fn cholesky_solve(l: &[f64], ld: usize, x: &mut [f64]) {
    cholesky_solve_on(Isa::detect(), l, ld, x)
}

fn cholesky_solve_on(isa: Isa, l: &[f64], ld: usize, x: &mut [f64]) {
    let m = x.len();
    assert!(ld >= m && (m == 0 || l.len() >= (m - 1) * ld + m));
    on_isa!(isa, fn(l: &[f64], ld: usize, x: &mut [f64]) {
        let m = x.len();
        // L y = b, by columns.
        for j in 0..m {
            let col = &l[j * ld + j..j * ld + m];
            let yj = x[j] / col[0];
            x[j] = yj;
            for (xi, c) in x[j + 1..].iter_mut().zip(&col[1..]) {
                *xi -= c * yj;
            }
        }
        // Lᵀ x = y, by rows of Lᵀ (columns of L).
        for j in (0..m).rev() {
            let col = &l[j * ld + j..j * ld + m];
            let s = dot(&col[1..], &x[j + 1..]);
            x[j] = (x[j] - s) / col[0];
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn numbers(len: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..len)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect()
    }

    #[test]
    fn symmetric_times_four_reads_the_lower_triangle_as_the_whole() {
        for n in [1usize, 5, 8, 9, 17, 40] {
            let mut a = numbers(n * n, 3 + n as u64);
            // A marker in the strict upper triangle, which must not be read.
            let sym = |a: &[f64], i: usize, j: usize| a[i.max(j) + i.min(j) * n];
            let full: Vec<f64> = (0..n * n).map(|k| sym(&a, k % n, k / n)).collect();
            for j in 0..n {
                for i in 0..j {
                    a[i + j * n] = f64::NAN;
                }
            }
            let v = numbers(4 * n, 7);
            let mut w = vec![f64::NAN; 4 * n];
            symmetric_times_four(&a, n, &v, &mut w);
            for k in 0..4 {
                for i in 0..n {
                    let want: f64 = (0..n).map(|j| full[i + j * n] * v[k * n + j]).sum();
                    assert!((w[k * n + i] - want).abs() < 1e-13, "n {n} ({i}, {k})");
                }
            }
        }
    }

    #[test]
    fn subtract_lower_rank8_leaves_the_upper_triangle() {
        for n in [1usize, 6, 16, 23] {
            let a0 = numbers(n * n, 11);
            let (l, r) = (numbers(8 * n, 12), numbers(8 * n, 13));
            let mut a = a0.clone();
            subtract_lower_rank8(&mut a, n, &l, &r);
            for j in 0..n {
                for i in 0..n {
                    let want = if i >= j {
                        a0[i + j * n] - (0..8).map(|k| l[k * n + i] * r[k * n + j]).sum::<f64>()
                    } else {
                        a0[i + j * n]
                    };
                    assert!((a[i + j * n] - want).abs() < 1e-14, "n {n} ({i}, {j})");
                }
            }
        }
    }

    #[test]
    fn cholesky_solve_inverts_l_lt() {
        for m in [1usize, 3, 8, 9, 30] {
            let ld = m + 2;
            // L: a well-conditioned lower triangle, NaN above it.
            let mut l = vec![f64::NAN; ld * m];
            let vals = numbers(ld * m, 5);
            for j in 0..m {
                for i in j..m {
                    l[i + j * ld] = if i == j {
                        2.0 + vals[i + j * ld]
                    } else {
                        vals[i + j * ld]
                    };
                }
            }
            let x0 = numbers(m, 9);
            // b = L Lᵀ x0.
            let lt_x: Vec<f64> = (0..m)
                .map(|i| (i..m).map(|k| l[k + i * ld] * x0[k]).sum())
                .collect();
            let mut x: Vec<f64> = (0..m)
                .map(|i| (0..=i).map(|k| l[i + k * ld] * lt_x[k]).sum())
                .collect();
            cholesky_solve(&l, ld, &mut x);
            for i in 0..m {
                assert!((x[i] - x0[i]).abs() < 1e-12, "m {m} row {i}");
            }
        }
    }

    /// Each kernel gives the same bits on every instruction set.
    #[test]
    fn the_same_bits_on_every_instruction_set() {
        let n = 37;
        let a = numbers(n * n, 21);
        let v = numbers(8 * n, 22);
        let run = |isa: Isa| {
            let mut w = vec![0.0; 4 * n];
            symmetric_times_four_on(isa, &a, n, &v, &mut w);
            let mut b = a.clone();
            subtract_lower_rank8_on(isa, &mut b, n, &v, &w.repeat(2));
            let mut l = a.clone();
            (0..n).for_each(|i| l[i + i * n] = 3.0 + l[i + i * n].abs());
            let mut x = numbers(n, 23);
            cholesky_solve_on(isa, &l, n, &mut x);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            (bits(&w), bits(&b), bits(&x))
        };
        let generic = run(Isa::Generic);
        for isa in Isa::available() {
            assert!(run(isa) == generic, "{isa:?}");
        }
    }
}
