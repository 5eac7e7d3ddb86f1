//! Radial basis functions φ(r) of the variational surfaces, and the vectorised sums over centres
//! that the evaluation spends its time in.
//!
//! The sums process blocks of [`LANES`] points against all centres, with the centres stored as
//! separate x, y, z and weight arrays: the inner update is independent per lane, so the compiler
//! turns it into SIMD instructions. On x86-64 the block loop is compiled a second time with AVX2 +
//! FMA enabled and chosen at run time when the CPU has them.

use crate::error::{Error, Result};

/// Points processed together by the vectorised sums.
pub const LANES: usize = 8;
/// Lanes the gradient sums process together.
const HALF: usize = LANES / 2;

/// The radial basis function of a variational surface.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Hash)]
pub enum Kernel {
    /// φ(r) = r³, the triharmonic spline of Turk & O'Brien (default). Minimises the energy of
    /// Cuno eq. (1) in 3-D together with a linear polynomial.
    #[default]
    Triharmonic,
    /// φ(r) = r, the biharmonic spline (Carr et al.); smoother far field, sharper near centres.
    Biharmonic,
    /// φ(r) = r² log r, the thin-plate spline.
    ThinPlate,
}

impl Kernel {
    /// Parses `"triharmonic"`, `"biharmonic"` or `"thin_plate"` (also `"cubic"`, `"linear"`,
    /// `"thin_plate_spline"`, the names scipy uses).
    pub fn parse(name: &str) -> Result<Kernel> {
        match name.to_ascii_lowercase().as_str() {
            "triharmonic" | "cubic" | "r3" => Ok(Kernel::Triharmonic),
            "biharmonic" | "linear" | "r" => Ok(Kernel::Biharmonic),
            "thin_plate" | "thin_plate_spline" | "thinplate" | "tps" => Ok(Kernel::ThinPlate),
            _ => Err(Error::invalid(
                "kernel",
                format!("unknown kernel {name:?}; use \"triharmonic\", \"biharmonic\" or \"thin_plate\""),
            )),
        }
    }

    /// The canonical name.
    pub fn name(self) -> &'static str {
        match self {
            Kernel::Triharmonic => "triharmonic",
            Kernel::Biharmonic => "biharmonic",
            Kernel::ThinPlate => "thin_plate",
        }
    }

    /// φ(r).
    pub fn phi(self, r: f64) -> f64 {
        match self {
            Kernel::Triharmonic => Triharmonic::phi_r2(r * r),
            Kernel::Biharmonic => Biharmonic::phi_r2(r * r),
            Kernel::ThinPlate => ThinPlate::phi_r2(r * r),
        }
    }

    /// φ as a function of r².
    pub fn phi_r2(self, r2: f64) -> f64 {
        match self {
            Kernel::Triharmonic => Triharmonic::phi_r2(r2),
            Kernel::Biharmonic => Biharmonic::phi_r2(r2),
            Kernel::ThinPlate => ThinPlate::phi_r2(r2),
        }
    }

    /// φ'(r)/r, so that ∇φ(|x − c|) = (φ'(r)/r)(x − c).
    pub fn dphi_over_r(self, r: f64) -> f64 {
        match self {
            Kernel::Triharmonic => Triharmonic::dphi_over_r_r2(r * r),
            Kernel::Biharmonic => Biharmonic::dphi_over_r_r2(r * r),
            Kernel::ThinPlate => ThinPlate::dphi_over_r_r2(r * r),
        }
    }

    /// +1 when φ is conditionally positive definite (r³, r² log r: order 2), −1 when −φ is (r:
    /// order 1). Decides the sign of the null-space system in `saddle.rs`.
    pub fn cpd_sign(self) -> f64 {
        match self {
            Kernel::Biharmonic => -1.0,
            _ => 1.0,
        }
    }

    /// φ(s·r) = s^k φ(r) (+ lower-order terms for the thin plate): the power k.
    pub fn degree(self) -> i32 {
        match self {
            Kernel::Triharmonic => 3,
            Kernel::Biharmonic => 1,
            Kernel::ThinPlate => 2,
        }
    }
}

/// A radial function written in terms of r², so that the sums need one square root at most.
pub trait RadialFn: Copy + Send + Sync + 'static {
    /// φ as a function of r².
    fn phi_r2(r2: f64) -> f64;
    /// φ'(r)/r as a function of r² (0 where the limit at r = 0 is 0).
    fn dphi_over_r_r2(r2: f64) -> f64;
}

