//! Marching-cubes case table, generated entirely by code.
//!
//! A cell of the sampling grid is a unit cube with 8 corners. Each corner is either
//! inside the surface (field < 0) or outside, which gives 256 possible cases. For each
//! case this module decides which triangles, with vertices on the cube edges whose two
//! ends have opposite signs ("crossed" edges), approximate the surface inside the cell.
//! Nothing here is typed in by hand; the table is derived as follows (the approach of
//! Triquet et al., "Fast polygonization of implicit surfaces", sections 4.5 and 4.6):
//!
//! 1. **Symmetries.** Three quarter turns (about x, y and z) are written as permutations
//!    of the 8 corners. Composing them until nothing new appears yields the 24 rotations
//!    of the cube. Each corner permutation induces a permutation of the 12 edges and of
//!    the 6 faces.
//! 2. **Base configurations.** Two cases are equivalent when a rotation maps one onto the
//!    other. Rotations alone (no mirror images, no inside/outside swap, so that the
//!    orientation of triangles and the treatment of ambiguous faces are preserved) split
//!    the 256 cases into 23 classes. The smallest case index of each class is taken as
//!    its representative, the "base configuration".
//! 3. **Triangulating a base configuration.** Each face is handled on its own: from the
//!    signs of its 4 corners, the face receives 0, 1 or 2 segments joining crossed edges
//!    of that face. When two diagonally opposite corners are inside and the other two
//!    outside, the face is ambiguous and the user's [`Ambiguity`] choice decides whether
//!    the inside corners are cut off separately or joined through the face. Segments are
//!    directed so that, looking at the face from outside the cube, the inside corners lie
//!    on the right. Every crossed edge belongs to exactly two faces and is the start of a
//!    segment on one of them and the end of a segment on the other, so the segments
//!    chain into closed loops. Each loop is a (generally non planar) polygon whose
//!    vertices are taken at the edge midpoints; it is triangulated by dynamic programming
//!    over all its triangulations, choosing the one whose worst triangle is best. The
//!    score of a triangle is its smallest angle; triangles whose normal disagrees with
//!    the gradient of the trilinear interpolant of the corner signs are heavily
//!    penalised, and diagonals joining two vertices of the same cube face are forbidden
//!    (they would lie on the face and break the agreement with the neighbouring cell).
//! 4. **All other cases.** A case is obtained from its base configuration by a rotation;
//!    mapping the base triangles' edge indices through that rotation's edge permutation
//!    gives its triangles. Rotations preserve orientation, so the winding stays correct,
//!    and the face rule is invariant under rotation, so every case remains consistent
//!    with its neighbours.
//!
//! Triangles are wound so that the normal `(b - a) x (c - a)` points from the inside
//! toward the outside (toward increasing field values).

use std::sync::OnceLock;

/// How a cube face whose two diagonally opposite corners are inside and the other two outside is split.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum Ambiguity {
    /// The two inside corners are cut off separately (two segments, each around one inside corner). Default.
    #[default]
    Separate,
    /// The two inside corners are joined through the face (each outside corner is cut off by its own segment).
    Join,
}

/// Corner k of the unit cell sits at offset (k & 1, (k >> 1) & 1, (k >> 2) & 1): bit 0 = x, bit 1 = y, bit 2 = z.
pub const CORNERS: [[u8; 3]; 8] = make_corners();

/// Edge e joins CORNER indices `EDGES[e][0]` (lower end) and `EDGES[e][1]` (upper end along the edge's axis).
/// Edges 0..4 run along x, 4..8 along y, 8..12 along z. Within an axis group the index is
/// (first other coordinate) + 2*(second other coordinate), the "other" axes taken in increasing order:
/// x-edges: e = y + 2z; y-edges: e = 4 + x + 2z; z-edges: e = 8 + x + 2y.
pub const EDGES: [[u8; 2]; 12] = make_edges();

/// Axis (0 = x, 1 = y, 2 = z) of each edge.
pub const EDGE_AXIS: [u8; 12] = make_edge_axes();

/// Faces: f = 2*axis + side, side 0 = the face at coordinate 0 on that axis, side 1 = at coordinate 1.
/// `FACE_CORNERS[f]` lists that face's 4 corners in cyclic order, counter-clockwise when the
/// face is seen from outside the cube, starting with the face's lowest corner index.
pub const FACE_CORNERS: [[u8; 4]; 6] = make_face_corners();

/// The two axes other than `axis`, in increasing order.
const fn other_axes(axis: usize) -> (usize, usize) {
    match axis {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    }
}

const fn make_corners() -> [[u8; 3]; 8] {
    let mut corners = [[0u8; 3]; 8];
    let mut k = 0;
    while k < 8 {
        corners[k] = [(k & 1) as u8, ((k >> 1) & 1) as u8, ((k >> 2) & 1) as u8];
        k += 1;
    }
    corners
}

const fn make_edges() -> [[u8; 2]; 12] {
    let mut edges = [[0u8; 2]; 12];
    let mut axis = 0;
    while axis < 3 {
        let (u, v) = other_axes(axis);
        let mut i = 0;
        while i < 4 {
            let lower = ((i & 1) << u) | (((i >> 1) & 1) << v);
            edges[4 * axis + i] = [lower as u8, (lower | (1 << axis)) as u8];
            i += 1;
        }
        axis += 1;
    }
    edges
}

