//! Ruling out the blocks inside a blob field's surface: a lower bound on the potential at the
//! points of a block, per pair of neighbouring points along x (4 × 8 × 8 pairs per block: half
//! its points, each bound from one term per primitive).
//!
//! Each primitive's term at both points of a pair is at least its term with the larger of their
//! two squared x-offsets (as dx²/R²), put through the splat's rounded operations in the splat's
//! order ([`BlobField::splat_block_with`], [`super::point::unit_t`]). Each of those rounded steps is
//! monotone, so the bound's t is at most each point's t; with positive strengths the bound's
//! term is then at most the point's term, up to the profile's own rounding (a few units in the
//! last place). The bounds are summed from 0, the primitives centred near the block first: in
//! any order, a rounded sum of n positive terms differs from the exact sum by at most
//! (n − 1)·2⁻⁵³ times it, and so does the splat's. A pair whose bound exceeds the threshold by
//! the margin of [`BlobField::box_sign`] (1e-9 of the threshold and the strengths' sum, above
//! both roundings for lists of up to 2²⁰ primitives; longer ones are not bounded) has both
//! points inside.
//!
//! Each axis paired loses about a sixth of the potential inside a fluid (every term takes its
//! worst point of the two, while their sum hardly changes): pairs along x alone keep the
//! colour field (about 1 inside, threshold 0.6) above its threshold; boxes of 2 × 2 × 2 points
//! do not.
//!
//! The bound needs every strength of the list positive: the terms then only add, a partial sum
//! is a bound too, and the loop stops once every pair is above the threshold.

use super::block::BlockCoords;
use super::{single, BlobField, Precision};
#[cfg(target_arch = "x86_64")]
use crate::field::blob::kernel::LaneProfile;
use crate::field::blob::kernel::{with_profile, Profile};
use crate::field::BLOCK_POINTS;
#[cfg(target_arch = "x86_64")]
use crate::simd::lanes::{F64s, Lanes};
use crate::simd::Isa;
use glam::DVec3;

/// Pairs of neighbouring points per block row along x.
const PAIRS: usize = BLOCK_POINTS / 2;

/// Primitives summed between two checks of whether every pair is already inside.
const CHECK_EVERY: usize = 8;

/// Lists longer than this are not bounded (the margin covers the rounding of sums of at most
/// this many terms).
const MAX_LIST: usize = 1 << 20;

/// Lower bounds on the potential at a block's pairs of points: `[z][y][pair along x]`.
type Pairs = [[[f64; PAIRS]; BLOCK_POINTS]; BLOCK_POINTS];

/// The larger value of each pair of neighbouring lanes.
#[inline(always)]
fn farthest(v: [f64; BLOCK_POINTS]) -> [f64; PAIRS] {
    std::array::from_fn(|p| v[2 * p].max(v[2 * p + 1]))
}

/// One primitive's terms over a block's pairs: the farthest dx²/R² per pair, dy² per row, dz²
/// per plane, 1/R², the smallest of the pairs' dx²/R², and A.
struct PrimitiveTerms {
    qx: [f64; PAIRS],
    dy2: [f64; BLOCK_POINTS],
    dz2: [f64; BLOCK_POINTS],
    inv: f64,
    nearest: f64,
    a: f64,
}

impl PrimitiveTerms {
    /// Calls `row_fn` with each row of plane `k` the primitive reaches (k = 1 − (dy² + dz²)/R²
    /// above the nearest pair's dx²/R²): the row, the pairs' dx²/R², k and A.
    #[inline(always)]
    fn rows(
        &self,
        plane: &mut [[f64; PAIRS]; BLOCK_POINTS],
        k: usize,
        row_fn: impl Fn(&mut [f64; PAIRS], &[f64; PAIRS], f64, f64),
    ) {
        for (row, dy2) in plane.iter_mut().zip(self.dy2) {
            let k = 1.0 - (dy2 + self.dz2[k]) * self.inv;
            if k > self.nearest {
                row_fn(row, &self.qx, k, self.a);
            }
        }
    }
}

