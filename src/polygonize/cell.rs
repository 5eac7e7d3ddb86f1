//! Triangulating one cell from its eight corner values with the shared case table. Every
//! polygonizer goes through [`case_index`] and [`emit_triangles`], and places edge vertices with
//! [`crate::lattice::edge_crossing`] from the edge's lower end, so their triangles coincide.

use super::table::{CaseTable, EDGES, EDGE_AXIS};

/// Case index of a cell: bit k set when corner k is inside (value < 0).
#[inline]
pub fn case_index(values: &[f64; 8]) -> u8 {
    let mut c = 0u8;
    for (k, v) in values.iter().enumerate() {
        if *v < 0.0 {
            c |= 1 << k;
        }
    }
    c
}

/// A corner of a cell, numbered as the case table numbers them: bits 0, 1 and 2 of its index
/// are its offset from the cell's lowest corner along x, y and z (and the bit of the case index
/// it sets). Octants of a cube, and children of an octree cell, are numbered the same way.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Corner(u8);

impl Corner {
    /// The eight corners in index order.
    pub const ALL: [Corner; 8] = [
        Corner(0),
        Corner(1),
        Corner(2),
        Corner(3),
        Corner(4),
        Corner(5),
        Corner(6),
        Corner(7),
    ];

    /// Corner `k` (below 8).
    #[inline]
    pub fn new(k: usize) -> Corner {
        debug_assert!(k < 8);
        Corner(k as u8)
    }

    /// Its index, 0 to 7.
    #[inline]
    pub fn index(self) -> usize {
        self.0 as usize
    }

    /// Its offset in lattice points from the cell's lowest corner (0 or 1 per axis, as in
    /// [`CORNERS`](super::table::CORNERS)).
    #[inline]
    pub fn offset(self) -> [u32; 3] {
        let k = self.0 as u32;
        [k & 1, (k >> 1) & 1, (k >> 2) & 1]
    }

    /// This corner of the cell whose lowest corner is lattice point `o`.
    #[inline]
    pub fn of_cell(self, o: [u32; 3]) -> [u32; 3] {
        let d = self.offset();
        [o[0] + d[0], o[1] + d[1], o[2] + d[2]]
    }

    /// This corner of the cube of `s` cells per side whose lowest corner is lattice point `o`.
    #[inline]
    pub fn of_cube(self, o: [u32; 3], s: u32) -> [u32; 3] {
        let d = self.offset();
        [o[0] + d[0] * s, o[1] + d[1] * s, o[2] + d[2] * s]
    }
}

/// An edge of a cell, numbered as the case table numbers them ([`EDGES`]): 0 to 3 along x, 4
/// to 7 along y, 8 to 11 along z.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Edge(u8);

impl Edge {
    /// The twelve edges in index order.
    pub const ALL: [Edge; 12] = [
        Edge(0),
        Edge(1),
        Edge(2),
        Edge(3),
        Edge(4),
        Edge(5),
        Edge(6),
        Edge(7),
        Edge(8),
        Edge(9),
        Edge(10),
        Edge(11),
    ];

    /// Edge `e` (below 12).
    #[inline]
    pub fn new(e: usize) -> Edge {
        debug_assert!(e < 12);
        Edge(e as u8)
    }

    /// Its index, 0 to 11.
    #[inline]
    pub fn index(self) -> usize {
        self.0 as usize
    }

    /// Its two corners, the lower along its axis first.
    #[inline]
    pub fn ends(self) -> [Corner; 2] {
        EDGES[self.0 as usize].map(Corner)
    }

    /// Its lower corner along its axis.
    #[inline]
    pub fn lower(self) -> Corner {
        Corner(EDGES[self.0 as usize][0])
    }

    /// The axis it runs along.
    #[inline]
    pub fn axis(self) -> Axis {
        Axis(EDGE_AXIS[self.0 as usize])
    }
}

/// An axis of the lattice: 0 = x, 1 = y, 2 = z.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Axis(u8);

impl Axis {
    /// Its index, 0 to 2.
    #[inline]
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

impl From<Axis> for u8 {
    /// The axis as the lattice's edge keys hold it ([`crate::lattice::Lattice::edge_key`]).
    #[inline]
    fn from(a: Axis) -> u8 {
        a.0
    }
}

/// Appends the triangles of `case` to `out`, mapping each cell edge to a vertex index with
/// `vertex_of_edge`.
#[inline]
pub fn emit_triangles(
    table: &CaseTable,
    case: u8,
    mut vertex_of_edge: impl FnMut(Edge) -> u32,
    out: &mut Vec<[u32; 3]>,
) {
    for t in table.triangles(case) {
        out.push([
            vertex_of_edge(Edge(t[0])),
            vertex_of_edge(Edge(t[1])),
            vertex_of_edge(Edge(t[2])),
        ]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::polygonize::table::CORNERS;

    /// The corners' offsets are the table's, and each edge joins its lower corner to the
    /// corner one step along its axis.
    #[test]
    fn corners_and_edges_agree_with_the_table() {
        for k in Corner::ALL {
            assert_eq!(k.offset(), CORNERS[k.index()].map(u32::from));
            assert_eq!(Corner::new(k.index()), k);
        }
        for e in Edge::ALL {
            let [a, b] = e.ends();
            assert_eq!(a, e.lower());
            let mut up = a.offset();
            up[e.axis().index()] += 1;
            assert_eq!(b.offset(), up);
            assert_eq!(e.index() / 4, e.axis().index());
        }
    }
}