const fn make_edge_axes() -> [u8; 12] {
    let mut axes = [0u8; 12];
    let mut e = 0;
    while e < 12 {
        axes[e] = (e / 4) as u8;
        e += 1;
    }
    axes
}

const fn make_face_corners() -> [[u8; 4]; 6] {
    let mut faces = [[0u8; 4]; 6];
    let mut f = 0;
    while f < 6 {
        let axis = f / 2;
        let side = f % 2;
        let (u, v) = other_axes(axis);
        let base = side << axis;
        // Walking (0,0) -> (1,0) -> (1,1) -> (0,1) in the (u, v) plane turns
        // counter-clockwise about u x v, which is +axis for x and z but -y for y.
        // Seen from outside, the face normal is +axis on side 1 and -axis on side 0.
        let forward = (side == 1) != (axis == 1);
        let (du, dv) = if forward {
            (1 << u, 1 << v)
        } else {
            (1 << v, 1 << u)
        };
        faces[f] = [
            base as u8,
            (base | du) as u8,
            (base | du | dv) as u8,
            (base | dv) as u8,
        ];
        f += 1;
    }
    faces
}

/// Whether corner `corner` is inside in case `case`.
fn is_inside(case: u8, corner: u8) -> bool {
    (case >> corner) & 1 == 1
}

/// The edge joining corners `a` and `b`, if they are adjacent.
fn edge_between(a: u8, b: u8) -> Option<u8> {
    let diff = a ^ b;
    if a >= 8 || b >= 8 || diff.count_ones() != 1 {
        return None;
    }
    let axis = diff.trailing_zeros() as usize;
    let lower = a.min(b);
    let (u, v) = other_axes(axis);
    Some((4 * axis) as u8 + ((lower >> u) & 1) + 2 * ((lower >> v) & 1))
}

/// Bit mask of the two faces that contain edge `e`.
fn edge_faces(e: u8) -> u8 {
    let axis = EDGE_AXIS[e as usize] as usize;
    let lower = EDGES[e as usize][0];
    let (u, v) = other_axes(axis);
    (1 << (2 * u + ((lower >> u) & 1) as usize)) | (1 << (2 * v + ((lower >> v) & 1) as usize))
}
/// Bit f set when face f has corners of both signs in `case`.
fn mixed_faces(case: u8) -> u8 {
    let mut mask = 0;
    for (f, corners) in FACE_CORNERS.iter().enumerate() {
        let inside = corners.iter().filter(|&&c| is_inside(case, c)).count();
        if inside != 0 && inside != 4 {
            mask |= 1 << f;
        }
    }
    mask
}

/// Midpoint of edge `e` in cell coordinates.
fn edge_midpoint(e: u8) -> [f64; 3] {
    let [a, b] = EDGES[e as usize];
    let (pa, pb) = (CORNERS[a as usize], CORNERS[b as usize]);
    [0, 1, 2].map(|i| 0.5 * f64::from(pa[i] + pb[i]))
}

