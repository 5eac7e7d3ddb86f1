//! Tracking cell by cell (Triquet et al. §4.4): starting from seed cells, visit only cells the
//! surface crosses, entering a neighbour only through a face whose corners change sign (known
//! from the case table, §4.6). Each cell is processed once. Corner values, edge vertices and
//! queued marks live in bricks of 8³ lattice points handed out on first touch and tagged with a
//! time stamp (§4.1, [`crate::polygonize::bricks`]): a brick from an earlier call is simply
//! stale, so nothing is cleared between frames, and storage grows with the surface, not with
//! the lattice (§4.7).
//!
//! The walk goes wave by wave: all unknown corners of the current wave of cells are evaluated
//! in one batched field call, so the field may be parallel (or a Python callable called in
//! batches).
//!
//! For a [`BlockField`] and [`Components::All`], after the walk every block of 7³ cells that
//! the field's bounds cannot rule out (the blocks [`crate::polygonize::sparse`] evaluates,
//! which hold every crossed cell) is evaluated at once, and the walk goes on from its crossed
//! cells not yet queued; the mesh is then the dense mesh, triangle for triangle and bit for
//! bit.

use super::settings::BLOCKS_PER_BATCH;
use super::walker::{start_walkers, step_walkers, FACE_STEP};
use super::{Components, TrackingSettings};
use crate::error::Result;
use crate::field::{BlockField, Field};
use crate::lattice::{edge_crossing, Lattice};
use crate::mesh::Mesh;
use crate::polygonize::bits::{crossed_cells, ALL_CELLS};
use crate::polygonize::bricks::{Bricks, Slot};
use crate::polygonize::cell::{case_index, emit_triangles, Edge};
use crate::polygonize::sparse::{self, BlockSigns};
use crate::polygonize::{
    check_memory, estimate_triangles, evaluate, finish_mesh, CaseTable, Settings, Stats,
    BYTES_PER_TRIANGLE,
};
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

/// The caches and buffers of tracking cell by cell, kept between calls: in steady state
/// nothing is reallocated.
#[derive(Default)]
pub(super) struct CellTracking {
    /// Corner values, edge vertices and queued marks, time-stamped.
    cache: Bricks,
    wave: Vec<[u32; 3]>,
    next: Vec<[u32; 3]>,
    points: Vec<DVec3>,
    /// Where the values of `points` go.
    slots: Vec<Slot>,
    vals: Vec<f64>,
    mesh: Mesh,
    /// When set, `edge_keys` holds the key of each vertex's lattice edge, beside
    /// `mesh.vertices`.
    pub(super) keyed: bool,
    pub(super) edge_keys: Vec<u64>,
    /// The search for components without a seed ([`Components::All`]): the blocks the field's
    /// bounds cannot rule out, and per block its sign words and points per axis (None: one
    /// sign) with the points evaluated.
    marks: Vec<bool>,
    candidates: Vec<u32>,
    signs: Vec<(Option<BlockSigns>, u64)>,
}

impl CellTracking {
    /// The mesh of the last call.
    pub(super) fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// Bytes held by the caches and buffers (capacities).
    pub(super) fn capacity_bytes(&self) -> usize {
        self.cache.capacity_bytes()
            + (self.wave.capacity() + self.next.capacity()) * 12
            + self.points.capacity() * 24
            + self.slots.capacity() * 4
            + self.vals.capacity() * 8
            + self.mesh.vertices.capacity() * 24
            + self.mesh.normals.capacity() * 24
            + self.mesh.triangles.capacity() * 12
            + self.edge_keys.capacity() * 8
            + self.marks.capacity()
            + self.candidates.capacity() * 4
            + self.signs.capacity() * std::mem::size_of::<(Option<BlockSigns>, u64)>()
    }

