//! Plain marching cubes over the whole lattice: the reference polygonizer.
//!
//! The lattice is swept in groups of z-layers of cells. For each group, one batched field call
//! (or a few, for small batches) fills the values of its planes ([`Field::lattice_values`]);
//! then, in parallel over the planes and layers of the group:
//! 1. the signs of every plane are packed into bit rows (64 points per word), and every point
//!    row is classified as all outside, all inside or mixed;
//! 2. each layer makes the vertices of the crossed edges it owns — the x- and y-edges of its top
//!    plane and the z-edges between its planes — with indices local to the layer; crossed
//!    edges are found a word at a time (the exclusive-or of neighbouring bit rows);
//! 3. a prefix sum over the layers turns local indices into global ones, and each layer
//!    triangulates its crossed cells (found a word at a time too) with the shared case table.
//!
//! So the work grows with the surface, plus one pass over the values. Every crossed lattice
//! edge gets exactly one vertex, shared by the four cells around it; the output (vertex and
//! triangle order included) does not depend on the number of threads. The working memory grows
//! with one group of planes, not with the lattice.

use super::bits::{for_each_set_bit, sign_word};
use super::{
    check_memory, estimate_triangles, finish_mesh, gather, CaseTable, Polygonized, Settings, Stats,
};
use crate::error::Result;
use crate::field::Field;
use crate::lattice::{edge_crossing, Lattice};
use crate::mesh::Mesh;
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

/// A point row (fixed y and z) whose points are all outside.
const OUT: u8 = 0;
/// A point row whose points are all inside.
const IN: u8 = 1;
/// A point row with points on both sides.
const MIXED: u8 = 2;

/// Smallest number of cell layers per group, so that both phases have parallel work.
const MIN_LAYERS_PER_GROUP: u32 = 8;

/// For each cell edge: which index array holds it (0 bottom x, 1 top x, 2 bottom y, 3 top y,
/// 4 z) and its offset in x and y from the cell's lower corner.
const EDGE_SLOT: [(usize, usize, usize); 12] = [
    (0, 0, 0),
    (0, 0, 1),
    (1, 0, 0),
    (1, 0, 1),
    (2, 0, 0),
    (2, 1, 0),
    (3, 0, 0),
    (3, 1, 0),
    (4, 0, 0),
    (4, 1, 0),
    (4, 0, 1),
    (4, 1, 1),
];

/// Shape of the bit rows: words per row.
#[derive(Clone, Copy)]
struct Bits {
    words: usize,
}

impl Bits {
    fn new(points: usize) -> Self {
        Bits {
            words: points.div_ceil(64),
        }
    }

    /// Mask of the bits of word `w` whose index is below `n`.
    #[inline]
    fn below(w: usize, n: usize) -> u64 {
        let lo = w * 64;
        if lo + 64 <= n {
            !0
        } else if lo >= n {
            0
        } else {
            (1u64 << (n - lo)) - 1
        }
    }

    /// Word `w` of `row` shifted down by one bit (bit i holds point i + 1).
    #[inline]
    fn next(row: &[u64], w: usize) -> u64 {
        (row[w] >> 1) | (row.get(w + 1).map_or(0, |n| n << 63))
    }
}

/// Packs the signs of a row (bit i set when point i is inside) and returns whether its points
/// are all outside, all inside, or mixed.
#[inline]
fn row_bits(row: &[f64], out: &mut [u64]) -> u8 {
    let mut inside = 0u32;
    for (o, chunk) in out.iter_mut().zip(row.chunks(64)) {
        let w = sign_word(chunk);
        inside += w.count_ones();
        *o = w;
    }
    if inside == 0 {
        OUT
    } else if inside as usize == row.len() {
        IN
    } else {
        MIXED
    }
}

/// True when an edge between rows of these kinds may be crossed.
#[inline]
fn may_cross(a: u8, b: u8) -> bool {
    a == MIXED || a != b
}

