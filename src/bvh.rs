//! A bounding-volume hierarchy over the triangles of a mesh, for the two queries a scan
//! simulation and distances to a true surface need: the first triangle a ray hits
//! ([`Bvh::cast`], [`Bvh::cast_many`]) and the closest point of the mesh to a point
//! ([`Bvh::closest`], [`Bvh::closest_many`]). Batches run on rayon's threads; a query allocates
//! nothing (its stack is an array).
//!
//! The tree is built top-down by the surface area heuristic over 12 bins of the triangles'
//! centroids along each axis; a node of more than [`MAX_LEAF`] triangles that the heuristic would
//! keep whole, or whose centroids coincide, is split at its median instead. Subtrees of more
//! than [`PARALLEL_BUILD`] triangles are built in parallel. Leaves hold their triangles'
//! vertices in leaf order, so a leaf's tests read one contiguous run of memory.

use crate::error::{Error, Result};
use glam::DVec3;
use rayon::prelude::*;

/// Most triangles in a leaf.
pub const MAX_LEAF: usize = 8;
/// Subtrees of more triangles than this are built with their sibling in parallel.
pub const PARALLEL_BUILD: usize = 1 << 14;
/// Bins per axis of the surface area heuristic.
const BINS: usize = 12;
/// Depth of the traversal stacks: the tree is at most this deep (median splits of at most 2³²
/// triangles bound the depth at 32 plus the heuristic's unbalanced splits, which stop at this
/// depth by splitting at the median).
const STACK: usize = 96;
/// Queries per parallel job of the batch queries.
const BATCH: usize = 512;

/// A node: its box, and either its children (`count == 0`: `first` is the left child, the right
/// child follows the left subtree at `right`) or its triangles (`first..first + count` in leaf
/// order).
#[derive(Clone, Copy, Debug)]
struct Node {
    lo: DVec3,
    hi: DVec3,
    first: u32,
    count: u32,
    right: u32,
}

/// The first triangle a ray hits: its ray parameter `t` (the hit is `origin + t × direction`) and
/// its index in the mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// The ray parameter of the hit.
    pub t: f64,
    /// The triangle hit.
    pub triangle: u32,
}

/// The closest point of the mesh to a query point, its distance and the triangle it lies on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Closest {
    /// The closest point of the mesh.
    pub point: DVec3,
    /// Its distance from the query point.
    pub distance: f64,
    /// The triangle it lies on.
    pub triangle: u32,
}

/// A bounding-volume hierarchy over the triangles of a mesh (see the module's documentation).
pub struct Bvh {
    nodes: Vec<Node>,
    /// Each triangle's vertices, in leaf order.
    corners: Vec<[DVec3; 3]>,
    /// The mesh's index of each triangle, in leaf order.
    index: Vec<u32>,
}

/// A triangle's box and centroid, for the build.
#[derive(Clone, Copy)]
struct Item {
    lo: DVec3,
    hi: DVec3,
    centroid: DVec3,
    triangle: u32,
}

fn half_area(lo: DVec3, hi: DVec3) -> f64 {
    let e = (hi - lo).max(DVec3::ZERO);
    e.x * e.y + e.y * e.z + e.z * e.x
}

fn bounds(items: &[Item]) -> (DVec3, DVec3, DVec3, DVec3) {
    let mut b = (
        DVec3::splat(f64::INFINITY),
        DVec3::splat(f64::NEG_INFINITY),
        DVec3::splat(f64::INFINITY),
        DVec3::splat(f64::NEG_INFINITY),
    );
    for it in items {
        b.0 = b.0.min(it.lo);
        b.1 = b.1.max(it.hi);
        b.2 = b.2.min(it.centroid);
        b.3 = b.3.max(it.centroid);
    }
    b
}

