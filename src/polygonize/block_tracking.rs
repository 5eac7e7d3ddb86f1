//! Surface tracking block by block: Triquet et al.'s walk (§4.4) over the blocks of 7³ cells of
//! [`super::sparse`], for fields that evaluate whole blocks at once ([`BlockField`], e.g. blob
//! fields).
//!
//! The cells reached are exactly those of cell-by-cell tracking ([`super::tracking`]): the
//! crossed cells joined to a seed cell through faces the surface crosses, from the same seeds
//! (the seed walks, by the same rule, read the signs of the blocks they pass). A block is
//! evaluated (all its 8³ points, vectorised) when a seed walk or the walk first enters one of
//! its cells; the same task splits its crossed cells into components (cells joined through
//! crossed faces, by a flood over bit sets, one 64-bit word per plane of cells), and the walk
//! takes each component it enters whole, entering the neighbouring blocks through the
//! component's crossed faces on the block's sides. Vertices, normals and triangles are then
//! made as by [`super::sparse`], triangles only for the cells reached and vertices only for
//! their edges, so the mesh is the dense mesh on every component that holds a seed, triangle
//! for triangle and bit for bit, and, like cell tracking's, it holds whole components only.
//!
//! With [`Components::All`] it finds every component, those no seed reaches too (the inner
//! surface of a cavity inside a cluster of blobs): when the walk from the seeds ends, the
//! crossed cells it did not reach in the blocks it evaluated, and every cell of the blocks it
//! did not enter that the field's bounds cannot rule out (the blocks [`super::sparse`]
//! evaluates, which hold every crossed cell), are entered, and the walk goes on until no cell
//! is left. The blocks not entered are bounded once; only those the bounds cannot rule out are
//! evaluated. The mesh is then sparse's, array for array: the dense mesh.
//!
//! Blocks are evaluated in waves (those newly entered), each wave in parallel; the seed walks'
//! steps and the walk between waves are serial bit arithmetic. An animation's surface moves
//! little from call to call, so the blocks the last call used (kept in the [`Workspace`]) are
//! evaluated in the first wave, and the walk rarely waits for a second. The output is
//! ordered by block, like sparse's: it depends neither on the number of threads nor on the
//! calls before.
//!
//! ```
//! use glam::DVec3;
//! use implicitmesh::field::blob::{BlobField, PerPrimitive, BlobSettings};
//! use implicitmesh::lattice::Lattice;
//! use implicitmesh::polygonize::tracking::Components;
//! use implicitmesh::polygonize::{block_tracking, dense, Settings};
//!
//! // Two blobs far apart: seeding one cell of the first finds only the first.
//! let centers = [DVec3::new(-0.5, 0.0, 0.0), DVec3::new(0.5, 0.0, 0.0)];
//! let blobs = BlobField::new(
//!     &centers,
//!     PerPrimitive::All(0.3),
//!     PerPrimitive::All(1.0),
//!     0.5,
//!     BlobSettings::default(),
//! )
//! .unwrap();
//! let lattice = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 40).unwrap();
//! // x from -0.35 to -0.3: the first blob's surface (at x = -0.338) crosses the cell.
//! let seed = [[13, 20, 20]];
//! let mut ws = block_tracking::Workspace::default();
//! let no_walks = (&[][..], 0);
//! let settings = Settings::default();
//! let seeded = Components::Seeded;
//! let (mesh, triangles, _) = block_tracking::polygonize_as::<_, u32>(
//!     &blobs, &lattice, no_walks, &seed, &settings, seeded, &mut ws,
//! )
//! .unwrap();
//! let (both, _) = dense::polygonize(&blobs, &lattice, &Settings::default()).unwrap();
//! let first = both.triangles.iter().filter(|t| both.vertices[t[0] as usize].x < 0.0);
//! assert_eq!(triangles.len(), first.count());
//! assert!(mesh.vertices.iter().all(|v| v.x < 0.0));
//! ```

