//! Solving the interpolation system of a variational surface,
//!
//! ```text
//! [ Φ + sI  P ] [λ]   [v]        Φ_ij = φ(|c_i − c_j|),  P = [1 x y z] (n × 4)
//! [ Pᵀ      0 ] [a] = [g]
//! ```
//!
//! The matrix is symmetric but indefinite (the zero block; Φ is only conditionally positive
//! definite), so plain Cholesky or LDLᵀ without pivoting break down on it. Two factorizations:
//!
//! - **Null-space + Cholesky** (used first). With P = QR (four Householder reflectors), the
//!   constraint Pᵀλ = g fixes the first four entries of y = Qᵀλ, and the remaining n − 4 satisfy
//!   (Q₂ᵀ(Φ + sI)Q₂) y₂ = rhs. For the kernels here Q₂ᵀΦQ₂ is positive definite — r³ and r² log r
//!   are conditionally positive definite of order 2, −r of order 1 — so Cholesky applies: half the
//!   flops of LU, no pivoting, and faer's blocked parallel LLᵀ is its fastest dense factorization.
//!   Forming Q₂ᵀΦQ₂ costs only four symmetric rank-2 updates.
//! - **Bunch–Kaufman LBLᵀ** on the whole saddle-point matrix: the standard stable factorization
//!   for symmetric indefinite systems (symmetric pivoting with 1×1 and 2×2 blocks). Used when
//!   Cholesky fails (smoothing that destroys definiteness, or rounding on near-degenerate data).

use crate::cancel;
use crate::error::Result;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt;
use faer::linalg::matmul::triangular::{self as tri, BlockStructure};
use faer::linalg::solvers::{Lblt, SolveCore};
use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::{Accum, Conj, Mat, MatMut, MatRef, Par, Side};
use glam::DVec3;
use rayon::prelude::*;
use std::cell::RefCell;

/// Columns per step of the assembly and of the blocked Cholesky factorization: the call
/// checks for interruption and reports progress (columns done) between steps.
const COLUMNS_PER_STEP: usize = 2048;

enum Factor {
    NullSpace {
        /// Householder vectors V (n × 4, column-major) and the T of Q = I − V T Vᵀ (compact WY).
        v: Vec<f64>,
        t: [[f64; 4]; 4],
        /// R of P = QR (upper triangular 4×4).
        r: [[f64; 4]; 4],
        /// First four rows of B = Qᵀ(Φ + sI)Q, column-major 4 × n.
        top: Vec<f64>,
        /// n × n column-major storage whose trailing (n − 4)² block holds the Cholesky factor L
        /// of ±B[4.., 4..] in its lower triangle.
        l: Vec<f64>,
        sign: f64,
    },
    Full(Lblt<f64>),
}

/// A factorized interpolation system, solvable for many right-hand sides.
pub struct SaddleSolver {
    n: usize,
    factor: Factor,
}

impl Drop for SaddleSolver {
    fn drop(&mut self) {
        if let Factor::NullSpace { l, .. } = &mut self.factor {
            give_back(std::mem::take(l));
        }
    }
}

/// Largest matrix (in elements) a thread keeps for its next system: 8 MiB.
const LARGEST_SPARE: usize = 1 << 20;

thread_local! {
    /// The storage of this thread's last factorized system, reused by its next one (a partition
    /// fit solves thousands of systems of a few hundred constraints on each thread).
    static SPARE: RefCell<Vec<f64>> = const { RefCell::new(Vec::new()) };
}

/// `len` zeros, in this thread's spare storage when it has some.
fn zeroed(len: usize) -> Vec<f64> {
    let mut v = SPARE.with(|s| std::mem::take(&mut *s.borrow_mut()));
    v.clear();
    v.resize(len, 0.0);
    v
}

/// Keeps `v` as this thread's spare storage unless it is larger than [`LARGEST_SPARE`] or
/// smaller than the spare already kept.
fn give_back(v: Vec<f64>) {
    if v.capacity() <= LARGEST_SPARE {
        SPARE.with(|s| {
            let mut s = s.borrow_mut();
            if v.capacity() > s.capacity() {
                *s = v;
            }
        });
    }
}