/// Where to split `items` (sorted in place so that the left part comes first): the count of the
/// left part, or None for a leaf.
fn split(
    items: &mut [Item],
    lo: DVec3,
    hi: DVec3,
    clo: DVec3,
    chi: DVec3,
    depth: usize,
) -> Option<usize> {
    let n = items.len();
    if n <= 2 {
        return None;
    }
    let extent = chi - clo;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    let median = |items: &mut [Item]| {
        let m = n / 2;
        items.select_nth_unstable_by(m, |a, b| a.centroid[axis].total_cmp(&b.centroid[axis]));
        Some(m)
    };
    if extent[axis] <= 0.0 {
        // Coincident centroids: the heuristic cannot separate them.
        return if n > MAX_LEAF { median(items) } else { None };
    }
    if depth + 1 >= STACK / 2 {
        return median(items);
    }
    // The heuristic over BINS bins along each axis: the cheapest plane.
    let mut best = (f64::INFINITY, 0usize, 0usize);
    for a in 0..3 {
        if extent[a] <= 0.0 {
            continue;
        }
        let scale = BINS as f64 / extent[a];
        let bin = |c: f64| (((c - clo[a]) * scale) as usize).min(BINS - 1);
        let mut count = [0usize; BINS];
        let mut blo = [DVec3::splat(f64::INFINITY); BINS];
        let mut bhi = [DVec3::splat(f64::NEG_INFINITY); BINS];
        for it in items.iter() {
            let b = bin(it.centroid[a]);
            count[b] += 1;
            blo[b] = blo[b].min(it.lo);
            bhi[b] = bhi[b].max(it.hi);
        }
        // Costs of the planes after bins 0..BINS-1 from the right, then the left.
        let mut right_cost = [0.0; BINS];
        let (mut rlo, mut rhi, mut rn) = (
            DVec3::splat(f64::INFINITY),
            DVec3::splat(f64::NEG_INFINITY),
            0,
        );
        for b in (1..BINS).rev() {
            rlo = rlo.min(blo[b]);
            rhi = rhi.max(bhi[b]);
            rn += count[b];
            right_cost[b - 1] = half_area(rlo, rhi) * rn as f64;
        }
        let (mut llo, mut lhi, mut ln) = (
            DVec3::splat(f64::INFINITY),
            DVec3::splat(f64::NEG_INFINITY),
            0,
        );
        for b in 0..BINS - 1 {
            llo = llo.min(blo[b]);
            lhi = lhi.max(bhi[b]);
            ln += count[b];
            if ln == 0 || ln == n {
                continue;
            }
            let cost = half_area(llo, lhi) * ln as f64 + right_cost[b];
            if cost < best.0 {
                best = (cost, a, b);
            }
        }
    }
    // A leaf costs one test per triangle; a split one traversal step plus its children's tests.
    let leaf_cost = n as f64 * half_area(lo, hi);
    if !best.0.is_finite() || (best.0 + half_area(lo, hi) >= leaf_cost && n <= MAX_LEAF) {
        return if n > MAX_LEAF { median(items) } else { None };
    }
    let (a, b) = (best.1, best.2);
    let scale = BINS as f64 / extent[a];
    let left = |it: &Item| ((((it.centroid[a] - clo[a]) * scale) as usize).min(BINS - 1)) <= b;
    // Partition in place: the left part first.
    let mut i = 0;
    let mut j = n;
    while i < j {
        if left(&items[i]) {
            i += 1;
        } else {
            j -= 1;
            items.swap(i, j);
        }
    }
    Some(i)
}

