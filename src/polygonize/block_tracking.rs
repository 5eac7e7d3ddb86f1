//! Surface tracking block by block: Triquet et al.'s walk (§4.4) over the blocks of 7³ cells of
//! [`super::sparse`], for fields that evaluate whole blocks at once ([`BlockField`], e.g. blob
//! fields).
//!
//! The cells reached are exactly those of cell-by-cell tracking ([`super::tracking`]): the
//! crossed cells joined to a seed cell through faces the surface crosses, from the same seeds
//! (the seed walks, by the same rule, read the signs of the blocks they pass). A block is
//! evaluated (all its 8³ points, vectorised) when a seed walk or the walk first enters one of
//! its cells; within it, the
//! walk is a flood over bit sets (one 64-bit word per plane of cells, a cell joining its
//! neighbour when the face between them has corners of both signs); a reached cell with a
//! crossed face on the block's side enters the neighbouring block. Vertices, normals and
//! triangles are then made as by [`super::sparse`], triangles only for the cells reached, so
//! the mesh is the dense mesh on every component that holds a seed, triangle for triangle and
//! bit for bit, and, like cell tracking's, it holds whole components only.
//!
//! Blocks are evaluated in waves (those newly entered), each wave in parallel; the seed walks'
//! steps and the flood between waves are serial bit arithmetic. The output does not depend on
//! the number of threads.
//!
//! ```
//! use glam::DVec3;
//! use implicitmesh::field::blob::{BlobField, PerPrimitive, Settings as BlobSettings};
//! use implicitmesh::lattice::Lattice;
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
//! let (mesh, triangles, _) =
//!     block_tracking::polygonize_as::<_, u32>(&blobs, &lattice, no_walks, &seed, &settings, &mut ws)
//!         .unwrap();
//! let (both, _) = dense::polygonize(&blobs, &lattice, &Settings::default()).unwrap();
//! let first = both.triangles.iter().filter(|t| both.vertices[t[0] as usize].x < 0.0);
//! assert_eq!(triangles.len(), first.count());
//! assert!(mesh.vertices.iter().all(|v| v.x < 0.0));
//! ```

use super::sparse::{
    block_dims, bounds_error, crossed_layer_cells, evaluate_block, finish_normals, gather_outputs,
    plane_mask, triangulate_blocks, Active, BlockCases, BlockOutput, TriangleIndex, NONE, STEP,
};
use super::tracking::start_walkers;
use super::{check_memory, estimate_triangles, CaseTable, Settings, Stats, BYTES_PER_TRIANGLE};
use crate::error::{Error, Result};
use crate::field::BlockField;
use crate::lattice::Lattice;
use crate::mesh::Mesh;
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

/// Blocks per task of a wave's evaluation.
const BLOCKS_PER_TASK: usize = 4;

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
    /// The part holding its vertices (for `Mixed`).
    part: u32,
    active: Active,
    faces: Faces,
    crossed: [u64; 8],
    /// Cells reached.
    reach: [u64; 8],
    /// Cells entered and not yet flooded from.
    pending: [u64; 8],
}

/// An evaluated block with both signs: its signs and owned vertices, crossed faces and
/// crossed cells.
type Evaluated = (Active, Faces, [u64; 8]);

/// What one task of a wave produces.
#[derive(Default)]
struct Part {
    /// Per block evaluated: its state, and what it holds (None: one sign).
    done: Vec<(u32, Option<Evaluated>)>,
    out: BlockOutput,
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
    /// The evaluated blocks with crossed cells, their reached cells, block index → position.
    active: Vec<Active>,
    reach: Vec<[u64; 8]>,
    amap: Vec<u32>,
}

impl Workspace {
    /// Bytes held (capacities).
    pub fn capacity_bytes(&self) -> usize {
        self.parts
            .iter()
            .map(|p| {
                p.done.capacity() * std::mem::size_of::<(u32, Option<Evaluated>)>()
                    + p.out.capacity_bytes()
            })
            .sum::<usize>()
            + (self.map.capacity()
                + self.index.capacity()
                + self.wave.capacity()
                + self.work.capacity()
                + self.amap.capacity())
                * 4
            + self.states.capacity() * std::mem::size_of::<State>()
            + self.active.capacity() * std::mem::size_of::<Active>()
            + self.reach.capacity() * 64
    }

