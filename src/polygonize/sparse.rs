//! Sparse marching cubes: the lattice is cut into blocks of 7³ cells (8³ points, the faces
//! shared), and a block is skipped when its field proves that all its points have one sign
//! ([`BlockField::block_sign`], which [`BlockField::block_values`] applies first: for a blob
//! field, bounds on each primitive's term over the block's box). Only the blocks the surface
//! may cross are evaluated and triangulated, so the work grows with the surface, not with the
//! lattice, and every component is found (no seeds). Surface tracking uses the same bounds to
//! find the components no seed reaches ([`super::tracking::Components::All`]).
//!
//! The mesh is the dense polygonizer's, triangle for triangle and bit for bit: a crossed edge
//! has ends of both signs, so every block holding it is evaluated, with the same values
//! ([`BlockField`] requires the same bits as [`crate::field::Field::values`]); vertices come from the edge's
//! lower end with [`edge_crossing`] and cells go through the shared case table. Only the order
//! of vertices and triangles differs (block by block instead of layer by layer). Normals are
//! the gradient at the same points with the same terms in the same order, so the same bits;
//! where the gradient vanishes, both fall back to the mean normal of the vertex's triangles,
//! summed in each mesh's own order (equal to rounding).
//!
//! Two parallel passes:
//! 1. a slab of z-layers of blocks at a time (the field's data for those layers only:
//!    [`BlockField::keep_layers`]), per block: values (or a sign), then the signs as eight
//!    64-bit words (one per z-plane, bit `i + 8j`), the crossed edges the block owns as bit
//!    words, and their vertices (and normals, from the field's gradient over the block's own
//!    primitive list), moved into the mesh after the slab. A block owns the edges starting at
//!    its points below its upper faces (at the lattice's upper sides, those on them too), so
//!    every lattice edge has one owner.
//! 2. per evaluated block: its crossed cells, found eight words at a time; a triangle corner on
//!    an edge another block owns looks up that block's rank of the edge (a popcount).
//!
//! The output does not depend on the number of threads.
//!
//! Tracking block by block ([`super::tracking`]) walks the same blocks and makes its mesh the
//! same way, through a small crate-private API: `start_blocks` (memory check, case table, the
//! field's block data), `evaluate_block` (an `Active` block with its vertices in a
//! `BlockOutput`), `Active::restricted` (a block reached in part), `triangulate_blocks` and
//! `finish_normals` (the mesh), `blocks_not_ruled_out` and `block_signs` (the search for
//! components no seed reaches), and `bounds_error`.
//!
//! ```
//! use glam::DVec3;
//! use implicitmesh::field::blob::{BlobField, PerPrimitive, BlobSettings};
//! use implicitmesh::lattice::Lattice;
//! use implicitmesh::polygonize::{polygonize, Method, Settings};
//!
//! let centers = [DVec3::new(-0.2, 0.0, 0.0), DVec3::new(0.25, 0.05, 0.0)];
//! let blobs = BlobField::new(
//!     &centers,
//!     PerPrimitive::All(0.5),
//!     PerPrimitive::All(1.0),
//!     0.5,
//!     BlobSettings::default(),
//! )
//! .unwrap();
//! let lattice = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 48).unwrap();
//! let sparse = polygonize(&blobs, &lattice, &Method::Sparse(Settings::default())).unwrap();
//! let (mesh, stats) = (sparse.mesh, sparse.stats);
//! let reference = polygonize(&blobs, &lattice, &Method::Dense(Settings::default()))
//!     .unwrap()
//!     .mesh;
//! assert_eq!(mesh.triangles.len(), reference.triangles.len());
//! assert!(mesh.is_closed_oriented());
//! assert!(stats.evaluations < stats.lattice_points / 2);
//! ```

use super::bits::{
    crossed_cells, crossed_edges, for_each_set_bit, plane_mask, plane_words, ALL_CELLS, COLUMN_0,
    ROW_0,
};
use super::bricks::Grid;
use super::{
    check_memory, estimate_triangles, fill_vanishing_normals, finish_mesh, normalize, CaseTable,
    Polygonized, Settings, Stats,
};
use crate::error::{Error, Result};
use crate::field::{Block, BlockField, BlockSign, BLOCK_POINTS};
use crate::lattice::{edge_crossing, Lattice};
use crate::mesh::Mesh;
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

/// Cells per block side.
const STEP: u32 = BLOCK_POINTS as u32 - 1;
/// Blocks per task of the first pass (most blocks are skipped after a few bounds).
const BLOCKS_PER_TASK: usize = 64;
/// Evaluated blocks per task of the second pass.
const ACTIVE_PER_TASK: usize = 16;
/// No evaluated block here.
const NONE: u32 = u32::MAX;

/// The blocks of a lattice: 7³ cells each, numbered x fastest.
pub(crate) type BlockGrid = Grid<STEP>;

/// The blocks of `lattice`.
pub(crate) fn block_grid(lattice: &Lattice) -> BlockGrid {
    Grid::new(lattice.cells())
}

/// An evaluated block with points of both signs ([`evaluate_block`]): what triangulating it
/// needs.
#[derive(Clone, Copy)]
pub(crate) struct Active {
    pub(crate) block: [u32; 3],
    /// Points per axis (2..=8).
    pub(crate) n: [u8; 3],
    /// Whether the block is the last along each axis (it then owns its upper faces).
    pub(crate) last: [bool; 3],
    /// Signs per z-plane: bit `i + 8j` of word `k` set when point (i, j, k) is inside.
    pub(crate) signs: [u64; 8],
    /// Crossed edges the block owns, per axis and z-plane of their lower end (word `8a + k`).
    edges: [u64; 24],
    /// Vertices of the block before word `w` of `edges`.
    before: [u16; 24],
    /// Index of the block's first vertex: in its [`BlockOutput`], then in the mesh (set by the
    /// caller, before [`triangulate_blocks`]).
    pub(crate) base: u32,
    /// Triangles of the block's crossed cells.
    triangles: u32,
}

impl Active {
    /// Vertices of the block (on the crossed edges it owns).
    #[inline]
    pub(crate) fn vertices(&self) -> usize {
        self.before[23] as usize + self.edges[23].count_ones() as usize
    }