/// Builds the subtree over `items` into `nodes` (its root first), with leaf-order offsets from
/// `offset`.
fn build(items: &mut [Item], offset: u32, depth: usize, nodes: &mut Vec<Node>) {
    let (lo, hi, clo, chi) = bounds(items);
    let root = nodes.len();
    nodes.push(Node {
        lo,
        hi,
        first: offset,
        count: items.len() as u32,
        right: 0,
    });
    let Some(m) = split(items, lo, hi, clo, chi, depth) else {
        return;
    };
    let (l, r) = items.split_at_mut(m);
    let roff = offset + m as u32;
    if items_len_parallel(l.len(), r.len()) {
        let (mut ln, mut rn) = (Vec::new(), Vec::new());
        rayon::join(
            || build(l, offset, depth + 1, &mut ln),
            || build(r, roff, depth + 1, &mut rn),
        );
        let base = nodes.len() as u32;
        append_shifted(nodes, ln, base);
        let rbase = nodes.len() as u32;
        append_shifted(nodes, rn, rbase);
        nodes[root].first = base;
        nodes[root].right = rbase;
    } else {
        build(l, offset, depth + 1, nodes);
        let rbase = nodes.len() as u32;
        build(r, roff, depth + 1, nodes);
        nodes[root].first = root as u32 + 1;
        nodes[root].right = rbase;
    }
    nodes[root].count = 0;
}

fn items_len_parallel(l: usize, r: usize) -> bool {
    l.min(r) > PARALLEL_BUILD
}

/// Appends a subtree built on its own (child indices from 0) with its indices moved by `base`.
fn append_shifted(nodes: &mut Vec<Node>, sub: Vec<Node>, base: u32) {
    nodes.extend(sub.into_iter().map(|mut n| {
        if n.count == 0 {
            n.first += base;
            n.right += base;
        }
        n
    }));
}

/// The squared distance from `p` to the box `lo..hi` (0 inside).
#[inline]
fn box_distance_squared(p: DVec3, lo: DVec3, hi: DVec3) -> f64 {
    let d = (lo - p).max(p - hi).max(DVec3::ZERO);
    d.length_squared()
}

/// The ray parameter at which the ray enters the box, if it meets it before `t_max`.
#[inline]
fn ray_box(origin: DVec3, inv: DVec3, lo: DVec3, hi: DVec3, t_max: f64) -> Option<f64> {
    let a = (lo - origin) * inv;
    let b = (hi - origin) * inv;
    let (mut near, mut far) = (0.0f64, t_max);
    for k in 0..3 {
        // NaN is 0 × ∞: a ray parallel to the axis' planes, in one of them, so within the slab.
        if a[k].is_nan() || b[k].is_nan() {
            continue;
        }
        near = near.max(a[k].min(b[k]));
        far = far.min(a[k].max(b[k]));
    }
    (near <= far).then_some(near)
}

/// Möller–Trumbore: the ray parameter of the ray's hit on the triangle, if positive.
#[inline]
fn ray_triangle(origin: DVec3, dir: DVec3, v: &[DVec3; 3]) -> Option<f64> {
    let e1 = v[1] - v[0];
    let e2 = v[2] - v[0];
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let s = origin - v[0];
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let w = dir.dot(q) * inv;
    if w < 0.0 || u + w > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    (t > 0.0).then_some(t)
}

/// The closest point of triangle `v` to `p` (Ericson, "Real-Time Collision Detection", 5.1.5).
pub fn closest_on_triangle(p: DVec3, v: &[DVec3; 3]) -> DVec3 {
    let (a, b, c) = (v[0], v[1], v[2]);
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = va + vb + vc;
    if denom == 0.0 || !denom.is_finite() {
        // A degenerate triangle (a segment or a point): the closest of its edges' points.
        let seg = |a: DVec3, b: DVec3| {
            let d = b - a;
            let l = d.length_squared();
            if l > 0.0 {
                a + d * ((p - a).dot(d) / l).clamp(0.0, 1.0)
            } else {
                a
            }
        };
        return [seg(a, b), seg(b, c), seg(c, a)]
            .into_iter()
            .min_by(|x, y| {
                (*x - p)
                    .length_squared()
                    .total_cmp(&(*y - p).length_squared())
            })
            .unwrap_or(a);
    }
    let inv = 1.0 / denom;
    a + ab * (vb * inv) + ac * (vc * inv)
}