    /// The components that hold a seed ([`Components::Seeded`]; [`Components::All`] is
    /// [`CellTracking::polygonize_bounded`]'s).
    pub(super) fn polygonize<F: Field + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        settings: &TrackingSettings,
    ) -> Result<(&Mesh, Stats)> {
        debug_assert_eq!(settings.components, Components::Seeded);
        let mut stats = self.walk_from(field, lattice, settings)?;
        self.finish(field, lattice, &settings.common, &mut stats)?;
        Ok((&self.mesh, stats))
    }

    /// The components `settings.components` names, of a field with block bounds.
    pub(super) fn polygonize_bounded<F: BlockField + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        settings: &TrackingSettings,
    ) -> Result<(&Mesh, Stats)> {
        let mut stats = self.walk_from(field, lattice, settings)?;
        if settings.components == Components::All {
            self.walk_the_rest(field, lattice, &settings.common, &mut stats)?;
        }
        self.finish(field, lattice, &settings.common, &mut stats)?;
        Ok((&self.mesh, stats))
    }

    /// Starts a call, walks the seeds from `settings.starts` and walks the surface from them
    /// and from `settings.seed_cells`; the mesh has no normals yet.
    fn walk_from<F: Field + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        settings: &TrackingSettings,
    ) -> Result<Stats> {
        let common = &settings.common;
        check_memory(
            estimate_triangles(lattice) * (BYTES_PER_TRIANGLE + 64),
            common.memory_limit,
        )?;
        let mut stats = Stats {
            lattice_points: lattice.num_points(),
            ..Default::default()
        };
        self.begin(lattice);
        let t = Instant::now();
        let (starts, max_walk) = (&settings.starts[..], settings.max_walk);
        let mut seeds = self.walk_seeds(field, lattice, (starts, max_walk), common, &mut stats)?;
        seeds.extend_from_slice(&settings.seed_cells);
        stats.add_time("seeds", t);
        self.walk(field, lattice, &seeds, common, &mut stats)?;
        Ok(stats)
    }

    /// Starts a call on `lattice`: the caches of earlier calls go stale, the mesh is emptied.
    fn begin(&mut self, lattice: &Lattice) {
        self.cache.begin(lattice.points_per_axis());
        self.mesh.vertices.clear();
        self.mesh.triangles.clear();
        self.mesh.normals.clear();
        self.edge_keys.clear();
    }

    /// Evaluates, in one batch, the corners of `cells` not yet known in this call.
    fn evaluate_corners<F: Field + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        cells: &[[u32; 3]],
        settings: &Settings,
        stats: &mut Stats,
    ) -> Result<()> {
        self.points.clear();
        self.slots.clear();
        for &o in cells {
            let (slots, points) = (&mut self.slots, &mut self.points);
            self.cache.claim_cell(o, |c, slot| {
                slots.push(slot);
                points.push(lattice.point(c));
            });
        }
        self.vals.resize(self.points.len(), 0.0);
        evaluate(field, &self.points, &mut self.vals, settings.batch)?;
        stats.evaluations += self.points.len() as u64;
        for (&slot, &v) in self.slots.iter().zip(&self.vals) {
            self.cache.set_slot(slot, v);
        }
        Ok(())
    }

    /// Seed cells from the walks from `starts` (at most `max_steps` cells in a direction):
    /// all walkers advance together, one batch of corners per step.
    fn walk_seeds<F: Field + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        (starts, max_steps): (&[DVec3], u32),
        settings: &Settings,
        stats: &mut Stats,
    ) -> Result<Vec<[u32; 3]>> {
        let cells = lattice.cells();
        let mut walkers = start_walkers(starts, lattice);
        let mut seeds = Vec::new();
        while !walkers.is_empty() {
            let cells_now: Vec<[u32; 3]> = walkers.iter().map(|w| w.cell).collect();
            self.evaluate_corners(field, lattice, &cells_now, settings, stats)?;
            let cache = &mut self.cache;
            step_walkers(&mut walkers, |w| {
                let case = case_index(&cache.cell_values(w.cell));
                if case != 0 && case != 255 {
                    seeds.push(w.cell);
                    return false;
                }
                w.advance(cells, max_steps)
            });
        }
        seeds.sort_unstable();
        seeds.dedup();
        Ok(seeds)
    }

    /// Walks from `seeds` (cells; those outside the lattice are ignored), adding the triangles
    /// of the cells reached to the mesh.
    fn walk<F: Field + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        seeds: &[[u32; 3]],
        settings: &Settings,
        stats: &mut Stats,
    ) -> Result<()> {
        let cells = lattice.cells();
        self.wave.clear();
        for &c in seeds {
            if c[0] < cells[0] && c[1] < cells[1] && c[2] < cells[2] && self.cache.queue(c) {
                self.wave.push(c);
            }
        }
        self.walk_waves(field, lattice, settings, stats)
    }

    /// Walks wave by wave from the cells of `self.wave` (queued), adding the triangles of the
    /// cells reached to the mesh: each wave's unknown corners are evaluated in one batch, and
    /// the next wave is the neighbours, not yet queued, across the crossed faces of its cells.
    fn walk_waves<F: Field + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        settings: &Settings,
        stats: &mut Stats,
    ) -> Result<()> {
        let table = CaseTable::get(settings.ambiguity);
        let cells = lattice.cells();
        let mut vertices = std::mem::take(&mut self.mesh.vertices);
        let mut triangles = std::mem::take(&mut self.mesh.triangles);
        while !self.wave.is_empty() {
            let t = Instant::now();
            let wave = std::mem::take(&mut self.wave);
            self.evaluate_corners(field, lattice, &wave, settings, stats)?;
            stats.add_time("evaluate", t);
            let t = Instant::now();
            self.next.clear();
            for &o in &wave {
                stats.cells_visited += 1;
                let v = self.cache.cell_values(o);
                let case = case_index(&v);
                if case == 0 || case == 255 {
                    continue;
                }
                stats.cells_crossed += 1;
                // The vertex of every crossed edge of the cell, looked up (or made) once.
                let mut idx = [0u32; 12];
                for (i, e) in Edge::ALL.into_iter().enumerate() {
                    let [lower, upper] = e.ends();
                    let (fa, fb) = (v[lower.index()], v[upper.index()]);
                    if (fa < 0.0) == (fb < 0.0) {
                        continue;
                    }
                    let (a, axis) = (lower.of_cell(o), e.axis());
                    let (keyed, keys) = (self.keyed, &mut self.edge_keys);
                    idx[i] = self.cache.edge(a, axis.into(), || {
                        let mut b = a;
                        b[axis.index()] += 1;
                        if keyed {
                            keys.push(lattice.whole_edge_key(a, axis.into()));
                        }
                        vertices.push(edge_crossing(lattice.point(a), lattice.point(b), fa, fb));
                        (vertices.len() - 1) as u32
                    });
                }
                emit_triangles(table, case, |e| idx[e.index()], &mut triangles);
                let faces = table.crossed_faces(case);
                for (f, &(axis, step)) in FACE_STEP.iter().enumerate() {
                    if faces & (1 << f) == 0 {
                        continue;
                    }
                    let n = o[axis] as i64 + step;
                    if n < 0 || n >= cells[axis] as i64 {
                        continue;
                    }
                    let mut c = o;
                    c[axis] = n as u32;
                    if self.cache.queue(c) {
                        self.next.push(c);
                    }
                }
            }
            self.wave = wave;
            std::mem::swap(&mut self.wave, &mut self.next);
            stats.add_time("track", t);
        }
        self.mesh.vertices = vertices;
        self.mesh.triangles = triangles;
        Ok(())
    }

    /// Projects the vertices and computes the normals of the mesh.
    fn finish<F: Field + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        settings: &Settings,
        stats: &mut Stats,
    ) -> Result<()> {
        let mut mesh = std::mem::take(&mut self.mesh);
        let r = finish_mesh(field, &mut mesh, lattice, settings, stats);
        self.mesh = mesh;
        r
    }

    /// After a walk, finds the components it did not reach: evaluates (block by block, in
    /// parallel) the blocks that the field's bounds cannot rule out, which hold every crossed
    /// cell, and walks on from their crossed cells not yet queued.
    fn walk_the_rest<F: BlockField + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        settings: &Settings,
        stats: &mut Stats,
    ) -> Result<()> {
        self.evaluate_blocks_not_ruled_out(field, lattice, stats)?;
        let t = Instant::now();
        self.queue_crossed_cells(lattice);
        stats.add_time("track", t);
        self.walk_waves(field, lattice, settings, stats)
    }

    /// Finds the blocks that `field`'s bounds cannot rule out (into `candidates`) and evaluates
    /// them in parallel (their signs into `signs`), a batch of blocks between checks for an
    /// interrupt.
    fn evaluate_blocks_not_ruled_out<F: BlockField + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        stats: &mut Stats,
    ) -> Result<()> {
        let t = Instant::now();
        let grid = sparse::block_grid(lattice);
        let blocks = field.blocks(lattice, grid.dims);
        let (marks, candidates) = (&mut self.marks, &mut self.candidates);
        sparse::blocks_not_ruled_out((field, &blocks), lattice, |_| true, marks, candidates)?;
        stats.add_time("classify", t);

        let t = Instant::now();
        self.signs.clear();
        for batch in self.candidates.chunks(BLOCKS_PER_BATCH) {
            crate::cancel::check()?;
            let first = self.signs.len();
            self.signs.par_extend(batch.par_iter().map_init(
                || [0.0f64; 512],
                |values, &i| {
                    let (b, mut evaluations) = (grid.position(i), 0);
                    let fb = (field, &blocks);
                    let signs = sparse::block_signs(fb, lattice, b, values, &mut evaluations);
                    (signs, evaluations)
                },
            ));
            let evaluations = self.signs[first..].iter().map(|s| s.1).sum::<u64>();
            stats.evaluations += evaluations;
            crate::cancel::advance(evaluations)?;
        }
        stats.add_time("evaluate", t);
        Ok(())
    }

    /// Queues the crossed cells of the blocks in `signs` that are not yet queued, as the next
    /// wave.
    fn queue_crossed_cells(&mut self, lattice: &Lattice) {
        let grid = sparse::block_grid(lattice);
        self.wave.clear();
        for (&i, &(signs, _)) in self.candidates.iter().zip(&self.signs) {
            let Some((signs, n)) = signs else { continue };
            let lo = grid.origin(grid.position(i));
            let (cache, wave) = (&mut self.cache, &mut self.wave);
            crossed_cells(&signs, n, &ALL_CELLS, |cell, _| {
                let c = [
                    lo[0] + (cell & 7) as u32,
                    lo[1] + ((cell >> 3) & 7) as u32,
                    lo[2] + (cell >> 6) as u32,
                ];
                if cache.queue(c) {
                    wave.push(c);
                }
            });
        }
    }
}
