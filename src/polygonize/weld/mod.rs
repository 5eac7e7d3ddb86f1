//! The exact weld of tile meshes into the mesh of the whole lattice.
//!
//! A tile is a [`Lattice::window`]: the vertex of a lattice edge on a face two tiles share is
//! the same number in both. The polygonizers give one vertex per crossed lattice edge, also
//! where several edges give one position (the field is zero at a lattice point, or a crossing
//! rounds onto it), and can report the edge of each vertex in the whole lattice's numbering
//! ([`Lattice::whole_edge_key`]). Each tile hands the weld the keys of its vertices on edges in
//! its boundary faces ([`boundary_edges`]); vertices with one key are one vertex. So the welded
//! mesh is the whole lattice's mesh, vertex for vertex, without tolerance.
//!
//! The welded mesh lists the vertices tile after tile, each tile's in its order; a joined vertex
//! takes the place of its first occurrence. Triangles follow tile after tile, in their order.

pub mod plan;
pub mod rows;

pub use plan::{Seams, TilePlan, WeldPlan};
use rows::Rows;

use crate::cancel;
use crate::error::{Error, Result};
use crate::lattice::Lattice;
use glam::DVec3;

/// Tiles of fewer triangles and vertices than this are welded on the calling thread, without the
/// machinery that lets Ctrl-C stop a long call.
pub const SMALL_TILE: usize = 1 << 16;

/// Tiles of fewer triangles and vertices than this are welded holding the GIL: their weld takes
/// tens of microseconds, while giving the GIL to another thread and taking it back can wait
/// for the interpreter's switch interval (5 ms) whenever another thread runs Python (Dask's
/// event loop, in a tiled run's client).
pub const TINY_TILE: usize = 1 << 12;

/// One tile's mesh, as a polygonizer run on a window of the lattice makes it.
#[derive(Clone, Copy, Debug)]
pub struct Tile<'a> {
    /// The cells `lo ≤ i < hi` (per axis) of the whole lattice the tile covers.
    pub window: [[u32; 3]; 2],
    /// Vertex positions.
    pub vertices: &'a [DVec3],
    /// Triangles, as indices into `vertices` (as the polygonizers make them).
    pub faces: &'a [[u32; 3]],
    /// Unit normals, one per vertex, or none.
    pub normals: &'a [DVec3],
    /// Indices of the vertices on lattice edges in the window's boundary faces.
    pub boundary: &'a [u32],
    /// The keys of those vertices' edges ([`Lattice::whole_edge_key`]), one per index of
    /// `boundary`.
    pub keys: &'a [u64],
}

/// The welded mesh; triangles index `vertices` as int64 (numpy's index type).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Welded {
    /// Vertex positions, tile after tile.
    pub vertices: Vec<DVec3>,
    /// Triangles, tile after tile.
    pub faces: Vec<[i64; 3]>,
    /// Normals of `vertices`; empty unless every tile has them.
    pub normals: Vec<DVec3>,
}

/// Triangles per unit of parallel work.
const CHUNK: usize = 1 << 14;

/// Global vertex numbers (tiles' vertices one after another) as `u32`.
pub type Id = u32;

/// Whether the lattice edge `key` lies in a boundary face of `window` (cells `lo ≤ i < hi`):
/// a coordinate other than its axis's is at `lo` or `hi`.
fn in_boundary(key: u64, window: &[[u32; 3]; 2]) -> bool {
    let (p, axis) = Lattice::unkey_whole_edge(key);
    (0..3).any(|a| a != axis as usize && (p[a] == window[0][a] || p[a] == window[1][a]))
}

/// The vertices, among those whose edge keys are `keys` (one per vertex, as a polygonizer's
/// `_keyed` variant gives them for a window of cells `lo ≤ i < hi`), that lie on lattice edges
/// in the window's boundary faces, which neighbouring windows share: their indices and keys.
pub fn boundary_edges(keys: &[u64], window: [[u32; 3]; 2]) -> (Vec<u32>, Vec<u64>) {
    keys.iter()
        .enumerate()
        .filter(|(_, &k)| in_boundary(k, &window))
        .map(|(i, &k)| (i as u32, k))
        .unzip()
}

/// Joins the tiles of `lattice` (the whole lattice their windows cut) into one mesh: a
/// [`StreamedWeld`] given every tile in turn.
///
/// Errors as [`StreamedWeld::add`].
pub fn weld(tiles: &[Tile], lattice: &Lattice) -> Result<Welded> {
    let mut stream = StreamedWeld::new(tiles.len(), None);
    for tile in tiles {
        stream.add(tile, lattice)?;
    }
    Ok(stream.finish())
}

/// Slack on the estimate of the welded mesh's rows (see [`StreamedWeld`]).
const SLACK: f64 = 1.25;

