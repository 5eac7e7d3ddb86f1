//! Subdivision of a control mesh onto an implicit surface (Jin, Sun & Peng 2003), the modified
//! butterfly scheme it is blended with (Zorin, Schröder & Sweldens 1996), and the blend itself.
//!
//! The control mesh is a triangle mesh whose vertices lie on the surface (typically the mesh the
//! surface was fitted to). Each level splits every triangle into four at its edge midpoints
//! ([`split`]) and moves the new midpoints onto the zero set by Newton steps along the gradient
//! (`project`), the "second way" of Jin §3: every level starts from vertices already on the
//! surface, so the midpoints start close to it; Newton starts from the middle of the Hermite
//! curve along the edge with the end normals (`hermite_midpoint`), closer still. Old vertices
//! keep their index and their exact coordinates, so level `k` is a sub-mesh of level `k + 1`.
//!
//! [`butterfly`] makes the same connectivity with positions from the modified butterfly scheme,
//! so that vertex `i` of both meshes corresponds and [`blend`] can mix them (Jin §4).

use crate::error::{check_finite_points, Error, Result};
use crate::field::rbf::VariationalSurface;
use crate::field::Field;
use crate::mesh::Mesh;
use glam::DVec3;
use rayon::prelude::*;
use std::collections::HashMap;
use std::time::Instant;

/// Most subdivision levels accepted (each multiplies the triangles by four).
pub const MAX_LEVELS: usize = 8;

/// Bytes per triangle of the finest level, counting its share of the vertices, normals and the
/// coarser levels kept alongside it.
const BYTES_PER_TRIANGLE: u64 = 96;

/// Newton steps shorter than this multiple of the local edge length that fail to halve the
/// previous step are taken as the rounding noise of the field: the point has converged.
const NOISE_STEP: f64 = 1e-6;

/// A Newton step is taken without a confirming evaluation when the step after it, predicted from
/// quadratic convergence (`len³ / last²`), times this margin is below the tolerance.
const PREDICT_MARGIN: f64 = 10.0;

/// ... and when the step is at most this multiple of the local edge length, so that the gradient
/// of the last evaluation (kept for the normal) is taken that close to the final point.
const PREDICT_MAX_STEP: f64 = 1e-5;

/// How the new vertices are projected onto the surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Newton stops when its step is shorter than `tolerance` × the local edge length (half the
    /// parent edge), when the next step predicted from quadratic convergence is (see
    /// `PREDICT_MARGIN`; the step is then taken without a confirming evaluation), or when a step
    /// below 1e-6 × that length no longer halves (the rounding noise of the field); the bisection
    /// fallback stops when its bracket is that short.
    pub tolerance: f64,
    /// Most Newton steps per vertex and level before the fallback takes over.
    pub max_iterations: u32,
    /// Longest Newton step, as a multiple of the local edge length.
    pub max_step: f64,
    /// Newton gives up on a vertex that wanders further than this multiple of the local edge
    /// length from its midpoint (it would land on another part of the surface).
    pub max_distance: f64,
    /// The fallback looks for a sign change along the gradient line within ± this multiple of the
    /// local edge length from the midpoint.
    pub search_range: f64,
    /// Samples per side of that search.
    pub search_samples: u32,
    /// Compute vertex normals from the field's gradient.
    pub normals: bool,
    /// Refuse requests whose finest level would need more than this many bytes.
    pub memory_limit: u64,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            tolerance: 1e-9,
            max_iterations: 30,
            max_step: 0.5,
            max_distance: 4.0,
            search_range: 4.0,
            search_samples: 16,
            normals: true,
            memory_limit: 4 << 30,
        }
    }
}

impl Settings {
    fn check(&self) -> Result<()> {
        if !(self.tolerance.is_finite() && self.tolerance > 0.0 && self.tolerance < 1.0) {
            return Err(Error::invalid(
                "tolerance",
                format!("must be in (0, 1), got {}", self.tolerance),
            ));
        }
        if self.max_iterations == 0 || self.max_iterations > 10_000 {
            return Err(Error::invalid(
                "max_steps",
                format!("must be between 1 and 10000, got {}", self.max_iterations),
            ));
        }
        for (name, v) in [
            ("max_step", self.max_step),
            ("max_distance", self.max_distance),
            ("search_range", self.search_range),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::invalid(
                    name,
                    format!("must be finite and positive, got {v}"),
                ));
            }
        }
        if self.search_samples == 0 || self.search_samples > 1000 {
            return Err(Error::invalid(
                "search_samples",
                format!("must be between 1 and 1000, got {}", self.search_samples),
            ));
        }
        Ok(())
    }
}

/// What the projection of one level did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SubdivisionStats {
    /// Subdivision level (0: the control mesh).
    pub level: usize,
    /// New vertices projected at this level.
    pub projected: usize,
    /// Field evaluations (value and gradient) per projected vertex during Newton: mean and max.
    pub iterations_mean: f64,
    pub iterations_max: u32,
    /// Points evaluated in total (Newton, fallback, and the fallback's points once more for their
    /// normals; Newton's points reuse the gradient of their last step, the old vertices theirs).
    pub evaluations: u64,
    /// Batched field calls made.
    pub batches: u64,
    /// Vertices for which Newton failed and the line search along the gradient took over.
    pub fallbacks: usize,
    /// Vertices left off the surface (no sign change found): they keep the point of smallest |f|
    /// seen.
    pub not_converged: usize,
    /// Largest |f| among the vertices that did not converge (0 when all did).
    pub not_converged_max_abs_value: f64,
    /// Largest |f| over the new vertices of this level after projection: for Newton's vertices the
    /// value of their last evaluation, before a final step shorter than the tolerance (so an upper
    /// bound to rounding), or, for a final step accepted by its predicted successor (see
    /// [`Settings::tolerance`]), the value predicted after it, f (len / last)²; for the
    /// fallback's vertices the value at the final point.
    pub max_abs_value: f64,
    /// Wall-clock seconds for the level (split, projection, normals).
    pub seconds: f64,
}

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

fn check_levels(mesh: &Mesh, levels: usize, memory_limit: u64) -> Result<()> {
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

/// 1-to-4 midpoint subdivision: one new vertex at the midpoint of every edge (shared by the
/// faces on both sides), appended after the old vertices, which keep their indices. Each
/// triangle `[a, b, c]` becomes `[a, ab, ca]`, `[ab, b, bc]`, `[ca, bc, c]`, `[ab, bc, ca]`, so
/// the orientation is kept. Boundary edges get a midpoint like any other.
///
/// Returns the new mesh (without normals) and, for every new vertex in order, the two old
/// vertices of its parent edge (smaller index first). Indices must be in range (see
/// [`check_mesh`]).
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

/// Batched values and gradients at points.
type ValuesGradientsFn<'a> = &'a (dyn Fn(&[DVec3], &mut [f64], &mut [DVec3]) + Sync);
/// Batched values at points.
type ValuesFn<'a> = &'a (dyn Fn(&[DVec3], &mut [f64]) + Sync);

/// A field seen through batched calls: values with gradients, and values alone.
struct Evaluator<'a> {
    values_gradients: ValuesGradientsFn<'a>,
    values: ValuesFn<'a>,
    /// Field evaluations one point of `both` costs (1, or 7 with difference gradients).
    both_cost: u64,
    evaluations: u64,
    batches: u64,
}

