//! Property tests of the core's entry points with arbitrary input: every call returns `Ok` or an
//! `Err`, never panics; where it returns `Ok`, the result keeps its promises (interpolation, mesh
//! equality between polygonizers, indices in range).

use glam::DVec3;
use implicitmesh::field::analytic::Sphere;
use implicitmesh::field::blob::densities::kernel_sums;
use implicitmesh::field::blob::kernel::BlobKernel;
use implicitmesh::field::blob::particles::{colour_field, ParticleSettings};
use implicitmesh::field::blob::{BlobField, BlobSettings, PerPrimitive};
use implicitmesh::field::rbf::partition::{PartitionSettings, PartitionSurface};
use implicitmesh::field::rbf::{constraints, FitSettings, VariationalSurface};
use implicitmesh::field::Field;
use implicitmesh::lattice::Lattice;
use implicitmesh::mesh::Mesh;
use implicitmesh::polygonize::{octree, polygonize, Method, Settings};
use implicitmesh::subdivision;
use proptest::prelude::*;

/// Any float, the special values often.
fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -2.0..2.0f64,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => Just(0.0),
        1 => Just(1e300),
        1 => Just(1e-300),
    ]
}

fn point() -> impl Strategy<Value = DVec3> {
    (any_f64(), any_f64(), any_f64()).prop_map(|(x, y, z)| DVec3::new(x, y, z))
}

/// Points that are mostly sane (finite, in the box), with a special one now and then.
fn points(max: usize) -> impl Strategy<Value = Vec<DVec3>> {
    prop::collection::vec(
        prop_oneof![9 => (-1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64).prop_map(|(x, y, z)| DVec3::new(x, y, z)), 1 => point()],
        0..max,
    )
}

/// A finite magnitude anywhere from 1e-300 to 1e300, either sign.
fn magnitude() -> impl Strategy<Value = f64> {
    (-300i32..=300, 1.0..10.0f64, any::<bool>()).prop_map(|(e, m, neg)| {
        let v = m * 10f64.powi(e);
        if neg {
            -v
        } else {
            v
        }
    })
}

/// Point sets over the whole finite range: a cloud of one scale at an offset, with a single far
/// point, mixed scales or near-duplicates at the offset (always finite).
fn extreme_points(max: usize) -> impl Strategy<Value = Vec<DVec3>> {
    let unit = (-1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64).prop_map(|(x, y, z)| DVec3::new(x, y, z));
    (
        prop::collection::vec(unit, 4..max),
        magnitude(),
        magnitude(),
        0u8..4,
        magnitude(),
        any::<prop::sample::Index>(),
    )
        .prop_map(|(u, scale, offset, kind, other, at)| {
            let mut p: Vec<DVec3> = u
                .iter()
                .map(|q| *q * scale.abs() + DVec3::splat(offset))
                .collect();
            let n = p.len();
            match kind {
                0 => p[at.index(n)].x = other,
                1 => p[..n / 2]
                    .iter_mut()
                    .zip(&u)
                    .for_each(|(q, v)| *q = *v * other.abs()),
                2 => {
                    let h = n / 2;
                    for i in h..n {
                        p[i] = p[i - h] * (1.0 + 1e-15);
                    }
                }
                _ => {}
            }
            p.into_iter()
                .map(|q| {
                    if q.is_finite() {
                        q
                    } else {
                        DVec3::splat(1e300)
                    }
                })
                .collect()
        })
}