/// Calls `f(j, column j)` for the columns of the column-major `a` (`n` rows), over rayon unless
/// `par` is [`Par::Seq`].
fn for_columns(a: &mut [f64], n: usize, par: Par, f: impl Fn(usize, &mut [f64]) + Sync) {
    if matches!(par, Par::Seq) {
        a.chunks_mut(n).enumerate().for_each(|(j, c)| f(j, c));
    } else {
        a.par_chunks_mut(n).enumerate().for_each(|(j, c)| f(j, c));
    }
}

/// The entries φ(|p_i − c_j|) of the matrix Φ, column by column. A closure of r² gives them
/// as `phi(dx² + dy² + dz²)`; [`crate::field::rbf::kernel::Arithmetic`] with the arithmetic of the
/// kernel sums, so that the matrix holds the numbers evaluation gives.
pub trait Entries: Sync {
    /// `out[i]` = φ(|p_i − c|), p_i = (`xs[i]`, `ys[i]`, `zs[i]`).
    fn column(&self, xs: &[f64], ys: &[f64], zs: &[f64], c: DVec3, out: &mut [f64]);
}

impl<F: Fn(f64) -> f64 + Sync> Entries for F {
    fn column(&self, xs: &[f64], ys: &[f64], zs: &[f64], c: DVec3, out: &mut [f64]) {
        let rows = xs.iter().zip(ys).zip(zs);
        for (o, ((x, y), z)) in out.iter_mut().zip(rows) {
            let (dx, dy, dz) = (x - c.x, y - c.y, z - c.z);
            *o = self(dx * dx + dy * dy + dz * dz);
        }
    }
}

/// The lower triangle of Φ + sI, column-major, computed [`COLUMNS_PER_STEP`] columns at a time
/// (the strict upper triangle is left zero).
fn assemble(points: &[DVec3], phi: &impl Entries, smoothing: f64, par: Par) -> Result<Vec<f64>> {
    let n = points.len();
    let mut a = zeroed(n * n);
    // The coordinates by axis, so that a column's loop reads contiguous slices.
    let (xs, ys, zs): (Vec<f64>, Vec<f64>, Vec<f64>) = (
        points.iter().map(|p| p.x).collect(),
        points.iter().map(|p| p.y).collect(),
        points.iter().map(|p| p.z).collect(),
    );
    for (s, step) in a.chunks_mut(n * COLUMNS_PER_STEP).enumerate() {
        cancel::check()?;
        for_columns(step, n, par, |k, col| {
            let j = s * COLUMNS_PER_STEP + k;
            let cj = points[j];
            phi.column(&xs[j..], &ys[j..], &zs[j..], cj, &mut col[j..]);
            col[j] += smoothing;
        });
    }
    cancel::check()?;
    Ok(a)
}

/// Columns per piece of a trailing update: the factorization checks for interruption between
/// pieces, so that a step of a large system stops within about a second.
const COLUMNS_PER_UPDATE: usize = 256;

/// The lower triangle of `a −= left rightᵀ`, [`COLUMNS_PER_UPDATE`] columns at a time (the
/// diagonal block of each piece as a lower triangle, the rows below it as a rectangle), with a
/// check for interruption between pieces.
fn subtract_lower(
    mut a: MatMut<'_, f64>,
    left: MatRef<'_, f64>,
    right: MatRef<'_, f64>,
    par: Par,
) -> Result<()> {
    let r = a.nrows();
    let k = left.ncols();
    let mut c0 = 0;
    while c0 < r {
        cancel::check()?;
        let w = COLUMNS_PER_UPDATE.min(r - c0);
        let piece = a.as_mut().submatrix_mut(c0, c0, r - c0, w);
        let (diagonal, below) = piece.split_at_row_mut(w);
        let columns = right.submatrix(c0, 0, w, k).transpose();
        tri::matmul(
            diagonal,
            BlockStructure::TriangularLower,
            Accum::Add,
            left.submatrix(c0, 0, w, k),
            BlockStructure::Rectangular,
            columns,
            BlockStructure::Rectangular,
            -1.0,
            par,
        );
        faer::linalg::matmul::matmul(
            below,
            Accum::Add,
            left.submatrix(c0 + w, 0, r - c0 - w, k),
            columns,
            -1.0,
            par,
        );
        c0 += w;
    }
    Ok(())
}

