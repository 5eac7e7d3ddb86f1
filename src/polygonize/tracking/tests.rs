//! Both engines against the dense and sparse polygonizers and against each other.

use super::blocks::BlockTracking;
use super::*;
use crate::error::Error;
use crate::field::blob::{BlobField, BlobSettings, PerPrimitive};
use crate::field::{BlockField, Counting, Field};
use crate::lattice::Lattice;
use crate::mesh::Mesh;
use crate::polygonize::{dense, sparse, Ambiguity, Settings, Stats};
use crate::testing::random_blobs as blobs;
use crate::testing::{
    canonical_triangles as canonical, for_each_blob_case, random_points, vertex_normal_bits, Lying,
    BLOB_CASES,
};
use glam::DVec3;

/// Walks from `starts`, at most `max_walk` cells each, to the components they reach.
fn walks(starts: &[DVec3], max_walk: u32) -> TrackingSettings {
    TrackingSettings {
        starts: starts.to_vec(),
        max_walk,
        ..Default::default()
    }
}

/// No walks: the components of `seed_cells`, or every one (`components`).
fn seeds(seed_cells: &[[u32; 3]], components: Components) -> TrackingSettings {
    TrackingSettings {
        seed_cells: seed_cells.to_vec(),
        components,
        ..Default::default()
    }
}

/// Tracking block by block with `ws`'s buffers: the mesh, its triangles, the stats.
fn by_blocks<F: BlockField + ?Sized>(
    f: &F,
    l: &Lattice,
    s: &TrackingSettings,
    ws: &mut BlockTracking,
) -> crate::error::Result<(Mesh, Vec<[u32; 3]>, Stats)> {
    ws.polygonize::<_, u32>(f, l, s)
}

#[test]
fn tracking_equals_dense_on_blobs() {
    for (n, r, res, seed) in [
        (1, 0.3, 20, 1),
        (30, 0.25, 40, 2),
        (200, 0.12, 64, 3),
        (5, 0.05, 30, 4),
    ] {
        let b = blobs(n, r, seed);
        let l = Lattice::new(DVec3::splat(-1.0), DVec3::splat(1.0), [res; 3]).unwrap();
        for amb in [Ambiguity::Separate, Ambiguity::Join] {
            let s = Settings {
                ambiguity: amb,
                ..Default::default()
            };
            let crate::polygonize::Polygonized {
                mesh: d, stats: _, ..
            } = dense::polygonize(&b, &l, &s).unwrap();
            let counting = Counting::new(&b);
            let max_walk = (r / l.cell().x).ceil() as u32 + 2;
            let ts = TrackingSettings {
                common: s,
                ..walks(b.centers(), max_walk)
            };
            let crate::polygonize::Polygonized {
                mesh: t, stats: st, ..
            } = polygonize(&counting, &l, &ts).unwrap();
            let c = d.compare(&t);
            assert_eq!(
                (c.missing, c.extra),
                (0, 0),
                "n={n} r={r} res={res} {amb:?}"
            );
            assert_eq!(counting.evaluations(), st.evaluations);
            if !t.triangles.is_empty() {
                assert!(t.is_closed_oriented());
            }
        }
    }
}

#[test]
fn every_component_needs_block_bounds() {
    // A field without block bounds is refused, cell by cell and block by block; a blob field,
    // also behind a reference, has them.
    let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 8).unwrap();
    let sphere = crate::field::analytic::Sphere {
        center: DVec3::ZERO,
        radius: 0.5,
    };
    let all = seeds(&[[4, 4, 4]], Components::All);
    let refused = |e: Error| matches!(e, Error::InvalidArgument { name: "method", .. });
    assert!(refused(polygonize(&sphere, &l, &all).unwrap_err()));
    let mut tess = Tessellator::new();
    assert!(refused(
        tess.polygonize_blocks::<_, u32>(&sphere, &l, &all)
            .unwrap_err()
    ));
    let b = blobs(3, 0.3, 1);
    assert!(polygonize(&&b, &l, &all).is_ok());
}