    /// The block with only its cells in `reach` (bit `i + 8j` of word `k` for cell (i, j, k);
    /// a walk reached them, and no cell outside them): their triangles, and only the crossed
    /// edges they use. Calls `keep(v)`, in order, for each vertex kept (`v` counts the block's
    /// vertices from 0); the result's `base` is to be set by the caller.
    pub(crate) fn restricted(
        &self,
        cases: &BlockCases,
        reach: &[u64; 8],
        mut keep: impl FnMut(usize),
    ) -> Active {
        let used = used_edges(self, reach);
        let mut v = 0;
        for (&e, &u) in self.edges.iter().zip(&used) {
            let mut m = e;
            while m != 0 {
                if u & m & m.wrapping_neg() != 0 {
                    keep(v);
                }
                m &= m - 1;
                v += 1;
            }
        }
        let mut a = Active {
            triangles: cases.count(self, reach),
            edges: used,
            ..*self
        };
        let mut count = 0u16;
        for (b, e) in a.before.iter_mut().zip(&used) {
            *b = count;
            count += e.count_ones() as u16;
        }
        a
    }

    /// Index of the vertex on the owned crossed edge along `axis` from local point `l`.
    #[inline(always)]
    fn vertex(&self, axis: usize, l: [u32; 3]) -> u32 {
        let w = axis * 8 + l[2] as usize;
        let bit = l[0] + 8 * l[1];
        let below = self.edges[w] & ((1u64 << bit) - 1);
        self.base + self.before[w] as u32 + below.count_ones()
    }
}

/// The vertices (and normals) of evaluated blocks, as one task makes them
/// ([`evaluate_block`]), and the points evaluated.
#[derive(Default)]
pub(crate) struct BlockOutput {
    pub(crate) vertices: Vec<DVec3>,
    pub(crate) normals: Vec<DVec3>,
    pub(crate) evaluations: u64,
    /// A normal is zero (the gradient vanishes) or not finite.
    zero_normal: bool,
    bad_normal: bool,
}

impl BlockOutput {
    /// Empties it for the next task (capacities are kept).
    pub(crate) fn clear(&mut self) {
        self.vertices.clear();
        self.normals.clear();
        self.evaluations = 0;
        self.zero_normal = false;
        self.bad_normal = false;
    }

    /// Bytes held (capacities).
    pub(crate) fn capacity_bytes(&self) -> usize {
        (self.vertices.capacity() + self.normals.capacity()) * 24
    }
}

/// Evaluates block `b` of a lattice whose blocks are `grid`. When its points have both signs,
/// appends the vertices of the crossed edges it owns (and their normals) to `out` and returns
/// the block with `base` its first vertex in `out` and the triangles of all its crossed cells
/// (`cases`); otherwise None.
#[allow(clippy::too_many_arguments)]
#[inline]
pub(crate) fn evaluate_block<F: BlockField + ?Sized>(
    (field, blocks): (&F, &F::Blocks),
    lattice: &Lattice,
    grid: &BlockGrid,
    b: [u32; 3],
    (cases, normals): (&BlockCases, bool),
    values: &mut [f64; 512],
    out: &mut BlockOutput,
) -> Option<Active> {
    let block = block_at(lattice, b);
    let Block { lo, n, .. } = block;
    if field.block_values(blocks, lattice, &block, values) != BlockSign::Mixed {
        return None;
    }
    out.evaluations += (n[0] * n[1] * n[2]) as u64;
    let first = out.vertices.len();
    let active = block_vertices(lattice, b, lo, n, grid.dims, values, &mut out.vertices);
    // One sign on every point after all (the bounds were not tight enough): no cell or edge of
    // the block is crossed, and no neighbour needs it.
    if one_sign(&active.signs, n) {
        return None;
    }
    if normals {
        let new = &out.vertices[first..];
        out.normals.resize(out.vertices.len(), DVec3::ZERO);
        let g = &mut out.normals[first..];
        field.block_gradients(blocks, &block, new, g);
        let (zero, bad) = normalize(g);
        out.zero_normal |= zero > 0;
        out.bad_normal |= bad.is_some();
    }
    Some(Active {
        base: first as u32,
        triangles: cases.count(&active, &ALL_CELLS),
        ..active
    })
}

/// Block `b` of `lattice`: its lattice points, 8 per axis (fewer at the lattice's upper sides).
fn block_at(lattice: &Lattice, b: [u32; 3]) -> Block {
    let points = lattice.points_per_axis();
    let lo = b.map(|v| v * STEP);
    let n: [u32; 3] = std::array::from_fn(|a| (points[a] - lo[a]).min(STEP + 1));
    Block { index: b, lo, n }
}

/// Whether a block's sign words (`n` points per axis, bits beyond them clear) have one sign.
fn one_sign(signs: &[u64; 8], n: [u32; 3]) -> bool {
    let all = plane_mask(n[0], n[1]);
    let planes = &signs[..n[2] as usize];
    planes.iter().all(|&w| w == 0) || planes.iter().all(|&w| w == all)
}

/// The blocks of `lattice` that `field`'s bounds cannot rule out ([`BlockField::block_sign`]:
/// the blocks [`polygonize`] evaluates, and every crossed cell lies in one), among those
/// `consider` accepts, as block indices (x fastest) in ascending order into `out`. The blocks
/// are bounded in parallel, [`BOUNDED_PER_BATCH`] between checks for an interrupt; `marks` is
/// scratch.
pub(crate) fn blocks_not_ruled_out<F: BlockField + ?Sized>(
    (field, blocks): (&F, &F::Blocks),
    lattice: &Lattice,
    consider: impl Fn(u32) -> bool + Sync,
    marks: &mut Vec<bool>,
    out: &mut Vec<u32>,
) -> Result<()> {
    let grid = block_grid(lattice);
    let num_blocks = grid.len() as u32;
    marks.clear();
    for first in (0..num_blocks).step_by(BOUNDED_PER_BATCH) {
        crate::cancel::check()?;
        let end = num_blocks.min(first.saturating_add(BOUNDED_PER_BATCH as u32));
        marks.par_extend(
            (first..end)
                .into_par_iter()
                .with_min_len(BLOCKS_PER_TASK)
                .map(|i| {
                    let block = block_at(lattice, grid.position(i));
                    consider(i) && field.block_sign(blocks, lattice, &block) == BlockSign::Mixed
                }),
        );
    }
    out.clear();
    out.extend((0..num_blocks).filter(|&i| marks[i as usize]));
    Ok(())
}

