//! The crossed leaves' triangles, made in parallel and numbered as a serial sweep would.

use super::leaves::CrossedLeaf;
use super::run::Run;
use super::store::{atomic_u32s, NONE};
use crate::field::Field;
use crate::lattice::{edge_crossing, Lattice};
use crate::mesh::Mesh;
use crate::polygonize::bits::set_bits;
use crate::polygonize::cell::Edge;
use crate::polygonize::{CaseTable, Stats};
use glam::DVec3;
use rayon::prelude::*;
use std::sync::atomic::Ordering::Relaxed;
use std::time::Instant;

impl<F: Field + ?Sized> Run<'_, F> {
    /// The mesh of the crossed `leaves` (without normals), its vertices' edge keys when
    /// `keyed` (else none), and the run's stats; everything else the run holds is dropped
    /// first.
    pub(super) fn triangulate(
        mut self,
        leaves: Vec<CrossedLeaf>,
        keyed: bool,
    ) -> (Mesh, Vec<u64>, Stats) {
        self.stats.cells_crossed = leaves.len() as u64;
        let t = Instant::now();
        let values = std::mem::take(&mut self.store.values);
        let (table, lattice) = (self.table, self.lattice);
        let mut stats = std::mem::take(&mut self.stats);
        drop(self);
        let (mesh, keys) = triangulate(table, lattice, &values, &leaves, keyed);
        drop((values, leaves));
        stats.add_time("triangulate", t);
        (mesh, keys, stats)
    }
}

/// The triangles of the crossed leaves, with a vertex on each crossed edge, made in parallel
/// but numbered as the serial loop over the leaves would number them: each edge vertex in the
/// order of its first use (by leaf, then triangle, then edge). The first leaf that uses an edge
/// (found with `fetch_min` on the edge's entry, keyed by the value index of its lower end and
/// its axis) makes its vertex; the leaves' counts of vertices made give where each leaf's
/// vertices start. With `keyed`, also each vertex's edge key, in the same order.
fn triangulate(
    table: &CaseTable,
    lattice: &Lattice,
    values: &[f64],
    leaves: &[CrossedLeaf],
    keyed: bool,
) -> (Mesh, Vec<u64>) {
    // The cell edges each case's triangles use.
    let used: [u16; 256] = std::array::from_fn(|c| {
        table
            .triangles(c as u8)
            .iter()
            .flatten()
            .fold(0, |m, &e| m | 1 << e)
    });
    let key =
        |l: &CrossedLeaf, e: Edge| 3 * l.corners[e.lower().index()] as usize + e.axis().index();
    // Per edge: the first leaf that uses it, then (once the leaves have their vertices) its
    // vertex.
    let mut entries = vec![NONE; 3 * values.len()];
    let entry = atomic_u32s(&mut entries);
    leaves
        .par_iter()
        .enumerate()
        .with_min_len(1024)
        .for_each(|(i, l)| {
            let i = i as u32;
            for e in set_bits(used[l.case as usize]) {
                let a = &entry[key(l, Edge::new(e))];
                if a.load(Relaxed) > i {
                    a.fetch_min(i, Relaxed);
                }
            }
        });
    // The edges each leaf makes the vertex of.
    let makes: Vec<u16> = leaves
        .par_iter()
        .enumerate()
        .with_min_len(1024)
        .map(|(i, l)| {
            set_bits(used[l.case as usize])
                .filter(|&e| entry[key(l, Edge::new(e))].load(Relaxed) == i as u32)
                .fold(0, |made, e| made | 1 << e)
        })
        .collect();
    // Where each leaf's vertices start, and how many vertices and triangles each makes.
    let mut start = Vec::with_capacity(leaves.len());
    let mut made_count = Vec::with_capacity(leaves.len());
    let mut n = 0u32;
    for m in &makes {
        start.push(n);
        made_count.push(m.count_ones());
        n += m.count_ones();
    }
    let triangle_count: Vec<u32> = leaves
        .iter()
        .map(|l| table.triangles(l.case).len() as u32)
        .collect();
    // The edges of the vertices leaf `i` makes, in order of first use in its triangles.
    let made_order = |i: usize| {
        let (l, made) = (&leaves[i], makes[i]);
        let mut order = [0u8; 12];
        let (mut k, mut left) = (0, made);
        for t in table.triangles(l.case) {
            for &e in t {
                if left & 1 << e != 0 {
                    left &= !(1 << e);
                    order[k] = e;
                    k += 1;
                }
            }
        }
        (order, k)
    };
    let vertices: Vec<DVec3> = crate::memory::collect_counted(&made_count, |i| {
        let (l, first) = (&leaves[i], start[i]);
        let (order, k) = made_order(i);
        for (j, &e) in order[..k].iter().enumerate() {
            entry[key(l, Edge::new(e as usize))].store(first + j as u32, Relaxed);
        }
        (0..k).map(move |j| {
            let [ka, kb] = Edge::new(order[j] as usize).ends();
            let (fa, fb) = (
                values[l.corners[ka.index()] as usize],
                values[l.corners[kb.index()] as usize],
            );
            edge_crossing(
                lattice.point(ka.of_cell(l.origin)),
                lattice.point(kb.of_cell(l.origin)),
                fa,
                fb,
            )
        })
    });
    let triangles: Vec<[u32; 3]> = crate::memory::collect_counted(&triangle_count, |i| {
        let l = &leaves[i];
        table
            .triangles(l.case)
            .iter()
            .map(move |t| t.map(|e| entry[key(l, Edge::new(e as usize))].load(Relaxed)))
    });
    let keys = if keyed {
        crate::memory::collect_counted(&made_count, |i| {
            let (order, k) = made_order(i);
            let o = leaves[i].origin;
            (0..k).map(move |j| {
                let e = Edge::new(order[j] as usize);
                lattice.whole_edge_key(e.lower().of_cell(o), e.axis().into())
            })
        })
    } else {
        Vec::new()
    };
    let mesh = Mesh {
        vertices,
        triangles,
        ..Default::default()
    };
    (mesh, keys)
}