impl Evaluator<'_> {
    fn both(&mut self, p: &[DVec3], v: &mut [f64], g: &mut [DVec3]) -> Result<()> {
        crate::cancel::check()?;
        (self.values_gradients)(p, v, g);
        crate::cancel::advance(p.len() as u64)?;
        self.evaluations += self.both_cost * p.len() as u64;
        self.batches += 1;
        match (0..p.len()).find(|&i| !(v[i].is_finite() && g[i].is_finite())) {
            Some(i) => Err(not_finite(p[i])),
            None => Ok(()),
        }
    }
    fn values(&mut self, p: &[DVec3], v: &mut [f64]) -> Result<()> {
        crate::cancel::check()?;
        (self.values)(p, v);
        crate::cancel::advance(p.len() as u64)?;
        self.evaluations += p.len() as u64;
        self.batches += 1;
        match v.iter().position(|x| !x.is_finite()) {
            Some(i) => Err(not_finite(p[i])),
            None => Ok(()),
        }
    }
}

fn not_finite(p: DVec3) -> Error {
    Error::FieldNotFinite {
        x: p.x,
        y: p.y,
        z: p.z,
    }
}

/// What `project` did to a batch of points.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Projection {
    /// Projected points.
    pub points: Vec<DVec3>,
    /// Newton evaluations per point.
    pub iterations: Vec<u32>,
    /// Points handed to the line-search fallback.
    pub fallbacks: usize,
    /// Indices of the points the fallback could not place either.
    pub not_converged: Vec<usize>,
    /// For points Newton placed: the value and gradient of its last evaluation (one final step
    /// away from the final point: shorter than the tolerance, or than `PREDICT_MAX_STEP` × the
    /// local edge length when accepted by prediction, and then with the value predicted at the
    /// final point); `None` for the fallback's points.
    pub last: Vec<Option<(f64, DVec3)>>,
}

#[derive(Clone, Copy, PartialEq)]
enum State {
    Moving,
    Done,
    Failed,
}

/// Moves every start point onto the zero set: Newton steps r ← r − f ∇f / |∇f|² (Jin eq. 10),
/// all still-moving points evaluated in one batched call per step. `scales[i]` is the local
/// edge length of point `i`, which sets the stopping tolerance, the longest step and how far the
/// point may go; `hints[i]` is a direction to search along when the gradient vanishes at the
/// start (e.g. the mean normal of the parent edge).
///
/// Points where Newton fails (vanishing gradient, too many steps, wandering too far) are searched
/// along the gradient line through their start point for the nearest sign change, then bisected.
fn project(
    eval: &mut Evaluator<'_>,
    starts: &[DVec3],
    scales: &[f64],
    hints: &[DVec3],
    s: &Settings,
) -> Result<Projection> {
    let n = starts.len();
    let mut pos = starts.to_vec();
    let mut iterations = vec![0u32; n];
    let mut state = vec![State::Moving; n];
    // Value and gradient at the start point (for the fallback); best point seen.
    let mut f0 = vec![0.0; n];
    let mut g0 = vec![DVec3::ZERO; n];
    let mut best: Vec<(f64, DVec3)> = starts.iter().map(|&p| (f64::INFINITY, p)).collect();
    let mut last = vec![f64::INFINITY; n];
    // Gradient of the previous evaluation and the step taken from it (for the secant estimate of
    // the gradient at a point accepted by prediction).
    let mut prev: Vec<(DVec3, DVec3)> = vec![(DVec3::ZERO, DVec3::ZERO); n];
    let mut last_eval: Vec<Option<(f64, DVec3)>> = vec![None; n];
    let mut active: Vec<usize> = (0..n).collect();
    let mut pts: Vec<DVec3> = Vec::with_capacity(n);
    let mut vals = vec![0.0; n];
    let mut grads = vec![DVec3::ZERO; n];
    for step in 0..s.max_iterations {
        if active.is_empty() {
            break;
        }
        pts.clear();
        pts.extend(active.iter().map(|&i| pos[i]));
        let m = pts.len();
        eval.both(&pts, &mut vals[..m], &mut grads[..m])?;
        let mut next = Vec::with_capacity(m);
        for (k, &i) in active.iter().enumerate() {
            let (f, g) = (vals[k], grads[k]);
            iterations[i] += 1;
            if step == 0 {
                f0[i] = f;
                g0[i] = g;
            }
            if f.abs() < best[i].0 {
                best[i] = (f.abs(), pos[i]);
            }
            if f == 0.0 {
                state[i] = State::Done;
                last_eval[i] = Some((f, g));
                continue;
            }
            let g2 = g.length_squared();
            if !(g2 > 0.0 && g2.is_finite()) {
                state[i] = State::Failed;
                continue;
            }
            let mut d = g * (-f / g2);
            let len = d.length();
            let h = scales[i];
            if !len.is_finite() {
                state[i] = State::Failed;
                continue;
            }
            // Converged, or stalled at the rounding noise of f: a tiny step that is no longer
            // shrinking quadratically.
            if len <= s.tolerance * h || (len <= NOISE_STEP * h && len > 0.5 * last[i]) {
                if len < last[i] {
                    pos[i] += d;
                }
                state[i] = State::Done;
                last_eval[i] = Some((f, g));
                continue;
            }
            // Converging quadratically (the step at least halved): Newton's error after this step
            // is about the next step, C len² with C = len / last², so the step is taken and the
            // point accepted when that prediction, with a margin, is below the tolerance. This
            // saves the evaluation that would only confirm it. The value kept is the one predicted
            // at the final point alike, f (len / last)², and the gradient is carried over the step
            // by the secant of the previous one, g + (g − g_prev) (d·d_prev) / |d_prev|² (the two
            // steps are nearly parallel, both along the gradient), so that the normal stays that
            // of the final point to second order.
            if last[i].is_finite()
                && len <= 0.5 * last[i]
                && len <= PREDICT_MAX_STEP * h
                && PREDICT_MARGIN * len * (len / last[i]).powi(2) <= s.tolerance * h
            {
                pos[i] += d;
                state[i] = State::Done;
                let (gp, dp) = prev[i];
                let dd = dp.length_squared();
                let moved = g + (g - gp) * (d.dot(dp) / dd);
                let g_final = if dd > 0.0 && moved.is_finite() {
                    moved
                } else {
                    g
                };
                last_eval[i] = Some((f * (len / last[i]).powi(2), g_final));
                continue;
            }
            last[i] = len;
            if len > s.max_step * h {
                d *= s.max_step * h / len;
            }
            pos[i] += d;
            prev[i] = (g, d);
            if (pos[i] - starts[i]).length() > s.max_distance * h {
                state[i] = State::Failed;
            } else {
                next.push(i);
            }
        }
        active = next;
    }
    for &i in &active {
        state[i] = State::Failed;
    }

    // Fallback: nearest sign change along the gradient line through the start point.
    let failed: Vec<usize> = (0..n).filter(|&i| state[i] == State::Failed).collect();
    let mut not_converged = Vec::new();
    if !failed.is_empty() {
        let ns = s.search_samples as usize;
        let dirs: Vec<DVec3> = failed
            .iter()
            .map(|&i| {
                let g = g0[i].normalize_or_zero();
                if g != DVec3::ZERO {
                    g
                } else {
                    hints[i].normalize_or_zero()
                }
            })
            .collect();
        let t_of = |i: usize, j: usize| -> f64 {
            // Sample j in 0..2ns: first the + side outward, then the − side outward.
            let r = s.search_range * scales[i] * ((j % ns) + 1) as f64 / ns as f64;
            if j < ns {
                r
            } else {
                -r
            }
        };
        let mut probes = Vec::with_capacity(failed.len() * 2 * ns);
        for (k, &i) in failed.iter().enumerate() {
            for j in 0..2 * ns {
                probes.push(starts[i] + dirs[k] * t_of(i, j));
            }
        }
        let mut pv = vec![0.0; probes.len()];
        if dirs.iter().any(|d| *d != DVec3::ZERO) {
            eval.values(&probes, &mut pv)?;
        }
        // Brackets (lo, f_lo, hi, f_hi) in t.
        let mut brackets: Vec<(usize, f64, f64, f64, f64)> = Vec::new();
        for (k, &i) in failed.iter().enumerate() {
            if dirs[k] == DVec3::ZERO {
                not_converged.push(i);
                continue;
            }
            let mut found: Option<(f64, f64, f64, f64)> = None;
            for side in 0..2 {
                let (mut tp, mut fp) = (0.0, f0[i]);
                for j in 0..ns {
                    let jj = side * ns + j;
                    let (t, f) = (t_of(i, jj), pv[k * 2 * ns + jj]);
                    if f.abs() < best[i].0 {
                        best[i] = (f.abs(), starts[i] + dirs[k] * t);
                    }
                    if (f <= 0.0) != (fp <= 0.0) {
                        if found.is_none_or(|b| t.abs() < b.2.abs().max(b.0.abs())) {
                            found = Some((tp, fp, t, f));
                        }
                        break;
                    }
                    (tp, fp) = (t, f);
                }
            }
            match found {
                Some((a, fa, b, fb)) => brackets.push((k, a, fa, b, fb)),
                None => not_converged.push(i),
            }
        }
        // Bisection, all bracketed points per batched call.
        let mut open: Vec<usize> = (0..brackets.len()).collect();
        let mut mids = Vec::with_capacity(brackets.len());
        let mut mv = vec![0.0; brackets.len()];
        for _ in 0..200 {
            open.retain(|&b| {
                let (k, a, _, c, _) = brackets[b];
                (c - a).abs() > s.tolerance * scales[failed[k]]
            });
            if open.is_empty() {
                break;
            }
            mids.clear();
            mids.extend(open.iter().map(|&b| {
                let (k, a, _, c, _) = brackets[b];
                starts[failed[k]] + dirs[k] * (0.5 * (a + c))
            }));
            eval.values(&mids, &mut mv[..open.len()])?;
            for (q, &b) in open.iter().enumerate() {
                let (_, a, fa, c, fc) = &mut brackets[b];
                let (t, f) = (0.5 * (*a + *c), mv[q]);
                if f == 0.0 {
                    (*a, *fa, *c, *fc) = (t, f, t, f);
                } else if (f <= 0.0) == (*fa <= 0.0) {
                    (*a, *fa) = (t, f);
                } else {
                    (*c, *fc) = (t, f);
                }
            }
        }
        for &(k, a, fa, c, fc) in &brackets {
            let i = failed[k];
            let t = if fa.abs() <= fc.abs() { a } else { c };
            pos[i] = starts[i] + dirs[k] * t;
        }
        for &i in &not_converged {
            pos[i] = best[i].1;
        }
    }
    Ok(Projection {
        points: pos,
        iterations,
        fallbacks: failed.len(),
        not_converged,
        last: last_eval,
    })
}

