//! The exact weld of tile meshes into the mesh of the whole lattice.
//!
//! A tile is a [`Lattice::window`]: the vertex of a lattice edge on a face two tiles share is
//! the same number in both, so joining the tiles' vertices on their faces gives the whole
//! lattice's mesh, vertex for vertex, without tolerance.
//!
//! A vertex not at a lattice point lies on exactly one lattice edge, so its position names the
//! edge and is its key; a tile has one vertex per crossed edge, so where `k` vertices of a tile
//! share a position (only at lattice points, in fact) the `k`-th of each tile are joined. At a
//! lattice point several edges can give the same position (where the field is zero there, or
//! the crossing rounds to the point), and a tile then holds several vertices there: such a
//! vertex is matched, per tile face it lies on, by its position and the positions of its
//! neighbours along the tile's open mesh edges in that face. Those edges are the cut of the
//! surface by the face (the segments marching cubes draws on the cell faces in it), which both
//! tiles make alike from the same corner values; a vertex of a lattice edge that leaves the face
//! into one tile has no such neighbours in that face and is not matched through it.
//!
//! The welded mesh lists the vertices tile after tile, each tile's in its order; a joined vertex
//! takes the place of its first occurrence. Triangles follow tile after tile, in their order.

use crate::cancel;
use crate::error::{Error, Result};
use crate::lattice::Lattice;
use glam::DVec3;
use rayon::prelude::*;
use std::collections::HashMap;

/// One tile's mesh, as a polygonizer run on a window of the lattice makes it.
#[derive(Clone, Copy, Debug)]
pub struct Tile<'a> {
    /// The cells `lo ≤ i < hi` (per axis) of the whole lattice the tile covers.
    pub window: [[u32; 3]; 2],
    /// Vertex positions.
    pub vertices: &'a [DVec3],
    /// Triangles, as indices into `vertices`.
    pub faces: &'a [[i64; 3]],
    /// Unit normals, one per vertex, or none.
    pub normals: &'a [DVec3],
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

/// Bit patterns of a position: equal exactly for equal coordinates.
type Bits = [u64; 3];

fn bits(p: DVec3) -> Bits {
    p.to_array().map(f64::to_bits)
}

