//! What the octree's store knows of a lattice point, in one byte.

use std::sync::atomic::{AtomicU8, Ordering::Relaxed};

/// A point's state: nothing known ([`PointState::UNKNOWN`]), claimed and not yet evaluated
/// ([`PointState::QUEUED`]), a sign inferred without a value, or a value (whose index the point's
/// slot holds). Bit 1: the sign is known; bit 0 with it: negative; bit 2: a value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(transparent)]
pub(super) struct PointState(u8);

impl PointState {
    pub(super) const UNKNOWN: Self = Self(0);
    pub(super) const QUEUED: Self = Self(0b001);
    /// A sign inferred (zero or positive), no value; see `settle_leaves`.
    pub(super) const INFERRED_POSITIVE: Self = Self(0b010);
    /// A sign inferred (negative), no value.
    pub(super) const INFERRED_NEGATIVE: Self = Self(0b011);
    /// A value, zero or positive.
    pub(super) const VALUE_POSITIVE: Self = Self(0b110);
    /// A value, negative.
    pub(super) const VALUE_NEGATIVE: Self = Self(0b111);

    /// The state of a point with value `v`.
    #[inline]
    pub(super) fn of_value(v: f64) -> Self {
        if v < 0.0 {
            Self::VALUE_NEGATIVE
        } else {
            Self::VALUE_POSITIVE
        }
    }

    /// The state of a point with a sign inferred.
    #[inline]
    pub(super) fn inferred(negative: bool) -> Self {
        if negative {
            Self::INFERRED_NEGATIVE
        } else {
            Self::INFERRED_POSITIVE
        }
    }

    /// Whether the point has a sign, inferred or from its value.
    #[inline]
    pub(super) fn has_sign(self) -> bool {
        self.0 & 0b010 != 0
    }

    /// Whether the point is known to be negative.
    #[inline]
    pub(super) fn is_negative(self) -> bool {
        self.0 & 0b011 == 0b011
    }

    /// Whether the point is known to be zero or positive.
    #[inline]
    pub(super) fn is_positive(self) -> bool {
        self.0 & 0b011 == 0b010
    }

    /// Whether the point has a sign inferred and no value.
    #[inline]
    pub(super) fn is_inferred(self) -> bool {
        self.0 & 0b110 == 0b010
    }

    /// Whether the point has a value.
    #[inline]
    pub(super) fn has_value(self) -> bool {
        self.0 & 0b100 != 0
    }
}

/// A point's state, read and written from several threads.
#[repr(transparent)]
pub(super) struct AtomicPointState(AtomicU8);

impl AtomicPointState {
    /// Claims the point for evaluation (unknown → queued) when nothing is known of it; returns
    /// whether this call claimed it.
    #[inline]
    pub(super) fn claim(&self) -> bool {
        let (unknown, queued) = (PointState::UNKNOWN.0, PointState::QUEUED.0);
        // (Most points are known: a plain read first.)
        self.0.load(Relaxed) == unknown
            && self
                .0
                .compare_exchange(unknown, queued, Relaxed, Relaxed)
                .is_ok()
    }

    /// Stores a sign inferred when nothing is known of the point; returns the point's state
    /// after (the sign given, or what another thread or an earlier step stored).
    #[inline]
    pub(super) fn infer(&self, negative: bool) -> PointState {
        let (unknown, inferred) = (PointState::UNKNOWN.0, PointState::inferred(negative).0);
        // Most points are shared: a plain read first spares the atomic write where a
        // neighbour stored the sign already.
        let now = self.0.load(Relaxed);
        if now != unknown {
            return PointState(now);
        }
        match self.0.compare_exchange(unknown, inferred, Relaxed, Relaxed) {
            Ok(_) => PointState(inferred),
            Err(now) => PointState(now),
        }
    }
}

/// `v` as atomics, for writes from several threads (the exclusive borrow guarantees that no one
/// else reads it meanwhile).
pub(super) fn atomic_states(v: &mut [PointState]) -> &[AtomicPointState] {
    // SAFETY: PointState is a transparent u8 and AtomicPointState a transparent AtomicU8, which
    // has u8's size and alignment; the exclusive borrow means every access for its lifetime
    // goes through the atomics.
    unsafe { &*(v as *mut [PointState] as *const [AtomicPointState]) }
}