/// A hollow shell: 150 blobs of radius 0.25 on a sphere of radius 0.6 (Fibonacci points).
/// Its inner surface, around a cavity at the centre, is a component of its own.
fn shell() -> BlobField {
    let centers: Vec<DVec3> = crate::testing::fibonacci_sphere(150)
        .into_iter()
        .map(|u| 0.6 * u)
        .collect();
    let one = |v| PerPrimitive::All(v);
    BlobField::new(&centers, one(0.25), one(1.0), 0.5, BlobSettings::default()).unwrap()
}

/// Triangles of `m` with a corner inside radius 0.6 (the shell's inner surface).
fn inner_triangles(m: &Mesh) -> usize {
    let inside = |t: &[u32; 3]| m.vertices[t[0] as usize].length() < 0.6;
    m.triangles.iter().filter(|t| inside(t)).count()
}

/// The mesh `m` (triangles `t`) is `d`'s: the same triangles, vertices and normals, bits.
fn assert_same_mesh(m: &Mesh, t: &[[u32; 3]], d: &Mesh) {
    assert_eq!(
        canonical(&m.vertices, t),
        canonical(&d.vertices, &d.triangles)
    );
    assert_eq!(
        vertex_normal_bits(&m.vertices, &m.normals),
        vertex_normal_bits(&d.vertices, &d.normals)
    );
}

#[test]
fn all_components_include_the_cavity_no_seed_reaches() {
    let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 48).unwrap();
    let s = Settings::default();
    let crate::polygonize::Polygonized {
        mesh: d,
        stats: dense_stats,
        ..
    } = dense::polygonize(&shell(), &l, &s).unwrap();
    let crate::polygonize::Polygonized {
        mesh: sp, stats: _, ..
    } = sparse::polygonize(&shell(), &l, &s).unwrap();
    // One start outside the shell: its walk along +x meets the outer surface first.
    let seeded = walks(&[DVec3::new(-0.95, 0.01, 0.02)], 48);
    let every = TrackingSettings {
        components: Components::All,
        ..seeded.clone()
    };
    let mut tess = Tessellator::new();
    let (found, _) = tess.polygonize(&shell(), &l, &seeded).unwrap();
    // The walk alone finds the outer surface whole and nothing of the inner one.
    let inner = inner_triangles(&d);
    assert!(inner > 0);
    assert_eq!(inner_triangles(found), 0);
    assert_eq!(found.triangles.len() + inner, d.triangles.len());
    // Every component, cell by cell: the dense mesh, every point counted.
    let counting = Counting::new(shell());
    let (all, st) = tess.polygonize(&counting, &l, &every).unwrap();
    assert_same_mesh(all, &all.triangles, &d);
    assert_eq!(st.evaluations, counting.evaluations());
    assert_eq!(st.cells_crossed, dense_stats.cells_crossed);
    // Block by block: the seeded walk misses the inner surface too; every component is
    // sparse's mesh, array for array.
    let f = Counting::new(shell());
    let mut ws = BlockTracking::default();
    let (_, t, _) = by_blocks(f.block_field().unwrap(), &l, &seeded, &mut ws).unwrap();
    assert_eq!(t.len() + inner, d.triangles.len());
    let before = f.evaluations();
    let (m, t, st) = by_blocks(f.block_field().unwrap(), &l, &every, &mut ws).unwrap();
    assert_eq!(
        (t, &m.vertices, &m.normals),
        (sp.triangles.clone(), &sp.vertices, &sp.normals)
    );
    assert_eq!(st.evaluations, f.evaluations() - before);
}

