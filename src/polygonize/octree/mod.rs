//! Hierarchical space sampling with the pseudo-Euclidean rejection test (Cuno et al. §4.3).
//!
//! The lattice is covered by a root cube of 2^L cells per side. Level by level, every surviving
//! block of `s × s × s` cells is tested at its centre `c` (a lattice point): when
//! `|f(c)| > safety × r`, with `r` the block's circumradius, the surface cannot reach the block
//! — provided `|f|` under-estimates the distance to the surface there, which the normal
//! constraints of a variational surface with w < d arrange (Cuno's property (6)), and which holds
//! for any exact or conservative signed distance. Otherwise the block splits into 8. Blocks of two
//! cells that survive split into leaf cells, whose corners are evaluated and triangulated with the
//! shared case table and edge vertices — so wherever nothing was rejected wrongly, the mesh is
//! exactly the dense mesh.
//!
//! Beyond the paper (on by default, see [`OctreeSettings::corner_test`]), values already known do
//! more of the work, by the same argument (no surface lies within |f(x)| / safety of x): a
//! block covered by the balls around its known corners is dropped unevaluated; every point of a
//! block dropped either way has its sign, which the leaves' corners on its faces take; and the
//! leaves are settled by signs, not values. Marching cubes needs only the signs of a cell's
//! corners, and values at the ends of its crossed edges; a corner inside the ball of a known
//! value has that value's sign. So signs are first inferred from the balls of the values the
//! levels left, then the leaves' corners still without one are evaluated, then signs are
//! inferred again; a leaf whose corners all have one sign is done without evaluating the
//! others, and the ends of crossed edges that only have a sign are evaluated last.
//!
//! The centres of one level are evaluated in one batched field call, the leaves' corners in
//! one more and the ends of crossed edges in a last; no point is evaluated twice (coarse
//! centres are corners of leaf cells). The values live in a block-sparse store: a dense table
//! of bricks of 8³ lattice points, each brick an array of indices into the values and one of
//! the points' states (a byte: unknown, queued, sign inferred, value; the sign in it), so
//! finding, claiming and reading a point is array indexing, and memory grows with the surface,
//! not with the lattice (besides the brick table, 4 bytes per 512 points, and the decided
//! blocks' signs, a byte per 8 cells: 262 kB at 128³, 134 MB at 1024³). Leaves are
//! triangulated in parallel, each edge vertex indexed through the value index of the edge's
//! lower end and numbered as a serial sweep over the leaves would (first use).
//!
//! One call is a `Run` (`run.rs`) going through its phases, a file each: `levels.rs` (the
//! rejection, level by level), `leaves.rs` (the crossed leaves), `settle.rs` (settling them by
//! signs: inferring, claiming the corners without a sign, evaluating the crossed edges' ends),
//! `repair.rs` and `triangulate.rs`. Beside them: the value store (`store.rs`, with the points'
//! states in `state.rs`), the points of a block of leaves (`block.rs`), the ball tests
//! (`cover.rs` for blocks, `balls.rs` for block points) and the decided blocks (`decided.rs`).

mod balls;
mod block;
mod cover;
mod decided;
mod leaves;
mod levels;
mod repair;
mod run;
mod settle;
mod state;
mod store;
mod triangulate;

use super::{finish_mesh, Polygonized, Settings};
use crate::error::Result;
use crate::field::Field;
use crate::lattice::Lattice;
use run::Run;
use std::time::Instant;

