//! The one error type of the core. The Python layer maps every variant to a Python exception
//! (`ValueError` for bad input) in one place, `src/python/errors.rs`.

/// Everything that can go wrong in the core. Messages name the argument at fault so that they can
/// be shown to a user as they are.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum Error {
    /// An argument has a value the function cannot use (the message says which and why).
    #[error("{name}: {reason}")]
    InvalidArgument {
        /// The argument, as the caller named it.
        name: &'static str,
        /// What is wrong with its value.
        reason: String,
    },
    /// A coordinate or value that must be finite is NaN or infinite.
    #[error("{name}: entry {index} is not finite (NaN or infinity)")]
    NotFinite {
        /// The argument.
        name: &'static str,
        /// The first entry that is not finite.
        index: usize,
    },
    /// A request whose memory estimate exceeds the allowed limit.
    #[error("{name}: this needs about {needed_mib} MiB, over the limit of {limit_mib} MiB (memory_limit); lower it or raise `memory_limit`")]
    TooMuchMemory {
        /// The argument that asks for the memory.
        name: &'static str,
        /// The estimate, in MiB.
        needed_mib: u64,
        /// The limit, in MiB.
        limit_mib: u64,
    },
    /// The interpolation system could not be solved to the required accuracy.
    #[error("the interpolation system is singular or too ill-conditioned (residual {residual:.3e}); points much closer together than the rest (merge them with a larger `merge_distance`) or degenerate data cause this")]
    SingularSystem {
        /// The largest residual of the solution found.
        residual: f64,
    },
    /// A field returned NaN or infinity at a point the polygonizer needed.
    #[error("field: returned a non-finite value at point ({x}, {y}, {z})")]
    FieldNotFinite {
        /// x of the point.
        x: f64,
        /// y of the point.
        y: f64,
        /// z of the point.
        z: f64,
    },
    /// The call was told to stop (see [`crate::cancel`]).
    #[error("interrupted")]
    Interrupted,
}

/// Result with the core's [`Error`].
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// Shorthand for [`Error::InvalidArgument`].
    pub fn invalid(name: &'static str, reason: impl Into<String>) -> Self {
        Error::InvalidArgument {
            name,
            reason: reason.into(),
        }
    }
}

/// Checks that every coordinate of `points` is finite.
pub fn check_finite_points(name: &'static str, points: &[glam::DVec3]) -> Result<()> {
    match points.iter().position(|p| !p.is_finite()) {
        Some(index) => Err(Error::NotFinite { name, index }),
        None => Ok(()),
    }
}

/// Checks that every value is finite.
pub fn check_finite_values(name: &'static str, values: &[f64]) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(Error::NotFinite { name, index }),
        None => Ok(()),
    }
}

/// Errors with [`Error::TooMuchMemory`], naming argument `name`, when `bytes` exceed `limit`.
pub fn check_memory(name: &'static str, bytes: u64, limit: u64) -> Result<()> {
    if bytes > limit {
        return Err(Error::TooMuchMemory {
            name,
            needed_mib: bytes.div_ceil(1 << 20),
            limit_mib: limit >> 20,
        });
    }
    Ok(())
}