/// Joins the tiles of `lattice` (the whole lattice their windows cut) into one mesh.
///
/// Errors (naming the argument of `_core.weld_tiles`) for a window outside the lattice, a
/// triangle index outside its tile's vertices, normals not one per vertex, or more than 2³²
/// vertices in all. Checks [`cancel::check`] between steps and reports the tiles' vertices
/// done.
pub fn weld(tiles: &[Tile], lattice: &Lattice) -> Result<Welded> {
    let starts = check(tiles, lattice)?;
    let total = starts[tiles.len()] as u64;
    let faces: Vec<OnFaces> = tiles
        .par_iter()
        .enumerate()
        .map(|(t, tile)| on_faces(tile, lattice, (t as u32, starts[t])))
        .collect();
    cancel::check()?;
    let mut joined = joined_by_position(&faces);
    cancel::check()?;
    let at_points: Vec<_> = tiles
        .par_iter()
        .zip(&faces)
        .enumerate()
        .flat_map_iter(|(t, (tile, f))| {
            point_groups(tile, lattice, &f.at_points, (t as u32, starts[t]))
        })
        .collect();
    joined.extend(joined_at_points(at_points));
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
        let n = tile.vertices.len() as i64;
        let outside = |c: &[[i64; 3]]| c.iter().flatten().find(|&&i| !(0..n).contains(&i)).copied();
        if let Some(bad) = tile.faces.par_chunks(CHUNK).find_map_any(outside) {
            return Err(Error::invalid(
                "faces",
                format!("tile {t} has vertex index {bad}, outside its {n} vertices"),
            ));
        }
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

/// A tile's vertices on its faces: those not at a lattice point as `(position, id, tile)`,
/// those at one by their index in the tile.
struct OnFaces {
    keyed: Vec<(Bits, Id, u32)>,
    at_points: Vec<u32>,
}

/// The corners of `window`'s box, as the lattice computes its points.
fn corners(lattice: &Lattice, window: [[u32; 3]; 2]) -> [DVec3; 2] {
    window.map(|w| lattice.point(w))
}

/// Whether `p` is a lattice point, bit for bit (the nearest point's index per axis, rounded
/// half to even, gives `p` back).
fn at_lattice_point(p: DVec3, lattice: &Lattice) -> bool {
    (0..3).all(|a| {
        let i = ((p[a] - lattice.base[a]) / lattice.cell[a]).round_ties_even();
        lattice.base[a] + i * lattice.cell[a] == p[a]
    })
}

/// The vertices of tile `t` (whose ids start at `start`) on its box's faces.
fn on_faces(tile: &Tile, lattice: &Lattice, (t, start): (u32, usize)) -> OnFaces {
    let [lo, hi] = corners(lattice, tile.window);
    let mut out = OnFaces {
        keyed: Vec::new(),
        at_points: Vec::new(),
    };
    for (i, &p) in tile.vertices.iter().enumerate() {
        if !(p.cmpeq(lo) | p.cmpeq(hi)).any() {
            continue;
        }
        if at_lattice_point(p, lattice) {
            out.at_points.push(i as u32);
        } else {
            out.keyed.push((bits(p), (start + i) as Id, t));
        }
    }
    out
}

/// `(vertex, the vertex it joins)` for the vertices on tile faces not at lattice points: among
/// the vertices with one position, the `r`-th of each tile joins the `r`-th of the first tile
/// that has one.
fn joined_by_position(faces: &[OnFaces]) -> Vec<(Id, Id)> {
    let mut all: Vec<(Bits, Id, u32)> = faces.iter().flat_map(|f| &f.keyed).copied().collect();
    // Ids grow tile after tile, so this sorts by position, then tile, then index in the tile.
    all.par_sort_unstable();
    let mut joined = Vec::new();
    let mut firsts = Vec::new();
    for run in all.chunk_by(|a, b| a.0 == b.0) {
        join_by_rank(run.iter().map(|e| (e.2, e.1)), &mut firsts, |id, first| {
            joined.push((id, first))
        });
    }
    joined
}

/// Walks `ids` (`(tile, id)`, increasing) and calls `join(id, first)` for the `r`-th id of a
/// tile when an earlier tile had an `r`-th id (`first`), else records `id` as the `r`-th.
fn join_by_rank(
    ids: impl Iterator<Item = (u32, Id)>,
    firsts: &mut Vec<Id>,
    mut join: impl FnMut(Id, Id),
) {
    firsts.clear();
    let (mut tile, mut rank) = (None, 0);
    for (t, id) in ids {
        if tile == Some(t) {
            rank += 1;
        } else {
            (tile, rank) = (Some(t), 0);
        }
        match firsts.get(rank) {
            Some(&first) => join(id, first),
            None => firsts.push(id),
        }
    }
}

/// A group of vertices at lattice points to match: the axis of the tile face, the position,
/// and the positions of the vertex's neighbours in that face (sorted).
type PointKey = (u8, Bits, Vec<Bits>);

/// The keys of the vertices `at_points` of tile `t` (indices in the tile), with their global
/// ids (the tile's start `start` plus the index) and `t`.
fn point_groups(
    tile: &Tile,
    lattice: &Lattice,
    at_points: &[u32],
    (t, start): (u32, usize),
) -> Vec<(PointKey, Id, u32)> {
    if at_points.is_empty() {
        return Vec::new();
    }
    let v = tile.vertices;
    let mut is_point = vec![false; v.len()];
    for &i in at_points {
        is_point[i as usize] = true;
    }
    // Mesh edges with an end at such a vertex, used by one triangle of the tile.
    let mut edges: Vec<(u32, u32)> = Vec::new();
    for f in tile.faces {
        let f = f.map(|i| i as u32);
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            if is_point[a as usize] || is_point[b as usize] {
                edges.push((a.min(b), a.max(b)));
            }
        }
    }
    edges.sort_unstable();
    let mut neighbours: HashMap<u32, Vec<u32>> = HashMap::new();
    for run in edges.chunk_by(|a, b| a == b) {
        if let [(a, b)] = run {
            for (p, q) in [(a, b), (b, a)] {
                if is_point[*p as usize] {
                    neighbours.entry(*p).or_default().push(*q);
                }
            }
        }
    }
    let [lo, hi] = corners(lattice, tile.window);
    let mut out = Vec::new();
    for &i in at_points {
        let p = v[i as usize];
        let nbrs = neighbours.get(&i).map_or(&[][..], |n| n.as_slice());
        for axis in 0..3 {
            for plane in [lo[axis], hi[axis]] {
                if p[axis] != plane {
                    continue;
                }
                let in_plane: Vec<DVec3> = nbrs
                    .iter()
                    .map(|&n| v[n as usize])
                    .filter(|q| q[axis] == plane)
                    .collect();
                if in_plane.is_empty() {
                    continue;
                }
                // Neighbours at the vertex's own position (segments of length zero, which may
                // lie on another face through the point) only say that there are some.
                let mut apart: Vec<Bits> =
                    in_plane.into_iter().filter(|&q| q != p).map(bits).collect();
                apart.sort_unstable();
                out.push(((axis as u8, bits(p), apart), (start + i as usize) as Id, t));
            }
        }
    }
    out
}

