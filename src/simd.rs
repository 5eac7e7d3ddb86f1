//! Which instruction set the hot loops run with, detected once per process.

/// Instruction sets the hot loops are compiled for: AVX2 stands for AVX2 with FMA (the kernel
/// sums use both), and AVX-512 for AVX-512F with both of those.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Isa {
    Generic,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

impl Isa {
    /// The instruction set, detected once per process (`IMPLICITMESH_NO_AVX512` set at start-up
    /// turns AVX-512 off).
    pub(crate) fn detect() -> Isa {
        static ISA: std::sync::OnceLock<Isa> = std::sync::OnceLock::new();
        *ISA.get_or_init(Isa::probe)
    }

    /// Every instruction set this CPU can run the hot loops with (for tests that compare the
    /// paths).
    #[cfg(test)]
    pub(crate) fn available() -> Vec<Isa> {
        #[allow(unused_mut)]
        let mut isas = vec![Isa::Generic];
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
                isas.push(Isa::Avx2);
            }
            if std::is_x86_feature_detected!("avx512f") && isas.contains(&Isa::Avx2) {
                isas.push(Isa::Avx512);
            }
        }
        isas
    }

    fn probe() -> Isa {
        #[cfg(target_arch = "x86_64")]
        {
            let avx2_fma =
                std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma");
            if std::env::var_os("IMPLICITMESH_NO_AVX512").is_none()
                && std::is_x86_feature_detected!("avx512f")
                && avx2_fma
            {
                return Isa::Avx512;
            }
            if avx2_fma {
                return Isa::Avx2;
            }
        }
        Isa::Generic
    }
}

/// Vectors of f64 or f32 lanes for the loops written once for AVX2 and AVX-512: each method is
/// one intrinsic, compiled with its feature and inlined into callers that have it.
#[cfg(target_arch = "x86_64")]
pub(crate) mod lanes {
    use std::arch::x86_64::*;

    /// A vector of [`Lanes::LANES`] values of type [`Lanes::Elem`] (at most 16). The methods'
    /// only requirement is the vector's CPU feature.
    pub(crate) trait Lanes: Copy {
        type Elem: Copy;
        const LANES: usize;
        /// Every lane `x`.
        unsafe fn splat(x: Self::Elem) -> Self;
        /// Every lane `x` rounded to the lane type (exact for the small constants the profiles
        /// use).
        unsafe fn constant(x: f64) -> Self;
        /// The first `LANES` values of `a`, which must hold that many.
        unsafe fn load(a: &[Self::Elem]) -> Self;
        /// Into the first `LANES` values of `a`, which must hold that many.
        unsafe fn store(self, a: &mut [Self::Elem]);
        unsafe fn add(self, o: Self) -> Self;
        unsafe fn sub(self, o: Self) -> Self;
        unsafe fn mul(self, o: Self) -> Self;
        /// Lane by lane `self > o ? self : o` (so `o` where either is NaN).
        unsafe fn max(self, o: Self) -> Self;
        unsafe fn sqrt(self) -> Self;
        /// Lane by lane `self <= o ? yes : no` (so `no` where `self` or `o` is NaN).
        unsafe fn select_le(self, o: Self, yes: Self, no: Self) -> Self;
    }

    /// A vector of f64 lanes (at most 8), with what the f64 loops need beyond [`Lanes`].
    pub(crate) trait F64s: Lanes<Elem = f64> {
        unsafe fn div(self, o: Self) -> Self;
        /// Bit per lane: `self < o` (false for NaN).
        unsafe fn lt(self, o: Self) -> u32;
        /// Bit per lane: `self > o` (false for NaN).
        unsafe fn gt(self, o: Self) -> u32;
    }

    macro_rules! binary {
        ($feature:literal, $($name:ident = $f:ident),*) => {
            $(
                #[inline]
                #[target_feature(enable = $feature)]
                unsafe fn $name(self, o: Self) -> Self {
                    $f(self, o)
                }
            )*
        };
    }

