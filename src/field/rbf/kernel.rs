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

/// φ(r) = r³ (the default).
#[derive(Clone, Copy)]
pub struct Triharmonic;
/// φ(r) = r.
#[derive(Clone, Copy)]
pub struct Biharmonic;
/// φ(r) = r² log r.
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
    /// x of each centre.
    pub x: Vec<f64>,
    /// y of each centre.
    pub y: Vec<f64>,
    /// z of each centre.
    pub z: Vec<f64>,
    /// Weight of each centre.
    pub w: Vec<f64>,
}

/// A block of [`LANES`] points in structure-of-arrays layout.
#[derive(Clone, Copy, Debug, Default)]
pub struct Block {
    /// x of each point.
    pub x: [f64; LANES],
    /// y of each point.
    pub y: [f64; LANES],
    /// z of each point.
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

    /// `out[i]` = φ(|p_i − c|) for the points p_i = (`xs[i]`, `ys[i]`, `zs[i]`), eight at a time,
    /// with the arithmetic of the sums (each entry has the bits of the term the sums add).
    #[target_feature(enable = "avx512f")]
    pub unsafe fn column(
        xs: &[f64],
        ys: &[f64],
        zs: &[f64],
        c: [f64; 3],
        out: &mut [f64],
        cube: bool,
    ) {
        let n = out.len().min(xs.len()).min(ys.len()).min(zs.len());
        let (cx, cy, cz) = (
            _mm512_set1_pd(c[0]),
            _mm512_set1_pd(c[1]),
            _mm512_set1_pd(c[2]),
        );
        let mut i = 0;
        while i < n {
            let mask = first((n - i).min(8));
            // SAFETY: the lanes of `mask` are rows i..min(i + 8, n) of every slice.
            unsafe {
                let px = _mm512_maskz_loadu_pd(mask, xs.as_ptr().add(i));
                let py = _mm512_maskz_loadu_pd(mask, ys.as_ptr().add(i));
                let pz = _mm512_maskz_loadu_pd(mask, zs.as_ptr().add(i));
                let phi = phi_block(px, py, pz, cx, cy, cz, cube);
                _mm512_mask_storeu_pd(out.as_mut_ptr().add(i), mask, phi);
            }
            i += 8;
        }
    }

    /// Mask of the first `n` lanes (n at most 8).
    #[inline(always)]
    fn first(n: usize) -> __mmask8 {
        ((1u16 << n) - 1) as __mmask8
    }

    /// Centres `j..j + 8` (the lanes of `mask`; zero in the others, whose weight is then 0).
    #[inline(always)]
    unsafe fn centres8(
        c: &Centres,
        j: usize,
        mask: __mmask8,
    ) -> (__m512d, __m512d, __m512d, __m512d) {
        // SAFETY: the caller passes lanes of `mask` within the centres' length.
        unsafe {
            (
                _mm512_maskz_loadu_pd(mask, c.x.as_ptr().add(j)),
                _mm512_maskz_loadu_pd(mask, c.y.as_ptr().add(j)),
                _mm512_maskz_loadu_pd(mask, c.z.as_ptr().add(j)),
                _mm512_maskz_loadu_pd(mask, c.w.as_ptr().add(j)),
            )
        }
    }

    /// Σ w φ at each point of `pts` (normalised), eight centres at a time: lane l sums the
    /// centres j ≡ l (mod 8) in increasing order, then the lanes are added in a fixed order, so
    /// each point's sum has the same bits however many points are passed with it.
    #[target_feature(enable = "avx512f")]
    pub unsafe fn values_by_point(c: &Centres, pts: &[[f64; 3]], out: &mut [f64], cube: bool) {
        let n = c.w.len();
        for (p, o) in pts.iter().zip(out.iter_mut()) {
            let [px, py, pz] = p.map(|x| _mm512_set1_pd(x));
            let mut acc = _mm512_setzero_pd();
            let mut j = 0;
            while j < n {
                let mask = first((n - j).min(8));
                // SAFETY: the lanes of `mask` are centres j..min(j + 8, n).
                let (cx, cy, cz, w) = unsafe { centres8(c, j, mask) };
                acc = _mm512_fmadd_pd(w, phi_block(px, py, pz, cx, cy, cz, cube), acc);
                j += 8;
            }
            *o = _mm512_reduce_add_pd(acc);
        }
    }