/// Newton's start point for the new vertex of edge `ab` (both ends on the surface, unit normals
/// `na`, `nb`): the middle of the cubic Hermite curve from `a` to `b` whose end tangents are the
/// edge projected into the two tangent planes, `(a + b) / 2 + c` with
/// `c = ((e·nb) nb − (e·na) na) / 8` and `e = b − a`, less the part of `c` along the edge (which
/// would slide the vertex towards one end where the two ends curve differently), so the start
/// stays in the plane through the midpoint perpendicular to the edge. On a circle of radius R
/// its distance to the curve is about 0.375 h⁴ / R³ for half edge h, against h² / 2R for the flat
/// midpoint, so Newton starts much closer. The correction is at most |e| / 4; without both
/// normals (a vanishing gradient) or for a degenerate edge, the flat midpoint is used.
fn hermite_midpoint(a: DVec3, b: DVec3, na: DVec3, nb: DVec3) -> DVec3 {
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

fn subdivide_with(
    eval: &mut Evaluator<'_>,
    control: &Mesh,
    levels: usize,
    settings: &Settings,
) -> Result<Vec<(Mesh, SubdivisionStats)>> {
    settings.check()?;
    check_mesh(control)?;
    check_levels(control, levels, settings.memory_limit)?;
    let mut out: Vec<(Mesh, SubdivisionStats)> = Vec::with_capacity(levels + 1);

    // Level 0: the control mesh with normals from the field.
    let t = Instant::now();
    let mut mesh = control.clone();
    let (ev0, b0) = (eval.evaluations, eval.batches);
    let mut v = vec![0.0; mesh.vertices.len()];
    let mut g = vec![DVec3::ZERO; mesh.vertices.len()];
    eval.both(&mesh.vertices, &mut v, &mut g)?;
    mesh.normals = normals_from_gradients(&mesh, &g);
    let stats = SubdivisionStats {
        level: 0,
        evaluations: eval.evaluations - ev0,
        batches: eval.batches - b0,
        max_abs_value: v.iter().fold(0.0, |a: f64, x| a.max(x.abs())),
        seconds: t.elapsed().as_secs_f64(),
        ..Default::default()
    };
    out.push((mesh.clone(), stats));

    for level in 1..=levels {
        crate::cancel::check()?;
        let t = Instant::now();
        let (ev0, b0) = (eval.evaluations, eval.batches);
        let old = mesh.vertices.len();
        let (mut next, parents) = split(&mesh);
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
        // Values and gradients at the final points: the old vertices keep theirs (same points),
        // Newton's points take those of their last evaluation (less than the tolerance away), and
        // only the fallback's points are evaluated again.
        let n_all = next.vertices.len();
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
        next.normals = if settings.normals {
            normals_from_gradients(&next, &g)
        } else {
            vec![]
        };
        let it = &proj.iterations;
        let stats = SubdivisionStats {
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
        // The next level needs normals for its search hints even when they are not wanted.
        if !settings.normals {
            let mut with = next.clone();
            with.normals = normals_from_gradients(&next, &g);
            mesh = with;
        } else {
            mesh = next.clone();
        }
        out.push((next, stats));
    }
    Ok(out)
}

/// Subdivides `control` `levels` times onto the zero set of `field` (Jin et al. §3): entry `k`
/// of the result is level `k` (entry 0 the control mesh, with normals), each with the stats of
/// its projection. Uses batched `values` and `gradients` calls (two per Newton step).
///
/// Errors for a broken control mesh (see [`check_mesh`]), `levels` over [`MAX_LEVELS`] or over
/// the memory limit, bad settings, or a field returning NaN/infinity.
pub fn subdivide<F: Field + ?Sized>(
    field: &F,
    control: &Mesh,
    levels: usize,
    settings: &Settings,
) -> Result<Vec<(Mesh, SubdivisionStats)>> {
    let vg = |p: &[DVec3], v: &mut [f64], g: &mut [DVec3]| {
        field.values(p, v);
        field.gradients(p, g);
    };
    let vo = |p: &[DVec3], v: &mut [f64]| field.values(p, v);
    let mut eval = Evaluator {
        values_gradients: &vg,
        values: &vo,
        both_cost: 1,
        evaluations: 0,
        batches: 0,
    };
    subdivide_with(&mut eval, control, levels, settings)
}

/// [`subdivide`] for a variational surface, with values and gradients from one batched call per
/// Newton step ([`VariationalSurface::values_gradients`]).
pub fn subdivide_surface(
    surface: &VariationalSurface,
    control: &Mesh,
    levels: usize,
    settings: &Settings,
) -> Result<Vec<(Mesh, SubdivisionStats)>> {
    let vg = |p: &[DVec3], v: &mut [f64], g: &mut [DVec3]| surface.values_gradients(p, v, g);
    let vo = |p: &[DVec3], v: &mut [f64]| surface.values(p, v);
    let mut eval = Evaluator {
        values_gradients: &vg,
        values: &vo,
        both_cost: 1,
        evaluations: 0,
        batches: 0,
    };
    subdivide_with(&mut eval, control, levels, settings)
}

/// [`subdivide`] for a field that only has values (such as a Python callable): each Newton step
/// makes one batched [`Field::values`] call on 7 points per vertex, the vertex and ± `h` along
/// each axis, and takes the gradient by central differences (as
/// [`crate::field::gradients_by_differences`]). `h` defaults (when `None`) to 1e-6 × the largest
/// side of the control mesh's bounding box. `evaluations` in the stats count all 7 points.
pub fn subdivide_by_differences<F: Field + ?Sized>(
    field: &F,
    control: &Mesh,
    levels: usize,
    settings: &Settings,
    h: Option<f64>,
) -> Result<Vec<(Mesh, SubdivisionStats)>> {
    check_finite_points("vertices", &control.vertices)?;
    let h = match h {
        Some(h) if h.is_finite() && h > 0.0 => h,
        Some(h) => {
            return Err(Error::invalid(
                "step",
                format!("must be finite and positive, got {h}"),
            ))
        }
        None => {
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
    };
    let vg = |p: &[DVec3], v: &mut [f64], g: &mut [DVec3]| {
        let mut probes = Vec::with_capacity(p.len() * 7);
        for &x in p {
            probes.push(x);
            for e in [DVec3::X, DVec3::Y, DVec3::Z] {
                probes.push(x + e * h);
                probes.push(x - e * h);
            }
        }
        let mut out = vec![0.0; probes.len()];
        field.values(&probes, &mut out);
        for (i, s) in out.chunks_exact(7).enumerate() {
            v[i] = s[0];
            g[i] = DVec3::new(s[1] - s[2], s[3] - s[4], s[5] - s[6]) / (2.0 * h);
        }
    };
    let vo = |p: &[DVec3], v: &mut [f64]| field.values(p, v);
    let mut eval = Evaluator {
        values_gradients: &vg,
        values: &vo,
        both_cost: 7,
        evaluations: 0,
        batches: 0,
    };
    subdivide_with(&mut eval, control, levels, settings)
}

/// Ordered one-ring of every vertex, from the oriented triangles: `rings[v]` lists the neighbours
/// counter-clockwise; `boundary[v]` tells whether the ring is an open fan (first and last
/// neighbours then lie across boundary edges).
struct Rings {
    rings: Vec<Vec<u32>>,
    boundary: Vec<bool>,
}

impl Rings {
    fn new(mesh: &Mesh) -> Result<Rings> {
        let n = mesh.vertices.len();
        // For triangle (v, x, y) counter-clockwise: the neighbour after x around v is y.
        let mut pairs: Vec<Vec<(u32, u32)>> = vec![Vec::new(); n];
        for t in &mesh.triangles {
            for k in 0..3 {
                pairs[t[k] as usize].push((t[(k + 1) % 3], t[(k + 2) % 3]));
            }
        }
        let mut rings = Vec::with_capacity(n);
        let mut boundary = Vec::with_capacity(n);
        for (v, p) in pairs.iter().enumerate() {
            if p.is_empty() {
                rings.push(Vec::new());
                boundary.push(false);
                continue;
            }
            let next = |x: u32| p.iter().find(|q| q.0 == x).map(|q| q.1);
            let start = p.iter().find(|q| !p.iter().any(|r| r.1 == q.0));
            let (first, open) = match start {
                Some(q) => (q.0, true),
                None => (p[0].0, false),
            };
            let mut ring = vec![first];
            let mut cur = first;
            while let Some(y) = next(cur) {
                if y == first {
                    break;
                }
                ring.push(y);
                cur = y;
                if ring.len() > p.len() + 1 {
                    break;
                }
            }
            let expected = if open { p.len() + 1 } else { p.len() };
            if ring.len() != expected {
                return Err(Error::invalid(
                    "faces",
                    format!("vertex {v} is not manifold (its faces do not form one fan)"),
                ));
            }
            rings.push(ring);
            boundary.push(open);
        }
        Ok(Rings { rings, boundary })
    }

    /// The ring of `v` rotated to start at `start`.
    fn from(&self, v: u32, start: u32) -> Vec<u32> {
        let r = &self.rings[v as usize];
        let s = r.iter().position(|&x| x == start).unwrap_or(0);
        r[s..].iter().chain(&r[..s]).copied().collect()
    }
}

/// Zorin's weights for an extraordinary interior vertex of valence `k`: the new point is
/// 3/4 × the vertex + Σ s_j × ring_j, ring_0 the other end of the edge. `None` for k < 3.
fn extraordinary_weights(k: usize) -> Option<Vec<f64>> {
    match k {
        0..=2 => None,
        3 => Some(vec![5.0 / 12.0, -1.0 / 12.0, -1.0 / 12.0]),
        4 => Some(vec![3.0 / 8.0, 0.0, -1.0 / 8.0, 0.0]),
        _ => {
            let kf = k as f64;
            Some(
                (0..k)
                    .map(|j| {
                        let a = 2.0 * std::f64::consts::PI * j as f64 / kf;
                        (0.25 + a.cos() + 0.5 * (2.0 * a).cos()) / kf
                    })
                    .collect(),
            )
        }
    }
}

/// The new point on edge (a, b) by the modified butterfly rules.
fn butterfly_point(mesh: &Mesh, rings: &Rings, a: u32, b: u32, w: f64) -> DVec3 {
    let p = |i: u32| mesh.vertices[i as usize];
    let (ia, ib) = (a as usize, b as usize);
    let ra_full = &rings.rings[ia];
    let rb_full = &rings.rings[ib];
    let is_boundary_edge = (rings.boundary[ia]
        && (ra_full.first() == Some(&b) || ra_full.last() == Some(&b)))
        || (rings.boundary[ib] && (rb_full.first() == Some(&a) || rb_full.last() == Some(&a)));
    if is_boundary_edge {
        // Four-point scheme along the boundary: the other boundary neighbour of each end.
        let other = |r: &Vec<u32>, skip: u32, v: u32| -> u32 {
            let (f, l) = (r[0], r[r.len() - 1]);
            if f != skip {
                f
            } else if l != skip {
                l
            } else {
                v
            }
        };
        let (a2, b2) = (other(ra_full, b, a), other(rb_full, a, b));
        return (p(a) + p(b)) * (9.0 / 16.0) - (p(a2) + p(b2)) * (1.0 / 16.0);
    }
    // Interior edge.
    let stencil = |v: u32, o: u32| -> Option<DVec3> {
        let r = rings.from(v, o);
        let s = extraordinary_weights(r.len())?;
        Some(p(v) * 0.75 + r.iter().zip(&s).map(|(&x, &sj)| p(x) * sj).sum::<DVec3>())
    };
    let interior = |v: usize| !rings.boundary[v];
    let regular = |v: usize| interior(v) && rings.rings[v].len() == 6;
    if regular(ia) && regular(ib) {
        let ra = rings.from(a, b);
        let rb = rings.from(b, a);
        return (p(a) + p(b)) * (0.5 - w)
            + (p(ra[1]) + p(ra[5])) * (0.125 + 2.0 * w)
            + (p(ra[2]) + p(ra[4]) + p(rb[2]) + p(rb[4])) * (-0.0625 - w)
            + (p(ra[3]) + p(rb[3])) * w;
    }
    let sa = if interior(ia) && !regular(ia) {
        stencil(a, b)
    } else {
        None
    };
    let sb = if interior(ib) && !regular(ib) {
        stencil(b, a)
    } else {
        None
    };
    match (sa, sb) {
        (Some(x), Some(y)) => (x + y) * 0.5,
        (Some(x), None) => x,
        (None, Some(y)) => y,
        (None, None) => {
            // One end on the boundary, the other interior and regular: the interior end's
            // stencil (Zorin's rule at k = 6 reads only that end's ring, all inside the mesh).
            if interior(ia) {
                if let Some(x) = stencil(a, b) {
                    return x;
                }
            }
            if interior(ib) {
                if let Some(y) = stencil(b, a) {
                    return y;
                }
            }
            // Both ends on the boundary (an interior edge cutting across a corner or a strip).
            boundary_butterfly(mesh, rings, a, b, w)
        }
    }
}

/// The vertex across edge (p, q) from `o`: the third vertex of the other face on (p, q), `None`
/// when (p, q) is a boundary edge.
fn across(rings: &Rings, p: u32, q: u32, o: u32) -> Option<u32> {
    let r = &rings.rings[p as usize];
    let n = r.len();
    let i = r.iter().position(|&x| x == q)?;
    let open = rings.boundary[p as usize];
    let prev = if i > 0 {
        Some(r[i - 1])
    } else if !open {
        Some(r[n - 1])
    } else {
        None
    };
    let next = if i + 1 < n {
        Some(r[i + 1])
    } else if !open {
        Some(r[0])
    } else {
        None
    };
    [prev, next].into_iter().flatten().find(|&z| z != o)
}

/// The 10-point butterfly on an interior edge (a, b) whose two ends both lie on the boundary.
/// Stencil vertices that do not exist are replaced by ghost vertices, affine extrapolations from
/// the mesh: the vertex across edge (x, y) of the butterfly's central faces, missing when (x, y)
/// is a boundary edge, becomes the reflection x + y − o of the central face's third vertex `o`
/// (the parallelogram it would complete on a regular lattice), and the two tension points become
/// 2a − b and 2b − a. The weights still sum to one, so the rule is affine invariant, keeps planar
/// meshes planar, is symmetric in (a, b) and in the two wings, and gives the exact midpoint on a
/// regular planar lattice (whose missing vertices are exactly the ghosts).
fn boundary_butterfly(mesh: &Mesh, rings: &Rings, a: u32, b: u32, w: f64) -> DVec3 {
    let p = |i: u32| mesh.vertices[i as usize];
    let Some((c, d)) = wing_vertices(rings, a, b) else {
        return (p(a) + p(b)) * 0.5;
    };
    let far = |x: u32, y: u32, o: u32| match across(rings, x, y, o) {
        Some(z) => p(z),
        None => p(x) + p(y) - p(o),
    };
    let outer = far(a, c, b) + far(b, c, a) + far(a, d, b) + far(b, d, a);
    let (pa, pb) = (p(a), p(b));
    (pa + pb) * (0.5 - w)
        + (p(c) + p(d)) * (0.125 + 2.0 * w)
        + outer * (-0.0625 - w)
        + (pa * 2.0 - pb + pb * 2.0 - pa) * w
}

/// The vertices opposite edge (a, b) in its two faces, when it has two.
fn wing_vertices(rings: &Rings, a: u32, b: u32) -> Option<(u32, u32)> {
    let r = &rings.rings[a as usize];
    let i = r.iter().position(|&x| x == b)?;
    let n = r.len();
    if rings.boundary[a as usize] && (i == 0 || i + 1 == n) {
        return None;
    }
    Some((r[(i + 1) % n], r[(i + n - 1) % n]))
}

/// Modified butterfly subdivision (Zorin, Schröder & Sweldens 1996; Jin §4) with tension `w`:
/// entry `k` of the result is level `k` (entry 0 the control mesh). Connectivity and vertex
/// numbering are those of [`split`], so vertex `i` matches vertex `i` of [`subdivide`].
///
/// Edges between two interior vertices of valence 6 use the 10-point stencil (a: 1/2 − w,
/// b: 1/8 + 2w, c: −1/16 − w, d: w); an end of another valence uses Zorin's stencil of that
/// vertex (the two stencils averaged when both ends are extraordinary); boundary edges use the
/// four-point scheme (−1/16, 9/16, 9/16, −1/16); an interior edge with one end on the boundary
/// uses the stencil of its interior end. An interior edge joining two boundary vertices uses the
/// 10-point stencil with ghost vertices in place of the missing ones (see `boundary_butterfly`).
/// Normals are the area-weighted face normals.
pub fn butterfly(control: &Mesh, levels: usize, w: f64) -> Result<Vec<Mesh>> {
    check_mesh(control)?;
    check_levels(control, levels, Settings::default().memory_limit)?;
    if !w.is_finite() {
        return Err(Error::invalid("w", format!("must be finite, got {w}")));
    }
    let mut mesh = control.clone();
    mesh.normals = mesh.face_normals_at_vertices();
    let mut out = vec![mesh.clone()];
    for _ in 0..levels {
        crate::cancel::check()?;
        let rings = Rings::new(&mesh)?;
        let old = mesh.vertices.len();
        let (mut next, parents) = split(&mesh);
        let pts: Vec<DVec3> = parents
            .par_iter()
            .map(|&[a, b]| butterfly_point(&mesh, &rings, a, b, w))
            .collect();
        next.vertices[old..].copy_from_slice(&pts);
        next.normals = next.face_normals_at_vertices();
        out.push(next.clone());
        mesh = next;
    }
    Ok(out)
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::analytic::Sphere;
    use crate::field::{constraints, rbf};

    /// The 12-vertex icosahedron with circumradius 0.9, faces counter-clockwise from outside.
    fn icosahedron() -> Mesh {
        let t = (1.0 + 5f64.sqrt()) / 2.0;
        let raw = [
            [-1.0, t, 0.0],
            [1.0, t, 0.0],
            [-1.0, -t, 0.0],
            [1.0, -t, 0.0],
            [0.0, -1.0, t],
            [0.0, 1.0, t],
            [0.0, -1.0, -t],
            [0.0, 1.0, -t],
            [t, 0.0, -1.0],
            [t, 0.0, 1.0],
            [-t, 0.0, -1.0],
            [-t, 0.0, 1.0],
        ];
        let vertices = raw
            .iter()
            .map(|v| DVec3::from_array(*v).normalize() * 0.9)
            .collect();
        let triangles = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        Mesh {
            vertices,
            triangles,
            normals: vec![],
        }
    }

    fn grid(n: u32, z: f64) -> Mesh {
        let mut vertices = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                // A slightly irregular planar grid.
                let x = i as f64 + 0.13 * ((i * 7 + j * 3) % 5) as f64;
                let y = j as f64 + 0.11 * ((i * 5 + j * 2) % 3) as f64;
                vertices.push(DVec3::new(x, y, z));
            }
        }
        let id = |i: u32, j: u32| j * (n + 1) + i;
        let mut triangles = Vec::new();
        for j in 0..n {
            for i in 0..n {
                if (i + j) % 2 == 0 {
                    triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                    triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
                } else {
                    triangles.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
                    triangles.push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
                }
            }
        }
        Mesh {
            vertices,
            triangles,
            normals: vec![],
        }
    }

    #[test]
    fn icosahedron_is_valid() {
        let m = icosahedron();
        assert!(m.is_closed_oriented());
        assert_eq!(m.euler_characteristic(), 2);
        assert!(m.volume() > 0.0);
    }

    #[test]
    fn split_counts_and_orientation() {
        let m = icosahedron();
        let (s, parents) = split(&m);
        assert_eq!(s.triangles.len(), 80);
        assert_eq!(parents.len(), 30);
        assert_eq!(s.vertices.len(), 42);
        assert_eq!(&s.vertices[..12], &m.vertices[..]);
        assert!(s.is_closed_oriented());
        assert_eq!(s.euler_characteristic(), 2);
        // Open mesh: boundary edges double.
        let mut open = m.clone();
        open.triangles.truncate(15);
        let boundary = |m: &Mesh| {
            let mut c: HashMap<(u32, u32), u32> = HashMap::new();
            for t in &m.triangles {
                for k in 0..3 {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    *c.entry((a.min(b), a.max(b))).or_default() += 1;
                }
            }
            c.values().filter(|&&x| x == 1).count()
        };
        let (so, _) = split(&open);
        assert_eq!(boundary(&so), 2 * boundary(&open));
    }

    /// The icosahedron and the variational surface fitted to it with the default settings.
    fn icosahedron_surface() -> (Mesh, VariationalSurface) {
        let m = icosahedron();
        let s = VariationalSurface::from_mesh(
            &m.vertices,
            &m.triangles,
            &constraints::ConstraintSettings::default(),
            &rbf::FitSettings::default(),
        )
        .unwrap();
        (m, s)
    }

    #[test]
    fn icosahedron_subdivides_onto_surface() {
        let (m, s) = icosahedron_surface();
        let levels = subdivide_surface(&s, &m, 5, &Settings::default()).unwrap();
        assert_eq!(levels.len(), 6);
        let counts: Vec<usize> = levels.iter().map(|(l, _)| l.triangles.len()).collect();
        assert_eq!(counts, vec![20, 80, 320, 1280, 5120, 20480]);
        for (k, (mesh, stats)) in levels.iter().enumerate() {
            assert_eq!(stats.level, k);
            assert!(mesh.is_closed_oriented(), "level {k}");
            assert_eq!(mesh.euler_characteristic(), 2, "level {k}");
            assert_eq!(mesh.normals.len(), mesh.vertices.len());
            for (a, b) in m.vertices.iter().zip(&mesh.vertices) {
                assert_eq!(
                    a.to_array().map(f64::to_bits),
                    b.to_array().map(f64::to_bits)
                );
            }
            let mut v = vec![0.0; mesh.vertices.len()];
            s.values(&mesh.vertices, &mut v);
            let worst = v.iter().fold(0.0, |a: f64, x| a.max(x.abs()));
            assert!(worst <= 1e-6, "level {k}: |f| up to {worst}");
            assert_eq!(stats.not_converged, 0);
            // The vertices of level k stay exactly in level k + 1.
            if k > 0 {
                let prev = &levels[k - 1].0;
                assert_eq!(&mesh.vertices[..prev.vertices.len()], &prev.vertices[..]);
            }
        }
        assert!(levels[5].1.iterations_mean < 6.0, "{:?}", levels[5].1);
    }

    #[test]
    fn hermite_midpoint_is_fourth_order_on_a_circle() {
        // Two points of the unit circle at ±θ, with their normals: the flat midpoint is θ²/2 off
        // the circle, the Hermite midpoint about 0.375 θ⁴.
        for theta in [0.02f64, 0.1, 0.3, 0.6] {
            let a = DVec3::new(-theta.sin(), theta.cos(), 0.0);
            let b = DVec3::new(theta.sin(), theta.cos(), 0.0);
            let p = hermite_midpoint(a, b, a, b);
            let err = (p.length() - 1.0).abs();
            assert!(err <= 0.4 * theta.powi(4), "θ = {theta}: {err}");
            assert!(
                err < theta * theta * (1.0 - theta.cos()),
                "θ = {theta}: {err}"
            );
            assert!(p.x.abs() < 1e-15 && p.z == 0.0);
        }
        // A vanishing normal gives the flat midpoint; a plane gives the midpoint too.
        let (a, b) = (DVec3::X, DVec3::Y);
        assert_eq!(hermite_midpoint(a, b, DVec3::ZERO, DVec3::Z), 0.5 * (a + b));
        assert_eq!(hermite_midpoint(a, b, DVec3::Z, DVec3::Z), 0.5 * (a + b));
        assert_eq!(hermite_midpoint(a, a, DVec3::Z, DVec3::Z), a);
        // Ends curving differently: the start stays in the plane perpendicular to the edge
        // through its midpoint.
        let (na, nb) = (
            DVec3::new(-0.3, 0.0, 1.0).normalize(),
            DVec3::new(0.05, 0.1, 1.0).normalize(),
        );
        let (a, b) = (DVec3::new(-0.1, 0.0, 0.0), DVec3::new(0.1, 0.02, 0.01));
        let p = hermite_midpoint(a, b, na, nb);
        assert!((p - 0.5 * (a + b)).dot(b - a).abs() < 1e-15);
        assert!((p - 0.5 * (a + b)).length() > 1e-3);
    }

    #[test]
    fn prediction_saves_the_confirming_evaluation() {
        // Onto a variational sphere: every new vertex of levels 2-4 is placed with about two
        // evaluations (a step from the Hermite midpoint, then one accepted by prediction), still
        // on the surface to |f| ≤ 1e-6 with normals that are the unit gradients there.
        let (m, s) = icosahedron_surface();
        let levels = subdivide_surface(&s, &m, 4, &Settings::default()).unwrap();
        for (k, (mesh, stats)) in levels.iter().enumerate().skip(1) {
            let old = levels[k - 1].0.vertices.len();
            let new = &mesh.vertices[old..];
            let mut v = vec![0.0; new.len()];
            let mut g = vec![DVec3::ZERO; new.len()];
            s.values_gradients(new, &mut v, &mut g);
            let worst = v.iter().fold(0.0, |a: f64, x| a.max(x.abs()));
            assert!(worst <= 1e-6, "level {k}: |f| up to {worst}");
            for (gi, ni) in g.iter().zip(&mesh.normals[old..]) {
                assert!((gi.normalize() - *ni).length() < 1e-6, "level {k}");
            }
            assert_eq!(stats.fallbacks, 0);
            if k >= 3 {
                assert!(stats.iterations_mean <= 2.2, "level {k}: {stats:?}");
            }
        }
    }

    #[test]
    fn generic_field_matches_and_fallback_runs() {
        let m = icosahedron();
        let sphere = Sphere {
            center: DVec3::ZERO,
            radius: 0.9,
        };
        let levels = subdivide(&sphere, &m, 3, &Settings::default()).unwrap();
        for (mesh, _) in &levels {
            for p in &mesh.vertices {
                assert!((p.length() - 0.9).abs() < 1e-9);
            }
            assert!(mesh.is_closed_oriented());
        }
        // A single Newton step forces the fallback for every vertex off the sphere.
        let s = Settings {
            max_iterations: 1,
            ..Default::default()
        };
        let levels = subdivide(&sphere, &m, 2, &s).unwrap();
        assert!(levels[1].1.fallbacks > 0);
        assert_eq!(levels[1].1.not_converged, 0);
        for p in &levels[2].0.vertices {
            assert!((p.length() - 0.9).abs() < 1e-7);
        }
    }

    #[test]
    fn difference_gradients_reach_the_surface() {
        let m = icosahedron();
        let sphere = Sphere {
            center: DVec3::ZERO,
            radius: 0.9,
        };
        // Values only: the analytic gradient is never asked for.
        struct ValuesOnly<'a>(&'a Sphere);
        impl Field for ValuesOnly<'_> {
            fn value(&self, p: DVec3) -> f64 {
                self.0.value(p)
            }
            fn gradient(&self, _: DVec3) -> DVec3 {
                panic!("gradient asked for")
            }
            fn gradients(&self, _: &[DVec3], _: &mut [DVec3]) {
                panic!("gradients asked for")
            }
        }
        let f = ValuesOnly(&sphere);
        let levels = subdivide_by_differences(&f, &m, 4, &Settings::default(), None).unwrap();
        let exact = subdivide(&sphere, &m, 4, &Settings::default()).unwrap();
        for ((mesh, stats), (e, _)) in levels.iter().zip(&exact) {
            assert_eq!(mesh.triangles, e.triangles);
            for (p, q) in mesh.vertices.iter().zip(&e.vertices) {
                assert!((p.length() - 0.9).abs() < 1e-12);
                assert!((*p - *q).length() < 1e-9);
            }
            assert_eq!(stats.not_converged, 0);
            // Seven values per point for every value-and-gradient evaluation.
            assert!(stats.evaluations >= 7 * mesh.vertices.len() as u64);
        }
        assert!(subdivide_by_differences(&f, &m, 1, &Settings::default(), Some(0.0)).is_err());
    }

    #[test]
    fn refuses_bad_input() {
        let m = icosahedron();
        let sphere = Sphere {
            center: DVec3::ZERO,
            radius: 0.9,
        };
        let s = Settings::default();
        let name = |e: Error| match e {
            Error::InvalidArgument { name, .. } => name,
            Error::TooMuchMemory { name, .. } => name,
            other => panic!("unexpected {other:?}"),
        };
        assert_eq!(name(subdivide(&sphere, &m, 9, &s).unwrap_err()), "levels");
        let mut bad = m.clone();
        bad.triangles[0][1] = 99;
        assert_eq!(name(subdivide(&sphere, &bad, 1, &s).unwrap_err()), "faces");
        let mut nm = m.clone();
        nm.triangles.push([0, 11, 3]);
        assert_eq!(name(butterfly(&nm, 1, 0.0).unwrap_err()), "faces");
        let mut flipped = m.clone();
        flipped.triangles[0] = [0, 5, 11];
        assert_eq!(name(check_mesh(&flipped).unwrap_err()), "faces");
        let (b, _) = split(&m);
        assert_eq!(name(blend(&m, &b, 0.5).unwrap_err()), "butterfly");
        assert_eq!(name(blend(&m, &m, 1.5).unwrap_err()), "lam");
        assert_eq!(name(blend(&m, &m, f64::NAN).unwrap_err()), "lam");
        let tight = Settings {
            memory_limit: 1 << 20,
            ..Default::default()
        };
        assert_eq!(
            name(subdivide(&sphere, &m, 8, &tight).unwrap_err()),
            "levels"
        );
    }

    #[test]
    fn butterfly_reproduces_planes() {
        let g = grid(8, 0.25);
        for w in [0.0, 1.0 / 16.0, -0.03, 0.1] {
            let levels = butterfly(&g, 3, w).unwrap();
            assert_eq!(levels.len(), 4);
            for (k, m) in levels.iter().enumerate() {
                assert_eq!(m.triangles.len(), g.triangles.len() << (2 * k));
                for p in &m.vertices {
                    assert!((p.z - 0.25).abs() <= 1e-12, "w {w}: z = {}", p.z);
                }
                assert_eq!(&m.vertices[..g.vertices.len()], &g.vertices[..]);
            }
        }
    }

    #[test]
    fn butterfly_regular_weights_and_linear_precision() {
        // On a regular triangular lattice the 10-point stencil reproduces linear functions
        // exactly: every new vertex is the edge midpoint.
        let n = 6u32;
        let h = 3f64.sqrt() / 2.0;
        let mut vertices = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                vertices.push(DVec3::new(i as f64 + 0.5 * j as f64, h * j as f64, 0.0));
            }
        }
        let id = |i: u32, j: u32| j * (n + 1) + i;
        let mut triangles = Vec::new();
        for j in 0..n {
            for i in 0..n {
                triangles.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
                triangles.push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let g = Mesh {
            vertices,
            triangles,
            normals: vec![],
        };
        let (s, parents) = split(&g);
        let levels = butterfly(&g, 1, 0.05).unwrap();
        let interior = |v: u32| {
            let (i, j) = (v % (n + 1), v / (n + 1));
            i > 0 && i < n && j > 0 && j < n
        };
        let mut checked = 0;
        let mut corner_edges = 0;
        for (k, &[a, b]) in parents.iter().enumerate() {
            let on_boundary = |v: u32| !interior(v);
            let boundary_edge = {
                let (ia, ja, ib, jb) = (a % (n + 1), a / (n + 1), b % (n + 1), b / (n + 1));
                (ja == 0 && jb == 0)
                    || (ja == n && jb == n)
                    || (ia == 0 && ib == 0)
                    || (ia == n && ib == n)
            };
            if on_boundary(a) && on_boundary(b) && !boundary_edge {
                // Interior edge across a corner: its ghosts are the lattice's own points.
                corner_edges += 1;
                let mid = 0.5 * (g.vertices[a as usize] + g.vertices[b as usize]);
                let got = levels[1].vertices[g.vertices.len() + k];
                assert!(
                    (got - mid).length() < 1e-12,
                    "corner edge {a}-{b}: {got} vs {mid}"
                );
                continue;
            }
            if !(interior(a) && interior(b)) {
                continue;
            }
            checked += 1;
            let mid = 0.5 * (g.vertices[a as usize] + g.vertices[b as usize]);
            let got = levels[1].vertices[g.vertices.len() + k];
            assert!((got - mid).length() < 1e-12, "edge {a}-{b}: {got} vs {mid}");
        }
        assert!(checked > 50);
        assert_eq!(corner_edges, 2);
        assert_eq!(levels[1].triangles, s.triangles);
    }

    /// The six-face open mesh around the interior edge (0, 1), both of whose ends lie on the
    /// boundary, symmetric under x -> 1 - x and y -> -y: wings 2 (y > 0) and 3 (y < 0), and one
    /// face across each of the edges (0, 2), (1, 2), (0, 3), (1, 3).
    fn bent_strip() -> Mesh {
        let vertices = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(0.5, 1.0, 0.3),
            DVec3::new(0.5, -1.0, 0.3),
            DVec3::new(-0.5, 1.0, 0.7),
            DVec3::new(1.5, 1.0, 0.7),
            DVec3::new(-0.5, -1.0, 0.7),
            DVec3::new(1.5, -1.0, 0.7),
        ];
        let triangles = vec![
            [0, 1, 2],
            [1, 0, 3],
            [0, 2, 4],
            [2, 1, 5],
            [3, 0, 6],
            [1, 3, 7],
        ];
        Mesh {
            vertices,
            triangles,
            normals: vec![],
        }
    }

    #[test]
    fn butterfly_edge_between_boundary_vertices() {
        let m = bent_strip();
        check_mesh(&m).unwrap();
        let rings = Rings::new(&m).unwrap();
        assert!((0..8).all(|v| rings.boundary[v]));
        let p = |i: usize| m.vertices[i];
        for w in [0.0, 1.0 / 16.0, -0.03] {
            let got = butterfly_point(&m, &rings, 0, 1, w);
            // The full stencil: every outer vertex exists here, tension points are 2a - b, 2b - a.
            let want = (p(0) + p(1)) * (0.5 - w)
                + (p(2) + p(3)) * (0.125 + 2.0 * w)
                + (p(4) + p(5) + p(6) + p(7)) * (-0.0625 - w)
                + (p(0) + p(1)) * w;
            assert!((got - want).length() < 1e-15, "w {w}: {got} vs {want}");
            // Symmetric configuration, symmetric answer.
            assert!((got.x - 0.5).abs() < 1e-15 && got.y.abs() < 1e-15, "{got}");
            // Either orientation of the edge gives the same point.
            assert_eq!(got, butterfly_point(&m, &rings, 1, 0, w));
        }
        // With the outer faces removed the four outer vertices are ghosts (reflections), and the
        // single quad's diagonal gets its midpoint whatever the wings.
        let quad = Mesh {
            vertices: m.vertices[..4].to_vec(),
            triangles: vec![[0, 1, 2], [1, 0, 3]],
            normals: vec![],
        };
        let rq = Rings::new(&quad).unwrap();
        for w in [0.0, 0.05] {
            let got = butterfly_point(&quad, &rq, 0, 1, w);
            assert!((got - DVec3::new(0.5, 0.0, 0.0)).length() < 1e-15, "{got}");
        }
        // Levels: face counts, the old vertices kept, and the mirror symmetry kept at every level.
        let levels = butterfly(&m, 3, 0.0).unwrap();
        for (k, l) in levels.iter().enumerate() {
            assert_eq!(l.triangles.len(), 6 << (2 * k));
            assert_eq!(&l.vertices[..8], &m.vertices[..]);
            let key = |v: DVec3| {
                (
                    (v.x * 1e9).round() as i64,
                    (v.y * 1e9).round() as i64,
                    (v.z * 1e9).round() as i64,
                )
            };
            let set: std::collections::HashSet<_> = l.vertices.iter().map(|&v| key(v)).collect();
            for v in &l.vertices {
                assert!(
                    set.contains(&key(DVec3::new(1.0 - v.x, v.y, v.z))),
                    "level {k}: {v}"
                );
                assert!(
                    set.contains(&key(DVec3::new(v.x, -v.y, v.z))),
                    "level {k}: {v}"
                );
            }
        }
    }

    #[test]
    fn butterfly_strip_stays_planar() {
        // A zig-zag strip: every vertex on the boundary, every diagonal an interior edge between
        // two boundary vertices.
        let n = 7u32;
        let mut vertices = Vec::new();
        for i in 0..=n {
            let x = i as f64 + 0.17 * ((i * 5) % 3) as f64;
            vertices.push(DVec3::new(x, 0.1 * (i % 2) as f64, -0.5));
            vertices.push(DVec3::new(x + 0.4, 1.0 + 0.05 * (i % 3) as f64, -0.5));
        }
        let mut triangles = Vec::new();
        for i in 0..n {
            let (a, b, c, d) = (2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 1);
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
        let strip = Mesh {
            vertices,
            triangles,
            normals: vec![],
        };
        for w in [0.0, 1.0 / 16.0] {
            let levels = butterfly(&strip, 3, w).unwrap();
            for (k, l) in levels.iter().enumerate() {
                assert_eq!(l.triangles.len(), strip.triangles.len() << (2 * k));
                for v in &l.vertices {
                    assert!((v.z + 0.5).abs() < 1e-12, "w {w}, level {k}: {v}");
                }
            }
        }
    }

    #[test]
    fn butterfly_closed_mesh_and_blend_identities() {
        let (m, s) = icosahedron_surface();
        let imp = subdivide_surface(&s, &m, 3, &Settings::default()).unwrap();
        let bf = butterfly(&m, 3, 0.0).unwrap();
        for k in 0..=3 {
            let (a, b) = (&imp[k].0, &bf[k]);
            assert_eq!(a.triangles, b.triangles);
            assert!(b.is_closed_oriented());
            let b0 = blend(a, b, 0.0).unwrap();
            let b1 = blend(a, b, 1.0).unwrap();
            assert_eq!(&b0, a);
            assert_eq!(&b1, b);
            let h = blend(a, b, 0.5).unwrap();
            for i in 0..a.vertices.len() {
                let e = 0.5 * (a.vertices[i] + b.vertices[i]);
                assert!((h.vertices[i] - e).length() < 1e-15);
            }
        }
        // Regular icosahedron: butterfly points lie on a sphere by symmetry per level (valence 5
        // stencil at level 1 is symmetric), and stay near the sphere.
        for p in &bf[1].vertices {
            assert!((p.length() - 0.9).abs() < 0.1);
        }
    }
}