/// Cholesky factorization in place of the lower triangle of `a` (faer's, which cannot be
/// stopped; systems of at most [`crate::linalg::cholesky::MAX_ORDER`] unknowns with `par` [`Par::Seq`] use
/// [`crate::linalg::cholesky`]), by blocks of [`COLUMNS_PER_STEP`] columns when `a` is larger than one block, with
/// a check for interruption between blocks and, unless `par` is [`Par::Seq`] (a fit inside
/// someone else's parallel loop, which reports its own progress), a progress report of the
/// columns done. `Ok(false)` when `a` is not positive definite.
fn cholesky_in_steps(mut a: MatMut<'_, f64>, par: Par) -> Result<bool> {
    let m = a.nrows();
    // A patch's system inside someone else's parallel loop: the small-system factorization.
    if matches!(par, Par::Seq) && m <= crate::linalg::cholesky::MAX_ORDER {
        if let Some(ok) = crate::linalg::cholesky::factor_lower(a.as_mut()) {
            return Ok(ok);
        }
    }
    let mut mem = MemBuffer::new(llt::factor::cholesky_in_place_scratch::<f64>(
        m.min(COLUMNS_PER_STEP),
        par,
        Default::default(),
    ));
    let mut k = 0;
    while k < m {
        cancel::check()?;
        let b = COLUMNS_PER_STEP.min(m - k);
        let rest = a.as_mut().submatrix_mut(k, k, m - k, m - k);
        let (l11, _, l21, a22) = rest.split_at_mut(b, b);
        let mut l11 = l11;
        if llt::factor::cholesky_in_place(
            l11.as_mut(),
            Default::default(),
            par,
            MemStack::new(&mut mem),
            Default::default(),
        )
        .is_err()
        {
            return Ok(false);
        }
        if b < m - k {
            // L₂₁ = A₂₁ L₁₁⁻ᵀ, then the trailing block's lower triangle A₂₂ −= L₂₁ L₂₁ᵀ.
            let mut l21 = l21;
            solve_lower_triangular_in_place(l11.as_ref(), l21.as_mut().transpose_mut(), par);
            subtract_lower(a22, l21.as_ref(), l21.as_ref(), par)?;
        }
        if matches!(par, Par::Seq) {
            cancel::check()?;
        } else {
            cancel::advance(b as u64)?;
        }
        k += b;
    }
    Ok(true)
}

impl SaddleSolver {
    /// Factorizes the system for `points` (already normalised). `phi` gives the kernel's
    /// entries (a function of r², see [`crate::field::rbf::kernel::RadialFn`], or [`Entries`]); `sign` is
    /// +1 for kernels conditionally positive definite of order 2 (r³, r² log r) and −1 for −r.
    pub fn new(points: &[DVec3], phi: impl Entries, smoothing: f64, sign: f64) -> Result<Self> {
        Self::with_parallelism(points, phi, smoothing, sign, faer::get_global_parallelism())
    }

    /// As [`SaddleSolver::new`], with the parallelism of the assembly and factorization:
    /// [`Par::Seq`] inside one's own rayon loops. Stops with [`crate::Error::Interrupted`] when
    /// this thread's [`cancel`] token is set.
    pub fn with_parallelism(
        points: &[DVec3],
        phi: impl Entries,
        smoothing: f64,
        sign: f64,
        par: Par,
    ) -> Result<Self> {
        let n = points.len();
        let a = assemble(points, &phi, smoothing, par)?;
        if let Some(f) = Self::null_space(points, a, sign, par)? {
            return Ok(SaddleSolver { n, factor: f });
        }
        Self::full(points, phi, smoothing, par)
    }