#[derive(Clone, Copy)]
pub struct Triharmonic;
#[derive(Clone, Copy)]
pub struct Biharmonic;
#[derive(Clone, Copy)]
pub struct ThinPlate;

impl RadialFn for Triharmonic {
    #[inline(always)]
    fn phi_r2(r2: f64) -> f64 {
        r2 * r2.sqrt()
    }
    #[inline(always)]
    fn dphi_over_r_r2(r2: f64) -> f64 {
        3.0 * r2.sqrt()
    }
}

impl RadialFn for Biharmonic {
    #[inline(always)]
    fn phi_r2(r2: f64) -> f64 {
        r2.sqrt()
    }
    #[inline(always)]
    fn dphi_over_r_r2(r2: f64) -> f64 {
        if r2 > 0.0 {
            1.0 / r2.sqrt()
        } else {
            0.0
        }
    }
}

impl RadialFn for ThinPlate {
    #[inline(always)]
    fn phi_r2(r2: f64) -> f64 {
        if r2 > 0.0 {
            0.5 * r2 * r2.ln()
        } else {
            0.0
        }
    }
    #[inline(always)]
    fn dphi_over_r_r2(r2: f64) -> f64 {
        if r2 > 0.0 {
            r2.ln() + 1.0
        } else {
            0.0
        }
    }
}

/// Centres and weights in structure-of-arrays layout.
#[derive(Clone, Debug, Default)]
pub struct Centres {
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub z: Vec<f64>,
    pub w: Vec<f64>,
}

/// A block of [`LANES`] points in structure-of-arrays layout.
#[derive(Clone, Copy, Debug, Default)]
pub struct Block {
    pub x: [f64; LANES],
    pub y: [f64; LANES],
    pub z: [f64; LANES],
}

/// a·b + c, fused (one rounding) when `FMA` (only where the CPU has FMA: elsewhere it would be
/// a library call).
#[inline(always)]
fn madd<const FMA: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// Σ_j w_j φ(|p − c_j|) for each lane.
#[inline(always)]
fn sum_values<K: RadialFn, const FMA: bool>(c: &Centres, b: &Block) -> [f64; LANES] {
    let mut acc = [0.0; LANES];
    let n = c.w.len();
    let (cx, cy, cz, cw) = (&c.x[..n], &c.y[..n], &c.z[..n], &c.w[..n]);
    for j in 0..n {
        let (x, y, z, w) = (cx[j], cy[j], cz[j], cw[j]);
        for l in 0..LANES {
            let dx = b.x[l] - x;
            let dy = b.y[l] - y;
            let dz = b.z[l] - z;
            let r2 = madd::<FMA>(dx, dx, madd::<FMA>(dy, dy, dz * dz));
            acc[l] = madd::<FMA>(w, K::phi_r2(r2), acc[l]);
        }
    }
    acc
}

/// (Σ_j w_j φ, Σ_j w_j ∇φ) for each lane; without `VALUES` the values stay 0 (the gradients
/// are the same bits).
#[inline(always)]
fn sum_with<K: RadialFn, const VALUES: bool, const FMA: bool>(
    c: &Centres,
    b: &Block,
) -> [[f64; LANES]; 4] {
    let mut out = [[0.0; LANES]; 4];
    let n = c.w.len();
    let (cx, cy, cz, cw) = (&c.x[..n], &c.y[..n], &c.z[..n], &c.w[..n]);
    // Half a block at a time: the four sums of eight lanes would not fit in AVX2's sixteen
    // registers with the points' coordinates.
    for h in (0..LANES).step_by(HALF) {
        let mut v = [0.0; HALF];
        let mut gx = [0.0; HALF];
        let mut gy = [0.0; HALF];
        let mut gz = [0.0; HALF];
        let px: [f64; HALF] = std::array::from_fn(|l| b.x[h + l]);
        let py: [f64; HALF] = std::array::from_fn(|l| b.y[h + l]);
        let pz: [f64; HALF] = std::array::from_fn(|l| b.z[h + l]);
        for j in 0..n {
            let (x, y, z, w) = (cx[j], cy[j], cz[j], cw[j]);
            for l in 0..HALF {
                let dx = px[l] - x;
                let dy = py[l] - y;
                let dz = pz[l] - z;
                let r2 = madd::<FMA>(dx, dx, madd::<FMA>(dy, dy, dz * dz));
                if VALUES {
                    v[l] = madd::<FMA>(w, K::phi_r2(r2), v[l]);
                }
                let s = w * K::dphi_over_r_r2(r2);
                gx[l] = madd::<FMA>(s, dx, gx[l]);
                gy[l] = madd::<FMA>(s, dy, gy[l]);
                gz[l] = madd::<FMA>(s, dz, gz[l]);
            }
        }
        for (o, sums) in out.iter_mut().zip([v, gx, gy, gz]) {
            o[h..h + HALF].copy_from_slice(&sums);
        }
    }
    out
}