/// Gradient at `p` of the trilinear interpolant of corner values -1 (inside) and +1 (outside).
fn field_gradient(case: u8, p: [f64; 3]) -> [f64; 3] {
    let mut grad = [0.0; 3];
    for (k, corner) in CORNERS.iter().enumerate() {
        let value = if is_inside(case, k as u8) { -1.0 } else { 1.0 };
        // Weight of this corner along each axis, and its derivative.
        let weight = |i: usize| {
            if corner[i] == 1 {
                p[i]
            } else {
                1.0 - p[i]
            }
        };
        let slope = |i: usize| if corner[i] == 1 { 1.0 } else { -1.0 };
        grad[0] += value * slope(0) * weight(1) * weight(2);
        grad[1] += value * weight(0) * slope(1) * weight(2);
        grad[2] += value * weight(0) * weight(1) * slope(2);
    }
    grad
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Normal `(b - a) x (c - a)` of a triangle given by edge indices, vertices at edge midpoints.
fn triangle_normal(tri: [u8; 3]) -> [f64; 3] {
    let [a, b, c] = tri.map(edge_midpoint);
    cross(sub(b, a), sub(c, a))
}

/// Centroid of a triangle given by edge indices, vertices at edge midpoints.
fn triangle_centroid(tri: [u8; 3]) -> [f64; 3] {
    let [a, b, c] = tri.map(edge_midpoint);
    [0, 1, 2].map(|i| (a[i] + b[i] + c[i]) / 3.0)
}

/// The directed segments that the face rule draws on face `face` for `case`.
///
/// Walking counter-clockwise around the face (seen from outside), every side whose ends
/// have different signs is either an *entry* (outside corner, then inside corner) or an
/// *exit* (inside, then outside). Each segment starts at an entry and ends at an exit,
/// which puts the inside corners on its right when seen from outside. An entry is paired
/// with the first exit found walking forward ([`Ambiguity::Separate`]: the segment wraps
/// the run of inside corners that follows the entry) or walking backward
/// ([`Ambiguity::Join`]: the segment wraps the outside corner that precedes the entry).
/// With a single entry both walks find the same exit, so the choice only matters on
/// ambiguous faces.
fn face_segments(case: u8, face: usize, ambiguity: Ambiguity) -> Vec<[u8; 2]> {
    let corners = FACE_CORNERS[face];
    let inside = |i: usize| is_inside(case, corners[i % 4]);
    let side_edge = |i: usize| edge_between(corners[i], corners[(i + 1) % 4]).expect("face side");
    let is_exit = |i: usize| inside(i) && !inside(i + 1);
    let step = match ambiguity {
        Ambiguity::Separate => 1,
        Ambiguity::Join => 3,
    };
    (0..4)
        .filter(|&i| !inside(i) && inside(i + 1))
        .map(|entry| {
            let mut exit = (entry + step) % 4;
            while !is_exit(exit) {
                exit = (exit + step) % 4;
            }
            [side_edge(entry), side_edge(exit)]
        })
        .collect()
}
/// Chains the face segments of `case` into closed loops of edge indices.
fn case_loops(case: u8, ambiguity: Ambiguity) -> Vec<Vec<u8>> {
    const NONE: u8 = u8::MAX;
    let mut next = [NONE; 12];
    let mut has_incoming = [false; 12];
    for face in 0..6 {
        for [from, to] in face_segments(case, face, ambiguity) {
            assert_eq!(next[from as usize], NONE, "edge {from} starts two segments");
            assert!(!has_incoming[to as usize], "edge {to} ends two segments");
            next[from as usize] = to;
            has_incoming[to as usize] = true;
        }
    }
    let mut visited = [false; 12];
    let mut loops = Vec::new();
    for start in 0..12u8 {
        if next[start as usize] == NONE || visited[start as usize] {
            continue;
        }
        let mut ring = Vec::new();
        let mut e = start;
        while !visited[e as usize] {
            visited[e as usize] = true;
            ring.push(e);
            e = next[e as usize];
            assert_ne!(e, NONE, "open chain of segments");
        }
        assert_eq!(e, start, "segments do not close into a loop");
        loops.push(ring);
    }
    loops
}

/// Score of a triangle for the loop triangulation: its smallest angle (radians), lowered
/// by 10 when its normal does not point along the interpolated field's gradient.
fn triangle_quality(case: u8, tri: [u8; 3]) -> f64 {
    let p = tri.map(edge_midpoint);
    let mut min_angle = f64::INFINITY;
    for i in 0..3 {
        let u = sub(p[(i + 1) % 3], p[i]);
        let v = sub(p[(i + 2) % 3], p[i]);
        let cos = dot(u, v) / (dot(u, u) * dot(v, v)).sqrt();
        min_angle = min_angle.min(cos.clamp(-1.0, 1.0).acos());
    }
    let agrees = dot(
        triangle_normal(tri),
        field_gradient(case, triangle_centroid(tri)),
    ) > 0.0;
    if agrees {
        min_angle
    } else {
        min_angle - 10.0
    }
}

/// Triangulates one closed loop (in its own winding order) by dynamic programming over
/// all triangulations of the polygon, maximising the worst triangle score. Diagonals
/// between two vertices of a common cube face are not allowed.
fn triangulate_loop(case: u8, ring: &[u8]) -> Vec<[u8; 3]> {
    let n = ring.len();
    assert!(n >= 3, "loop with fewer than 3 vertices");
    let usable = |i: usize, j: usize| {
        j == i + 1 || (i == 0 && j == n - 1) || edge_faces(ring[i]) & edge_faces(ring[j]) == 0
    };
    // best[i][j]: best worst-score over triangulations of the sub-polygon i..=j
    // (closed by the chord i-j); NEG_INFINITY when impossible.
    let mut best = vec![vec![f64::NEG_INFINITY; n]; n];
    let mut split = vec![vec![usize::MAX; n]; n];
    for i in 0..n - 1 {
        best[i][i + 1] = f64::INFINITY;
    }
    for len in 2..n {
        for i in 0..n - len {
            let j = i + len;
            if !usable(i, j) {
                continue;
            }
            for k in i + 1..j {
                let score = best[i][k]
                    .min(best[k][j])
                    .min(triangle_quality(case, [ring[i], ring[k], ring[j]]));
                if score > best[i][j] {
                    best[i][j] = score;
                    split[i][j] = k;
                }
            }
        }
    }
    assert!(
        best[0][n - 1] > f64::NEG_INFINITY,
        "no valid triangulation of loop {ring:?} in case {case}"
    );
    let mut triangles = Vec::with_capacity(n - 2);
    let mut pending = vec![(0, n - 1)];
    while let Some((i, j)) = pending.pop() {
        if j - i < 2 {
            continue;
        }
        let k = split[i][j];
        triangles.push([ring[i], ring[k], ring[j]]);
        pending.push((k, j));
        pending.push((i, k));
    }
    triangles
}

/// Triangulates a case from first principles (used for the base configurations).
fn triangulate_case(case: u8, ambiguity: Ambiguity) -> Vec<[u8; 3]> {
    case_loops(case, ambiguity)
        .iter()
        .flat_map(|ring| triangulate_loop(case, ring))
        .collect()
}

/// A rotation of the cube, as permutations of its corners, edges and faces.
#[derive(Clone, Debug, PartialEq, Eq)]
struct Rotation {
    corners: [u8; 8],
    edges: [u8; 12],
    faces: [u8; 6],
}

impl Rotation {
    /// Builds a rotation from its corner permutation (corner k goes to `corners[k]`).
    fn from_corners(corners: [u8; 8]) -> Rotation {
        let edges = EDGES.map(|[a, b]| {
            edge_between(corners[a as usize], corners[b as usize]).expect("not a cube symmetry")
        });
        let faces = FACE_CORNERS.map(|fc| {
            let mask: u8 = fc.iter().map(|&c| 1 << corners[c as usize]).sum();
            let target = FACE_CORNERS
                .iter()
                .position(|g| g.iter().map(|&c| 1u8 << c).sum::<u8>() == mask)
                .expect("not a cube symmetry");
            target as u8
        });
        Rotation {
            corners,
            edges,
            faces,
        }
    }

    /// Quarter turn about `axis`: in the plane of the two other axes (u, v), the corner
    /// at (u, v) moves to (1 - v, u).
    fn quarter_turn(axis: usize) -> Rotation {
        let (u, v) = other_axes(axis);
        Rotation::from_corners(std::array::from_fn(|k| {
            let bit = |i: usize| (k >> i) & 1;
            let moved = (k & (1 << axis)) | ((1 - bit(v)) << u) | (bit(u) << v);
            moved as u8
        }))
    }

    /// `self` applied after `first`.
    fn after(&self, first: &Rotation) -> Rotation {
        Rotation::from_corners(first.corners.map(|c| self.corners[c as usize]))
    }

    /// The case whose inside corners are the images of the inside corners of `case`.
    fn map_case(&self, case: u8) -> u8 {
        (0..8u8)
            .filter(|&k| is_inside(case, k))
            .map(|k| 1u8 << self.corners[k as usize])
            .sum()
    }
}

/// The 24 rotations of the cube (identity first), generated by closing the three quarter
/// turns under composition.
fn rotations() -> &'static [Rotation] {
    static ROTATIONS: OnceLock<Vec<Rotation>> = OnceLock::new();
    ROTATIONS.get_or_init(|| {
        let generators: Vec<Rotation> = (0..3).map(Rotation::quarter_turn).collect();
        let mut all = vec![Rotation::from_corners(std::array::from_fn(|k| k as u8))];
        let mut i = 0;
        while i < all.len() {
            for g in &generators {
                let r = g.after(&all[i]);
                if !all.contains(&r) {
                    all.push(r);
                }
            }
            i += 1;
        }
        assert_eq!(all.len(), 24, "the cube must have 24 rotations");
        all
    })
}

