//! What a tracking call is asked to do: [`TrackingSettings`].

use crate::error::{Error, Result};
use crate::field::Field;
use crate::lattice::Lattice;
use crate::polygonize::Settings;
use glam::DVec3;

/// Which components of the surface a walk finds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Components {
    /// Those that hold a seed: the walk from the seeds reaches them.
    #[default]
    Seeded,
    /// Every component: after the walk from the seeds, the blocks that the field's bounds cannot
    /// rule out are searched for crossed cells the walk did not reach, and the walk goes on from
    /// them. Needs a field with block bounds ([`crate::field::BlockField`]).
    All,
}

/// Settings of a tracking polygonization: those all polygonizers share, and where the walk
/// starts.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackingSettings {
    /// Ambiguity, normals, batch size, memory limit, difference gradients.
    pub common: Settings,
    /// Points the seed walks start from (e.g. blob centres or data points): each walks from the
    /// cell holding it to the first cell the surface crosses, along +x first, then −x, ±y, ±z
    /// when the box cuts the walk.
    pub starts: Vec<DVec3>,
    /// Cells a seed walk goes at most in one direction (unlimited by default: up to the
    /// lattice's side).
    pub max_walk: u32,
    /// Seed cells (lower corners) beside the walks' (those outside the lattice, and those the
    /// surface does not cross, are ignored).
    pub seed_cells: Vec<[u32; 3]>,
    /// The components found.
    pub components: Components,
}

impl Default for TrackingSettings {
    fn default() -> Self {
        TrackingSettings {
            common: Settings::default(),
            starts: Vec::new(),
            max_walk: u32::MAX,
            seed_cells: Vec::new(),
            components: Components::Seeded,
        }
    }
}

impl TrackingSettings {
    /// The tracking `field` calls for on `lattice`, with the shared settings `common`: walks
    /// from `seeds` when given (each up to the lattice's longest side), else from the field's
    /// own starts ([`Field::starts`]: blob centres, a fit's data points); every component
    /// ([`Components::All`]) of a field with block bounds ([`Field::block_field`]), the seeded
    /// ones of any other.
    ///
    /// Errors (naming `seeds`) when a seed is not finite, or when no seeds are given and the
    /// field has no starts of its own (a Python callable).
    pub fn for_field<F: Field + ?Sized>(
        field: &F,
        lattice: &Lattice,
        common: Settings,
        seeds: Option<Vec<DVec3>>,
    ) -> Result<Self> {
        let (starts, max_walk) = match seeds {
            Some(points) => {
                crate::error::check_finite_points("seeds", &points)?;
                (points, *lattice.cells().iter().max().unwrap())
            }
            None => {
                let s = field.starts(lattice.cell().min_element()).ok_or_else(|| {
                    Error::invalid(
                        "seeds",
                        "tracking a field with no starts of its own (a callable) needs seeds: \
                         points inside or on each component of the surface",
                    )
                })?;
                (s.points, s.max_walk)
            }
        };
        let components = match field.block_field() {
            Some(_) => Components::All,
            None => Components::Seeded,
        };
        Ok(TrackingSettings {
            common,
            starts,
            max_walk,
            components,
            ..Default::default()
        })
    }
}

/// Blocks (of 8³ points) evaluated in parallel between checks for an interrupt
/// ([`crate::cancel`]).
pub(super) const BLOCKS_PER_BATCH: usize = 1024;
