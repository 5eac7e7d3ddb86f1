//! Step 2: patches. Neighbours are joined into one patch, and their normals made to agree, only
//! across *safe* edges: the two normals are nearly parallel (as lines) and the neighbour does
//! not lie mainly along them — the edge runs along the surface, not across a thin part from
//! one side to the other, where the two normals are parallel lines too but must point apart.
//! Inside a patch every normal's sign follows from its neighbour's, so a patch is consistently
//! oriented; patches end at creases, thin parts and where noise makes the planes disagree.
//!
//! The patches are the sets of a [`ParityForest`] (union–find with, for every element, whether
//! its sign is flipped relative to its set's root) over the safe edges.

use super::local::Local;
use super::NormalSettings;
use glam::DVec3;

/// Disjoint sets whose elements each carry a sign relative to their set's root.
#[derive(Clone, Debug)]
pub struct ParityForest {
    parent: Vec<u32>,
    /// Whether an element's sign is opposite to its parent's.
    flip: Vec<bool>,
    size: Vec<u32>,
}

impl ParityForest {
    /// `n` sets of one element each.
    pub fn new(n: usize) -> Self {
        ParityForest {
            parent: (0..n as u32).collect(),
            flip: vec![false; n],
            size: vec![1; n],
        }
    }

    /// The root of `i`'s set and whether `i`'s sign is opposite to the root's (paths are
    /// compressed on the way).
    pub fn find(&mut self, i: usize) -> (usize, bool) {
        let mut root = i;
        let mut parity = false;
        while self.parent[root] as usize != root {
            parity ^= self.flip[root];
            root = self.parent[root] as usize;
        }
        // Compress: every element on the path points at the root, with its own parity.
        let (mut at, mut p) = (i, parity);
        while self.parent[at] as usize != root {
            let next = self.parent[at] as usize;
            let next_p = p ^ self.flip[at];
            self.parent[at] = root as u32;
            self.flip[at] = p;
            at = next;
            p = next_p;
        }
        (root, parity)
    }

    /// Joins the sets of `i` and `j` so that their signs differ when `opposite`; false (and no
    /// change) when they are in one set already and its signs disagree with that.
    pub fn join(&mut self, i: usize, j: usize, opposite: bool) -> bool {
        let (ri, pi) = self.find(i);
        let (rj, pj) = self.find(j);
        if ri == rj {
            return pi ^ pj == opposite;
        }
        let (big, small) = if self.size[ri] >= self.size[rj] {
            (ri, rj)
        } else {
            (rj, ri)
        };
        self.parent[small] = big as u32;
        self.flip[small] = pi ^ pj ^ opposite;
        self.size[big] += self.size[small];
        true
    }

    /// Every element's root and sign relative to it, all paths compressed.
    pub fn resolve(&mut self) -> (Vec<u32>, Vec<bool>) {
        let n = self.parent.len();
        let mut roots = Vec::with_capacity(n);
        let mut signs = Vec::with_capacity(n);
        for i in 0..n {
            let (r, p) = self.find(i);
            roots.push(r as u32);
            signs.push(p);
        }
        (roots, signs)
    }
}

/// How an edge from `p` (normal `a`) to `q` (normal `b`) reads: the cosine between the normals
/// and the larger of the two normals' cosines with the edge.
#[inline]
pub fn edge(p: DVec3, a: DVec3, q: DVec3, b: DVec3) -> (f64, f64) {
    let d = (q - p).normalize_or_zero();
    (a.dot(b), d.dot(a).abs().max(d.dot(b).abs()))
}

/// The patches of the points (`points` and `local` in leaf order): each point's patch (a root,
/// a leaf position) and its normal oriented within the patch. Also the number of safe edges
/// that disagreed with the signs their patch had already (kept out).
pub fn grow_patches(
    points: &[DVec3],
    local: &[Local],
    settings: &NormalSettings,
) -> (Vec<u32>, Vec<DVec3>, usize) {
    let safe = settings.patch_angle.to_radians().cos();
    let mut forest = ParityForest::new(points.len());
    let mut conflicts = 0;
    for (i, l) in local.iter().enumerate() {
        for j in l.neighbours() {
            let (c, along) = edge(points[i], l.normal, points[j], local[j].normal);
            if c.abs() >= safe && along <= settings.across && !forest.join(i, j, c < 0.0) {
                conflicts += 1;
            }
        }
    }
    let (roots, signs) = forest.resolve();
    let normals = local
        .iter()
        .zip(&signs)
        .map(|(l, &f)| if f { -l.normal } else { l.normal })
        .collect();
    (roots, normals, conflicts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::knn::PointTree;
    use crate::normals::local::local_planes;

    #[test]
    fn parity_forest_keeps_relative_signs() {
        let mut f = ParityForest::new(5);
        assert!(f.join(0, 1, true));
        assert!(f.join(1, 2, true));
        assert!(f.join(3, 4, false));
        assert!(f.join(2, 4, true));
        // 0 and 2 agree (two flips), 4 is opposite to 2, 3 agrees with 4.
        assert!(f.join(0, 2, false));
        assert!(!f.join(0, 2, true));
        let (roots, signs) = f.resolve();
        assert!(roots.iter().all(|&r| r == roots[0]));
        let s = |i: usize| signs[i] ^ signs[0];
        assert_eq!(
            [s(0), s(1), s(2), s(3), s(4)],
            [false, true, false, true, true]
        );
    }

    /// A closed box 1.5 spacings thick (a thin plate): within every patch the normals agree
    /// with the outward ones up to one sign for the patch, away from the box's edges, where
    /// the planes of the two sides mix.
    #[test]
    fn patches_do_not_cross_a_thin_plate() {
        let h = 0.02;
        let (pts, truth) = crate::testing::thin_box(h, 1.5 * h);
        let tree = PointTree::new(&pts).unwrap();
        let local = local_planes(&tree, &tree.positions(), 16).unwrap();
        let (sorted, order, ..) = tree.layout();
        let (roots, normals, _) = grow_patches(sorted, &local, &NormalSettings::default());
        let inner =
            |p: DVec3| p.x > 2.0 * h && p.x < 1.0 - 2.0 * h && p.y > 2.0 * h && p.y < 1.0 - 2.0 * h;
        let mut sign = std::collections::HashMap::new();
        for s in 0..sorted.len() {
            if !inner(sorted[s]) {
                continue;
            }
            let agrees = normals[s].dot(truth[order[s] as usize]) > 0.0;
            assert_eq!(*sign.entry(roots[s]).or_insert(agrees), agrees);
        }
    }
}
