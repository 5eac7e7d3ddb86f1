//! The radial profiles a blob field can sum: Triquet et al.'s (1 − q²)², and the SPH cubic
//! spline and Wendland C2 kernels, each scaled to 1 at the centre, with q = d/R and R the
//! compact support (the profile is 0 for q ≥ 1).
//!
//! Every evaluation of a blob field (point, lattice plane, block) computes the same rounded
//! t = (1 − (dy² + dz²)/R²) − dx²/R² (one minus q², unclamped) and hands it to
//! [`Profile::value`], so that every path gives the same bits. Each profile is 0 (+0.0) for
//! t ≤ 0 and does not decrease as t grows, which the blob field's row and block skipping rely on.
//!
//! The SPH kernels as SPH codes normalise them (integral 1 over space) are these profiles times
//! σ/R³: 8/π for the cubic spline (as splashsurf's `CubicSplineKernel` with compact support R) and
//! 21/(2π) for Wendland C2.

use crate::error::{Error, Result};
#[cfg(target_arch = "x86_64")]
use crate::simd::lanes::Lanes;

/// The kernel a blob field sums (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BlobKernel {
    /// (1 − q²)² (Triquet et al. §4.2).
    #[default]
    Triquet,
    /// The SPH cubic spline: 1 − 6q² + 6q³ for q ≤ 1/2, 2(1 − q)³ for 1/2 < q ≤ 1.
    CubicSpline,
    /// Wendland C2 in 3-D: (1 − q)⁴(1 + 4q).
    Wendland,
}

impl BlobKernel {
    /// Every kernel, in the order of [`BlobKernel::NAMES`].
    pub const ALL: [BlobKernel; 3] = [
        BlobKernel::Triquet,
        BlobKernel::CubicSpline,
        BlobKernel::Wendland,
    ];
    /// The names [`BlobKernel::parse`] reads.
    pub const NAMES: [&'static str; 3] = ["triquet", "cubic_spline", "wendland"];

    /// The kernel's name (`"triquet"`, `"cubic_spline"`, `"wendland"`).
    pub fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }

    /// The kernel called `name`; an error names the argument `kernel`.
    pub fn parse(name: &str) -> Result<BlobKernel> {
        Self::NAMES
            .iter()
            .position(|n| *n == name)
            .map(|i| Self::ALL[i])
            .ok_or_else(|| {
                Error::invalid(
                    "kernel",
                    format!("unknown kernel {name:?}; expected one of {:?}", Self::NAMES),
                )
            })
    }

    /// The profile's value at distance `d` for compact support `r` (by [`Profile::value`]).
    pub fn value(self, d: f64, r: f64) -> f64 {
        let t = 1.0 - (d * d) / (r * r);
        match self {
            BlobKernel::Triquet => Triquet::value(t),
            BlobKernel::CubicSpline => CubicSpline::value(t),
            BlobKernel::Wendland => Wendland::value(t),
        }
    }

    /// max over q of |w′(q)|: a primitive of strength A and support R has |∇| ≤ this · A / R.
    pub fn max_slope(self) -> f64 {
        match self {
            BlobKernel::Triquet => Triquet::MAX_SLOPE,
            BlobKernel::CubicSpline => CubicSpline::MAX_SLOPE,
            BlobKernel::Wendland => Wendland::MAX_SLOPE,
        }
    }

    /// The factor `c` of a primitive's gradient c·(A/R²)·g(s)·(p − centre) (see
    /// [`Profile::GRADIENT_SCALE`]).
    pub fn gradient_scale(self) -> f64 {
        match self {
            BlobKernel::Triquet => Triquet::GRADIENT_SCALE,
            BlobKernel::CubicSpline => CubicSpline::GRADIENT_SCALE,
            BlobKernel::Wendland => Wendland::GRADIENT_SCALE,
        }
    }
}

/// The float types a profile's value is computed in (f64, or f32 for fields in single
/// precision): the operations [`Profile::value`] uses, each correctly rounded.
pub trait Real:
    Copy
    + PartialOrd
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
{
    /// `x` rounded to this type (exact for the profiles' constants).
    fn of(x: f64) -> Self;
    /// `self > o ? self : o`, `o` where `self` is NaN.
    fn max(self, o: Self) -> Self;
    /// Square root, correctly rounded.
    fn sqrt(self) -> Self;
}

