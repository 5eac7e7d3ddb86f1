//! What a tracking call is asked to do: [`TrackingSettings`].

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

/// Blocks (of 8³ points) evaluated in parallel between checks for an interrupt
/// ([`crate::cancel`]).
pub(super) const BLOCKS_PER_BATCH: usize = 1024;
