//! Surface tracking (Triquet et al. §4.4): starting from seed cells, visit only cells the surface
//! crosses, entering a neighbour only through a face whose corners change sign (known from the
//! case table, §4.6). Each cell is processed once. Corner values, edge vertices and visited marks
//! live in bricks of 8³ lattice points handed out on first touch and tagged with a time stamp
//! (§4.1, [`super::bricks`]): a brick from an earlier call is simply stale, so nothing is
//! cleared between frames, and storage grows with the surface, not with the lattice (§4.7).
//!
//! The walk goes wave by wave: all unknown corners of the current wave of cells are evaluated in
//! one batched field call, so the field may be parallel (or a Python callable called in batches).
//! Because the lattice, the table and the edge arithmetic are those of the dense polygonizer, the
//! mesh equals the dense mesh on every component that holds a seed.
//!
//! A walk reaches only the components that hold a seed ([`Components::Seeded`]): for a field
//! without block bounds (a variational surface, a Python callable), a component no seed walk
//! reaches (e.g. the inner surface of a cavity) is not found. For a [`BlockField`] (a blob
//! field), [`Tessellator::polygonize_all`] finds every component ([`Components::All`]): after
//! the walk, every block of 7³ cells that the field's bounds cannot rule out (the blocks
//! [`super::sparse`] evaluates, which hold every crossed cell) is evaluated at once, and the
//! walk goes on from its crossed cells not yet queued; the mesh is then the dense mesh,
//! triangle for triangle and bit for bit.

use super::block_tracking;
use super::bricks::{Bricks, Slot};
use super::cell::{case_index, edge_origin, emit_triangles};
use super::sparse::{self, BlockSigns, TriangleIndex, ALL_CELLS, STEP};
use super::table::EDGES;
use super::{compute_normals, evaluate, CaseTable, Settings, Stats};
use crate::error::Result;
use crate::field::{BlockField, Field};
use crate::lattice::{edge_crossing, Lattice};
use crate::mesh::Mesh;
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

/// Which components of the surface a walk finds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Components {
    /// Those that hold a seed: the walk from the seeds reaches them.
    Seeded,
    /// Every component: after the walk from the seeds, the blocks that the field's bounds cannot
    /// rule out are searched for crossed cells the walk did not reach, and the walk goes on from
    /// them.
    All,
}

/// Neighbour offsets across the six faces (face f = 2·axis + side).
pub(super) const FACE_STEP: [(usize, i64); 6] = [(0, -1), (0, 1), (1, -1), (1, 1), (2, -1), (2, 1)];

/// The directions a seed walk tries, in order, as faces: +x first (Triquet's Fig. 1), then −x,
/// ±y, ±z.
const WALK_ORDER: [usize; 6] = [1, 0, 3, 2, 5, 4];

/// A seed walk: its current cell, the cell it started from, the index into [`WALK_ORDER`] of
/// its direction and the steps taken in that direction.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(super) struct Walker {
    pub(super) cell: [u32; 3],
    start: [u32; 3],
    direction: u8,
    steps: u32,
}

impl Walker {
    /// Moves to the next cell of the walk (its current cell is not crossed): along its
    /// direction, or, when the walk meets the side of a lattice with `cells` per axis, to the
    /// first cell from the start along the next direction. False when the walk is over: out of
    /// directions, or `max_steps` taken (the surface is farther than the walk may go, deep
    /// inside a cluster, which other walks reach; only a walk cut by the box tries the next
    /// direction).
    pub(super) fn advance(&mut self, cells: [u32; 3], max_steps: u32) -> bool {
        loop {
            let (axis, step) = FACE_STEP[WALK_ORDER[self.direction as usize]];
            let n = self.cell[axis] as i64 + step;
            if self.steps >= max_steps {
                return false;
            }
            if n >= 0 && n < cells[axis] as i64 {
                self.cell[axis] = n as u32;
                self.steps += 1;
                return true;
            }
            if self.direction as usize + 1 == WALK_ORDER.len() {
                return false;
            }
            self.direction += 1;
            self.cell = self.start;
            self.steps = 0;
        }
    }
}