/// (Σ_j w_j φ, Σ_j w_j ∇φ) for each lane.
#[inline(always)]
fn sum_values_gradients<K: RadialFn, const FMA: bool>(c: &Centres, b: &Block) -> [[f64; LANES]; 4] {
    sum_with::<K, true, FMA>(c, b)
}

/// Σ_j w_j ∇φ for each lane (the values left 0).
#[inline(always)]
fn sum_gradients<K: RadialFn, const FMA: bool>(c: &Centres, b: &Block) -> [[f64; LANES]; 4] {
    sum_with::<K, false, FMA>(c, b)
}

macro_rules! dispatch {
    ($generic:ident, $avx2:ident, $ret:ty) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn $avx2<K: RadialFn>(c: &Centres, blocks: &[Block], out: &mut [$ret]) {
            for (b, o) in blocks.iter().zip(out.iter_mut()) {
                *o = $generic::<K, true>(c, b);
            }
        }
    };
}

dispatch!(sum_values, values_avx2, [f64; LANES]);
dispatch!(
    sum_values_gradients,
    values_gradients_avx2,
    [[f64; LANES]; 4]
);
dispatch!(sum_gradients, gradients_avx2, [[f64; LANES]; 4]);

/// AVX-512 sums for the triharmonic and biharmonic kernels without `sqrt`: 1/√r² from the
/// 14-bit `rsqrt14` estimate refined by two Newton steps (14 → 28 → 53+ bits), then r = r²·(1/r),
/// all in multiplies and FMAs (no `vsqrtpd`, whose latency and throughput are far worse). The result matches
/// the square root to a few units in the last place. r² = 0 (a point on a centre) gives φ = 0 and
/// ∇φ = 0 as it must.
#[cfg(target_arch = "x86_64")]
mod avx512 {
    use super::{Block, Centres, LANES};
    use std::arch::x86_64::*;

    /// 1/√x for x > 0 (x already clamped away from 0).
    #[inline(always)]
    unsafe fn rsqrt_clamped(x: __m512d) -> __m512d {
        let half = _mm512_mul_pd(x, _mm512_set1_pd(0.5));
        let three_halves = _mm512_set1_pd(1.5);
        let mut y = _mm512_rsqrt14_pd(x);
        for _ in 0..2 {
            let yy = _mm512_mul_pd(y, y);
            y = _mm512_mul_pd(y, _mm512_fnmadd_pd(half, yy, three_halves));
        }
        y
    }

    /// φ for one block against one centre: r³ (`cube`) or r.
    #[inline(always)]
    unsafe fn phi_block(
        px: __m512d,
        py: __m512d,
        pz: __m512d,
        cx: __m512d,
        cy: __m512d,
        cz: __m512d,
        cube: bool,
    ) -> __m512d {
        let dx = _mm512_sub_pd(px, cx);
        let dy = _mm512_sub_pd(py, cy);
        let dz = _mm512_sub_pd(pz, cz);
        let r2 = _mm512_fmadd_pd(dx, dx, _mm512_fmadd_pd(dy, dy, _mm512_mul_pd(dz, dz)));
        let x = _mm512_max_pd(r2, _mm512_set1_pd(1e-280));
        let r = _mm512_mul_pd(x, rsqrt_clamped(x));
        if cube {
            _mm512_mul_pd(r2, r)
        } else {
            r
        }
    }

