//! Stray fragments of a particle surface: the bodies (connected components) of a mesh, how many
//! particles each holds, and which to drop because they hold fewer than a given number.
//!
//! A particle belongs to the body of the mesh vertex nearest to it (particles lie inside their
//! own body, whose surface is nearer to them than any other's unless two bodies nearly touch).

use crate::error::{Error, Result};
use crate::knn::PointTree;
use crate::mesh::{Bodies, Mesh};
use glam::DVec3;
use rayon::prelude::*;

/// What [`small_bodies`] found: the vertices to keep, and the bodies and particles dropped.
#[derive(Clone, Debug, PartialEq)]
pub struct Fragments {
    /// One flag per vertex: false for the vertices of a dropped body.
    pub keep: Vec<bool>,
    /// The bodies dropped.
    pub bodies: usize,
    /// The particles they held.
    pub particles: usize,
}

/// The bodies of `mesh` ([`Mesh::bodies`]) holding fewer than `min_particles` of `particles`
/// (see the module docs). Errors naming `faces` for an index that is no vertex.
pub fn small_bodies(mesh: &Mesh, particles: &[DVec3], min_particles: usize) -> Result<Fragments> {
    let vertices = &mesh.vertices;
    if let Some(f) = mesh
        .triangles
        .iter()
        .find(|f| f.iter().any(|&v| v as usize >= vertices.len()))
    {
        return Err(Error::invalid(
            "faces",
            format!("{f:?} names a vertex past the {} vertices", vertices.len()),
        ));
    }
    let bodies = mesh.bodies();
    let body = &bodies.of_vertex;
    let mut held = vec![0usize; bodies.count()];
    if !vertices.is_empty() && !particles.is_empty() {
        let tree = PointTree::new(vertices)?;
        let nearest: Vec<u32> = particles
            .par_iter()
            .map(|&p| {
                let mut out = [(0.0, 0u32)];
                tree.k_nearest_into(p, &mut out);
                body[out[0].1 as usize]
            })
            .collect();
        for b in nearest {
            if b != Bodies::UNUSED {
                held[b as usize] += 1;
            }
        }
    }
    let dropped: Vec<bool> = held.iter().map(|&h| h < min_particles).collect();
    Ok(Fragments {
        keep: body
            .iter()
            .map(|&b| b != Bodies::UNUSED && !dropped[b as usize])
            .collect(),
        bodies: dropped.iter().filter(|&&d| d).count(),
        particles: held
            .iter()
            .zip(&dropped)
            .filter(|(_, &d)| d)
            .map(|(h, _)| h)
            .sum(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two tetrahedra: a big body near 10 particles and a small one near 2.
    #[test]
    fn drops_the_body_with_few_particles() {
        let tet = |o: DVec3| [o, o + DVec3::X, o + DVec3::Y, o + DVec3::Z];
        let mut v = tet(DVec3::ZERO).to_vec();
        v.extend(tet(DVec3::splat(10.0)));
        let f = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let faces: Vec<[u32; 3]> = f
            .iter()
            .chain(&f)
            .enumerate()
            .map(|(k, t)| t.map(|i| i + if k >= 4 { 4 } else { 0 }))
            .collect();
        let mut p = vec![DVec3::splat(0.2); 10];
        p.extend([DVec3::splat(10.2); 2]);
        let mesh = Mesh {
            vertices: v.to_vec(),
            triangles: faces,
            normals: Vec::new(),
        };
        let r = small_bodies(&mesh, &p, 3).unwrap();
        assert_eq!((r.bodies, r.particles), (1, 2));
        assert_eq!(r.keep, [true, true, true, true, false, false, false, false]);
        let r = small_bodies(&mesh, &p, 2).unwrap();
        assert_eq!((r.bodies, r.particles), (0, 0));
        let bad = Mesh {
            triangles: vec![[0, 1, 9]],
            ..mesh
        };
        assert!(small_bodies(&bad, &p, 2).is_err());
    }
}