impl Real for f64 {
    #[inline(always)]
    fn of(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        f64::max(self, o)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
}

impl Real for f32 {
    #[inline(always)]
    fn of(x: f64) -> Self {
        x as f32
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        f32::max(self, o)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f32::sqrt(self)
    }
}

/// One radial profile w(q), q = d/R ∈ [0, 1], w(0) = 1, read through t = 1 − q².
pub trait Profile: 'static {
    /// w at t = 1 − q² as rounded by the caller; +0.0 for t ≤ 0. The same operations in f64 and
    /// f32.
    fn value<T: Real>(t: T) -> T;

    /// g(s) = −w′(q)/(q·GRADIENT_SCALE) at s = 1 − q² (unclamped): the gradient of A·w(|p − c|/R)
    /// is −GRADIENT_SCALE·(A/R²)·g(s)·(p − c). +0.0 for s ≤ 0.
    fn slope(s: f64) -> f64;
    /// The constant factor taken out of [`Profile::slope`].
    const GRADIENT_SCALE: f64;
    /// max over q of |w′(q)|.
    const MAX_SLOPE: f64;
}

/// (1 − q²)².
pub struct Triquet;

impl Profile for Triquet {
    #[inline(always)]
    fn value<T: Real>(t: T) -> T {
        let t = t.max(T::of(0.0));
        t * t
    }
    #[inline(always)]
    fn slope(s: f64) -> f64 {
        s.max(0.0)
    }
    const GRADIENT_SCALE: f64 = 4.0;
    /// 4q(1 − q²) peaks at q = 1/√3: 8/(3√3).
    const MAX_SLOPE: f64 = 1.539_600_717_839_002;
}

/// q from t = 1 − q² (clamped to [0, 1]).
#[inline(always)]
fn q_of<T: Real>(t: T) -> (T, T) {
    let zero = T::of(0.0);
    let q2 = T::of(1.0) - t.max(zero);
    (q2, q2.max(zero).sqrt())
}

/// [`q_of`] of each lane (the same bits).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn q_of_lanes<V: Lanes>(t: V) -> (V, V) {
    // SAFETY: the caller runs where V's feature is.
    unsafe {
        let zero = V::constant(0.0);
        let q2 = V::constant(1.0).sub(t.max(zero));
        (q2, q2.max(zero).sqrt())
    }
}

/// 1 − 6q² + 6q³ for q ≤ 1/2, 2(1 − q)³ beyond.
pub struct CubicSpline;

impl Profile for CubicSpline {
    #[inline(always)]
    fn value<T: Real>(t: T) -> T {
        let (q2, q) = q_of(t);
        let one = T::of(1.0);
        if q <= T::of(0.5) {
            one + T::of(6.0) * q2 * (q - one)
        } else {
            let u = one - q;
            T::of(2.0) * (u * u * u)
        }
    }
    /// −w′/q: 12 − 18q for q ≤ 1/2, 6(1 − q)²/q beyond.
    #[inline(always)]
    fn slope(s: f64) -> f64 {
        let (_, q) = q_of(s);
        if q <= 0.5 {
            12.0 - 18.0 * q
        } else {
            let u = 1.0 - q;
            6.0 * (u * u) / q
        }
    }
    const GRADIENT_SCALE: f64 = 1.0;
    /// |18q² − 12q| peaks at q = 1/3: 2.
    const MAX_SLOPE: f64 = 2.0;
}

/// (1 − q)⁴(1 + 4q).
pub struct Wendland;

impl Profile for Wendland {
    #[inline(always)]
    fn value<T: Real>(t: T) -> T {
        let (_, q) = q_of(t);
        let one = T::of(1.0);
        let u = one - q;
        let u2 = u * u;
        (u2 * u2) * (one + T::of(4.0) * q)
    }
    /// −w′/q = 20(1 − q)³.
    #[inline(always)]
    fn slope(s: f64) -> f64 {
        let (_, q) = q_of(s);
        let u = 1.0 - q;
        20.0 * (u * u * u)
    }
    const GRADIENT_SCALE: f64 = 1.0;
    /// 20q(1 − q)³ peaks at q = 1/4: 135/64.
    const MAX_SLOPE: f64 = 2.109_375;
}

/// A [`Profile`] evaluated a vector of lanes at a time.
#[cfg(target_arch = "x86_64")]
pub(crate) trait LaneProfile: Profile {
    /// [`Profile::value`] of each lane (f64 or f32): the same operations in the same order, so
    /// the same bits. The caller runs where `V`'s feature is.
    unsafe fn value_lanes<V: Lanes>(t: V) -> V;
}

