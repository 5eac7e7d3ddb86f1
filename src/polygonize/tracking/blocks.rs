//! Tracking block by block: Triquet et al.'s walk (§4.4) over the blocks of 7³ cells of
//! [`crate::polygonize::sparse`], for fields that evaluate whole blocks at once
//! ([`BlockField`], e.g. blob fields).
//!
//! The cells reached are exactly those of tracking cell by cell ([`super::cells`]): the
//! crossed cells joined to a seed cell through faces the surface crosses, from the same seeds
//! (the seed walks, by the same rule, read the signs of the blocks they pass). A block is
//! evaluated (all its 8³ points, vectorised) when a seed walk or the walk first enters one of
//! its cells; the same task splits its crossed cells into components (cells joined through
//! crossed faces, by a flood over bit sets, one 64-bit word per plane of cells), and the walk
//! takes each component it enters whole, entering the neighbouring blocks through the
//! component's crossed faces on the block's sides. Vertices, normals and triangles are then
//! made as by sparse, triangles only for the cells reached and vertices only for their edges,
//! so the mesh is the dense mesh on every component that holds a seed, triangle for triangle
//! and bit for bit, and, like tracking cell by cell, it holds whole components only.
//!
//! With [`Components::All`] it finds every component, those no seed reaches too (the inner
//! surface of a cavity inside a cluster of blobs): when the walk from the seeds ends, the
//! crossed cells it did not reach in the blocks it evaluated, and every cell of the blocks it
//! did not enter that the field's bounds cannot rule out (the blocks sparse evaluates, which
//! hold every crossed cell), are entered, and the walk goes on until no cell is left. The
//! blocks not entered are bounded once; only those the bounds cannot rule out are evaluated.
//! The mesh is then sparse's, array for array: the dense mesh.
//!
//! Blocks are evaluated in waves (those newly entered), each wave in parallel, a batch of
//! blocks between checks for an interrupt; the seed walks' steps and the walk between waves
//! are serial bit arithmetic. An animation's surface moves little from call to call, so the
//! blocks the last call used (kept in [`BlockTracking`]) are evaluated in the first wave, and
//! the walk rarely waits for a second. The output is ordered by block, like sparse's: it
//! depends neither on the number of threads nor on the calls before.

use super::settings::BLOCKS_PER_BATCH;
use super::walker::{start_walkers, step_walkers, Walker};
use super::{Components, TrackingSettings};
use crate::error::{Error, Result};
use crate::field::BlockField;
use crate::lattice::Lattice;
use crate::mesh::Mesh;
use crate::polygonize::bits::{crossed_layer_cells, mixed, plane_mask, ALL_CELLS, COLUMN_0, ROW_0};
use crate::polygonize::sparse::{
    block_grid, blocks_not_ruled_out, bounds_error, evaluate_block, finish_normals, start_blocks,
    triangulate_blocks, Active, BlockCases, BlockGrid, BlockOutput, BlockStart, TriangleIndex,
};
use crate::polygonize::{gather, Stats};
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

/// No state (block map), no block evaluated (state slot), or kept aside (vertex source).
const NONE: u32 = u32::MAX;

/// Blocks per task of a wave's evaluation.
const BLOCKS_PER_TASK: usize = 8;

/// The faces between the cells of a block that the surface crosses (corners of both signs):
/// `x[k]` bit `a + 8j` for the face at x = a between cells (a − 1, j, k) and (a, j, k), `y[k]` bit
/// `i + 8b` for the face at y = b, `z[c]` bit `i + 8j` for the face at z = c between cells
/// (i, j, c − 1) and (i, j, c). Faces on the block's sides (a, b or c at 0 or the last point)
/// lead to neighbouring blocks.
#[derive(Clone, Copy, Default)]
struct Faces {
    x: [u64; 8],
    y: [u64; 8],
    z: [u64; 8],
}

