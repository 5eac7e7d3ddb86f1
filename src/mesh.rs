//! Triangle meshes as the polygonizers return them, with the measures the tests and users need:
//! area, enclosed volume, Euler characteristic, closedness and orientation, triangle quality.

use glam::DVec3;
use std::collections::HashMap;

/// A triangle mesh: triangles index `vertices`, counter-clockwise seen from outside.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions.
    pub vertices: Vec<DVec3>,
    /// Vertex indices of each triangle.
    pub triangles: Vec<[u32; 3]>,
    /// Unit vertex normals (empty when not computed).
    pub normals: Vec<DVec3>,
}

/// Summary of per-triangle quality.
#[derive(Clone, Debug, PartialEq)]
pub struct Quality {
    /// Smallest interior angle of each triangle, in degrees.
    pub min_angles: Vec<f64>,
    /// Aspect ratio of each triangle: longest edge / (2√3 × inradius); 1 for equilateral.
    pub aspect_ratios: Vec<f64>,
}

impl Mesh {
    /// Total surface area.
    pub fn area(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.vertices[i as usize]);
                0.5 * (b - a).cross(c - a).length()
            })
            .sum()
    }

    /// Signed enclosed volume (positive when closed and oriented outward).
    pub fn volume(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.vertices[i as usize]);
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// Directed edge counts: for each undirected edge, (uses as a→b with a<b, uses as b→a).
    fn edge_uses(&self) -> HashMap<(u32, u32), (u32, u32)> {
        let mut m: HashMap<(u32, u32), (u32, u32)> =
            HashMap::with_capacity(self.triangles.len() * 2);
        for t in &self.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let e = m.entry((a.min(b), a.max(b))).or_default();
                if a < b {
                    e.0 += 1;
                } else {
                    e.1 += 1;
                }
            }
        }
        m
    }

    /// Every edge is shared by exactly two triangles that traverse it in opposite directions:
    /// closed (watertight), manifold along edges and consistently oriented.
    pub fn is_closed_oriented(&self) -> bool {
        !self.triangles.is_empty() && self.edge_uses().values().all(|&(f, b)| f == 1 && b == 1)
    }

    /// V − E + F, counting only vertices used by a triangle.
    pub fn euler_characteristic(&self) -> i64 {
        let mut used = vec![false; self.vertices.len()];
        for t in &self.triangles {
            for &v in t {
                used[v as usize] = true;
            }
        }
        let v = used.iter().filter(|u| **u).count() as i64;
        v - self.edge_uses().len() as i64 + self.triangles.len() as i64
    }

    /// Per-triangle smallest angle and aspect ratio.
    pub fn quality(&self) -> Quality {
        let mut min_angles = Vec::with_capacity(self.triangles.len());
        let mut aspect_ratios = Vec::with_capacity(self.triangles.len());
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| self.vertices[i as usize]);
            let (la, lb, lc) = ((b - c).length(), (c - a).length(), (a - b).length());
            let angle = |opp: f64, s1: f64, s2: f64| {
                let cos = ((s1 * s1 + s2 * s2 - opp * opp) / (2.0 * s1 * s2)).clamp(-1.0, 1.0);
                cos.acos().to_degrees()
            };
            let m = angle(la, lb, lc)
                .min(angle(lb, lc, la))
                .min(angle(lc, la, lb));
            min_angles.push(if m.is_finite() { m } else { 0.0 });
            let area = 0.5 * (b - a).cross(c - a).length();
            let s = 0.5 * (la + lb + lc);
            let inradius = if s > 0.0 { area / s } else { 0.0 };
            let longest = la.max(lb).max(lc);
            aspect_ratios.push(if inradius > 0.0 {
                longest / (2.0 * 3f64.sqrt() * inradius)
            } else {
                f64::INFINITY
            });
        }
        Quality {
            min_angles,
            aspect_ratios,
        }
    }

    /// Area-weighted face normals accumulated at vertices, normalised.
    pub fn face_normals_at_vertices(&self) -> Vec<DVec3> {
        let mut n = vec![DVec3::ZERO; self.vertices.len()];
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| self.vertices[i as usize]);
            let fnrm = (b - a).cross(c - a);
            for &v in t {
                n[v as usize] += fnrm;
            }
        }
        n.iter().map(|v| v.normalize_or_zero()).collect()
    }
}

/// The bodies of a mesh: sets of vertices joined by triangles (see [`Mesh::bodies`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Bodies {
    /// The body of each vertex, `0..count`; [`Bodies::UNUSED`] for a vertex no triangle uses.
    pub of_vertex: Vec<u32>,
    /// Triangles of each body.
    pub triangles: Vec<usize>,
}