/// The base configuration (smallest case index among all rotated images) of `case`.
fn base_case_of(case: u8) -> u8 {
    rotations()
        .iter()
        .map(|r| r.map_case(case))
        .min()
        .expect("rotations")
}

/// The base configurations: one representative per class of cases that are rotations of
/// each other, namely the smallest case index of the class, sorted increasingly. There
/// are 23 classes, including the empty case 0 and the full case 255. Inside/outside
/// swaps and mirror images are deliberately not merged, since they would change the
/// handling of ambiguous faces or the triangle winding.
pub fn base_cases() -> Vec<u8> {
    let mut bases: Vec<u8> = (0..=255u8).map(base_case_of).collect();
    bases.sort_unstable();
    bases.dedup();
    bases
}

/// One generated case: triangles as triples of edge indices, and the faces the surface crosses.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Case {
    /// Triangles as triples of edge indices, wound so that `(b - a) x (c - a)` points outward.
    pub triangles: Vec<[u8; 3]>,
    /// Bit f set if face f has corners of both signs.
    pub crossed_faces: u8,
}

/// The 256-case table for one ambiguity choice. Case index: bit k set when corner k is INSIDE (field < 0).
#[derive(Clone, Debug)]
pub struct CaseTable {
    ambiguity: Ambiguity,
    /// Triangles of case c are `triangles[offsets[c]..offsets[c + 1]]`.
    offsets: [u16; 257],
    triangles: Vec<[u8; 3]>,
    crossed: [u8; 256],
    max_triangles: usize,
}

impl CaseTable {
    /// Generates the table: base configurations are triangulated, every other case is
    /// the rotated triangulation of its base configuration.
    pub fn new(ambiguity: Ambiguity) -> CaseTable {
        let mut base_triangles: Vec<Option<Vec<[u8; 3]>>> = vec![None; 256];
        for base in base_cases() {
            base_triangles[base as usize] = Some(triangulate_case(base, ambiguity));
        }
        let mut offsets = [0u16; 257];
        let mut triangles = Vec::new();
        let mut crossed = [0u8; 256];
        let mut max_triangles = 0;
        for case in 0..=255u8 {
            let base = base_case_of(case);
            let rotation = rotations()
                .iter()
                .find(|r| r.map_case(base) == case)
                .expect("case is a rotation of its base configuration");
            let source = base_triangles[base as usize]
                .as_ref()
                .expect("base configuration triangulated");
            triangles.extend(
                source
                    .iter()
                    .map(|tri| tri.map(|e| rotation.edges[e as usize])),
            );
            max_triangles = max_triangles.max(source.len());
            offsets[case as usize + 1] = u16::try_from(triangles.len()).expect("table size");
            crossed[case as usize] = mixed_faces(case);
        }
        CaseTable {
            ambiguity,
            offsets,
            triangles,
            crossed,
            max_triangles,
        }
    }