/// Calls `f(i)` for every set bit `i` of the words that `mask(w)` gives.
#[inline(always)]
fn for_each_bit(words: usize, mut mask: impl FnMut(usize) -> u64, mut f: impl FnMut(usize)) {
    for w in 0..words {
        for_each_set_bit(mask(w), |b| f(w * 64 + b as usize));
    }
}

/// The edge vertices one layer of cells owns (the x- and y-edges of its top plane, the z-edges
/// between its planes). An index array entry is written only when its edge is crossed and read
/// only for crossed edges (the case table refers to no other), so the arrays are never cleared.
#[derive(Default)]
struct Layer {
    /// x-edge `(i, j)` of the top plane at `j * nx + i`.
    x: Vec<u32>,
    /// y-edge `(i, j)` of the top plane at `j * px + i`.
    y: Vec<u32>,
    /// z-edge from point `(i, j)` of the bottom plane at `j * px + i`.
    z: Vec<u32>,
    /// Global index of the layer's first vertex.
    base: u32,
}

/// One plane's values, sign bits and row kinds.
#[derive(Clone, Copy)]
struct Plane<'a> {
    values: &'a [f64],
    bits: &'a [u64],
    rows: &'a [u8],
}

impl Plane<'_> {
    #[inline]
    fn bit_row(&self, b: Bits, j: usize) -> &[u64] {
        &self.bits[j * b.words..(j + 1) * b.words]
    }
}

/// Makes the vertices of the crossed x- and y-edges of plane `k`, writing their indices (from
/// `vertices.len()`) into `xe` and `ye`, and their edges' keys into `keys` when given.
fn plane_edges(
    lattice: &Lattice,
    k: u32,
    p: Plane,
    (xe, ye): (&mut [u32], &mut [u32]),
    vertices: &mut Vec<DVec3>,
    mut keys: Option<&mut Vec<u64>>,
) {
    let [nx, ny, _] = lattice.cells();
    let (nxu, px) = (nx as usize, nx as usize + 1);
    let b = Bits::new(px);
    for j in 0..=ny as usize {
        if p.rows[j] != MIXED {
            continue;
        }
        let r = p.bit_row(b, j);
        let v = &p.values[j * px..(j + 1) * px];
        for_each_bit(
            b.words,
            |w| (r[w] ^ Bits::next(r, w)) & Bits::below(w, nxu),
            |i| {
                xe[j * nxu + i] = vertices.len() as u32;
                if let Some(keys) = keys.as_mut() {
                    keys.push(lattice.whole_edge_key([i as u32, j as u32, k], 0));
                }
                let pa = lattice.point([i as u32, j as u32, k]);
                let pb = lattice.point([i as u32 + 1, j as u32, k]);
                vertices.push(edge_crossing(pa, pb, v[i], v[i + 1]));
            },
        );
    }
    for j in 0..ny as usize {
        if !may_cross(p.rows[j], p.rows[j + 1]) {
            continue;
        }
        let (r0, r1) = (p.bit_row(b, j), p.bit_row(b, j + 1));
        for_each_bit(
            b.words,
            |w| r0[w] ^ r1[w],
            |i| {
                ye[j * px + i] = vertices.len() as u32;
                if let Some(keys) = keys.as_mut() {
                    keys.push(lattice.whole_edge_key([i as u32, j as u32, k], 1));
                }
                let pa = lattice.point([i as u32, j as u32, k]);
                let pb = lattice.point([i as u32, j as u32 + 1, k]);
                let (a, c) = (p.values[j * px + i], p.values[(j + 1) * px + i]);
                vertices.push(edge_crossing(pa, pb, a, c));
            },
        );
    }
}