    /// Bunch–Kaufman LBLᵀ of the whole (n + 4) × (n + 4) saddle-point matrix: the fallback of
    /// [`SaddleSolver::with_parallelism`], and for systems whose null-space solution is not
    /// finite.
    pub fn full(points: &[DVec3], phi: impl Entries, smoothing: f64, par: Par) -> Result<Self> {
        let n = points.len();
        let a = assemble(points, &phi, smoothing, par)?;
        let m = n + 4;
        let mut full = vec![0.0f64; m * m];
        for_columns(&mut full, m, par, |j, col| {
            if j < n {
                col[..n].copy_from_slice(&a[j * n..(j + 1) * n]);
                let c = points[j];
                col[n] = 1.0;
                col[n + 1] = c.x;
                col[n + 2] = c.y;
                col[n + 3] = c.z;
            } else {
                for (i, x) in col[..n].iter_mut().enumerate() {
                    let c = points[i];
                    *x = [1.0, c.x, c.y, c.z][j - n];
                }
            }
        });
        drop(a);
        // faer's LBLᵀ constructor runs with the global parallelism whatever `par` says (it
        // takes no parallelism argument); nested in a rayon loop it joins that loop's pool.
        cancel::check()?;
        let lblt = Lblt::new(MatRef::from_column_major_slice(&full, m, m), Side::Lower);
        cancel::check()?;
        Ok(SaddleSolver {
            n,
            factor: Factor::Full(lblt),
        })
    }

