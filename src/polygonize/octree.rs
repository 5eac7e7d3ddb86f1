//! Hierarchical space sampling with the pseudo-Euclidean rejection test (Cuno et al. §4.3).
//!
//! The lattice is covered by a root cube of 2^L cells per side. Level by level, every surviving
//! block of `s × s × s` cells is tested at its centre `c` (a lattice point): when
//! `|f(c)| > safety × r`, with `r` the block's circumradius, the surface cannot reach the block
//! — provided `|f|` under-estimates the distance to the surface there, which the normal
//! constraints of a variational surface with w < d arrange (Cuno's property (6)), and which holds
//! for any exact or conservative signed distance. Otherwise the block splits into 8. Blocks of two
//! cells that survive split into leaf cells, whose corners are evaluated and triangulated with the
//! shared case table and edge vertices — so wherever nothing was rejected wrongly, the mesh is
//! exactly the dense mesh.
//!
//! All the centres of one level are evaluated in one batched field call, then all the leaf
//! corners in one more; a cache keyed by lattice coordinates guarantees that no point is evaluated
//! twice (coarse centres are corners of leaf cells).

use super::cell::{case_index, corner_offset, edge_origin, emit_triangles};
use super::{check_memory, compute_normals, estimate_triangles, evaluate, CaseTable, Stats};
use crate::error::Result;
use crate::field::Field;
use crate::lattice::{edge_crossing, KeyMap, Lattice};
use crate::mesh::Mesh;
use glam::DVec3;
use std::time::Instant;

/// Octree-specific settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Level of the first rejection test: 1 tests the root's 8 octants (the paper's
    /// r = √3/2 for a [-1, 1]³ root), 2 the 64 blocks below them (r = √3/4), and so on. Levels
    /// above it are split without evaluating anything. `None`: the first level whose blocks
    /// span at most 1/8 of the lattice's longest side. Measured on the shared meshes at 24³ to
    /// 128³: starting at coarser blocks (the paper's r = √3/2) rejected cells wrongly at some
    /// resolutions, because far from the surface |f| stops under-estimating distance (Cuno's
    /// Fig. 2c and Table 1); testing from 1/8 costs at most 8³·(root/lattice)³ extra centres.
    pub start_level: Option<u32>,
    /// Multiplies the circumradius in the test |f(c)| > safety × r. Values above 1 keep more
    /// blocks (safer for fields that over-estimate distance, more evaluations).
    pub safety: f64,
    /// Before evaluating all corners of the leaf cells, evaluate only each leaf's corner shared
    /// with its parent block's corners (the one with even lattice coordinates) and reject the
    /// leaf when |f| there exceeds safety × the cell's diagonal — the same pseudo-distance test,
    /// from a corner instead of the centre. Not in the paper; `false` gives §4.3 exactly.
    pub corner_test: bool,
}

impl Default for Settings {
    fn default() -> Self {
        // Measured on the shared meshes (d = 0.015, w/d = 3/4, 24³ to 128³): see
        // notebooks/cuno_tables.ipynb and BENCHMARKS.md.
        Settings {
            start_level: None,
            safety: 1.0,
            corner_test: true,
        }
    }
}

/// Number of levels L: the root cube has 2^L cells per side, enough to cover the lattice.
pub fn levels(lattice: &Lattice) -> u32 {
    let n = *lattice.cells.iter().max().unwrap();
    n.next_power_of_two().trailing_zeros()
}

/// Evaluates, in one batched call, the lattice points of `wanted` not yet in `cache` (each once)
/// and adds them to it.
fn fill_cache<F: Field + ?Sized>(
    field: &F,
    lattice: &Lattice,
    cache: &mut KeyMap<f64>,
    wanted: impl Iterator<Item = [u32; 3]>,
    settings: &super::Settings,
    stats: &mut Stats,
) -> Result<()> {
    let mut keys = Vec::new();
    let mut points = Vec::new();
    for c in wanted {
        let key = Lattice::key(c);
        if let std::collections::hash_map::Entry::Vacant(e) = cache.entry(key) {
            e.insert(f64::NAN);
            keys.push(key);
            points.push(lattice.point(c));
        }
    }
    let mut values = vec![0.0; points.len()];
    evaluate(field, &points, &mut values, settings.batch)?;
    stats.evaluations += points.len() as u64;
    cache.extend(keys.into_iter().zip(values));
    Ok(())
}