    /// [`Lanes`] for one vector type: its feature, element, lane count and intrinsics.
    macro_rules! lanes {
        ($v:ty, $feature:literal, $elem:ty, $n:literal, $set1:ident, $loadu:ident, $storeu:ident,
         $add:ident, $sub:ident, $mul:ident, $max:ident, $sqrt:ident,
         |$a:ident, $o:ident, $yes:ident, $no:ident| $select:expr) => {
            impl Lanes for $v {
                type Elem = $elem;
                const LANES: usize = $n;
                #[inline]
                #[target_feature(enable = $feature)]
                unsafe fn splat(x: $elem) -> Self {
                    $set1(x)
                }
                #[inline]
                #[target_feature(enable = $feature)]
                unsafe fn constant(x: f64) -> Self {
                    $set1(x as $elem)
                }
                #[inline]
                #[target_feature(enable = $feature)]
                unsafe fn load(a: &[$elem]) -> Self {
                    debug_assert!(a.len() >= Self::LANES);
                    // SAFETY: the caller passes at least LANES values.
                    unsafe { $loadu(a.as_ptr()) }
                }
                #[inline]
                #[target_feature(enable = $feature)]
                unsafe fn store(self, a: &mut [$elem]) {
                    debug_assert!(a.len() >= Self::LANES);
                    // SAFETY: as in `load`.
                    unsafe { $storeu(a.as_mut_ptr(), self) }
                }
                binary!($feature, add = $add, sub = $sub, mul = $mul, max = $max);
                #[inline]
                #[target_feature(enable = $feature)]
                unsafe fn sqrt(self) -> Self {
                    $sqrt(self)
                }
                #[inline]
                #[target_feature(enable = $feature)]
                unsafe fn select_le(self, o: Self, yes: Self, no: Self) -> Self {
                    let ($a, $o, $yes, $no) = (self, o, yes, no);
                    $select
                }
            }
        };
    }

    lanes!(
        __m256d,
        "avx2",
        f64,
        4,
        _mm256_set1_pd,
        _mm256_loadu_pd,
        _mm256_storeu_pd,
        _mm256_add_pd,
        _mm256_sub_pd,
        _mm256_mul_pd,
        _mm256_max_pd,
        _mm256_sqrt_pd,
        |a, o, yes, no| _mm256_blendv_pd(no, yes, _mm256_cmp_pd::<_CMP_LE_OQ>(a, o))
    );
    lanes!(
        __m512d,
        "avx512f",
        f64,
        8,
        _mm512_set1_pd,
        _mm512_loadu_pd,
        _mm512_storeu_pd,
        _mm512_add_pd,
        _mm512_sub_pd,
        _mm512_mul_pd,
        _mm512_max_pd,
        _mm512_sqrt_pd,
        |a, o, yes, no| _mm512_mask_blend_pd(_mm512_cmp_pd_mask::<_CMP_LE_OQ>(a, o), no, yes)
    );
    lanes!(
        __m256,
        "avx2",
        f32,
        8,
        _mm256_set1_ps,
        _mm256_loadu_ps,
        _mm256_storeu_ps,
        _mm256_add_ps,
        _mm256_sub_ps,
        _mm256_mul_ps,
        _mm256_max_ps,
        _mm256_sqrt_ps,
        |a, o, yes, no| _mm256_blendv_ps(no, yes, _mm256_cmp_ps::<_CMP_LE_OQ>(a, o))
    );
    lanes!(
        __m512,
        "avx512f",
        f32,
        16,
        _mm512_set1_ps,
        _mm512_loadu_ps,
        _mm512_storeu_ps,
        _mm512_add_ps,
        _mm512_sub_ps,
        _mm512_mul_ps,
        _mm512_max_ps,
        _mm512_sqrt_ps,
        |a, o, yes, no| _mm512_mask_blend_ps(_mm512_cmp_ps_mask::<_CMP_LE_OQ>(a, o), no, yes)
    );

    impl F64s for __m256d {
        binary!("avx2", div = _mm256_div_pd);
        #[inline]
        #[target_feature(enable = "avx2")]
        unsafe fn lt(self, o: Self) -> u32 {
            _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_LT_OQ>(self, o)) as u32
        }
        #[inline]
        #[target_feature(enable = "avx2")]
        unsafe fn gt(self, o: Self) -> u32 {
            _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(self, o)) as u32
        }
    }

    impl F64s for __m512d {
        binary!("avx512f", div = _mm512_div_pd);
        #[inline]
        #[target_feature(enable = "avx512f")]
        unsafe fn lt(self, o: Self) -> u32 {
            _mm512_cmp_pd_mask::<_CMP_LT_OQ>(self, o) as u32
        }
        #[inline]
        #[target_feature(enable = "avx512f")]
        unsafe fn gt(self, o: Self) -> u32 {
            _mm512_cmp_pd_mask::<_CMP_GT_OQ>(self, o) as u32
        }
    }
}
