//! Stray fragments of a particle surface: the bodies (connected components) of a mesh, how many
//! particles each holds, and which to drop because they hold fewer than a given number.
//!
//! A particle belongs to the body of the mesh vertex nearest to it (particles lie inside their
//! own body, whose surface is nearer to them than any other's unless two bodies nearly touch).

use crate::error::{Error, Result};
use crate::knn::PointTree;
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

/// The body of each vertex, numbered from 0 in order of first vertex, and the number of bodies
/// (union–find over the triangles' edges; a vertex in no triangle is a body of its own).
pub fn bodies(vertices: usize, faces: &[[u32; 3]]) -> (Vec<u32>, usize) {
    let mut parent: Vec<u32> = (0..vertices as u32).collect();
    fn root(parent: &mut [u32], mut v: u32) -> u32 {
        while parent[v as usize] != v {
            let up = parent[parent[v as usize] as usize];
            parent[v as usize] = up;
            v = up;
        }
        v
    }
    for f in faces {
        let a = root(&mut parent, f[0]);
        for &v in &f[1..] {
            let b = root(&mut parent, v);
            if a != b {
                parent[b as usize] = a;
            }
        }
    }
    let mut label = vec![u32::MAX; vertices];
    let mut body = vec![0u32; vertices];
    let mut count = 0usize;
    for v in 0..vertices as u32 {
        let r = root(&mut parent, v) as usize;
        if label[r] == u32::MAX {
            label[r] = count as u32;
            count += 1;
        }
        body[v as usize] = label[r];
    }
    (body, count)
}

/// The bodies of the mesh (`vertices`, `faces`) holding fewer than `min_particles` of
/// `particles` (see the module docs). Errors naming `faces` for an index that is no vertex.
pub fn small_bodies(
    vertices: &[DVec3],
    faces: &[[u32; 3]],
    particles: &[DVec3],
    min_particles: usize,
) -> Result<Fragments> {
    if let Some(f) = faces
        .iter()
        .find(|f| f.iter().any(|&v| v as usize >= vertices.len()))
    {
        return Err(Error::invalid(
            "faces",
            format!("{f:?} names a vertex past the {} vertices", vertices.len()),
        ));
    }
    let (body, count) = bodies(vertices.len(), faces);
    let mut held = vec![0usize; count];
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
            held[b as usize] += 1;
        }
    }
    let dropped: Vec<bool> = held.iter().map(|&h| h < min_particles).collect();
    Ok(Fragments {
        keep: body.iter().map(|&b| !dropped[b as usize]).collect(),
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
        let r = small_bodies(&v, &faces, &p, 3).unwrap();
        assert_eq!((r.bodies, r.particles), (1, 2));
        assert_eq!(r.keep, [true, true, true, true, false, false, false, false]);
        let r = small_bodies(&v, &faces, &p, 2).unwrap();
        assert_eq!((r.bodies, r.particles), (0, 0));
        assert!(small_bodies(&v, &[[0, 1, 9]], &p, 2).is_err());
    }
}