/// Z-layers of blocks whose field data [`polygonize`] holds at once: a few per thread (each
/// layer's lists are made by one thread).
fn layers_per_slab() -> u32 {
    (4 * rayon::current_num_threads() as u32).max(8)
}

/// Blocks bounded in parallel by [`blocks_not_ruled_out`] between checks for an interrupt.
const BOUNDED_PER_BATCH: usize = 1 << 16;

/// A block's sign words ([`Active::signs`]) and its points per axis.
pub(crate) type BlockSigns = ([u64; 8], [u8; 3]);

/// The sign words of block `b` and its points per axis when its values have both signs; None
/// when the field's bounds or its values give one sign. Adds the points evaluated to
/// `evaluations`.
pub(crate) fn block_signs<F: BlockField + ?Sized>(
    (field, blocks): (&F, &F::Blocks),
    lattice: &Lattice,
    b: [u32; 3],
    values: &mut [f64; 512],
    evaluations: &mut u64,
) -> Option<BlockSigns> {
    let block = block_at(lattice, b);
    let n = block.n;
    if field.block_values(blocks, lattice, &block, values) != BlockSign::Mixed {
        return None;
    }
    *evaluations += (n[0] * n[1] * n[2]) as u64;
    let signs = sign_words(values, n);
    (!one_sign(&signs, n)).then_some((signs, n.map(|v| v as u8)))
}

/// The sign words of a block's `values` with `n` points per axis (bit `i + 8j` of word `k` set
/// when point (i, j, k) is inside). Points beyond the lattice hold 0.0 (outside); their bits
/// are masked off.
fn sign_words(values: &[f64; 512], n: [u32; 3]) -> [u64; 8] {
    let mut signs = plane_words(values, n[2] as usize);
    let points = plane_mask(n[0], n[1]);
    for s in signs.iter_mut() {
        *s &= points;
    }
    signs
}

/// What one task of the first pass produces.
#[derive(Default)]
struct Part {
    active: Vec<Active>,
    out: BlockOutput,
}

/// Buffers kept between calls (an animation allocates nothing in steady state).
#[derive(Default)]
struct Workspace {
    parts: Vec<Part>,
    active: Vec<Active>,
    map: Vec<u32>,
}

static WORKSPACES: std::sync::Mutex<Vec<Workspace>> = std::sync::Mutex::new(Vec::new());
/// Workspaces above this are dropped after the call. Below it (256³ lattices of dense blob
/// clusters fit), a repeated call reuses them instead of faulting in fresh pages; at most two
/// are kept.
const KEEP_BYTES: usize = 256 << 20;

impl Workspace {
    fn bytes(&self) -> usize {
        self.parts
            .iter()
            .map(|p| p.active.capacity() * std::mem::size_of::<Active>() + p.out.capacity_bytes())
            .sum::<usize>()
            + self.active.capacity() * std::mem::size_of::<Active>()
            + self.map.capacity() * 4
    }
}

/// Polygonizes `field` over the blocks of `lattice` it cannot rule out; the mesh equals
/// [`super::dense`]'s (up to the order of vertices and triangles). With the vertices' edge keys
/// when [`Settings::keys`] asks for them ([`super::polygonize`] with [`super::Method::Sparse`]).
pub(crate) fn polygonize<F: BlockField + ?Sized>(
    field: &F,
    lattice: &Lattice,
    settings: &Settings,
) -> Result<Polygonized> {
    let (mut mesh, triangles, keys, stats) =
        polygonize_with_keys::<F, u32>(field, lattice, settings, settings.keys)?;
    mesh.triangles = triangles;
    Ok(Polygonized {
        mesh,
        keys: settings.keys.then_some(keys),
        stats,
    })
}

/// The integer type of the vertex indices the sparse polygonizer writes: `u32` (as [`Mesh`] holds
/// them) or `i64` (as numpy and trimesh want faces).
pub trait TriangleIndex: Copy + Send + Sync + 'static {
    /// `v` as this type.
    fn from_u32(v: u32) -> Self;
    /// This index as `u32` (it came from one).
    fn to_u32(self) -> u32;
}

impl TriangleIndex for u32 {
    #[inline(always)]
    fn from_u32(v: u32) -> Self {
        v
    }
    #[inline(always)]
    fn to_u32(self) -> u32 {
        self
    }
}

impl TriangleIndex for i64 {
    #[inline(always)]
    fn from_u32(v: u32) -> Self {
        v as i64
    }
    #[inline(always)]
    fn to_u32(self) -> u32 {
        self as u32
    }
}

/// [`polygonize`] with the triangles' vertex indices as `I`, written straight into their final
/// buffer (each block knows its number of triangles after the first pass), and the vertices'
/// edge keys when `keyed` (else none). The returned mesh has no triangles; they come beside it.
#[allow(clippy::type_complexity)]
fn polygonize_with_keys<F: BlockField + ?Sized, I: TriangleIndex>(
    field: &F,
    lattice: &Lattice,
    settings: &Settings,
    keyed: bool,
) -> Result<(Mesh, Vec<[I; 3]>, Vec<u64>, Stats)> {
    // With projection, the normals are the field's gradients at the moved vertices.
    let inner = Settings {
        normals: settings.normals && !settings.project,
        ..*settings
    };
    let start = start_blocks::<F, I>(field, lattice, &inner, true)?;
    let mut ws = WORKSPACES
        .lock()
        .ok()
        .and_then(|mut w| w.pop())
        .unwrap_or_default();
    let r = run(field, lattice, (&inner, keyed), start, &mut ws);
    if ws.bytes() <= KEEP_BYTES {
        if let Ok(mut pool) = WORKSPACES.lock() {
            if pool.len() < 2 {
                pool.push(ws);
            }
        }
    }
    let (mut mesh, triangles, keys, mut stats) = r?;
    if settings.project {
        finish_mesh(field, &mut mesh, lattice, settings, &mut stats)?;
        // Normals where the gradient vanishes come from the faces, which travel beside the mesh.
        if mesh.normals.contains(&DVec3::ZERO) {
            mesh.triangles = triangles.iter().map(|t| t.map(I::to_u32)).collect();
            fill_vanishing_normals(&mut mesh);
            mesh.triangles = Vec::new();
        }
    }
    Ok((mesh, triangles, keys, stats))
}

