//! Triangulating one cell from its eight corner values with the shared case table. Every
//! polygonizer goes through [`case_index`] and [`emit_triangles`], and places edge vertices with
//! [`crate::lattice::edge_crossing`] from the edge's lower end, so their triangles coincide.

use super::table::{CaseTable, CORNERS, EDGES, EDGE_AXIS};

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

/// Lattice point offset of corner `k` of a cell.
#[inline]
pub fn corner_offset(k: usize) -> [u32; 3] {
    let c = CORNERS[k];
    [c[0] as u32, c[1] as u32, c[2] as u32]
}

/// Lower corner offset and axis of cell edge `e`.
#[inline]
pub fn edge_origin(e: usize) -> ([u32; 3], u8) {
    (corner_offset(EDGES[e][0] as usize), EDGE_AXIS[e])
}

/// Appends the triangles of `case` to `out`, mapping each cell edge to a vertex index with
/// `vertex_of_edge`.
#[inline]
pub fn emit_triangles(
    table: &CaseTable,
    case: u8,
    mut vertex_of_edge: impl FnMut(usize) -> u32,
    out: &mut Vec<[u32; 3]>,
) {
    for t in table.triangles(case) {
        out.push([
            vertex_of_edge(t[0] as usize),
            vertex_of_edge(t[1] as usize),
            vertex_of_edge(t[2] as usize),
        ]);
    }
}