impl Faces {
    fn new(signs: &[u64; 8], n: [u8; 3]) -> Faces {
        let [nx, ny, nz] = n.map(|v| v as u32);
        let mut f = Faces::default();
        let (mx, my, mz) = (
            plane_mask(nx, ny - 1),
            plane_mask(nx - 1, ny),
            plane_mask(nx - 1, ny - 1),
        );
        for k in 0..nz as usize - 1 {
            let (a, b) = (signs[k], signs[k + 1]);
            f.x[k] = mixed([a, a >> 8, b, b >> 8]) & mx;
            f.y[k] = mixed([a, a >> 1, b, b >> 1]) & my;
        }
        for (z, &p) in f.z.iter_mut().zip(signs).take(nz as usize) {
            *z = mixed([p, p >> 1, p >> 8, p >> 9]) & mz;
        }
        f
    }
}

/// Crossed cells of a block (bit `i + 8j` of word `k` for cell (i, j, k)).
fn crossed_mask(signs: &[u64; 8], n: [u8; 3]) -> [u64; 8] {
    let cells = plane_mask(n[0] as u32 - 1, n[1] as u32 - 1);
    std::array::from_fn(|k| {
        if k + 1 < n[2] as usize {
            crossed_layer_cells(signs[k], signs[k + 1]) & cells
        } else {
            0
        }
    })
}

/// What is known of a block the walk entered.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// Entered, not yet evaluated.
    Queued,
    /// Evaluated: its points have both signs.
    Mixed,
    /// Evaluated (or bounded): one sign on every point, so no cell is crossed.
    Empty,
}

/// A block the walk entered.
#[derive(Clone, Copy)]
struct State {
    kind: Kind,
    /// Whether the state is on the flood's work list.
    listed: bool,
    /// Whether a seed, a seed walk or the flood entered the block (not only the previous
    /// call's blocks, evaluated ahead).
    used: bool,
    /// Where it is: its part (holding its vertices) and its place in the part's `evaluated`
    /// (for `Mixed`).
    part: u32,
    slot: u32,
    block: [u32; 3],
    crossed: [u64; 8],
    /// Cells reached.
    reach: [u64; 8],
    /// Cells entered and not yet flooded from.
    pending: [u64; 8],
    /// Its components (crossed cells joined through crossed faces): `comps` of its part.
    comps: (u32, u32),
}

/// A component of a block's crossed cells (joined through crossed faces; the walk reaches it
/// whole or not at all), and the cells it enters in the neighbouring blocks (sides −x, +x,
/// −y, +y, −z, +z; bits as in [`State::reach`] of the neighbour).
#[derive(Clone, Copy)]
struct Component {
    cells: [u64; 8],
    exits: [[u64; 8]; 6],
    /// Bit `side` set when `exits[side]` has cells.
    sides: u8,
}

/// An evaluated block with both signs: its signs and owned vertices, crossed cells and
/// components (a range of its part's `comps`).
type Evaluated = (Active, [u64; 8], (u32, u32));

/// What one task of a wave produces.
#[derive(Default)]
struct Part {
    /// Per block evaluated: its state and its place in `evaluated` (`NONE`: one sign).
    done: Vec<(u32, u32)>,
    evaluated: Vec<Evaluated>,
    out: BlockOutput,
    /// The components of its blocks' crossed cells.
    comps: Vec<Component>,
}