    /// Evaluates the blocks entered since the last wave, in parallel; those with both signs
    /// and cells entered go on the flood's work list. Returns the points evaluated.
    fn evaluate_wave<F: BlockField + ?Sized>(
        &mut self,
        field: &F,
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
                part.out.clear();
                let mut values = [0.0f64; 512];
                for &s in chunk {
                    let i = index[s as usize];
                    let b = [
                        i % dims[0],
                        (i / dims[0]) % dims[1],
                        i / (dims[0] * dims[1]),
                    ];
                    let out = &mut part.out;
                    let got =
                        evaluate_block(field, blocks, lattice, dims, b, normals, &mut values, out)
                            .map(|a| (a, Faces::new(&a.signs, a.n), crossed_mask(&a.signs, a.n)));
                    part.done.push((s, got));
                }
            });
        self.wave.clear();
        let mut evaluations = 0;
        for p in used..used + tasks {
            let part = &self.parts[p];
            evaluations += part.out.evaluations;
            for &(s, ref got) in &part.done {
                let st = &mut self.states[s as usize];
                match got {
                    None => st.kind = Kind::Empty,
                    Some((active, faces, crossed)) => {
                        st.kind = Kind::Mixed;
                        st.part = p as u32;
                        st.active = *active;
                        st.faces = *faces;
                        st.crossed = *crossed;
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
    fn enter(&mut self, i: u32, cells: &[u64; 8]) -> bool {
        let s = self.map[i as usize];
        if s == NONE {
            self.map[i as usize] = self.states.len() as u32;
            self.wave.push(self.states.len() as u32);
            self.index.push(i);
            self.states.push(State {
                kind: Kind::Queued,
                listed: false,
                part: 0,
                active: EMPTY_ACTIVE,
                faces: Faces::default(),
                crossed: [0; 8],
                reach: [0; 8],
                pending: *cells,
            });
            return true;
        }
        let st = &mut self.states[s as usize];
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
}

const EMPTY_ACTIVE: Active = Active {
    block: [0; 3],
    n: [2; 3],
    last: [false; 3],
    signs: [0; 8],
    edges: [0; 24],
    before: [0; 24],
    base: 0,
    triangles: 0,
};

/// Floods the cells of a block from `reach` ∪ `pending` (crossed cells only) through crossed
/// faces; returns the cells reached.
fn flood(st: &State) -> [u64; 8] {
    let n = st.active.n;
    let cells = plane_mask(n[0] as u32 - 1, n[1] as u32 - 1);
    let nc = n[2] as usize - 1;
    let f = &st.faces;
    let mut r: [u64; 8] = std::array::from_fn(|k| (st.reach[k] | st.pending[k]) & st.crossed[k]);
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
        if r == st.crossed {
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

/// Polygonizes the components of `field`'s surface that hold a seed, block by block: seed
/// cells walked from `starts` as [`super::tracking::Tessellator::walk_seeds`] walks them (at most
/// `max_walk` cells each; here read from the signs of the blocks the walks enter), and
/// `seed_cells` (those outside the lattice and those the surface does not cross are ignored).
/// The mesh (vertices, normals) comes with its triangles as `I` beside it; `ws` keeps the
/// buffers for the next call.
pub fn polygonize_as<F: BlockField + ?Sized, I: TriangleIndex>(
    field: &F,
    lattice: &Lattice,
    (starts, max_walk): (&[DVec3], u32),
    seed_cells: &[[u32; 3]],
    settings: &Settings,
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
    let cells = lattice.cells;
    let locate = |c: [u32; 3]| {
        let b = c.map(|v| v / STEP);
        (
            b[0] + dims[0] * (b[1] + dims[1] * b[2]),
            c.map(|v| v % STEP),
        )
    };
    let normals = settings.normals;
    let eval = |ws: &mut Workspace| ws.evaluate_wave(field, &blocks, lattice, normals);
    let block_index = |b: [u32; 3]| b[0] + dims[0] * (b[1] + dims[1] * b[2]);
    // A seed cell: its bit, entering its block.
    let seed = |ws: &mut Workspace, c: [u32; 3]| {
        if (0..3).all(|a| c[a] < cells[a]) {
            let (i, l) = locate(c);
            let mut bits = [0u64; 8];
            bits[l[2] as usize] = 1 << (l[0] + 8 * l[1]);
            ws.enter(i, &bits);
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
        ws.enter(locate(w.cell).0, &[0; 8]);
    }
    let mut unreached = false;
    loop {
        if !ws.wave.is_empty() {
            stats.evaluations += eval(ws);
        }
        let mut keep = 0;
        for i in 0..walkers.len() {
            let mut w = walkers[i];
            let alive = loop {
                let (b, l) = locate(w.cell);
                let st = match ws.map[b as usize] {
                    NONE => {
                        ws.enter(b, &[0; 8]);
                        break true;
                    }
                    s => &ws.states[s as usize],
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
            let r = flood(st);
            st.reach = r;
            st.pending = [0; 8];
            let (a, f) = (st.active, st.faces);
            let [nx, ny, nz] = a.n.map(|v| v as usize);
            let nc = nz - 1;
            let b = a.block;
            let mut out = [[0u64; 8]; 6];
            for k in 0..nc {
                out[0][k] = (r[k] & f.x[k] & COLUMN_0) << 6;
                out[2][k] = (r[k] & f.y[k] & ROW_0) << 48;
                if !a.last[0] {
                    out[1][k] = (r[k] & (f.x[k] >> 1) & (COLUMN_0 << (nx - 2))) >> 6;
                }
                if !a.last[1] {
                    out[3][k] = (r[k] & (f.y[k] >> 8) & (ROW_0 << (8 * (ny - 2)))) >> 48;
                }
            }
            out[4][6] = r[0] & f.z[0];
            if !a.last[2] {
                out[5][0] = r[nc - 1] & f.z[nz - 1];
            }
            for (side, bits) in out.iter().enumerate() {
                if bits.iter().all(|&w| w == 0) {
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
                if !ws.enter(block_index(nb), bits) {
                    return Err(bounds_error());
                }
            }
        }
        // Walks still going wait for blocks of the next wave.
        if ws.wave.is_empty() {
            break;
        }
    }
    stats.add_time("track", t);

    // Vertex bases (parts in order), the evaluated blocks with their reached cells.
    let t = Instant::now();
    let used_parts = ws.used_parts;
    let mut offsets = Vec::with_capacity(used_parts);
    let mut vertices = 0usize;
    for p in &ws.parts[..used_parts] {
        offsets.push(vertices);
        vertices += p.out.vertices.len();
    }
    u32::try_from(vertices).map_err(|_| Error::invalid("resolution", "more than 2³² vertices"))?;
    ws.active.clear();
    ws.reach.clear();
    ws.amap.clear();
    ws.amap.resize(num_blocks, NONE);
    for (s, st) in ws.states.iter().enumerate() {
        if st.kind != Kind::Mixed {
            continue;
        }
        unreached |= (0..8).any(|k| st.crossed[k] & !st.reach[k] != 0);
        stats.cells_visited += st.reach.iter().map(|w| w.count_ones() as u64).sum::<u64>();
        ws.amap[ws.index[s] as usize] = ws.active.len() as u32;
        ws.active.push(Active {
            base: (offsets[st.part as usize] + st.active.base as usize) as u32,
            ..st.active
        });
        ws.reach.push(st.reach);
    }
    ws.active
        .par_iter_mut()
        .zip(ws.reach.par_iter())
        .with_min_len(16)
        .for_each(|(a, r)| a.triangles = cases.count(a, r));
    let outputs: Vec<&BlockOutput> = ws.parts[..used_parts].iter().map(|p| &p.out).collect();
    let mut mesh = gather_outputs(&outputs, normals);
    let (mut triangles, crossed) =
        triangulate_blocks::<I, true>(cases, &ws.active, Some(&ws.reach), &ws.amap, dims)?;
    stats.cells_crossed = crossed;
    if unreached {
        // Crossed cells in the blocks entered that no seed reaches: their edges' vertices go.
        compact(&mut mesh, &mut triangles);
    }
    stats.add_time("triangulate", t);
    if normals {
        let t = Instant::now();
        finish_normals(&mut mesh, &triangles, &outputs)?;
        stats.normal_evaluations = mesh.vertices.len() as u64;
        stats.add_time("normals", t);
    }
    Ok((mesh, triangles, stats))
}

/// Drops the vertices (and normals) no triangle uses, renumbering the triangles.
fn compact<I: TriangleIndex>(mesh: &mut Mesh, triangles: &mut [[I; 3]]) {
    let mut new = vec![NONE; mesh.vertices.len()];
    for t in triangles.iter() {
        for v in t {
            new[v.to_u32() as usize] = 0;
        }
    }
    let mut kept = 0u32;
    for (i, n) in new.iter_mut().enumerate() {
        if *n == 0 {
            *n = kept;
            mesh.vertices[kept as usize] = mesh.vertices[i];
            if let Some(&g) = mesh.normals.get(i) {
                mesh.normals[kept as usize] = g;
            }
            kept += 1;
        }
    }
    mesh.vertices.truncate(kept as usize);
    if !mesh.normals.is_empty() {
        mesh.normals.truncate(kept as usize);
    }
    for t in triangles.iter_mut() {
        *t = t.map(|v| I::from_u32(new[v.to_u32() as usize]));
    }
}

#[cfg(test)]
mod tests {
    use super::super::{dense, tracking, Ambiguity};
    use super::*;
    use crate::field::testing::random_blobs as blobs;
    use crate::field::testing::{canonical_triangles as canonical, vertex_normal_bits, Lying};
    use glam::DVec3;

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
        let (m, t, bs) = polygonize_as::<_, u32>(field, l, walk, &[], &s, ws).unwrap();
        assert_eq!(
            canonical(&m.vertices, &t),
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
        use crate::field::blob::{BlobField, PerPrimitive, Settings as BlobSettings};
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
                polygonize_as::<_, u32>(&f, &l, walk, &[], &Settings::default(), &mut ws).unwrap();
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
        let e = polygonize_as::<_, u32>(&f, &l, none, &seed, &Settings::default(), &mut ws)
            .unwrap_err();
        assert!(
            matches!(e, Error::InvalidArgument { name: "field", .. }),
            "{e}"
        );
        // The true field from the same seed: the whole sphere.
        let (m, t, _) =
            polygonize_as::<_, u32>(&f.0, &l, none, &seed, &Settings::default(), &mut ws).unwrap();
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
            &mut ws,
        )
        .unwrap();
        assert!(t.is_empty() && m.vertices.is_empty());
        assert_eq!(st.cells_crossed, 0);
    }
}