/// Clusters of 50 to 400 blobs of radius 0.15 to 0.3 with centres in [-0.7, 0.7]³: the
/// walks from the centres miss components in some (cavities inside the cluster); every
/// component, cell by cell and block by block, gives the dense mesh.
#[test]
fn every_component_of_random_clusters() {
    let s = Settings::default();
    let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 48).unwrap();
    let (mut tess, mut ws) = (Tessellator::new(), BlockTracking::default());
    let mut missed = 0;
    // Clusters 10, 16, 18 and 21 have cavities no walk from a centre reaches (at 48³).
    for seed in 10..=21 {
        let n = 50 + (seed as usize * 97) % 351;
        let r = 0.15 + 0.15 * ((seed * 37) % 100) as f64 / 100.0;
        let centers = random_points(n, -0.7, 0.7, seed);
        let one = |v| PerPrimitive::All(v);
        let f = BlobField::new(&centers, one(r), one(1.0), 0.5, BlobSettings::default());
        let f = f.unwrap();
        let crate::polygonize::Polygonized {
            mesh: d, stats: _, ..
        } = dense::polygonize(&f, &l, &s).unwrap();
        let max_walk = (r / l.cell().x).ceil() as u32 + 2;
        let seeded = walks(&centers, max_walk);
        let (found, _) = tess.polygonize(&f, &l, &seeded).unwrap();
        let c = d.compare(found);
        assert_eq!(c.extra, 0);
        missed += (c.missing > 0) as usize;
        let every = TrackingSettings {
            components: Components::All,
            ..seeded
        };
        let (all, _) = tess.polygonize(&f, &l, &every).unwrap();
        assert_same_mesh(all, &all.triangles, &d);
        let (m, t, _) = tess.polygonize_blocks::<_, u32>(&f, &l, &every).unwrap();
        assert_same_mesh(&m, &t, &d);
        let (m, t, _) = by_blocks(&f, &l, &every, &mut ws).unwrap();
        assert_same_mesh(&m, &t, &d);
    }
    assert_eq!(missed, 4);
}

#[test]
fn animation_reuses_memory() {
    let mut b = blobs(200, 0.25, 9);
    let l = Lattice::new(DVec3::splat(-1.2), DVec3::splat(1.2), [64; 3]).unwrap();
    let mut tess = Tessellator::new();
    let base: Vec<DVec3> = b.centers().to_vec();
    let mut sizes = vec![];
    for frame in 0..60 {
        let t = frame as f64 * 0.05;
        let c: Vec<DVec3> = base
            .iter()
            .enumerate()
            .map(|(i, p)| {
                *p + DVec3::new((t + i as f64).sin(), (t * 1.3 + i as f64).cos(), 0.0) * 0.05
            })
            .collect();
        b.update(&c, None, None).unwrap();
        let (m, _) = tess.polygonize(&b, &l, &walks(b.centers(), 10)).unwrap();
        assert!(m.is_closed_oriented());
        sizes.push(tess.capacity_bytes());
    }
    // After warming up, the capacity stays flat.
    assert!(sizes[59] <= sizes[19] * 5 / 4, "{:?}", sizes);
}

/// The walk block by block's output equals the walk cell by cell's: the same triangles,
/// vertices and normals (bits), every vertex used, the same cells crossed.
fn assert_same((m, t, bs): (&Mesh, &[[u32; 3]], &Stats), (cells, st): (&Mesh, &Stats)) {
    assert_eq!(
        canonical(&m.vertices, t),
        canonical(&cells.vertices, &cells.triangles)
    );
    assert_eq!(m.vertices.len(), cells.vertices.len());
    assert_eq!(bs.cells_crossed, st.cells_crossed);
    assert_eq!(
        vertex_normal_bits(&m.vertices, &m.normals),
        vertex_normal_bits(&cells.vertices, &cells.normals)
    );
}

#[test]
fn blocks_equal_cells_on_random_blobs() {
    // Block tracking and cell tracking, each walking its seeds from the blob centres.
    let mut ws = BlockTracking::default();
    let mut tess = Tessellator::new();
    let cases = [&BLOB_CASES[..], &[(40, 0.1, 90, 7)]].concat();
    for_each_blob_case(&cases, |f, l| {
        for amb in [Ambiguity::Separate, Ambiguity::Join] {
            let s = TrackingSettings {
                common: Settings {
                    ambiguity: amb,
                    ..Default::default()
                },
                ..walks(f.centers(), 12)
            };
            let (cells, st) = tess.polygonize(&f, l, &s).unwrap();
            let (m, t, bs) = by_blocks(&f, l, &s, &mut ws).unwrap();
            assert_same((&m, &t, &bs), (cells, &st));
        }
    });
}