/// Makes the vertices layer `k` owns, into `vertices` (and their edges' keys into `keys` when
/// given): the crossed x- and y-edges of plane `k + 1` and the crossed z-edges between planes
/// `k` and `k + 1`.
fn layer_vertices(
    lattice: &Lattice,
    k: u32,
    (lo, hi): (Plane, Plane),
    layer: &mut Layer,
    vertices: &mut Vec<DVec3>,
    mut keys: Option<&mut Vec<u64>>,
) {
    let [nx, ny, _] = lattice.cells();
    let (nxu, pxu, pyu) = (nx as usize, nx as usize + 1, ny as usize + 1);
    for (a, n) in [
        (&mut layer.x, nxu * pyu),
        (&mut layer.y, pxu * (pyu - 1)),
        (&mut layer.z, pxu * pyu),
    ] {
        if a.len() != n {
            *a = vec![0; n];
        }
    }
    vertices.clear();
    if let Some(keys) = keys.as_mut() {
        keys.clear();
    }
    let edges = (&mut layer.x[..], &mut layer.y[..]);
    plane_edges(lattice, k + 1, hi, edges, vertices, keys.as_deref_mut());
    let b = Bits::new(pxu);
    for j in 0..pyu {
        if !may_cross(lo.rows[j], hi.rows[j]) {
            continue;
        }
        let (r0, r1) = (lo.bit_row(b, j), hi.bit_row(b, j));
        for_each_bit(
            b.words,
            |w| r0[w] ^ r1[w],
            |i| {
                let idx = j * pxu + i;
                layer.z[idx] = vertices.len() as u32;
                if let Some(keys) = keys.as_mut() {
                    keys.push(lattice.whole_edge_key([i as u32, j as u32, k], 2));
                }
                let pa = lattice.point([i as u32, j as u32, k]);
                let pb = lattice.point([i as u32, j as u32, k + 1]);
                vertices.push(edge_crossing(pa, pb, lo.values[idx], hi.values[idx]));
            },
        );
    }
}

/// Edge-vertex indices of a layer's bottom plane: x-edges, y-edges and the number to add.
type Bottom<'a> = (&'a [u32], &'a [u32], u32);

/// Triangulates the crossed cells of one layer into `out`; returns their number.
fn triangulate_layer(
    table: &CaseTable,
    lattice: &Lattice,
    (lo, hi): (Plane, Plane),
    bottom: Bottom,
    layer: &Layer,
    out: &mut Vec<[u32; 3]>,
) -> u64 {
    let [nx, ny, _] = lattice.cells();
    let (nxu, pxu) = (nx as usize, nx as usize + 1);
    let b = Bits::new(pxu);
    let (bx, by, bbase) = bottom;
    let arrays: [&[u32]; 5] = [bx, &layer.x, by, &layer.y, &layer.z];
    let strides = [nxu, nxu, pxu, pxu, pxu];
    let bases = [bbase, layer.base, bbase, layer.base, layer.base];
    let mut crossed = 0;
    for j in 0..ny as usize {
        let kinds = [lo.rows[j], lo.rows[j + 1], hi.rows[j], hi.rows[j + 1]];
        if kinds[0] != MIXED && kinds.iter().all(|&r| r == kinds[0]) {
            continue;
        }
        // Corner rows in case-bit order: (y, z) = (0, 0), (1, 0), (0, 1), (1, 1).
        let rows = [
            lo.bit_row(b, j),
            lo.bit_row(b, j + 1),
            hi.bit_row(b, j),
            hi.bit_row(b, j + 1),
        ];
        // Bits i and i + 1 of a row (the two corners of cell i along x).
        let pair = |r: &[u64], i: usize| -> u8 {
            let (w, s) = (i >> 6, i & 63);
            if s < 63 {
                ((r[w] >> s) & 3) as u8
            } else {
                ((r[w] >> 63) | ((r[w + 1] & 1) << 1)) as u8
            }
        };
        // Each cell edge's index row for this cell row, and the number to add.
        let edge_rows: [(&[u32], u32); 12] = std::array::from_fn(|e| {
            let (slot, dx, dy) = EDGE_SLOT[e];
            (&arrays[slot][(j + dy) * strides[slot] + dx..], bases[slot])
        });
        for_each_bit(
            b.words,
            |w| {
                // A cell is crossed unless its eight corners agree.
                let (mut any, mut all) = (0u64, !0u64);
                for r in rows {
                    let (a, n) = (r[w], Bits::next(r, w));
                    any |= a | n;
                    all &= a & n;
                }
                any & !all & Bits::below(w, nxu)
            },
            |i| {
                let case = pair(rows[0], i)
                    | pair(rows[1], i) << 2
                    | pair(rows[2], i) << 4
                    | pair(rows[3], i) << 6;
                crossed += 1;
                let vertex = |e: u8| {
                    let (row, base) = edge_rows[e as usize];
                    row[i].wrapping_add(base)
                };
                for t in table.triangles(case) {
                    out.push([vertex(t[0]), vertex(t[1]), vertex(t[2])]);
                }
            },
        );
    }
    crossed
}