/// `(vertex, the vertex it joins)` for the vertices at lattice points: within a group of equal
/// keys the `r`-th of each tile and the `r`-th of the first tile having one are one vertex; a
/// vertex in several groups joins all of theirs, and each set takes its smallest id.
fn joined_at_points(mut keyed: Vec<(PointKey, Id, u32)>) -> Vec<(Id, Id)> {
    keyed.sort_unstable();
    // Union-find over the ids, each set's root its smallest id.
    let mut parent: HashMap<Id, Id> = HashMap::new();
    fn find(parent: &mut HashMap<Id, Id>, a: Id) -> Id {
        let mut root = a;
        while let Some(&p) = parent.get(&root) {
            if p == root {
                break;
            }
            root = p;
        }
        let mut x = a;
        while x != root {
            let p = parent[&x];
            parent.insert(x, root);
            x = p;
        }
        root
    }
    let mut firsts = Vec::new();
    for run in keyed.chunk_by(|a, b| a.0 == b.0) {
        join_by_rank(run.iter().map(|e| (e.2, e.1)), &mut firsts, |id, first| {
            let (a, b) = (find(&mut parent, id), find(&mut parent, first));
            parent.insert(a.max(b), a.min(b));
        });
    }
    let mut ids: Vec<Id> = parent.keys().copied().collect();
    ids.sort_unstable();
    ids.into_iter()
        .filter_map(|id| {
            let root = find(&mut parent, id);
            (root != id).then_some((id, root))
        })
        .collect()
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
    use crate::polygonize::{dense, Settings};

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
        let meshes: Vec<_> = tiles_of(&lattice, 5)
            .into_iter()
            .map(|(l, w)| {
                let (m, _) = dense::polygonize(&sphere, &l, &settings).unwrap();
                let f: Vec<[i64; 3]> = m.triangles.iter().map(|t| t.map(i64::from)).collect();
                (m, f, w)
            })
            .collect();
        let tiles: Vec<Tile> = meshes
            .iter()
            .map(|(m, f, w)| Tile {
                window: *w,
                vertices: &m.vertices,
                faces: f,
                normals: &m.normals,
            })
            .collect();
        let welded = weld(&tiles, &lattice).unwrap();
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
        // The first tile's vertices come first, in their order.
        let first = &meshes[0].0.vertices;
        assert_eq!(&welded.vertices[..first.len()], &first[..]);
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
        };
        let w = [[0, 0, 0], [4, 4, 4]];
        let name = |r: Result<Welded>| match r {
            Err(Error::InvalidArgument { name, .. }) => name,
            other => panic!("{other:?}"),
        };
        assert_eq!(name(weld(&[tile(&[[0, 1, 3]], &[], w)], &lattice)), "faces");
        assert_eq!(
            name(weld(&[tile(&[[0, -1, 2]], &[], w)], &lattice)),
            "faces"
        );
        assert_eq!(
            name(weld(&[tile(&[[0, 1, 2]], &v[..1], w)], &lattice)),
            "normals"
        );
        assert_eq!(
            name(weld(&[tile(&[], &[], [[0, 0, 0], [5, 4, 4]])], &lattice)),
            "window"
        );
        assert_eq!(weld(&[], &lattice).unwrap(), Welded::default());
    }
}