impl Bodies {
    /// The body of a vertex that no triangle uses.
    pub const UNUSED: u32 = u32::MAX;

    /// The number of bodies.
    pub fn count(&self) -> usize {
        self.triangles.len()
    }
}

impl Mesh {
    /// The bodies (connected components) of the mesh, numbered in the order of their first
    /// vertex.
    pub fn bodies(&self) -> Bodies {
        let mut parent: Vec<u32> = (0..self.vertices.len() as u32).collect();
        fn root(parent: &mut [u32], mut i: u32) -> u32 {
            while parent[i as usize] != i {
                let up = parent[parent[i as usize] as usize];
                parent[i as usize] = up;
                i = up;
            }
            i
        }
        for t in &self.triangles {
            let a = root(&mut parent, t[0]);
            for &v in &t[1..] {
                let b = root(&mut parent, v);
                if a != b {
                    parent[b as usize] = a;
                }
            }
        }
        let mut used = vec![false; self.vertices.len()];
        for t in &self.triangles {
            for &v in t {
                used[v as usize] = true;
            }
        }
        let mut label = vec![Bodies::UNUSED; self.vertices.len()];
        let mut of_vertex = vec![Bodies::UNUSED; self.vertices.len()];
        let mut count = 0u32;
        for v in 0..self.vertices.len() {
            if !used[v] {
                continue;
            }
            let r = root(&mut parent, v as u32) as usize;
            if label[r] == Bodies::UNUSED {
                label[r] = count;
                count += 1;
            }
            of_vertex[v] = label[r];
        }
        let mut triangles = vec![0; count as usize];
        for t in &self.triangles {
            triangles[of_vertex[t[0] as usize] as usize] += 1;
        }
        Bodies {
            of_vertex,
            triangles,
        }
    }
}

/// Triangle-by-triangle comparison of two meshes (see [`Mesh::compare`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Comparison {
    /// Triangles of the first mesh missing from the second.
    pub missing: usize,
    /// Triangles of the second mesh not in the first.
    pub extra: usize,
    /// Triangles in both.
    pub common: usize,
}

impl Mesh {
    /// Each triangle as the exact bits of its corners, rotated so the smallest corner comes first
    /// (orientation kept): equal for equal triangles whatever the vertex numbering.
    fn triangle_keys(&self) -> std::collections::HashSet<[u64; 9]> {
        self.triangles
            .iter()
            .map(|t| {
                let c = t.map(|i| {
                    let p = self.vertices[i as usize];
                    [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
                });
                let m = (0..3).min_by_key(|&k| c[k]).unwrap();
                let mut key = [0u64; 9];
                for k in 0..3 {
                    key[3 * k..3 * k + 3].copy_from_slice(&c[(m + k) % 3]);
                }
                key
            })
            .collect()
    }

    /// Compares triangles by exact vertex coordinates and orientation: `missing` counts the
    /// triangles of `self` that `other` lacks (holes, when `self` is the dense reference).
    pub fn compare(&self, other: &Mesh) -> Comparison {
        let a = self.triangle_keys();
        let b = other.triangle_keys();
        let common = a.intersection(&b).count();
        Comparison {
            missing: a.len() - common,
            extra: b.len() - common,
            common,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bodies_are_the_components_joined_by_triangles() {
        let tet = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let mut triangles: Vec<[u32; 3]> = tet.to_vec();
        // A second tetrahedron on vertices 5..9 and a lone triangle on 9..12; vertex 4 unused.
        triangles.extend(tet.iter().map(|t| t.map(|v| v + 5)));
        triangles.push([9, 10, 11]);
        let m = Mesh {
            vertices: vec![DVec3::ZERO; 12],
            triangles,
            normals: vec![],
        };
        let b = m.bodies();
        assert_eq!(b.count(), 3);
        assert_eq!(b.triangles, vec![4, 4, 1]);
        assert_eq!(
            b.of_vertex,
            vec![0, 0, 0, 0, Bodies::UNUSED, 1, 1, 1, 1, 2, 2, 2]
        );
    }

    #[test]
    fn tetrahedron_measures() {
        let m = Mesh {
            vertices: vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
            normals: vec![],
        };
        assert!(m.is_closed_oriented());
        assert_eq!(m.euler_characteristic(), 2);
        assert!((m.volume() - 1.0 / 6.0).abs() < 1e-15);
        let mut open = m.clone();
        open.triangles.pop();
        assert!(!open.is_closed_oriented());
        let mut flipped = m.clone();
        flipped.triangles[0] = [0, 1, 2];
        assert!(!flipped.is_closed_oriented());
    }
}