    /// Σ w φ for φ = r³ (`cube = true`) or φ = r; two blocks per pass over the centres (a last,
    /// odd block alone).
    #[target_feature(enable = "avx512f")]
    pub unsafe fn values(c: &Centres, blocks: &[Block], out: &mut [[f64; LANES]], cube: bool) {
        let n = c.w.len();
        let mut k = 0;
        while k < blocks.len() {
            let two = k + 1 < blocks.len();
            let b0 = &blocks[k];
            let b1 = if two { &blocks[k + 1] } else { b0 };
            let (p0x, p0y, p0z) = (
                _mm512_loadu_pd(b0.x.as_ptr()),
                _mm512_loadu_pd(b0.y.as_ptr()),
                _mm512_loadu_pd(b0.z.as_ptr()),
            );
            let (p1x, p1y, p1z) = (
                _mm512_loadu_pd(b1.x.as_ptr()),
                _mm512_loadu_pd(b1.y.as_ptr()),
                _mm512_loadu_pd(b1.z.as_ptr()),
            );
            let mut a0 = _mm512_setzero_pd();
            let mut a1 = _mm512_setzero_pd();
            let centre = |j: usize| {
                (
                    _mm512_set1_pd(c.x[j]),
                    _mm512_set1_pd(c.y[j]),
                    _mm512_set1_pd(c.z[j]),
                    _mm512_set1_pd(c.w[j]),
                )
            };
            if two {
                for j in 0..n {
                    let (cx, cy, cz, w) = centre(j);
                    a0 = _mm512_fmadd_pd(w, phi_block(p0x, p0y, p0z, cx, cy, cz, cube), a0);
                    a1 = _mm512_fmadd_pd(w, phi_block(p1x, p1y, p1z, cx, cy, cz, cube), a1);
                }
                _mm512_storeu_pd(out[k + 1].as_mut_ptr(), a1);
            } else {
                // A last, odd block alone: the same sums in the same order, half the work.
                for j in 0..n {
                    let (cx, cy, cz, w) = centre(j);
                    a0 = _mm512_fmadd_pd(w, phi_block(p0x, p0y, p0z, cx, cy, cz, cube), a0);
                }
            }
            _mm512_storeu_pd(out[k].as_mut_ptr(), a0);
            k += 2;
        }
    }

    /// One block against one centre: (φ, φ'/r, dx, dy, dz).
    #[inline(always)]
    unsafe fn phi_grad_block(
        px: __m512d,
        py: __m512d,
        pz: __m512d,
        cx: __m512d,
        cy: __m512d,
        cz: __m512d,
        cube: bool,
    ) -> (__m512d, __m512d, __m512d, __m512d, __m512d) {
        let dx = _mm512_sub_pd(px, cx);
        let dy = _mm512_sub_pd(py, cy);
        let dz = _mm512_sub_pd(pz, cz);
        let r2 = _mm512_fmadd_pd(dx, dx, _mm512_fmadd_pd(dy, dy, _mm512_mul_pd(dz, dz)));
        let x = _mm512_max_pd(r2, _mm512_set1_pd(1e-280));
        let inv = rsqrt_clamped(x);
        let r = _mm512_mul_pd(x, inv);
        if cube {
            // φ = r³, φ'/r = 3r.
            (
                _mm512_mul_pd(r2, r),
                _mm512_mul_pd(_mm512_set1_pd(3.0), r),
                dx,
                dy,
                dz,
            )
        } else {
            // φ = r, φ'/r = 1/r (0 at r = 0).
            let nz = _mm512_cmp_pd_mask(r2, _mm512_setzero_pd(), _CMP_GT_OQ);
            (r, _mm512_maskz_mov_pd(nz, inv), dx, dy, dz)
        }
    }

