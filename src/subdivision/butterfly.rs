//! The modified butterfly scheme (Zorin, Schröder & Sweldens 1996; Jin §4): the same
//! connectivity as [`subdivide`](super::subdivide), positions from stencils of the mesh alone.

use super::checks::{check_levels, check_mesh};
use super::settings::SubdivisionSettings;
use super::split::split;
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use glam::DVec3;
use rayon::prelude::*;

/// Ordered one-ring of every vertex, from the oriented triangles: `rings[v]` lists the neighbours
/// counter-clockwise; `boundary[v]` tells whether the ring is an open fan (first and last
/// neighbours then lie across boundary edges).
pub(super) struct Rings {
    rings: Vec<Vec<u32>>,
    pub(super) boundary: Vec<bool>,
}

impl Rings {
    pub(super) fn new(mesh: &Mesh) -> Result<Rings> {
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
pub(super) fn butterfly_point(mesh: &Mesh, rings: &Rings, a: u32, b: u32, w: f64) -> DVec3 {
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
/// numbering are those of [`split`](super::split), so vertex `i` matches vertex `i` of
/// [`subdivide`](super::subdivide).
///
/// Edges between two interior vertices of valence 6 use the 10-point stencil (a: 1/2 − w,
/// b: 1/8 + 2w, c: −1/16 − w, d: w); an end of another valence uses Zorin's stencil of that
/// vertex (the two stencils averaged when both ends are extraordinary); boundary edges use the
/// four-point scheme (−1/16, 9/16, 9/16, −1/16); an interior edge with one end on the boundary
/// uses the stencil of its interior end. An interior edge joining two boundary vertices uses the
/// 10-point stencil with ghost vertices in place of the missing ones (see `boundary_butterfly`).
/// Normals are the area-weighted face normals. Reports every vertex placed to
/// [`crate::cancel::advance`] ([`vertex_count`](super::vertex_count) in all).
pub fn butterfly(control: &Mesh, levels: usize, w: f64) -> Result<Vec<Mesh>> {
    check_mesh(control)?;
    check_levels(control, levels, SubdivisionSettings::default().memory_limit)?;
    if !w.is_finite() {
        return Err(Error::invalid("w", format!("must be finite, got {w}")));
    }
    let mut mesh = control.clone();
    mesh.normals = mesh.face_normals_at_vertices();
    let mut out = vec![mesh.clone()];
    crate::cancel::advance(mesh.vertices.len() as u64)?;
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
        crate::cancel::advance(pts.len() as u64)?;
        next.normals = next.face_normals_at_vertices();
        out.push(next.clone());
        mesh = next;
    }
    Ok(out)
}