use super::sparse::{
    block_dims, blocks_not_ruled_out, bounds_error, crossed_layer_cells, evaluate_block,
    finish_normals, plane_mask, triangulate_blocks, Active, BlockCases, BlockOutput, TriangleIndex,
    ALL_CELLS, NONE, STEP,
};
use super::tracking::{start_walkers, Components};
use super::{
    check_memory, estimate_triangles, gather, CaseTable, Settings, Stats, BYTES_PER_TRIANGLE,
};
use crate::error::{Error, Result};
use crate::field::BlockField;
use crate::lattice::Lattice;
use crate::mesh::Mesh;
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

/// Blocks per task of a wave's evaluation.
const BLOCKS_PER_TASK: usize = 8;

/// Bits of a plane word at x = 0 (one per row).
const COLUMN_0: u64 = 0x0101_0101_0101_0101;
/// Bits of a plane word at y = 0.
const ROW_0: u64 = 0xff;

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
        let mixed = |w: [u64; 4]| (w[0] | w[1] | w[2] | w[3]) & !(w[0] & w[1] & w[2] & w[3]);
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

/// Buffers kept between calls (an animation allocates nothing here in steady state).
#[derive(Default)]
pub struct Workspace {
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

impl Workspace {
    /// Bytes held (capacities).
    pub fn capacity_bytes(&self) -> usize {
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

    /// Evaluates the blocks entered since the last wave, in parallel; those with both signs
    /// and cells entered go on the flood's work list. Returns the points evaluated.
    fn evaluate_wave<F: BlockField + ?Sized>(
        &mut self,
        field: &F,
        cases: &BlockCases,
        blocks: &F::Blocks,
        lattice: &Lattice,
        normals: bool,
    ) -> u64 {
        let dims = block_dims(lattice);
        let used = self.used_parts;
        let tasks = self.wave.len().div_ceil(BLOCKS_PER_TASK);
        if self.parts.len() < used + tasks {
            self.parts.resize_with(used + tasks, Part::default);
        }
        let (wave, index) = (&self.wave, &self.index);
        self.parts[used..used + tasks]
            .par_iter_mut()
            .zip(wave.par_chunks(BLOCKS_PER_TASK))
            .for_each(|(part, chunk)| {
                part.done.clear();
                part.evaluated.clear();
                part.out.clear();
                part.comps.clear();
                let mut values = [0.0f64; 512];
                for &s in chunk {
                    let i = index[s as usize];
                    let b = [
                        i % dims[0],
                        (i / dims[0]) % dims[1],
                        i / (dims[0] * dims[1]),
                    ];
                    let out = &mut part.out;
                    // Triangles counted for all crossed cells (those usually all reached), and
                    // the components that the walk will reach whole.
                    let got =
                        evaluate_block(field, blocks, lattice, dims, b, normals, &mut values, out);
                    let slot = match got {
                        None => NONE,
                        Some(a) => {
                            let a = Active {
                                triangles: cases.count(&a, &ALL_CELLS),
                                ..a
                            };
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
        self.wave.clear();
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
    fn enter(&mut self, i: u32, cells: &[u64; 8], dims: [u32; 3]) -> bool {
        let s = self.map[i as usize];
        if s == NONE {
            self.queue(i, cells, true, dims);
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
    ) {
        let dims = block_dims(lattice);
        if classify {
            let map = &self.map;
            let not_entered = |i: u32| map[i as usize] == NONE;
            let (marks, candidates) = (&mut self.marks, &mut self.candidates);
            blocks_not_ruled_out(field, blocks, lattice, not_entered, marks, candidates);
            for k in 0..self.candidates.len() {
                self.queue(self.candidates[k], &ALL_CELLS, true, dims);
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
                self.enter(self.index[s], &rest, dims);
            }
        }
    }

    /// Queues block `i` (not yet entered) for the next wave.
    fn queue(&mut self, i: u32, cells: &[u64; 8], used: bool, dims: [u32; 3]) {
        self.map[i as usize] = self.states.len() as u32;
        self.wave.push(self.states.len() as u32);
        self.index.push(i);
        self.states.push(State {
            kind: Kind::Queued,
            listed: false,
            used,
            part: 0,
            slot: NONE,
            block: [
                i % dims[0],
                (i / dims[0]) % dims[1],
                i / (dims[0] * dims[1]),
            ],
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

/// Polygonizes the components of `field`'s surface that hold a seed, block by block: seed
/// cells walked from `starts` as [`super::tracking::Tessellator::walk_seeds`] walks them (at most
/// `max_walk` cells each; here read from the signs of the blocks the walks enter), and
/// `seed_cells` (those outside the lattice and those the surface does not cross are ignored).
/// With [`Components::All`], every component: when the walk ends, the crossed cells it did not
/// reach in the blocks evaluated, and the blocks not entered that the field's bounds cannot
/// rule out, are entered, and the walk goes on (the mesh is then [`super::sparse`]'s, array
/// for array). The mesh (vertices, normals) comes with its triangles as `I` beside it; `ws`
/// keeps the buffers for the next call.
#[allow(clippy::too_many_arguments)]
pub fn polygonize_as<F: BlockField + ?Sized, I: TriangleIndex>(
    field: &F,
    lattice: &Lattice,
    (starts, max_walk): (&[DVec3], u32),
    seed_cells: &[[u32; 3]],
    settings: &Settings,
    components: Components,
    ws: &mut Workspace,
) -> Result<(Mesh, Vec<[I; 3]>, Stats)> {
    let dims = block_dims(lattice);
    let num_blocks = dims.iter().map(|&d| d as u64).product::<u64>();
    check_memory(
        num_blocks * 4 + estimate_triangles(lattice) * BYTES_PER_TRIANGLE,
        settings.memory_limit,
    )?;
    let num_blocks = num_blocks as usize;
    let table = CaseTable::get(settings.ambiguity);
    let cases = BlockCases::get(table);
    let mut stats = Stats {
        lattice_points: lattice.num_points(),
        ..Default::default()
    };
    let t = Instant::now();
    let blocks = field.blocks(lattice, dims);
    stats.add_time("blocks", t);

    let t = Instant::now();
    ws.map.clear();
    ws.map.resize(num_blocks, NONE);
    ws.states.clear();
    ws.index.clear();
    ws.wave.clear();
    ws.work.clear();
    ws.used_parts = 0;
    // An animation's surface moves little from call to call: the blocks the last call used are
    // evaluated in the first wave, beside the seeds' (the walk then rarely waits for a wave).
    if ws.last_lattice == Some(*lattice) {
        for k in 0..ws.last.len() {
            ws.queue(ws.last[k], &[0; 8], false, dims);
        }
    }
    let cells = lattice.cells;
    let locate = |c: [u32; 3]| {
        let b = c.map(|v| v / STEP);
        (
            b[0] + dims[0] * (b[1] + dims[1] * b[2]),
            c.map(|v| v % STEP),
        )
    };
    let normals = settings.normals;
    let eval = |ws: &mut Workspace| ws.evaluate_wave(field, cases, &blocks, lattice, normals);
    let block_index = |b: [u32; 3]| b[0] + dims[0] * (b[1] + dims[1] * b[2]);
    // A seed cell: its bit, entering its block.
    let seed = |ws: &mut Workspace, c: [u32; 3]| {
        if (0..3).all(|a| c[a] < cells[a]) {
            let (i, l) = locate(c);
            let mut bits = [0u64; 8];
            bits[l[2] as usize] = 1 << (l[0] + 8 * l[1]);
            ws.enter(i, &bits, dims);
        }
    };
    for &c in seed_cells {
        seed(ws, c);
    }
    // The seed walks read the signs of the blocks they enter; they and the flood share the
    // waves of evaluation (the cells reached from a set of seeds do not depend on the order in
    // which the seeds are found).
    let mut walkers = start_walkers(starts, lattice);
    for w in &walkers {
        ws.enter(locate(w.cell).0, &[0; 8], dims);
    }
    // Seconds evaluating (the rest of the walk is serial) and bounding blocks.
    let (mut waves, mut classify) = (0.0, 0.0);
    // Whether the blocks not entered were bounded (once, when the walk from the seeds ends).
    let mut classified = false;
    loop {
        if !ws.wave.is_empty() {
            let w = Instant::now();
            stats.evaluations += eval(ws);
            waves += w.elapsed().as_secs_f64();
        }
        let mut keep = 0;
        for i in 0..walkers.len() {
            let mut w = walkers[i];
            let alive = loop {
                let (b, l) = locate(w.cell);
                let st = match ws.map[b as usize] {
                    NONE => {
                        ws.enter(b, &[0; 8], dims);
                        break true;
                    }
                    s => {
                        let st = &mut ws.states[s as usize];
                        st.used = true;
                        &*st
                    }
                };
                if st.kind == Kind::Queued {
                    break true;
                }
                if st.crossed[l[2] as usize] >> (l[0] + 8 * l[1]) & 1 != 0 {
                    seed(ws, w.cell);
                    break false;
                }
                if !w.advance(cells, max_walk) {
                    break false;
                }
            };
            if alive {
                walkers[keep] = w;
                keep += 1;
            }
        }
        walkers.truncate(keep);
        walkers.sort_unstable();
        walkers.dedup();
        // Flood: serial bit arithmetic, entering neighbouring blocks through crossed faces on
        // the blocks' sides (new ones are evaluated in the next wave).
        while let Some(s) = ws.work.pop() {
            let st = &mut ws.states[s as usize];
            st.listed = false;
            // The components entered, not reached before, join the reached cells whole; their
            // cells on the block's sides enter the neighbours.
            let (first, end) = st.comps;
            let b = st.block;
            for c in first..end {
                let st = &mut ws.states[s as usize];
                let comp = &ws.parts[st.part as usize].comps[c as usize];
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
                    let bits = ws.parts[part].comps[c as usize].exits[side];
                    if !ws.enter(block_index(nb), &bits, dims) {
                        return Err(bounds_error());
                    }
                }
            }
            ws.states[s as usize].pending = [0; 8];
        }
        // Walks still going wait for blocks of the next wave.
        if !ws.wave.is_empty() {
            continue;
        }
        if components == Components::Seeded {
            break;
        }
        // The walk has ended: the cells it did not reach (every crossed cell is in a block
        // evaluated or not ruled out by the bounds), until there are none.
        let c = Instant::now();
        ws.enter_the_rest((field, &blocks), lattice, !classified);
        classified = true;
        classify += c.elapsed().as_secs_f64();
        if ws.wave.is_empty() && ws.work.is_empty() {
            break;
        }
    }
    // The phases: the waves' evaluation, the bounds of the blocks not entered, the walks and
    // the flood.
    stats.seconds.push(("evaluate", waves));
    if components == Components::All {
        stats.seconds.push(("classify", classify));
    }
    stats
        .seconds
        .push(("track", t.elapsed().as_secs_f64() - waves - classify));

    // The blocks with reached cells, in block order (so the mesh depends neither on the order
    // of the waves nor on earlier calls: it is sparse's, less the cells not reached), their
    // vertices gathered block by block; the blocks used, for the next call.
    let t = Instant::now();
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
    ws.amap.resize(num_blocks, NONE);
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
        let mut a = Active { base, ..*active };
        if st.reach == st.crossed {
            ws.sources.push((st.part, from, from + active.vertices()));
        } else {
            // Crossed cells no seed reaches: fewer triangles, and only the vertices of edges
            // next to a reached cell (copied aside).
            a.triangles = cases.count(&a, &st.reach);
            let used = used_edges(&a, &st.reach);
            let start = ws.kept.len();
            let mut v = from;
            for (&e, &u) in a.edges.iter().zip(&used) {
                let mut m = e;
                while m != 0 {
                    if u & m & m.wrapping_neg() != 0 {
                        ws.kept.push(out.vertices[v]);
                        if normals {
                            ws.kept_normals.push(out.normals[v]);
                        }
                    }
                    m &= m - 1;
                    v += 1;
                }
            }
            ws.sources.push((NONE, start, ws.kept.len()));
            a.edges = used;
            let mut count = 0u16;
            for (b, e) in a.before.iter_mut().zip(&used) {
                *b = count;
                count += e.count_ones() as u16;
            }
        }
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
    let mut mesh = Mesh {
        vertices: gather(&slices(false)),
        normals: if normals {
            gather(&slices(true))
        } else {
            Vec::new()
        },
        ..Default::default()
    };
    let (triangles, crossed) =
        triangulate_blocks::<I, true>(cases, &ws.active, Some(&ws.reach), &ws.amap, dims)?;
    stats.cells_crossed = crossed;
    stats.add_time("triangulate", t);
    if normals {
        let t = Instant::now();
        let outputs: Vec<&BlockOutput> = ws.parts[..ws.used_parts].iter().map(|p| &p.out).collect();
        finish_normals(&mut mesh, &triangles, &outputs)?;
        stats.normal_evaluations = mesh.vertices.len() as u64;
        stats.add_time("normals", t);
    }
    Ok((mesh, triangles, stats))
}

/// The crossed edges `a` owns that its cells in `reach` use: those whose vertices the mesh
/// keeps. The four cells around a crossed edge are joined through crossed faces (each face
/// holding the edge has corners of both signs), so the walk reaches all or none of them, and
/// one in the block (the nearest, as the block's upper faces have no cells beyond) decides.
fn used_edges(a: &Active, reach: &[u64; 8]) -> [u64; 24] {
    let [nx, ny, nz] = a.n.map(|v| v as usize);
    // Bits of the last column (x) and row (y) of cells, moved onto the points beyond them (the
    // column's whole, for the row's moved bits too).
    let column = COLUMN_0 << (nx - 2);
    let row = ROW_0 << (8 * (ny - 2));
    let up_y = |r: u64| r | ((r & row) << 8);
    let up_x = |r: u64| r | ((r & column) << 1);
    let mut used = [0u64; 24];
    for k in 0..nz {
        let r = reach[k.min(nz - 2)];
        used[k] = a.edges[k] & up_y(r);
        used[8 + k] = a.edges[8 + k] & up_x(r);
        if k + 1 < nz {
            used[16 + k] = a.edges[16 + k] & up_x(up_y(reach[k]));
        }
    }
    used
}

#[cfg(test)]
mod tests {
    use super::super::{dense, tracking, Ambiguity};
    use super::*;
    use crate::field::testing::random_blobs as blobs;
    use crate::field::testing::{canonical_triangles as canonical, vertex_normal_bits, Lying};
    use glam::DVec3;

    const SEEDED: Components = Components::Seeded;

    /// Block tracking and cell tracking, each walking its seeds from the blob centres: the same
    /// triangles, vertices and normals (bits), every vertex used.
    fn check(
        field: &crate::field::blob::BlobField,
        l: &Lattice,
        amb: Ambiguity,
        ws: &mut Workspace,
    ) {
        let s = Settings {
            ambiguity: amb,
            ..Default::default()
        };
        let mut tess = tracking::Tessellator::new();
        let max_walk = 12;
        let (cells, st) = tess
            .polygonize(field, l, field.centers(), max_walk, &[], &s)
            .unwrap();
        let walk = (field.centers(), max_walk);
        let (m, t, bs) = polygonize_as::<_, u32>(field, l, walk, &[], &s, SEEDED, ws).unwrap();
        assert_same((&m, &t, &bs), (cells, &st));
    }

    /// The walk block by block's output equals the walk cell by cell's: the same triangles,
    /// vertices and normals (bits), every vertex used, the same cells crossed.
    fn assert_same((m, t, bs): (&Mesh, &[[u32; 3]], &Stats), (cells, st): (&Mesh, &Stats)) {
        assert_eq!(
            canonical(&m.vertices, t),
            canonical(&cells.vertices, &cells.triangles)
        );
        assert_eq!(m.vertices.len(), cells.vertices.len());
        assert_eq!(bs.cells_crossed, st.cells_crossed);
        assert_eq!(
            vertex_normal_bits(&m.vertices, &m.normals),
            vertex_normal_bits(&cells.vertices, &cells.normals)
        );
    }

    #[test]
    fn equals_cell_tracking_on_random_blobs() {
        let mut ws = Workspace::default();
        for (n, r, res, seed) in [
            (200, 0.25, 64, 1),
            (60, 0.12, 37, 2),
            (500, 0.08, 50, 3),
            (5, 0.6, 22, 4),
            (1, 0.3, 7, 5),
            (30, 0.2, 8, 6),
            (40, 0.1, 90, 7),
        ] {
            let f = blobs(n, r, seed);
            let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), res).unwrap();
            for amb in [Ambiguity::Separate, Ambiguity::Join] {
                check(&f, &l, amb, &mut ws);
            }
        }
    }

    #[test]
    fn one_seed_finds_one_component_of_many() {
        // Separate blobs on a line, sharing blocks: a seed in one finds it alone, and only the
        // vertices of its triangles.
        use crate::field::blob::{BlobField, BlobSettings, PerPrimitive};
        let centers: Vec<DVec3> = (0..4)
            .map(|i| DVec3::new(-0.45 + 0.3 * i as f64, 0.1, -0.05))
            .collect();
        let f = BlobField::new(
            &centers,
            PerPrimitive::All(0.2),
            PerPrimitive::All(1.0),
            0.5,
            BlobSettings::default(),
        )
        .unwrap();
        let l = Lattice::new(DVec3::splat(-1.0), DVec3::splat(1.0), [61, 23, 30]).unwrap();
        let (all, _) = dense::polygonize(&f, &l, &Settings::default()).unwrap();
        let mut ws = Workspace::default();
        for centre in &centers {
            // Walked from inside the blob along +x to its surface.
            let c = *centre - DVec3::new(0.05, 0.0, 0.0);
            let walk = (&[c][..], 20);
            let (m, t, _) =
                polygonize_as::<_, u32>(&f, &l, walk, &[], &Settings::default(), SEEDED, &mut ws)
                    .unwrap();
            let near = |v: DVec3| (v.x - centre.x).abs() < 0.15;
            let own = all.triangles.iter();
            let own = own.filter(|t| near(all.vertices[t[0] as usize]));
            assert_eq!(t.len(), own.count());
            assert!(!t.is_empty());
            assert!(m.vertices.iter().all(|&v| near(v)));
            // Every vertex is used.
            let mut used = vec![false; m.vertices.len()];
            t.iter().flatten().for_each(|&v| used[v as usize] = true);
            assert!(used.iter().all(|&u| u));
        }
    }

    #[test]
    fn wrong_bounds_give_an_error_not_a_panic() {
        let f = Lying::sphere();
        let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 32).unwrap();
        // Cell (8, 16, 16) holds the surface (at x = -0.487, in block 1); the sphere also crosses
        // block 2, which the bounds wrongly rule out.
        let mut ws = Workspace::default();
        let (seed, none) = ([[8, 16, 16]], (&[][..], 0));
        let e = polygonize_as::<_, u32>(&f, &l, none, &seed, &Settings::default(), SEEDED, &mut ws)
            .unwrap_err();
        assert!(
            matches!(e, Error::InvalidArgument { name: "field", .. }),
            "{e}"
        );
        // The true field from the same seed: the whole sphere.
        let (m, t, _) =
            polygonize_as::<_, u32>(&f.0, &l, none, &seed, &Settings::default(), SEEDED, &mut ws)
                .unwrap();
        let (d, _) = dense::polygonize(&f.0, &l, &Settings::default()).unwrap();
        assert_eq!(
            (m.vertices.len(), t.len()),
            (d.vertices.len(), d.triangles.len())
        );
    }

    #[test]
    fn seeds_not_crossed_or_outside_find_nothing() {
        let f = blobs(10, 0.2, 8);
        let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 30).unwrap();
        let mut ws = Workspace::default();
        let (m, t, st) = polygonize_as::<_, u32>(
            &f,
            &l,
            (&[][..], 0),
            &[[0, 0, 0], [30, 2, 2], [u32::MAX, 0, 0]],
            &Settings::default(),
            SEEDED,
            &mut ws,
        )
        .unwrap();
        assert!(t.is_empty() && m.vertices.is_empty());
        assert_eq!(st.cells_crossed, 0);
    }

    /// A seed cell in every triangle of `m` (the cell holding its centroid).
    fn seeds_of(m: &Mesh, l: &Lattice) -> Vec<[u32; 3]> {
        m.triangles
            .iter()
            .map(|t| {
                let c = t.iter().map(|&v| m.vertices[v as usize]).sum::<DVec3>() / 3.0;
                ((c - l.origin) / l.cell)
                    .floor()
                    .to_array()
                    .map(|v| v as u32)
            })
            .collect()
    }

    #[test]
    fn equals_sparse_exactly_whatever_the_earlier_calls() {
        // Every component seeded: sparse's mesh, array for array (same order, same bits),
        // from a fresh workspace and from one that polygonized other fields and lattices first
        // (whose blocks it evaluates ahead).
        let s = Settings::default();
        let mut kept = Workspace::default();
        let cube = |res| Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), res).unwrap();
        for (n, r, res, seed) in [
            (200, 0.25, 64, 11),
            (200, 0.25, 64, 12),
            (60, 0.12, 37, 13),
            (500, 0.08, 50, 14),
            (500, 0.08, 64, 14),
            (3, 0.5, 20, 15),
        ] {
            let f = blobs(n, r, seed);
            let l = cube(res);
            let (sp, _) = super::super::sparse::polygonize(&f, &l, &s).unwrap();
            let seeds = seeds_of(&sp, &l);
            let none = (&[][..], 0);
            let (m, t, _) = polygonize_as::<_, u32>(
                &f,
                &l,
                none,
                &seeds,
                &s,
                SEEDED,
                &mut Workspace::default(),
            )
            .unwrap();
            assert!(!t.is_empty());
            assert_eq!(t, sp.triangles);
            assert_eq!(m.vertices, sp.vertices);
            assert_eq!(m.normals, sp.normals);
            let (again, t_again, _) =
                polygonize_as::<_, u32>(&f, &l, none, &seeds, &s, SEEDED, &mut kept).unwrap();
            assert_eq!(t_again, sp.triangles);
            assert_eq!(again.vertices, sp.vertices);
            assert_eq!(again.normals, sp.normals);
        }
    }

    #[test]
    fn every_component_without_seeds_is_sparse_exactly() {
        // No seed at all: every component is found, sparse's mesh array for array, from a fresh
        // workspace and from one that polygonized other fields first; every point evaluated is
        // counted.
        let s = Settings::default();
        let mut kept = Workspace::default();
        let none = (&[][..], 0);
        for (n, r, res, seed) in [(200, 0.25, 64, 31), (60, 0.12, 37, 32), (3, 0.5, 20, 33)] {
            let f = crate::field::Counting::new(blobs(n, r, seed));
            let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), res).unwrap();
            let (sp, _) = super::super::sparse::polygonize(&f.inner, &l, &s).unwrap();
            assert!(!sp.triangles.is_empty());
            for ws in [&mut Workspace::default(), &mut kept] {
                let before = f.evaluations();
                let (m, t, st) =
                    polygonize_as::<_, u32>(&f, &l, none, &[], &s, Components::All, ws).unwrap();
                assert_eq!(t, sp.triangles);
                assert_eq!((&m.vertices, &m.normals), (&sp.vertices, &sp.normals));
                assert_eq!(st.evaluations, f.evaluations() - before);
            }
        }
    }

    #[test]
    fn every_component_with_wrong_bounds_gives_an_error() {
        // The bounds rule out blocks the sphere crosses: an error, not a panic nor a mesh with
        // holes.
        let f = Lying::sphere();
        let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 32).unwrap();
        let none = (&[][..], 0);
        let mut ws = Workspace::default();
        let all = Components::All;
        let e = polygonize_as::<_, u32>(&f, &l, none, &[], &Settings::default(), all, &mut ws)
            .unwrap_err();
        assert!(
            matches!(e, Error::InvalidArgument { name: "field", .. }),
            "{e}"
        );
    }

    #[test]
    fn blocks_evaluated_ahead_change_nothing() {
        // A workspace that last polygonized all of a field, then one seed: only that seed's
        // component, the same arrays as from a fresh workspace (the blocks evaluated ahead that
        // no seed reaches add nothing; those partly reached give up their unused vertices).
        let s = Settings::default();
        let f = blobs(40, 0.2, 21);
        let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 48).unwrap();
        let (sp, _) = super::super::sparse::polygonize(&f, &l, &s).unwrap();
        let seeds = seeds_of(&sp, &l);
        let none = (&[][..], 0);
        let mut kept = Workspace::default();
        let (all, all_t, _) =
            polygonize_as::<_, u32>(&f, &l, none, &seeds, &s, SEEDED, &mut kept).unwrap();
        let mut smaller = 0;
        for seed in seeds.iter().step_by(97) {
            let one = std::slice::from_ref(seed);
            let (m, t, st) =
                polygonize_as::<_, u32>(&f, &l, none, one, &s, SEEDED, &mut Workspace::default())
                    .unwrap();
            // Evaluated ahead: at least the blocks of the whole surface.
            polygonize_as::<_, u32>(&f, &l, none, &seeds, &s, SEEDED, &mut kept).unwrap();
            let (k, kt, kst) =
                polygonize_as::<_, u32>(&f, &l, none, one, &s, SEEDED, &mut kept).unwrap();
            assert!(kst.evaluations > st.evaluations);
            assert_eq!(
                (kt, k.vertices, k.normals),
                (t.clone(), m.vertices, m.normals)
            );
            smaller += (t.len() < all_t.len()) as usize;
        }
        // The seeds found components smaller than the whole.
        assert!(smaller > 0 && !all.vertices.is_empty());
    }

    #[test]
    fn blobs_apart_in_the_last_blocks_one_at_a_time() {
        // Blobs 0.08 apart on a grid by the lattice's upper corner, cut by its sides, in
        // blocks shared by several (and last blocks of 2 points along each axis): seeded one at
        // a time, each equals cell tracking's, bit for bit, and keeps only its own vertices.
        use crate::field::blob::{BlobField, BlobSettings, PerPrimitive};
        let mut centers = vec![];
        for i in 0..4 {
            for j in 0..4 {
                for k in 0..4 {
                    centers.push(
                        DVec3::new(0.75, 0.751, 0.752)
                            + 0.08 * DVec3::new(i as f64, j as f64, k as f64),
                    );
                }
            }
        }
        let f = BlobField::new(
            &centers,
            PerPrimitive::All(0.055),
            PerPrimitive::All(1.0),
            0.5,
            BlobSettings::default(),
        )
        .unwrap();
        // 36 cells per axis: blocks of 7, 7, 7, 7, 7 and a last block of 1 cell.
        let l = Lattice::cubic(DVec3::splat(0.64), DVec3::splat(1.0), 36).unwrap();
        let (s, mut ws, mut tess) = (
            Settings::default(),
            Workspace::default(),
            tracking::Tessellator::new(),
        );
        let mut found = 0;
        for c in &centers {
            let start = std::slice::from_ref(c);
            let (cells, st) = tess.polygonize(&f, &l, start, 10, &[], &s).unwrap();
            let (m, t, bs) =
                polygonize_as::<_, u32>(&f, &l, (start, 10), &[], &s, SEEDED, &mut ws).unwrap();
            assert_same((&m, &t, &bs), (cells, &st));
            found += !t.is_empty() as usize;
        }
        // Every blob found alone (the blobs do not touch).
        assert_eq!(found, centers.len());
        let (all, _) = dense::polygonize(&f, &l, &s).unwrap();
        assert!(all
            .vertices
            .iter()
            .any(|v| v.max_element() > l.origin.x + 35.0 * l.cell.x));
    }
}
