//! Subdivision onto the implicit surface (Jin et al. §3): the level loop of [`subdivide`], the
//! start point of each new vertex and the normals from the field's gradients.

use super::checks::{check_levels, check_mesh};
use super::evaluator::Evaluator;
use super::projection::{project, Projection};
use super::settings::{LevelStats, SubdivisionSettings};
use super::split::split;
use crate::error::Result;
use crate::field::Field;
use crate::mesh::Mesh;
use glam::DVec3;
use std::time::Instant;

/// Newton's start point for the new vertex of edge `ab` (both ends on the surface, unit normals
/// `na`, `nb`): the middle of the cubic Hermite curve from `a` to `b` whose end tangents are the
/// edge projected into the two tangent planes, `(a + b) / 2 + c` with
/// `c = ((e·nb) nb − (e·na) na) / 8` and `e = b − a`, less the part of `c` along the edge (which
/// would slide the vertex towards one end where the two ends curve differently), so the start
/// stays in the plane through the midpoint perpendicular to the edge. On a circle of radius R
/// its distance to the curve is about 0.375 h⁴ / R³ for half edge h, against h² / 2R for the flat
/// midpoint, so Newton starts much closer. The correction is at most |e| / 4; without both
/// normals (a vanishing gradient) or for a degenerate edge, the flat midpoint is used.
pub(super) fn hermite_midpoint(a: DVec3, b: DVec3, na: DVec3, nb: DVec3) -> DVec3 {
    let mid = 0.5 * (a + b);
    let e = b - a;
    let e2 = e.length_squared();
    if na == DVec3::ZERO || nb == DVec3::ZERO || !(e2 > 0.0 && e2.is_finite()) {
        return mid;
    }
    let c = (nb * e.dot(nb) - na * e.dot(na)) * 0.125;
    let p = mid + c - e * (c.dot(e) / e2);
    if p.is_finite() {
        p
    } else {
        mid
    }
}

/// Unit normals from gradients, falling back to face normals where the gradient vanishes.
fn normals_from_gradients(mesh: &Mesh, g: &[DVec3]) -> Vec<DVec3> {
    let mut fallback: Option<Vec<DVec3>> = None;
    g.iter()
        .enumerate()
        .map(|(i, gi)| {
            let n = gi.normalize_or_zero();
            if n != DVec3::ZERO {
                n
            } else {
                fallback.get_or_insert_with(|| mesh.face_normals_at_vertices())[i]
            }
        })
        .collect()
}

/// Subdivides `control` `levels` times onto the zero set of `field` (Jin et al. §3): entry `k`
/// of the result is level `k` (entry 0 the control mesh, with normals), each with the stats of
/// its projection. Every Newton step makes one batched [`Field::values_gradients`] call for all
/// the vertices still moving; the fallback calls [`Field::values`]. Evaluations are counted as
/// [`Field::values_per_value_gradient`] says (7 per point for [`Differences`], all of them).
/// Reports every vertex placed to [`crate::cancel::advance`], [`vertex_count`] in all.
///
/// Errors for bad settings, a broken control mesh (see [`check_mesh`]), `levels` over
/// [`MAX_LEVELS`](super::MAX_LEVELS) or over the memory limit, or a field returning
/// NaN/infinity.
///
/// [`Differences`]: crate::field::Differences
/// [`vertex_count`]: super::vertex_count
pub fn subdivide<F: Field + ?Sized>(
    field: &F,
    control: &Mesh,
    levels: usize,
    settings: &SubdivisionSettings,
) -> Result<Vec<(Mesh, LevelStats)>> {
    settings.check()?;
    check_mesh(control)?;
    check_levels(control, levels, settings.memory_limit)?;
    let mut eval = Evaluator::new(field);
    let mut out: Vec<(Mesh, LevelStats)> = Vec::with_capacity(levels + 1);
    let (mut mesh, stats) = control_level(&mut eval, control)?;
    out.push((mesh.clone(), stats));
    for level in 1..=levels {
        crate::cancel::check()?;
        let (next, stats) = next_level(&mut eval, &mesh, level, settings)?;
        // The next level needs normals for its search hints even when they are not wanted.
        let mut kept = next.clone();
        if !settings.normals {
            kept.normals = vec![];
        }
        out.push((kept, stats));
        mesh = next;
    }
    Ok(out)
}

/// The central-difference step for a field that only has values, when none is given:
/// 1e-6 × the largest side of the bounding box of `control`'s vertices (1e-6 for a box of no
/// finite positive size).
pub fn difference_step(control: &Mesh) -> f64 {
    let (lo, hi) = control.vertices.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let side = (hi - lo).max_element();
    1e-6 * if side.is_finite() && side > 0.0 {
        side
    } else {
        1.0
    }
}

