//! Blending an implicit subdivision with a butterfly subdivision of the same level (Jin §4).

use crate::error::{Error, Result};
use crate::mesh::Mesh;

/// (1 − λ) a + λ b per vertex (Jin §4). Both meshes must have the same triangles and vertex
/// count; λ in [0, 1]. At λ = 0 and λ = 1 the result is exactly `a` and `b`. Normals (when
/// both have them) are blended and renormalised.
pub fn blend(a: &Mesh, b: &Mesh, lam: f64) -> Result<Mesh> {
    if !(lam.is_finite() && (0.0..=1.0).contains(&lam)) {
        return Err(Error::invalid(
            "lam",
            format!("must be in [0, 1], got {lam}"),
        ));
    }
    if a.vertices.len() != b.vertices.len() || a.triangles != b.triangles {
        return Err(Error::invalid(
            "butterfly",
            "must have the same connectivity as the implicit mesh (same subdivision level and \
             control mesh)",
        ));
    }
    if lam == 0.0 {
        return Ok(a.clone());
    }
    if lam == 1.0 {
        return Ok(b.clone());
    }
    let vertices = a
        .vertices
        .iter()
        .zip(&b.vertices)
        .map(|(x, y)| *x * (1.0 - lam) + *y * lam)
        .collect();
    let normals = if a.normals.len() == a.vertices.len() && b.normals.len() == b.vertices.len() {
        a.normals
            .iter()
            .zip(&b.normals)
            .map(|(x, y)| (*x * (1.0 - lam) + *y * lam).normalize_or_zero())
            .collect()
    } else {
        vec![]
    };
    Ok(Mesh {
        vertices,
        triangles: a.triangles.clone(),
        normals,
    })
}