/// Bytes per output triangle with indices `I`: its three indices, and half a vertex (a
/// position, and a normal when `normals`), as the caller receives them (`i64` indices for
/// numpy: 48 bytes with normals, 36 without).
pub(crate) fn triangle_bytes<I: TriangleIndex>(normals: bool) -> u64 {
    let vertex = std::mem::size_of::<DVec3>() as u64 * if normals { 2 } else { 1 };
    std::mem::size_of::<[I; 3]>() as u64 + vertex / 2
}

/// What a polygonization over the blocks of a lattice starts from ([`start_blocks`]).
pub(crate) struct BlockStart<B> {
    pub(crate) grid: BlockGrid,
    pub(crate) cases: &'static BlockCases,
    /// The field's data for its blocks ([`BlockField::blocks`]).
    pub(crate) blocks: B,
    /// The lattice's points, and the time making `blocks` took.
    pub(crate) stats: Stats,
}

/// Starts a polygonization of `field` over the blocks of `lattice`: refuses a lattice whose
/// output (triangles of indices `I`) could exceed `settings.memory_limit`, then makes the
/// field's data for its blocks (for all of them, or with `by_layers` to be filled a few
/// z-layers at a time: [`BlockField::blocks_by_layers`]).
pub(crate) fn start_blocks<F: BlockField + ?Sized, I: TriangleIndex>(
    field: &F,
    lattice: &Lattice,
    settings: &Settings,
    by_layers: bool,
) -> Result<BlockStart<F::Blocks>> {
    let grid = block_grid(lattice);
    check_memory(
        grid.len() as u64 * 4 + estimate_triangles(lattice) * triangle_bytes::<I>(settings.normals),
        settings.memory_limit,
    )?;
    let cases = BlockCases::get(CaseTable::get(settings.ambiguity));
    let mut stats = Stats {
        lattice_points: lattice.num_points(),
        ..Default::default()
    };
    crate::cancel::check()?;
    let t = Instant::now();
    let blocks = if by_layers {
        field.blocks_by_layers(lattice, grid.dims)
    } else {
        field.blocks(lattice, grid.dims)
    };
    stats.add_time("blocks", t);
    Ok(BlockStart {
        grid,
        cases,
        blocks,
        stats,
    })
}

#[allow(clippy::type_complexity)]
fn run<F: BlockField + ?Sized, I: TriangleIndex>(
    field: &F,
    lattice: &Lattice,
    (settings, keyed): (&Settings, bool),
    start: BlockStart<F::Blocks>,
    ws: &mut Workspace,
) -> Result<(Mesh, Vec<[I; 3]>, Vec<u64>, Stats)> {
    let BlockStart {
        grid,
        cases,
        mut blocks,
        mut stats,
    } = start;
    let grid = &grid;

    // Pass 1: values, signs, owned vertices (and normals) per block, a slab of z-layers of
    // blocks at a time: the field's data for the slab only, and the slab's vertices moved into
    // the mesh before the next (the tasks' outputs hold one slab).
    let t = Instant::now();
    let num_blocks = grid.len();
    let layer = (grid.dims[0] * grid.dims[1]) as usize;
    // Up to BLOCKS_PER_TASK blocks per task, fewer on small lattices (parallel work there too),
    // each task within one z-layer.
    let per_task = (num_blocks / 64).clamp(1, BLOCKS_PER_TASK).min(layer);
    let tasks_per_layer = layer.div_ceil(per_task);
    let slab = layers_per_slab().min(grid.dims[2]);
    ws.parts
        .resize_with(tasks_per_layer * slab as usize, Part::default);
    ws.active.clear();
    ws.map.clear();
    ws.map.resize(num_blocks, NONE);
    let normals = settings.normals;
    // Room for as many vertices as the estimate of triangles (address space, touched as the
    // slabs fill it), so that growing never copies the vertices.
    let room = (estimate_triangles(lattice) as usize).min(u32::MAX as usize);
    let mut mesh = Mesh {
        vertices: crate::memory::reserve_huge(room),
        normals: if normals {
            crate::memory::reserve_huge(room)
        } else {
            Vec::new()
        },
        ..Default::default()
    };
    // What the outputs found about their normals, for `finish_normals`.
    let mut found = BlockOutput::default();
    let mut listing = 0.0;
    for z0 in (0..grid.dims[2]).step_by(slab as usize) {
        crate::cancel::check()?;
        let z1 = (z0 + slab).min(grid.dims[2]);
        let tb = Instant::now();
        field.keep_layers(&mut blocks, lattice, z0..z1);
        listing += tb.elapsed().as_secs_f64();
        let first_task = z0 as usize * tasks_per_layer;
        let parts = &mut ws.parts[..(z1 - z0) as usize * tasks_per_layer];
        parts.par_iter_mut().enumerate().for_each(|(k, part)| {
            part.active.clear();
            part.out.clear();
            let mut values = [0.0f64; 512];
            let task = first_task + k;
            let (z, nth) = (task / tasks_per_layer, task % tasks_per_layer);
            let begin = z * layer + nth * per_task;
            let end = (begin + per_task).min((z + 1) * layer);
            for index in begin..end {
                let b = grid.position(index as u32);
                let (out, how) = (&mut part.out, (cases, normals));
                let fb = (field, &blocks);
                if let Some(a) = evaluate_block(fb, lattice, grid, b, how, &mut values, out) {
                    part.active.push(a);
                }
            }
        });
        // In task order: global vertex indices, the list of evaluated blocks, the block map.
        for part in parts.iter() {
            let first = mesh.vertices.len();
            for a in &part.active {
                ws.map[grid.index(a.block)] = ws.active.len() as u32;
                let base = u32::try_from(first + a.base as usize)
                    .map_err(|_| Error::invalid("resolution", "more than 2³² vertices"))?;
                ws.active.push(Active { base, ..*a });
            }
            mesh.vertices.extend_from_slice(&part.out.vertices);
            mesh.normals.extend_from_slice(&part.out.normals);
            stats.evaluations += part.out.evaluations;
            found.zero_normal |= part.out.zero_normal;
            found.bad_normal |= part.out.bad_normal;
        }
        // The slab's block lists are made again for the next: the memory they held can go.
        if mesh.vertices.len() * std::mem::size_of::<DVec3>() > KEEP_OUTPUT_BYTES {
            crate::memory::release_free_memory();
        }
    }
    // The field's block data is not needed to triangulate, nor are large outputs; for a large
    // mesh, their pages go back to the system before the triangles are allocated.
    drop(blocks);
    release_large_outputs(&mut ws.parts);
    if mesh.vertices.len() * std::mem::size_of::<DVec3>() > KEEP_OUTPUT_BYTES {
        crate::memory::release_free_memory();
    }
    stats.cells_visited = ws
        .active
        .iter()
        .map(|a| a.n.iter().map(|&v| v as u64 - 1).product::<u64>())
        .sum();
    let keys = if keyed {
        let keys = edge_keys(lattice, &ws.active);
        debug_assert_eq!(keys.len(), mesh.vertices.len());
        keys
    } else {
        Vec::new()
    };
    stats.add_time("evaluate", t);
    // The slabs' block data was made inside the evaluation's time: it counts as "blocks".
    for (phase, s) in stats.seconds.iter_mut() {
        match *phase {
            "blocks" => *s += listing,
            "evaluate" => *s -= listing,
            _ => {}
        }
    }

    // Pass 2: triangles per evaluated block, each task into its own range of the final buffer.
    crate::cancel::check()?;
    let t = Instant::now();
    let (triangles, crossed) =
        triangulate_blocks::<I, false>(cases, &ws.active, None, &ws.map, grid)?;
    stats.cells_crossed = crossed;
    stats.add_time("triangulate", t);
    if normals {
        crate::cancel::check()?;
        let t = Instant::now();
        finish_normals(&mut mesh, &triangles, &[&found])?;
        stats.normal_evaluations = mesh.vertices.len() as u64;
        stats.add_time("normals", t);
    }
    Ok((mesh, triangles, keys, stats))
}