/// The buffers of tracking block by block, kept between calls (an animation allocates nothing
/// here in steady state).
#[derive(Default)]
pub(super) struct BlockTracking {
    /// Block index → state index, or `NONE`.
    map: Vec<u32>,
    states: Vec<State>,
    /// Blocks of each state (block index).
    index: Vec<u32>,
    parts: Vec<Part>,
    /// Parts holding this call's blocks.
    used_parts: usize,
    wave: Vec<u32>,
    work: Vec<u32>,
    /// The blocks the last call used (block index, ascending), on `last_lattice`: evaluated in
    /// the first wave of the next call on the same lattice.
    last: Vec<u32>,
    last_lattice: Option<Lattice>,
    /// The blocks with reached cells (block index, state), ascending.
    order: Vec<(u32, u32)>,
    /// Where each block's vertices come from: (part, range), or (`NONE`, range of `kept`).
    sources: Vec<(u32, usize, usize)>,
    /// The vertices (and normals) kept of blocks partly reached.
    kept: Vec<DVec3>,
    kept_normals: Vec<DVec3>,
    /// The evaluated blocks with crossed cells, their reached cells, block index → position.
    active: Vec<Active>,
    reach: Vec<[u64; 8]>,
    amap: Vec<u32>,
    /// The blocks not entered that the field's bounds cannot rule out (block index), and
    /// scratch for finding them.
    candidates: Vec<u32>,
    marks: Vec<bool>,
}

impl BlockTracking {
    /// Bytes held (capacities).
    pub(super) fn capacity_bytes(&self) -> usize {
        self.parts
            .iter()
            .map(|p| {
                p.done.capacity() * 8
                    + p.evaluated.capacity() * std::mem::size_of::<Evaluated>()
                    + p.out.capacity_bytes()
                    + p.comps.capacity() * std::mem::size_of::<Component>()
            })
            .sum::<usize>()
            + (self.map.capacity()
                + self.index.capacity()
                + self.wave.capacity()
                + self.work.capacity()
                + self.last.capacity()
                + self.amap.capacity()
                + self.candidates.capacity())
                * 4
            + self.marks.capacity()
            + self.order.capacity() * 8
            + self.sources.capacity() * std::mem::size_of::<(u32, usize, usize)>()
            + (self.kept.capacity() + self.kept_normals.capacity()) * 24
            + self.states.capacity() * std::mem::size_of::<State>()
            + self.active.capacity() * std::mem::size_of::<Active>()
            + self.reach.capacity() * 64
    }

    /// Evaluates the blocks entered since the last wave, in parallel, [`BLOCKS_PER_BATCH`]
    /// between checks for an interrupt; those with both signs and cells entered go on the
    /// flood's work list. Returns the points evaluated.
    fn evaluate_wave<F: BlockField + ?Sized>(
        &mut self,
        (field, blocks): (&F, &F::Blocks),
        lattice: &Lattice,
        (cases, normals): (&BlockCases, bool),
    ) -> Result<u64> {
        let mut evaluations = 0;
        let wave = std::mem::take(&mut self.wave);
        for batch in wave.chunks(BLOCKS_PER_BATCH) {
            crate::cancel::check()?;
            let done = self.evaluate_batch((field, blocks), lattice, (cases, normals), batch);
            evaluations += done;
            crate::cancel::advance(done)?;
        }
        self.wave = wave;
        self.wave.clear();
        Ok(evaluations)
    }

