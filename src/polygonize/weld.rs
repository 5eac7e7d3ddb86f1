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

use crate::cancel;
use crate::error::{Error, Result};
use crate::lattice::Lattice;
use glam::DVec3;
use rayon::prelude::*;

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
type Id = u32;

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

/// A tile's vertices' welded indices and its boundary keys new to the weld with theirs (see
/// [`StreamedWeld::renumbered`]).
type Renumbered = (Vec<Id>, Vec<(u64, Id)>);

/// Marker of a joined vertex in [`StreamedWeld::renumbered`]'s first pass.
const JOINED: Id = Id::MAX;

/// The weld of tiles given one at a time, in the order their vertices and triangles take in
/// the welded mesh (a tiled run gives them in window order): each tile's boundary vertices are
/// looked up among those of the tiles added before it, by edge key; a vertex whose edge an
/// earlier tile has is joined to that tile's vertex, the others are kept, in the tile's order;
/// its triangles follow the earlier tiles', renumbered. A tile can be freed once added, so the
/// caller holds the welded mesh and the tiles not yet added.
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
    /// The welded vertex of each boundary edge key of the tiles added.
    ids: std::collections::HashMap<u64, Id>,
    /// Tiles that will be added in all (for the estimate).
    tiles: usize,
    /// Tiles added.
    added: usize,
    /// Whether the tiles carry normals: given, or as the first tile with vertices does.
    normals: Option<bool>,
    /// Bytes the welded mesh may hold (`None`: no limit).
    memory_limit: Option<u64>,
}

impl StreamedWeld {
    /// A weld of `tiles` tiles (for the estimate of its rows: more or fewer may be added), with
    /// normals if `normals` says so (`None`: if the first tile with vertices has them).
    pub fn new(tiles: usize, normals: Option<bool>) -> Self {
        StreamedWeld {
            tiles,
            normals,
            ..Default::default()
        }
    }

    /// The weld with a limit of `bytes` on the welded mesh's rows (vertices, normals and
    /// `int64` triangles): [`StreamedWeld::add`] refuses a tile that would take them over it.
    pub fn with_memory_limit(self, bytes: u64) -> Self {
        StreamedWeld {
            memory_limit: Some(bytes),
            ..self
        }
    }

    /// Tiles added so far.
    pub fn added(&self) -> usize {
        self.added
    }

    /// Vertices welded so far.
    pub fn vertices(&self) -> usize {
        self.welded.vertices.len()
    }

    /// Adds the next tile, a window of `lattice`.
    ///
    /// Errors (naming the argument of `_core.weld_tiles`) for a window outside the lattice, a
    /// triangle index outside the tile's vertices, normals not one per vertex (also none where
    /// the weld has normals), boundary indices and keys that do not match (an index outside
    /// the tile, a key outside its window, a key twice in the tile), a vertex at other
    /// coordinates than the earlier tile's vertex of its edge, more than 2³² vertices in all,
    /// or a welded mesh over the memory limit (naming `memory_limit`); the weld is then as it
    /// was before the call. Checks [`cancel::check`] between steps and reports the tile's
    /// vertices done.
    pub fn add(&mut self, tile: &Tile, lattice: &Lattice) -> Result<()> {
        let t = self.added;
        check(t, tile, lattice)?;
        let nv = tile.vertices.len();
        if self.normals.is_none() && nv > 0 {
            self.normals = Some(!tile.normals.is_empty());
        }
        let normals = self.normals == Some(true);
        if normals && tile.normals.len() != nv {
            return Err(Error::invalid(
                "normals",
                format!(
                    "tile {t} has {} normals for {nv} vertices (the tiles before it have normals)",
                    tile.normals.len()
                ),
            ));
        }
        let first = self.welded.vertices.len();
        if first + nv > Id::MAX as usize {
            return Err(Error::invalid(
                "vertices",
                format!(
                    "{} vertices in all, over the weld's limit of 2³²",
                    first + nv
                ),
            ));
        }
        let (index, new) = self.renumbered(t, tile)?;
        cancel::check()?;
        let kept = kept_per_chunk(&index, first);
        self.check_memory(
            first + kept.iter().sum::<usize>(),
            self.welded.faces.len() + tile.faces.len(),
        )?;
        let (tiles, added) = (self.tiles.max(t + 1) as f64, (t + 1) as f64);
        let estimate =
            |now: usize, more: usize| ((now + more) as f64 / added * tiles * SLACK) as usize;
        let rows = estimate(first, kept.iter().sum());
        append_kept(
            &mut self.welded.vertices,
            tile.vertices,
            &index,
            &kept,
            rows,
        );
        if normals {
            append_kept(&mut self.welded.normals, tile.normals, &index, &kept, rows);
        }
        let faces = estimate(self.welded.faces.len(), tile.faces.len());
        append_faces(&mut self.welded.faces, tile.faces, &index, faces);
        self.ids.extend(new);
        self.added += 1;
        cancel::advance(nv as u64)
    }