/// The keys of the lattice edges of the vertices of the evaluated blocks `active` (block after
/// block, each in the order [`block_vertices`] made them).
fn edge_keys(lattice: &Lattice, active: &[Active]) -> Vec<u64> {
    let counts: Vec<u32> = active.iter().map(|a| a.vertices() as u32).collect();
    crate::memory::collect_counted(&counts, |b| {
        let a = &active[b];
        let lo = a.block.map(|v| v * STEP);
        let mut keys = Vec::with_capacity(counts[b] as usize);
        for (w, &e) in a.edges.iter().enumerate() {
            let (axis, k) = (w / 8, (w % 8) as u32);
            for_each_set_bit(e, |bit| {
                let p = [lo[0] + (bit & 7), lo[1] + (bit >> 3), lo[2] + k];
                keys.push(lattice.whole_edge_key(p, axis as u8));
            });
        }
        keys
    })
}

/// Releases the tasks' outputs when they hold more than [`KEEP_OUTPUT_BYTES`] in all; smaller
/// ones keep their capacity for the next call.
fn release_large_outputs(parts: &mut [Part]) {
    if parts.iter().map(|p| p.out.capacity_bytes()).sum::<usize>() > KEEP_OUTPUT_BYTES {
        parts
            .iter_mut()
            .for_each(|p| p.out = BlockOutput::default());
    }
}

/// Bytes of the tasks' outputs (vertices and normals) above which [`release_large_outputs`]
/// releases them.
const KEEP_OUTPUT_BYTES: usize = 16 << 20;

/// Triangles of the evaluated blocks `active` (with their cells in `reach`, or all crossed
/// cells), in block order, in parallel, straight into one buffer; and the number of cells.
/// `map` gives each block's position in `active` by its index in `grid` (`u32::MAX`: none; see
/// [`triangulate_block`] for `TRACKED`).
pub(crate) fn triangulate_blocks<I: TriangleIndex, const TRACKED: bool>(
    cases: &BlockCases,
    active: &[Active],
    reach: Option<&[[u64; 8]]>,
    map: &[u32],
    grid: &BlockGrid,
) -> Result<(Vec<[I; 3]>, u64)> {
    let chunks: Vec<(usize, &[Active])> = active
        .chunks(ACTIVE_PER_TASK)
        .enumerate()
        .map(|(c, a)| (c * ACTIVE_PER_TASK, a))
        .collect();
    let total: usize = active.iter().map(|a| a.triangles as usize).sum();
    let mut triangles: Vec<[I; 3]> = crate::memory::with_capacity_huge(total);
    let mut rest = &mut triangles.spare_capacity_mut()[..total];
    let mut outs = Vec::with_capacity(chunks.len());
    for (_, c) in &chunks {
        let (a, b) = rest.split_at_mut(c.iter().map(|a| a.triangles as usize).sum());
        outs.push(a);
        rest = b;
    }
    let crossed = outs
        .into_par_iter()
        .zip(chunks.par_iter())
        .map(|(out, &(first, chunk))| {
            let mut ids = [0u32; IDS];
            let mut at = 0;
            let mut crossed = 0;
            for (k, a) in chunk.iter().enumerate() {
                let end = at + a.triangles as usize;
                let cells = reach.map_or(&ALL_CELLS, |r| &r[first + k]);
                crossed += triangulate_block::<I, TRACKED>(
                    cases,
                    a,
                    cells,
                    active,
                    map,
                    grid,
                    &mut ids,
                    &mut out[at..end],
                )?;
                at = end;
            }
            Some(crossed)
        })
        .sum::<Option<u64>>()
        .ok_or_else(bounds_error)?;
    // SAFETY: the tasks' ranges cover triangles[..total] exactly, and each block wrote all the
    // triangles it counted (`triangulate_block` checks that, and the error above returns early).
    unsafe { triangles.set_len(total) };
    Ok((triangles, crossed))
}

/// The error of a [`BlockField`] whose bounds ruled out a block that the surface crosses.
pub(crate) fn bounds_error() -> Error {
    Error::invalid(
        "field",
        "its block bounds ruled out a block that the surface crosses",
    )
}

