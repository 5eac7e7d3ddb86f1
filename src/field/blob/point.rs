//! Point queries: the potential F(p) and the gradient ∇f = −∇F at single points from the voxel
//! lists (or by brute force, the tests' reference), and gradients over a given list of
//! primitives for whole batches of points, with vector paths for the default profile. Every
//! evaluation computes a term in the order of [`unit_t`], so point, plane and block values give
//! the same bits.

use super::kernel::{with_profile, Profile, Triquet};
use super::{BlobField, Packed, Precision};
use crate::field::PAR_CHUNK;
#[cfg(target_arch = "x86_64")]
use crate::simd::lanes::F64s;
use crate::simd::Isa;
use glam::DVec3;
use rayon::prelude::*;

impl BlobField {
    /// Potential F(p) by brute force over all primitives (the reference for tests).
    pub fn potential_brute_force(&self, p: DVec3) -> f64 {
        if let Some(s) = &self.shapes {
            return self.shaped_potential_brute_force(s, p);
        }
        let packed = self.packed();
        with_profile!(self.settings.kernel, K => packed.iter().map(|q| term::<K>(q, p)).sum())
    }

    /// Centre, 1/R², A and R of primitive `i`.
    #[inline(always)]
    pub(super) fn primitive(&self, i: u32) -> (DVec3, f64, f64, f64) {
        let i = i as usize;
        (
            self.centers[i],
            self.inv_r2[i],
            self.strengths[i],
            self.radii[i],
        )
    }

    /// c·A / R² of primitive `i` (c: the profile's [`Profile::GRADIENT_SCALE`]), the factor of
    /// its gradient.
    #[inline(always)]
    fn gradient_factor<K: Profile>(&self, i: usize) -> f64 {
        K::GRADIENT_SCALE * self.strengths[i] * self.inv_r2[i]
    }

    /// ∇f(p) = −∇F(p) from the voxel lists.
    #[inline(always)]
    pub(super) fn gradient_at(&self, p: DVec3) -> DVec3 {
        with_profile!(self.settings.kernel, K => self.gradient_over::<K>(self.grid().candidates(p), p))
    }

    /// ∇f(p) summed over the primitives `list` (in index order: the same terms, in the same
    /// order, as any other list that holds every primitive reaching `p`).
    #[inline(always)]
    pub(super) fn gradient_over<K: Profile>(&self, list: &[u32], p: DVec3) -> DVec3 {
        if let Some(s) = &self.shapes {
            return self.shaped_gradient::<K>(s, list, p);
        }
        let mut g = DVec3::ZERO;
        for &i in list {
            let i = i as usize;
            let d = p - self.centers[i];
            let s = K::slope(1.0 - d.length_squared() * self.inv_r2[i]);
            g += d * (self.gradient_factor::<K>(i) * s);
        }
        g
    }

    /// Potential F(p) from the voxel lists (the same terms in the same order as
    /// [`BlobField::potential_brute_force`] minus those that cannot reach `p`); in single
    /// precision the f32 sum, widened.
    #[inline(always)]
    pub fn potential(&self, p: DVec3) -> f64 {
        if let Some(s) = &self.shapes {
            return self.shaped_potential(s, p);
        }
        match self.settings.precision {
            Precision::Double => {
                with_profile!(self.settings.kernel, K => self.potential_with::<K>(p))
            }
            Precision::Single => {
                with_profile!(self.settings.kernel, K => self.potential_single::<K>(p) as f64)
            }
        }
    }

    /// [`BlobField::potential`] with the profile `K`.
    #[inline(always)]
    pub(super) fn potential_with<K: Profile>(&self, p: DVec3) -> f64 {
        let packed = self.packed();
        let mut f = 0.0;
        for &i in self.grid().candidates(p) {
            f += term::<K>(&packed[i as usize], p);
        }
        f
    }

    /// [`BlobField::gradient_over`] at each point, with the vector path of `isa` (which the CPU
    /// must have) for whole vectors of points: the same bits on every path.
    pub(super) fn gradients_over(
        &self,
        isa: Isa,
        list: &[u32],
        points: &[DVec3],
        out: &mut [DVec3],
    ) {
        if self.shapes.is_some() {
            return with_profile!(self.settings.kernel, K => map_points(points, out, |p| {
                self.gradient_over::<K>(list, p)
            }));
        }
        with_profile!(self.settings.kernel, K => self.gradients_over_with::<K>(isa, list, points, out))
    }