    /// Evaluates the blocks of states `batch` (part of a wave), in parallel, [`BLOCKS_PER_TASK`]
    /// to a part; returns the points evaluated.
    fn evaluate_batch<F: BlockField + ?Sized>(
        &mut self,
        (field, blocks): (&F, &F::Blocks),
        lattice: &Lattice,
        (cases, normals): (&BlockCases, bool),
        batch: &[u32],
    ) -> u64 {
        let grid = block_grid(lattice);
        let used = self.used_parts;
        let tasks = batch.len().div_ceil(BLOCKS_PER_TASK);
        if self.parts.len() < used + tasks {
            self.parts.resize_with(used + tasks, Part::default);
        }
        let index = &self.index;
        self.parts[used..used + tasks]
            .par_iter_mut()
            .zip(batch.par_chunks(BLOCKS_PER_TASK))
            .for_each(|(part, chunk)| {
                part.done.clear();
                part.evaluated.clear();
                part.out.clear();
                part.comps.clear();
                let mut values = [0.0f64; 512];
                for &s in chunk {
                    let b = grid.position(index[s as usize]);
                    let (out, how) = (&mut part.out, (cases, normals));
                    // Triangles counted for all crossed cells (those usually all reached), and
                    // the components that the walk will reach whole.
                    let got =
                        evaluate_block((field, blocks), lattice, &grid, b, how, &mut values, out);
                    let slot = match got {
                        None => NONE,
                        Some(a) => {
                            let crossed = crossed_mask(&a.signs, a.n);
                            let first = part.comps.len() as u32;
                            components(&a, &crossed, &mut part.comps);
                            let comps = (first, part.comps.len() as u32);
                            part.evaluated.push((a, crossed, comps));
                            part.evaluated.len() as u32 - 1
                        }
                    };
                    part.done.push((s, slot));
                }
            });
        let mut evaluations = 0;
        for p in used..used + tasks {
            let part = &self.parts[p];
            evaluations += part.out.evaluations;
            for &(s, slot) in &part.done {
                let st = &mut self.states[s as usize];
                match part.evaluated.get(slot as usize) {
                    None => st.kind = Kind::Empty,
                    Some(&(_, crossed, comps)) => {
                        st.kind = Kind::Mixed;
                        st.part = p as u32;
                        st.slot = slot;
                        st.crossed = crossed;
                        st.comps = comps;
                        if st.pending.iter().any(|&w| w != 0) {
                            st.listed = true;
                            self.work.push(s);
                        }
                    }
                }
            }
        }
        self.used_parts += tasks;
        evaluations
    }

    /// Adds `cells` (bits as in [`State::reach`]) to the block with index `i`, entering it
    /// when new; returns false when the block is known to have one sign (its cells cannot be
    /// crossed, so the field's bounds or values disagree).
    fn enter(&mut self, i: u32, cells: &[u64; 8], grid: &BlockGrid) -> bool {
        let s = self.map[i as usize];
        if s == NONE {
            self.queue(i, cells, true, grid);
            return true;
        }
        let st = &mut self.states[s as usize];
        st.used = true;
        let mut new = false;
        for ((p, &r), &c) in st.pending.iter_mut().zip(&st.reach).zip(cells) {
            let add = c & !r & !*p;
            *p |= add;
            new |= add != 0;
        }
        match st.kind {
            Kind::Empty => !new,
            Kind::Mixed if new && !st.listed => {
                st.listed = true;
                self.work.push(s);
                true
            }
            _ => true,
        }
    }

    /// Enters the cells that the walk has not reached: the crossed cells of the blocks
    /// evaluated, and (`classify`) every cell of the blocks not entered that `field`'s bounds
    /// cannot rule out (queued for the next wave). Every crossed cell lies in such a block.
    fn enter_the_rest<F: BlockField + ?Sized>(
        &mut self,
        (field, blocks): (&F, &F::Blocks),
        lattice: &Lattice,
        classify: bool,
    ) -> Result<()> {
        let grid = block_grid(lattice);
        if classify {
            let map = &self.map;
            let not_entered = |i: u32| map[i as usize] == NONE;
            let (marks, candidates) = (&mut self.marks, &mut self.candidates);
            blocks_not_ruled_out((field, blocks), lattice, not_entered, marks, candidates)?;
            for k in 0..self.candidates.len() {
                self.queue(self.candidates[k], &ALL_CELLS, true, &grid);
            }
        }
        for s in 0..self.states.len() {
            let st = &self.states[s];
            if st.kind != Kind::Mixed {
                continue;
            }
            let rest: [u64; 8] = std::array::from_fn(|k| st.crossed[k] & !st.reach[k]);
            if rest.iter().any(|&w| w != 0) {
                // A block with both signs: entering it never fails.
                self.enter(self.index[s], &rest, &grid);
            }
        }
        Ok(())
    }

    /// Queues block `i` (not yet entered) for the next wave.
    fn queue(&mut self, i: u32, cells: &[u64; 8], used: bool, grid: &BlockGrid) {
        self.map[i as usize] = self.states.len() as u32;
        self.wave.push(self.states.len() as u32);
        self.index.push(i);
        self.states.push(State {
            kind: Kind::Queued,
            listed: false,
            used,
            part: 0,
            slot: NONE,
            block: grid.position(i),
            crossed: [0; 8],
            reach: [0; 8],
            pending: *cells,
            comps: (0, 0),
        });
    }
}