    /// The null-space factorization; `Ok(None)` when it does not apply (fewer than five or
    /// coplanar points, or a trailing block that is not positive definite).
    fn null_space(
        points: &[DVec3],
        mut a: Vec<f64>,
        sign: f64,
        par: Par,
    ) -> Result<Option<Factor>> {
        let n = points.len();
        if n < 5 {
            return Ok(None);
        }
        // Householder QR of P (n × 4).
        let mut p: Vec<[f64; 4]> = points.iter().map(|c| [1.0, c.x, c.y, c.z]).collect();
        let mut v = vec![0.0; 4 * n];
        let mut tau = [0.0; 4];
        for k in 0..4 {
            let norm = (k..n).map(|i| p[i][k] * p[i][k]).sum::<f64>().sqrt();
            if norm == 0.0 {
                return Ok(None);
            }
            let alpha = if p[k][k] > 0.0 { -norm } else { norm };
            let vk = &mut v[k * n..(k + 1) * n];
            for i in k..n {
                vk[i] = p[i][k];
            }
            vk[k] -= alpha;
            let vv: f64 = vk[k..].iter().map(|x| x * x).sum();
            if vv == 0.0 {
                return Ok(None);
            }
            tau[k] = 2.0 / vv;
            for col in k..4 {
                let s: f64 = (k..n).map(|i| vk[i] * p[i][col]).sum::<f64>() * tau[k];
                for i in k..n {
                    p[i][col] -= s * vk[i];
                }
            }
        }
        let mut r = [[0.0; 4]; 4];
        for i in 0..4 {
            r[i][i..4].copy_from_slice(&p[i][i..4]);
        }
        // R must be well conditioned: otherwise the points are (nearly) coplanar.
        let rmax = (0..4).map(|i| r[i][i].abs()).fold(0.0, f64::max);
        let rmin = (0..4).map(|i| r[i][i].abs()).fold(f64::INFINITY, f64::min);
        if rmin <= 1e-10 * rmax {
            return Ok(None);
        }
        let col = |k: usize| &v[k * n..(k + 1) * n];
        // T of the compact WY form Q = H₀H₁H₂H₃ = I − V T Vᵀ (upper triangular).
        let mut t = [[0.0; 4]; 4];
        for k in 0..4 {
            t[k][k] = tau[k];
            let vtv: Vec<f64> = (0..k)
                .map(|j| col(j).iter().zip(col(k)).map(|(a, b)| a * b).sum())
                .collect();
            for i in 0..k {
                t[i][k] = -tau[k] * (i..k).map(|j| t[i][j] * vtv[j]).sum::<f64>();
            }
        }
        // QᵀAQ = A − V Zᵀ − Z Vᵀ with W = AV, S = Tᵀ(VᵀW)T, Z = WT − ½VS: one pass to read A
        // (W) and one to update it.
        // W = AV, with A symmetric and stored as its lower triangle L: W = LV + (L − D)ᵀV.
        let small = matches!(par, Par::Seq) && n <= crate::linalg::cholesky::MAX_ORDER;
        let mut wcols = vec![0.0; 4 * n];
        let vm = MatRef::from_column_major_slice(&v, n, 4);
        cancel::check()?;
        if small {
            crate::linalg::small_dense::symmetric_times_four(&a, n, &v, &mut wcols);
        } else {
            let mut wm = MatMut::from_column_major_slice_mut(&mut wcols, n, 4);
            let lower = MatRef::from_column_major_slice(&a, n, n);
            tri::matmul(
                wm.as_mut(),
                BlockStructure::Rectangular,
                Accum::Replace,
                lower,
                BlockStructure::TriangularLower,
                vm,
                BlockStructure::Rectangular,
                1.0,
                par,
            );
            tri::matmul(
                wm.as_mut(),
                BlockStructure::Rectangular,
                Accum::Add,
                lower.transpose(),
                BlockStructure::StrictTriangularUpper,
                vm,
                BlockStructure::Rectangular,
                1.0,
                par,
            );
        }
        let wcol = |k: usize| &wcols[k * n..(k + 1) * n];
        let mut m = [[0.0; 4]; 4];
        for i in 0..4 {
            for j in 0..4 {
                m[i][j] = col(i).iter().zip(wcol(j)).map(|(x, y)| x * y).sum();
            }
        }
        let mul = |x: &[[f64; 4]; 4], y: &[[f64; 4]; 4]| {
            let mut o = [[0.0; 4]; 4];
            for i in 0..4 {
                for j in 0..4 {
                    o[i][j] = (0..4).map(|k| x[i][k] * y[k][j]).sum();
                }
            }
            o
        };
        let tt = {
            let mut o = [[0.0; 4]; 4];
            for i in 0..4 {
                for j in 0..4 {
                    o[i][j] = t[j][i];
                }
            }
            o
        };
        let smat = mul(&tt, &mul(&m, &t));
        // left = [V Z] and right = [Z V] (n × 8, column-major), Z = WT − ½VS.
        let mut left = vec![0.0; 8 * n];
        left[..4 * n].copy_from_slice(&v);
        for j in 0..4 {
            let zj = &mut left[(4 + j) * n..(5 + j) * n];
            for (k, (wk, vk)) in (0..4).map(|k| (wcol(k), col(k))).enumerate() {
                let (tk, sk) = (t[k][j], -0.5 * smat[k][j]);
                for ((z, w), v) in zj.iter_mut().zip(wk).zip(vk) {
                    *z += w * tk + v * sk;
                }
            }
        }
        let mut right = vec![0.0; 8 * n];
        right[..4 * n].copy_from_slice(&left[4 * n..]);
        right[4 * n..].copy_from_slice(&v);
        // The lower triangle of A − [V Z][Z V]ᵀ, the only part read afterwards.
        if small {
            crate::linalg::small_dense::subtract_lower_rank8(&mut a, n, &left, &right);
        } else {
            subtract_lower(
                MatMut::from_column_major_slice_mut(&mut a, n, n),
                MatRef::from_column_major_slice(&left, n, 8),
                MatRef::from_column_major_slice(&right, n, 8),
                par,
            )?;
        }
        // The trailing block (rows and columns from 4 on) changes sign for sign < 0.
        if sign < 0.0 {
            for_columns(&mut a[4 * n..], n, par, |k, c| {
                c[k + 4..].iter_mut().for_each(|x| *x = -*x)
            });
        }
        // The first four rows of the symmetric result, read from its first four columns.
        let top: Vec<f64> = (0..n)
            .flat_map(|j| (0..4).map(move |i| (i, j)))
            .map(|(i, j)| if j >= i { a[i * n + j] } else { a[j * n + i] })
            .collect();
        // In-place Cholesky of the trailing block (its lower triangle).
        let mm = n - 4;
        let block = MatMut::from_column_major_slice_mut(&mut a, n, n).submatrix_mut(4, 4, mm, mm);
        if !cholesky_in_steps(block, par)? {
            return Ok(None);
        }
        Ok(Some(Factor::NullSpace {
            v,
            t,
            r,
            top,
            l: a,
            sign,
        }))
    }

