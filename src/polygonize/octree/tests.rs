//! Unit tests of the octree: equality with dense marching cubes, repairs, thread independence
//! and the settling's tables.

use super::balls::{ball_masks, block_reach};
use super::block::{block_point, LEAF_CORNERS};
use super::cover::{covered, covered_by_opposite_balls, covered_piece};
use super::decided::{DecidedBlocks, SHARED};
use super::settle::{sign_masks, unknown_edge_ends};
use super::state::PointState;
use super::*;
use crate::field::analytic::{Sphere, Torus};
use crate::field::Counting;
use crate::mesh::Mesh;
use crate::polygonize::cell::Corner;
use crate::polygonize::table::EDGES;
use crate::polygonize::{dense, Ambiguity, Settings, Stats};
use crate::testing::Lcg;
use glam::DVec3;

/// Polygonizes `f` with the octree (`settings`) and checks the mesh is the dense mesh (`dense`,
/// from `settings.common`) and that the evaluations counted are those the field was asked for;
/// returns the octree's mesh and stats.
fn check_equals_dense<F: Field>(
    f: &F,
    lattice: &Lattice,
    settings: &OctreeSettings,
    dense: &Mesh,
    what: &str,
) -> (Mesh, Stats) {
    let counting = Counting::new(f);
    let crate::polygonize::Polygonized {
        mesh: o, stats: st, ..
    } = polygonize(&counting, lattice, settings).unwrap();
    let c = dense.compare(&o);
    assert_eq!(
        (c.missing, c.extra),
        (0, 0),
        "octree differs from dense: {what}"
    );
    // Every point evaluated once, and the count is exact.
    assert_eq!(counting.evaluations(), st.evaluations, "{what}");
    (o, st)
}

