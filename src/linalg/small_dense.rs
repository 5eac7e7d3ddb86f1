//! Dense kernels for the small systems of partition-of-unity patches (a few hundred unknowns,
//! solved one per rayon task, see [`crate::linalg::saddle`]): a symmetric matrix stored as its lower
//! triangle times four columns, a rank-8 update of a lower triangle, and the two triangular
//! solves with a Cholesky factor. At these sizes a call to a general matrix library costs more
//! in dispatch and packing than these loops do in flops. The product and the update take two
//! columns per pass over the rows, so that each row's loads serve both columns.
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
        let mut w = [w0, w1, w2, w3];
        let v: [&[f64]; 4] = std::array::from_fn(|k| &v[k * n..(k + 1) * n]);
        // Columns j and j + 1 at once: one pass over the rows below both adds their terms
        // to those rows of W and gathers the rows' terms of W's rows j and j + 1.
        let mut j = 0;
        while j + 1 < n {
            let c0 = &a[j * n + j..(j + 1) * n];
            let c1 = &a[(j + 1) * n + j + 1..(j + 2) * n];
            let s0: [f64; 4] = std::array::from_fn(|k| v[k][j]);
            let s1: [f64; 4] = std::array::from_fn(|k| v[k][j + 1]);
            // The 2 × 2 diagonal block.
            for k in 0..4 {
                w[k][j] += c0[0] * s0[k] + c0[1] * s1[k];
                w[k][j + 1] += c0[1] * s0[k] + c1[0] * s1[k];
            }
            // Rows j + 2.. : A[i, j] and A[i, j + 1].
            let (x0, x1) = (&c0[2..], &c1[1..]);
            let m = x0.len();
            let below = j + 2;
            let full = m / LANES * LANES;
            let mut d0 = [[0.0f64; LANES]; 4];
            let mut d1 = [[0.0f64; LANES]; 4];
            {
                let [wa, wb, wc, wd] = &mut w;
                let (wa, wb) = (&mut wa[below..below + m], &mut wb[below..below + m]);
                let (wc, wd) = (&mut wc[below..below + m], &mut wd[below..below + m]);
                let vr: [&[f64]; 4] = std::array::from_fn(|k| &v[k][below..below + m]);
                for t in (0..full).step_by(LANES) {
                    let a0: [f64; LANES] = x0[t..t + LANES].try_into().unwrap();
                    let a1: [f64; LANES] = x1[t..t + LANES].try_into().unwrap();
                    for (k, wk) in [&mut *wa, &mut *wb, &mut *wc, &mut *wd].into_iter().enumerate() {
                        let vk: [f64; LANES] = vr[k][t..t + LANES].try_into().unwrap();
                        let wk: &mut [f64; LANES] = (&mut wk[t..t + LANES]).try_into().unwrap();
                        for l in 0..LANES {
                            wk[l] += a0[l] * s0[k] + a1[l] * s1[k];
                            d0[k][l] += a0[l] * vk[l];
                            d1[k][l] += a1[l] * vk[l];
                        }
                    }
                }
            }
            for k in 0..4 {
                let (wk, vk) = (&mut w[k][below..below + m], &v[k][below..below + m]);
                let (sk0, sk1) = (s0[k], s1[k]);
                let mut e0 = d0[k].iter().sum::<f64>();
                let mut e1 = d1[k].iter().sum::<f64>();
                for i in full..m {
                    let (a0, a1, vi) = (x0[i], x1[i], vk[i]);
                    wk[i] += a0 * sk0 + a1 * sk1;
                    e0 += a0 * vi;
                    e1 += a1 * vi;
                }
                w[k][j] += e0;
                w[k][j + 1] += e1;
            }
            j += 2;
        }
        if j < n {
            for k in 0..4 {
                w[k][j] += a[j * n + j] * v[k][j];
            }
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
        let l: [&[f64]; 8] = std::array::from_fn(|k| &left[k * n..(k + 1) * n]);
        // Σ_k L[i, k] R[j, k], in increasing k.
        let term = |i: usize, r: &[f64; 8]| {
            let mut s = l[0][i] * r[0];
            for k in 1..8 {
                s += l[k][i] * r[k];
            }
            s
        };
        // Columns j and j + 1 at once: each row's eight entries of L are read once for both.
        let mut j = 0;
        while j < n {
            let r0: [f64; 8] = std::array::from_fn(|k| right[k * n + j]);
            if j + 1 == n {
                a[j * n + j] -= term(j, &r0);
                break;
            }
            let r1: [f64; 8] = std::array::from_fn(|k| right[k * n + j + 1]);
            let (first, second) = a[j * n..(j + 2) * n].split_at_mut(n);
            first[j] -= term(j, &r0);
            // Rows j + 1.. of both columns.
            let (c0, c1) = (&mut first[j + 1..], &mut second[j + 1..]);
            let m = c0.len();
            let lr: [&[f64]; 8] = std::array::from_fn(|k| &l[k][j + 1..j + 1 + m]);
            for i in 0..m {
                let x: [f64; 8] = std::array::from_fn(|k| lr[k][i]);
                let mut s0 = x[0] * r0[0];
                let mut s1 = x[0] * r1[0];
                for k in 1..8 {
                    s0 += x[k] * r0[k];
                    s1 += x[k] * r1[k];
                }
                c0[i] -= s0;
                c1[i] -= s1;
            }
            j += 2;
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
    use crate::testing::XorShift;

    fn numbers(len: usize, seed: u64) -> Vec<f64> {
        let mut rng = XorShift::new(seed);
        (0..len).map(|_| rng.uniform() - 0.5).collect()
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
