//! The weld's bookkeeping without the tiles' rows: where each tile's vertices and triangles go
//! in the welded mesh, from its vertex and triangle counts and its boundary vertices (their
//! indices, edge keys and positions). [`StreamedWeld`](super::StreamedWeld) writes the rows
//! itself; a tiled run whose workers share the client's memory has each worker write its
//! tile's rows where the plan says ([`super::rows`]).

use super::Id;
use crate::error::{Error, Result};
use crate::lattice::Lattice;
use glam::DVec3;
use std::collections::HashMap;

/// What the plan reads of one tile.
#[derive(Clone, Copy, Debug)]
pub struct Seams<'a> {
    /// The cells `lo ≤ i < hi` (per axis) of the whole lattice the tile covers.
    pub window: [[u32; 3]; 2],
    /// Its number of vertices.
    pub vertices: usize,
    /// Its number of triangles.
    pub faces: usize,
    /// Whether it has normals (one per vertex).
    pub normals: bool,
    /// Indices of its vertices on lattice edges in the window's boundary faces.
    pub boundary: &'a [u32],
    /// The keys of those vertices' edges ([`Lattice::whole_edge_key`]), one per index.
    pub keys: &'a [u64],
    /// The positions of those vertices, one per index.
    pub positions: &'a [DVec3],
}

/// Where one tile's rows go in the welded mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TilePlan {
    /// Its number of vertices.
    pub vertices: usize,
    /// Its number of triangles.
    pub faces: usize,
    /// The welded index of its first kept vertex: the vertices it keeps take the next indices,
    /// in its order.
    pub first_vertex: usize,
    /// The welded row of its first triangle.
    pub first_face: usize,
    /// Its vertices joined to an earlier tile's vertex of their edge: (index in the tile,
    /// welded index), increasing in the first.
    pub joined: Vec<(u32, Id)>,
}

impl TilePlan {
    /// The vertices the weld keeps of the tile.
    pub fn kept(&self) -> usize {
        self.vertices - self.joined.len()
    }
}

/// The weld's bookkeeping for tiles given one at a time, in the order their rows take in the
/// welded mesh (see [`StreamedWeld`](super::StreamedWeld)).
#[derive(Debug, Default)]
pub struct WeldPlan {
    /// The welded vertex of each boundary edge key of the tiles added, and its position.
    ids: HashMap<u64, (Id, DVec3)>,
    /// Welded vertices and triangles so far.
    vertices: usize,
    faces: usize,
    /// Tiles added.
    added: usize,
    /// Whether the tiles carry normals: given, or as the first tile with vertices does.
    normals: Option<bool>,
    /// Bytes the welded mesh may hold (`None`: no limit).
    memory_limit: Option<u64>,
}

impl WeldPlan {
    /// A plan with normals if `normals` says so (`None`: if the first tile with vertices has
    /// them).
    pub fn new(normals: Option<bool>) -> Self {
        WeldPlan {
            normals,
            ..Default::default()
        }
    }

    /// The plan with a limit of `bytes` on the welded mesh's rows (vertices, normals and
    /// `int64` triangles): [`WeldPlan::add`] refuses a tile that would take them over it.
    pub fn with_memory_limit(self, bytes: u64) -> Self {
        WeldPlan {
            memory_limit: Some(bytes),
            ..self
        }
    }

    /// Tiles added so far.
    pub fn added(&self) -> usize {
        self.added
    }

    /// Welded vertices so far.
    pub fn vertices(&self) -> usize {
        self.vertices
    }

    /// Welded triangles so far.
    pub fn faces(&self) -> usize {
        self.faces
    }

    /// Whether the welded mesh has normals (`None` until a tile with vertices says so).
    pub fn normals(&self) -> Option<bool> {
        self.normals
    }

    /// Adds the next tile, a window of `lattice`: where its rows go.
    ///
    /// Errors (naming the argument of `_core.weld_tiles`) for a window outside the lattice,
    /// normals missing where the weld has normals, boundary indices and keys that do not match
    /// (an index outside the tile or twice, a key outside its window or twice, not one key and
    /// one position per index), a vertex at other coordinates than the earlier tile's vertex
    /// of its edge, more than 2³² vertices in all, or a welded mesh over the memory limit
    /// (naming `memory_limit`); the plan is then as it was before the call.
    pub fn add(&mut self, s: &Seams, lattice: &Lattice) -> Result<TilePlan> {
        let t = self.added;
        lattice.window(s.window[0], s.window[1])?;
        check_boundary(t, s)?;
        let normals = match self.normals {
            None if s.vertices > 0 => Some(s.normals),
            n => n,
        };
        if normals == Some(true) && s.vertices > 0 && !s.normals {
            return Err(Error::invalid(
                "normals",
                format!(
                    "tile {t} has no normals for its {} vertices (the tiles before it have normals)",
                    s.vertices
                ),
            ));
        }
        if self.vertices + s.vertices > Id::MAX as usize {
            return Err(Error::invalid(
                "vertices",
                format!(
                    "{} vertices in all, over the weld's limit of 2³²",
                    self.vertices + s.vertices
                ),
            ));
        }
        let joined = self.joined(t, s)?;
        let kept = s.vertices - joined.len();
        self.check_memory(normals, self.vertices + kept, self.faces + s.faces)?;
        let first = self.vertices;
        for ((&k, &i), &p) in s.keys.iter().zip(s.boundary).zip(s.positions) {
            if let std::collections::hash_map::Entry::Vacant(e) = self.ids.entry(k) {
                // The kept vertices before `i` are those not joined.
                let before = joined.partition_point(|&(j, _)| j < i);
                e.insert(((first + i as usize - before) as Id, p));
            }
        }
        let plan = TilePlan {
            vertices: s.vertices,
            faces: s.faces,
            first_vertex: first,
            first_face: self.faces,
            joined,
        };
        self.vertices += kept;
        self.faces += s.faces;
        self.normals = normals;
        self.added += 1;
        Ok(plan)
    }

