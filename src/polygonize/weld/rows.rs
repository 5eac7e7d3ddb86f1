//! Writing one tile's rows where its [`TilePlan`] puts them: the vertices (and normals) the weld
//! keeps, in order, and every triangle with its indices renumbered to welded vertices. The
//! rows of a tile are written in parallel chunks.

use super::plan::TilePlan;
use super::{Id, CHUNK};
use crate::error::{Error, Result};
use glam::DVec3;
use rayon::prelude::*;
use std::mem::MaybeUninit;

/// Where one tile's rows go: room for exactly its kept vertices, their normals (`None` when
/// the welded mesh has no normals) and its triangles.
pub struct Rows<'a> {
    /// Room for the tile's kept vertices.
    pub vertices: &'a mut [MaybeUninit<DVec3>],
    /// Room for their normals, `None` when the welded mesh has none.
    pub normals: Option<&'a mut [MaybeUninit<DVec3>]>,
    /// Room for the tile's triangles.
    pub faces: &'a mut [MaybeUninit<[i64; 3]>],
}

/// `rows` as room to write into.
pub fn room<T: Copy>(rows: &mut [T]) -> &mut [MaybeUninit<T>] {
    // SAFETY: `MaybeUninit<T>` has `T`'s layout, and a `Copy` type has no drop glue; the
    // writers only write initialised values.
    unsafe { &mut *(rows as *mut [T] as *mut [MaybeUninit<T>]) }
}

/// Every vertex's welded index in a tile planned as `plan`: the joined ones their earlier
/// vertex's, the others `first_vertex` on, in order. Errors (naming `joined`) when the joined
/// indices are not increasing tile vertices each below `first_vertex`.
pub fn welded_index(plan: &TilePlan) -> Result<Vec<Id>> {
    let n = plan.vertices;
    let first = plan.first_vertex;
    let ok = plan.joined.windows(2).all(|w| w[0].0 < w[1].0)
        && plan
            .joined
            .iter()
            .all(|&(i, to)| (i as usize) < n && (to as usize) < first);
    if !ok || first + plan.kept() > Id::MAX as usize + 1 {
        return Err(Error::invalid(
            "joined",
            format!(
                "expected increasing vertex indices below {n}, each joined to a vertex below {first}"
            ),
        ));
    }
    let mut index = vec![0 as Id; n];
    let mut joined = plan.joined.iter().peekable();
    let mut next = first as Id;
    for (i, slot) in index.iter_mut().enumerate() {
        match joined.peek() {
            Some(&&(j, to)) if j as usize == i => {
                *slot = to;
                joined.next();
            }
            _ => {
                *slot = next;
                next = next.wrapping_add(1);
            }
        }
    }
    Ok(index)
}

/// Writes a tile's rows (`vertices`, `normals` (one per vertex when `out` has room for
/// normals), `faces`) where `plan` puts them, into `out`. Errors (naming the argument) when `out`
/// is not exactly the room the plan asks for, the tile's counts are not the plan's, or a
/// triangle indexes outside the tile's vertices.
pub fn write(
    vertices: &[DVec3],
    normals: &[DVec3],
    faces: &[[u32; 3]],
    plan: &TilePlan,
    out: Rows<'_>,
) -> Result<()> {
    let n = vertices.len();
    if n != plan.vertices || faces.len() != plan.faces {
        return Err(Error::invalid(
            "vertices",
            format!(
                "the tile has {n} vertices and {} triangles, its plan {} and {}",
                faces.len(),
                plan.vertices,
                plan.faces
            ),
        ));
    }
    let kept = plan.kept();
    if out.vertices.len() != kept || out.faces.len() != faces.len() {
        return Err(Error::invalid(
            "out_vertices",
            format!(
                "room for {} vertices and {} triangles, the plan writes {kept} and {}",
                out.vertices.len(),
                out.faces.len(),
                faces.len()
            ),
        ));
    }
    if let Some(room) = &out.normals {
        if room.len() != kept || normals.len() != n {
            return Err(Error::invalid(
                "normals",
                format!(
                    "{} normals for {n} vertices, room for {} of the {kept} kept",
                    normals.len(),
                    room.len()
                ),
            ));
        }
    }
    if let Some(bad) = index_outside(faces, n) {
        return Err(Error::invalid(
            "faces",
            format!("vertex index {bad} is outside the tile's {n} vertices"),
        ));
    }
    let index = welded_index(plan)?;
    let first = plan.first_vertex as Id;
    let per_chunk = kept_per_chunk(&index, first);
    write_kept(out.vertices, vertices, &index, &per_chunk, first);
    if let Some(room) = out.normals {
        write_kept(room, normals, &index, &per_chunk, first);
    }
    write_faces(out.faces, faces, &index);
    Ok(())
}

/// A triangle index of `faces` that is `n` or more (outside `n` vertices), if any.
pub(super) fn index_outside(faces: &[[u32; 3]], n: usize) -> Option<u32> {
    let outside = |c: &[[u32; 3]]| c.iter().flatten().find(|&&i| i as usize >= n).copied();
    faces.par_chunks(CHUNK).find_map_any(outside)
}

/// How many vertices of each chunk of [`CHUNK`] vertices of a tile the weld keeps: those whose
/// welded `index` is `first` (the tile's first welded vertex) or after.
fn kept_per_chunk(index: &[Id], first: Id) -> Vec<usize> {
    index
        .par_chunks(CHUNK)
        .map(|c| c.iter().filter(|&&i| i >= first).count())
        .collect()
}

/// Writes the `rows` (vertices or normals) the weld keeps (`kept` per chunk) into `out`, in
/// order; chunks in parallel.
fn write_kept(
    out: &mut [MaybeUninit<DVec3>],
    rows: &[DVec3],
    index: &[Id],
    kept: &[usize],
    first: Id,
) {
    let slices = split_by(out, kept.iter().copied());
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
}

/// Writes a tile's triangles with every index mapped through `index` into `out`, chunks in
/// parallel.
fn write_faces(out: &mut [MaybeUninit<[i64; 3]>], faces: &[[u32; 3]], index: &[Id]) {
    out.par_chunks_mut(CHUNK)
        .zip(faces.par_chunks(CHUNK))
        .for_each(|(o, f)| {
            for (o, f) in o.iter_mut().zip(f) {
                o.write(f.map(|i| index[i as usize] as i64));
            }
        });
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
