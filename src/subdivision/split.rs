//! The 1-to-4 midpoint split every level starts from.

use crate::mesh::Mesh;

/// 1-to-4 midpoint subdivision: one new vertex at the midpoint of every edge (shared by the
/// faces on both sides), appended after the old vertices, which keep their indices. Each
/// triangle `[a, b, c]` becomes `[a, ab, ca]`, `[ab, b, bc]`, `[ca, bc, c]`, `[ab, bc, ca]`, so
/// the orientation is kept. Boundary edges get a midpoint like any other.
///
/// Returns the new mesh (without normals) and, for every new vertex in order, the two old
/// vertices of its parent edge (smaller index first). Indices must be in range (see
/// [`check_mesh`](super::check_mesh)).
pub fn split(mesh: &Mesh) -> (Mesh, Vec<[u32; 2]>) {
    let n = mesh.vertices.len() as u32;
    // Edges filed under their smaller vertex: a slot per triangle side in CSR order, of which
    // each vertex uses as many as it has distinct larger neighbours, searched linearly (a vertex
    // has few), so no hashing. New vertices are numbered in the order their edges are met.
    let mut first = vec![0u32; mesh.vertices.len() + 1];
    for t in &mesh.triangles {
        for e in 0..3 {
            first[t[e].min(t[(e + 1) % 3]) as usize + 1] += 1;
        }
    }
    for v in 0..mesh.vertices.len() {
        first[v + 1] += first[v];
    }
    let mut used = vec![0u32; mesh.vertices.len()];
    // (larger vertex, new vertex) per slot.
    let mut slots = vec![(0u32, 0u32); mesh.triangles.len() * 3];
    let mut parents: Vec<[u32; 2]> = Vec::with_capacity(mesh.triangles.len() * 3 / 2 + 3);
    let mut triangles = Vec::with_capacity(mesh.triangles.len() * 4);
    for t in &mesh.triangles {
        let mut mid = [0u32; 3];
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            let (lo, hi) = (a.min(b), a.max(b));
            let base = first[lo as usize] as usize;
            let list = &mut slots[base..base + used[lo as usize] as usize];
            mid[e] = match list.iter().find(|s| s.0 == hi) {
                Some(&(_, m)) => m,
                None => {
                    let m = n + parents.len() as u32;
                    parents.push([lo, hi]);
                    slots[base + used[lo as usize] as usize] = (hi, m);
                    used[lo as usize] += 1;
                    m
                }
            };
        }
        let [a, b, c] = *t;
        let [ab, bc, ca] = mid;
        triangles.push([a, ab, ca]);
        triangles.push([ab, b, bc]);
        triangles.push([ca, bc, c]);
        triangles.push([ab, bc, ca]);
    }
    let mut vertices = Vec::with_capacity(mesh.vertices.len() + parents.len());
    vertices.extend_from_slice(&mesh.vertices);
    vertices.extend(
        parents
            .iter()
            .map(|&[a, b]| 0.5 * (mesh.vertices[a as usize] + mesh.vertices[b as usize])),
    );
    (
        Mesh {
            vertices,
            triangles,
            normals: vec![],
        },
        parents,
    )
}