    /// (Σ w φ, Σ w ∇φ) for φ = r³ (`cube = true`) or φ = r; two blocks per pass (a last, odd
    /// block alone). Without
    /// `VALUES`, the values are left at 0 and not computed (the gradients are the same bits).
    #[target_feature(enable = "avx512f")]
    pub unsafe fn values_gradients<const VALUES: bool>(
        c: &Centres,
        blocks: &[Block],
        out: &mut [[[f64; LANES]; 4]],
        cube: bool,
    ) {
        let n = c.w.len();
        let zero = _mm512_setzero_pd();
        let mut k = 0;
        while k < blocks.len() {
            let two = k + 1 < blocks.len();
            let b0 = &blocks[k];
            let b1 = if two { &blocks[k + 1] } else { b0 };
            let p0 = (
                _mm512_loadu_pd(b0.x.as_ptr()),
                _mm512_loadu_pd(b0.y.as_ptr()),
                _mm512_loadu_pd(b0.z.as_ptr()),
            );
            let p1 = (
                _mm512_loadu_pd(b1.x.as_ptr()),
                _mm512_loadu_pd(b1.y.as_ptr()),
                _mm512_loadu_pd(b1.z.as_ptr()),
            );
            let mut acc = [[zero; 4]; 2];
            for j in 0..n {
                let (cx, cy, cz) = (
                    _mm512_set1_pd(c.x[j]),
                    _mm512_set1_pd(c.y[j]),
                    _mm512_set1_pd(c.z[j]),
                );
                let w = _mm512_set1_pd(c.w[j]);
                // A last, odd block alone: the same sums in the same order, half the work.
                for (a, p) in acc.iter_mut().zip([p0, p1]).take(if two { 2 } else { 1 }) {
                    let (phi, s, dx, dy, dz) = phi_grad_block(p.0, p.1, p.2, cx, cy, cz, cube);
                    if VALUES {
                        a[0] = _mm512_fmadd_pd(w, phi, a[0]);
                    }
                    let ws = _mm512_mul_pd(w, s);
                    a[1] = _mm512_fmadd_pd(ws, dx, a[1]);
                    a[2] = _mm512_fmadd_pd(ws, dy, a[2]);
                    a[3] = _mm512_fmadd_pd(ws, dz, a[3]);
                }
            }
            for (q, a) in acc.iter().enumerate().take(if two { 2 } else { 1 }) {
                for (m, v) in a.iter().enumerate() {
                    _mm512_storeu_pd(out[k + q][m].as_mut_ptr(), *v);
                }
            }
            k += 2;
        }
    }
}

fn has_avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        crate::simd::Isa::detect() == crate::simd::Isa::Avx512
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Which kernel has an AVX-512 path: Some(true) for r³, Some(false) for r.
fn avx512_kernel<K: 'static>() -> Option<bool> {
    let id = std::any::TypeId::of::<K>();
    if id == std::any::TypeId::of::<Triharmonic>() {
        Some(true)
    } else if id == std::any::TypeId::of::<Biharmonic>() {
        Some(false)
    } else {
        None
    }
}

/// AVX2 and FMA: present whenever [`crate::simd::Isa::detect`] is not generic.
fn has_avx2_fma() -> bool {
    crate::simd::Isa::detect() != crate::simd::Isa::Generic
}

/// Kernel sums for a run of blocks: `out[i]` = per-lane Σ_j w_j φ(|p − c_j|) for `blocks[i]`.
pub fn block_values<K: RadialFn>(c: &Centres, blocks: &[Block], out: &mut [[f64; LANES]]) {
    #[cfg(target_arch = "x86_64")]
    if let Some(cube) = avx512_kernel::<K>() {
        if has_avx512() {
            // SAFETY: the CPU supports AVX-512F, checked just above.
            unsafe { avx512::values(c, blocks, out, cube) };
            return;
        }
    }
    #[cfg(target_arch = "x86_64")]
    if has_avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA, checked just above.
        unsafe { values_avx2::<K>(c, blocks, out) };
        return;
    }
    for (b, o) in blocks.iter().zip(out.iter_mut()) {
        *o = sum_values::<K, false>(c, b);
    }
}

/// Kernel sums and their gradients for a run of blocks: `out[i] = [value, gx, gy, gz]` per lane.
pub fn block_values_gradients<K: RadialFn>(
    c: &Centres,
    blocks: &[Block],
    out: &mut [[[f64; LANES]; 4]],
) {
    #[cfg(target_arch = "x86_64")]
    if let Some(cube) = avx512_kernel::<K>() {
        if has_avx512() {
            // SAFETY: the CPU supports AVX-512F, checked just above.
            unsafe { avx512::values_gradients::<true>(c, blocks, out, cube) };
            return;
        }
    }
    #[cfg(target_arch = "x86_64")]
    if has_avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA, checked just above.
        unsafe { values_gradients_avx2::<K>(c, blocks, out) };
        return;
    }
    for (b, o) in blocks.iter().zip(out.iter_mut()) {
        *o = sum_values_gradients::<K, false>(c, b);
    }
}