/// The walks from `starts` (finite ones): each from the cell holding it, or the nearest cell
/// for points outside the lattice; sorted, each once.
pub(super) fn start_walkers(starts: &[DVec3], lattice: &Lattice) -> Vec<Walker> {
    let cells = lattice.cells;
    let mut walkers: Vec<Walker> = starts
        .iter()
        .filter(|p| p.is_finite())
        .map(|p| {
            let q = (*p - lattice.origin) / lattice.cell;
            let c = [0, 1, 2].map(|k| q[k].floor().clamp(0.0, (cells[k] - 1) as f64) as u32);
            Walker {
                cell: c,
                start: c,
                direction: 0,
                steps: 0,
            }
        })
        .collect();
    walkers.sort_unstable();
    walkers.dedup();
    walkers
}

/// Caches and buffers kept between calls, for animation: polygonize, move the field, polygonize
/// again — in steady state nothing is reallocated.
#[derive(Default)]
pub struct Tessellator {
    /// Corner values, edge vertices and queued marks, time-stamped.
    cache: Bricks,
    wave: Vec<[u32; 3]>,
    next: Vec<[u32; 3]>,
    points: Vec<DVec3>,
    /// Where the values of `points` go.
    slots: Vec<Slot>,
    vals: Vec<f64>,
    mesh: Mesh,
    /// Buffers of the walk block by block ([`Tessellator::polygonize_blocks`]).
    blocks: block_tracking::Workspace,
    /// The search for components without a seed ([`Tessellator::polygonize_all`]): the blocks
    /// the field's bounds cannot rule out, and per block its sign words and points per axis
    /// (None: one sign) with the points evaluated.
    marks: Vec<bool>,
    candidates: Vec<u32>,
    signs: Vec<(Option<BlockSigns>, u64)>,
}

impl Tessellator {
    pub fn new() -> Self {
        Self::default()
    }

    /// The mesh of the last call.
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// Bytes held by the caches and buffers (capacities), to check that memory stays flat.
    pub fn capacity_bytes(&self) -> usize {
        self.cache.capacity_bytes()
            + (self.wave.capacity() + self.next.capacity()) * 12
            + self.points.capacity() * 24
            + self.slots.capacity() * 4
            + self.vals.capacity() * 8
            + self.mesh.vertices.capacity() * 24
            + self.mesh.normals.capacity() * 24
            + self.mesh.triangles.capacity() * 12
            + self.blocks.capacity_bytes()
            + self.marks.capacity()
            + self.candidates.capacity() * 4
            + self.signs.capacity() * std::mem::size_of::<(Option<BlockSigns>, u64)>()
    }

    fn begin(&mut self, lattice: &Lattice) {
        self.cache.begin(lattice.points_per_axis());
        self.mesh.vertices.clear();
        self.mesh.triangles.clear();
        self.mesh.normals.clear();
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

    fn corners(&mut self, o: [u32; 3]) -> [f64; 8] {
        self.cache.cell_values(o)
    }

    /// Seed cells from points: from the cell holding each point, walk along +x (Triquet's
    /// Fig. 1) to the first cell the surface crosses, at most `max_steps` cells. When the walk
    /// reaches the side of the lattice first (a primitive cut by the box), it starts again from
    /// the same cell along −x, then ±y, ±z. Points outside the lattice start from the nearest
    /// cell. All walkers advance together,
    /// one batch per step.
    pub fn walk_seeds<F: Field + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        starts: &[DVec3],
        max_steps: u32,
        settings: &Settings,
        stats: &mut Stats,
    ) -> Result<Vec<[u32; 3]>> {
        let cells = lattice.cells;
        let mut walkers = start_walkers(starts, lattice);
        let mut seeds = Vec::new();
        while !walkers.is_empty() {
            let cells_now: Vec<[u32; 3]> = walkers.iter().map(|w| w.cell).collect();
            self.evaluate_corners(field, lattice, &cells_now, settings, stats)?;
            let mut keep = 0;
            for i in 0..walkers.len() {
                let mut w = walkers[i];
                let case = case_index(&self.corners(w.cell));
                if case != 0 && case != 255 {
                    seeds.push(w.cell);
                    continue;
                }
                let moved = w.advance(cells, max_steps);
                if !moved {
                    continue;
                }
                walkers[keep] = w;
                keep += 1;
            }
            walkers.truncate(keep);
            walkers.sort_unstable();
            walkers.dedup();
        }
        seeds.sort_unstable();
        seeds.dedup();
        Ok(seeds)
    }

