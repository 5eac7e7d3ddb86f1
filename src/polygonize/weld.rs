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

/// Joins the tiles of `lattice` (the whole lattice their windows cut) into one mesh.
///
/// Errors (naming the argument of `_core.weld_tiles`) for a window outside the lattice, a
/// triangle index outside its tile's vertices, normals not one per vertex, boundary indices
/// and keys that do not match (an index outside the tile, a key outside its window, a key
/// twice in a tile), vertices of one edge at different positions in two tiles, or more than
/// 2³² vertices in all. Checks [`cancel::check`] between steps and reports the tiles' vertices
/// done.
pub fn weld(tiles: &[Tile], lattice: &Lattice) -> Result<Welded> {
    let starts = check(tiles, lattice)?;
    let total = starts[tiles.len()] as u64;
    let joined = joined_by_edge(tiles, &starts)?;
    cancel::advance(total / 2)?;
    let (index, kept) = renumbered(tiles, &joined);
    cancel::check()?;
    let welded = Welded {
        vertices: kept_rows(tiles, &index, &kept, |t| t.vertices),
        normals: if tiles.iter().all(|t| t.normals.len() == t.vertices.len()) {
            kept_rows(tiles, &index, &kept, |t| t.normals)
        } else {
            Vec::new()
        },
        faces: renumbered_faces(tiles, &index),
    };
    cancel::advance(total - total / 2)?;
    Ok(welded)
}