#[test]
fn one_seed_finds_one_component_of_many() {
    // Separate blobs on a line, sharing blocks: a seed in one finds it alone, and only the
    // vertices of its triangles.
    let centers: Vec<DVec3> = (0..4)
        .map(|i| DVec3::new(-0.45 + 0.3 * i as f64, 0.1, -0.05))
        .collect();
    let f = BlobField::new(
        &centers,
        PerPrimitive::All(0.2),
        PerPrimitive::All(1.0),
        0.5,
        BlobSettings::default(),
    )
    .unwrap();
    let l = Lattice::new(DVec3::splat(-1.0), DVec3::splat(1.0), [61, 23, 30]).unwrap();
    let crate::polygonize::Polygonized {
        mesh: all,
        stats: _,
        ..
    } = dense::polygonize(&f, &l, &Settings::default()).unwrap();
    let mut ws = BlockTracking::default();
    for centre in &centers {
        // Walked from inside the blob along +x to its surface.
        let c = *centre - DVec3::new(0.05, 0.0, 0.0);
        let (m, t, _) = by_blocks(&f, &l, &walks(&[c], 20), &mut ws).unwrap();
        let near = |v: DVec3| (v.x - centre.x).abs() < 0.15;
        let own = all.triangles.iter();
        let own = own.filter(|t| near(all.vertices[t[0] as usize]));
        assert_eq!(t.len(), own.count());
        assert!(!t.is_empty());
        assert!(m.vertices.iter().all(|&v| near(v)));
        // Every vertex is used.
        let mut used = vec![false; m.vertices.len()];
        t.iter().flatten().for_each(|&v| used[v as usize] = true);
        assert!(used.iter().all(|&u| u));
    }
}

#[test]
fn wrong_bounds_give_an_error_not_a_panic() {
    let f = Lying::sphere();
    let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 32).unwrap();
    // Cell (8, 16, 16) holds the surface (at x = -0.487, in block 1); the sphere also crosses
    // block 2, which the bounds wrongly rule out.
    let mut ws = BlockTracking::default();
    let seed = seeds(&[[8, 16, 16]], Components::Seeded);
    let e = by_blocks(&f, &l, &seed, &mut ws).unwrap_err();
    assert!(
        matches!(e, Error::InvalidArgument { name: "field", .. }),
        "{e}"
    );
    // The true field from the same seed: the whole sphere.
    let (m, t, _) = by_blocks(&f.0, &l, &seed, &mut ws).unwrap();
    let crate::polygonize::Polygonized {
        mesh: d, stats: _, ..
    } = dense::polygonize(&f.0, &l, &Settings::default()).unwrap();
    assert_eq!(
        (m.vertices.len(), t.len()),
        (d.vertices.len(), d.triangles.len())
    );
}

#[test]
fn seeds_not_crossed_or_outside_find_nothing() {
    let f = blobs(10, 0.2, 8);
    let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 30).unwrap();
    let mut ws = BlockTracking::default();
    let s = seeds(
        &[[0, 0, 0], [30, 2, 2], [u32::MAX, 0, 0]],
        Components::Seeded,
    );
    let (m, t, st) = by_blocks(&f, &l, &s, &mut ws).unwrap();
    assert!(t.is_empty() && m.vertices.is_empty());
    assert_eq!(st.cells_crossed, 0);
}

/// A seed cell in every triangle of `m` (the cell holding its centroid).
fn seeds_of(m: &Mesh, l: &Lattice) -> Vec<[u32; 3]> {
    m.triangles
        .iter()
        .map(|t| {
            let c = t.iter().map(|&v| m.vertices[v as usize]).sum::<DVec3>() / 3.0;
            ((c - l.origin()) / l.cell())
                .floor()
                .to_array()
                .map(|v| v as u32)
        })
        .collect()
}

/// `m` with triangles `t` is `sp`, array for array (the same order, the same bits).
fn assert_is_sparse((m, t): (&Mesh, &[[u32; 3]]), sp: &Mesh) {
    assert_eq!(t, sp.triangles);
    assert_eq!((&m.vertices, &m.normals), (&sp.vertices, &sp.normals));
}