#[cfg(target_arch = "x86_64")]
impl LaneProfile for Triquet {
    #[inline(always)]
    unsafe fn value_lanes<V: Lanes>(t: V) -> V {
        // SAFETY: the caller runs where V's feature is.
        unsafe {
            let t = t.max(V::constant(0.0));
            t.mul(t)
        }
    }
}

#[cfg(target_arch = "x86_64")]
impl LaneProfile for CubicSpline {
    /// Both branches, then each lane's.
    #[inline(always)]
    unsafe fn value_lanes<V: Lanes>(t: V) -> V {
        // SAFETY: the caller runs where V's feature is.
        unsafe {
            let (q2, q) = q_of_lanes(t);
            let one = V::constant(1.0);
            let near = one.add(V::constant(6.0).mul(q2).mul(q.sub(one)));
            let u = one.sub(q);
            let far = V::constant(2.0).mul(u.mul(u).mul(u));
            q.select_le(V::constant(0.5), near, far)
        }
    }
}

#[cfg(target_arch = "x86_64")]
impl LaneProfile for Wendland {
    #[inline(always)]
    unsafe fn value_lanes<V: Lanes>(t: V) -> V {
        // SAFETY: the caller runs where V's feature is.
        unsafe {
            let (_, q) = q_of_lanes(t);
            let one = V::constant(1.0);
            let u = one.sub(q);
            let u2 = u.mul(u);
            u2.mul(u2).mul(one.add(V::constant(4.0).mul(q)))
        }
    }
}