    /// [`BlobField::gradients_over`] with the profile `K` (vector paths for the default one).
    #[inline(always)]
    fn gradients_over_with<K: Profile>(
        &self,
        isa: Isa,
        list: &[u32],
        points: &[DVec3],
        out: &mut [DVec3],
    ) {
        let done = match isa {
            #[cfg(target_arch = "x86_64")]
            _ if !is_triquet::<K>() => 0,
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => {
                let full = points.len() / 8 * 8;
                // SAFETY: the caller passes an instruction set the CPU has.
                unsafe { self.gradients8_avx512(list, &points[..full], &mut out[..full]) };
                full
            }
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => {
                let full = points.len() / 4 * 4;
                // SAFETY: as above.
                unsafe { self.gradients4_avx2(list, &points[..full], &mut out[..full]) };
                full
            }
            Isa::Generic => 0,
        };
        for (p, o) in points[done..].iter().zip(&mut out[done..]) {
            *o = self.gradient_over::<K>(list, *p);
        }
    }

    /// [`BlobField::gradient_over`] for `V::LANES` points per step (`points.len()` a multiple
    /// of it). The same operations in the same order, so the same bits.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn gradients_lanes<V: F64s>(&self, list: &[u32], points: &[DVec3], out: &mut [DVec3]) {
        // SAFETY (every vector operation below): the caller runs where V's feature is.
        unsafe {
            let (one, zero) = (V::splat(1.0), V::splat(0.0));
            for (pc, oc) in points
                .chunks_exact(V::LANES)
                .zip(out.chunks_exact_mut(V::LANES))
            {
                let (mut x, mut y, mut z) = ([0.0; 8], [0.0; 8], [0.0; 8]);
                for (k, p) in pc.iter().enumerate() {
                    (x[k], y[k], z[k]) = (p.x, p.y, p.z);
                }
                let (px, py, pz) = (V::load(&x), V::load(&y), V::load(&z));
                let (mut gx, mut gy, mut gz) = (zero, zero, zero);
                for &i in list {
                    let i = i as usize;
                    let c = self.centers[i];
                    let dx = px.sub(V::splat(c.x));
                    let dy = py.sub(V::splat(c.y));
                    let dz = pz.sub(V::splat(c.z));
                    let s = dx.mul(dx).add(dy.mul(dy)).add(dz.mul(dz));
                    let t = one.sub(s.mul(V::splat(self.inv_r2[i]))).max(zero);
                    let k = V::splat(self.gradient_factor::<Triquet>(i)).mul(t);
                    gx = gx.add(dx.mul(k));
                    gy = gy.add(dy.mul(k));
                    gz = gz.add(dz.mul(k));
                }
                gx.store(&mut x);
                gy.store(&mut y);
                gz.store(&mut z);
                for (k, o) in oc.iter_mut().enumerate() {
                    *o = DVec3::new(x[k], y[k], z[k]);
                }
            }
        }
    }

    /// [`BlobField::gradients_lanes`] with AVX-512, eight points per step.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn gradients8_avx512(&self, list: &[u32], points: &[DVec3], out: &mut [DVec3]) {
        // SAFETY: AVX-512F is enabled here.
        unsafe { self.gradients_lanes::<std::arch::x86_64::__m512d>(list, points, out) }
    }

    /// [`BlobField::gradients_lanes`] with AVX2, four points per step.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn gradients4_avx2(&self, list: &[u32], points: &[DVec3], out: &mut [DVec3]) {
        // SAFETY: AVX2 is enabled here.
        unsafe { self.gradients_lanes::<std::arch::x86_64::__m256d>(list, points, out) }
    }
}

/// The term A·w(t) of the packed primitive `q` at `p`.
#[inline(always)]
fn term<K: Profile>(q: &Packed, p: DVec3) -> f64 {
    q.strength * K::value(unit_t(p - q.center, q.inv_r2))
}

/// Point batches smaller than this are evaluated on the calling thread (about 0.1 ms of work).
const SERIAL_BELOW: usize = 2048;