/// Fills `out` with the values of planes `z0..z1`, at most `batch` points per field call (at
/// least one plane), and checks that they are finite.
fn fill_planes<F: Field + ?Sized>(
    field: &F,
    lattice: &Lattice,
    (z0, z1): (u32, u32),
    batch: usize,
    points: &mut Vec<DVec3>,
    out: &mut [f64],
) -> Result<()> {
    let [px, py, _] = lattice.points_per_axis();
    let plane = px as usize * py as usize;
    let per = (batch / plane).max(1) as u32;
    let mut z = z0;
    while z < z1 {
        let z2 = (z + per).min(z1);
        let chunk = &mut out[(z - z0) as usize * plane..(z2 - z0) as usize * plane];
        crate::cancel::check()?;
        field.lattice_values(lattice, z, z2, points, chunk);
        crate::cancel::advance(chunk.len() as u64)?;
        if let Some(i) = chunk.iter().position(|v| !v.is_finite()) {
            let (pl, r) = (i / plane, i % plane);
            let q = lattice.point([
                (r % px as usize) as u32,
                (r / px as usize) as u32,
                z + pl as u32,
            ]);
            return Err(crate::Error::FieldNotFinite {
                x: q.x,
                y: q.y,
                z: q.z,
            });
        }
        z = z2;
    }
    Ok(())
}

/// Buffers of one polygonization, kept between calls so that a repeated call (an animation, a
/// benchmark) does not fault in fresh pages for them every time.
#[derive(Default)]
struct Workspace {
    values: Vec<f64>,
    bits: Vec<u64>,
    rows: Vec<u8>,
    points: Vec<DVec3>,
    layers: Vec<Layer>,
    /// Per cell layer of the lattice (plus the bottom plane first): its vertices and triangles,
    /// gathered into the mesh at the end.
    vertices: Vec<Vec<DVec3>>,
    /// Beside `vertices`, their edges' keys ([`polygonize_keyed`] only).
    keys: Vec<Vec<u64>>,
    triangles: Vec<Vec<[u32; 3]>>,
    carry_x: Vec<u32>,
    carry_y: Vec<u32>,
}

impl Workspace {
    fn bytes(&self) -> usize {
        self.values.capacity() * 8
            + self.bits.capacity() * 8
            + self.rows.capacity()
            + self.points.capacity() * 24
            + self.carry_x.capacity() * 4
            + self.carry_y.capacity() * 4
            + self
                .layers
                .iter()
                .map(|l| (l.x.capacity() + l.y.capacity() + l.z.capacity()) * 4)
                .sum::<usize>()
            + self
                .vertices
                .iter()
                .map(|v| v.capacity() * 24)
                .sum::<usize>()
            + self
                .triangles
                .iter()
                .map(|t| t.capacity() * 12)
                .sum::<usize>()
            + self.keys.iter().map(|k| k.capacity() * 8).sum::<usize>()
    }
}

/// Workspaces returned by finished calls (at most two, and none above [`KEEP_BYTES`]).
static WORKSPACES: std::sync::Mutex<Vec<Workspace>> = std::sync::Mutex::new(Vec::new());
const KEEP_BYTES: usize = 64 << 20;

fn take_workspace() -> Workspace {
    WORKSPACES
        .lock()
        .ok()
        .and_then(|mut w| w.pop())
        .unwrap_or_default()
}