/// The weld of tiles given one at a time, in the order their vertices and triangles take in
/// the welded mesh (a tiled run gives them in window order): each tile's boundary vertices are
/// looked up among those of the tiles added before it, by edge key; a vertex whose edge an
/// earlier tile has is joined to that tile's vertex, the others are kept, in the tile's order;
/// its triangles follow the earlier tiles', renumbered ([`WeldPlan`] says where, [`rows`]
/// writes them). A tile can be freed once added, so the caller holds the welded mesh and the
/// tiles not yet added.
///
/// The welded rows are written from the front of vectors reserved for an estimate of the
/// whole (the rows so far per tile, times the tiles, plus a quarter) and not touched beyond
/// the rows written (`memory::reserve_huge`); a vector short of room grows to a new
/// estimate. A tile that would make the welded mesh's rows exceed the weld's memory limit
/// ([`StreamedWeld::with_memory_limit`]) is refused before anything is written.
#[derive(Debug, Default)]
pub struct StreamedWeld {
    /// The mesh of the tiles added so far.
    welded: Welded,
    /// Where the tiles' rows go.
    plan: WeldPlan,
    /// Tiles that will be added in all (for the estimate).
    tiles: usize,
}

impl StreamedWeld {
    /// A weld of `tiles` tiles (for the estimate of its rows: more or fewer may be added), with
    /// normals if `normals` says so (`None`: if the first tile with vertices has them).
    pub fn new(tiles: usize, normals: Option<bool>) -> Self {
        StreamedWeld {
            welded: Welded::default(),
            plan: WeldPlan::new(normals),
            tiles,
        }
    }

    /// The weld with a limit of `bytes` on the welded mesh's rows (vertices, normals and
    /// `int64` triangles): [`StreamedWeld::add`] refuses a tile that would take them over it.
    pub fn with_memory_limit(self, bytes: u64) -> Self {
        StreamedWeld {
            plan: self.plan.with_memory_limit(bytes),
            ..self
        }
    }

    /// Tiles added so far.
    pub fn added(&self) -> usize {
        self.plan.added()
    }

    /// Vertices welded so far.
    pub fn vertices(&self) -> usize {
        self.plan.vertices()
    }

    /// Adds the next tile, a window of `lattice`.
    ///
    /// Errors as [`WeldPlan::add`], and for a triangle index outside the tile's vertices or
    /// normals not one per vertex; the weld is then as it was before the call. Checks
    /// [`cancel::check`] before writing and reports the tile's vertices done.
    pub fn add(&mut self, tile: &Tile, lattice: &Lattice) -> Result<()> {
        let t = self.plan.added();
        check(t, tile)?;
        let positions: Vec<DVec3> = tile
            .boundary
            .iter()
            .map(|&i| tile.vertices.get(i as usize).copied().unwrap_or(DVec3::NAN))
            .collect();
        let seams = Seams {
            window: tile.window,
            vertices: tile.vertices.len(),
            faces: tile.faces.len(),
            normals: !tile.normals.is_empty(),
            boundary: tile.boundary,
            keys: tile.keys,
            positions: &positions,
        };
        cancel::check()?;
        let plan = self.plan.add(&seams, lattice)?;
        let (tiles, added) = (self.tiles.max(t + 1) as f64, (t + 1) as f64);
        let estimate = |rows: usize| (rows as f64 / added * tiles * SLACK) as usize;
        let kept = plan.kept();
        let w = &mut self.welded;
        let (nv, nf) = (w.vertices.len(), w.faces.len());
        make_room(&mut w.vertices, kept, estimate(nv + kept));
        make_room(
            &mut w.faces,
            tile.faces.len(),
            estimate(nf + tile.faces.len()),
        );
        let normals = self.plan.normals() == Some(true);
        if normals {
            make_room(&mut w.normals, kept, estimate(nv + kept));
        }
        let out = Rows {
            vertices: &mut w.vertices.spare_capacity_mut()[..kept],
            normals: normals.then(|| &mut w.normals.spare_capacity_mut()[..kept]),
            faces: &mut w.faces.spare_capacity_mut()[..tile.faces.len()],
        };
        // The tile was checked: the rows' writer cannot fail on it.
        rows::write(tile.vertices, tile.normals, tile.faces, &plan, out)?;
        // SAFETY: `rows::write` wrote every row of the room it was given.
        unsafe {
            w.vertices.set_len(nv + kept);
            w.faces.set_len(nf + tile.faces.len());
            if normals {
                w.normals.set_len(nv + kept);
            }
        }
        cancel::advance(tile.vertices.len() as u64)
    }

    /// The welded mesh of the tiles added.
    pub fn finish(self) -> Welded {
        self.welded
    }
}

/// Room for `more` rows after those of `v`, at least `estimate` rows in all when it grows.
fn make_room<T>(v: &mut Vec<T>, more: usize, estimate: usize) {
    let need = v.len() + more;
    if need <= v.capacity() {
        return;
    }
    let size = need.max(estimate);
    if v.is_empty() {
        *v = crate::memory::reserve_huge(size);
    }
    v.reserve_exact(size - v.len());
}

/// Checks tile `t`'s normals (none, or one per vertex) and triangle indices.
fn check(t: usize, tile: &Tile) -> Result<()> {
    if !tile.normals.is_empty() && tile.normals.len() != tile.vertices.len() {
        return Err(Error::invalid(
            "normals",
            format!(
                "tile {t} has {} normals for {} vertices",
                tile.normals.len(),
                tile.vertices.len()
            ),
        ));
    }
    let n = tile.vertices.len();
    if let Some(bad) = rows::index_outside(tile.faces, n) {
        return Err(Error::invalid(
            "faces",
            format!("tile {t} has vertex index {bad}, outside its {n} vertices"),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests;