/// Floods the crossed cells of a block (`crossed`, with crossed faces `f`, `n` points per axis)
/// from the cells `from` through crossed faces; returns the cells reached.
fn flood(from: &[u64; 8], f: &Faces, crossed: &[u64; 8], n: [u8; 3]) -> [u64; 8] {
    let cells = plane_mask(n[0] as u32 - 1, n[1] as u32 - 1);
    let nc = n[2] as usize - 1;
    let mut r: [u64; 8] = std::array::from_fn(|k| from[k] & crossed[k]);
    let grow = |x: u64, k: usize| {
        let mut x = x;
        loop {
            let y = (x
                | ((x << 1) & f.x[k])
                | ((x & f.x[k]) >> 1)
                | ((x << 8) & f.y[k])
                | ((x & f.y[k]) >> 8))
                & cells;
            if y == x {
                return x;
            }
            x = y;
        }
    };
    loop {
        // Every crossed cell reached: nothing left to grow into.
        if r == *crossed {
            return r;
        }
        let mut changed = false;
        // Up through the planes, then down.
        for k in (0..nc).chain((0..nc).rev()) {
            let mut x = r[k];
            if k > 0 {
                x |= r[k - 1] & f.z[k];
            }
            if k + 1 < nc {
                x |= r[k + 1] & f.z[k + 1];
            }
            let x = grow(x & cells, k);
            if x != r[k] {
                r[k] = x;
                changed = true;
            }
        }
        if !changed {
            return r;
        }
    }
}

/// Appends the components of a block's crossed cells to `out`: the sets of cells joined
/// through crossed faces, with the cells each enters in the neighbouring blocks.
fn components(a: &Active, crossed: &[u64; 8], out: &mut Vec<Component>) {
    let f = Faces::new(&a.signs, a.n);
    let [nx, ny, nz] = a.n.map(|v| v as usize);
    let nc = nz - 1;
    let mut left = *crossed;
    while let Some(k) = left.iter().position(|&w| w != 0) {
        let mut from = [0u64; 8];
        from[k] = left[k] & left[k].wrapping_neg();
        let r = flood(&from, &f, crossed, a.n);
        for (l, w) in left.iter_mut().zip(&r) {
            *l &= !w;
        }
        // Reached cells with a crossed face on the block's side, as the neighbour's cells.
        let mut exits = [[0u64; 8]; 6];
        for k in 0..nc {
            exits[0][k] = (r[k] & f.x[k] & COLUMN_0) << 6;
            exits[2][k] = (r[k] & f.y[k] & ROW_0) << 48;
            if !a.last[0] {
                exits[1][k] = (r[k] & (f.x[k] >> 1) & (COLUMN_0 << (nx - 2))) >> 6;
            }
            if !a.last[1] {
                exits[3][k] = (r[k] & (f.y[k] >> 8) & (ROW_0 << (8 * (ny - 2)))) >> 48;
            }
        }
        exits[4][6] = r[0] & f.z[0];
        if !a.last[2] {
            exits[5][0] = r[nc - 1] & f.z[nz - 1];
        }
        let sides = (0..6).fold(0u8, |m, side| {
            m | ((exits[side].iter().any(|&w| w != 0) as u8) << side)
        });
        out.push(Component {
            cells: r,
            exits,
            sides,
        });
    }
}