#[test]
fn equals_sparse_exactly_whatever_the_earlier_calls() {
    // Every component seeded: sparse's mesh, array for array, from a fresh workspace and from
    // one that polygonized other fields and lattices first (whose blocks it evaluates ahead).
    let s = Settings::default();
    let mut kept = BlockTracking::default();
    let cases = [
        (200, 0.25, 64, 11),
        (200, 0.25, 64, 12),
        (60, 0.12, 37, 13),
        (500, 0.08, 50, 14),
        (500, 0.08, 64, 14),
        (3, 0.5, 20, 15),
    ];
    for_each_blob_case(&cases, |f, l| {
        let crate::polygonize::Polygonized {
            mesh: sp, stats: _, ..
        } = sparse::polygonize(&f, l, &s).unwrap();
        let every = seeds(&seeds_of(&sp, l), Components::Seeded);
        let (m, t, _) = by_blocks(&f, l, &every, &mut BlockTracking::default()).unwrap();
        assert!(!t.is_empty());
        assert_is_sparse((&m, &t), &sp);
        let (again, t_again, _) = by_blocks(&f, l, &every, &mut kept).unwrap();
        assert_is_sparse((&again, &t_again), &sp);
    });
}

#[test]
fn every_component_without_seeds_is_sparse_exactly() {
    // No seed at all: every component is found, sparse's mesh array for array, from a fresh
    // workspace and from one that polygonized other fields first; every point evaluated is
    // counted.
    let s = Settings::default();
    let mut kept = BlockTracking::default();
    let all = seeds(&[], Components::All);
    let cases = [(200, 0.25, 64, 31), (60, 0.12, 37, 32), (3, 0.5, 20, 33)];
    for_each_blob_case(&cases, |f, l| {
        let f = Counting::new(f);
        let crate::polygonize::Polygonized {
            mesh: sp, stats: _, ..
        } = sparse::polygonize(&f.inner, l, &s).unwrap();
        assert!(!sp.triangles.is_empty());
        for ws in [&mut BlockTracking::default(), &mut kept] {
            let before = f.evaluations();
            let (m, t, st) = by_blocks(f.block_field().unwrap(), l, &all, ws).unwrap();
            assert_is_sparse((&m, &t), &sp);
            assert_eq!(st.evaluations, f.evaluations() - before);
        }
    });
}

#[test]
fn every_component_with_wrong_bounds_gives_an_error() {
    // The bounds rule out blocks the sphere crosses: an error, not a panic nor a mesh with
    // holes.
    let f = Lying::sphere();
    let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 32).unwrap();
    let mut ws = BlockTracking::default();
    let e = by_blocks(&f, &l, &seeds(&[], Components::All), &mut ws).unwrap_err();
    assert!(
        matches!(e, Error::InvalidArgument { name: "field", .. }),
        "{e}"
    );
}

#[test]
fn blocks_evaluated_ahead_change_nothing() {
    // A workspace that last polygonized all of a field, then one seed: only that seed's
    // component, the same arrays as from a fresh workspace (the blocks evaluated ahead that
    // no seed reaches add nothing; those partly reached give up their unused vertices).
    let s = Settings::default();
    let f = blobs(40, 0.2, 21);
    let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 48).unwrap();
    let crate::polygonize::Polygonized {
        mesh: sp, stats: _, ..
    } = sparse::polygonize(&f, &l, &s).unwrap();
    let every = seeds(&seeds_of(&sp, &l), Components::Seeded);
    let mut kept = BlockTracking::default();
    let (all, all_t, _) = by_blocks(&f, &l, &every, &mut kept).unwrap();
    let mut smaller = 0;
    for seed in every.seed_cells.iter().step_by(97) {
        let one = seeds(std::slice::from_ref(seed), Components::Seeded);
        let (m, t, st) = by_blocks(&f, &l, &one, &mut BlockTracking::default()).unwrap();
        // Evaluated ahead: at least the blocks of the whole surface.
        by_blocks(&f, &l, &every, &mut kept).unwrap();
        let (k, kt, kst) = by_blocks(&f, &l, &one, &mut kept).unwrap();
        assert!(kst.evaluations > st.evaluations);
        assert_eq!(
            (kt, k.vertices, k.normals),
            (t.clone(), m.vertices, m.normals)
        );
        smaller += (t.len() < all_t.len()) as usize;
    }
    // The seeds found components smaller than the whole.
    assert!(smaller > 0 && !all.vertices.is_empty());
}

