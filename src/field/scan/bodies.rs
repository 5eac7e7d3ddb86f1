//! Bodies of a polygonized scan fit that its data disowns.
//!
//! Near a stray point the cleaning kept, or a normal it did not correct, the fit may close a
//! small bubble (a body outside the data's surface) or a void (inside it). The data's
//! [`WindingNumber`](super::WindingNumber) tells them from the surface it samples: across a
//! true surface it falls from about 1 inside to about 0 outside, while around a bubble it is
//! about 0 on both sides and around a void about 1. A body is disowned when, at vertices within
//! the guard's `near` band of the data, the median of
//!
//! ```text
//! w(v − ε n) − w(v + ε n),    ε = OFFSET · spacing, n the body's outward vertex normal,
//! ```
//!
//! is below ½. A body without such vertices lies where the winding number alone makes the field
//! and is its surface; the body with the most triangles is never disowned.

use super::guard::Guard;
use crate::mesh::{Bodies, Mesh};
use rayon::prelude::*;

/// The offset on either side of a vertex, in spacings.
pub const OFFSET: f64 = 1.5;
/// Vertices of a body looked at for their distance to the data.
const CANDIDATES: usize = 512;
/// Vertices of a body near the data whose winding numbers decide.
const SAMPLES: usize = 64;

/// Whether each vertex of `mesh` is kept (used by a triangle of a body its data owns), and the
/// number of bodies disowned.
pub fn owned_vertices(guard: &Guard, mesh: &Mesh) -> (Vec<bool>, usize) {
    let bodies = mesh.bodies();
    let drop = disowned(guard, mesh, &bodies);
    let keep = bodies
        .of_vertex
        .iter()
        .map(|&b| b != Bodies::UNUSED && !drop[b as usize])
        .collect();
    (keep, drop.iter().filter(|d| **d).count())
}

/// Whether each body of `mesh` (numbered as in `bodies`, the mesh's [`Mesh::bodies`]) is
/// disowned by the data of `guard` (see the module's documentation).
pub fn disowned(guard: &Guard, mesh: &Mesh, bodies: &Bodies) -> Vec<bool> {
    let count = bodies.count();
    if count <= 1 {
        return vec![false; count];
    }
    let normals = mesh.face_normals_at_vertices();
    let samples = samples(guard, mesh, bodies);
    let eps = OFFSET * guard.spacing();
    let largest = (0..count).max_by_key(|&b| bodies.triangles[b]).unwrap_or(0);
    (0..count)
        .into_par_iter()
        .map(|b| {
            if b == largest || samples[b].is_empty() {
                return false;
            }
            let mut drops: Vec<f64> = samples[b]
                .iter()
                .map(|&v| {
                    let (p, n) = (mesh.vertices[v as usize], normals[v as usize]);
                    guard.winding().value(p - eps * n) - guard.winding().value(p + eps * n)
                })
                .collect();
            let mid = drops.len() / 2;
            *drops.select_nth_unstable_by(mid, f64::total_cmp).1 < 0.5
        })
        .collect()
}

/// Per body, up to [`SAMPLES`] of its vertices within the guard's `near` band of the data, spread
/// over its vertices in index order.
fn samples(guard: &Guard, mesh: &Mesh, bodies: &Bodies) -> Vec<Vec<u32>> {
    let mut members: Vec<Vec<u32>> = vec![Vec::new(); bodies.count()];
    for (v, &b) in bodies.of_vertex.iter().enumerate() {
        if b != Bodies::UNUSED {
            members[b as usize].push(v as u32);
        }
    }
    let near = guard.bands().0;
    members
        .into_par_iter()
        .map(|m| {
            let near_data: Vec<u32> = spread(&m, CANDIDATES)
                .filter(|&v| guard.distance_to_data(mesh.vertices[v as usize]) <= near)
                .collect();
            spread(&near_data, SAMPLES).collect()
        })
        .collect()
}

/// At most `k` of `items`, evenly spread.
fn spread(items: &[u32], k: usize) -> impl Iterator<Item = u32> + '_ {
    let step = items.len().div_ceil(k).max(1);
    items.iter().copied().step_by(step)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::scan::{surface::guard_of, Guarded, ScanSettings};
    use crate::field::Field;
    use crate::lattice::Lattice;
    use crate::polygonize::octree;
    use crate::testing::fibonacci_sphere;
    use glam::DVec3;
    use std::sync::Arc;

    /// The unit sphere with a bubble of radius `r` around `bubble` (outside the sphere) and a
    /// void of radius `r` around `void` (inside it): the stray bodies a fit may leave.
    #[derive(Clone)]
    struct WithStrays {
        bubble: DVec3,
        void: DVec3,
        r: f64,
    }

    impl Field for WithStrays {
        fn value(&self, p: DVec3) -> f64 {
            let sphere = p.length() - 1.0;
            let bubble = (p - self.bubble).length() - self.r;
            let void = self.r - (p - self.void).length();
            sphere.min(bubble).max(void)
        }
        fn gradient(&self, p: DVec3) -> DVec3 {
            let h = 1e-6;
            let e = |v: DVec3| (self.value(p + v) - self.value(p - v)) / (2.0 * h);
            DVec3::new(e(DVec3::X * h), e(DVec3::Y * h), e(DVec3::Z * h))
        }
    }

    #[test]
    fn bubbles_and_voids_are_disowned_and_the_sphere_kept() {
        let n = 6_000;
        let p = fibonacci_sphere(n);
        let area = 4.0 * std::f64::consts::PI / n as f64;
        let spacing = 2.0 * area.sqrt();
        let guard = guard_of(
            p.clone(),
            p,
            vec![area; n],
            spacing,
            &ScanSettings::default(),
        )
        .unwrap();
        let fit = WithStrays {
            bubble: DVec3::new(0.0, 0.0, 1.0 + 2.5 * spacing),
            void: DVec3::new(0.0, 0.6, 0.0),
            r: 1.5 * spacing,
        };
        let field = Guarded::new(fit, Arc::new(guard));
        let lattice = Lattice::new(DVec3::splat(-1.3), DVec3::splat(1.3), [64, 64, 64]).unwrap();
        let mesh = octree::polygonize(&field, &lattice, &octree::OctreeSettings::default())
            .unwrap()
            .mesh;
        let bodies = mesh.bodies();
        assert_eq!(bodies.count(), 3, "the sphere, the bubble and the void");
        let (keep, dropped) = owned_vertices(field.guard(), &mesh);
        assert_eq!(dropped, 2);
        for (v, k) in mesh.vertices.iter().zip(&keep) {
            assert_eq!(*k, (v.length() - 1.0).abs() < 0.02, "vertex {v}");
        }
    }
}