/// `out[i] = f(points[i])`, in parallel chunks. Batches below [`SERIAL_BELOW`] points run on the
/// calling thread: handing them to the pool costs more than it saves (the tracking
/// polygonizer's waves are often that small).
#[inline(always)]
pub(super) fn map_points<T: Send>(points: &[DVec3], out: &mut [T], f: impl Fn(DVec3) -> T + Sync) {
    assert_eq!(points.len(), out.len());
    let run = |p: &[DVec3], o: &mut [T]| {
        for (pi, oi) in p.iter().zip(o.iter_mut()) {
            *oi = f(*pi);
        }
    };
    if points.len() < SERIAL_BELOW {
        return run(points, out);
    }
    points
        .par_chunks(PAR_CHUNK)
        .zip(out.par_chunks_mut(PAR_CHUNK))
        .for_each(|(p, o)| run(p, o));
}

/// t = (1 − (dy² + dz²)/R²) − dx²/R² of one primitive at offset `d` from its centre (1/R²
/// `inv`), unclamped, which [`Profile::value`] turns into the term: the order every evaluation of
/// the potential uses (point, plane and block), so that all give the same bits. Grouping
/// dy² + dz² first lets a lattice row share 1 − (dy² + dz²)/R² and a block share dx²/R² per
/// primitive; both rounded steps are monotone, so t never grows with any |d_i|.
#[inline(always)]
pub(super) fn unit_t(d: DVec3, inv: f64) -> f64 {
    (1.0 - (d.y * d.y + d.z * d.z) * inv) - (d.x * d.x) * inv
}

/// Whether `K` is the default profile, the one the hand-written vector paths compute.
#[inline(always)]
pub(super) fn is_triquet<K: Profile>() -> bool {
    std::any::TypeId::of::<K>() == std::any::TypeId::of::<Triquet>()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::blob::kernel::BlobKernel;
    use crate::field::blob::{BlobSettings, PerPrimitive};
    use crate::field::Field;
    use crate::testing::{gradient_error, random_points, sized_blobs};

    #[test]
    fn voxel_evaluation_equals_brute_force() {
        for ((n, seed), kernel) in [(1, 3), (20, 5), (300, 7)]
            .into_iter()
            .flat_map(|c| BlobKernel::ALL.map(|k| (c, k)))
        {
            let b = sized_blobs(n, seed, kernel);
            for p in random_points(2000, -1.2, 1.2, seed + 9) {
                assert!((b.potential(p) - b.potential_brute_force(p)).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn gradient_bound_holds() {
        for ((n, seed), kernel) in [(1, 41), (50, 43), (400, 47)]
            .into_iter()
            .flat_map(|c| BlobKernel::ALL.map(|k| (c, k)))
        {
            let b = sized_blobs(n, seed, kernel);
            let bound = b.gradient_bound().unwrap();
            let worst = random_points(20_000, -1.2, 1.2, seed + 1)
                .iter()
                .map(|p| b.gradient(*p).length())
                .fold(0.0, f64::max);
            assert!(
                worst > 0.0 && worst <= bound,
                "n={n}: |∇f| {worst} > bound {bound}"
            );
        }
        // One primitive: the bound is attained on the sphere d = R/√3.
        let one = BlobField::new(
            &[DVec3::ZERO],
            PerPrimitive::All(0.5),
            PerPrimitive::All(2.0),
            0.5,
            BlobSettings::default(),
        )
        .unwrap();
        let p = DVec3::new(0.5 / 3f64.sqrt(), 0.0, 0.0);
        assert!((one.gradient(p).length() - one.gradient_bound().unwrap()).abs() < 1e-12);
    }

    #[test]
    fn gradient_matches_differences() {
        for kernel in BlobKernel::ALL {
            let b = sized_blobs(50, 11, kernel);
            let pts = random_points(300, -1.0, 1.0, 12);
            assert!(gradient_error(&b, &pts, 1e-6) < 1e-6, "{kernel:?}");
        }
    }

    /// The potential of one primitive of each profile at known distances.
    #[test]
    fn potential_follows_the_profile() {
        for kernel in BlobKernel::ALL {
            let b = BlobField::new(
                &[DVec3::new(0.1, 0.2, 0.3)],
                PerPrimitive::All(0.5),
                PerPrimitive::All(2.0),
                0.5,
                BlobSettings {
                    kernel,
                    ..Default::default()
                },
            )
            .unwrap();
            for d in [0.0, 0.1, 0.2, 0.25, 0.3, 0.49, 0.5, 0.7] {
                let p = DVec3::new(0.1, 0.2, 0.3) + DVec3::new(0.6, 0.0, 0.8) * d;
                let want = 2.0 * kernel.value(d, 0.5);
                assert!((b.potential(p) - want).abs() < 1e-12, "{kernel:?} d={d}");
            }
        }
    }
}