#[test]
fn blobs_apart_in_the_last_blocks_one_at_a_time() {
    // Blobs 0.08 apart on a grid by the lattice's upper corner, cut by its sides, in blocks
    // shared by several (and last blocks of 2 points along each axis): seeded one at a time,
    // each equals cell tracking's, bit for bit, and keeps only its own vertices.
    let mut centers = vec![];
    for i in 0..4 {
        for j in 0..4 {
            for k in 0..4 {
                centers.push(
                    DVec3::new(0.75, 0.751, 0.752)
                        + 0.08 * DVec3::new(i as f64, j as f64, k as f64),
                );
            }
        }
    }
    let f = BlobField::new(
        &centers,
        PerPrimitive::All(0.055),
        PerPrimitive::All(1.0),
        0.5,
        BlobSettings::default(),
    )
    .unwrap();
    // 36 cells per axis: blocks of 7, 7, 7, 7, 7 and a last block of 1 cell.
    let l = Lattice::cubic(DVec3::splat(0.64), DVec3::splat(1.0), 36).unwrap();
    let (mut ws, mut tess) = (BlockTracking::default(), Tessellator::new());
    let mut found = 0;
    for c in &centers {
        let s = walks(std::slice::from_ref(c), 10);
        let (cells, st) = tess.polygonize(&f, &l, &s).unwrap();
        let (m, t, bs) = by_blocks(&f, &l, &s, &mut ws).unwrap();
        assert_same((&m, &t, &bs), (cells, &st));
        found += !t.is_empty() as usize;
    }
    // Every blob found alone (the blobs do not touch).
    assert_eq!(found, centers.len());
    let crate::polygonize::Polygonized {
        mesh: all,
        stats: _,
        ..
    } = dense::polygonize(&f, &l, &Settings::default()).unwrap();
    assert!(all
        .vertices
        .iter()
        .any(|v| v.max_element() > l.origin().x + 35.0 * l.cell().x));
}

/// `track` goes block by block only for a field with block bounds, and both ways give the
/// settings' mesh: a blob field's every component, a sphere's seeded one.
#[test]
fn track_walks_blocks_only_with_block_bounds() {
    let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 24).unwrap();
    let b = blobs(20, 0.25, 5);
    let s = TrackingSettings::for_field(&b, &l, Settings::default(), None).unwrap();
    assert_eq!(s.components, Components::All);
    let mut tess = Tessellator::new();
    let (cells, t_cells, _) = tess.track::<_, u32>(&b, &l, &s, false).unwrap();
    let (blocks, t_blocks, st) = tess.track::<_, i64>(&b, &l, &s, true).unwrap();
    let canon = |m: &Mesh, t: Vec<[u32; 3]>| canonical(&m.vertices, &t);
    let wide: Vec<[u32; 3]> = t_blocks.iter().map(|t| t.map(|v| v as u32)).collect();
    assert_eq!(canon(&cells, t_cells), canon(&blocks, wide));
    assert!(st.evaluations > 0 && cells.triangles.is_empty());
    let sphere = crate::field::analytic::Sphere {
        center: DVec3::ZERO,
        radius: 0.5,
    };
    let s = TrackingSettings::for_field(&sphere, &l, Settings::default(), Some(vec![DVec3::ZERO]))
        .unwrap();
    assert_eq!(s.components, Components::Seeded);
    let (m, t, _) = tess.track::<_, u32>(&sphere, &l, &s, true).unwrap();
    let d = dense::polygonize(&sphere, &l, &Settings::default())
        .unwrap()
        .mesh;
    assert_eq!(canon(&m, t), canonical(&d.vertices, &d.triangles));
}
