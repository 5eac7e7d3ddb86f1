//! Blob fields in single precision ([`Precision::Single`]): lattice values, block values and
//! point values computed in f32 and widened to f64, so that every polygonizer reads the same
//! values; vertices (placed from the widened values) and normals (gradients, always in f64)
//! stay f64.
//!
//! Every evaluation computes a term the same way: dx²/R² and k = 1 − (dy² + dz²)/R² in f64, in
//! the order of [`super::point::unit_t`], each rounded to f32; then t = k − dx²/R², the profile
//! ([`Profile::value`] in f32) and A·w(t) in f32 (A rounded to f32). The terms are summed in
//! f32 in index order from 0 and the value is threshold − F in f32 (the threshold rounded). So
//! point, lattice-plane and block evaluations give the same bits, as in double precision; the
//! block splat takes two rows of a block per AVX-512 vector of 16 lanes.
//!
//! **Rounding.** With u = 2⁻²⁴, each term differs from the exact A·w(t) by at most 83·u·|A|
//! (the roundings of k, dx²/R² and t, at most 3.1u in t, times the profile's largest slope in
//! t, 10 for Wendland; the profile's own f32 evaluation, at most 50u; A's rounding and the
//! product), the f32 sum of n terms from the exact sum of those terms by at most (n − 1)·u
//! times the sum of their magnitudes (for n·u small), and the rounded threshold from the
//! threshold by u times it. The difference threshold − F keeps its sign when rounded. A block
//! ruled out from bounds in double precision is ruled out in single precision only when the
//! bounds leave the threshold out by twice the sum of these ([`rounding`]), so that the f32
//! values provably have the sign claimed.

use super::block::BlockCoords;
use super::plane::RowTerm;
use super::BlobField;
use crate::error::{Error, Result};
#[cfg(target_arch = "x86_64")]
use crate::field::blob::kernel::LaneProfile;
use crate::field::blob::kernel::{with_profile, Profile};
use crate::lattice::Lattice;
use crate::simd::Isa;
use glam::DVec3;

/// The float type a blob field's values are computed in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Precision {
    /// f64 throughout.
    #[default]
    Double,
    /// Values in f32 (see the module docs); vertices and normals in f64.
    Single,
}

impl Precision {
    /// The names [`Precision::parse`] reads, in the order of the variants.
    pub const NAMES: [&'static str; 2] = ["double", "single"];

    /// The precision's name (`"double"` or `"single"`).
    pub fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }

    /// The precision called `name`; an error names the argument `precision`.
    pub fn parse(name: &str) -> Result<Precision> {
        match name {
            "double" => Ok(Precision::Double),
            "single" => Ok(Precision::Single),
            _ => Err(Error::invalid(
                "precision",
                format!(
                    "unknown precision {name:?}; expected one of {:?}",
                    Self::NAMES
                ),
            )),
        }
    }
}

/// u = 2⁻²⁴, the unit roundoff of f32.
const UNIT: f64 = 1.0 / 16_777_216.0;

/// A bound on one term's error in units of u·|A| (83 by the module docs, rounded up).
const TERM_ERROR: f64 = 128.0;

/// Lists longer than this are never ruled out in single precision (the sum's error bound needs
/// n·u small).
const MAX_LIST: usize = 1 << 20;

/// The widening of the double-precision margin for single precision: twice the bound of the
/// module docs on |f32 value − exact value| at a point reached by `n` primitives whose
/// strengths' magnitudes sum to `strengths` and whose terms' magnitudes sum to at most
/// `terms`. Infinite for lists over [`MAX_LIST`].
pub(super) fn rounding(threshold: f64, strengths: f64, terms: f64, n: usize) -> f64 {
    if n > MAX_LIST {
        return f64::INFINITY;
    }
    2.0 * UNIT * (threshold.abs() + TERM_ERROR * strengths + (n as f64 + 1.0) * terms)
}

/// The lower bound the potential must exceed for the f32 values to be provably inside, from
/// the double-precision `goal`: with F the exact potential, the f32 potential is at least
/// F·(1 − 2(n + 1)u) − 2u·128·Σ A, and the rounded threshold at most the threshold·(1 + u).
pub(super) fn inside_goal(threshold: f64, strengths: f64, n: usize, goal: f64) -> f64 {
    if n > MAX_LIST {
        return f64::INFINITY;
    }
    let shrink = 1.0 - 2.0 * UNIT * (n as f64 + 1.0);
    (goal + 2.0 * UNIT * (threshold.abs() + TERM_ERROR * strengths)) / shrink
}

/// A·w(k − dx²/R²) in f32 from k and dx²/R² in f64 (see the module docs).
#[inline(always)]
pub(super) fn term<K: Profile>(k: f64, qx: f64, a: f32) -> f32 {
    a * K::value(k as f32 - qx as f32)
}