    /// Starts a call: call before [`Tessellator::walk_seeds`] and [`Tessellator::track`].
    pub fn start(&mut self, lattice: &Lattice) {
        self.begin(lattice);
    }

    /// Tracks the surface from `seeds` (cells) and returns the mesh (valid until the next call).
    pub fn track<F: Field + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        seeds: &[[u32; 3]],
        settings: &Settings,
        stats: &mut Stats,
    ) -> Result<&Mesh> {
        self.walk(field, lattice, seeds, settings, stats)?;
        self.finish(field, lattice, settings, stats)?;
        Ok(&self.mesh)
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
        let cells = lattice.cells;
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
        let cells = lattice.cells;
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
                let v = self.corners(o);
                let case = case_index(&v);
                if case == 0 || case == 255 {
                    continue;
                }
                stats.cells_crossed += 1;
                // The vertex of every crossed edge of the cell, looked up (or made) once.
                let mut idx = [0u32; 12];
                for (e, ends) in EDGES.iter().enumerate() {
                    let (fa, fb) = (v[ends[0] as usize], v[ends[1] as usize]);
                    if (fa < 0.0) == (fb < 0.0) {
                        continue;
                    }
                    let (d, axis) = edge_origin(e);
                    let a = [o[0] + d[0], o[1] + d[1], o[2] + d[2]];
                    idx[e] = self.cache.edge(a, axis, || {
                        let mut b = a;
                        b[axis as usize] += 1;
                        vertices.push(edge_crossing(lattice.point(a), lattice.point(b), fa, fb));
                        (vertices.len() - 1) as u32
                    });
                }
                emit_triangles(table, case, |e| idx[e], &mut triangles);
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

    /// Computes the normals of the mesh.
    fn finish<F: Field + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        settings: &Settings,
        stats: &mut Stats,
    ) -> Result<()> {
        let mut mesh = std::mem::take(&mut self.mesh);
        let r = compute_normals(field, lattice, &mut mesh, settings, stats);
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
        self.evaluate_blocks_not_ruled_out(field, lattice, stats);
        let t = Instant::now();
        self.queue_crossed_cells(lattice);
        stats.add_time("track", t);
        self.walk_waves(field, lattice, settings, stats)
    }

    /// Finds the blocks that `field`'s bounds cannot rule out (into `candidates`) and evaluates
    /// them in parallel (their signs into `signs`).
    fn evaluate_blocks_not_ruled_out<F: BlockField + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        stats: &mut Stats,
    ) {
        let t = Instant::now();
        let dims = sparse::block_dims(lattice);
        let blocks = field.blocks(lattice, dims);
        let (marks, candidates) = (&mut self.marks, &mut self.candidates);
        sparse::blocks_not_ruled_out(field, &blocks, lattice, |_| true, marks, candidates);
        stats.add_time("classify", t);

        let t = Instant::now();
        self.candidates
            .par_iter()
            .map_init(
                || [0.0f64; 512],
                |values, &i| {
                    let (b, mut evaluations) = (sparse::block_coords(i, dims), 0);
                    let signs =
                        sparse::block_signs(field, &blocks, lattice, b, values, &mut evaluations);
                    (signs, evaluations)
                },
            )
            .collect_into_vec(&mut self.signs);
        stats.evaluations += self.signs.iter().map(|s| s.1).sum::<u64>();
        stats.add_time("evaluate", t);
    }

    /// Queues the crossed cells of the blocks in `signs` that are not yet queued, as the next
    /// wave.
    fn queue_crossed_cells(&mut self, lattice: &Lattice) {
        let dims = sparse::block_dims(lattice);
        self.wave.clear();
        for (&i, &(signs, _)) in self.candidates.iter().zip(&self.signs) {
            let Some((signs, n)) = signs else { continue };
            let lo = sparse::block_coords(i, dims).map(|v| v * STEP);
            let (cache, wave) = (&mut self.cache, &mut self.wave);
            sparse::crossed_cells(&signs, n, &ALL_CELLS, |cell, _| {
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

    /// One polygonization: seeds walked from `starts` (e.g. blob centres or data points), then
    /// tracking from them and from the extra `seed_cells`. Finds the components that hold a
    /// seed ([`Components::Seeded`]).
    #[allow(clippy::too_many_arguments)]
    pub fn polygonize<F: Field + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        starts: &[DVec3],
        max_walk: u32,
        seed_cells: &[[u32; 3]],
        settings: &Settings,
    ) -> Result<(&Mesh, Stats)> {
        let mut stats = self.walk_from(field, lattice, (starts, max_walk), seed_cells, settings)?;
        self.finish(field, lattice, settings, &mut stats)?;
        Ok((&self.mesh, stats))
    }

    /// [`Tessellator::polygonize`] finding every component ([`Components::All`]) of a field
    /// with block bounds (a blob field): after the walk from the seeds, the blocks of 7³ cells
    /// that the bounds cannot rule out are evaluated (each block at once, as
    /// [`super::sparse`] does), and the walk goes on from their crossed cells it did not reach.
    /// The mesh is the dense mesh, triangle for triangle and bit for bit (up to the order of
    /// vertices and triangles).
    #[allow(clippy::too_many_arguments)]
    pub fn polygonize_all<F: BlockField + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        starts: &[DVec3],
        max_walk: u32,
        seed_cells: &[[u32; 3]],
        settings: &Settings,
    ) -> Result<(&Mesh, Stats)> {
        let mut stats = self.walk_from(field, lattice, (starts, max_walk), seed_cells, settings)?;
        self.walk_the_rest(field, lattice, settings, &mut stats)?;
        self.finish(field, lattice, settings, &mut stats)?;
        Ok((&self.mesh, stats))
    }

    /// Starts a call, walks the seeds from `starts` (at most `max_walk` cells each) and walks
    /// the surface from them and from `seed_cells`; the mesh has no normals yet.
    fn walk_from<F: Field + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        (starts, max_walk): (&[DVec3], u32),
        seed_cells: &[[u32; 3]],
        settings: &Settings,
    ) -> Result<Stats> {
        super::check_memory(
            super::estimate_triangles(lattice) * (super::BYTES_PER_TRIANGLE + 64),
            settings.memory_limit,
        )?;
        let mut stats = Stats {
            lattice_points: lattice.num_points(),
            ..Default::default()
        };
        self.start(lattice);
        let t = Instant::now();
        let mut seeds = self.walk_seeds(field, lattice, starts, max_walk, settings, &mut stats)?;
        seeds.extend_from_slice(seed_cells);
        stats.add_time("seeds", t);
        self.walk(field, lattice, &seeds, settings, &mut stats)?;
        Ok(stats)
    }

    /// [`Tessellator::polygonize`] ([`Components::Seeded`]) or
    /// [`Tessellator::polygonize_all`] ([`Components::All`]) for fields that evaluate whole
    /// blocks of the lattice (blob fields): seeds walked by the same rule, then the walk block
    /// by block ([`super::block_tracking`]). The mesh is the same (up to the order of vertices
    /// and triangles); more points are evaluated (whole blocks of 8³, vectorised), in much less
    /// time. The triangles come beside the mesh, as `I`.
    #[allow(clippy::too_many_arguments)]
    pub fn polygonize_blocks<F: BlockField + ?Sized, I: TriangleIndex>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        starts: &[DVec3],
        max_walk: u32,
        seed_cells: &[[u32; 3]],
        settings: &Settings,
        components: Components,
    ) -> Result<(Mesh, Vec<[I; 3]>, Stats)> {
        block_tracking::polygonize_as(
            field,
            lattice,
            (starts, max_walk),
            seed_cells,
            settings,
            components,
            &mut self.blocks,
        )
    }
}