/// Checks the normals the blocks made (an error at the first non-finite one) and fills those
/// where the gradient vanished with the mean normal of the vertex's triangles.
pub(crate) fn finish_normals<I: TriangleIndex>(
    mesh: &mut Mesh,
    triangles: &[[I; 3]],
    outputs: &[&BlockOutput],
) -> Result<()> {
    // (Block tracking's outputs may hold vertices the mesh dropped: only the mesh's count.)
    if outputs.iter().any(|p| p.bad_normal) {
        if let Some(i) = mesh.normals.iter().position(|g| !g.is_finite()) {
            let p = mesh.vertices[i];
            return Err(Error::FieldNotFinite {
                x: p.x,
                y: p.y,
                z: p.z,
            });
        }
    }
    if outputs.iter().any(|p| p.zero_normal) {
        // Rare (the gradient vanishes at a vertex): the face normals need the triangles as u32,
        // for this once.
        mesh.triangles = triangles.iter().map(|t| t.map(I::to_u32)).collect();
        fill_vanishing_normals(mesh);
        mesh.triangles = Vec::new();
    }
    Ok(())
}

/// Signs and owned crossed edges of an evaluated block; appends its vertices in rank order.
fn block_vertices(
    lattice: &Lattice,
    b: [u32; 3],
    lo: [u32; 3],
    n: [u32; 3],
    dims: [u32; 3],
    values: &[f64; 512],
    vertices: &mut Vec<DVec3>,
) -> Active {
    let last: [bool; 3] = std::array::from_fn(|a| b[a] + 1 == dims[a]);
    // Owned coordinates per axis: below the upper face, or all at the lattice's upper side.
    let own: [u32; 3] = std::array::from_fn(|a| if last[a] { n[a] } else { STEP });
    let signs = sign_words(values, n);
    let mut edges = [0u64; 24];
    let x_mask = plane_mask(n[0] - 1, own[1]);
    let y_mask = plane_mask(own[0], n[1] - 1);
    let z_mask = plane_mask(own[0], own[1]);
    for k in 0..own[2].min(n[2]) as usize {
        edges[k] = crossed_edges(&signs, k, 0) & x_mask;
        edges[8 + k] = crossed_edges(&signs, k, 1) & y_mask;
        if k + 1 < n[2] as usize {
            edges[16 + k] = crossed_edges(&signs, k, 2) & z_mask;
        }
    }
    let mut before = [0u16; 24];
    let mut count = 0u16;
    for (w, e) in edges.iter().enumerate() {
        before[w] = count;
        count += e.count_ones() as u16;
    }
    // Coordinates of the block's points (and one beyond) per axis, as Lattice::point makes them.
    let coords: [[f64; 9]; 3] = std::array::from_fn(|a| {
        std::array::from_fn(|i| {
            let mut g = [0; 3];
            g[a] = lo[a] + i as u32;
            lattice.point(g)[a]
        })
    });
    const STRIDE: [usize; 3] = [1, 8, 64];
    for (w, &e) in edges.iter().enumerate() {
        let (axis, k) = (w / 8, w % 8);
        for_each_set_bit(e, |bit| {
            let bit = bit as usize;
            let (i, j) = (bit & 7, bit >> 3);
            let idx = bit + 64 * k;
            let pa = DVec3::new(coords[0][i], coords[1][j], coords[2][k]);
            let pb = match axis {
                0 => DVec3::new(coords[0][i + 1], pa.y, pa.z),
                1 => DVec3::new(pa.x, coords[1][j + 1], pa.z),
                _ => DVec3::new(pa.x, pa.y, coords[2][k + 1]),
            };
            vertices.push(edge_crossing(
                pa,
                pb,
                values[idx],
                values[idx + STRIDE[axis]],
            ));
        });
    }
    Active {
        block: b,
        n: n.map(|v| v as u8),
        last,
        signs,
        edges,
        before,
        base: 0,
        triangles: 0,
    }
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

/// Offset of each cell edge's entry in a block's vertex table (`axis · 512 + x + 8y + 64z` of
/// its lower end, relative to the cell's lower corner).
const EDGE_ENTRY: [usize; 12] = {
    let mut t = [0usize; 12];
    let mut e = 0;
    while e < 12 {
        let c = super::table::CORNERS[super::table::EDGES[e][0] as usize];
        t[e] = super::table::EDGE_AXIS[e] as usize * 512
            + c[0] as usize
            + 8 * c[1] as usize
            + 64 * c[2] as usize;
        e += 1;
    }
    t
};

/// Entries of a block's vertex table: 3 axes × 512 (a power of two, so that indices masked
/// with `IDS - 1` need no bounds check; the largest index used is 1535).
const IDS: usize = 2048;

/// A case table with each triangle corner's edge replaced by its [`EDGE_ENTRY`] offset: the
/// triangles of a cell are read straight from the block's vertex table.
pub(crate) struct BlockCases {
    /// Triangles of case c are `entries[offsets[c]..offsets[c + 1]]`.
    offsets: [u16; 257],
    entries: Vec<[u16; 3]>,
}

impl BlockCases {
    /// Triangles of a block's crossed cells in `reach` (bit `i + 8j` of word `k` for cell
    /// (i, j, k); [`ALL_CELLS`] for all).
    pub(crate) fn count(&self, a: &Active, reach: &[u64; 8]) -> u32 {
        let mut n = 0;
        crossed_cells(&a.signs, a.n, reach, |_, case| {
            n += (self.offsets[case + 1] - self.offsets[case]) as u32
        });
        n
    }

    /// The block case table of `table`.
    pub(crate) fn get(table: &CaseTable) -> &'static BlockCases {
        static SEPARATE: std::sync::OnceLock<BlockCases> = std::sync::OnceLock::new();
        static JOIN: std::sync::OnceLock<BlockCases> = std::sync::OnceLock::new();
        let cell = match table.ambiguity() {
            super::Ambiguity::Separate => &SEPARATE,
            super::Ambiguity::Join => &JOIN,
        };
        cell.get_or_init(|| {
            let mut offsets = [0u16; 257];
            let mut entries = Vec::new();
            for case in 0..256 {
                entries.extend(
                    table
                        .triangles(case as u8)
                        .iter()
                        .map(|t| t.map(|e| EDGE_ENTRY[e as usize] as u16)),
                );
                offsets[case + 1] = entries.len() as u16;
            }
            BlockCases { offsets, entries }
        })
    }
}