/// Adds the f32 terms of one primitive to a row of a lattice plane (as [`splat_row`](super::plane::splat_row)).
#[inline(always)]
fn splat_row<K: Profile>(row: &mut [f32], xs: &[f64], q: &RowTerm) {
    let a = q.a as f32;
    for (v, &x) in row.iter_mut().zip(xs) {
        let dx = x - q.cx;
        *v += term::<K>(q.k, (dx * dx) * q.inv, a);
    }
}

impl BlobField {
    /// The potential at `p` in f32 from the voxel lists, in index order.
    #[inline(always)]
    pub(super) fn potential_single<K: Profile>(&self, p: DVec3) -> f32 {
        let packed = self.packed();
        let mut f = 0.0f32;
        for &i in self.grid().candidates(p) {
            let q = &packed[i as usize];
            let d = p - q.center;
            let k = 1.0 - (d.y * d.y + d.z * d.z) * q.inv_r2;
            f += term::<K>(k, (d.x * d.x) * q.inv_r2, q.strength as f32);
        }
        f
    }

    /// threshold − F at `p` in f32, widened.
    #[inline(always)]
    pub(super) fn value_single<K: Profile>(&self, p: DVec3) -> f64 {
        (self.threshold as f32 - self.potential_single::<K>(p)) as f64
    }

    /// One z-plane of lattice values in f32, widened into `slab` (see
    /// [`BlobField::splat_plane_with`]).
    pub(super) fn splat_plane_single<K: Profile>(
        &self,
        lattice: &Lattice,
        [xs, ys]: [&[f64]; 2],
        z: f64,
        slab: &mut [f64],
    ) {
        let mut v = vec![0.0f32; slab.len()];
        self.splat_plane_with(lattice, xs, ys, z, &mut v, splat_row::<K>);
        for (o, v) in slab.iter_mut().zip(&v) {
            *o = *v as f64;
        }
    }

