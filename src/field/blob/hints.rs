//! Which proof settled each block's sign in the last polygonization of a lattice, kept beside
//! the block lists (the `kept` module) for the next frame of an animation: a block crossed by
//! the surface in the last frame is splatted at once (so is one whose proofs failed and whose
//! values had one sign, for the next [`ONE_SIGN_FRAMES`] frames), one proved inside from pairs of points or outside
//! from its octants goes straight to that proof. A hint only orders the work: every
//! sign claimed is still proved on this frame's field, and a block splatted without proofs
//! gives its values, so the mesh is the one without hints.

use std::sync::atomic::{AtomicU8, Ordering};

/// How a block's sign was found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Proof {
    /// Nothing known: every proof in turn.
    Unknown,
    /// Inside from the bounds over pairs of points ([`super::BlobField::block_inside`]).
    Pairs,
    /// Outside from the bounds over the block's eight octants.
    Octants,
    /// Splatted, and its values had both signs.
    Crossed,
    /// Splatted after proofs that failed (or splatted without proofs since), and its values had
    /// one sign: splatted without proofs in the next `frames` frames while its values keep one
    /// sign, then proved again ([`ONE_SIGN_FRAMES`]).
    OneSign {
        /// Frames left to splat without proofs, after the next.
        frames: u8,
    },
}

/// Frames a block whose proofs failed and whose values had one sign is splatted without proofs
/// before they are tried again: a block near the surface whose proofs fail once (bounds too
/// loose for it) mostly fails again, and a failed proof costs about half a splat.
pub(crate) const ONE_SIGN_FRAMES: u8 = 8;

impl Proof {
    fn from_u8(v: u8) -> Proof {
        match v {
            1 => Proof::Pairs,
            2 => Proof::Octants,
            3 => Proof::Crossed,
            v if v >= 4 => Proof::OneSign { frames: v - 4 },
            _ => Proof::Unknown,
        }
    }

    fn to_u8(self) -> u8 {
        match self {
            Proof::Unknown => 0,
            Proof::Pairs => 1,
            Proof::Octants => 2,
            Proof::Crossed => 3,
            Proof::OneSign { frames } => 4 + frames.min(u8::MAX - 4),
        }
    }
}

/// One [`Proof`] per block of a lattice (x fastest), read and written by the tasks that
/// polygonize it.
#[derive(Default)]
pub(crate) struct Hints(Vec<AtomicU8>);

impl Hints {
    /// `blocks` blocks, nothing known.
    pub(crate) fn new(blocks: usize) -> Hints {
        Hints((0..blocks).map(|_| AtomicU8::new(0)).collect())
    }

    /// The blocks hinted.
    pub(crate) fn len(&self) -> usize {
        self.0.len()
    }

    /// The proof of block `k` in the last frame ([`Proof::Unknown`] beyond the blocks).
    #[inline]
    pub(crate) fn get(&self, k: usize) -> Proof {
        self.0.get(k).map_or(Proof::Unknown, |h| {
            Proof::from_u8(h.load(Ordering::Relaxed))
        })
    }

    /// Records the proof of block `k` in this frame.
    #[inline]
    pub(crate) fn set(&self, k: usize, proof: Proof) {
        if let Some(h) = self.0.get(k) {
            h.store(proof.to_u8(), Ordering::Relaxed);
        }
    }
}