/// [`block_values_gradients`] where only the gradients are wanted: `out[i][0]` (the value) is
/// left unspecified, and the gradients are the same bits.
pub fn block_gradients<K: RadialFn>(c: &Centres, blocks: &[Block], out: &mut [[[f64; LANES]; 4]]) {
    #[cfg(target_arch = "x86_64")]
    if let Some(cube) = avx512_kernel::<K>() {
        if has_avx512() {
            // SAFETY: the CPU supports AVX-512F, checked just above.
            unsafe { avx512::values_gradients::<false>(c, blocks, out, cube) };
            return;
        }
    }
    #[cfg(target_arch = "x86_64")]
    if has_avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA, checked just above.
        unsafe { gradients_avx2::<K>(c, blocks, out) };
        return;
    }
    for (b, o) in blocks.iter().zip(out.iter_mut()) {
        *o = sum_gradients::<K, false>(c, b);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vector_paths_agree_with_scalar_sums() {
        let pts = crate::field::testing::random_points(203, -1.0, 1.0, 9);
        let mut c = Centres::default();
        for (k, p) in pts.iter().enumerate() {
            c.x.push(p.x);
            c.y.push(p.y);
            c.z.push(p.z);
            c.w.push(((k as f64) * 0.37).sin());
        }
        let q = crate::field::testing::random_points(64, -1.2, 1.2, 4);
        let mut blocks = vec![Block::default(); 8];
        for (i, p) in q.iter().enumerate() {
            blocks[i / LANES].x[i % LANES] = p.x;
            blocks[i / LANES].y[i % LANES] = p.y;
            blocks[i / LANES].z[i % LANES] = p.z;
        }
        // A lane exactly on a centre.
        blocks[0].x[0] = c.x[5];
        blocks[0].y[0] = c.y[5];
        blocks[0].z[0] = c.z[5];
        fn check<K: RadialFn>(c: &Centres, blocks: &[Block], kernel: Kernel) {
            let mut v = vec![[0.0; LANES]; blocks.len()];
            let mut g = vec![[[0.0; LANES]; 4]; blocks.len()];
            block_values::<K>(c, blocks, &mut v);
            block_values_gradients::<K>(c, blocks, &mut g);
            // Gradients alone: the same bits.
            let mut only = vec![[[f64::NAN; LANES]; 4]; blocks.len()];
            block_gradients::<K>(c, blocks, &mut only);
            for (a, b) in g.iter().zip(&only) {
                for m in 1..4 {
                    assert!(a[m]
                        .iter()
                        .zip(&b[m])
                        .all(|(x, y)| x.to_bits() == y.to_bits()));
                }
            }
            for (bi, b) in blocks.iter().enumerate() {
                for l in 0..LANES {
                    let (mut sv, mut sg) = (0.0, [0.0; 3]);
                    for j in 0..c.w.len() {
                        let d = [b.x[l] - c.x[j], b.y[l] - c.y[j], b.z[l] - c.z[j]];
                        let r = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                        sv += c.w[j] * kernel.phi(r);
                        let s = if r > 0.0 {
                            c.w[j] * kernel.dphi_over_r(r)
                        } else {
                            0.0
                        };
                        for k in 0..3 {
                            sg[k] += s * d[k];
                        }
                    }
                    assert!(
                        (v[bi][l] - sv).abs() < 1e-12 * sv.abs().max(1.0),
                        "{kernel:?} value"
                    );
                    assert!(
                        (g[bi][0][l] - sv).abs() < 1e-12 * sv.abs().max(1.0),
                        "{kernel:?} value"
                    );
                    for k in 0..3 {
                        assert!(
                            (g[bi][k + 1][l] - sg[k]).abs() < 1e-11 * sg[k].abs().max(1.0),
                            "{kernel:?} gradient"
                        );
                    }
                }
            }
        }
        check::<Triharmonic>(&c, &blocks, Kernel::Triharmonic);
        // An odd number of blocks (the vector path takes two at a time).
        check::<Triharmonic>(&c, &blocks[..7], Kernel::Triharmonic);
        check::<Biharmonic>(&c, &blocks[..1], Kernel::Biharmonic);
        check::<Biharmonic>(&c, &blocks, Kernel::Biharmonic);
        check::<ThinPlate>(&c, &blocks, Kernel::ThinPlate);
    }

    #[test]
    fn derivatives_match_differences() {
        for k in [Kernel::Triharmonic, Kernel::Biharmonic, Kernel::ThinPlate] {
            for r in [0.05, 0.3, 1.0, 2.7] {
                let h = 1e-6;
                let fd = (k.phi(r + h) - k.phi(r - h)) / (2.0 * h);
                let an = k.dphi_over_r(r) * r;
                assert!((fd - an).abs() < 1e-6 * an.abs().max(1.0), "{k:?} r={r}");
            }
        }
        assert_eq!(Kernel::parse("CUBIC").unwrap(), Kernel::Triharmonic);
        assert!(Kernel::parse("gaussian").is_err());
    }
}