    /// A block's values in f32 from the primitives of `list` with the vector path of `isa`
    /// (which the CPU must have), widened into `out`: the same bits on every path and as
    /// [`BlobField::splat_plane_single`].
    pub(super) fn splat_block_single(
        &self,
        isa: Isa,
        list: &[u32],
        block: &BlockCoords,
        out: &mut [f64; 512],
    ) {
        let mut v = [0.0f32; 512];
        with_profile!(self.settings.kernel, K => match isa {
            // SAFETY: the caller passes an instruction set the CPU has.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => unsafe { self.splat_block_single_avx512::<K>(list, block, &mut v) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe {
                self.splat_block_lanes_avx2::<K, std::arch::x86_64::__m256>(list, block, &mut v)
            },
            Isa::Generic => self.splat_block_generic::<K, f32>(list, block, &mut v),
        });
        for (o, v) in out.iter_mut().zip(v) {
            *o = v as f64;
        }
    }

    /// [`BlobField::splat_block_with`] in f32 with AVX-512: per primitive, dx²/R² in f64 is one
    /// vector, rounded to f32 and repeated in both halves of a 16-lane vector; per plane the
    /// rows' k another, compared with the nearest lane's dx²/R² for the mask of rows to splat
    /// (as in double precision), and the rows are splatted two at a time (rows 2m and 2m + 1
    /// when either is in the mask: a row out of the mask gains +0.0 or −0.0, which changes no
    /// sum started from +0.0). The operations on each value are [`term`]'s, so the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn splat_block_single_avx512<K: LaneProfile>(
        &self,
        list: &[u32],
        block: &BlockCoords,
        out: &mut [f32; 512],
    ) {
        use std::arch::x86_64::*;
        let BlockCoords { xs, ys, zs, n, .. } = block;
        let in_block = ((1u32 << n[1]) - 1) as __mmask8;
        out.fill(0.0);
        // SAFETY: the coordinate arrays hold eight f64 each.
        let (vx, vy) = unsafe { (_mm512_loadu_pd(xs.as_ptr()), _mm512_loadu_pd(ys.as_ptr())) };
        let one = _mm512_set1_pd(1.0);
        // Lanes 0..8 read row j, lanes 8..16 row j + 1.
        let pair = _mm512_set_epi32(1, 1, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0);
        for &i in list {
            let (c, inv, a, r) = self.primitive(i);
            let vinv = _mm512_set1_pd(inv);
            let dx = _mm512_sub_pd(vx, _mm512_set1_pd(c.x));
            let qx = _mm512_mul_pd(_mm512_mul_pd(dx, dx), vinv);
            let near = _mm512_set1_pd(_mm512_reduce_min_pd(qx));
            let q8 = _mm512_castps256_ps512(_mm512_cvtpd_ps(qx));
            let q16 = _mm512_shuffle_f32x4::<0b01_00_01_00>(q8, q8);
            let dy = _mm512_sub_pd(vy, _mm512_set1_pd(c.y));
            let dy2 = _mm512_mul_pd(dy, dy);
            let va = _mm512_set1_ps(a as f32);
            let planes = block.planes(c.z, r);
            for k in planes {
                let dz = zs[k] - c.z;
                let ks = _mm512_sub_pd(
                    one,
                    _mm512_mul_pd(_mm512_add_pd(dy2, _mm512_set1_pd(dz * dz)), vinv),
                );
                let rows = _mm512_mask_cmp_pd_mask::<_CMP_GT_OQ>(in_block, ks, near) as u32;
                if rows == 0 {
                    continue;
                }
                let k8 = _mm512_castps256_ps512(_mm512_cvtpd_ps(ks));
                let mut pairs = (rows | rows >> 1) & 0x55;
                while pairs != 0 {
                    let j = pairs.trailing_zeros() as usize;
                    pairs &= pairs - 1;
                    let kj = _mm512_permutexvar_ps(
                        _mm512_add_epi32(pair, _mm512_set1_epi32(j as i32)),
                        k8,
                    );
                    // SAFETY: the caller runs where AVX-512F is.
                    let w = unsafe { K::value_lanes(_mm512_sub_ps(kj, q16)) };
                    // SAFETY: 8j + 64k + 16 ≤ 512 (j ≤ 6 even, k < 8).
                    unsafe {
                        let p = out.as_mut_ptr().add(8 * j + 64 * k);
                        _mm512_storeu_ps(
                            p,
                            _mm512_add_ps(_mm512_loadu_ps(p), _mm512_mul_ps(va, w)),
                        );
                    }
                }
            }
        }
        let th = _mm512_set1_ps(self.threshold as f32);
        for row in out.chunks_exact_mut(16) {
            // SAFETY: sixteen f32.
            unsafe {
                let p = row.as_mut_ptr();
                _mm512_storeu_ps(p, _mm512_sub_ps(th, _mm512_loadu_ps(p)));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::blob::kernel::BlobKernel;
    use crate::field::blob::{BlobSettings, PerPrimitive};
    use crate::field::{Block, BlockField, BlockSign, BLOCK_POINTS};
    use crate::testing::jittered_cube;

    #[test]
    fn names_parse() {
        for p in [Precision::Double, Precision::Single] {
            assert_eq!(Precision::parse(p.name()), Ok(p));
        }
        assert!(Precision::parse("f32").is_err());
    }

    /// In single precision, every block ruled out (from box bounds, octants or pairs of points)
    /// has the sign claimed at each of its f32 values, on every vector path; blocks of each
    /// kind occur.
    #[test]
    fn ruled_out_blocks_have_their_sign() {
        let p = jittered_cube(10, 3);
        let lattice = Lattice::new(DVec3::splat(-2.3), DVec3::splat(11.2), [54, 54, 54]).unwrap();
        let dims = lattice.cells().map(|c| c.div_ceil(BLOCK_POINTS as u32 - 1));
        let points = lattice.points_per_axis();
        for kernel in BlobKernel::ALL {
            for share in [0.3, 0.6, 0.9] {
                let settings = BlobSettings {
                    kernel,
                    precision: Precision::Single,
                    ..Default::default()
                };
                let field = |t: f64| {
                    let (r, a) = (PerPrimitive::All(2.0), PerPrimitive::All(1.0));
                    BlobField::new(&p, r, a, t, settings).unwrap()
                };
                let centre = field(1.0).potential(DVec3::splat(4.5));
                let f = field(share * centre);
                let lists = f.blocks(&lattice, dims);
                let mut counts = [0usize; 3];
                for b in 0..dims.iter().product::<u32>() {
                    let index = [b % dims[0], b / dims[0] % dims[1], b / dims[0] / dims[1]];
                    let lo = index.map(|v| v * 7);
                    let n: [u32; 3] = std::array::from_fn(|a| (points[a] - lo[a]).min(8));
                    let sign = f.block_sign(&lists, &lattice, &Block { index, lo, n });
                    counts[sign as usize] += 1;
                    if sign == BlockSign::Mixed {
                        continue;
                    }
                    let coords = BlockCoords::new(&lattice, lo, n);
                    for isa in Isa::available() {
                        let mut v = [0.0; 512];
                        f.splat_block(isa, lists.list(index), &coords, &mut v);
                        for k in 0..n[2] as usize {
                            for j in 0..n[1] as usize {
                                for i in 0..n[0] as usize {
                                    let v = v[i + 8 * j + 64 * k];
                                    let ok = match sign {
                                        BlockSign::Outside => v > 0.0,
                                        _ => v < 0.0,
                                    };
                                    assert!(ok, "{kernel:?} {share} {index:?} {sign:?}: {v}");
                                }
                            }
                        }
                    }
                }
                // (Close to the interior's potential, no block is provably inside.)
                let inside = share > 0.8 || counts[BlockSign::Inside as usize] > 0;
                assert!(
                    counts[0] > 0 && counts[2] > 0 && inside,
                    "{kernel:?} {share}: {counts:?}"
                );
            }
        }
    }
}