/// Level 0: the control mesh with normals from the field, and the largest |f| at its vertices.
fn control_level<F: Field + ?Sized>(
    eval: &mut Evaluator<'_, F>,
    control: &Mesh,
) -> Result<(Mesh, LevelStats)> {
    let t = Instant::now();
    let mut mesh = control.clone();
    let (ev0, b0) = (eval.evaluations, eval.batches);
    let mut v = vec![0.0; mesh.vertices.len()];
    let mut g = vec![DVec3::ZERO; mesh.vertices.len()];
    eval.both(&mesh.vertices, &mut v, &mut g)?;
    mesh.normals = normals_from_gradients(&mesh, &g);
    crate::cancel::advance(mesh.vertices.len() as u64)?;
    let stats = LevelStats {
        level: 0,
        evaluations: eval.evaluations - ev0,
        batches: eval.batches - b0,
        max_abs_value: v.iter().fold(0.0, |a: f64, x| a.max(x.abs())),
        seconds: t.elapsed().as_secs_f64(),
        ..Default::default()
    };
    Ok((mesh, stats))
}

/// Level `level` from the level before, `mesh` (with normals): the split, each new vertex
/// projected from its Hermite midpoint, and normals at every vertex.
fn next_level<F: Field + ?Sized>(
    eval: &mut Evaluator<'_, F>,
    mesh: &Mesh,
    level: usize,
    settings: &SubdivisionSettings,
) -> Result<(Mesh, LevelStats)> {
    let t = Instant::now();
    let (ev0, b0) = (eval.evaluations, eval.batches);
    let old = mesh.vertices.len();
    let (mut next, parents) = split(mesh);
    let scales: Vec<f64> = parents
        .iter()
        .map(|&[a, b]| 0.5 * (mesh.vertices[a as usize] - mesh.vertices[b as usize]).length())
        .collect();
    let hints: Vec<DVec3> = parents
        .iter()
        .map(|&[a, b]| mesh.normals[a as usize] + mesh.normals[b as usize])
        .collect();
    let starts: Vec<DVec3> = parents
        .iter()
        .map(|&[a, b]| {
            let (a, b) = (a as usize, b as usize);
            hermite_midpoint(
                mesh.vertices[a],
                mesh.vertices[b],
                mesh.normals[a],
                mesh.normals[b],
            )
        })
        .collect();
    let proj = project(eval, &starts, &scales, &hints, settings)?;
    next.vertices[old..].copy_from_slice(&proj.points);
    let (v, g) = final_values_gradients(eval, mesh, &proj)?;
    next.normals = normals_from_gradients(&next, &g);
    let it = &proj.iterations;
    let stats = LevelStats {
        level,
        projected: it.len(),
        iterations_mean: it.iter().map(|&x| x as f64).sum::<f64>() / it.len().max(1) as f64,
        iterations_max: it.iter().copied().max().unwrap_or(0),
        evaluations: eval.evaluations - ev0,
        batches: eval.batches - b0,
        fallbacks: proj.fallbacks,
        not_converged: proj.not_converged.len(),
        not_converged_max_abs_value: proj
            .not_converged
            .iter()
            .fold(0.0, |a: f64, &i| a.max(v[old + i].abs())),
        max_abs_value: v[old..].iter().fold(0.0, |a: f64, x| a.max(x.abs())),
        seconds: t.elapsed().as_secs_f64(),
    };
    Ok((next, stats))
}

/// Values and gradients at every vertex of the next level (the old vertices of `mesh` first,
/// then the projected ones): the old vertices keep their normals as gradients (same points, and
/// only their direction is used) and no value, Newton's points take those of their last
/// evaluation (less than the tolerance away), and only the fallback's points are evaluated again.
fn final_values_gradients<F: Field + ?Sized>(
    eval: &mut Evaluator<'_, F>,
    mesh: &Mesh,
    proj: &Projection,
) -> Result<(Vec<f64>, Vec<DVec3>)> {
    let old = mesh.vertices.len();
    let n_all = old + proj.points.len();
    let mut v = vec![0.0; n_all];
    let mut g = vec![DVec3::ZERO; n_all];
    g[..old].copy_from_slice(&mesh.normals);
    let again: Vec<usize> = (0..proj.points.len())
        .filter(|&k| proj.last[k].is_none())
        .collect();
    for (k, last) in proj.last.iter().enumerate() {
        if let Some((f, grad)) = last {
            v[old + k] = *f;
            g[old + k] = *grad;
        }
    }
    if !again.is_empty() {
        let pts: Vec<DVec3> = again.iter().map(|&k| proj.points[k]).collect();
        let mut av = vec![0.0; pts.len()];
        let mut ag = vec![DVec3::ZERO; pts.len()];
        eval.both(&pts, &mut av, &mut ag)?;
        for (q, &k) in again.iter().enumerate() {
            v[old + k] = av[q];
            g[old + k] = ag[q];
        }
    }
    Ok((v, g))
}