fn return_workspace(w: Workspace) {
    if w.bytes() <= KEEP_BYTES {
        if let Ok(mut pool) = WORKSPACES.lock() {
            if pool.len() < 2 {
                pool.push(w);
            }
        }
    }
}

/// Cell layers per group: as many planes as one batch holds, at least a few for parallel work.
/// The groups are balanced: 64 layers in batches of 62 make two groups of 32, not 62 and 2.
fn layers_per_group(lattice: &Lattice, settings: &Settings) -> u32 {
    let [px, py, _] = lattice.points_per_axis();
    let nz = lattice.cells()[2] as u64;
    let most = (settings.batch as u64 / (px as u64 * py as u64))
        .max(MIN_LAYERS_PER_GROUP as u64)
        .min(nz);
    nz.div_ceil(nz.div_ceil(most)) as u32
}

/// Polygonizes `field` over every cell of `lattice` with plain marching cubes, with the
/// vertices' edge keys when [`Settings::keys`] asks for them ([`super::polygonize`] with
/// [`super::Method::Dense`]).
pub(crate) fn polygonize<F: Field + ?Sized>(
    field: &F,
    lattice: &Lattice,
    settings: &Settings,
) -> Result<Polygonized> {
    let keyed = settings.keys;
    let plane = lattice.points_per_axis()[..2]
        .iter()
        .map(|&p| p as u64)
        .product::<u64>();
    let per_group = layers_per_group(lattice, settings) as u64;
    // Working memory: the group's values, sign bits, edge indices and row kinds, the points of
    // one batch (for fields that build them); plus the output.
    let working = (per_group + 1) * plane * 10
        + per_group * plane * 12
        + (settings.batch as u64).max(plane) * 24;
    check_memory(
        working + estimate_triangles(lattice) * super::BYTES_PER_TRIANGLE,
        settings.memory_limit,
    )?;

    let table = CaseTable::get(settings.ambiguity);
    let mut stats = Stats {
        lattice_points: lattice.num_points(),
        cells_visited: lattice.num_cells(),
        ..Default::default()
    };
    let mut mesh = Mesh::default();
    let mut ws = take_workspace();
    let r = sweep(
        field,
        lattice,
        (settings, table, keyed),
        &mut ws,
        &mut mesh,
        &mut stats,
    );
    return_workspace(ws);
    let keys = r?;
    debug_assert!(mesh
        .triangles
        .iter()
        .flatten()
        .all(|&v| (v as usize) < mesh.vertices.len()));
    finish_mesh(field, &mut mesh, lattice, settings, &mut stats)?;
    Ok(Polygonized {
        mesh,
        keys: keyed.then_some(keys),
        stats,
    })
}

