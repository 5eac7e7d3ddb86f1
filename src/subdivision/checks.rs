//! Checks before subdividing: the control mesh ([`check_mesh`]) and the level count against
//! [`MAX_LEVELS`] and the memory limit.

use crate::error::{check_finite_points, Error, Result};
use crate::mesh::Mesh;
use std::collections::HashMap;

/// Most subdivision levels accepted (each multiplies the triangles by four).
pub const MAX_LEVELS: usize = 8;

/// Bytes per triangle of the finest level, counting its share of the vertices, normals and the
/// coarser levels kept alongside it.
const BYTES_PER_TRIANGLE: u64 = 96;

/// Checks that `mesh` can be subdivided: finite vertices, at least one triangle, indices in
/// range, no triangle repeating a vertex, no edge shared by more than two triangles, and two
/// triangles sharing an edge traverse it in opposite directions (consistent orientation).
pub fn check_mesh(mesh: &Mesh) -> Result<()> {
    check_finite_points("vertices", &mesh.vertices)?;
    if mesh.triangles.is_empty() {
        return Err(Error::invalid("faces", "the mesh has no faces"));
    }
    if mesh.vertices.len() > u32::MAX as usize / 2 {
        return Err(Error::invalid("vertices", "too many vertices"));
    }
    let n = mesh.vertices.len();
    let mut uses: HashMap<(u32, u32), (u32, u32)> =
        HashMap::with_capacity(mesh.triangles.len() * 2);
    for (k, t) in mesh.triangles.iter().enumerate() {
        if let Some(&bad) = t.iter().find(|&&v| v as usize >= n) {
            return Err(Error::invalid(
                "faces",
                format!("face {k} refers to vertex {bad}, but there are {n} vertices"),
            ));
        }
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            return Err(Error::invalid(
                "faces",
                format!("face {k} repeats a vertex: {t:?}"),
            ));
        }
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            let u = uses.entry((a.min(b), a.max(b))).or_default();
            if a < b {
                u.0 += 1;
            } else {
                u.1 += 1;
            }
            if u.0 + u.1 > 2 {
                return Err(Error::invalid(
                    "faces",
                    format!("edge ({a}, {b}) is shared by more than two faces (non-manifold)"),
                ));
            }
            if u.0 > 1 || u.1 > 1 {
                return Err(Error::invalid(
                    "faces",
                    format!(
                        "edge ({a}, {b}) is traversed twice in the same direction: faces are not \
                         consistently oriented"
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Checks that `levels` is at most [`MAX_LEVELS`] and that the finest level of `mesh` fits in
/// `memory_limit` bytes (errors name `levels`).
pub(super) fn check_levels(mesh: &Mesh, levels: usize, memory_limit: u64) -> Result<()> {
    if levels > MAX_LEVELS {
        return Err(Error::invalid(
            "levels",
            format!("must be at most {MAX_LEVELS}, got {levels}"),
        ));
    }
    let faces = (mesh.triangles.len() as u64).saturating_mul(1u64 << (2 * levels));
    let bytes = faces.saturating_mul(BYTES_PER_TRIANGLE);
    if bytes > memory_limit || faces > u32::MAX as u64 / 2 {
        return Err(Error::TooMuchMemory {
            name: "levels",
            needed_mib: bytes.div_ceil(1 << 20),
            limit_mib: memory_limit >> 20,
        });
    }
    Ok(())
}

/// Vertices of level `levels` of the subdivision of `mesh` (the count [`subdivide`] and
/// [`butterfly`] report as progress): level `k + 1` adds one vertex per edge of level `k`, whose
/// edges are twice its own plus three per face. Indices must be in range (see [`check_mesh`]).
///
/// [`subdivide`]: super::subdivide
/// [`butterfly`]: super::butterfly
pub fn vertex_count(mesh: &Mesh, levels: usize) -> u64 {
    let mut edges: Vec<(u32, u32)> = mesh
        .triangles
        .iter()
        .flat_map(|t| (0..3).map(move |e| (t[e].min(t[(e + 1) % 3]), t[e].max(t[(e + 1) % 3]))))
        .collect();
    edges.sort_unstable();
    edges.dedup();
    let (mut v, mut e, mut f) = (
        mesh.vertices.len() as u64,
        edges.len() as u64,
        mesh.triangles.len() as u64,
    );
    for _ in 0..levels {
        (v, e, f) = (v + e, 2 * e + 3 * f, 4 * f);
    }
    v
}