    /// Which factorization is in use: `"cholesky"` (null space) or `"lblt"`.
    pub fn method(&self) -> &'static str {
        match self.factor {
            Factor::NullSpace { .. } => "cholesky",
            Factor::Full(_) => "lblt",
        }
    }

    /// Solves for right-hand side (`f`: n values, `g`: 4 orthogonality values); returns (λ, a).
    pub fn solve(&self, f: &[f64], g: [f64; 4]) -> (Vec<f64>, [f64; 4]) {
        let n = self.n;
        match &self.factor {
            Factor::Full(lblt) => {
                let mut x = Mat::<f64>::zeros(n + 4, 1);
                for i in 0..n {
                    x[(i, 0)] = f[i];
                }
                for k in 0..4 {
                    x[(n + k, 0)] = g[k];
                }
                lblt.solve_in_place_with_conj(Conj::No, x.as_mut());
                let lam = (0..n).map(|i| x[(i, 0)]).collect();
                (
                    lam,
                    [x[(n, 0)], x[(n + 1, 0)], x[(n + 2, 0)], x[(n + 3, 0)]],
                )
            }
            Factor::NullSpace {
                v,
                t,
                r,
                top,
                l,
                sign,
            } => {
                let col = |k: usize| &v[k * n..(k + 1) * n];
                let vt_x = |x: &[f64]| -> [f64; 4] {
                    let mut o = [0.0; 4];
                    for (k, ok) in o.iter_mut().enumerate() {
                        *ok = col(k).iter().zip(x).map(|(a, b)| a * b).sum();
                    }
                    o
                };
                // Qᵀf = f − V Tᵀ (Vᵀ f).
                let mut qf = f.to_vec();
                let vf = vt_x(f);
                let c: [f64; 4] = std::array::from_fn(|j| (0..4).map(|k| t[k][j] * vf[k]).sum());
                for (q, x) in qf.iter_mut().enumerate() {
                    *x -= (0..4).map(|k| col(k)[q] * c[k]).sum::<f64>();
                }
                // Rᵀ y₁ = g (forward substitution; Rᵀ is lower triangular).
                let mut y1 = [0.0; 4];
                for i in 0..4 {
                    let s: f64 = (0..i).map(|k| r[k][i] * y1[k]).sum();
                    y1[i] = (g[i] - s) / r[i][i];
                }
                // B₂₂ y₂ = (Qᵀf)[4..] − B₂₁ y₁, with B₂₁ = B₁₂ᵀ (the top rows' tail).
                let mut y = vec![0.0; n];
                y[..4].copy_from_slice(&y1);
                for j in 4..n {
                    let cj = &top[j * 4..(j + 1) * 4];
                    let b21y1: f64 = (0..4).map(|k| cj[k] * y1[k]).sum();
                    y[j] = sign * (qf[j] - b21y1);
                }
                // The factor of the trailing block starts at (4, 4).
                crate::linalg::small_dense::cholesky_solve(&l[4 * n + 4..], n, &mut y[4..]);
                // R a = (Qᵀf)[..4] − B₁₁ y₁ − B₁₂ y₂ (back substitution).
                let mut tv = [0.0; 4];
                for (i, ti) in tv.iter_mut().enumerate() {
                    let by: f64 = (0..n).map(|j| top[j * 4 + i] * y[j]).sum();
                    *ti = qf[i] - by;
                }
                let mut a = [0.0; 4];
                for i in (0..4).rev() {
                    let s: f64 = (i + 1..4).map(|k| r[i][k] * a[k]).sum();
                    a[i] = (tv[i] - s) / r[i][i];
                }
                // λ = Q y = y − V T (Vᵀ y).
                let vy = vt_x(&y);
                let c: [f64; 4] = std::array::from_fn(|i| (0..4).map(|k| t[i][k] * vy[k]).sum());
                let lam = (0..n)
                    .map(|q| y[q] - (0..4).map(|k| col(k)[q] * c[k]).sum::<f64>())
                    .collect();
                (lam, a)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::random_points;

    fn check(points: &[DVec3], phi_r2: fn(f64) -> f64, smoothing: f64, sign: f64, expect: &str) {
        let s = SaddleSolver::new(points, phi_r2, smoothing, sign).unwrap();
        assert_eq!(s.method(), expect);
        let n = points.len();
        let f: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let g = [0.1, -0.2, 0.3, 0.05];
        let (lam, a) = s.solve(&f, g);
        for i in 0..n {
            let c = points[i];
            let row: f64 = (0..n)
                .map(|j| phi_r2((c - points[j]).length_squared()) * lam[j])
                .sum::<f64>()
                + smoothing * lam[i]
                + a[0]
                + a[1] * c.x
                + a[2] * c.y
                + a[3] * c.z;
            assert!((row - f[i]).abs() < 1e-8, "row {i}: {row} vs {}", f[i]);
        }
        let sums = [
            lam.iter().sum::<f64>(),
            lam.iter().zip(points).map(|(l, c)| l * c.x).sum(),
            lam.iter().zip(points).map(|(l, c)| l * c.y).sum(),
            lam.iter().zip(points).map(|(l, c)| l * c.z).sum(),
        ];
        for k in 0..4 {
            assert!((sums[k] - g[k]).abs() < 1e-8);
        }
    }

    #[test]
    fn null_space_cholesky_solves_the_saddle_system() {
        let p = random_points(120, -1.0, 1.0, 11);
        check(&p, |r2| r2 * r2.sqrt(), 0.0, 1.0, "cholesky");
        check(&p, f64::sqrt, 0.0, -1.0, "cholesky");
        check(
            &p,
            |r2| if r2 > 0.0 { 0.5 * r2 * r2.ln() } else { 0.0 },
            0.0,
            1.0,
            "cholesky",
        );
        check(&p, |r2| r2 * r2.sqrt(), 0.01, 1.0, "cholesky");
    }

    #[test]
    fn falls_back_to_lblt_when_not_definite() {
        let p = random_points(60, -1.0, 1.0, 5);
        // Wrong sign: −r³ on the null space is negative definite, so Cholesky fails.
        check(&p, |r2| -r2 * r2.sqrt(), 0.0, 1.0, "lblt");
    }

    /// Above one block of columns the factorization runs in steps; it solves the system as the
    /// single call does (the residual check above), and the steps' factor equals the single
    /// call's to rounding.
    #[test]
    fn cholesky_in_steps_solves_large_systems() {
        let p = random_points(COLUMNS_PER_STEP + 300, -1.0, 1.0, 3);
        // Smoothed: well conditioned at this size, so the residual check is about the steps.
        check(&p, |r2| r2 * r2.sqrt(), 0.01, 1.0, "cholesky");
        let m = 2 * COLUMNS_PER_STEP + 77;
        let b = Mat::<f64>::from_fn(m, m, |i, j| ((i * 7 + j * 13) % 17) as f64 / 17.0 - 0.5);
        let spd = &b * b.transpose() + Mat::<f64>::identity(m, m) * (m as f64);
        let mut whole = spd.clone();
        let mut mem = MemBuffer::new(llt::factor::cholesky_in_place_scratch::<f64>(
            m,
            Par::Seq,
            Default::default(),
        ));
        llt::factor::cholesky_in_place(
            whole.as_mut(),
            Default::default(),
            Par::Seq,
            MemStack::new(&mut mem),
            Default::default(),
        )
        .unwrap();
        let mut steps = spd.clone();
        assert!(cholesky_in_steps(steps.as_mut(), Par::rayon(2)).unwrap());
        for j in 0..m {
            for i in j..m {
                let (x, y) = (whole[(i, j)], steps[(i, j)]);
                assert!(
                    (x - y).abs() <= 1e-12 * whole[(j, j)].abs(),
                    "({i}, {j}): {x} vs {y}"
                );
            }
        }
        let mut indefinite = spd.clone();
        indefinite[(m - 1, m - 1)] = -1e9;
        assert!(!cholesky_in_steps(indefinite.as_mut(), Par::Seq).unwrap());
    }

    /// A set token stops the factorization between steps.
    #[test]
    fn stops_when_told() {
        let p = random_points(COLUMNS_PER_STEP + 300, -1.0, 1.0, 3);
        let t = cancel::Token::new();
        t.stop();
        let r = cancel::run_under(t, || {
            SaddleSolver::new(&p, |r2: f64| r2 * r2.sqrt(), 0.0, 1.0)
        });
        assert!(matches!(r, Err(crate::Error::Interrupted)));
    }
}