/// The sweep over the groups of planes (see the module documentation); returns the vertices'
/// edge keys when `keyed` (else none).
fn sweep<F: Field + ?Sized>(
    field: &F,
    lattice: &Lattice,
    (settings, table, keyed): (&Settings, &CaseTable, bool),
    ws: &mut Workspace,
    mesh: &mut Mesh,
    stats: &mut Stats,
) -> Result<Vec<u64>> {
    let [nx, _, nz] = lattice.cells();
    let [px, py, _] = lattice.points_per_axis();
    let (nxu, pxu, pyu) = (nx as usize, px as usize, py as usize);
    let plane = pxu * pyu;
    let b = Bits::new(pxu);
    let plane_words = b.words * pyu;
    let per_group = layers_per_group(lattice, settings);
    let Workspace {
        values,
        bits,
        rows,
        points,
        layers,
        vertices,
        keys,
        triangles,
        carry_x,
        carry_y,
    } = ws;
    // Global vertex indices of the x- and y-edges of the group's bottom plane.
    carry_x.resize(nxu * pyu, 0);
    carry_y.resize(pxu * (pyu - 1), 0);
    // vertices[0]: the bottom plane's; vertices[k + 1]: cell layer k's.
    let nzu = nz as usize;
    if vertices.len() < nzu + 1 {
        vertices.resize_with(nzu + 1, Vec::new);
    }
    if keyed && keys.len() < nzu + 1 {
        keys.resize_with(nzu + 1, Vec::new);
    }
    if triangles.len() < nzu {
        triangles.resize_with(nzu, Vec::new);
    }
    values.clear();
    let mut next_base = 0u32;
    let mut g0 = 0u32;
    while g0 < nz {
        let g1 = (g0 + per_group).min(nz);
        let (n_planes, n_layers) = ((g1 - g0 + 1) as usize, (g1 - g0) as usize);
        let t = Instant::now();
        // The previous group's top plane is this group's bottom plane: evaluated once.
        let first_new = if g0 == 0 {
            0
        } else {
            let last = values.len() - plane;
            values.copy_within(last.., 0);
            1
        };
        values.resize(n_planes * plane, 0.0);
        fill_planes(
            field,
            lattice,
            (g0 + first_new as u32, g1 + 1),
            settings.batch,
            points,
            &mut values[first_new * plane..],
        )?;
        stats.evaluations += ((n_planes - first_new) * plane) as u64;
        stats.add_time("evaluate", t);

        let t = Instant::now();
        rows.resize(n_planes * pyu, OUT);
        bits.resize(n_planes * plane_words, 0);
        rows.par_chunks_mut(pyu)
            .zip(bits.par_chunks_mut(plane_words))
            .zip(values.par_chunks(plane))
            .for_each(|((r, bw), v)| {
                for (j, rj) in r.iter_mut().enumerate() {
                    *rj = row_bits(
                        &v[j * pxu..(j + 1) * pxu],
                        &mut bw[j * b.words..(j + 1) * b.words],
                    );
                }
            });
        let planes: Vec<Plane> = (0..n_planes)
            .map(|l| Plane {
                values: &values[l * plane..(l + 1) * plane],
                bits: &bits[l * plane_words..(l + 1) * plane_words],
                rows: &rows[l * pyu..(l + 1) * pyu],
            })
            .collect();
        if g0 == 0 {
            vertices[0].clear();
            let mut first_keys = keys.first_mut().filter(|_| keyed);
            if let Some(k) = first_keys.as_deref_mut() {
                k.clear();
            }
            let edges = (&mut carry_x[..], &mut carry_y[..]);
            plane_edges(lattice, 0, planes[0], edges, &mut vertices[0], first_keys);
            next_base = vertices[0].len() as u32;
        }
        if layers.len() < n_layers {
            layers.resize_with(n_layers, Layer::default);
        }
        let group = g0 as usize + 1..g1 as usize + 1;
        let group_vertices = &mut vertices[group.clone()];
        let mut group_keys: Vec<Option<&mut Vec<u64>>> = match keyed {
            true => keys[group].iter_mut().map(Some).collect(),
            false => (0..n_layers).map(|_| None).collect(),
        };
        layers[..n_layers]
            .par_iter_mut()
            .zip(group_vertices.par_iter_mut())
            .zip(group_keys.par_iter_mut())
            .enumerate()
            .for_each(|(l, ((layer, v), k))| {
                let planes = (planes[l], planes[l + 1]);
                layer_vertices(lattice, g0 + l as u32, planes, layer, v, k.take())
            });
        for (layer, v) in layers[..n_layers].iter_mut().zip(group_vertices.iter()) {
            layer.base = next_base;
            next_base = u32::try_from(next_base as usize + v.len())
                .map_err(|_| crate::Error::invalid("resolution", "more than 2³² vertices"))?;
        }
        let done: &[Layer] = &layers[..n_layers];
        let (cx, cy) = (&carry_x[..], &carry_y[..]);
        stats.cells_crossed += triangles[g0 as usize..g1 as usize]
            .par_iter_mut()
            .enumerate()
            .map(|(l, out)| {
                out.clear();
                let bottom = match l {
                    0 => (cx, cy, 0),
                    _ => (&done[l - 1].x[..], &done[l - 1].y[..], done[l - 1].base),
                };
                triangulate_layer(
                    table,
                    lattice,
                    (planes[l], planes[l + 1]),
                    bottom,
                    &done[l],
                    out,
                )
            })
            .sum::<u64>();
        let top = &layers[n_layers - 1];
        for (c, &i) in carry_x.iter_mut().zip(&top.x) {
            *c = i.wrapping_add(top.base);
        }
        for (c, &i) in carry_y.iter_mut().zip(&top.y) {
            *c = i.wrapping_add(top.base);
        }
        stats.add_time("triangulate", t);
        g0 = g1;
    }
    let t = Instant::now();
    mesh.vertices = gather(&vertices[..nzu + 1]);
    mesh.triangles = gather(&triangles[..nzu]);
    let keys = if keyed {
        gather(&keys[..nzu + 1])
    } else {
        Vec::new()
    };
    stats.add_time("triangulate", t);
    Ok(keys)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::analytic::{Sphere, Torus};
    use crate::polygonize::Ambiguity;

    fn cube(n: u32, h: f64) -> Lattice {
        Lattice::new(DVec3::splat(-h), DVec3::splat(h), [n, n, n]).unwrap()
    }

    #[test]
    fn sphere_is_closed_with_the_right_area() {
        let s = Sphere {
            center: DVec3::new(0.01, 0.02, -0.03),
            radius: 0.7,
        };
        for amb in [Ambiguity::Separate, Ambiguity::Join] {
            let settings = Settings {
                ambiguity: amb,
                batch: 1000, // several planes per batch and a partial last batch
                ..Default::default()
            };
            let crate::polygonize::Polygonized {
                mesh: m, stats: st, ..
            } = polygonize(&s, &cube(64, 1.0), &settings).unwrap();
            assert!(m.is_closed_oriented());
            assert_eq!(m.euler_characteristic(), 2);
            let exact = 4.0 * std::f64::consts::PI * 0.49;
            assert!((m.area() - exact).abs() / exact < 0.01);
            assert!(m.volume() > 0.0);
            assert_eq!(st.evaluations, 65 * 65 * 65);
            assert_eq!(m.normals.len(), m.vertices.len());
        }
    }

    #[test]
    fn torus_has_genus_one() {
        let t = Torus {
            center: DVec3::new(0.013, -0.02, 0.007),
            major: 0.6,
            minor: 0.25,
        };
        let crate::polygonize::Polygonized {
            mesh: m, stats: _, ..
        } = polygonize(&t, &cube(48, 1.0), &Settings::default()).unwrap();
        assert!(m.is_closed_oriented());
        assert_eq!(m.euler_characteristic(), 0);
    }

    #[test]
    fn anisotropic_lattice() {
        let s = Sphere {
            center: DVec3::ZERO,
            radius: 0.5,
        };
        let l = Lattice::new(
            DVec3::new(-1.0, -0.7, -0.6),
            DVec3::new(0.9, 0.8, 0.6),
            [37, 23, 19],
        )
        .unwrap();
        let crate::polygonize::Polygonized {
            mesh: m, stats: _, ..
        } = polygonize(&s, &l, &Settings::default()).unwrap();
        assert!(m.is_closed_oriented());
        assert_eq!(m.euler_characteristic(), 2);
    }

    #[test]
    fn surface_cut_by_the_bounds_is_open() {
        let s = Sphere {
            center: DVec3::ZERO,
            radius: 1.2,
        };
        let crate::polygonize::Polygonized {
            mesh: m, stats: _, ..
        } = polygonize(&s, &cube(16, 1.0), &Settings::default()).unwrap();
        assert!(!m.triangles.is_empty());
        assert!(!m.is_closed_oriented());
    }

    #[test]
    fn absurd_resolution_refused() {
        let s = Sphere {
            center: DVec3::ZERO,
            radius: 0.5,
        };
        let l = cube(1_000_000, 1.0);
        assert!(matches!(
            polygonize(&s, &l, &Settings::default()),
            Err(crate::error::Error::TooMuchMemory { .. })
        ));
    }
}