/// Checks the tiles; returns where each tile's vertices start among all (and their total last).
fn check(tiles: &[Tile], lattice: &Lattice) -> Result<Vec<usize>> {
    let mut starts = Vec::with_capacity(tiles.len() + 1);
    let mut total = 0usize;
    for (t, tile) in tiles.iter().enumerate() {
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
        check_boundary(t, tile)?;
        starts.push(total);
        total += tile.vertices.len();
    }
    if total > Id::MAX as usize {
        return Err(Error::invalid(
            "vertices",
            format!("{total} vertices in all, over the weld's limit of 2³²"),
        ));
    }
    starts.push(total);
    Ok(starts)
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

/// `(vertex, the vertex it joins)`: the vertices of one edge key are one, the first (the
/// lowest id, of the first tile that has it) kept. Errors for a key twice in one tile or
/// joined vertices at different positions.
fn joined_by_edge(tiles: &[Tile], starts: &[usize]) -> Result<Vec<(Id, Id)>> {
    let mut all: Vec<(u64, Id)> = tiles
        .par_iter()
        .zip(starts)
        .flat_map_iter(|(tile, &start)| {
            tile.keys
                .iter()
                .zip(tile.boundary)
                .map(move |(&k, &i)| (k, (start + i as usize) as Id))
        })
        .collect();
    cancel::check()?;
    all.par_sort_unstable();
    cancel::check()?;
    let tile_of = |id: Id| starts.partition_point(|&s| s <= id as usize) - 1;
    let position = |id: Id| {
        let t = tile_of(id);
        (t, tiles[t].vertices[id as usize - starts[t]])
    };
    let mut joined = Vec::new();
    for run in all.chunk_by(|a, b| a.0 == b.0) {
        let (key, first) = run[0];
        let (mut last, p) = position(first);
        for &(_, id) in &run[1..] {
            let (t, q) = position(id);
            if t == last {
                return Err(Error::invalid(
                    "keys",
                    format!("tile {t} has edge key {key} for two vertices"),
                ));
            }
            if q.to_array().map(f64::to_bits) != p.to_array().map(f64::to_bits) {
                return Err(Error::invalid(
                    "tiles",
                    format!(
                        "the vertex of edge key {key} is at {p} in tile {} and at {q} in tile {t} (tiles of different fields or lattices?)",
                        tile_of(first)
                    ),
                ));
            }
            last = t;
            joined.push((id, first));
        }
    }
    Ok(joined)
}

/// Marker of a vertex joined to another in [`renumbered`]'s first pass.
const JOINED: u32 = u32::MAX;

/// Every tile vertex's index in the welded mesh, and the vertices each tile keeps: their
/// number and the welded index of the tile's first.
fn renumbered(tiles: &[Tile], joined: &[(Id, Id)]) -> (Vec<u32>, Vec<(usize, usize)>) {
    let total: usize = tiles.iter().map(|t| t.vertices.len()).sum();
    let mut index = vec![0u32; total];
    for &(id, _) in joined {
        index[id as usize] = JOINED;
    }
    let mut slices = split_by(&mut index, tiles.iter().map(|t| t.vertices.len()));
    let counts: Vec<usize> = slices
        .par_iter()
        .map(|s| s.iter().filter(|&&i| i != JOINED).count())
        .collect();
    let mut next = 0usize;
    let kept: Vec<(usize, usize)> = counts
        .into_iter()
        .map(|n| {
            next += n;
            (n, next - n)
        })
        .collect();
    slices
        .par_iter_mut()
        .zip(&kept)
        .for_each(|(s, &(_, mut next))| {
            for i in s.iter_mut() {
                if *i != JOINED {
                    *i = next as u32;
                    next += 1;
                }
            }
        });
    // A vertex joins one before it, whose index is final by now.
    for &(id, first) in joined {
        index[id as usize] = index[first as usize];
    }
    (index, kept)
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

/// The rows of `rows(tile)` (vertices or normals) of the vertices the weld keeps, tile after
/// tile; `index` and `kept` as [`renumbered`] gives them. Written in parallel into fresh
/// memory, so that all threads fault its pages in.
fn kept_rows<'a>(
    tiles: &[Tile<'a>],
    index: &[u32],
    kept: &[(usize, usize)],
    rows: impl Fn(&Tile<'a>) -> &'a [DVec3] + Sync,
) -> Vec<DVec3> {
    let total: usize = kept.iter().map(|k| k.0).sum();
    let mut out: Vec<DVec3> = crate::memory::with_capacity_huge(total);
    let slices = split_by(
        &mut out.spare_capacity_mut()[..total],
        kept.iter().map(|k| k.0),
    );
    let own = split_index(index, tiles);
    slices
        .into_par_iter()
        .zip(tiles.par_iter().zip(own).zip(kept))
        .for_each(|(o, ((tile, own), &(_, first)))| {
            let mut at = 0;
            for (&p, &i) in rows(tile).iter().zip(own) {
                // A kept vertex has the next index; a joined one the index of an earlier one.
                if i as usize == first + at {
                    o[at].write(p);
                    at += 1;
                }
            }
        });
    // SAFETY: tile t writes exactly kept[t].0 rows (its vertices with the next index, as
    // `renumbered` counted them) into its slice, and the slices cover out[..total].
    unsafe { out.set_len(total) };
    out
}

/// `index` cut into the tiles' slices.
fn split_index<'a>(index: &'a [u32], tiles: &[Tile]) -> Vec<&'a [u32]> {
    let mut rest = index;
    tiles
        .iter()
        .map(|t| {
            let (a, b) = rest.split_at(t.vertices.len());
            rest = b;
            a
        })
        .collect()
}

/// The tiles' triangles, tile after tile, with every index mapped through `index` (written in
/// parallel into fresh memory, as in [`kept_rows`]).
fn renumbered_faces(tiles: &[Tile], index: &[u32]) -> Vec<[i64; 3]> {
    let total: usize = tiles.iter().map(|t| t.faces.len()).sum();
    let mut out: Vec<[i64; 3]> = crate::memory::with_capacity_huge(total);
    let slices = split_by(
        &mut out.spare_capacity_mut()[..total],
        tiles.iter().map(|t| t.faces.len()),
    );
    let work: Vec<_> = slices
        .into_iter()
        .zip(tiles)
        .zip(split_index(index, tiles))
        .flat_map(|((o, tile), own)| {
            o.chunks_mut(CHUNK)
                .zip(tile.faces.chunks(CHUNK))
                .map(move |(o, f)| (o, f, own))
        })
        .collect();
    work.into_par_iter().for_each(|(o, f, own)| {
        for (o, f) in o.iter_mut().zip(f) {
            o.write(f.map(|i| own[i as usize] as i64));
        }
    });
    // SAFETY: the chunks cover out[..total] and each of their elements is written above.
    unsafe { out.set_len(total) };
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