impl Bvh {
    /// The hierarchy over `triangles` (vertex indices into `vertices`). Errors name the argument:
    /// no triangles, an index out of range, a vertex that is not finite, 2³² or more triangles.
    pub fn new(vertices: &[DVec3], triangles: &[[u32; 3]]) -> Result<Bvh> {
        if triangles.is_empty() {
            return Err(Error::invalid("faces", "no triangles"));
        }
        if triangles.len() >= u32::MAX as usize {
            return Err(Error::invalid("faces", "2³² or more triangles"));
        }
        crate::error::check_finite_points("vertices", vertices)?;
        if let Some((k, t)) = triangles
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&v| v as usize >= vertices.len()))
        {
            return Err(Error::invalid(
                "faces",
                format!(
                    "face {k} has index {} out of range for {} vertices",
                    t.iter().max().unwrap(),
                    vertices.len()
                ),
            ));
        }
        let mut items: Vec<Item> = triangles
            .par_iter()
            .enumerate()
            .map(|(k, t)| {
                let v = t.map(|i| vertices[i as usize]);
                Item {
                    lo: v[0].min(v[1]).min(v[2]),
                    hi: v[0].max(v[1]).max(v[2]),
                    centroid: (v[0] + v[1] + v[2]) / 3.0,
                    triangle: k as u32,
                }
            })
            .collect();
        let mut nodes = Vec::with_capacity(2 * triangles.len() / 2 + 1);
        build(&mut items, 0, 0, &mut nodes);
        let index: Vec<u32> = items.par_iter().map(|it| it.triangle).collect();
        let corners = index
            .par_iter()
            .map(|&k| triangles[k as usize].map(|i| vertices[i as usize]))
            .collect();
        Ok(Bvh {
            nodes,
            corners,
            index,
        })
    }

    /// The number of triangles.
    pub fn len(&self) -> usize {
        self.index.len()
    }

    /// Whether there are no triangles (never: [`Bvh::new`] refuses them).
    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    /// The first triangle hit by the ray `origin + t × direction`, `t > 0` (`direction` need not
    /// be a unit vector; `t` is in its units). None when the ray misses, or is not finite.
    pub fn cast(&self, origin: DVec3, direction: DVec3) -> Option<Hit> {
        if !origin.is_finite() || !direction.is_finite() || direction == DVec3::ZERO {
            return None;
        }
        let inv = direction.recip();
        let mut best = f64::INFINITY;
        let mut hit = u32::MAX;
        let mut stack = [0u32; STACK];
        let mut top = 0;
        let root = &self.nodes[0];
        ray_box(origin, inv, root.lo, root.hi, best)?;
        stack[0] = 0;
        top += 1;
        while top > 0 {
            top -= 1;
            let node = &self.nodes[stack[top] as usize];
            if node.count > 0 {
                let first = node.first as usize;
                for k in first..first + node.count as usize {
                    if let Some(t) = ray_triangle(origin, direction, &self.corners[k]) {
                        if t < best {
                            best = t;
                            hit = k as u32;
                        }
                    }
                }
                continue;
            }
            let (l, r) = (node.first, node.right);
            let (nl, nr) = (&self.nodes[l as usize], &self.nodes[r as usize]);
            let tl = ray_box(origin, inv, nl.lo, nl.hi, best);
            let tr = ray_box(origin, inv, nr.lo, nr.hi, best);
            // The nearer child is popped first.
            match (tl, tr) {
                (Some(a), Some(b)) => {
                    let (near, far) = if a <= b { (l, r) } else { (r, l) };
                    stack[top] = far;
                    stack[top + 1] = near;
                    top += 2;
                }
                (Some(_), None) => {
                    stack[top] = l;
                    top += 1;
                }
                (None, Some(_)) => {
                    stack[top] = r;
                    top += 1;
                }
                (None, None) => {}
            }
        }
        (hit != u32::MAX).then(|| Hit {
            t: best,
            triangle: self.index[hit as usize],
        })
    }

    /// [`Bvh::cast`] for many rays (`origins[i]`, `directions[i]`), in parallel.
    pub fn cast_many(&self, origins: &[DVec3], directions: &[DVec3]) -> Result<Vec<Option<Hit>>> {
        if origins.len() != directions.len() {
            return Err(Error::invalid(
                "directions",
                format!(
                    "{} directions for {} origins",
                    directions.len(),
                    origins.len()
                ),
            ));
        }
        let mut out = vec![None; origins.len()];
        out.par_chunks_mut(BATCH)
            .zip(origins.par_chunks(BATCH).zip(directions.par_chunks(BATCH)))
            .for_each(|(out, (o, d))| {
                for ((h, o), d) in out.iter_mut().zip(o).zip(d) {
                    *h = self.cast(*o, *d);
                }
            });
        crate::cancel::check()?;
        Ok(out)
    }

    /// The closest point of the mesh to `p` (finite), its distance and its triangle (the
    /// smallest leaf-order one among equally close triangles found first).
    pub fn closest(&self, p: DVec3) -> Closest {
        let mut best = f64::INFINITY;
        let mut point = p;
        let mut tri = 0u32;
        let mut stack = [(0u32, 0.0f64); STACK];
        stack[0] = (
            0,
            box_distance_squared(p, self.nodes[0].lo, self.nodes[0].hi),
        );
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let (n, d) = stack[top];
            if d >= best {
                continue;
            }
            let node = &self.nodes[n as usize];
            if node.count > 0 {
                let first = node.first as usize;
                for k in first..first + node.count as usize {
                    let q = closest_on_triangle(p, &self.corners[k]);
                    let d = (q - p).length_squared();
                    if d < best {
                        best = d;
                        point = q;
                        tri = k as u32;
                    }
                }
                continue;
            }
            let (l, r) = (node.first, node.right);
            let dl = box_distance_squared(p, self.nodes[l as usize].lo, self.nodes[l as usize].hi);
            let dr = box_distance_squared(p, self.nodes[r as usize].lo, self.nodes[r as usize].hi);
            let ((near, dn), (far, df)) = if dl <= dr {
                ((l, dl), (r, dr))
            } else {
                ((r, dr), (l, dl))
            };
            if df < best {
                stack[top] = (far, df);
                top += 1;
            }
            if dn < best {
                stack[top] = (near, dn);
                top += 1;
            }
        }
        Closest {
            point,
            distance: best.sqrt(),
            triangle: self.index[tri as usize],
        }
    }

    /// [`Bvh::closest`] for many points, in parallel. Errors when a point is not finite.
    pub fn closest_many(&self, points: &[DVec3]) -> Result<Vec<Closest>> {
        crate::error::check_finite_points("points", points)?;
        let mut out = vec![
            Closest {
                point: DVec3::ZERO,
                distance: 0.0,
                triangle: 0
            };
            points.len()
        ];
        out.par_chunks_mut(BATCH)
            .zip(points.par_chunks(BATCH))
            .for_each(|(out, p)| {
                for (c, p) in out.iter_mut().zip(p) {
                    *c = self.closest(*p);
                }
            });
        crate::cancel::check()?;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{fibonacci_sphere, random_points};

    /// The unit cube [-1, 1]³ as 12 triangles, outward.
    fn cube() -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let v: Vec<DVec3> = (0..8)
            .map(|i| {
                DVec3::new(
                    if i & 1 == 0 { -1.0 } else { 1.0 },
                    if i & 2 == 0 { -1.0 } else { 1.0 },
                    if i & 4 == 0 { -1.0 } else { 1.0 },
                )
            })
            .collect();
        let quads = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let t = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        (v, t)
    }

    /// A UV sphere of radius 1 (`rings` × `segments`).
    fn sphere(rings: u32, segments: u32) -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let mut v = vec![DVec3::Z, -DVec3::Z];
        for i in 1..rings {
            let th = std::f64::consts::PI * i as f64 / rings as f64;
            for j in 0..segments {
                let ph = std::f64::consts::TAU * j as f64 / segments as f64;
                v.push(DVec3::new(
                    th.sin() * ph.cos(),
                    th.sin() * ph.sin(),
                    th.cos(),
                ));
            }
        }
        let at = |i: u32, j: u32| 2 + (i - 1) * segments + j % segments;
        let mut t = vec![];
        for j in 0..segments {
            t.push([0, at(1, j), at(1, j + 1)]);
            t.push([1, at(rings - 1, j + 1), at(rings - 1, j)]);
            for i in 1..rings - 1 {
                t.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                t.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        (v, t)
    }

    #[test]
    fn rays_hit_the_cube_where_the_planes_are() {
        let (v, t) = cube();
        let bvh = Bvh::new(&v, &t).unwrap();
        let origins = random_points(500, -0.9, 0.9, 3);
        for (o, d) in origins.iter().zip(fibonacci_sphere(500)) {
            // From outside, towards a point inside: the first face the ray meets.
            let from = *o - d * 5.0;
            let h = bvh
                .cast(from, d)
                .expect("a ray through the cube's inside hits it");
            // The exit parameter of the slab [-1, 1]³ along -d from `o`, entered from `from`.
            let t_enter = (0..3)
                .map(|k| {
                    if d[k] == 0.0 {
                        f64::NEG_INFINITY
                    } else {
                        ((-d[k].signum()) - from[k]) / d[k]
                    }
                })
                .fold(f64::NEG_INFINITY, f64::max);
            assert!((h.t - t_enter).abs() < 1e-12, "{} vs {}", h.t, t_enter);
            let p = from + d * h.t;
            // The face the hit triangle lies on holds the hit point.
            let tri = t[h.triangle as usize].map(|i| v[i as usize]);
            let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]).normalize();
            assert!((p - tri[0]).dot(n).abs() < 1e-12);
            // From inside, the ray hits the far side: t is the exit distance.
            let inside = bvh.cast(*o, d).unwrap();
            assert!((o + d * inside.t).abs().max_element() > 1.0 - 1e-12);
        }
        // Rays that pass the cube, or point away from it, miss.
        assert!(bvh.cast(DVec3::new(0.0, 3.0, 0.0), DVec3::X).is_none());
        assert!(bvh.cast(DVec3::new(0.0, 0.0, 3.0), DVec3::Z).is_none());
        assert!(bvh.cast(DVec3::new(0.0, 0.0, 3.0), DVec3::ZERO).is_none());
        // A ray in the plane of a face of every box (y = 0 and z = 0 are the cube's diagonal
        // planes, on which its triangles' edges lie) hits.
        let h = bvh.cast(DVec3::new(3.0, 0.0, 0.0), -DVec3::X).unwrap();
        assert!((h.t - 2.0).abs() < 1e-12);
        let h = bvh.cast(DVec3::new(3.0, 1.0, 0.0), -DVec3::X).unwrap();
        assert!((h.t - 2.0).abs() < 1e-12);
    }

    #[test]
    fn rays_hit_a_fine_sphere_at_the_analytic_distance() {
        let (v, t) = sphere(200, 400);
        let bvh = Bvh::new(&v, &t).unwrap();
        let dirs = fibonacci_sphere(2000);
        let hits = bvh
            .cast_many(
                &dirs.iter().map(|d| *d * 3.0).collect::<Vec<_>>(),
                &dirs.iter().map(|d| -*d).collect::<Vec<_>>(),
            )
            .unwrap();
        for h in hits {
            // The polygon's chord is within 1 − cos(π/200) of the sphere.
            let h = h.expect("every ray towards the centre hits");
            assert!((h.t - 2.0).abs() < 2e-4, "{}", h.t);
        }
        // Rays that graze past the sphere miss; off-centre rays hit at the analytic distance.
        let o = DVec3::new(0.0, 1.01, 3.0);
        assert!(bvh.cast(o, -DVec3::Z).is_none());
        let o = DVec3::new(0.0, 0.6, 3.0);
        let h = bvh.cast(o, -DVec3::Z).unwrap();
        assert!((h.t - (3.0 - 0.8)).abs() < 2e-4);
    }

    #[test]
    fn closest_points_agree_with_brute_force() {
        for seed in 1..4u64 {
            // A random soup of triangles, and query points around and inside it.
            let v = random_points(900, -1.0, 1.0, seed);
            let t: Vec<[u32; 3]> = (0..300).map(|k| [3 * k, 3 * k + 1, 3 * k + 2]).collect();
            let bvh = Bvh::new(&v, &t).unwrap();
            let q = random_points(400, -1.5, 1.5, seed + 10);
            let got = bvh.closest_many(&q).unwrap();
            for (p, c) in q.iter().zip(&got) {
                let brute = t
                    .iter()
                    .map(|t| (closest_on_triangle(*p, &t.map(|i| v[i as usize])) - *p).length())
                    .fold(f64::INFINITY, f64::min);
                assert!((c.distance - brute).abs() < 1e-12);
                assert!(((c.point - *p).length() - c.distance).abs() < 1e-12);
                let tri = t[c.triangle as usize].map(|i| v[i as usize]);
                assert!((closest_on_triangle(*p, &tri) - c.point).length() < 1e-12);
            }
        }
    }

    #[test]
    fn closest_on_triangle_is_the_minimum_over_the_triangle() {
        let tri = [DVec3::ZERO, DVec3::X, DVec3::new(0.3, 1.0, 0.0)];
        for p in random_points(300, -1.0, 2.0, 5) {
            let c = closest_on_triangle(p, &tri);
            // No barycentric sample of the triangle is closer.
            for i in 0..=20 {
                for j in 0..=20 - i {
                    let (a, b) = (i as f64 / 20.0, j as f64 / 20.0);
                    let q = tri[0] + (tri[1] - tri[0]) * a + (tri[2] - tri[0]) * b;
                    assert!((q - p).length() >= (c - p).length() - 1e-12);
                }
            }
        }
        // Degenerate triangles: a segment and a point.
        let seg = [DVec3::ZERO, DVec3::X, DVec3::X * 2.0];
        assert!(
            (closest_on_triangle(DVec3::new(1.5, 1.0, 0.0), &seg) - DVec3::X * 1.5).length()
                < 1e-12
        );
        let pt = [DVec3::ONE; 3];
        assert_eq!(closest_on_triangle(DVec3::ZERO, &pt), DVec3::ONE);
    }

    #[test]
    fn bad_meshes_are_refused_naming_the_argument() {
        let (v, t) = cube();
        assert!(matches!(
            Bvh::new(&v, &[]),
            Err(Error::InvalidArgument { name: "faces", .. })
        ));
        assert!(matches!(
            Bvh::new(&v[..7], &t),
            Err(Error::InvalidArgument { name: "faces", .. })
        ));
        let mut w = v.clone();
        w[3].x = f64::NAN;
        assert!(matches!(
            Bvh::new(&w, &t),
            Err(Error::NotFinite {
                name: "vertices",
                ..
            })
        ));
        let bvh = Bvh::new(&v, &t).unwrap();
        assert!(bvh.cast_many(&[DVec3::ZERO], &[]).is_err());
    }

    /// A large mesh is built in parallel (subtrees above PARALLEL_BUILD) and gives the same
    /// answers as brute force.
    #[test]
    fn a_parallel_build_answers_as_brute_force() {
        let (v, t) = sphere(150, 300);
        assert!(t.len() > 4 * PARALLEL_BUILD);
        let bvh = Bvh::new(&v, &t).unwrap();
        for p in random_points(40, -1.5, 1.5, 8) {
            let brute = t
                .iter()
                .map(|t| (closest_on_triangle(p, &t.map(|i| v[i as usize])) - p).length())
                .fold(f64::INFINITY, f64::min);
            assert!((bvh.closest(p).distance - brute).abs() < 1e-12);
        }
    }
}
