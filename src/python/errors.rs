//! The one mapping from core errors to Python exceptions.

use crate::error::Error;
use pyo3::exceptions::{PyKeyboardInterrupt, PyValueError};
use pyo3::PyErr;

impl From<Error> for PyErr {
    fn from(e: Error) -> PyErr {
        match e {
            // A call told to stop (see `interrupt.rs`, which raises the signal's own exception).
            Error::Interrupted => PyKeyboardInterrupt::new_err("interrupted"),
            // Every other core error is caused by the arguments (bad input, singular data, a
            // request too large for the memory limit): ValueError, with a message naming the
            // argument.
            e => PyValueError::new_err(e.to_string()),
        }
    }
}

/// A ValueError naming the argument.
pub fn value_error(name: &str, reason: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(format!("{name}: {reason}"))
}
