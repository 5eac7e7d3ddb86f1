//! The state of one octree run, carried from each phase to the next: the levels
//! ([`Run::test_levels`]), the leaves ([`Run::crossed_leaves`]), the repair ([`Run::repair`]) and
//! the triangulation ([`Run::triangulate`]).

use super::decided::DecidedBlocks;
use super::levels::{levels, KnownCorners};
use super::repair::Suspects;
use super::store::{Store, BYTES_PER_TRIANGLE_STORE};
use super::OctreeSettings;
use crate::error::Result;
use crate::field::Field;
use crate::lattice::Lattice;
use crate::polygonize::{check_memory, estimate_triangles, CaseTable, Stats, BYTES_PER_TRIANGLE};
use glam::DVec3;

/// One polygonization by the octree.
pub(super) struct Run<'a, F: ?Sized> {
    pub(super) field: &'a F,
    pub(super) lattice: &'a Lattice,
    pub(super) settings: &'a OctreeSettings,
    /// The safety factor of the tests ([`OctreeSettings::safety_for`] the field).
    pub(super) safety: f64,
    /// Number of levels: the root cube has 2^levels cells per side.
    pub(super) levels: u32,
    pub(super) table: &'static CaseTable,
    pub(super) stats: Stats,
    /// The values evaluated and what is known at each lattice point.
    pub(super) store: Store,
    /// The blocks the levels dropped, with their signs.
    pub(super) decided: DecidedBlocks,
    /// The points to evaluate next (one buffer for every phase).
    pub(super) points: Vec<DVec3>,
    /// The blocks of the current level, by their lowest lattice point; after the levels, the
    /// blocks of 2 × 2 × 2 cells that hold the leaves (or, for a lattice of one cell, the root,
    /// whose only child inside is that cell).
    pub(super) blocks: Vec<[u32; 3]>,
    /// Per block, the values known at its corners (until the leaves are first settled).
    pub(super) known: Vec<KnownCorners>,
    /// Per block, the index of its centre's value (`NONE`: not evaluated). During the levels,
    /// those of the current level once its centres are tested (empty before); the centre of a
    /// block of leaves stays here instead of in the store.
    pub(super) centres: Vec<u32>,
    /// Per block of leaves, a mask of its children (case-bit order): those inside the lattice
    /// and not yet decided, and once the leaves are settled by signs, the crossed ones.
    pub(super) masks: Vec<u8>,
    /// Where the premise failed, found while settling the leaves (for the repair).
    pub(super) suspects: Suspects,
}

impl<'a, F: Field + ?Sized> Run<'a, F> {
    /// A run over `lattice` before any evaluation; errors for a safety factor that is not
    /// positive and finite, or a lattice whose memory estimate exceeds the limit.
    pub(super) fn new(
        field: &'a F,
        lattice: &'a Lattice,
        settings: &'a OctreeSettings,
    ) -> Result<Self> {
        let safety = settings.safety_for(field)?;
        // Output, working memory (see BYTES_PER_TRIANGLE_STORE), the brick table and the
        // decided blocks' signs.
        check_memory(
            estimate_triangles(lattice)
                .saturating_mul(BYTES_PER_TRIANGLE + BYTES_PER_TRIANGLE_STORE)
                .saturating_add(Store::table_bytes(lattice))
                .saturating_add(DecidedBlocks::bytes(lattice)),
            settings.common.memory_limit,
        )?;
        Ok(Run {
            field,
            lattice,
            settings,
            safety,
            levels: levels(lattice),
            table: CaseTable::get(settings.common.ambiguity),
            stats: Stats {
                lattice_points: lattice.num_points(),
                ..Default::default()
            },
            store: Store::new(lattice),
            decided: DecidedBlocks::new(lattice),
            points: Vec::new(),
            blocks: Vec::new(),
            known: Vec::new(),
            centres: Vec::new(),
            masks: Vec::new(),
            suspects: Suspects::default(),
        })
    }

    /// Evaluates `points` (queued in the store, or level centres) and appends their values to
    /// the store's.
    pub(super) fn evaluate_points(&mut self) -> Result<()> {
        self.store.evaluate(
            self.field,
            &self.points,
            &self.settings.common,
            &mut self.stats,
        )
    }
}