/// [`check_equals_dense`] with the default settings but `amb`, for a closed surface.
fn check_equal<F: Field>(f: &F, lattice: &Lattice, amb: Ambiguity) -> Stats {
    let settings = OctreeSettings {
        common: Settings {
            ambiguity: amb,
            ..Default::default()
        },
        ..Default::default()
    };
    let crate::polygonize::Polygonized {
        mesh: d, stats: _, ..
    } = dense::polygonize(f, lattice, &settings.common).unwrap();
    let (o, st) = check_equals_dense(f, lattice, &settings, &d, "");
    assert!(o.is_closed_oriented());
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
fn tiny_lattices_and_brick_boundaries() {
    // Lattices of one or a few cells, and sides just below, at and above the 8-point bricks
    // of the value store; the surface is cut by the box, so the meshes are open.
    let s = Sphere {
        center: DVec3::new(0.1, -0.05, 0.02),
        radius: 0.5,
    };
    for cells in [
        [1, 1, 1],
        [2, 1, 3],
        [1, 7, 9],
        [7, 8, 9],
        [15, 16, 17],
        [31, 1, 33],
    ] {
        let l = Lattice::new(DVec3::splat(-0.2), DVec3::splat(0.8), cells).unwrap();
        let set = Settings::default();
        let crate::polygonize::Polygonized {
            mesh: d, stats: _, ..
        } = dense::polygonize(&s, &l, &set).unwrap();
        assert!(!d.triangles.is_empty(), "{cells:?}");
        for corner_test in [true, false] {
            let o = OctreeSettings {
                corner_test,
                ..Default::default()
            };
            check_equals_dense(&s, &l, &o, &d, &format!("{cells:?}"));
        }
    }
}

#[test]
fn wrong_rejections_are_repaired() {
    // A field that over-estimates distance (3 × the signed distance) breaks the premise:
    // the levels drop blocks the surface crosses and balls infer wrong signs. The repair
    // walks on from the crossed leaves into those blocks, and the mesh is the dense mesh,
    // with the paper's test alone and with the corner test.
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
    let crate::polygonize::Polygonized {
        mesh: d, stats: _, ..
    } = dense::polygonize(&f, &l, &Settings::default()).unwrap();
    for corner_test in [true, false] {
        let octree = OctreeSettings {
            corner_test,
            ..Default::default()
        };
        let what = format!("corner test {corner_test}");
        let (o, stats) = check_equals_dense(&f, &l, &octree, &d, &what);
        assert!(stats.cells_repaired > 0, "{what}");
        // One vertex per crossed edge, shared across the seams: closed like the dense mesh.
        assert_eq!(
            o.vertices.len(),
            d.vertices.len(),
            "corner test {corner_test}"
        );
        assert!(o.is_closed_oriented(), "corner test {corner_test}");
    }
    // With a safety factor that restores the premise, nothing needs repair.
    let crate::polygonize::Polygonized { mesh: o, stats, .. } = polygonize(
        &f,
        &l,
        &OctreeSettings {
            safety: Some(3.0),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(stats.cells_repaired, 0);
    assert_eq!(d.compare(&o).missing, 0);
}

#[test]
fn same_mesh_and_count_on_any_number_of_threads() {
    // Signs and claims are stored in parallel; where the premise fails (a field three times
    // the distance), blocks infer different signs for shared points, and the outcome must
    // still not depend on the threads.
    struct Over(Torus);
    impl Field for Over {
        fn value(&self, p: DVec3) -> f64 {
            3.0 * self.0.value(p)
        }
    }
    let l = Lattice::new(DVec3::splat(-1.0), DVec3::new(1.0, 0.9, 1.0), [70, 64, 61]).unwrap();
    let t = Torus {
        center: DVec3::new(0.01, 0.0, -0.02),
        major: 0.55,
        minor: 0.2,
    };
    let run = |threads: usize, f: &(dyn Field + Sync)| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let p = polygonize(f, &l, &OctreeSettings::default()).unwrap();
            (p.mesh, p.stats)
        })
    };
    for f in [&Over(t) as &(dyn Field + Sync), &t] {
        let (one, st1) = run(1, f);
        for threads in [2, 3, 8] {
            let (m, st) = run(threads, f);
            assert_eq!(m.vertices, one.vertices);
            assert_eq!(m.triangles, one.triangles);
            assert_eq!(st.evaluations, st1.evaluations);
        }
    }
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
    let crate::polygonize::Polygonized {
        mesh: d, stats: _, ..
    } = dense::polygonize(&f, &l, &Settings::default()).unwrap();
    let coarse = OctreeSettings {
        start_level: Some(1),
        ..Default::default()
    };
    let crate::polygonize::Polygonized {
        mesh: o, stats: _, ..
    } = polygonize(&f, &l, &coarse).unwrap();
    assert!(d.compare(&o).missing > 0);
    let deep = OctreeSettings {
        start_level: Some(6),
        ..Default::default()
    };
    let crate::polygonize::Polygonized {
        mesh: o, stats: _, ..
    } = polygonize(&f, &l, &deep).unwrap();
    assert_eq!(d.compare(&o).missing, 0);
}

#[test]
fn safety_is_given_or_derived_from_the_field() {
    use crate::field::blob::{BlobField, BlobSettings, PerPrimitive};
    let sphere = Sphere {
        center: DVec3::ZERO,
        radius: 0.5,
    };
    let blob = BlobField::new(
        &[DVec3::ZERO],
        PerPrimitive::All(0.5),
        PerPrimitive::All(2.0),
        0.5,
        BlobSettings::default(),
    )
    .unwrap();
    // Derived: 1 for a field without a gradient bound, the bound where it is larger.
    let derived = OctreeSettings::default();
    assert_eq!(derived.safety_for(&sphere).unwrap(), 1.0);
    let bound = blob.gradient_bound().unwrap();
    assert!(bound > 1.0);
    assert_eq!(derived.safety_for(&blob).unwrap(), bound);
    assert_eq!(derived.safety_for(&Counting::new(&blob)).unwrap(), bound);
    // Given: as it is, when positive and finite.
    let given = |safety| OctreeSettings {
        safety: Some(safety),
        ..Default::default()
    };
    assert_eq!(given(0.5).safety_for(&blob).unwrap(), 0.5);
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(given(bad).safety_for(&sphere).is_err(), "{bad}");
    }
}

