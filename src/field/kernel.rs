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

/// Σ_j w_j φ(|p − c_j|) for each lane.
#[inline(always)]
fn sum_values<K: RadialFn>(c: &Centres, b: &Block) -> [f64; LANES] {
    let mut acc = [0.0; LANES];
    let n = c.w.len();
    let (cx, cy, cz, cw) = (&c.x[..n], &c.y[..n], &c.z[..n], &c.w[..n]);
    for j in 0..n {
        let (x, y, z, w) = (cx[j], cy[j], cz[j], cw[j]);
        for l in 0..LANES {
            let dx = b.x[l] - x;
            let dy = b.y[l] - y;
            let dz = b.z[l] - z;
            let r2 = dx * dx + dy * dy + dz * dz;
            acc[l] += w * K::phi_r2(r2);
        }
    }
    acc
}

/// (Σ_j w_j φ, Σ_j w_j ∇φ) for each lane.
#[inline(always)]
fn sum_values_gradients<K: RadialFn>(c: &Centres, b: &Block) -> [[f64; LANES]; 4] {
    let mut v = [0.0; LANES];
    let mut gx = [0.0; LANES];
    let mut gy = [0.0; LANES];
    let mut gz = [0.0; LANES];
    let n = c.w.len();
    let (cx, cy, cz, cw) = (&c.x[..n], &c.y[..n], &c.z[..n], &c.w[..n]);
    for j in 0..n {
        let (x, y, z, w) = (cx[j], cy[j], cz[j], cw[j]);
        for l in 0..LANES {
            let dx = b.x[l] - x;
            let dy = b.y[l] - y;
            let dz = b.z[l] - z;
            let r2 = dx * dx + dy * dy + dz * dz;
            v[l] += w * K::phi_r2(r2);
            let s = w * K::dphi_over_r_r2(r2);
            gx[l] += s * dx;
            gy[l] += s * dy;
            gz[l] += s * dz;
        }
    }
    [v, gx, gy, gz]
}

macro_rules! dispatch {
    ($generic:ident, $avx2:ident, $ret:ty) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn $avx2<K: RadialFn>(c: &Centres, blocks: &[Block], out: &mut [$ret]) {
            for (b, o) in blocks.iter().zip(out.iter_mut()) {
                *o = $generic::<K>(c, b);
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

fn has_avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Kernel sums for a run of blocks: `out[i]` = per-lane Σ_j w_j φ(|p − c_j|) for `blocks[i]`.
pub fn block_values<K: RadialFn>(c: &Centres, blocks: &[Block], out: &mut [[f64; LANES]]) {
    #[cfg(target_arch = "x86_64")]
    if has_avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA, checked just above.
        unsafe { values_avx2::<K>(c, blocks, out) };
        return;
    }
    for (b, o) in blocks.iter().zip(out.iter_mut()) {
        *o = sum_values::<K>(c, b);
    }
}

/// Kernel sums and their gradients for a run of blocks: `out[i] = [value, gx, gy, gz]` per lane.
pub fn block_values_gradients<K: RadialFn>(
    c: &Centres,
    blocks: &[Block],
    out: &mut [[[f64; LANES]; 4]],
) {
    #[cfg(target_arch = "x86_64")]
    if has_avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA, checked just above.
        unsafe { values_gradients_avx2::<K>(c, blocks, out) };
        return;
    }
    for (b, o) in blocks.iter().zip(out.iter_mut()) {
        *o = sum_values_gradients::<K>(c, b);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