    /// [Σ w φ, Σ w ∇φ] at each point of `pts` (normalised), in the order of
    /// [`values_by_point`].
    #[target_feature(enable = "avx512f")]
    pub unsafe fn values_gradients_by_point(
        c: &Centres,
        pts: &[[f64; 3]],
        out: &mut [[f64; 4]],
        cube: bool,
    ) {
        let n = c.w.len();
        for (p, o) in pts.iter().zip(out.iter_mut()) {
            let [px, py, pz] = p.map(|x| _mm512_set1_pd(x));
            let mut acc = [_mm512_setzero_pd(); 4];
            let mut j = 0;
            while j < n {
                let mask = first((n - j).min(8));
                // SAFETY: the lanes of `mask` are centres j..min(j + 8, n).
                let (cx, cy, cz, w) = unsafe { centres8(c, j, mask) };
                let (phi, s, dx, dy, dz) = phi_grad_block(px, py, pz, cx, cy, cz, cube);
                acc[0] = _mm512_fmadd_pd(w, phi, acc[0]);
                let ws = _mm512_mul_pd(w, s);
                acc[1] = _mm512_fmadd_pd(ws, dx, acc[1]);
                acc[2] = _mm512_fmadd_pd(ws, dy, acc[2]);
                acc[3] = _mm512_fmadd_pd(ws, dz, acc[3]);
                j += 8;
            }
            *o = acc.map(|a| _mm512_reduce_add_pd(a));
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

/// [`avx512_kernel`] where the CPU has AVX-512.
fn avx512_cube<K: 'static>() -> Option<bool> {
    avx512_kernel::<K>().filter(|_| has_avx512())
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

/// Kernel sums at a few points against all centres, for the patches of a partition fit (which
/// evaluate a handful of points each): `out[i]` = Σ_j w_j φ(|p_i − c_j|). With AVX-512 (r³ and r),
/// vectorised over the centres, so that the work is proportional to the points; elsewhere over
/// blocks of [`LANES`] points. Either way a point's sum does not depend on the other points.
pub fn values_by_point<K: RadialFn>(c: &Centres, pts: &[[f64; 3]], out: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if let Some(cube) = avx512_cube::<K>() {
        // SAFETY: `avx512_cube` checked that the CPU supports AVX-512F.
        unsafe { avx512::values_by_point(c, pts, out, cube) };
        return;
    }
    for (p, o) in pts.chunks(LANES).zip(out.chunks_mut(LANES)) {
        let mut s = [[0.0; LANES]];
        block_values::<K>(c, &[block_of(p)], &mut s);
        o.copy_from_slice(&s[0][..o.len()]);
    }
}

/// [Σ_j w_j φ, Σ_j w_j ∇φ] at a few points, as [`values_by_point`].
pub fn values_gradients_by_point<K: RadialFn>(c: &Centres, pts: &[[f64; 3]], out: &mut [[f64; 4]]) {
    #[cfg(target_arch = "x86_64")]
    if let Some(cube) = avx512_cube::<K>() {
        // SAFETY: `avx512_cube` checked that the CPU supports AVX-512F.
        unsafe { avx512::values_gradients_by_point(c, pts, out, cube) };
        return;
    }
    for (p, o) in pts.chunks(LANES).zip(out.chunks_mut(LANES)) {
        let mut s = [[[0.0; LANES]; 4]];
        block_values_gradients::<K>(c, &[block_of(p)], &mut s);
        for (l, ol) in o.iter_mut().enumerate() {
            *ol = std::array::from_fn(|m| s[0][m][l]);
        }
    }
}

/// The entries of an interpolation matrix with kernel `K` (see [`crate::linalg::saddle::Entries`]),
/// computed as the sums compute their terms: with AVX-512 (r³ and r) each entry has the bits of
/// the term φ(|p_i − c_j|) that evaluation at p_i adds for centre c_j.
pub struct Arithmetic<K>(std::marker::PhantomData<K>);

impl<K> Default for Arithmetic<K> {
    fn default() -> Self {
        Arithmetic(std::marker::PhantomData)
    }
}

impl<K: RadialFn> crate::linalg::saddle::Entries for Arithmetic<K> {
    fn column(&self, xs: &[f64], ys: &[f64], zs: &[f64], c: glam::DVec3, out: &mut [f64]) {
        #[cfg(target_arch = "x86_64")]
        if let Some(cube) = avx512_cube::<K>() {
            // SAFETY: `avx512_cube` checked that the CPU supports AVX-512F.
            unsafe { avx512::column(xs, ys, zs, c.to_array(), out, cube) };
            return;
        }
        K::phi_r2.column(xs, ys, zs, c, out);
    }
}

/// The block of up to [`LANES`] points (the last repeated in the lanes beyond them).
fn block_of(p: &[[f64; 3]]) -> Block {
    let mut b = Block::default();
    for l in 0..LANES {
        let q = p[l.min(p.len() - 1)];
        (b.x[l], b.y[l], b.z[l]) = (q[0], q[1], q[2]);
    }
    b
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

    /// 203 random centres in [-1, 1]³ with weights sin(0.37 k).
    fn centres() -> Centres {
        let pts = crate::testing::random_points(203, -1.0, 1.0, 9);
        let mut c = Centres::default();
        for (k, p) in pts.iter().enumerate() {
            c.x.push(p.x);
            c.y.push(p.y);
            c.z.push(p.z);
            c.w.push(((k as f64) * 0.37).sin());
        }
        c
    }

    #[test]
    fn vector_paths_agree_with_scalar_sums() {
        let c = centres();
        let q = crate::testing::random_points(64, -1.2, 1.2, 4);
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

    /// Sums by point agree with the sums by block, do not depend on the other points passed
    /// with a point, and a matrix column of [`Arithmetic`] holds the terms they add.
    #[test]
    fn sums_by_point_agree_and_do_not_depend_on_the_batch() {
        use crate::linalg::saddle::Entries;
        let c = centres();
        let mut q: Vec<[f64; 3]> = crate::testing::random_points(21, -1.2, 1.2, 4)
            .iter()
            .map(|p| p.to_array())
            .collect();
        q[3] = [c.x[5], c.y[5], c.z[5]];
        fn check<K: RadialFn>(c: &Centres, q: &[[f64; 3]]) {
            let mut v = vec![0.0; q.len()];
            let mut g = vec![[0.0; 4]; q.len()];
            values_by_point::<K>(c, q, &mut v);
            values_gradients_by_point::<K>(c, q, &mut g);
            let mut bv = vec![0.0; q.len()];
            let mut bg = vec![[0.0; 4]; q.len()];
            for (i, p) in q.iter().enumerate() {
                // Alone: the same bits.
                values_by_point::<K>(c, &q[i..i + 1], &mut bv[i..i + 1]);
                values_gradients_by_point::<K>(c, &q[i..i + 1], &mut bg[i..i + 1]);
                assert_eq!(v[i].to_bits(), bv[i].to_bits());
                assert!((0..4).all(|m| g[i][m].to_bits() == bg[i][m].to_bits()));
                assert_eq!(v[i].to_bits(), g[i][0].to_bits());
                // Against the sums by block.
                let mut s = [[0.0; LANES]];
                block_values::<K>(c, &[block_of(&[*p])], &mut s);
                assert!((v[i] - s[0][0]).abs() < 1e-12 * s[0][0].abs().max(1.0));
            }
            // One centre of weight 1: the sum at p_i is the column's entry i (with AVX-512,
            // where the entries use the sums' arithmetic).
            if !(avx512_kernel::<K>().is_some() && has_avx512()) {
                return;
            }
            for j in [0, 5, 202] {
                let one = Centres {
                    x: vec![c.x[j]],
                    y: vec![c.y[j]],
                    z: vec![c.z[j]],
                    w: vec![1.0],
                };
                let (xs, ys, zs): (Vec<f64>, Vec<f64>, Vec<f64>) = (
                    q.iter().map(|p| p[0]).collect(),
                    q.iter().map(|p| p[1]).collect(),
                    q.iter().map(|p| p[2]).collect(),
                );
                let mut col = vec![0.0; q.len()];
                let centre = glam::DVec3::new(c.x[j], c.y[j], c.z[j]);
                Arithmetic::<K>::default().column(&xs, &ys, &zs, centre, &mut col);
                let mut v = vec![0.0; q.len()];
                values_by_point::<K>(&one, q, &mut v);
                assert!(col.iter().zip(&v).all(|(a, b)| a.to_bits() == b.to_bits()));
            }
        }
        check::<Triharmonic>(&c, &q);
        check::<Biharmonic>(&c, &q);
        check::<ThinPlate>(&c, &q);
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