/// Triangulates the crossed cells of block `a` in `reach` (see [`crossed_cells`]) into `out`
/// (room for exactly their triangles); returns the number of cells. None when a crossed edge
/// lies in a block the field ruled out, which a correct [`BlockField`] never does; with
/// `TRACKED`, blocks not in `active` are those the tracking did not reach, which only cells
/// outside `reach` may touch (None when a cell in `reach` does). First fills a table of the vertex index of every crossed edge its cells use (its own, then those on its upper faces
/// that neighbours own), then reads the triangles' corners from it. Entries of `ids` are read
/// only for crossed edges, which are written first, so the table is never cleared.
#[allow(clippy::too_many_arguments)]
pub(super) fn triangulate_block<I: TriangleIndex, const TRACKED: bool>(
    cases: &BlockCases,
    a: &Active,
    reach: &[u64; 8],
    active: &[Active],
    map: &[u32],
    grid: &BlockGrid,
    ids: &mut [u32; IDS],
    out: &mut [std::mem::MaybeUninit<[I; 3]>],
) -> Option<u64> {
    let [nx, ny, nz] = a.n.map(|v| v as u32);
    let mut next = a.base;
    for (w, &e) in a.edges.iter().enumerate() {
        for_each_set_bit(e, |bit| {
            ids[((w / 8) * 512 + (w % 8) * 64 + bit as usize) & (IDS - 1)] = next;
            next += 1;
        });
    }
    // Crossed edges of the block that a neighbour owns (lower end on an upper face). (A block
    // that tracking reached in part owns only the edges of its reached cells: its other crossed
    // edges, looked up here too, get ids that no reached cell uses.)
    let masks = [
        plane_mask(nx - 1, ny),
        plane_mask(nx, ny - 1),
        plane_mask(nx, ny),
    ];
    for axis in 0..3 {
        for k in 0..nz as usize {
            let crossed = match axis {
                2 if k + 1 == nz as usize => 0,
                _ => crossed_edges(&a.signs, k, axis),
            } & masks[axis];
            let mut m = crossed & !a.edges[axis * 8 + k];
            while m != 0 {
                let bit = m.trailing_zeros();
                m &= m - 1;
                let mut l = [bit & 7, bit >> 3, k as u32];
                let mut b = a.block;
                for d in 0..3 {
                    if l[d] == STEP && !a.last[d] {
                        b[d] += 1;
                        l[d] = 0;
                    }
                }
                let i = map[grid.index(b)];
                let id = &mut ids[(axis * 512 + k * 64 + bit as usize) & (IDS - 1)];
                match active.get(i as usize) {
                    Some(owner) => *id = owner.vertex(axis, l),
                    // Checked below, should a cell in `reach` use it.
                    None if TRACKED => *id = NONE,
                    // A crossed edge in a skipped block: the field's bounds were wrong.
                    None => return None,
                }
            }
        }
    }
    let (mut crossed, mut w) = (0, 0);
    let mut unreached = false;
    crossed_cells(&a.signs, a.n, reach, |cell, case| {
        crossed += 1;
        let range = cases.offsets[case] as usize..cases.offsets[case + 1] as usize;
        for t in &cases.entries[range] {
            let v = t.map(|o| ids[(cell + o as usize) & (IDS - 1)]);
            if TRACKED {
                unreached |= v.contains(&NONE);
            }
            if let Some(slot) = out.get_mut(w) {
                slot.write(v.map(I::from_u32));
            }
            w += 1;
        }
    });
    if unreached {
        return None;
    }
    // The block's count came from the same cells and table, so every slot is written exactly;
    // were it otherwise, this is an error, not a panic nor uninitialised output.
    (w == out.len()).then_some(())?;
    Some(crossed)
}

#[cfg(test)]
mod tests {
    use super::super::dense;
    use super::*;
    use crate::field::blob::BlobField;
    use crate::polygonize::Ambiguity;
    use crate::testing::random_blobs as blobs;
    use crate::testing::{canonical_triangles, vertex_normal_bits, Lying};
    use crate::testing::{for_each_blob_case, BLOB_CASES};

    /// Triangles, order-free and bit-exact.
    fn canonical(m: &Mesh) -> Vec<[[u64; 3]; 3]> {
        canonical_triangles(&m.vertices, &m.triangles)
    }

    fn check_equal(field: &BlobField, lattice: &Lattice, ambiguity: Ambiguity) -> Stats {
        let s = Settings {
            ambiguity,
            ..Default::default()
        };
        let crate::polygonize::Polygonized {
            mesh: a, stats: st, ..
        } = polygonize(field, lattice, &s).unwrap();
        let crate::polygonize::Polygonized {
            mesh: b, stats: _, ..
        } = dense::polygonize(field, lattice, &s).unwrap();
        assert_eq!(a.vertices.len(), b.vertices.len());
        assert_eq!(canonical(&a), canonical(&b));
        // Normals are the field's gradient at the same vertex: the same bits.
        let pairs = |m: &Mesh| vertex_normal_bits(&m.vertices, &m.normals);
        let (na, nb) = (pairs(&a), pairs(&b));
        assert_eq!(na, nb);
        st
    }

    #[test]
    fn equals_dense_on_random_blobs() {
        for_each_blob_case(&BLOB_CASES, |f, l| {
            for amb in [Ambiguity::Separate, Ambiguity::Join] {
                let st = check_equal(&f, l, amb);
                assert!(st.evaluations <= st.lattice_points * 2);
            }
        });
    }

    #[test]
    fn equals_dense_with_sph_kernels() {
        use crate::field::blob::kernel::BlobKernel;
        use crate::field::blob::{BlobSettings, PerPrimitive};
        for kernel in [BlobKernel::CubicSpline, BlobKernel::Wendland] {
            for_each_blob_case(&BLOB_CASES[..4], |f, l| {
                let settings = BlobSettings {
                    kernel,
                    ..Default::default()
                };
                let g = BlobField::new(
                    f.centers(),
                    PerPrimitive::Each(f.radii()),
                    PerPrimitive::All(1.0),
                    0.3,
                    settings,
                )
                .unwrap();
                let st = check_equal(&g, l, Ambiguity::Separate);
                assert!(st.cells_crossed > 0);
            });
        }
    }