/// The octree's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OctreeSettings {
    /// The settings shared by the polygonizers.
    pub common: Settings,
    /// Level of the first rejection test: 1 tests the root's 8 octants (the paper's
    /// r = √3/2 for a [-1, 1]³ root), 2 the 64 blocks below them (r = √3/4), and so on. Levels
    /// above it are split without evaluating anything. `None`: the first level whose blocks
    /// span at most 1/8 of the lattice's longest side. On the shared meshes at 24³ to 128³,
    /// starting at coarser blocks (the paper's r = √3/2) rejects cells wrongly at some
    /// resolutions, because far from the surface |f| stops under-estimating distance (Cuno's
    /// Fig. 2c and Table 1); testing from 1/8 costs at most 8³·(root/lattice)³ extra centres.
    pub start_level: Option<u32>,
    /// Multiplies the circumradius in the test |f(c)| > safety × r. Values above 1 keep more
    /// blocks (safer for fields that over-estimate distance, more evaluations). `None`: derived
    /// from the field, max(1, [`Field::gradient_bound`]) — a bound on |∇f| makes the rejection
    /// exact (a blob field's), and 1 suits a distance.
    pub safety: Option<f64>,
    /// Tests beyond the paper that decide with values already known, each by the rejection
    /// test's premise (no surface within |f(x)| / safety of x):
    /// - a block whose known corners have balls of radius |f| / safety that together cover it
    ///   is dropped without evaluating its centre (the known corners are the centres of its
    ///   parent and of ancestors further up, two at most, at opposite corners, where covering
    ///   is decided exactly);
    /// - a block dropped (by its centre's ball, which holds the whole block, or by its corners')
    ///   holds one sign, so the leaves' corners on its faces, edges and corners have that sign
    ///   without evaluation (a map of one byte per block of 2 × 2 × 2 cells records them);
    /// - leaf cells are settled by the signs of their corners: a corner in the ball of a known
    ///   value has its sign, so only the corners still without a sign after the levels are
    ///   evaluated, a leaf whose corners all have one sign needs no more, and of a crossed leaf
    ///   only the ends of its crossed edges need values.
    ///
    /// The mesh is the same. On the shared meshes at 128³ over [-1, 1]³ this evaluates about
    /// half the points the paper's test alone does (torus2 2.41 % of the lattice instead of
    /// 5.33 %, icosahedron 6.50 % instead of 14.60 %). `false` gives §4.3 exactly.
    pub corner_test: bool,
}

impl Default for OctreeSettings {
    fn default() -> Self {
        // Chosen on the shared meshes (d = 0.015, w/d = 3/4, 24³ to 128³): see
        // notebooks/cuno_tables.ipynb and BENCHMARKS.md.
        OctreeSettings {
            common: Settings::default(),
            start_level: None,
            safety: None,
            corner_test: true,
        }
    }
}

impl OctreeSettings {
    /// The safety factor for `field`: [`OctreeSettings::safety`], or derived from the field's
    /// gradient bound when `None`; errors unless it is positive and finite.
    pub fn safety_for<F: Field + ?Sized>(&self, field: &F) -> Result<f64> {
        let safety = self
            .safety
            .unwrap_or_else(|| field.gradient_bound().map_or(1.0, |b| 1.0f64.max(b)));
        if !(safety.is_finite() && safety > 0.0) {
            return Err(crate::Error::invalid(
                "safety",
                format!("must be positive and finite, got {safety}"),
            ));
        }
        Ok(safety)
    }
}

/// Polygonizes `field` over `lattice` with hierarchical rejection; leaves are single cells.
/// With the vertices' edge keys when [`Settings::keys`](crate::polygonize::Settings::keys) asks
/// for them ([`super::polygonize`] with [`super::Method::Octree`]).
pub(crate) fn polygonize<F: Field + ?Sized>(
    field: &F,
    lattice: &Lattice,
    settings: &OctreeSettings,
) -> Result<Polygonized> {
    let keyed = settings.common.keys;
    let mut run = Run::new(field, lattice, settings)?;
    run.test_levels()?;
    let sampling = Instant::now();
    let mut leaves = run.crossed_leaves()?;
    run.repair(&mut leaves)?;
    run.stats.add_time("sample", sampling);
    let (mut mesh, keys, mut stats) = run.triangulate(leaves, keyed);
    finish_mesh(field, &mut mesh, lattice, &settings.common, &mut stats)?;
    Ok(Polygonized {
        mesh,
        keys: keyed.then_some(keys),
        stats,
    })
}

#[cfg(test)]
mod tests;
