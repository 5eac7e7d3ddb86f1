//! Step 3: patches oriented against each other. Every edge of the neighbour graph between two
//! patches that is not across a thin part (see [`super::patches`]) and whose normals are not
//! nearly perpendicular votes, with the cosine of its oriented normals, for the two patches
//! keeping their signs (positive) or one turning (negative). The votes of each pair of patches
//! are summed, and the pairs are taken in decreasing order of their summed vote's magnitude
//! into a [`ParityForest`] of patches (Kruskal's maximum spanning forest, each pair fixing its
//! two patches' relative sign): a long boundary between two large patches decides before a few
//! edges between small ones, and a pair that contradicts the signs already fixed is ignored.
//! Patches that no vote joins stay separate pieces.

use super::local::Local;
use super::patches::{edge, ParityForest};
use super::NormalSettings;
use crate::error::Result;
use glam::DVec3;
use rayon::prelude::*;

/// Points per chunk whose votes are collected and summed at once (bounds the memory of votes).
const CHUNK: usize = 1 << 20;

/// The patches joined into pieces: each point's piece (a leaf position) and whether its patch
/// turns.
pub struct Pieces {
    /// Each point's piece, a leaf position.
    pub piece: Vec<u32>,
    /// Whether each point's normal turns.
    pub turn: Vec<bool>,
}

/// The summed vote of every pair of patches `(a, b)`, `a < b`, sorted by pair.
fn votes(
    points: &[DVec3],
    local: &[Local],
    roots: &[u32],
    normals: &[DVec3],
    settings: &NormalSettings,
) -> Result<Vec<((u32, u32), f64)>> {
    let sure = settings.vote_angle.to_radians().cos();
    let mut all: Vec<((u32, u32), f64)> = Vec::new();
    for start in (0..points.len()).step_by(CHUNK) {
        let end = (start + CHUNK).min(points.len());
        let mut chunk: Vec<((u32, u32), f64)> = (start..end)
            .into_par_iter()
            .flat_map_iter(|i| {
                local[i].neighbours().filter_map(move |j| {
                    let (a, b) = (roots[i], roots[j]);
                    if a == b {
                        return None;
                    }
                    let (c, along) = edge(points[i], normals[i], points[j], normals[j]);
                    (c.abs() >= sure && along <= settings.across)
                        .then_some(((a.min(b), a.max(b)), c))
                })
            })
            .collect();
        chunk.par_sort_unstable_by_key(|v| v.0);
        all.extend(sum_runs(chunk));
        crate::cancel::check()?;
    }
    all.par_sort_unstable_by_key(|v| v.0);
    Ok(sum_runs(all))
}

/// Sorted (pair, vote) entries with the votes of equal pairs summed.
fn sum_runs(sorted: Vec<((u32, u32), f64)>) -> Vec<((u32, u32), f64)> {
    let mut out: Vec<((u32, u32), f64)> = Vec::new();
    for (pair, v) in sorted {
        match out.last_mut() {
            Some(last) if last.0 == pair => last.1 += v,
            _ => out.push((pair, v)),
        }
    }
    out
}

/// Joins the patches (`roots`, with `normals` oriented within each) into pieces.
pub fn join_patches(
    points: &[DVec3],
    local: &[Local],
    roots: &[u32],
    normals: &[DVec3],
    settings: &NormalSettings,
) -> Result<Pieces> {
    let mut pairs = votes(points, local, roots, normals, settings)?;
    pairs.par_sort_unstable_by(|a, b| b.1.abs().total_cmp(&a.1.abs()).then(a.0.cmp(&b.0)));
    let mut forest = ParityForest::new(points.len());
    for ((a, b), v) in pairs {
        forest.join(a as usize, b as usize, v < 0.0);
    }
    let (piece_of_root, turn_of_root) = forest.resolve();
    let piece = roots.iter().map(|&r| piece_of_root[r as usize]).collect();
    let turn = roots.iter().map(|&r| turn_of_root[r as usize]).collect();
    Ok(Pieces { piece, turn })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn votes_of_a_pair_are_summed_and_the_larger_decides() {
        let v = sum_runs(vec![((0, 1), 0.5), ((0, 1), -0.2), ((1, 2), -0.9)]);
        assert_eq!(v.len(), 2);
        assert!((v[0].1 - 0.3).abs() < 1e-15);
        assert_eq!(v[1], ((1, 2), -0.9));
    }

    /// Three flat strips side by side along x, given as three patches, the middle one with its
    /// normals turned: the votes turn it back.
    #[test]
    fn a_turned_patch_between_two_is_turned_back() {
        let h = 0.1;
        let mut points = Vec::new();
        for i in 0..30 {
            for j in 0..10 {
                points.push(DVec3::new(i as f64 * h, j as f64 * h, 0.0));
            }
        }
        let tree = crate::knn::PointTree::new(&points).unwrap();
        let local = super::super::local::local_planes(&tree, &tree.positions(), 12).unwrap();
        let (sorted, ..) = tree.layout();
        let strip = |s: usize| (sorted[s].x / h / 10.0).floor().min(2.0) as u32;
        // Patches by hand: one per strip, the middle one turned.
        let first: Vec<u32> = (0..3)
            .map(|k| (0..sorted.len()).find(|&s| strip(s) == k).unwrap() as u32)
            .collect();
        let roots: Vec<u32> = (0..sorted.len())
            .map(|s| first[strip(s) as usize])
            .collect();
        let normals: Vec<DVec3> = (0..sorted.len())
            .map(|s| if strip(s) == 1 { -DVec3::Z } else { DVec3::Z })
            .collect();
        let pieces =
            join_patches(sorted, &local, &roots, &normals, &NormalSettings::default()).unwrap();
        assert!(pieces.piece.iter().all(|&p| p == pieces.piece[0]));
        for s in 0..sorted.len() {
            let n = if pieces.turn[s] {
                -normals[s]
            } else {
                normals[s]
            };
            let n0 = if pieces.turn[0] {
                -normals[0]
            } else {
                normals[0]
            };
            assert_eq!(n, n0);
        }
    }
}
