//! The field seen through counted batched calls, with the cancellation checks and the
//! finiteness check of every batch.

use crate::error::{Error, Result};
use crate::field::Field;
use glam::DVec3;

/// A field's batched calls, counted: values with gradients, and values alone.
pub(super) struct Evaluator<'a, F: Field + ?Sized> {
    pub field: &'a F,
    /// Field evaluations counted so far ([`Field::values_per_value_gradient`] per point of a
    /// value-and-gradient call, 1 per point of a values call).
    pub evaluations: u64,
    /// Batched calls made so far.
    pub batches: u64,
}

impl<'a, F: Field + ?Sized> Evaluator<'a, F> {
    pub fn new(field: &'a F) -> Self {
        Evaluator {
            field,
            evaluations: 0,
            batches: 0,
        }
    }

    /// Values and gradients at `p`; errors when told to stop or when one is not finite.
    pub fn both(&mut self, p: &[DVec3], v: &mut [f64], g: &mut [DVec3]) -> Result<()> {
        crate::cancel::check()?;
        self.field.values_gradients(p, v, g);
        crate::cancel::check()?;
        self.evaluations += self.field.values_per_value_gradient() * p.len() as u64;
        self.batches += 1;
        match (0..p.len()).find(|&i| !(v[i].is_finite() && g[i].is_finite())) {
            Some(i) => Err(not_finite(p[i])),
            None => Ok(()),
        }
    }

    /// Values at `p`; errors when told to stop or when one is not finite.
    pub fn values(&mut self, p: &[DVec3], v: &mut [f64]) -> Result<()> {
        crate::cancel::check()?;
        self.field.values(p, v);
        crate::cancel::check()?;
        self.evaluations += p.len() as u64;
        self.batches += 1;
        match v.iter().position(|x| !x.is_finite()) {
            Some(i) => Err(not_finite(p[i])),
            None => Ok(()),
        }
    }
}

fn not_finite(p: DVec3) -> Error {
    Error::FieldNotFinite {
        x: p.x,
        y: p.y,
        z: p.z,
    }
}