/// One-shot tracking polygonization (see [`Tessellator::polygonize`]): the components that
/// hold a seed.
pub fn polygonize<F: Field + ?Sized>(
    field: &F,
    lattice: &Lattice,
    starts: &[DVec3],
    max_walk: u32,
    settings: &Settings,
) -> Result<(Mesh, Stats)> {
    let mut t = Tessellator::new();
    let (m, s) = t.polygonize(field, lattice, starts, max_walk, &[], settings)?;
    Ok((m.clone(), s))
}

/// One-shot tracking polygonization of every component of a field with block bounds (see
/// [`Tessellator::polygonize_all`]).
pub fn polygonize_all<F: BlockField + ?Sized>(
    field: &F,
    lattice: &Lattice,
    starts: &[DVec3],
    max_walk: u32,
    settings: &Settings,
) -> Result<(Mesh, Stats)> {
    let mut t = Tessellator::new();
    let (m, s) = t.polygonize_all(field, lattice, starts, max_walk, &[], settings)?;
    Ok((m.clone(), s))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::blob::{BlobField, BlobSettings, PerPrimitive};
    use crate::field::testing::random_blobs as blobs;
    use crate::field::testing::{
        canonical_triangles as canonical, random_points, vertex_normal_bits,
    };
    use crate::field::Counting;
    use crate::polygonize::{dense, sparse, Ambiguity};

    #[test]
    fn tracking_equals_dense_on_blobs() {
        for (n, r, res, seed) in [
            (1, 0.3, 20, 1),
            (30, 0.25, 40, 2),
            (200, 0.12, 64, 3),
            (5, 0.05, 30, 4),
        ] {
            let b = blobs(n, r, seed);
            let l = Lattice::new(DVec3::splat(-1.0), DVec3::splat(1.0), [res; 3]).unwrap();
            for amb in [Ambiguity::Separate, Ambiguity::Join] {
                let s = Settings {
                    ambiguity: amb,
                    ..Default::default()
                };
                let (d, _) = dense::polygonize(&b, &l, &s).unwrap();
                let counting = Counting::new(&b);
                let max_walk = (r / l.cell.x).ceil() as u32 + 2;
                let (t, st) = polygonize(&counting, &l, b.centers(), max_walk, &s).unwrap();
                let c = d.compare(&t);
                assert_eq!(
                    (c.missing, c.extra),
                    (0, 0),
                    "n={n} r={r} res={res} {amb:?}"
                );
                assert_eq!(counting.evaluations(), st.evaluations);
                if !t.triangles.is_empty() {
                    assert!(t.is_closed_oriented());
                }
            }
        }
    }

    /// A hollow shell: 150 blobs of radius 0.25 on a sphere of radius 0.6 (Fibonacci points).
    /// Its inner surface, around a cavity at the centre, is a component of its own.
    fn shell() -> BlobField {
        let centers: Vec<DVec3> = crate::field::testing::fibonacci_sphere(150)
            .into_iter()
            .map(|u| 0.6 * u)
            .collect();
        let one = |v| PerPrimitive::All(v);
        BlobField::new(&centers, one(0.25), one(1.0), 0.5, BlobSettings::default()).unwrap()
    }

    /// Triangles of `m` with a corner inside radius 0.6 (the shell's inner surface).
    fn inner_triangles(m: &Mesh) -> usize {
        let inside = |t: &[u32; 3]| m.vertices[t[0] as usize].length() < 0.6;
        m.triangles.iter().filter(|t| inside(t)).count()
    }

    /// The mesh `m` (triangles `t`) is `d`'s: the same triangles, vertices and normals, bits.
    fn assert_same_mesh(m: &Mesh, t: &[[u32; 3]], d: &Mesh) {
        assert_eq!(
            canonical(&m.vertices, t),
            canonical(&d.vertices, &d.triangles)
        );
        assert_eq!(
            vertex_normal_bits(&m.vertices, &m.normals),
            vertex_normal_bits(&d.vertices, &d.normals)
        );
    }

    #[test]
    fn all_components_include_the_cavity_no_seed_reaches() {
        let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 48).unwrap();
        let s = Settings::default();
        let (d, dense_stats) = dense::polygonize(&shell(), &l, &s).unwrap();
        let (sp, _) = sparse::polygonize(&shell(), &l, &s).unwrap();
        // One start outside the shell: its walk along +x meets the outer surface first.
        let start = [DVec3::new(-0.95, 0.01, 0.02)];
        let mut tess = Tessellator::new();
        let (seeded, _) = tess.polygonize(&shell(), &l, &start, 48, &[], &s).unwrap();
        // The walk alone finds the outer surface whole and nothing of the inner one.
        let inner = inner_triangles(&d);
        assert!(inner > 0);
        assert_eq!(inner_triangles(seeded), 0);
        assert_eq!(seeded.triangles.len() + inner, d.triangles.len());
        // Every component, cell by cell: the dense mesh, every point counted.
        let counting = Counting::new(shell());
        let (all, st) = tess
            .polygonize_all(&counting, &l, &start, 48, &[], &s)
            .unwrap();
        assert_same_mesh(all, &all.triangles, &d);
        assert_eq!(st.evaluations, counting.evaluations());
        assert_eq!(st.cells_crossed, dense_stats.cells_crossed);
        // Block by block: the seeded walk misses the inner surface too; every component is
        // sparse's mesh, array for array.
        let f = Counting::new(shell());
        let walk = (&start[..], 48);
        let mut ws = block_tracking::Workspace::default();
        let seeded = Components::Seeded;
        let (_, t, _) =
            block_tracking::polygonize_as::<_, u32>(&f, &l, walk, &[], &s, seeded, &mut ws)
                .unwrap();
        assert_eq!(t.len() + inner, d.triangles.len());
        let before = f.evaluations();
        let every = Components::All;
        let (m, t, st) =
            block_tracking::polygonize_as::<_, u32>(&f, &l, walk, &[], &s, every, &mut ws).unwrap();
        assert_eq!(
            (t, &m.vertices, &m.normals),
            (sp.triangles.clone(), &sp.vertices, &sp.normals)
        );
        assert_eq!(st.evaluations, f.evaluations() - before);
    }

    /// Clusters of 50 to 400 blobs of radius 0.15 to 0.3 with centres in [-0.7, 0.7]³: the
    /// walks from the centres miss components in some (cavities inside the cluster); every
    /// component, cell by cell and block by block, gives the dense mesh.
    #[test]
    fn every_component_of_random_clusters() {
        let s = Settings::default();
        let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 48).unwrap();
        let (mut tess, mut ws) = (Tessellator::new(), block_tracking::Workspace::default());
        let mut missed = 0;
        // Clusters 10, 16, 18 and 21 have cavities no walk from a centre reaches (at 48³).
        for seed in 10..=21 {
            let n = 50 + (seed as usize * 97) % 351;
            let r = 0.15 + 0.15 * ((seed * 37) % 100) as f64 / 100.0;
            let centers = random_points(n, -0.7, 0.7, seed);
            let one = |v| PerPrimitive::All(v);
            let f = BlobField::new(&centers, one(r), one(1.0), 0.5, BlobSettings::default());
            let f = f.unwrap();
            let (d, _) = dense::polygonize(&f, &l, &s).unwrap();
            let max_walk = (r / l.cell.x).ceil() as u32 + 2;
            let (seeded, _) = tess
                .polygonize(&f, &l, &centers, max_walk, &[], &s)
                .unwrap();
            let c = d.compare(seeded);
            assert_eq!(c.extra, 0);
            missed += (c.missing > 0) as usize;
            let (all, _) = tess
                .polygonize_all(&f, &l, &centers, max_walk, &[], &s)
                .unwrap();
            assert_same_mesh(all, &all.triangles, &d);
            let every = Components::All;
            let (m, t, _) = tess
                .polygonize_blocks::<_, u32>(&f, &l, &centers, max_walk, &[], &s, every)
                .unwrap();
            assert_same_mesh(&m, &t, &d);
            let walk = (&centers[..], max_walk);
            let (m, t, _) =
                block_tracking::polygonize_as::<_, u32>(&f, &l, walk, &[], &s, every, &mut ws)
                    .unwrap();
            assert_same_mesh(&m, &t, &d);
        }
        assert_eq!(missed, 4);
    }

    #[test]
    fn animation_reuses_memory() {
        let mut b = blobs(200, 0.25, 9);
        let l = Lattice::new(DVec3::splat(-1.2), DVec3::splat(1.2), [64; 3]).unwrap();
        let s = Settings::default();
        let mut tess = Tessellator::new();
        let base: Vec<DVec3> = b.centers().to_vec();
        let mut sizes = vec![];
        for frame in 0..60 {
            let t = frame as f64 * 0.05;
            let c: Vec<DVec3> = base
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    *p + DVec3::new((t + i as f64).sin(), (t * 1.3 + i as f64).cos(), 0.0) * 0.05
                })
                .collect();
            b.update(&c, None, None).unwrap();
            let (m, _) = tess.polygonize(&b, &l, b.centers(), 10, &[], &s).unwrap();
            assert!(m.is_closed_oriented());
            sizes.push(tess.capacity_bytes());
        }
        // After warming up, the capacity stays flat.
        assert!(sizes[59] <= sizes[19] * 5 / 4, "{:?}", sizes);
    }
}
