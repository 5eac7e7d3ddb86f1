//! What a subdivision is asked to do ([`SubdivisionSettings`]) and what each level did
//! ([`LevelStats`]).

use crate::error::{Error, Result};

/// How the new vertices are projected onto the surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SubdivisionSettings {
    /// Newton stops when its step is shorter than `tolerance` × the local edge length (half the
    /// parent edge), when the next step predicted from quadratic convergence is (see
    /// `PREDICT_MARGIN`; the step is then taken without a confirming evaluation), or when a step
    /// below 1e-6 × that length no longer halves (the rounding noise of the field); the bisection
    /// fallback stops when its bracket is that short.
    pub tolerance: f64,
    /// Most Newton steps per vertex and level before the fallback takes over.
    pub max_iterations: u32,
    /// Longest Newton step, as a multiple of the local edge length.
    pub max_step: f64,
    /// Newton gives up on a vertex that wanders further than this multiple of the local edge
    /// length from its midpoint (it would land on another part of the surface).
    pub max_distance: f64,
    /// The fallback looks for a sign change along the gradient line within ± this multiple of the
    /// local edge length from the midpoint.
    pub search_range: f64,
    /// Samples per side of that search.
    pub search_samples: u32,
    /// Compute vertex normals from the field's gradient.
    pub normals: bool,
    /// Refuse requests whose finest level would need more than this many bytes.
    pub memory_limit: u64,
}

impl Default for SubdivisionSettings {
    fn default() -> Self {
        SubdivisionSettings {
            tolerance: 1e-9,
            max_iterations: 30,
            max_step: 0.5,
            max_distance: 4.0,
            search_range: 4.0,
            search_samples: 16,
            normals: true,
            memory_limit: 4 << 30,
        }
    }
}

impl SubdivisionSettings {
    /// Errors naming the Python argument of the first setting out of range.
    pub(super) fn check(&self) -> Result<()> {
        if !(self.tolerance.is_finite() && self.tolerance > 0.0 && self.tolerance < 1.0) {
            return Err(Error::invalid(
                "tolerance",
                format!("must be in (0, 1), got {}", self.tolerance),
            ));
        }
        if self.max_iterations == 0 || self.max_iterations > 10_000 {
            return Err(Error::invalid(
                "max_steps",
                format!("must be between 1 and 10000, got {}", self.max_iterations),
            ));
        }
        for (name, v) in [
            ("max_step", self.max_step),
            ("max_distance", self.max_distance),
            ("search_range", self.search_range),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::invalid(
                    name,
                    format!("must be finite and positive, got {v}"),
                ));
            }
        }
        if self.search_samples == 0 || self.search_samples > 1000 {
            return Err(Error::invalid(
                "search_samples",
                format!("must be between 1 and 1000, got {}", self.search_samples),
            ));
        }
        Ok(())
    }
}

/// Per-level statistics: what the projection of one level did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LevelStats {
    /// Subdivision level (0: the control mesh).
    pub level: usize,
    /// New vertices projected at this level.
    pub projected: usize,
    /// Field evaluations (value and gradient) per projected vertex during Newton: mean and max.
    pub iterations_mean: f64,
    /// The largest of those counts.
    pub iterations_max: u32,
    /// Points evaluated in total (Newton, fallback, and the fallback's points once more for their
    /// normals; Newton's points reuse the gradient of their last step, the old vertices theirs).
    pub evaluations: u64,
    /// Batched field calls made.
    pub batches: u64,
    /// Vertices for which Newton failed and the line search along the gradient took over.
    pub fallbacks: usize,
    /// Vertices left off the surface (no sign change found): they keep the point of smallest |f|
    /// seen.
    pub not_converged: usize,
    /// Largest |f| among the vertices that did not converge (0 when all did).
    pub not_converged_max_abs_value: f64,
    /// Largest |f| over the new vertices of this level after projection: for Newton's vertices the
    /// value of their last evaluation, before a final step shorter than the tolerance (so an upper
    /// bound to rounding), or, for a final step accepted by its predicted successor (see
    /// [`SubdivisionSettings::tolerance`]), the value predicted after it, f (len / last)²; for the
    /// fallback's vertices the value at the final point.
    pub max_abs_value: f64,
    /// Wall-clock seconds for the level (split, projection, normals).
    pub seconds: f64,
}