/// Polygonizes `field` over `lattice` with hierarchical rejection; leaves are single cells.
pub fn polygonize<F: Field + ?Sized>(
    field: &F,
    lattice: &Lattice,
    settings: &super::Settings,
    octree: &Settings,
) -> Result<(Mesh, Stats)> {
    if !(octree.safety.is_finite() && octree.safety > 0.0) {
        return Err(crate::Error::invalid(
            "safety",
            format!("must be positive and finite, got {}", octree.safety),
        ));
    }
    let tris = estimate_triangles(lattice);
    // Output plus the value cache (a few lattice points per triangle, key + value + slack).
    check_memory(
        tris * (super::BYTES_PER_TRIANGLE + 4 * 32),
        settings.memory_limit,
    )?;

    let table = CaseTable::get(settings.ambiguity);
    let mut stats = Stats {
        lattice_points: lattice.num_points(),
        ..Default::default()
    };
    let cells = lattice.cells;
    let inside = |o: [u32; 3]| o[0] < cells[0] && o[1] < cells[1] && o[2] < cells[2];
    let levels = levels(lattice);
    let mut cache: KeyMap<f64> = KeyMap::default();
    let mut points: Vec<DVec3> = Vec::new();
    let mut keys: Vec<u64> = Vec::new();
    let mut values: Vec<f64> = Vec::new();

    // Blocks of the current level, by their lowest lattice corner.
    let largest = *cells.iter().max().unwrap();
    let start_level = octree.start_level.unwrap_or_else(|| {
        (1..=levels)
            .find(|&l| 8 * (1u32 << (levels - l)) <= largest)
            .unwrap_or(levels)
    });
    let mut blocks: Vec<[u32; 3]> = vec![[0, 0, 0]];
    for level in 0..levels {
        let s = 1u32 << (levels - level);
        if level >= start_level {
            let t = Instant::now();
            points.clear();
            keys.clear();
            for o in &blocks {
                let c = [o[0] + s / 2, o[1] + s / 2, o[2] + s / 2];
                keys.push(Lattice::key(c));
                points.push(lattice.point(c));
            }
            values.resize(points.len(), 0.0);
            evaluate(field, &points, &mut values, settings.batch)?;
            stats.evaluations += points.len() as u64;
            let r = octree.safety * lattice.block_radius(s);
            let mut kept = 0;
            for i in 0..blocks.len() {
                cache.insert(keys[i], values[i]);
                if values[i].abs() <= r {
                    blocks[kept] = blocks[i];
                    kept += 1;
                }
            }
            blocks.truncate(kept);
            stats.add_time("sample", t);
        }
        stats.cells_per_level.push(blocks.len() as u64);
        let h = s / 2;
        let mut next = Vec::with_capacity(blocks.len() * 8);
        for o in &blocks {
            for k in 0..8 {
                let d = corner_offset(k);
                let c = [o[0] + d[0] * h, o[1] + d[1] * h, o[2] + d[2] * h];
                if inside(c) {
                    next.push(c);
                }
            }
        }
        blocks = next;
    }
    // `blocks` now holds the leaf cells.
    let t = Instant::now();
    if octree.corner_test && levels > 0 {
        // Each leaf's corner with even coordinates is a corner of its parent block; evaluate the
        // unknown ones in one batch and reject leaves whose corner is provably far.
        let even = |o: &[u32; 3]| [o[0] + (o[0] & 1), o[1] + (o[1] & 1), o[2] + (o[2] & 1)];
        fill_cache(
            field,
            lattice,
            &mut cache,
            blocks.iter().map(even),
            settings,
            &mut stats,
        )?;
        let diag = octree.safety * lattice.cell.length();
        blocks.retain(|o| cache[&Lattice::key(even(o))].abs() <= diag);
    }
    // Evaluate the leaves' corners not yet known, in one batch.
    let corners = blocks.iter().flat_map(|o| {
        (0..8).map(move |k| {
            let d = corner_offset(k);
            [o[0] + d[0], o[1] + d[1], o[2] + d[2]]
        })
    });
    fill_cache(field, lattice, &mut cache, corners, settings, &mut stats)?;
    stats.cells_per_level.push(blocks.len() as u64);
    stats.cells_visited = blocks.len() as u64;
    stats.add_time("sample", t);

    let t = Instant::now();
    let mut mesh = Mesh::default();
    let mut edges: KeyMap<u32> = KeyMap::default();
    for o in &blocks {
        let mut v = [0.0; 8];
        for (k, vk) in v.iter_mut().enumerate() {
            let d = corner_offset(k);
            *vk = cache[&Lattice::key([o[0] + d[0], o[1] + d[1], o[2] + d[2]])];
        }
        let case = case_index(&v);
        if case == 0 || case == 255 {
            continue;
        }
        stats.cells_crossed += 1;
        emit_triangles(
            table,
            case,
            |e| {
                let (d, axis) = edge_origin(e);
                let a = [o[0] + d[0], o[1] + d[1], o[2] + d[2]];
                *edges.entry(Lattice::edge_key(a, axis)).or_insert_with(|| {
                    let mut b = a;
                    b[axis as usize] += 1;
                    let (fa, fb) = (cache[&Lattice::key(a)], cache[&Lattice::key(b)]);
                    mesh.vertices
                        .push(edge_crossing(lattice.point(a), lattice.point(b), fa, fb));
                    (mesh.vertices.len() - 1) as u32
                })
            },
            &mut mesh.triangles,
        );
    }
    stats.add_time("triangulate", t);
    compute_normals(field, lattice, &mut mesh, settings, &mut stats)?;
    Ok((mesh, stats))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::analytic::{Sphere, Torus};
    use crate::field::Counting;
    use crate::polygonize::{dense, Ambiguity};

    fn check_equal<F: Field>(f: &F, lattice: &Lattice, amb: Ambiguity) -> Stats {
        let s = crate::polygonize::Settings {
            ambiguity: amb,
            ..Default::default()
        };
        let (d, _) = dense::polygonize(f, lattice, &s).unwrap();
        let counting = Counting::new(f);
        let (o, st) = polygonize(&counting, lattice, &s, &Settings::default()).unwrap();
        let c = d.compare(&o);
        assert_eq!((c.missing, c.extra), (0, 0), "octree differs from dense");
        assert!(o.is_closed_oriented());
        // Every point evaluated once, and the count is exact.
        assert_eq!(counting.evaluations(), st.evaluations);
        st
    }

    #[test]
    fn sphere_and_torus_equal_dense() {
        let l = Lattice::new(DVec3::splat(-1.0), DVec3::splat(1.0), [64, 64, 64]).unwrap();
        let s = Sphere {
            center: DVec3::new(0.03, -0.01, 0.02),
            radius: 0.6,
        };
        let st = check_equal(&s, &l, Ambiguity::Separate);
        assert!(
            st.evaluation_percent() < 15.0,
            "{}",
            st.evaluation_percent()
        );
        let t = Torus {
            center: DVec3::new(0.01, 0.0, -0.02),
            major: 0.55,
            minor: 0.2,
        };
        check_equal(&t, &l, Ambiguity::Join);
    }

    #[test]
    fn non_power_of_two_and_anisotropic_lattices() {
        let s = Sphere {
            center: DVec3::ZERO,
            radius: 0.45,
        };
        let l = Lattice::new(
            DVec3::new(-0.6, -0.5, -0.7),
            DVec3::new(0.5, 0.6, 0.5),
            [37, 50, 23],
        )
        .unwrap();
        check_equal(&s, &l, Ambiguity::Separate);
    }

    #[test]
    fn wrong_rejection_makes_holes() {
        // A field that over-estimates distance (3 × the signed distance) breaks the premise:
        // rejection then loses cells, and the comparison finds the holes.
        struct Over(Sphere);
        impl Field for Over {
            fn value(&self, p: DVec3) -> f64 {
                3.0 * self.0.value(p)
            }
        }
        let l = Lattice::new(DVec3::splat(-1.0), DVec3::splat(1.0), [64, 64, 64]).unwrap();
        let f = Over(Sphere {
            center: DVec3::new(0.01, 0.02, 0.03),
            radius: 0.6,
        });
        let s = crate::polygonize::Settings::default();
        let (d, _) = dense::polygonize(&f, &l, &s).unwrap();
        let (o, _) = polygonize(&f, &l, &s, &Settings::default()).unwrap();
        assert!(d.compare(&o).missing > 0);
        // A large enough safety factor restores the dense mesh.
        let (o, _) = polygonize(
            &f,
            &l,
            &s,
            &Settings {
                safety: 3.0,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(d.compare(&o).missing, 0);
    }

    #[test]
    fn start_level_matters_when_far_values_overshoot() {
        // Like an RBF (Cuno's Fig. 2c): the value equals the distance near the surface but grows
        // four times faster beyond 0.1. Testing from the coarse root octants rejects blocks that
        // hold the surface; testing from blocks small enough for the near region does not.
        struct Far(Sphere);
        impl Field for Far {
            fn value(&self, p: DVec3) -> f64 {
                let d = self.0.value(p);
                if d.abs() < 0.1 {
                    d
                } else {
                    d.signum() * (0.1 + 4.0 * (d.abs() - 0.1))
                }
            }
        }
        let l = Lattice::new(DVec3::splat(-1.0), DVec3::splat(1.0), [64, 64, 64]).unwrap();
        let f = Far(Sphere {
            center: DVec3::new(0.51, 0.02, 0.03),
            radius: 0.3,
        });
        let s = crate::polygonize::Settings::default();
        let (d, _) = dense::polygonize(&f, &l, &s).unwrap();
        let coarse = Settings {
            start_level: Some(1),
            ..Default::default()
        };
        let (o, _) = polygonize(&f, &l, &s, &coarse).unwrap();
        assert!(d.compare(&o).missing > 0);
        let deep = Settings {
            start_level: Some(6),
            ..Default::default()
        };
        let (o, _) = polygonize(&f, &l, &s, &deep).unwrap();
        assert_eq!(d.compare(&o).missing, 0);
    }
}