/// Runs `$body` with the type alias `$K` naming the profile of `$kernel` (one match per call, the
/// loops inside monomorphised per profile).
macro_rules! with_profile {
    ($kernel:expr, $K:ident => $body:expr) => {
        match $kernel {
            $crate::field::blob::kernel::BlobKernel::Triquet => {
                type $K = $crate::field::blob::kernel::Triquet;
                $body
            }
            $crate::field::blob::kernel::BlobKernel::CubicSpline => {
                type $K = $crate::field::blob::kernel::CubicSpline;
                $body
            }
            $crate::field::blob::kernel::BlobKernel::Wendland => {
                type $K = $crate::field::blob::kernel::Wendland;
                $body
            }
        }
    };
}
pub(crate) use with_profile;

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "x86_64")]
    use crate::simd::Isa;

    /// w(q) by the textbook formulas.
    fn textbook(k: BlobKernel, q: f64) -> f64 {
        if q >= 1.0 {
            return 0.0;
        }
        match k {
            BlobKernel::Triquet => (1.0 - q * q).powi(2),
            BlobKernel::CubicSpline if q <= 0.5 => 6.0 * (q.powi(3) - q * q) + 1.0,
            BlobKernel::CubicSpline => 2.0 * (1.0 - q).powi(3),
            BlobKernel::Wendland => (1.0 - q).powi(4) * (1.0 + 4.0 * q),
        }
    }

    #[test]
    fn profiles_match_their_formulas_and_vanish_outside() {
        for k in BlobKernel::ALL {
            assert_eq!(BlobKernel::parse(k.name()), Ok(k));
            for i in 0..=200 {
                let q = i as f64 / 100.0;
                assert!(
                    (k.value(q, 1.0) - textbook(k, q)).abs() < 1e-7,
                    "{k:?} q={q}"
                );
            }
            assert_eq!(k.value(1.0, 1.0).to_bits(), 0.0f64.to_bits());
            assert_eq!(k.value(3.0, 1.0).to_bits(), 0.0f64.to_bits());
        }
        assert!(BlobKernel::parse("gauss").is_err());
    }

    /// Every vector path's values are the scalar values' bits, in f64 and f32, on both sides of
    /// the cubic spline's q = 1/2 and where the profiles vanish.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn lane_values_are_the_scalar_bits() {
        use std::arch::x86_64::{__m256, __m256d, __m512, __m512d};
        fn check<K: LaneProfile>() {
            let quarter = 0.75f64; // t at q = 1/2
            let mut ts: Vec<f64> = (0..4000).map(|i| i as f64 / 3000.0 - 0.25).collect();
            ts.extend([-1.0, -0.0, 0.0, 1.0, quarter, 1e-300, -1e-300]);
            ts.extend([quarter.to_bits() + 1, quarter.to_bits() - 1].map(f64::from_bits));
            let q32 = 0.75f32;
            let mut ts32: Vec<f32> = ts.iter().map(|&t| t as f32).collect();
            ts32.extend([q32.to_bits() + 1, q32.to_bits() - 1].map(f32::from_bits));
            ts32.extend([1e-38, -1e-38]);
            same_bits(&ts, K::value, |isa, t, out| match isa {
                Isa::Avx512 => vectors::<K, __m512d>(t, out),
                _ => vectors::<K, __m256d>(t, out),
            });
            same_bits(&ts32, K::value, |isa, t, out| match isa {
                Isa::Avx512 => vectors::<K, __m512>(t, out),
                _ => vectors::<K, __m256>(t, out),
            });
        }
        check::<Triquet>();
        check::<CubicSpline>();
        check::<Wendland>();
    }

    /// Checks that `vector(isa, t, out)`, run on every instruction set with vectors, gives the
    /// bits of `scalar` at each of `ts` (compared by their shortest decimal forms, which tell
    /// apart every two floats of one type, −0.0 and +0.0 included).
    #[cfg(target_arch = "x86_64")]
    fn same_bits<T: Real + std::fmt::Debug + Default>(
        ts: &[T],
        scalar: fn(T) -> T,
        vector: impl Fn(Isa, &[T], &mut [T]),
    ) {
        let mut ts = ts.to_vec();
        ts.resize(ts.len().next_multiple_of(16), T::of(0.5));
        let want: Vec<String> = ts.iter().map(|&t| format!("{:?}", scalar(t))).collect();
        for isa in Isa::available().into_iter().filter(|&i| i != Isa::Generic) {
            let mut got = vec![T::default(); ts.len()];
            for (t, g) in ts.chunks_exact(16).zip(got.chunks_exact_mut(16)) {
                vector(isa, t, g);
            }
            let got: Vec<String> = got.iter().map(|v| format!("{v:?}")).collect();
            assert_eq!(got, want, "{isa:?}");
        }
    }

    /// `K`'s values at sixteen values of `t` with vectors `V` (the CPU must have their feature).
    #[cfg(target_arch = "x86_64")]
    fn vectors<K: LaneProfile, V: Lanes>(t: &[V::Elem], out: &mut [V::Elem]) {
        for h in (0..16).step_by(V::LANES) {
            // SAFETY: called only on the instruction sets the CPU has (`same_bits`), and
            // `value_lanes` inlines into code with V's feature.
            unsafe { K::value_lanes(V::load(&t[h..])).store(&mut out[h..]) }
        }
    }

    /// σ/R³ · w integrates to 1 (midpoint rule on a grid of R/40).
    #[test]
    fn normalised_sph_kernels_integrate_to_one() {
        use std::f64::consts::PI;
        for (k, sigma) in [
            (BlobKernel::CubicSpline, 8.0 / PI),
            (BlobKernel::Wendland, 21.0 / (2.0 * PI)),
        ] {
            let n = 40;
            let h = 1.0 / n as f64;
            let mut sum = 0.0;
            for i in -n..n {
                for j in -n..n {
                    for l in -n..n {
                        let p = [i, j, l].map(|v| (v as f64 + 0.5) * h);
                        let d = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                        sum += k.value(d, 1.0);
                    }
                }
            }
            assert!((sum * h * h * h * sigma - 1.0).abs() < 1e-3, "{k:?}");
        }
    }

    /// The slope functions against differences of the values, and MAX_SLOPE attained and not
    /// exceeded.
    #[test]
    fn slopes_match_differences() {
        for k in BlobKernel::ALL {
            let (slope, scale): (fn(f64) -> f64, f64) = match k {
                BlobKernel::Triquet => (Triquet::slope, Triquet::GRADIENT_SCALE),
                BlobKernel::CubicSpline => (CubicSpline::slope, CubicSpline::GRADIENT_SCALE),
                BlobKernel::Wendland => (Wendland::slope, Wendland::GRADIENT_SCALE),
            };
            let mut worst = 0.0f64;
            for i in 1..1000 {
                let q = i as f64 / 1000.0;
                let e = 1e-6;
                let dw = (k.value(q + e, 1.0) - k.value(q - e, 1.0)) / (2.0 * e);
                let g = -scale * slope(1.0 - q * q) * q;
                assert!((dw - g).abs() < 1e-5, "{k:?} q={q}: {dw} vs {g}");
                worst = worst.max(g.abs());
            }
            assert!(
                worst <= k.max_slope() && worst > 0.999 * k.max_slope(),
                "{k:?}"
            );
            assert_eq!(slope(-0.5).to_bits(), 0.0f64.to_bits());
        }
    }
}