/// `SHARED` holds exactly the points a block of 2 × 2 × 2 cells has in common with each
/// neighbour, and the decided map gives those points, clipped to the lattice, the sign of
/// the decided region they lie in.
#[test]
fn decided_neighbours_give_their_shared_points() {
    for k in 0..27 {
        let d = [k % 3, (k / 3) % 3, k / 9].map(|c| c as i32 - 1);
        let mine = |p: usize| [p % 3, (p / 3) % 3, p / 9].map(|c| c as i32);
        let want = (0..27)
            .filter(|&p| {
                (0..3).all(|a| (mine(p)[a] - 2 * d[a]).clamp(0, 2) == mine(p)[a] - 2 * d[a])
            })
            .fold(0u32, |m, p| m | 1 << p);
        assert_eq!(SHARED[k], want, "neighbour {d:?}");
    }
    let lattice = Lattice::new(DVec3::ZERO, DVec3::ONE, [12, 12, 9]).unwrap();
    let mut map = DecidedBlocks::new(&lattice);
    assert_eq!(map.dims, [6, 6, 5]);
    // Lattice points 4..=8 per axis negative; 8..=12 (x), 0..=4 (y), 8..=9 (z) positive.
    map.mark([4, 4, 4], 4, Some(true));
    map.mark([8, 0, 8], 4, Some(false));
    map.mark([0, 0, 0], 2, None);
    let face = (0..27).filter(|p| p % 3 == 2).fold(0u32, |m, p| m | 1 << p);
    // The block at x 2..=4 touches the negative region with its face x = 4.
    assert_eq!(map.masks([2, 4, 4]), (face, 0));
    // The block at 8..=10 shares its corner (8, 8, 8) with it, and its face z = 8 with the
    // positive region only along y ≤ 4: none of its points.
    assert_eq!(map.masks([8, 8, 8]), (1, 0));
    // The block at (8, 4, 6): corner-edge (x = 8, y = 4..=6, z = 6..=8) with the negative
    // region's face x = 8; z = 8, y = 4 with the positive region.
    let (neg, pos) = map.masks([8, 4, 6]);
    let at = |x: usize, y: usize, z: usize| 1u32 << block_point(x, y, z);
    assert_eq!(
        neg,
        (0..3)
            .flat_map(|y| (0..3).map(move |z| (y, z)))
            .fold(0, |m, (y, z)| m | at(0, y, z))
    );
    assert_eq!(pos, at(0, 0, 2) | at(1, 0, 2) | at(2, 0, 2));
    // Inside an undecided region and at the lattice's far corner: nothing.
    assert_eq!(map.masks([0, 8, 0]), (0, 0));
    assert_eq!(map.masks([10, 10, 8]), (0, 0));
    // A block dropped without a sign gives none, and every dropped block reads as dropped.
    assert_eq!(map.masks([2, 0, 0]), (0, 0));
    for z in 0..9 {
        for y in 0..12 {
            for x in 0..12 {
                let dropped = (4..8).contains(&x) && (4..8).contains(&y) && (4..8).contains(&z)
                    || x >= 8 && y < 4 && z >= 8
                    || x < 2 && y < 2 && z < 2;
                assert_eq!(map.dropped([x, y, z]), dropped, "cell {:?}", [x, y, z]);
            }
        }
    }
}

/// The decided blocks' codes, two bits each, are those a byte per block holds after the same
/// marks: single blocks, runs of whole bytes and of parts of bytes, clipped at the lattice's
/// ends, each mark over earlier ones; and the parallel marks of the last level.
#[test]
fn decided_codes_are_those_of_a_byte_per_block() {
    let lattice = Lattice::new(DVec3::splat(-1.0), DVec3::splat(1.0), [118, 60, 42]).unwrap();
    let mut map = DecidedBlocks::new(&lattice);
    let [nx, ny, nz] = map.dims;
    let mut model = vec![0u8; nx * ny * nz];
    let mut next = uniform(3);
    let mut pick = |n: u32| (next() * n as f64) as u32;
    for _ in 0..400 {
        let s = 2 << pick(4);
        let o = [pick(124), pick(64), pick(46)].map(|c| c & !1);
        let negative = [Some(true), Some(false), None][pick(3) as usize];
        map.mark(o, s, negative);
        let code = match negative {
            Some(true) => 1,
            Some(false) => 2,
            None => 3,
        };
        for z in (o[2] / 2) as usize..((o[2] + s) / 2).min(nz as u32) as usize {
            for y in (o[1] / 2) as usize..((o[1] + s) / 2).min(ny as u32) as usize {
                for x in (o[0] / 2) as usize..((o[0] + s) / 2).min(nx as u32) as usize {
                    model[x + nx * (y + ny * z)] = code;
                }
            }
        }
        let codes: Vec<u8> = (0..map.len()).map(|i| map.get(i)).collect();
        assert_eq!(codes, model, "after a mark of {s} at {o:?}");
    }
    let blocks: Vec<[u32; 3]> = (0..map.len())
        .map(|i| [2 * (i % nx), 2 * (i / nx % ny), 2 * (i / (nx * ny))].map(|c| c as u32))
        .collect();
    let marks: Vec<Option<Option<bool>>> = (0..blocks.len())
        .map(|_| [None, Some(Some(true)), Some(Some(false)), Some(None)][pick(4) as usize])
        .collect();
    map.mark_blocks(&blocks, 2, |i| marks[i]);
    for (i, m) in marks.iter().enumerate() {
        let want = match m {
            None => model[i],
            Some(Some(true)) => 1,
            Some(Some(false)) => 2,
            Some(None) => 3,
        };
        assert_eq!(map.get(i), want, "block {i}");
    }
}