    /// A jittered cube of particles with each kernel and as a colour field: the blocks deep in
    /// it are ruled out, and the mesh is still the dense one, bit for bit.
    #[test]
    fn equals_dense_on_particles_with_inside_blocks() {
        use crate::field::blob::kernel::BlobKernel;
        use crate::field::blob::particles::{colour_field, ParticleSettings};
        use crate::field::blob::{BlobSettings, PerPrimitive};
        let p = crate::testing::jittered_cube(14, 7);
        // Cells of 1/4 over the particles and their support (2) on every side, partial blocks.
        let l = Lattice::new(DVec3::splat(-2.3), DVec3::splat(15.2), [70, 69, 71]).unwrap();
        let mut fields = vec![colour_field(&p, 0.5, &ParticleSettings::default()).unwrap()];
        for (kernel, threshold) in [
            (BlobKernel::Triquet, 3.9),
            (BlobKernel::CubicSpline, 1.4),
            (BlobKernel::Wendland, 1.0),
        ] {
            let settings = BlobSettings {
                kernel,
                ..Default::default()
            };
            let one = PerPrimitive::All(1.0);
            let f = BlobField::new(&p, PerPrimitive::All(2.0), one, threshold, settings);
            fields.push(f.unwrap());
        }
        let grid = block_grid(&l);
        for f in &fields {
            let st = check_equal(f, &l, Ambiguity::Separate);
            assert!(st.cells_crossed > 0);
            // The blocks 3..=6 per axis lie in [2.95, 9.95]³, 2.95 or more into the particles.
            let blocks = f.blocks(&l, grid.dims);
            for b in (0..64).map(|i| [3 + i % 4, 3 + i / 4 % 4, 3 + i / 16]) {
                let sign = f.block_sign(&blocks, &l, &block_at(&l, b));
                assert_eq!(sign, BlockSign::Inside, "{:?} {b:?}", f.settings().kernel);
            }
        }
    }

    #[test]
    fn anisotropic_and_cut_lattices() {
        let f = blobs(40, 0.3, 9);
        // Odd cell counts (partial blocks on every axis) and a box that cuts the surface.
        let l = Lattice::new(
            DVec3::new(-1.0, -0.7, -0.3),
            DVec3::new(0.9, 1.0, 0.4),
            [29, 15, 10],
        )
        .unwrap();
        check_equal(&f, &l, Ambiguity::Separate);
    }

    #[test]
    fn int64_triangles_are_the_u32_triangles() {
        // Many blocks and tasks, the lattice's upper sides cut through blocks.
        let f = blobs(60, 0.2, 12);
        let l = Lattice::new(DVec3::splat(-1.0), DVec3::splat(1.0), [61, 47, 90]).unwrap();
        let s = Settings::default();
        let crate::polygonize::Polygonized {
            mesh: m, stats: st, ..
        } = polygonize(&f, &l, &s).unwrap();
        let (m64, t64, st64) = polygonize_with_keys::<_, i64>(&f, &l, &s, false)
            .map(|(m, t, _, st)| (m, t, st))
            .unwrap();
        assert!(m64.triangles.is_empty() && !m.triangles.is_empty());
        let t: Vec<[u32; 3]> = t64
            .iter()
            .map(|t| t.map(|v| u32::try_from(v).unwrap()))
            .collect();
        assert_eq!(t, m.triangles);
        assert_eq!(
            (m64.vertices, st64.cells_crossed),
            (m.vertices, st.cells_crossed)
        );
    }

    #[test]
    fn skips_most_blocks_and_is_closed() {
        let f = blobs(20, 0.3, 11);
        let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 96).unwrap();
        let crate::polygonize::Polygonized {
            mesh: m, stats: st, ..
        } = polygonize(&f, &l, &Settings::default()).unwrap();
        assert!(m.is_closed_oriented());
        assert!(
            st.evaluations * 3 < st.lattice_points,
            "{} of {}",
            st.evaluations,
            st.lattice_points
        );
    }

    #[test]
    fn wrong_bounds_give_an_error_not_a_panic() {
        let f = Lying::sphere();
        let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 32).unwrap();
        let r = polygonize(&f, &l, &Settings::default());
        let e = r.unwrap_err();
        assert!(
            matches!(e, Error::InvalidArgument { name: "field", .. }),
            "{e}"
        );
    }

    #[test]
    fn the_memory_estimate_counts_the_indices_and_normals_returned() {
        assert_eq!(triangle_bytes::<u32>(true), 12 + 24);
        assert_eq!(triangle_bytes::<i64>(true), 24 + 24);
        assert_eq!(triangle_bytes::<i64>(false), 24 + 12);
        // A limit between the two estimates refuses the int64 triangles with normals only.
        let field = BlobField::new(
            &[DVec3::ZERO],
            crate::field::blob::PerPrimitive::All(0.5),
            crate::field::blob::PerPrimitive::All(1.0),
            0.5,
            crate::field::blob::BlobSettings::default(),
        )
        .unwrap();
        let lattice = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 64).unwrap();
        let grid = block_grid(&lattice).len() as u64 * 4;
        let limit = grid + estimate_triangles(&lattice) * 42;
        let settings = Settings {
            memory_limit: limit,
            ..Default::default()
        };
        assert!(polygonize_with_keys::<_, u32>(&field, &lattice, &settings, false).is_ok());
        assert!(polygonize_with_keys::<_, i64>(&field, &lattice, &settings, false).is_err());
        let no_normals = Settings {
            normals: false,
            ..settings
        };
        assert!(polygonize_with_keys::<_, i64>(&field, &lattice, &no_normals, false).is_ok());
    }

    #[test]
    fn empty_field_gives_empty_mesh() {
        let f = blobs(3, 0.2, 12);
        // A box far from every blob.
        let l = Lattice::cubic(DVec3::splat(5.0), DVec3::splat(6.0), 16).unwrap();
        let crate::polygonize::Polygonized {
            mesh: m, stats: st, ..
        } = polygonize(&f, &l, &Settings::default()).unwrap();
        assert!(m.triangles.is_empty() && m.vertices.is_empty());
        assert_eq!(st.evaluations, 0);
    }
}