impl BlobField {
    /// Whether every point of `block` is provably inside (potential above the threshold), from
    /// the primitives of `list` (every primitive reaching the block, in index order), with the
    /// vector path of `isa` (which the CPU must have). False when a strength of the list is
    /// not positive.
    pub(super) fn block_inside(&self, isa: Isa, list: &[u32], block: &BlockCoords) -> bool {
        // The pairs bound is made for round kernels only (the `ellipsoids` module).
        if self.shapes.is_some() {
            return false;
        }
        with_profile!(self.settings.kernel, K => match isa {
            // SAFETY: the caller passes an instruction set the CPU has.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => unsafe { self.block_inside_avx512::<K>(list, block) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe { self.block_inside_avx2::<K>(list, block) },
            Isa::Generic => self.block_inside_with(list, block, |low, term, planes| {
                for k in planes {
                    term.rows(&mut low[k], k, |row, qx, k, a| {
                        for (v, q) in row.iter_mut().zip(qx) {
                            *v += a * K::value(k - q);
                        }
                    })
                }
            }),
        })
    }

    /// [`BlobField::block_inside_with`] with a row of pairs per AVX2 vector
    /// ([`LaneProfile::value_lanes`], the same bits).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn block_inside_avx2<K: LaneProfile>(&self, list: &[u32], block: &BlockCoords) -> bool {
        use std::arch::x86_64::__m256d;
        self.block_inside_with(list, block, |low, term, planes| {
            for k in planes {
                term.rows(&mut low[k], k, |row, qx, k, a| {
                    // SAFETY: AVX2 is enabled here; a row holds four values, one vector.
                    unsafe {
                        let t = __m256d::splat(k).sub(__m256d::load(qx));
                        let v = __m256d::load(row).add(__m256d::splat(a).mul(K::value_lanes(t)));
                        v.store(row);
                    }
                })
            }
        })
    }

    /// [`BlobField::block_inside_with`] with AVX-512: a plane's rows' k in one vector, compared
    /// with the nearest pair's dx²/R² for the rows reached, then two rows of pairs per vector
    /// (rows 2m and 2m + 1 when either is reached). A row not reached gains +0.0 (its every t
    /// is at most 0, and the strengths are positive), which changes no sum: the same bits as
    /// the other paths.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn block_inside_avx512<K: LaneProfile>(
        &self,
        list: &[u32],
        block: &BlockCoords,
    ) -> bool {
        use std::arch::x86_64::*;
        // Lanes 0..4 read row j, lanes 4..8 row j + 1.
        let pair = _mm512_set_epi64(1, 1, 1, 1, 0, 0, 0, 0);
        let one = _mm512_set1_pd(1.0);
        self.block_inside_with(list, block, |low, term, planes| {
            // SAFETY: AVX-512F is enabled here; `dy2` holds eight f64, `qx` four, and a pair
            // of rows of a plane eight from 4j (j ≤ 6).
            unsafe {
                let dy2 = _mm512_loadu_pd(term.dy2.as_ptr());
                let inv = _mm512_set1_pd(term.inv);
                let nearest = _mm512_set1_pd(term.nearest);
                let qx = _mm512_broadcast_f64x4(_mm256_loadu_pd(term.qx.as_ptr()));
                let a = _mm512_set1_pd(term.a);
                for k in planes {
                    let dz2 = _mm512_set1_pd(term.dz2[k]);
                    let ks = _mm512_sub_pd(one, _mm512_mul_pd(_mm512_add_pd(dy2, dz2), inv));
                    let rows = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(ks, nearest) as u32;
                    let mut pairs = (rows | rows >> 1) & 0x55;
                    let base = low[k].as_mut_ptr() as *mut f64;
                    while pairs != 0 {
                        let j = pairs.trailing_zeros() as usize;
                        pairs &= pairs - 1;
                        let idx = _mm512_add_epi64(pair, _mm512_set1_epi64(j as i64));
                        let t = _mm512_sub_pd(_mm512_permutexvar_pd(idx, ks), qx);
                        let p = base.add(PAIRS * j);
                        let w = K::value_lanes(t);
                        _mm512_storeu_pd(p, _mm512_add_pd(_mm512_loadu_pd(p), _mm512_mul_pd(a, w)));
                    }
                }
            }
        })
    }

    /// Whether the potential at each of the block's eight corners is above the threshold, from
    /// the primitives of `list` (in f64, the order of [`super::point::unit_t`]), with the vector path
    /// of `isa` (which the CPU must have). When it is not, a point of the block is not inside
    /// and [`BlobField::block_inside`] cannot succeed: this costs one term per primitive and
    /// corner, where `block_inside` takes one per primitive and pair of points reached.
    pub(super) fn corners_inside(&self, isa: Isa, list: &[u32], block: &BlockCoords) -> bool {
        if self.shapes.is_some() {
            return false;
        }
        let BlockCoords { xs, ys, zs, n, .. } = block;
        let last = n.map(|v| v as usize - 1);
        let corner = |c: usize, axis: &[f64; BLOCK_POINTS], a: usize| {
            axis[if c >> a & 1 == 1 { last[a] } else { 0 }]
        };
        let cx: [f64; 8] = std::array::from_fn(|c| corner(c, xs, 0));
        let cy: [f64; 8] = std::array::from_fn(|c| corner(c, ys, 1));
        let cz: [f64; 8] = std::array::from_fn(|c| corner(c, zs, 2));
        let mut f = [0.0f64; 8];
        with_profile!(self.settings.kernel, K => match isa {
            // SAFETY: the caller passes an instruction set the CPU has.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => unsafe { self.corners_avx512::<K>(list, [&cx, &cy, &cz], &mut f) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe { self.corners_avx2::<K>(list, [&cx, &cy, &cz], &mut f) },
            Isa::Generic => {
                for &i in list {
                    let (c, inv, a, _) = self.primitive(i);
                    for (k, f) in f.iter_mut().enumerate() {
                        let d = DVec3::new(cx[k], cy[k], cz[k]) - c;
                        *f += a * K::value(super::point::unit_t(d, inv));
                    }
                }
            }
        });
        f.iter().all(|&f| f > self.threshold)
    }

    /// The potentials of [`BlobField::corners_inside`], `V::LANES` corners per vector.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn corners_lanes<K: LaneProfile, V: F64s>(
        &self,
        list: &[u32],
        [cx, cy, cz]: [&[f64; 8]; 3],
        out: &mut [f64; 8],
    ) {
        // SAFETY (every vector operation below): the caller runs where V's feature is; eight
        // values are a whole number of vectors.
        unsafe {
            let one = V::splat(1.0);
            for h in (0..8).step_by(V::LANES) {
                let (x, y, z) = (V::load(&cx[h..]), V::load(&cy[h..]), V::load(&cz[h..]));
                let mut f = V::splat(0.0);
                for &i in list {
                    let (c, inv, a, _) = self.primitive(i);
                    let (dx, dy, dz) = (
                        x.sub(V::splat(c.x)),
                        y.sub(V::splat(c.y)),
                        z.sub(V::splat(c.z)),
                    );
                    let vinv = V::splat(inv);
                    let k = one.sub(dy.mul(dy).add(dz.mul(dz)).mul(vinv));
                    let t = k.sub(dx.mul(dx).mul(vinv));
                    f = f.add(V::splat(a).mul(K::value_lanes(t)));
                }
                f.store(&mut out[h..]);
            }
        }
    }

    /// [`BlobField::corners_lanes`] with AVX-512, the eight corners in one vector.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn corners_avx512<K: LaneProfile>(
        &self,
        list: &[u32],
        c: [&[f64; 8]; 3],
        out: &mut [f64; 8],
    ) {
        // SAFETY: AVX-512F is enabled here.
        unsafe { self.corners_lanes::<K, std::arch::x86_64::__m512d>(list, c, out) }
    }

    /// [`BlobField::corners_lanes`] with AVX2, four corners per vector.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn corners_avx2<K: LaneProfile>(
        &self,
        list: &[u32],
        c: [&[f64; 8]; 3],
        out: &mut [f64; 8],
    ) {
        // SAFETY: AVX2 is enabled here.
        unsafe { self.corners_lanes::<K, std::arch::x86_64::__m256d>(list, c, out) }
    }

    /// [`BlobField::block_inside`] with `primitive_fn` adding one primitive's terms
    /// ([`PrimitiveTerms`]) to the planes of pairs it may reach (a range of planes).
    #[inline(always)]
    fn block_inside_with(
        &self,
        list: &[u32],
        block: &BlockCoords,
        primitive_fn: impl Fn(&mut Pairs, &PrimitiveTerms, std::ops::Range<usize>),
    ) -> bool {
        if list.len() > MAX_LIST {
            return false;
        }
        let mut scale = self.threshold.abs();
        for &i in list {
            let a = self.strengths[i as usize];
            // (Strengths are finite: see `PerPrimitive::fill`.)
            if a <= 0.0 {
                return false;
            }
            scale += a;
        }
        let goal = self.threshold + 1e-9 * scale;
        let goal = match self.settings.precision {
            Precision::Double => goal,
            Precision::Single => single::inside_goal(
                self.threshold,
                scale - self.threshold.abs(),
                list.len(),
                goal,
            ),
        };
        let above = |low: &Pairs| low.iter().flatten().flatten().all(|&v| v > goal);
        let BlockCoords { xs, ys, zs, .. } = block;
        // The primitives centred within a quarter of the block's side of its box add the most:
        // they go first, then those within half their radius of it, so that the sum is above
        // the threshold sooner.
        let (lo, hi) = (
            DVec3::new(xs[0], ys[0], zs[0]),
            DVec3::new(
                xs[BLOCK_POINTS - 1],
                ys[BLOCK_POINTS - 1],
                zs[BLOCK_POINTS - 1],
            ),
        );
        let grow = (hi - lo) * 0.25;
        let within = |i: u32, grow: DVec3| {
            let c = self.centers[i as usize];
            c.cmpge(lo - grow).all() && c.cmple(hi + grow).all()
        };
        let (mut first, mut second, mut then) = (Vec::new(), Vec::new(), Vec::new());
        for &i in list {
            if within(i, grow) {
                first.push(i);
            } else if within(i, DVec3::splat(0.5 * self.radii[i as usize])) {
                second.push(i);
            } else {
                then.push(i);
            }
        }
        let mut low: Pairs = [[[0.0; PAIRS]; BLOCK_POINTS]; BLOCK_POINTS];
        for (m, &i) in first.iter().chain(&second).chain(&then).enumerate() {
            let (c, inv, a, r) = self.primitive(i);
            let qx = farthest(std::array::from_fn(|l| {
                ((xs[l] - c.x) * (xs[l] - c.x)) * inv
            }));
            let dy2: [f64; BLOCK_POINTS] = std::array::from_fn(|j| (ys[j] - c.y) * (ys[j] - c.y));
            // Terms left out are bounded below by 0: only the planes and rows the primitive
            // reaches are summed (as in the splat).
            let nearest = qx.iter().fold(f64::INFINITY, |m, &q| m.min(q));
            let term = PrimitiveTerms {
                qx,
                dy2,
                dz2: std::array::from_fn(|k| (zs[k] - c.z) * (zs[k] - c.z)),
                inv,
                nearest,
                a,
            };
            primitive_fn(&mut low, &term, block.planes(c.z, r));
            if m % CHECK_EVERY == CHECK_EVERY - 1 && above(&low) {
                return true;
            }
        }
        above(&low)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::blob::kernel::BlobKernel;
    use crate::field::blob::particles::{colour_field, ParticleSettings};
    use crate::field::blob::{BlobSettings, PerPrimitive};
    use crate::field::{Block, BlockField, BlockSign};
    use crate::lattice::Lattice;
    use crate::testing::jittered_cube;
    use glam::DVec3;

    /// `field` with the threshold `t`.
    fn with_threshold(field: &BlobField, t: f64) -> BlobField {
        BlobField::new(
            field.centers(),
            PerPrimitive::Each(field.radii()),
            PerPrimitive::Each(field.strengths()),
            t,
            field.settings(),
        )
        .unwrap()
    }

    /// The blocks `block_inside` rules out, after checking that every point of each has a
    /// negative value (the splat's bits) on every vector path.
    fn inside_blocks(field: &BlobField, lattice: &Lattice) -> usize {
        let dims = lattice.cells().map(|c| c.div_ceil(BLOCK_POINTS as u32 - 1));
        let lists = field.blocks(lattice, dims);
        let points = lattice.points_per_axis();
        let mut inside = 0;
        for b in 0..dims.iter().product::<u32>() {
            let index = [b % dims[0], b / dims[0] % dims[1], b / dims[0] / dims[1]];
            let lo = index.map(|v| v * 7);
            let n: [u32; 3] = std::array::from_fn(|a| (points[a] - lo[a]).min(8));
            let list = lists.list(index);
            let coords = BlockCoords::new(lattice, lo, n);
            let claims: Vec<bool> = Isa::available()
                .into_iter()
                .chain([Isa::Generic])
                .map(|isa| field.block_inside(isa, list, &coords))
                .collect();
            assert!(claims.iter().all(|&c| c == claims[0]));
            if !claims[0] {
                continue;
            }
            inside += 1;
            let mut values = [0.0; 512];
            field.splat_block(Isa::Generic, list, &coords, &mut values);
            for k in 0..n[2] as usize {
                for j in 0..n[1] as usize {
                    for i in 0..n[0] as usize {
                        let v = values[i + 8 * j + 64 * k];
                        assert!(v < 0.0, "block {index:?}, point {:?}: {v}", [i, j, k]);
                    }
                }
            }
            let block = Block { index, lo, n };
            assert_eq!(field.block_sign(&lists, lattice, &block), BlockSign::Inside);
        }
        inside
    }

    /// Fields of a jittered cube of particles (support 2, cells 1/4) with each kernel, and the
    /// colour field, at thresholds from far below the interior's potential to just below it:
    /// every block ruled out has only inside points, and some are ruled out.
    #[test]
    fn rules_out_only_blocks_inside() {
        let p = jittered_cube(10, 3);
        let lattice = Lattice::new(DVec3::splat(-1.3), DVec3::splat(10.2), [46, 46, 46]).unwrap();
        let mut fields = vec![];
        for kernel in BlobKernel::ALL {
            let settings = BlobSettings {
                kernel,
                ..Default::default()
            };
            let f = BlobField::new(
                &p,
                PerPrimitive::All(2.0),
                PerPrimitive::All(1.0),
                1.0,
                settings,
            );
            fields.push(f.unwrap());
        }
        fields.push(colour_field(&p, 0.5, &ParticleSettings::default()).unwrap());
        for f in &fields {
            let centre = f.potential(DVec3::splat(4.5));
            let mut ruled_out = vec![];
            for share in [0.2, 0.5, 0.65, 0.75, 0.9, 0.97] {
                ruled_out.push(inside_blocks(&with_threshold(f, share * centre), &lattice));
            }
            let kernel = f.settings().kernel;
            assert!(ruled_out[1] > 0, "{kernel:?}: {ruled_out:?}");
            assert!(ruled_out.windows(2).all(|w| w[0] >= w[1]), "{ruled_out:?}");
        }
    }

    /// A negative strength in a block's list: no bound (the terms no longer only add).
    #[test]
    fn negative_strengths_are_never_ruled_out() {
        let p = jittered_cube(6, 5);
        let mut a = vec![1.0; p.len()];
        a[0] = -1e-3;
        let f = BlobField::new(
            &p,
            PerPrimitive::All(2.0),
            PerPrimitive::Each(&a),
            0.1,
            BlobSettings::default(),
        )
        .unwrap();
        let lattice = Lattice::new(DVec3::splat(-0.5), DVec3::splat(5.5), [24, 24, 24]).unwrap();
        let all: Vec<u32> = (0..p.len() as u32).collect();
        let coords = BlockCoords::new(&lattice, [7, 7, 7], [8, 8, 8]);
        assert!(!f.block_inside(Isa::detect(), &all, &coords));
        assert!(f.block_inside(Isa::detect(), &all[1..], &coords));
    }
}