/// The ends of crossed edges with only a sign are those that an edge-by-edge search finds,
/// for every leaf of a block and mixes of values, signs and unknown points.
#[test]
fn decided_masks_inside_the_map_are_those_at_its_edge() {
    let lattice = Lattice::new(DVec3::splat(-1.0), DVec3::splat(1.0), [12, 10, 14]).unwrap();
    let mut d = DecidedBlocks::new(&lattice);
    let mut next = uniform(7);
    for i in 0..d.len() {
        d.set(i, (next() * 4.0) as u8);
    }
    let [nx, ny, nz] = d.dims.map(|n| n as u32);
    let mut inside = 0;
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let o = [2 * x, 2 * y, 2 * z];
                assert_eq!(d.masks(o), d.masks_at_edge(o), "block {o:?}");
                inside +=
                    (x > 0 && y > 0 && z > 0 && x + 1 < nx && y + 1 < ny && z + 1 < nz) as u32;
            }
        }
    }
    assert!(inside > 50);
}

#[test]
fn unknown_edge_ends_are_those_of_crossed_edges() {
    let mut next = uniform(5);
    for _ in 0..2000 {
        // Signs inferred as ±∞, values as numbers, unknown as NaN.
        let v: [f64; 27] = std::array::from_fn(|_| match (4.0 * next()) as u32 {
            0 => f64::NEG_INFINITY,
            1 => f64::INFINITY,
            2 => f64::NAN,
            _ => next() - 0.5,
        });
        let states = v.map(|x| match x {
            f64::NEG_INFINITY => PointState::INFERRED_NEGATIVE,
            f64::INFINITY => PointState::INFERRED_POSITIVE,
            _ if x.is_nan() => PointState::UNKNOWN,
            _ => PointState::of_value(x),
        });
        for d in 0..8 {
            let mut want = 0;
            for [ka, kb] in EDGES {
                let [a, b] = [ka, kb].map(|k| LEAF_CORNERS[d][k as usize] as usize);
                if (v[a] < 0.0) != (v[b] < 0.0) {
                    want |= (v[a].is_infinite() as u32) << a | (v[b].is_infinite() as u32) << b;
                }
            }
            let (neg, _, inferred) = sign_masks(&states);
            assert_eq!(unknown_edge_ends(neg, inferred, d), want, "{v:?} {d}");
        }
    }
}

/// The signs inferred are exactly those of the block points inside the balls of one sign,
/// and a cubic block has 9 distances from its corner.
#[test]
fn ball_masks_are_the_balls() {
    let mut next = uniform(3);
    for cell in [DVec3::splat(0.1), DVec3::new(0.1, 0.07, 0.16)] {
        for safety in [1.0, 1.7] {
            let reach = block_reach(cell, safety);
            let at =
                |p: usize| DVec3::new((p % 3) as f64, ((p / 3) % 3) as f64, (p / 9) as f64) * cell;
            for _ in 0..500 {
                let v: [f64; 27] = std::array::from_fn(|_| match (next() * 5.0) as u32 {
                    0 => f64::NAN,
                    1 => f64::INFINITY,
                    2 => f64::NEG_INFINITY,
                    _ => (next() - 0.5) * 0.8,
                });
                let (neg, pos) = ball_masks(&v, (1 << 27) - 1, &reach);
                for q in 0..27 {
                    let inside = |negative: bool| {
                        (0..27).any(|p| {
                            p != q
                                && v[p].is_finite()
                                && (v[p] < 0.0) == negative
                                && v[p] != 0.0
                                && v[p].abs() / safety > (at(p) - at(q)).length()
                        })
                    };
                    assert_eq!(neg & 1 << q != 0, inside(true), "{q} {v:?}");
                    assert_eq!(pos & 1 << q != 0, inside(false), "{q} {v:?}");
                }
            }
        }
    }
    let cubic = block_reach(DVec3::splat(0.1), 1.0);
    assert_eq!(cubic[0].iter().filter(|r| r.reach.is_finite()).count(), 9);
    assert_eq!(cubic[13].iter().filter(|r| r.reach.is_finite()).count(), 3);
}

