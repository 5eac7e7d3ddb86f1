//! Projection of a mesh's vertices onto the zero set ([`Settings::project`]).
//!
//! Marching cubes puts each vertex where the straight line between an edge's two corner values
//! crosses zero. Where the field curves along the edge, the true crossing lies elsewhere, by up
//! to a fraction of the cell; that error, not the flatness of the triangles, dominates the
//! distance from a fine mesh to the surface. One Newton step along the gradient,
//!
//! ```text
//! x ← x − f(x) ∇f(x) / |∇f(x)|²
//! ```
//!
//! removes it to second order. The step is shortened to at most half the lattice's smallest
//! cell side, so a vertex stays near its cell, and a vertex where the gradient vanishes stays
//! where it is. The faces are unchanged. Each vertex moves on its
//! own position alone, so meshes that share vertices (the polygonizers' meshes of one lattice,
//! or tiles of it) share the projected ones too.

use super::{Settings, Stats};
use crate::error::{Error, Result};
use crate::field::Field;
use crate::lattice::Lattice;
use crate::mesh::Mesh;
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

/// The largest step of the projection, as a fraction of the lattice's smallest cell side.
pub const MAX_STEP_OVER_CELL: f64 = 0.5;

/// Moves every vertex of `mesh` by one bounded Newton step onto the zero set of `field` when
/// `settings.project` is set (see the module documentation); counts the field values it uses in
/// `stats.projection_evaluations`.
pub fn project_vertices<F: Field + ?Sized>(
    field: &F,
    mesh: &mut Mesh,
    lattice: &Lattice,
    settings: &Settings,
    stats: &mut Stats,
) -> Result<()> {
    if !settings.project || mesh.vertices.is_empty() {
        return Ok(());
    }
    let t = Instant::now();
    let max_step = MAX_STEP_OVER_CELL * lattice.cell().min_element();
    let per_vertex = 1 + field.values_per_gradient();
    let batch = (settings.batch / per_vertex as usize).max(1);
    let mut values = vec![0.0; batch.min(mesh.vertices.len())];
    let mut gradients = vec![DVec3::ZERO; values.len()];
    for chunk in mesh.vertices.chunks_mut(batch) {
        let (f, g) = (&mut values[..chunk.len()], &mut gradients[..chunk.len()]);
        super::evaluate(field, chunk, f, chunk.len())?;
        crate::cancel::check()?;
        field.gradients(chunk, g);
        crate::cancel::advance(field.values_per_gradient() * chunk.len() as u64)?;
        if let Some(i) = g.iter().position(|v| !v.is_finite()) {
            let p = chunk[i];
            return Err(Error::FieldNotFinite {
                x: p.x,
                y: p.y,
                z: p.z,
            });
        }
        chunk
            .par_iter_mut()
            .zip(f.par_iter())
            .zip(g.par_iter())
            .for_each(|((x, &fx), &gx)| *x += newton_step(fx, gx, max_step));
    }
    stats.projection_evaluations += per_vertex * mesh.vertices.len() as u64;
    stats.add_time("project", t);
    Ok(())
}

/// −f ∇f / |∇f|², shortened to `max_step`; zero where the gradient vanishes.
fn newton_step(f: f64, g: DVec3, max_step: f64) -> DVec3 {
    let gg = g.length_squared();
    if gg == 0.0 || f == 0.0 {
        return DVec3::ZERO;
    }
    let step = g * (-f / gg);
    let length = step.length();
    if length > max_step {
        step * (max_step / length)
    } else {
        step
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::polygonize::dense;

    /// A sphere of radius 0.6 whose field is far from a distance: f = |x|⁴ − 0.6⁴.
    struct Quartic;
    impl Field for Quartic {
        fn value(&self, p: DVec3) -> f64 {
            p.length_squared().powi(2) - 0.6f64.powi(4)
        }
        fn gradient(&self, p: DVec3) -> DVec3 {
            p * (4.0 * p.length_squared())
        }
    }

    fn radial_error(m: &Mesh) -> f64 {
        m.vertices
            .iter()
            .map(|v| (v.length() - 0.6).abs())
            .fold(0.0, f64::max)
    }

    #[test]
    fn projection_moves_vertices_onto_the_zero_set() {
        let lattice = Lattice::new(DVec3::splat(-1.0), DVec3::splat(1.0), [24; 3]).unwrap();
        let plain = dense::polygonize(&Quartic, &lattice, &Settings::default()).unwrap();
        let settings = Settings {
            project: true,
            ..Default::default()
        };
        let crate::polygonize::Polygonized {
            mesh: projected,
            stats,
            ..
        } = dense::polygonize(&Quartic, &lattice, &settings).unwrap();
        assert_eq!(plain.mesh.triangles, projected.triangles);
        let (before, after) = (radial_error(&plain.mesh), radial_error(&projected));
        assert!(before > 1e-3, "{before}");
        assert!(after < before / 20.0, "{before} -> {after}");
        assert_eq!(
            stats.projection_evaluations,
            2 * projected.vertices.len() as u64
        );
        // Normals are the gradient's at the projected vertices.
        for (v, n) in projected.vertices.iter().zip(&projected.normals) {
            assert!((*n - v.normalize()).length() < 1e-12);
        }
    }

    #[test]
    fn steps_are_bounded_and_vanishing_gradients_keep_the_vertex() {
        let s = newton_step(10.0, DVec3::new(0.0, 0.0, 1.0), 0.25);
        assert_eq!(s, DVec3::new(0.0, 0.0, -0.25));
        assert_eq!(newton_step(1.0, DVec3::ZERO, 0.25), DVec3::ZERO);
        let s = newton_step(0.01, DVec3::new(2.0, 0.0, 0.0), 0.25);
        assert_eq!(s, DVec3::new(-0.005, 0.0, 0.0));
    }
}
