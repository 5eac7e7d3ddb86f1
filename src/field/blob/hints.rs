//! Which proof settled each block's sign in the last polygonization of a lattice, kept beside
//! the block lists (the `kept` module) for the next frame of an animation: a block crossed by
//! the surface in the last frame is splatted at once (so is one whose proofs failed and whose
//! values had one sign, every other frame), one proved inside from pairs of points or outside
//! from its octants goes straight to that proof. A hint only orders the work: every
//! sign claimed is still proved on this frame's field, and a block splatted without proofs
//! gives its values, so the mesh is the one without hints.

use std::sync::atomic::{AtomicU8, Ordering};

/// How a block's sign was found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub(crate) enum Proof {
    /// Nothing known: every proof in turn.
    Unknown = 0,
    /// Inside from the bounds over pairs of points ([`super::BlobField::block_inside`]).
    Pairs = 1,
    /// Outside from the bounds over the block's eight octants.
    Octants = 2,
    /// Splatted, and its values had both signs.
    Crossed = 3,
    /// Splatted after proofs that failed, and its values had one sign: splatted again without
    /// proofs in the next frame, then proved again in the one after.
    OneSign = 4,
}

impl Proof {
    fn from_u8(v: u8) -> Proof {
        match v {
            1 => Proof::Pairs,
            2 => Proof::Octants,
            3 => Proof::Crossed,
            4 => Proof::OneSign,
            _ => Proof::Unknown,
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
            h.store(proof as u8, Ordering::Relaxed);
        }
    }
}