    /// Shared, lazily built table for `ambiguity`.
    pub fn get(ambiguity: Ambiguity) -> &'static CaseTable {
        static SEPARATE: OnceLock<CaseTable> = OnceLock::new();
        static JOIN: OnceLock<CaseTable> = OnceLock::new();
        let cell = match ambiguity {
            Ambiguity::Separate => &SEPARATE,
            Ambiguity::Join => &JOIN,
        };
        cell.get_or_init(|| CaseTable::new(ambiguity))
    }

    /// The ambiguity choice this table was built with.
    pub fn ambiguity(&self) -> Ambiguity {
        self.ambiguity
    }

    /// Triangles of a case as edge-index triples, wound so that the normal points outward.
    #[inline]
    pub fn triangles(&self, case: u8) -> &[[u8; 3]] {
        let c = case as usize;
        &self.triangles[self.offsets[c] as usize..self.offsets[c + 1] as usize]
    }

    /// Bit f set when face f has corners of both signs (the surface crosses it; the neighbour across it must be visited by a surface-tracking polygonizer).
    #[inline]
    pub fn crossed_faces(&self, case: u8) -> u8 {
        self.crossed[case as usize]
    }

    /// Maximum number of triangles of any case (for buffer sizing).
    pub fn max_triangles(&self) -> usize {
        self.max_triangles
    }

    /// An owned copy of one case.
    pub fn case(&self, case: u8) -> Case {
        Case {
            triangles: self.triangles(case).to_vec(),
            crossed_faces: self.crossed_faces(case),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::XorShift;
    use std::collections::{HashMap, HashSet};

    const BOTH: [Ambiguity; 2] = [Ambiguity::Separate, Ambiguity::Join];

    /// Whether edge `e` has ends of opposite signs in `case`.
    fn is_crossed_edge(case: u8, e: u8) -> bool {
        let [a, b] = EDGES[e as usize];
        is_inside(case, a) != is_inside(case, b)
    }

    /// Whether face `face` is ambiguous (diagonal corners share a sign, adjacent ones differ) in `case`.
    fn is_ambiguous_face(case: u8, face: usize) -> bool {
        let s = FACE_CORNERS[face].map(|c| is_inside(case, c));
        s[0] == s[2] && s[1] == s[3] && s[0] != s[1]
    }

    /// Directed triangle sides (pairs of edge indices) of a list of triangles.
    fn sides(tris: &[[u8; 3]]) -> Vec<(u8, u8)> {
        tris.iter()
            .flat_map(|t| (0..3).map(move |i| (t[i], t[(i + 1) % 3])))
            .collect()
    }

    /// Directed triangle sides lying on face `face`.
    fn face_sides(tris: &[[u8; 3]], face: usize) -> HashSet<(u8, u8)> {
        sides(tris)
            .into_iter()
            .filter(|&(a, b)| edge_faces(a) & edge_faces(b) & (1 << face) != 0)
            .collect()
    }

    #[test]
    fn geometry_constants_are_consistent() {
        for (e, &[a, b]) in EDGES.iter().enumerate() {
            let axis = EDGE_AXIS[e] as usize;
            assert_eq!(a ^ b, 1 << axis, "edge {e} not along its axis");
            assert!(a < b);
            let p = CORNERS[a as usize];
            let expected = match axis {
                0 => p[1] + 2 * p[2],
                1 => 4 + p[0] + 2 * p[2],
                _ => 8 + p[0] + 2 * p[1],
            };
            assert_eq!(expected as usize, e);
            assert_eq!(edge_between(a, b), Some(e as u8));
            assert_eq!(edge_between(b, a), Some(e as u8));
        }
        assert_eq!(edge_between(0, 3), None);
        for (f, corners) in FACE_CORNERS.iter().enumerate() {
            let axis = f / 2;
            let side = (f % 2) as u8;
            for &c in corners {
                assert_eq!(CORNERS[c as usize][axis], side);
            }
            let distinct: HashSet<u8> = corners.iter().copied().collect();
            assert_eq!(distinct.len(), 4);
            // Consecutive corners are adjacent, and the order is counter-clockwise from outside.
            let pos = corners.map(|c| CORNERS[c as usize].map(f64::from));
            let mut outward = [0.0; 3];
            outward[axis] = if side == 1 { 1.0 } else { -1.0 };
            for i in 0..4 {
                assert!(edge_between(corners[i], corners[(i + 1) % 4]).is_some());
                let n = cross(
                    sub(pos[(i + 1) % 4], pos[i]),
                    sub(pos[(i + 2) % 4], pos[(i + 1) % 4]),
                );
                assert!(dot(n, outward) > 0.0, "face {f} is not counter-clockwise");
            }
            for e in 0..12u8 {
                let [a, b] = EDGES[e as usize];
                let on_face = corners.contains(&a) && corners.contains(&b);
                assert_eq!(on_face, edge_faces(e) & (1 << f) != 0);
            }
        }
    }

    #[test]
    fn exactly_24_distinct_proper_rotations() {
        let rots = rotations();
        assert_eq!(rots.len(), 24);
        let distinct: HashSet<[u8; 8]> = rots.iter().map(|r| r.corners).collect();
        assert_eq!(distinct.len(), 24);
        for r in rots {
            // Linear part from the images of the three unit steps out of corner 0.
            let origin = CORNERS[r.corners[0] as usize].map(i32::from);
            let column = |k: usize| {
                let p = CORNERS[r.corners[k] as usize].map(i32::from);
                [p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]]
            };
            let (a, b, c) = (column(1), column(2), column(4));
            let det = a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                + a[2] * (b[0] * c[1] - b[1] * c[0]);
            assert_eq!(det, 1, "a rotation must preserve orientation");
            // Edge and face permutations agree with the corner permutation.
            for e in 0..12 {
                let [a, b] = EDGES[e];
                let [c, d] = EDGES[r.edges[e] as usize];
                let mapped: HashSet<u8> = [r.corners[a as usize], r.corners[b as usize]].into();
                assert_eq!(mapped, HashSet::from([c, d]));
            }
            let faces: HashSet<u8> = r.faces.iter().copied().collect();
            assert_eq!(faces.len(), 6);
            for f in 0..6 {
                let mapped: HashSet<u8> = FACE_CORNERS[f]
                    .iter()
                    .map(|&c| r.corners[c as usize])
                    .collect();
                let target: HashSet<u8> = FACE_CORNERS[r.faces[f] as usize].into();
                assert_eq!(mapped, target);
            }
        }
    }

    #[test]
    fn twenty_three_classes_of_rotated_cases() {
        let bases = base_cases();
        assert_eq!(bases.len(), 23);
        assert!(bases.contains(&0) && bases.contains(&255));
        let mut covered = HashSet::new();
        for &base in &bases {
            let orbit: HashSet<u8> = rotations().iter().map(|r| r.map_case(base)).collect();
            assert_eq!(
                *orbit.iter().min().unwrap(),
                base,
                "representative is the minimum"
            );
            for &member in &orbit {
                assert_eq!(base_case_of(member), base);
                assert!(covered.insert(member), "classes overlap");
            }
        }
        assert_eq!(covered.len(), 256);
        for case in 0..=255u8 {
            let base = base_case_of(case);
            assert!(bases.contains(&base));
            assert!(rotations().iter().any(|r| r.map_case(base) == case));
        }
    }

    #[test]
    fn derived_cases_are_rotated_base_triangulations() {
        for amb in BOTH {
            let table = CaseTable::new(amb);
            for case in 0..=255u8 {
                let base = base_case_of(case);
                let base_tris: HashSet<[u8; 3]> = table.triangles(base).iter().copied().collect();
                let found = rotations().iter().any(|r| {
                    r.map_case(base) == case
                        && table
                            .triangles(case)
                            .iter()
                            .all(|t| base_tris.contains(&t.map(|e| preimage(r, e))))
                });
                assert!(found, "case {case} is not a rotation of base {base}");
            }
        }
    }

    fn preimage(r: &Rotation, e: u8) -> u8 {
        r.edges.iter().position(|&x| x == e).unwrap() as u8
    }

    #[test]
    fn cases_use_exactly_the_crossed_edges() {
        for amb in BOTH {
            let table = CaseTable::new(amb);
            assert_eq!(table.ambiguity(), amb);
            assert!(table.triangles(0).is_empty());
            assert!(table.triangles(255).is_empty());
            let mut max = 0;
            for case in 0..=255u8 {
                let tris = table.triangles(case);
                max = max.max(tris.len());
                let mut used = HashSet::new();
                for t in tris {
                    assert!(
                        t[0] != t[1] && t[1] != t[2] && t[0] != t[2],
                        "case {case}: repeated vertex in {t:?}"
                    );
                    for &e in t {
                        assert!(e < 12);
                        assert!(is_crossed_edge(case, e), "case {case}: {e} not crossed");
                        used.insert(e);
                    }
                }
                for e in 0..12u8 {
                    if is_crossed_edge(case, e) {
                        assert!(used.contains(&e), "case {case}: crossed edge {e} unused");
                    }
                }
                // Independent recount of the faces with both signs.
                let mut expected = 0u8;
                for (f, corners) in FACE_CORNERS.iter().enumerate() {
                    let signs: HashSet<bool> =
                        corners.iter().map(|&c| case & (1 << c) != 0).collect();
                    if signs.len() == 2 {
                        expected |= 1 << f;
                    }
                }
                assert_eq!(table.crossed_faces(case), expected, "case {case}");
                assert_eq!(table.case(case).crossed_faces, expected);
                assert_eq!(table.case(case).triangles, tris);
            }
            assert_eq!(table.max_triangles(), max);
        }
    }

    #[test]
    fn each_case_is_closed_inside_the_cube() {
        for amb in BOTH {
            let table = CaseTable::new(amb);
            for case in 0..=255u8 {
                let mut counts: HashMap<(u8, u8), usize> = HashMap::new();
                for side in sides(table.triangles(case)) {
                    *counts.entry(side).or_default() += 1;
                }
                let mut on_faces: HashSet<(u8, u8)> = HashSet::new();
                for (&(a, b), &n) in &counts {
                    assert_eq!(n, 1, "case {case}: side ({a},{b}) used {n} times");
                    if edge_faces(a) & edge_faces(b) != 0 {
                        on_faces.insert((a, b));
                    } else {
                        assert_eq!(
                            counts.get(&(b, a)),
                            Some(&1),
                            "case {case}: interior side ({a},{b}) has no reverse"
                        );
                    }
                }
                let expected: HashSet<(u8, u8)> = (0..6)
                    .flat_map(|f| face_segments(case, f, amb))
                    .map(|[a, b]| (a, b))
                    .collect();
                assert_eq!(on_faces, expected, "case {case}: face sides");
            }
        }
    }

    #[test]
    fn neighbouring_cells_agree_on_shared_faces() {
        for amb in BOTH {
            let table = CaseTable::new(amb);
            for (face, face_corners) in FACE_CORNERS.iter().enumerate() {
                let axis = face / 2;
                let other = face ^ 1;
                let flip = 1u8 << axis;
                // Neighbour's edge on its face `other` -> our edge on `face`.
                let to_ours = |e: u8| {
                    let [a, b] = EDGES[e as usize];
                    edge_between(a ^ flip, b ^ flip).unwrap()
                };
                let mut pairs = 0;
                for a in 0..=255u8 {
                    let ours = face_sides(table.triangles(a), face);
                    assert_eq!(ours.is_empty(), table.crossed_faces(a) & (1 << face) == 0);
                    for b in 0..=255u8 {
                        let same = face_corners
                            .iter()
                            .all(|&c| is_inside(a, c) == is_inside(b, c ^ flip));
                        if !same {
                            continue;
                        }
                        pairs += 1;
                        let theirs: HashSet<(u8, u8)> = face_sides(table.triangles(b), other)
                            .into_iter()
                            .map(|(x, y)| (to_ours(y), to_ours(x)))
                            .collect();
                        assert_eq!(ours, theirs, "{amb:?} face {face}: cases {a} / {b}");
                    }
                }
                assert_eq!(pairs, 256 * 16);
            }
        }
    }

    #[test]
    fn normals_follow_the_field_gradient() {
        for amb in BOTH {
            let table = CaseTable::new(amb);
            let mut checked = 0;
            for case in 0..=255u8 {
                for &t in table.triangles(case) {
                    let g = field_gradient(case, triangle_centroid(t));
                    let n = triangle_normal(t);
                    let cosine = dot(n, g) / (dot(n, n) * dot(g, g)).sqrt();
                    assert!(cosine > 0.0, "{amb:?} case {case}: {t:?} faces inward");
                    // The test is sign-sensitive: the flipped triangle must fail.
                    assert!(dot(triangle_normal([t[0], t[2], t[1]]), g) < 0.0);
                    checked += 1;
                }
            }
            let total: usize = (0..=255u8).map(|c| table.triangles(c).len()).sum();
            assert_eq!(checked, total);
            assert!(checked > 500);
        }
        // A hand-checked case: only corner 0 inside, normal must point away from it.
        let t = CaseTable::new(Ambiguity::Separate).triangles(1)[0];
        assert!(dot(triangle_normal(t), [1.0, 1.0, 1.0]) > 0.0);
    }

    /// Number of connected components of a triangle set (triangles connected by vertices).
    fn components(tris: &[[u8; 3]]) -> usize {
        let mut parent: Vec<usize> = (0..12).collect();
        fn find(p: &mut [usize], x: usize) -> usize {
            if p[x] != x {
                let root = find(p, p[x]);
                p[x] = root;
            }
            p[x]
        }
        let mut used = HashSet::new();
        for t in tris {
            for &e in t {
                used.insert(e as usize);
            }
            for i in 1..3 {
                let (a, b) = (
                    find(&mut parent, t[0] as usize),
                    find(&mut parent, t[i] as usize),
                );
                parent[a] = b;
            }
        }
        let roots: HashSet<usize> = used.iter().map(|&e| find(&mut parent, e)).collect();
        roots.len()
    }

    #[test]
    fn separate_and_join_differ_only_on_ambiguous_cases() {
        let sep = CaseTable::new(Ambiguity::Separate);
        let join = CaseTable::new(Ambiguity::Join);
        let case = 0b0000_1001; // corners 0 and 3: diagonal on face z = 0
        assert!(is_ambiguous_face(case, 4));
        assert_eq!(sep.triangles(case).len(), 2);
        assert_eq!(components(sep.triangles(case)), 2);
        assert_eq!(join.triangles(case).len(), 4);
        assert_eq!(components(join.triangles(case)), 1);
        assert_ne!(sep.triangles(case), join.triangles(case));
        let mut ambiguous = 0;
        for case in 0..=255u8 {
            let has_ambiguous = (0..6).any(|f| is_ambiguous_face(case, f));
            ambiguous += usize::from(has_ambiguous);
            assert_eq!(
                sep.triangles(case) != join.triangles(case),
                has_ambiguous,
                "case {case}"
            );
            assert_eq!(sep.crossed_faces(case), join.crossed_faces(case));
        }
        assert!(ambiguous > 0);
    }

    #[test]
    fn shared_tables_are_cached() {
        for amb in BOTH {
            let a = CaseTable::get(amb);
            let b = CaseTable::get(amb);
            assert!(std::ptr::eq(a, b));
            assert_eq!(a.ambiguity(), amb);
            let fresh = CaseTable::new(amb);
            for case in 0..=255u8 {
                assert_eq!(a.triangles(case), fresh.triangles(case));
            }
        }
        assert_eq!(Ambiguity::default(), Ambiguity::Separate);
    }

    /// Assembles a 2x2x2 block of cells with random signs on the 27 lattice points and
    /// checks that the mesh is a consistently oriented manifold away from the block's
    /// outer boundary.
    #[test]
    fn random_blocks_form_oriented_manifolds() {
        let point = |x: usize, y: usize, z: usize| x + 3 * y + 9 * z;
        for amb in BOTH {
            let table = CaseTable::get(amb);
            let mut rng = XorShift::new(0x9E37_79B9_7F4A_7C15);
            let mut total_triangles = 0;
            for _ in 0..4000 {
                let bits = rng.next_u64();
                let inside = |p: usize| (bits >> p) & 1 == 1;
                // Global vertex: lattice edge (lower lattice point, axis).
                let mut tris: Vec<[(usize, usize, usize, usize); 3]> = Vec::new();
                for cell in 0..8 {
                    let origin = [cell & 1, (cell >> 1) & 1, (cell >> 2) & 1];
                    let corner_point = |k: u8| {
                        let c = CORNERS[k as usize];
                        [
                            origin[0] + c[0] as usize,
                            origin[1] + c[1] as usize,
                            origin[2] + c[2] as usize,
                        ]
                    };
                    let mut case = 0u8;
                    for k in 0..8u8 {
                        let [x, y, z] = corner_point(k);
                        if inside(point(x, y, z)) {
                            case |= 1 << k;
                        }
                    }
                    for t in table.triangles(case) {
                        tris.push(t.map(|e| {
                            let [x, y, z] = corner_point(EDGES[e as usize][0]);
                            (x, y, z, EDGE_AXIS[e as usize] as usize)
                        }));
                    }
                }
                total_triangles += tris.len();
                // A lattice edge lies in the outer plane `coord[b] == 0 or 2` (b != axis).
                let outer_planes = |v: (usize, usize, usize, usize)| {
                    let c = [v.0, v.1, v.2];
                    let mut mask = 0u8;
                    for (b, &coord) in c.iter().enumerate() {
                        if b != v.3 && (coord == 0 || coord == 2) {
                            mask |= 1 << (2 * b + coord / 2);
                        }
                    }
                    mask
                };
                let mut counts: HashMap<_, usize> = HashMap::new();
                for t in &tris {
                    for i in 0..3 {
                        *counts.entry((t[i], t[(i + 1) % 3])).or_default() += 1;
                    }
                }
                for (&(a, b), &n) in &counts {
                    assert_eq!(n, 1, "{amb:?}: directed side repeated");
                    let boundary = outer_planes(a) & outer_planes(b) != 0;
                    let reverse = counts.get(&(b, a)).copied().unwrap_or(0);
                    if boundary {
                        assert_eq!(reverse, 0, "{amb:?}: boundary side used twice");
                    } else {
                        assert_eq!(reverse, 1, "{amb:?}: interior side not matched");
                    }
                }
                // Vertex links: around every vertex off the outer boundary, the opposite
                // sides of its triangles form one single cycle (a disc neighbourhood).
                let mut links: HashMap<_, HashMap<_, _>> = HashMap::new();
                for t in &tris {
                    for i in 0..3 {
                        let link = links.entry(t[i]).or_default();
                        let old = link.insert(t[(i + 1) % 3], t[(i + 2) % 3]);
                        assert!(old.is_none(), "{amb:?}: vertex link not simple");
                    }
                }
                for (v, link) in &links {
                    if outer_planes(*v) != 0 {
                        continue;
                    }
                    let start = *link.keys().next().unwrap();
                    let mut at = start;
                    let mut steps = 0;
                    loop {
                        at = *link.get(&at).expect("vertex link is open");
                        steps += 1;
                        if at == start {
                            break;
                        }
                    }
                    assert_eq!(steps, link.len(), "{amb:?}: vertex link has several cycles");
                }
            }
            assert!(total_triangles > 10_000);
        }
    }

    /// Each case is polygons over its crossed edges, one vertex per edge, each polygon of at
    /// least 3 vertices fanned into (vertices − 2) triangles: with E crossed edges and P
    /// polygons, E − 2P triangles, so E/3 ≤ triangles ≤ E − 2 and of E's parity; and
    /// `max_triangles` is the largest case.
    #[test]
    fn triangle_counts_follow_the_crossed_edges() {
        for amb in BOTH {
            let table = CaseTable::get(amb);
            let mut largest = 0;
            for case in 0..=255u8 {
                let crossed = EDGES
                    .iter()
                    .filter(|[a, b]| (case >> a & 1) != (case >> b & 1))
                    .count();
                let t = table.triangles(case).len();
                largest = largest.max(t);
                if crossed == 0 {
                    assert_eq!(t, 0, "{amb:?} case {case}");
                    continue;
                }
                assert_eq!((crossed - t) % 2, 0, "{amb:?} case {case}");
                assert!(3 * t >= crossed && t + 2 <= crossed, "{amb:?} case {case}");
            }
            assert_eq!(table.max_triangles(), largest);
        }
    }
}