    /// The tile's boundary vertices whose edge an earlier tile has, with that tile's welded
    /// vertex, increasing in the tile's index; errors for a vertex at other coordinates.
    fn joined(&self, t: usize, s: &Seams) -> Result<Vec<(u32, Id)>> {
        let mut joined = Vec::new();
        for ((&k, &i), &q) in s.keys.iter().zip(s.boundary).zip(s.positions) {
            let Some(&(to, p)) = self.ids.get(&k) else {
                continue;
            };
            if q.to_array().map(f64::to_bits) != p.to_array().map(f64::to_bits) {
                return Err(Error::invalid(
                    "tiles",
                    format!(
                        "the vertex of edge key {k} is at {p} in an earlier tile and at {q} in tile {t} (tiles of different fields or lattices?)"
                    ),
                ));
            }
            joined.push((i, to));
        }
        joined.sort_unstable();
        Ok(joined)
    }

    /// Errors when a welded mesh of `vertices` vertices and `faces` triangles would exceed the
    /// memory limit.
    fn check_memory(&self, normals: Option<bool>, vertices: usize, faces: usize) -> Result<()> {
        let Some(limit) = self.memory_limit else {
            return Ok(());
        };
        let per_vertex = if normals == Some(true) { 48 } else { 24 };
        let bytes = vertices as u64 * per_vertex + faces as u64 * 24;
        if bytes <= limit {
            return Ok(());
        }
        Err(Error::invalid(
            "memory_limit",
            format!(
                "the welded mesh of the first {} tiles needs {} MiB, over the limit of {} MiB; raise memory_limit, or write the tiles to a directory (output=DIR) and weld them where there is room",
                self.added + 1,
                bytes.div_ceil(1 << 20),
                limit >> 20
            ),
        ))
    }
}

/// Checks tile `t`'s boundary: one key and one position per index, indices below its vertex
/// count and each once, keys edges of its window (lower end inside, upper end too) and each
/// once.
fn check_boundary(t: usize, s: &Seams) -> Result<()> {
    if s.boundary.len() != s.keys.len() {
        return Err(Error::invalid(
            "keys",
            format!(
                "tile {t} has {} keys for {} boundary vertices",
                s.keys.len(),
                s.boundary.len()
            ),
        ));
    }
    if s.boundary.len() != s.positions.len() {
        return Err(Error::invalid(
            "positions",
            format!(
                "tile {t} has {} positions for {} boundary vertices",
                s.positions.len(),
                s.boundary.len()
            ),
        ));
    }
    let n = s.vertices;
    if let Some(&bad) = s.boundary.iter().find(|&&i| i as usize >= n) {
        return Err(Error::invalid(
            "boundary",
            format!("tile {t} has vertex index {bad}, outside its {n} vertices"),
        ));
    }
    let [lo, hi] = s.window;
    let outside = |&&k: &&u64| {
        let (p, axis) = Lattice::unkey_whole_edge(k);
        k >> 62 != 0
            || axis > 2
            || (0..3).any(|a| p[a] < lo[a] || p[a] + (a == axis as usize) as u32 > hi[a])
    };
    if let Some(&bad) = s.keys.iter().find(outside) {
        return Err(Error::invalid(
            "keys",
            format!("tile {t} has edge key {bad}, not an edge of its window"),
        ));
    }
    if let Some(k) = twice(s.keys) {
        return Err(Error::invalid(
            "keys",
            format!("tile {t} has edge key {k} for two vertices"),
        ));
    }
    if let Some(i) = twice(s.boundary) {
        return Err(Error::invalid(
            "boundary",
            format!("tile {t} lists vertex {i} twice"),
        ));
    }
    Ok(())
}

/// A value `values` holds twice, if any.
fn twice<T: Ord + Copy>(values: &[T]) -> Option<T> {
    let mut sorted = values.to_vec();
    sorted.sort_unstable();
    sorted.windows(2).find(|w| w[0] == w[1]).map(|w| w[0])
}
