//! Proving a block has one sign without computing its values: bounds on each listed
//! primitive's term over the block's box ([`BlobField::box_sign`]) or over its eight octants,
//! and for blocks inside the surface the bounds over pairs of points of the `interior` module;
//! the proof that settled a block is the hint it leaves for the next frame
//! ([`splatted_proof`]).

use super::block::BlockCoords;
use super::hints::{Proof, ONE_SIGN_FRAMES};
use super::kernel::{with_profile, Profile};
use super::lists::{block_box, BlockLists};
use super::single;
use super::{BlobField, Precision};
use crate::field::{Block, BlockSign};
use crate::lattice::Lattice;
use crate::simd::Isa;
use glam::DVec3;

impl BlobField {
    /// The sign of `block` as [`BlockField::block_sign`](crate::field::BlockField::block_sign) proves it, and the proof that did
    /// ([`Proof::Unknown`]: the box bounds, or none). The proof `hint` names goes first and
    /// alone: [`Proof::Crossed`] tries none.
    pub(super) fn block_sign_by(
        &self,
        blocks: &BlockLists,
        lattice: &Lattice,
        block: &Block,
        hint: Proof,
    ) -> (BlockSign, Proof) {
        let Block { index: b, lo, n } = *block;
        let list = blocks.list(b);
        let inside = |coords: &BlockCoords| {
            if self.block_inside(Isa::detect(), list, coords) {
                (BlockSign::Inside, Proof::Pairs)
            } else {
                (BlockSign::Mixed, Proof::Unknown)
            }
        };
        let octants = || {
            if self.octants_outside(list, lattice, lo, n) {
                (BlockSign::Outside, Proof::Octants)
            } else {
                (BlockSign::Mixed, Proof::Unknown)
            }
        };
        match hint {
            Proof::Crossed | Proof::OneSign { .. } => return (BlockSign::Mixed, Proof::Unknown),
            Proof::Pairs => return inside(&BlockCoords::new(lattice, lo, n)),
            Proof::Octants => return octants(),
            Proof::Unknown => {}
        }
        let (plo, phi) = block_box(lattice, b);
        let sign = self.box_sign(list, plo, phi);
        if sign != BlockSign::Mixed {
            return (sign, Proof::Unknown);
        }
        // Inside the surface, the bounds over boxes of many points are loose (each term's
        // smallest value is at the box's farthest corner): bound pairs of points instead, when
        // the potential is above the threshold at the block's eight corners (most blocks the
        // surface crosses have a corner outside, found at the cost of a term per primitive and
        // corner).
        let coords = BlockCoords::new(lattice, lo, n);
        if self.corners_inside(Isa::detect(), list, &coords) {
            return inside(&coords);
        }
        octants()
    }

    /// The sign the field provably has on the box `[plo, phi]` (from each primitive of `list`,
    /// which must hold every primitive reaching the box: its term lies between its values at
    /// the nearest and the farthest point of the box), or [`BlockSign::Mixed`]. The margin,
    /// 1e-9 of the strengths' sum, is far above rounding.
    pub(super) fn box_sign(&self, list: &[u32], plo: DVec3, phi: DVec3) -> BlockSign {
        with_profile!(self.settings.kernel, K => self.box_sign_with::<K>(list, plo, phi))
    }

    /// [`BlobField::box_sign`] with the profile `K`.
    #[inline(always)]
    fn box_sign_with<K: Profile>(&self, list: &[u32], plo: DVec3, phi: DVec3) -> BlockSign {
        let (mut fmin, mut fmax, mut scale) = (0.0f64, 0.0f64, self.threshold.abs());
        let mut terms = 0.0f64;
        for &i in list {
            let i = i as usize;
            let (c, inv, a) = (self.centers[i], self.inv_r2[i], self.strengths[i]);
            let (near, far) = box_distances2(c, plo, phi);
            let (big, small) = (
                a * K::value(1.0 - near * inv),
                a * K::value(1.0 - far * self.far_inv(i)),
            );
            fmax += big.max(small);
            fmin += big.min(small);
            terms += big.abs().max(small.abs());
            scale += a.abs();
        }
        let margin = 1e-9 * scale
            + match self.settings.precision {
                Precision::Double => 0.0,
                Precision::Single => single::rounding(
                    self.threshold,
                    scale - self.threshold.abs(),
                    terms,
                    list.len(),
                ),
            };
        if fmax < self.threshold - margin {
            BlockSign::Outside
        } else if fmin > self.threshold + margin {
            BlockSign::Inside
        } else {
            BlockSign::Mixed
        }
    }

    /// Whether the bounds over each of the block's eight octants (points 0..=3 and 4..=7 per
    /// axis) prove it outside: outside the surface the bounds over the whole block are loose
    /// where many terms overlap. Stops at the first octant that may be crossed; false for a
    /// block of at most four points along an axis.
    fn octants_outside(&self, list: &[u32], lattice: &Lattice, lo: [u32; 3], n: [u32; 3]) -> bool {
        if !n.iter().all(|&v| v > 4) {
            return false;
        }
        let half = |a: usize, s: u32| -> (u32, u32) {
            if s == 0 {
                (lo[a], lo[a] + 3)
            } else {
                (lo[a] + 4, lo[a] + n[a] - 1)
            }
        };
        (0..8u32).all(|o| {
            let (x, y, z) = (half(0, o & 1), half(1, (o >> 1) & 1), half(2, o >> 2));
            let (plo, phi) = (
                lattice.point([x.0, y.0, z.0]),
                lattice.point([x.1, y.1, z.1]),
            );
            self.box_sign(list, plo, phi) == BlockSign::Outside
        })
    }
}

/// Squared distances from `c` to the nearest and the farthest point of the box `[lo, hi]`.
#[inline(always)]
pub(super) fn box_distances2(c: DVec3, lo: DVec3, hi: DVec3) -> (f64, f64) {
    let near = (lo - c).max(c - hi).max(DVec3::ZERO);
    let far = (c - lo).abs().max((hi - c).abs());
    (near.length_squared(), far.length_squared())
}

/// The hint a block leaves for the next frame: the `proof` of its `sign`, or when it was
/// splatted, [`Proof::Crossed`] if its values have both signs (`crossed`), else
/// [`Proof::OneSign`] after proofs (for [`ONE_SIGN_FRAMES`] frames, counted down by the splats
/// without proofs that follow), and [`Proof::Unknown`] after a splat without proofs that ends
/// the count or follows a crossed frame: the next frame proves it again.
pub(super) fn splatted_proof(
    sign: BlockSign,
    proof: Proof,
    hint: Proof,
    crossed: impl FnOnce() -> bool,
) -> Proof {
    if sign != BlockSign::Mixed {
        proof
    } else if crossed() {
        Proof::Crossed
    } else {
        match hint {
            Proof::Crossed | Proof::OneSign { frames: 0 } => Proof::Unknown,
            Proof::OneSign { frames } => Proof::OneSign { frames: frames - 1 },
            _ => Proof::OneSign {
                frames: ONE_SIGN_FRAMES - 1,
            },
        }
    }
}

/// Whether the values of a block of `n` points per axis have both signs (inside: below zero).
pub(super) fn both_signs(values: &[f64; 512], n: [u32; 3]) -> bool {
    let (mut inside, mut outside) = (false, false);
    for plane in values.chunks_exact(64).take(n[2] as usize) {
        for row in plane.chunks_exact(8).take(n[1] as usize) {
            for &v in &row[..n[0] as usize] {
                inside |= v < 0.0;
                outside |= v >= 0.0;
            }
        }
    }
    inside && outside
}