impl BlockTracking {
    /// Polygonizes the components of `field`'s surface that hold a seed, block by block: seed
    /// cells walked from `settings.starts` by the rule tracking cell by cell walks them (here
    /// read from the signs of the blocks the walks enter), and `settings.seed_cells`. With
    /// [`Components::All`], every component (the mesh is then sparse's, array for array). The
    /// mesh (vertices, normals) comes with its triangles as `I` beside it.
    pub(super) fn polygonize<F: BlockField + ?Sized, I: TriangleIndex>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        settings: &TrackingSettings,
    ) -> Result<(Mesh, Vec<[I; 3]>, Stats)> {
        let BlockStart {
            cases,
            blocks,
            mut stats,
            ..
        } = start_blocks::<F, I>(field, lattice, &settings.common, false)?;
        self.walk((field, &blocks), lattice, settings, cases, &mut stats)?;
        // The field's block data is not needed to assemble the mesh.
        drop(blocks);
        crate::cancel::check()?;
        let normals = settings.common.normals;
        let (mesh, triangles) = self.assemble(lattice, cases, normals, &mut stats)?;
        Ok((mesh, triangles, stats))
    }

    /// Starts a call: no block entered, and the blocks the last call used on the same lattice
    /// queued for the first wave (an animation's surface moves little from call to call, so
    /// the walk then rarely waits for a wave). Returns whether any was queued.
    fn begin(&mut self, lattice: &Lattice, grid: &BlockGrid) -> bool {
        self.map.clear();
        self.map.resize(grid.len(), NONE);
        self.states.clear();
        self.index.clear();
        self.wave.clear();
        self.work.clear();
        self.used_parts = 0;
        if self.last_lattice == Some(*lattice) {
            for k in 0..self.last.len() {
                self.queue(self.last[k], &[0; 8], false, grid);
            }
        }
        !self.wave.is_empty()
    }

    /// Enters seed cell `c` (ignored outside the lattice): its bit in its block.
    fn seed(&mut self, c: [u32; 3], lattice: &Lattice, grid: &BlockGrid) {
        if (0..3).all(|a| c[a] < lattice.cells()[a]) {
            let (i, l) = grid.locate(c);
            let mut bits = [0u64; 8];
            bits[l[2] as usize] = 1 << (l[0] + 8 * l[1]);
            self.enter(i as u32, &bits, grid);
        }
    }

    /// The walk: the seeds and the seed walks, then the flood through crossed faces, wave by
    /// wave of evaluation; with [`Components::All`], on from the cells it did not reach until
    /// none is left. Adds the phases' times and the points evaluated to `stats`.
    ///
    /// With [`Components::All`] and the last call's blocks queued (an animation on one
    /// lattice), there are no seed walks: they only choose where the walk starts, every
    /// component is entered from the last call's blocks and the blocks the bounds cannot rule
    /// out, and a walk from each of many starts (a particle's centre) crosses the inside of the
    /// surface cell by cell.
    fn walk<F: BlockField + ?Sized>(
        &mut self,
        (field, blocks): (&F, &F::Blocks),
        lattice: &Lattice,
        settings: &TrackingSettings,
        cases: &BlockCases,
        stats: &mut Stats,
    ) -> Result<()> {
        let t = Instant::now();
        let grid = block_grid(lattice);
        let again = self.begin(lattice, &grid);
        for &c in &settings.seed_cells {
            self.seed(c, lattice, &grid);
        }
        // The seed walks read the signs of the blocks they enter; they and the flood share the
        // waves of evaluation (the cells reached from a set of seeds do not depend on the order
        // in which the seeds are found).
        let starts: &[DVec3] = match settings.components {
            Components::All if again => &[],
            _ => &settings.starts,
        };
        let mut walkers = start_walkers(starts, lattice);
        for w in &walkers {
            self.enter(grid.locate(w.cell).0 as u32, &[0; 8], &grid);
        }
        let how = (cases, settings.common.normals);
        // Seconds evaluating (the rest of the walk is serial) and bounding blocks.
        let (mut waves, mut classify) = (0.0, 0.0);
        // Whether the blocks not entered were bounded (once, when the walk from the seeds ends).
        let mut classified = false;
        loop {
            if !self.wave.is_empty() {
                let w = Instant::now();
                stats.evaluations += self.evaluate_wave((field, blocks), lattice, how)?;
                waves += w.elapsed().as_secs_f64();
            }
            step_walkers(&mut walkers, |w| {
                self.step_walk(w, lattice, settings.max_walk, &grid)
            });
            self.flood_entered(&grid)?;
            // Walks still going wait for blocks of the next wave.
            if !self.wave.is_empty() {
                continue;
            }
            if settings.components == Components::Seeded {
                break;
            }
            // The walk has ended: the cells it did not reach (every crossed cell is in a block
            // evaluated or not ruled out by the bounds), until there are none.
            let c = Instant::now();
            self.enter_the_rest((field, blocks), lattice, !classified)?;
            classified = true;
            classify += c.elapsed().as_secs_f64();
            if self.wave.is_empty() && self.work.is_empty() {
                break;
            }
        }
        // The phases: the waves' evaluation, the bounds of the blocks not entered, the walks
        // and the flood.
        stats.seconds.push(("evaluate", waves));
        if settings.components == Components::All {
            stats.seconds.push(("classify", classify));
        }
        stats
            .seconds
            .push(("track", t.elapsed().as_secs_f64() - waves - classify));
        Ok(())
    }

    /// Walks `w` on through the blocks evaluated: false when it found a crossed cell (entered
    /// as a seed) or its walk is over; true when it waits for a block of the next wave.
    fn step_walk(
        &mut self,
        w: &mut Walker,
        lattice: &Lattice,
        max_walk: u32,
        grid: &BlockGrid,
    ) -> bool {
        loop {
            let (b, l) = grid.locate(w.cell);
            let st = match self.map[b] {
                NONE => {
                    self.enter(b as u32, &[0; 8], grid);
                    return true;
                }
                s => {
                    let st = &mut self.states[s as usize];
                    st.used = true;
                    &*st
                }
            };
            if st.kind == Kind::Queued {
                return true;
            }
            if st.crossed[l[2] as usize] >> (l[0] + 8 * l[1]) & 1 != 0 {
                self.seed(w.cell, lattice, grid);
                return false;
            }
            if !w.advance(lattice.cells(), max_walk) {
                return false;
            }
        }
    }

    /// The flood: serial bit arithmetic over the blocks on the work list, entering
    /// neighbouring blocks through crossed faces on the blocks' sides (new ones are evaluated
    /// in the next wave).
    fn flood_entered(&mut self, grid: &BlockGrid) -> Result<()> {
        while let Some(s) = self.work.pop() {
            let st = &mut self.states[s as usize];
            st.listed = false;
            // The components entered, not reached before, join the reached cells whole; their
            // cells on the block's sides enter the neighbours.
            let (first, end) = st.comps;
            let b = st.block;
            for c in first..end {
                let st = &mut self.states[s as usize];
                let comp = &self.parts[st.part as usize].comps[c as usize];
                let hit = (0..8).any(|k| comp.cells[k] & st.pending[k] != 0);
                if !hit || (0..8).any(|k| comp.cells[k] & st.reach[k] != 0) {
                    continue;
                }
                for (w, &x) in st.reach.iter_mut().zip(&comp.cells) {
                    *w |= x;
                }
                let (sides, part) = (comp.sides, st.part as usize);
                for side in 0..6 {
                    if sides >> side & 1 == 0 {
                        continue;
                    }
                    let axis = side / 2;
                    let mut nb = b;
                    if side % 2 == 0 {
                        if b[axis] == 0 {
                            continue;
                        }
                        nb[axis] -= 1;
                    } else {
                        nb[axis] += 1;
                    }
                    let bits = self.parts[part].comps[c as usize].exits[side];
                    if !self.enter(grid.index(nb) as u32, &bits, grid) {
                        return Err(bounds_error());
                    }
                }
            }
            self.states[s as usize].pending = [0; 8];
        }
        Ok(())
    }

    /// The mesh of the cells reached: the blocks with reached cells in block order (so the
    /// mesh depends neither on the order of the waves nor on earlier calls: it is sparse's,
    /// less the cells not reached), their vertices gathered block by block, the triangles as
    /// `I`; and the blocks used, for the next call.
    fn assemble<I: TriangleIndex>(
        &mut self,
        lattice: &Lattice,
        cases: &BlockCases,
        normals: bool,
        stats: &mut Stats,
    ) -> Result<(Mesh, Vec<[I; 3]>)> {
        let t = Instant::now();
        let grid = block_grid(lattice);
        let ws = self;
        ws.last.clear();
        ws.order.clear();
        for (s, st) in ws.states.iter().enumerate() {
            if st.used {
                ws.last.push(ws.index[s]);
            }
            if st.kind == Kind::Mixed && st.reach.iter().any(|&w| w != 0) {
                ws.order.push((ws.index[s], s as u32));
            }
        }
        ws.last.sort_unstable();
        ws.last_lattice = Some(*lattice);
        ws.order.sort_unstable();
        ws.active.clear();
        ws.reach.clear();
        ws.amap.clear();
        ws.amap.resize(grid.len(), NONE);
        ws.kept.clear();
        ws.kept_normals.clear();
        ws.sources.clear();
        let mut vertices = 0usize;
        for &(i, s) in &ws.order {
            let st = &ws.states[s as usize];
            let part = &ws.parts[st.part as usize];
            let (active, out) = (&part.evaluated[st.slot as usize].0, &part.out);
            let from = active.base as usize;
            stats.cells_visited += st.reach.iter().map(|w| w.count_ones() as u64).sum::<u64>();
            ws.amap[i as usize] = ws.active.len() as u32;
            let base = u32::try_from(vertices)
                .map_err(|_| Error::invalid("resolution", "more than 2³² vertices"))?;
            let mut a = if st.reach == st.crossed {
                ws.sources.push((st.part, from, from + active.vertices()));
                *active
            } else {
                // Crossed cells no seed reaches: fewer triangles, and only the vertices of
                // edges next to a reached cell (copied aside).
                let (kept, kept_normals) = (&mut ws.kept, &mut ws.kept_normals);
                let start = kept.len();
                let a = active.restricted(cases, &st.reach, |v| {
                    kept.push(out.vertices[from + v]);
                    if normals {
                        kept_normals.push(out.normals[from + v]);
                    }
                });
                ws.sources.push((NONE, start, ws.kept.len()));
                a
            };
            a.base = base;
            vertices += a.vertices();
            ws.active.push(a);
            ws.reach.push(st.reach);
        }
        let slices = |normals: bool| -> Vec<&[DVec3]> {
            let pick = |&(p, a, b): &(u32, usize, usize)| match (p, normals) {
                (NONE, false) => &ws.kept[a..b],
                (NONE, true) => &ws.kept_normals[a..b],
                (p, false) => &ws.parts[p as usize].out.vertices[a..b],
                (p, true) => &ws.parts[p as usize].out.normals[a..b],
            };
            ws.sources.iter().map(pick).collect()
        };
        // Each step writes a large buffer: Ctrl-C is checked between them.
        let vertices = gather(&slices(false));
        crate::cancel::check()?;
        let mut mesh = Mesh {
            vertices,
            normals: if normals {
                gather(&slices(true))
            } else {
                Vec::new()
            },
            ..Default::default()
        };
        crate::cancel::check()?;
        let (triangles, crossed) =
            triangulate_blocks::<I, true>(cases, &ws.active, Some(&ws.reach), &ws.amap, &grid)?;
        stats.cells_crossed = crossed;
        stats.add_time("triangulate", t);
        crate::cancel::check()?;
        if normals {
            let t = Instant::now();
            let outputs: Vec<&BlockOutput> =
                ws.parts[..ws.used_parts].iter().map(|p| &p.out).collect();
            finish_normals(&mut mesh, &triangles, &outputs)?;
            stats.normal_evaluations = mesh.vertices.len() as u64;
            stats.add_time("normals", t);
        }
        Ok((mesh, triangles))
    }
}