/// Uniform numbers in [0, 1) from a seed ([`Lcg`]).
fn uniform(seed: u64) -> impl FnMut() -> f64 {
    let mut rng = Lcg::new(seed);
    move || rng.uniform()
}

/// The exact test for two opposite balls is sound (sampled) and proves at least what the
/// octant splitting proves.
#[test]
fn opposite_balls_are_decided_exactly() {
    let mut next = uniform(5);
    let (mut exact, mut split) = (0, 0);
    for _ in 0..4000 {
        let size = DVec3::new(0.5 + next(), 0.5 + next(), 0.5 + next());
        let far = size.length();
        let (r0, r1) = (next() * 1.1 * far, next() * 1.1 * far);
        let yes = covered_by_opposite_balls(r0, r1, size);
        let balls = [(DVec3::ZERO, r0 * r0), (size, r1 * r1)];
        let by_split = covered_piece(&balls, 3, DVec3::ZERO, size, 5);
        assert!(yes || !by_split, "{r0} {r1} {size}");
        exact += yes as u32;
        split += by_split as u32;
        if yes {
            for _ in 0..100 {
                let p = DVec3::new(next(), next(), next()) * size;
                assert!(
                    p.length() < r0 || (p - size).length() < r1,
                    "{r0} {r1} {size} {p}"
                );
            }
            // The box's other corners, where the two balls are weakest.
            for k in 1..7 {
                let d = Corner::new(k).offset();
                let p = DVec3::new(d[0] as f64, d[1] as f64, d[2] as f64) * size;
                assert!(p.length() < r0 || (p - size).length() < r1);
            }
        }
    }
    assert!(exact > split && split > 100, "{exact} {split}");
}

/// `covered` is sound: wherever it says a box is covered, every sample point of the box
/// lies in a ball; and it finds the covers that are easy to see.
#[test]
fn cover_test_is_sound() {
    let mut next = uniform(11);
    let size = DVec3::new(1.0, 0.8, 1.3);
    let corners: [DVec3; 8] = Corner::ALL.map(|k| {
        let d = k.offset();
        DVec3::new(d[0] as f64, d[1] as f64, d[2] as f64) * size
    });
    let mut yes = 0;
    for _ in 0..3000 {
        let radius: [f64; 8] = std::array::from_fn(|_| {
            let r = next() * 1.8;
            if next() < 0.3 {
                f64::NAN
            } else {
                r
            }
        });
        if !covered(&radius, size) {
            continue;
        }
        yes += 1;
        for _ in 0..200 {
            let p = DVec3::new(next(), next(), next()) * size;
            assert!(
                corners
                    .iter()
                    .zip(&radius)
                    .any(|(c, r)| (p - *c).length() < *r),
                "{radius:?} {p}"
            );
        }
    }
    assert!(yes > 100, "{yes}");
    // One ball reaching the far corner covers the box; two opposite balls that miss the
    // box's centre do not; two that each reach past the centre and take in the corners
    // nearest to them do.
    let far = size.length();
    let mut r = [f64::NAN; 8];
    r[0] = far * 1.0001;
    assert!(covered(&r, size));
    r[0] = 0.45 * far;
    r[7] = 0.45 * far;
    assert!(!covered(&r, size));
    r[0] = 0.95 * far;
    r[7] = 0.95 * far;
    assert!(covered(&r, size));
    assert!(!covered(&[f64::NAN; 8], size));
}