fn small_lattice() -> impl Strategy<Value = Lattice> {
    (1u32..14, 1u32..14, 1u32..14).prop_map(|(a, b, c)| {
        Lattice::new(DVec3::splat(-1.0), DVec3::splat(1.0), [a, b, c]).unwrap()
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, .. ProptestConfig::default() })]

    #[test]
    fn lattices_refuse_or_hold(min in point(), max in point(), a in 0u32..40, b in 0u32..40, c in 0u32..40, n in 0u32..40) {
        if let Ok(l) = Lattice::new(min, max, [a, b, c]) {
            prop_assert_eq!(l.cells(), [a, b, c]);
            prop_assert!(l.cell().is_finite() && l.cell().min_element() > 0.0);
        }
        if let Ok(l) = Lattice::cubic(min, max, n) {
            prop_assert!(l.cells().iter().all(|&k| k >= 1));
        }
    }

    #[test]
    fn fits_refuse_or_interpolate(p in points(24), n in points(24)) {
        let k = p.len().min(n.len());
        let fit = VariationalSurface::fit(&p[..k], &n[..k], &constraints::ConstraintSettings::default(), &FitSettings::default());
        if let Ok(s) = fit {
            let c = s.constraints();
            let scale = c.values.iter().fold(1e-300f64, |m, v| m.max(v.abs()));
            for (q, v) in c.points.iter().zip(&c.values) {
                prop_assert!((s.value(*q) - v).abs() <= 1e-4 * scale);
            }
        }
    }

    #[test]
    fn blob_polygonizers_agree(c in points(12), r in 0.05..0.6f64, t in prop_oneof![Just(0.5), any_f64()], l in small_lattice()) {
        let Ok(blobs) = BlobField::new(&c, PerPrimitive::All(r), PerPrimitive::All(1.0), t, BlobSettings::default()) else {
            return Ok(());
        };
        let s = Settings::default();
        let d = polygonize(&blobs, &l, &Method::Dense(s)).unwrap().mesh;
        let m = polygonize(&blobs, &l, &Method::Sparse(s)).unwrap().mesh;
        let cmp = d.compare(&m);
        prop_assert_eq!((cmp.missing, cmp.extra), (0, 0));
        prop_assert!(m.triangles.iter().flatten().all(|&i| (i as usize) < m.vertices.len()));
    }

    #[test]
    fn octree_settings_refuse_or_equal_dense(safety in any_f64(), start in prop::option::of(0u32..12), corner_test: bool, l in small_lattice(), r in 0.1..0.9f64) {
        let sphere = Sphere { center: DVec3::new(0.01, -0.02, 0.03), radius: r };
        let s = Settings::default();
        let o = octree::OctreeSettings { common: s, safety: Some(safety), start_level: start, corner_test };
        if let Ok(m) = polygonize(&sphere, &l, &Method::Octree(o)).map(|p| p.mesh) {
            let d = polygonize(&sphere, &l, &Method::Dense(s)).unwrap().mesh;
            let cmp = d.compare(&m);
            // Only the dense mesh's triangles, and never a hole: what the octree finds of a
            // component, it finds whole (the repair walks on from it).
            prop_assert_eq!(cmp.extra, 0);
            prop_assert!(m.triangles.is_empty() || m.is_closed_oriented());
            // With the premise (a distance, safety ≥ 1) nothing is missed; a smaller safety may
            // drop a whole component.
            if safety >= 1.0 {
                prop_assert_eq!(cmp.missing, 0);
            }
        } else {
            prop_assert!(!(safety.is_finite() && safety > 0.0));
        }
    }

    #[test]
    fn butterfly_refuses_or_refines(v in points(10), f in prop::collection::vec((0u32..12, 0u32..12, 0u32..12), 0..14), w in any_f64()) {
        let control = Mesh {
            vertices: v,
            triangles: f.into_iter().map(|(a, b, c)| [a, b, c]).collect(),
            normals: vec![],
        };
        if let Ok(levels) = subdivision::butterfly(&control, 1, w) {
            let fine = levels.last().unwrap();
            prop_assert!(fine.triangles.iter().flatten().all(|&i| (i as usize) < fine.vertices.len()));
        }
    }

    #[test]
    fn blob_fields_take_any_magnitude(c in extreme_points(40), r in magnitude(), l in small_lattice()) {
        let Ok(blobs) = BlobField::new(&c, PerPrimitive::All(r.abs()), PerPrimitive::All(1.0), 0.5, BlobSettings::default()) else {
            return Ok(());
        };
        let s = Settings::default();
        if let (Ok(d), Ok(m)) = (polygonize(&blobs, &l, &Method::Dense(s)), polygonize(&blobs, &l, &Method::Sparse(s))) {
            let cmp = d.mesh.compare(&m.mesh);
            prop_assert_eq!((cmp.missing, cmp.extra), (0, 0));
        }
    }

    #[test]
    fn particles_take_any_magnitude(p in extreme_points(40), r in magnitude()) {
        if let Ok(f) = colour_field(&p, r.abs(), &ParticleSettings::default()) {
            prop_assert_eq!(f.centers().len(), p.len());
            prop_assert!(f.strengths().iter().all(|a| a.is_finite() && *a > 0.0));
        }
        // The densities alone (whose cell list must not depend on a far point for its size):
        // every sum counts the particle itself.
        if let Ok(sums) = kernel_sums(&p, r.abs(), BlobKernel::CubicSpline) {
            prop_assert!(sums.iter().all(|s| *s >= 1.0 || !s.is_finite()));
        }
    }

    #[test]
    fn partition_fits_take_any_magnitude(p in extreme_points(60)) {
        let n: Vec<DVec3> = p.iter().enumerate().map(|(i, _)| DVec3::new(1.0, i as f64, 0.5).normalize()).collect();
        let settings = PartitionSettings { max_per_leaf: 8, max_patch: 16, min_points: 8, ..Default::default() };
        if let Ok(s) = PartitionSurface::fit(&p, &n, &Default::default(), &settings) {
            // Loading what it saved, with one constraint moved anywhere, gives a surface or an
            // error.
            let mut parts = s.parts();
            if let Some(q) = parts.constraints.points.first_mut() {
                *q = DVec3::new(1e200, 0.0, 0.0);
            }
            let _ = PartitionSurface::from_parts(parts);
        }
    }
}