    /// Errors when a welded mesh of `vertices` vertices and `faces` triangles would exceed the
    /// memory limit.
    fn check_memory(&self, vertices: usize, faces: usize) -> Result<()> {
        let Some(limit) = self.memory_limit else {
            return Ok(());
        };
        let per_vertex = if self.normals == Some(true) { 48 } else { 24 };
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

    /// The welded mesh of the tiles added.
    pub fn finish(self) -> Welded {
        self.welded
    }

    /// Every vertex of tile `t`'s welded index (the vertices the weld keeps take the next
    /// indices, in order; a joined vertex the index of the earlier tile's vertex of its edge),
    /// and the tile's boundary keys no earlier tile has, with their welded indices. Errors for
    /// a key twice in the tile or a joined vertex at other coordinates.
    fn renumbered(&self, t: usize, tile: &Tile) -> Result<Renumbered> {
        let mut keys = tile.keys.to_vec();
        keys.sort_unstable();
        if let Some(k) = keys.windows(2).find(|w| w[0] == w[1]) {
            return Err(Error::invalid(
                "keys",
                format!("tile {t} has edge key {} for two vertices", k[0]),
            ));
        }
        let mut index = vec![0 as Id; tile.vertices.len()];
        let mut joined = Vec::new();
        for (&k, &i) in tile.keys.iter().zip(tile.boundary) {
            let Some(&to) = self.ids.get(&k) else {
                continue;
            };
            let (p, q) = (self.welded.vertices[to as usize], tile.vertices[i as usize]);
            if q.to_array().map(f64::to_bits) != p.to_array().map(f64::to_bits) {
                return Err(Error::invalid(
                    "tiles",
                    format!(
                        "the vertex of edge key {k} is at {p} in an earlier tile and at {q} in tile {t} (tiles of different fields or lattices?)"
                    ),
                ));
            }
            index[i as usize] = JOINED;
            joined.push((i, to));
        }
        let kept = index.iter_mut().filter(|i| **i != JOINED);
        for (next, i) in (self.welded.vertices.len() as Id..).zip(kept) {
            *i = next;
        }
        for &(i, to) in &joined {
            index[i as usize] = to;
        }
        let first = self.welded.vertices.len() as Id;
        let new = tile
            .keys
            .iter()
            .zip(tile.boundary)
            .map(|(&k, &i)| (k, index[i as usize]))
            .filter(|&(_, w)| w >= first)
            .collect();
        Ok((index, new))
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

/// How many vertices of each chunk of [`CHUNK`] vertices of a tile the weld keeps: those whose
/// welded `index` is `first` (the tile's first welded vertex) or after.
fn kept_per_chunk(index: &[Id], first: usize) -> Vec<usize> {
    index
        .par_chunks(CHUNK)
        .map(|c| c.iter().filter(|&&i| i as usize >= first).count())
        .collect()
}

/// Appends the `rows` (vertices or normals) of a tile's vertices the weld keeps (`kept` per
/// chunk, as [`kept_per_chunk`] counts them), in order; chunks written in parallel.
fn append_kept(
    out: &mut Vec<DVec3>,
    rows: &[DVec3],
    index: &[Id],
    kept: &[usize],
    estimate: usize,
) {
    let (len, total) = (out.len(), kept.iter().sum::<usize>());
    let first = len as Id;
    make_room(out, total, estimate);
    let slices = split_by(&mut out.spare_capacity_mut()[..total], kept.iter().copied());
    slices
        .into_par_iter()
        .zip(rows.par_chunks(CHUNK).zip(index.par_chunks(CHUNK)))
        .for_each(|(o, (rows, index))| {
            let mut at = 0;
            for (&p, &i) in rows.iter().zip(index) {
                if i >= first {
                    o[at].write(p);
                    at += 1;
                }
            }
        });
    // SAFETY: each chunk writes exactly its count of kept rows (those with an index at or
    // after `first`, as `kept_per_chunk` counted them) into its slice, and the slices cover
    // the `total` rows after `len`.
    unsafe { out.set_len(len + total) };
}

/// Appends a tile's triangles with every index mapped through `index`, chunks in parallel.
fn append_faces(out: &mut Vec<[i64; 3]>, faces: &[[u32; 3]], index: &[Id], estimate: usize) {
    let len = out.len();
    make_room(out, faces.len(), estimate);
    out.spare_capacity_mut()[..faces.len()]
        .par_chunks_mut(CHUNK)
        .zip(faces.par_chunks(CHUNK))
        .for_each(|(o, f)| {
            for (o, f) in o.iter_mut().zip(f) {
                o.write(f.map(|i| index[i as usize] as i64));
            }
        });
    // SAFETY: the chunks cover the faces.len() rows after `len`, each written above.
    unsafe { out.set_len(len + faces.len()) };
}

/// Checks tile `t`: its window in `lattice`, normals (none, or one per vertex), triangle
/// indices and boundary vertices.
fn check(t: usize, tile: &Tile, lattice: &Lattice) -> Result<()> {
    lattice.window(tile.window[0], tile.window[1])?;
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
    let n = tile.vertices.len() as u32;
    let outside = |c: &[[u32; 3]]| c.iter().flatten().find(|&&i| i >= n).copied();
    if let Some(bad) = tile.faces.par_chunks(CHUNK).find_map_any(outside) {
        return Err(Error::invalid(
            "faces",
            format!("tile {t} has vertex index {bad}, outside its {n} vertices"),
        ));
    }
    check_boundary(t, tile)
}

/// Checks tile `t`'s boundary indices (below its vertex count, one per key) and keys (edges in
/// its window: lower end inside, upper end too).
fn check_boundary(t: usize, tile: &Tile) -> Result<()> {
    if tile.boundary.len() != tile.keys.len() {
        return Err(Error::invalid(
            "keys",
            format!(
                "tile {t} has {} keys for {} boundary vertices",
                tile.keys.len(),
                tile.boundary.len()
            ),
        ));
    }
    let n = tile.vertices.len();
    if let Some(&bad) = tile.boundary.par_iter().find_any(|&&i| i as usize >= n) {
        return Err(Error::invalid(
            "boundary",
            format!("tile {t} has vertex index {bad}, outside its {n} vertices"),
        ));
    }
    let [lo, hi] = tile.window;
    let outside = |&&k: &&u64| {
        let (p, axis) = Lattice::unkey_whole_edge(k);
        k >> 62 != 0
            || axis > 2
            || (0..3).any(|a| p[a] < lo[a] || p[a] + (a == axis as usize) as u32 > hi[a])
    };
    if let Some(&bad) = tile.keys.par_iter().find_any(outside) {
        return Err(Error::invalid(
            "keys",
            format!("tile {t} has edge key {bad}, not an edge of its window"),
        ));
    }
    Ok(())
}

/// `data` cut into consecutive slices of `lengths`.
fn split_by<T>(mut data: &mut [T], lengths: impl Iterator<Item = usize>) -> Vec<&mut [T]> {
    let mut out = Vec::new();
    for n in lengths {
        let (a, b) = std::mem::take(&mut data).split_at_mut(n);
        out.push(a);
        data = b;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::analytic::Sphere;
    use crate::field::Field;
    use crate::mesh::Mesh;
    use crate::polygonize::{dense, octree, Settings};

    /// Bit patterns of a position: equal exactly for equal coordinates.
    type Bits = [u64; 3];

    fn bits(p: DVec3) -> Bits {
        p.to_array().map(f64::to_bits)
    }

    /// `|x| + |y| + |z| − 0.75`: zero at many lattice points of a lattice of cells of 1/8,
    /// where up to six crossed edges give one position.
    struct Octahedron;

    impl Field for Octahedron {
        fn value(&self, p: DVec3) -> f64 {
            p.x.abs() + p.y.abs() + p.z.abs() - 0.75
        }
        fn gradient(&self, p: DVec3) -> DVec3 {
            DVec3::new(p.x.signum(), p.y.signum(), p.z.signum())
        }
    }

    /// Positions of each triangle's corners, bit for bit, sorted: equal for equal meshes
    /// whatever their numbering.
    fn triangles(v: &[DVec3], f: impl Iterator<Item = [usize; 3]>) -> Vec<[Bits; 3]> {
        let mut t: Vec<[Bits; 3]> = f.map(|t| t.map(|i| bits(v[i]))).collect();
        for t in &mut t {
            let m = (0..3).min_by_key(|&k| t[k]).unwrap();
            t.rotate_left(m);
        }
        t.sort_unstable();
        t
    }

    fn tiles_of(lattice: &Lattice, tile: u32) -> Vec<(Lattice, [[u32; 3]; 2])> {
        let starts = |n: u32| {
            (0..n)
                .step_by(tile as usize)
                .map(move |s| (s, (s + tile).min(n)))
        };
        let [nx, ny, nz] = lattice.cells;
        let mut out = Vec::new();
        for (z0, z1) in starts(nz) {
            for (y0, y1) in starts(ny) {
                for (x0, x1) in starts(nx) {
                    let w = [[x0, y0, z0], [x1, y1, z1]];
                    out.push((lattice.window(w[0], w[1]).unwrap(), w));
                }
            }
        }
        out
    }

    /// A tile's mesh, its faces and its boundary vertices with their edge keys.
    type TileMesh = (Mesh, Vec<[u32; 3]>, (Vec<u32>, Vec<u64>), [[u32; 3]; 2]);

    /// Polygonizes every tile of `tile` cells with `polygonize` (a mesh and its edge keys).
    fn tile_meshes(
        lattice: &Lattice,
        tile: u32,
        polygonize: impl Fn(&Lattice) -> (Mesh, Vec<u64>),
    ) -> Vec<TileMesh> {
        tiles_of(lattice, tile)
            .into_iter()
            .map(|(l, w)| {
                let (m, keys) = polygonize(&l);
                assert_eq!(keys.len(), m.vertices.len());
                let f = m.triangles.clone();
                (m, f, boundary_edges(&keys, w), w)
            })
            .collect()
    }

    fn as_tiles(meshes: &[TileMesh]) -> Vec<Tile<'_>> {
        meshes
            .iter()
            .map(|(m, f, (b, k), w)| Tile {
                window: *w,
                vertices: &m.vertices,
                faces: f,
                normals: &m.normals,
                boundary: b,
                keys: k,
            })
            .collect()
    }

    /// The welded mesh is `whole`: the same number of vertices, the same triangles and normals
    /// bit for bit, the same Euler characteristic.
    fn assert_whole(welded: &Welded, whole: &Mesh) {
        assert_eq!(welded.vertices.len(), whole.vertices.len());
        assert_eq!(welded.faces.len(), whole.triangles.len());
        assert_eq!(
            triangles(
                &welded.vertices,
                welded.faces.iter().map(|t| t.map(|i| i as usize))
            ),
            triangles(
                &whole.vertices,
                whole.triangles.iter().map(|t| t.map(|i| i as usize))
            )
        );
        let normals = |v: &[DVec3], n: &[DVec3]| {
            let mut p: Vec<(Bits, Bits)> =
                v.iter().zip(n).map(|(&a, &b)| (bits(a), bits(b))).collect();
            p.sort_unstable();
            p
        };
        assert_eq!(
            normals(&welded.vertices, &welded.normals),
            normals(&whole.vertices, &whole.normals)
        );
        let mesh = Mesh {
            vertices: welded.vertices.clone(),
            triangles: welded.faces.iter().map(|t| t.map(|i| i as u32)).collect(),
            normals: Vec::new(),
        };
        assert_eq!(mesh.euler_characteristic(), whole.euler_characteristic());
        assert_eq!(mesh.is_closed_oriented(), whole.is_closed_oriented());
    }

    /// Tiles of a sphere, welded, give the whole lattice's mesh: the same triangles and
    /// normals bit for bit, the same number of vertices, tile after tile.
    #[test]
    fn welded_tiles_are_the_whole_mesh() {
        let sphere = Sphere {
            center: DVec3::new(0.03, -0.05, 0.02),
            radius: 0.7,
        };
        let lattice =
            Lattice::new(DVec3::splat(-1.0), DVec3::new(1.0, 0.9, 0.8), [23, 19, 17]).unwrap();
        let settings = Settings::default();
        let (whole, _) = dense::polygonize(&sphere, &lattice, &settings).unwrap();
        let meshes = tile_meshes(&lattice, 5, |l| {
            let (m, k, _) = dense::polygonize_keyed(&sphere, l, &settings).unwrap();
            (m, k)
        });
        let welded = weld(&as_tiles(&meshes), &lattice).unwrap();
        assert_whole(&welded, &whole);
        // The first tile's vertices come first, in their order.
        let first = &meshes[0].0.vertices;
        assert_eq!(&welded.vertices[..first.len()], &first[..]);
    }

    /// Where the field is zero at lattice points on tile faces, edges and corners (several
    /// vertices at one position in a tile and on one machine), the weld joins each vertex to
    /// the one of its own edge: the whole mesh, vertex for vertex, for dense and octree tiles.
    #[test]
    fn zeros_at_lattice_points_weld_to_the_whole_mesh() {
        let lattice = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 16).unwrap();
        let settings = Settings::default();
        let (whole, keys, _) = dense::polygonize_keyed(&Octahedron, &lattice, &settings).unwrap();
        // One vertex per crossed edge: several at one position, distinct keys.
        let mut at = whole.vertices.iter().map(|&p| bits(p)).collect::<Vec<_>>();
        at.sort_unstable();
        at.dedup();
        assert!(at.len() < whole.vertices.len());
        let mut distinct = keys.clone();
        distinct.sort_unstable();
        distinct.dedup();
        assert_eq!(distinct.len(), whole.vertices.len());
        assert!(whole.is_closed_oriented());
        let octree_settings = octree::OctreeSettings::default();
        let (whole_octree, _) =
            octree::polygonize(&Octahedron, &lattice, &octree_settings).unwrap();
        for tile in [2, 3, 5, 16] {
            let meshes = tile_meshes(&lattice, tile, |l| {
                let (m, k, _) = dense::polygonize_keyed(&Octahedron, l, &settings).unwrap();
                (m, k)
            });
            assert_whole(&weld(&as_tiles(&meshes), &lattice).unwrap(), &whole);
            let meshes = tile_meshes(&lattice, tile, |l| {
                let (m, k, _) = octree::polygonize_keyed(&Octahedron, l, &octree_settings).unwrap();
                (m, k)
            });
            assert_whole(&weld(&as_tiles(&meshes), &lattice).unwrap(), &whole_octree);
        }
    }

    /// A sphere's dense tiles of `tile` cells on a lattice of 18³ cells over [-1, 1]³.
    fn sphere_tiles(tile: u32) -> (Lattice, Vec<TileMesh>) {
        let sphere = Sphere {
            center: DVec3::new(0.03, -0.05, 0.02),
            radius: 0.7,
        };
        let lattice = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 18).unwrap();
        let settings = Settings::default();
        let meshes = tile_meshes(&lattice, tile, |l| {
            let (m, k, _) = dense::polygonize_keyed(&sphere, l, &settings).unwrap();
            (m, k)
        });
        (lattice, meshes)
    }

    /// A streamed weld told of one tile and given them all (its rows grow past every
    /// estimate) makes the arrays of a weld told of all; a tile refused leaves it unchanged.
    #[test]
    fn a_streamed_weld_grows_past_its_estimate_and_survives_a_refused_tile() {
        let (lattice, meshes) = sphere_tiles(4);
        let tiles = as_tiles(&meshes);
        let mut stream = StreamedWeld::new(1, None);
        let mut seen = std::collections::HashSet::new();
        let mut refused = 0;
        for tile in &tiles {
            let moved: Vec<DVec3> = tile.vertices.iter().map(|&p| p + DVec3::X).collect();
            let bad = Tile {
                vertices: &moved,
                ..*tile
            };
            // Moved, a vertex of an edge an earlier tile has is at other coordinates.
            if tile.keys.iter().any(|k| seen.contains(k)) {
                let before = (stream.added(), stream.vertices());
                assert!(stream.add(&bad, &lattice).is_err());
                assert_eq!((stream.added(), stream.vertices()), before);
                refused += 1;
            }
            stream.add(tile, &lattice).unwrap();
            seen.extend(tile.keys.iter().copied());
        }
        assert!(refused > 10);
        assert_eq!(stream.finish(), weld(&tiles, &lattice).unwrap());
    }

    /// A weld with a memory limit refuses the tile that would take the welded mesh's rows over
    /// it, naming `memory_limit`, and is unchanged; the tiles before it are welded as without a
    /// limit.
    #[test]
    fn a_streamed_weld_refuses_a_tile_over_its_memory_limit() {
        let (lattice, meshes) = sphere_tiles(6);
        let tiles = as_tiles(&meshes);
        let whole = weld(&tiles, &lattice).unwrap();
        let bytes = (whole.vertices.len() * 48 + whole.faces.len() * 24) as u64;
        let mut unlimited = StreamedWeld::new(tiles.len(), None);
        let mut stream = StreamedWeld::new(tiles.len(), None).with_memory_limit(bytes / 2);
        let mut refused = None;
        for (t, tile) in tiles.iter().enumerate() {
            let before = (stream.added(), stream.vertices());
            match stream.add(tile, &lattice) {
                Ok(()) => unlimited.add(tile, &lattice).unwrap(),
                Err(Error::InvalidArgument { name, reason }) => {
                    assert_eq!(name, "memory_limit");
                    assert!(reason.contains("output=DIR"), "{reason}");
                    assert_eq!((stream.added(), stream.vertices()), before);
                    refused = Some(t);
                    break;
                }
                Err(e) => panic!("{e:?}"),
            }
        }
        let t = refused.expect("half the whole mesh's bytes is reached before the last tile");
        assert!(t > 0);
        let (held, first) = (stream.finish(), unlimited.finish());
        assert_eq!(held, first);
        assert!((held.vertices.len() * 48 + held.faces.len() * 24) as u64 <= bytes / 2);
        // The whole mesh within a limit of its bytes.
        let mut exact = StreamedWeld::new(tiles.len(), None).with_memory_limit(bytes);
        for tile in &tiles {
            exact.add(tile, &lattice).unwrap();
        }
        assert_eq!(exact.finish(), whole);
    }

    /// Bad tiles are refused naming the argument at fault.
    #[test]
    fn bad_tiles_are_refused() {
        let lattice = Lattice::new(DVec3::ZERO, DVec3::ONE, [4, 4, 4]).unwrap();
        let v = [DVec3::ZERO, DVec3::X, DVec3::Y];
        let tile = |faces, normals, window| Tile {
            window,
            vertices: &v,
            faces,
            normals,
            boundary: &[],
            keys: &[],
        };
        let w = [[0, 0, 0], [4, 4, 4]];
        let name = |r: Result<Welded>| match r {
            Err(Error::InvalidArgument { name, .. }) => name,
            other => panic!("{other:?}"),
        };
        assert_eq!(name(weld(&[tile(&[[0, 1, 3]], &[], w)], &lattice)), "faces");
        assert_eq!(
            name(weld(&[tile(&[[0, 1, 2]], &v[..1], w)], &lattice)),
            "normals"
        );
        assert_eq!(
            name(weld(&[tile(&[], &[], [[0, 0, 0], [5, 4, 4]])], &lattice)),
            "window"
        );
        fn keyed<'a>(
            vertices: &'a [DVec3],
            boundary: &'a [u32],
            keys: &'a [u64],
            window: [[u32; 3]; 2],
        ) -> Tile<'a> {
            Tile {
                window,
                vertices,
                faces: &[],
                normals: &[],
                boundary,
                keys,
            }
        }
        let k = lattice.whole_edge_key([0, 0, 0], 0);
        let beyond = lattice.whole_edge_key([1, 0, 0], 0);
        let w1 = [[0, 0, 0], [1, 4, 4]];
        let name_of = |tiles: &[Tile]| name(weld(tiles, &lattice));
        let (one, two, three) = ([0u32], [0u32, 1], [3u32]);
        let (kk, k2) = ([k], [k, k]);
        assert_eq!(name_of(&[keyed(&v, &two, &kk, w)]), "keys");
        assert_eq!(name_of(&[keyed(&v, &three, &kk, w)]), "boundary");
        assert_eq!(name_of(&[keyed(&v, &one, &[beyond], w1)]), "keys");
        assert_eq!(name_of(&[keyed(&v, &two, &k2, w)]), "keys");
        // One edge at two positions in two tiles.
        let moved = [DVec3::X];
        assert_eq!(
            name_of(&[keyed(&v, &one, &kk, w1), keyed(&moved, &one, &kk, w1)]),
            "tiles"
        );
        assert_eq!(weld(&[], &lattice).unwrap(), Welded::default());
    }
}
