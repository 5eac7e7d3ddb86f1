//! Tests of the subdivision: split, projection, the level loop on analytic, variational and
//! values-only fields, butterfly and blend.

use super::butterfly::{butterfly_point, Rings};
use super::implicit::hermite_midpoint;
use super::*;
use crate::error::Error;
use crate::field::analytic::Sphere;
use crate::field::rbf::VariationalSurface;
use crate::field::rbf::{self, constraints};
use crate::field::{Differences, Field};
use crate::mesh::Mesh;
use glam::DVec3;
use std::collections::HashMap;

/// The 12-vertex icosahedron with circumradius 0.9, faces counter-clockwise from outside.
fn icosahedron() -> Mesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let raw = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ];
    let vertices = raw
        .iter()
        .map(|v| DVec3::from_array(*v).normalize() * 0.9)
        .collect();
    let triangles = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    Mesh {
        vertices,
        triangles,
        normals: vec![],
    }
}

fn grid(n: u32, z: f64) -> Mesh {
    let mut vertices = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            // A slightly irregular planar grid.
            let x = i as f64 + 0.13 * ((i * 7 + j * 3) % 5) as f64;
            let y = j as f64 + 0.11 * ((i * 5 + j * 2) % 3) as f64;
            vertices.push(DVec3::new(x, y, z));
        }
    }
    let id = |i: u32, j: u32| j * (n + 1) + i;
    let mut triangles = Vec::new();
    for j in 0..n {
        for i in 0..n {
            if (i + j) % 2 == 0 {
                triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            } else {
                triangles.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
                triangles.push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
    }
    Mesh {
        vertices,
        triangles,
        normals: vec![],
    }
}

#[test]
fn icosahedron_is_valid() {
    let m = icosahedron();
    assert!(m.is_closed_oriented());
    assert_eq!(m.euler_characteristic(), 2);
    assert!(m.volume() > 0.0);
}

#[test]
fn split_counts_and_orientation() {
    let m = icosahedron();
    let (s, parents) = split(&m);
    assert_eq!(s.triangles.len(), 80);
    assert_eq!(parents.len(), 30);
    assert_eq!(s.vertices.len(), 42);
    assert_eq!(&s.vertices[..12], &m.vertices[..]);
    assert!(s.is_closed_oriented());
    assert_eq!(s.euler_characteristic(), 2);
    // Open mesh: boundary edges double.
    let mut open = m.clone();
    open.triangles.truncate(15);
    let boundary = |m: &Mesh| {
        let mut c: HashMap<(u32, u32), u32> = HashMap::new();
        for t in &m.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *c.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        c.values().filter(|&&x| x == 1).count()
    };
    let (so, _) = split(&open);
    assert_eq!(boundary(&so), 2 * boundary(&open));
}

/// The icosahedron and the variational surface fitted to it with the default settings.
fn icosahedron_surface() -> (Mesh, VariationalSurface) {
    let m = icosahedron();
    let s = VariationalSurface::from_mesh(
        &m.vertices,
        &m.triangles,
        &constraints::ConstraintSettings::default(),
        &rbf::FitSettings::default(),
    )
    .unwrap();
    (m, s)
}

#[test]
fn icosahedron_subdivides_onto_surface() {
    let (m, s) = icosahedron_surface();
    let levels = subdivide(&s, &m, 5, &SubdivisionSettings::default()).unwrap();
    assert_eq!(levels.len(), 6);
    let counts: Vec<usize> = levels.iter().map(|(l, _)| l.triangles.len()).collect();
    assert_eq!(counts, vec![20, 80, 320, 1280, 5120, 20480]);
    for (k, (mesh, stats)) in levels.iter().enumerate() {
        assert_eq!(stats.level, k);
        assert!(mesh.is_closed_oriented(), "level {k}");
        assert_eq!(mesh.euler_characteristic(), 2, "level {k}");
        assert_eq!(mesh.normals.len(), mesh.vertices.len());
        for (a, b) in m.vertices.iter().zip(&mesh.vertices) {
            assert_eq!(
                a.to_array().map(f64::to_bits),
                b.to_array().map(f64::to_bits)
            );
        }
        let mut v = vec![0.0; mesh.vertices.len()];
        s.values(&mesh.vertices, &mut v);
        let worst = v.iter().fold(0.0, |a: f64, x| a.max(x.abs()));
        assert!(worst <= 1e-6, "level {k}: |f| up to {worst}");
        assert_eq!(stats.not_converged, 0);
        // The vertices of level k stay exactly in level k + 1.
        if k > 0 {
            let prev = &levels[k - 1].0;
            assert_eq!(&mesh.vertices[..prev.vertices.len()], &prev.vertices[..]);
        }
    }
    assert!(levels[5].1.iterations_mean < 6.0, "{:?}", levels[5].1);
}

#[test]
fn hermite_midpoint_is_fourth_order_on_a_circle() {
    // Two points of the unit circle at ±θ, with their normals: the flat midpoint is θ²/2 off
    // the circle, the Hermite midpoint about 0.375 θ⁴.
    for theta in [0.02f64, 0.1, 0.3, 0.6] {
        let a = DVec3::new(-theta.sin(), theta.cos(), 0.0);
        let b = DVec3::new(theta.sin(), theta.cos(), 0.0);
        let p = hermite_midpoint(a, b, a, b);
        let err = (p.length() - 1.0).abs();
        assert!(err <= 0.4 * theta.powi(4), "θ = {theta}: {err}");
        assert!(
            err < theta * theta * (1.0 - theta.cos()),
            "θ = {theta}: {err}"
        );
        assert!(p.x.abs() < 1e-15 && p.z == 0.0);
    }
    // A vanishing normal gives the flat midpoint; a plane gives the midpoint too.
    let (a, b) = (DVec3::X, DVec3::Y);
    assert_eq!(hermite_midpoint(a, b, DVec3::ZERO, DVec3::Z), 0.5 * (a + b));
    assert_eq!(hermite_midpoint(a, b, DVec3::Z, DVec3::Z), 0.5 * (a + b));
    assert_eq!(hermite_midpoint(a, a, DVec3::Z, DVec3::Z), a);
    // Ends curving differently: the start stays in the plane perpendicular to the edge
    // through its midpoint.
    let (na, nb) = (
        DVec3::new(-0.3, 0.0, 1.0).normalize(),
        DVec3::new(0.05, 0.1, 1.0).normalize(),
    );
    let (a, b) = (DVec3::new(-0.1, 0.0, 0.0), DVec3::new(0.1, 0.02, 0.01));
    let p = hermite_midpoint(a, b, na, nb);
    assert!((p - 0.5 * (a + b)).dot(b - a).abs() < 1e-15);
    assert!((p - 0.5 * (a + b)).length() > 1e-3);
}

#[test]
fn prediction_saves_the_confirming_evaluation() {
    // Onto a variational sphere: every new vertex of levels 2-4 is placed with about two
    // evaluations (a step from the Hermite midpoint, then one accepted by prediction), still
    // on the surface to |f| ≤ 1e-6 with normals that are the unit gradients there.
    let (m, s) = icosahedron_surface();
    let levels = subdivide(&s, &m, 4, &SubdivisionSettings::default()).unwrap();
    for (k, (mesh, stats)) in levels.iter().enumerate().skip(1) {
        let old = levels[k - 1].0.vertices.len();
        let new = &mesh.vertices[old..];
        let mut v = vec![0.0; new.len()];
        let mut g = vec![DVec3::ZERO; new.len()];
        s.values_gradients(new, &mut v, &mut g);
        let worst = v.iter().fold(0.0, |a: f64, x| a.max(x.abs()));
        assert!(worst <= 1e-6, "level {k}: |f| up to {worst}");
        for (gi, ni) in g.iter().zip(&mesh.normals[old..]) {
            assert!((gi.normalize() - *ni).length() < 1e-6, "level {k}");
        }
        assert_eq!(stats.fallbacks, 0);
        if k >= 3 {
            assert!(stats.iterations_mean <= 2.2, "level {k}: {stats:?}");
        }
    }
}

#[test]
fn generic_field_matches_and_fallback_runs() {
    let m = icosahedron();
    let sphere = Sphere {
        center: DVec3::ZERO,
        radius: 0.9,
    };
    let levels = subdivide(&sphere, &m, 3, &SubdivisionSettings::default()).unwrap();
    for (mesh, _) in &levels {
        for p in &mesh.vertices {
            assert!((p.length() - 0.9).abs() < 1e-9);
        }
        assert!(mesh.is_closed_oriented());
    }
    // A single Newton step forces the fallback for every vertex off the sphere.
    let s = SubdivisionSettings {
        max_iterations: 1,
        ..Default::default()
    };
    let levels = subdivide(&sphere, &m, 2, &s).unwrap();
    assert!(levels[1].1.fallbacks > 0);
    assert_eq!(levels[1].1.not_converged, 0);
    for p in &levels[2].0.vertices {
        assert!((p.length() - 0.9).abs() < 1e-7);
    }
}

#[test]
fn difference_gradients_reach_the_surface() {
    let m = icosahedron();
    let sphere = Sphere {
        center: DVec3::ZERO,
        radius: 0.9,
    };
    // Values only: the analytic gradient is never asked for.
    struct ValuesOnly<'a>(&'a Sphere);
    impl Field for ValuesOnly<'_> {
        fn value(&self, p: DVec3) -> f64 {
            self.0.value(p)
        }
        fn gradient(&self, _: DVec3) -> DVec3 {
            panic!("gradient asked for")
        }
        fn gradients(&self, _: &[DVec3], _: &mut [DVec3]) {
            panic!("gradients asked for")
        }
    }
    let f = ValuesOnly(&sphere);
    let d = Differences::new(&f, difference_step(&m)).unwrap();
    let levels = subdivide(&d, &m, 4, &SubdivisionSettings::default()).unwrap();
    let exact = subdivide(&sphere, &m, 4, &SubdivisionSettings::default()).unwrap();
    for ((mesh, stats), (e, _)) in levels.iter().zip(&exact) {
        assert_eq!(mesh.triangles, e.triangles);
        for (p, q) in mesh.vertices.iter().zip(&e.vertices) {
            assert!((p.length() - 0.9).abs() < 1e-12);
            assert!((*p - *q).length() < 1e-9);
        }
        assert_eq!(stats.not_converged, 0);
        // Seven values per point for every value-and-gradient evaluation.
        assert!(stats.evaluations >= 7 * mesh.vertices.len() as u64);
    }
    assert!(Differences::new(&f, 0.0).is_err());
}

#[test]
fn progress_counts_every_vertex_placed() {
    use crate::cancel::{run_under, Token};
    let m = icosahedron();
    let sphere = Sphere {
        center: DVec3::ZERO,
        radius: 0.9,
    };
    // With and without the fallback.
    for max_iterations in [30, 1] {
        let s = SubdivisionSettings {
            max_iterations,
            ..Default::default()
        };
        let t = Token::new();
        let levels = run_under(t.clone(), || subdivide(&sphere, &m, 3, &s)).unwrap();
        let finest = levels[3].0.vertices.len() as u64;
        assert_eq!(t.done(), finest);
        assert_eq!(vertex_count(&m, 3), finest);
    }
    let t = Token::new();
    let levels = run_under(t.clone(), || butterfly(&m, 2, 0.0)).unwrap();
    assert_eq!(t.done(), levels[2].vertices.len() as u64);
    // An open mesh: boundary edges count once.
    let mut open = m.clone();
    open.triangles.truncate(15);
    let (s1, _) = split(&open);
    let (s2, _) = split(&s1);
    assert_eq!(vertex_count(&open, 2), s2.vertices.len() as u64);
    // A stopped token stops the subdivision.
    let t = Token::new();
    t.stop();
    let r = run_under(t, || {
        subdivide(&sphere, &m, 3, &SubdivisionSettings::default())
    });
    assert_eq!(r.unwrap_err(), Error::Interrupted);
}

#[test]
fn refuses_bad_input() {
    let m = icosahedron();
    let sphere = Sphere {
        center: DVec3::ZERO,
        radius: 0.9,
    };
    let s = SubdivisionSettings::default();
    let name = |e: Error| match e {
        Error::InvalidArgument { name, .. } => name,
        Error::TooMuchMemory { name, .. } => name,
        other => panic!("unexpected {other:?}"),
    };
    assert_eq!(name(subdivide(&sphere, &m, 9, &s).unwrap_err()), "levels");
    let mut bad = m.clone();
    bad.triangles[0][1] = 99;
    assert_eq!(name(subdivide(&sphere, &bad, 1, &s).unwrap_err()), "faces");
    let mut nm = m.clone();
    nm.triangles.push([0, 11, 3]);
    assert_eq!(name(butterfly(&nm, 1, 0.0).unwrap_err()), "faces");
    let mut flipped = m.clone();
    flipped.triangles[0] = [0, 5, 11];
    assert_eq!(name(check_mesh(&flipped).unwrap_err()), "faces");
    let (b, _) = split(&m);
    assert_eq!(name(blend(&m, &b, 0.5).unwrap_err()), "butterfly");
    assert_eq!(name(blend(&m, &m, 1.5).unwrap_err()), "lam");
    assert_eq!(name(blend(&m, &m, f64::NAN).unwrap_err()), "lam");
    let tight = SubdivisionSettings {
        memory_limit: 1 << 20,
        ..Default::default()
    };
    assert_eq!(
        name(subdivide(&sphere, &m, 8, &tight).unwrap_err()),
        "levels"
    );
}

#[test]
fn butterfly_reproduces_planes() {
    let g = grid(8, 0.25);
    for w in [0.0, 1.0 / 16.0, -0.03, 0.1] {
        let levels = butterfly(&g, 3, w).unwrap();
        assert_eq!(levels.len(), 4);
        for (k, m) in levels.iter().enumerate() {
            assert_eq!(m.triangles.len(), g.triangles.len() << (2 * k));
            for p in &m.vertices {
                assert!((p.z - 0.25).abs() <= 1e-12, "w {w}: z = {}", p.z);
            }
            assert_eq!(&m.vertices[..g.vertices.len()], &g.vertices[..]);
        }
    }
}

#[test]
fn butterfly_regular_weights_and_linear_precision() {
    // On a regular triangular lattice the 10-point stencil reproduces linear functions
    // exactly: every new vertex is the edge midpoint.
    let n = 6u32;
    let h = 3f64.sqrt() / 2.0;
    let mut vertices = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            vertices.push(DVec3::new(i as f64 + 0.5 * j as f64, h * j as f64, 0.0));
        }
    }
    let id = |i: u32, j: u32| j * (n + 1) + i;
    let mut triangles = Vec::new();
    for j in 0..n {
        for i in 0..n {
            triangles.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
            triangles.push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    let g = Mesh {
        vertices,
        triangles,
        normals: vec![],
    };
    let (s, parents) = split(&g);
    let levels = butterfly(&g, 1, 0.05).unwrap();
    let interior = |v: u32| {
        let (i, j) = (v % (n + 1), v / (n + 1));
        i > 0 && i < n && j > 0 && j < n
    };
    let mut checked = 0;
    let mut corner_edges = 0;
    for (k, &[a, b]) in parents.iter().enumerate() {
        let on_boundary = |v: u32| !interior(v);
        let boundary_edge = {
            let (ia, ja, ib, jb) = (a % (n + 1), a / (n + 1), b % (n + 1), b / (n + 1));
            (ja == 0 && jb == 0)
                || (ja == n && jb == n)
                || (ia == 0 && ib == 0)
                || (ia == n && ib == n)
        };
        if on_boundary(a) && on_boundary(b) && !boundary_edge {
            // Interior edge across a corner: its ghosts are the lattice's own points.
            corner_edges += 1;
            let mid = 0.5 * (g.vertices[a as usize] + g.vertices[b as usize]);
            let got = levels[1].vertices[g.vertices.len() + k];
            assert!(
                (got - mid).length() < 1e-12,
                "corner edge {a}-{b}: {got} vs {mid}"
            );
            continue;
        }
        if !(interior(a) && interior(b)) {
            continue;
        }
        checked += 1;
        let mid = 0.5 * (g.vertices[a as usize] + g.vertices[b as usize]);
        let got = levels[1].vertices[g.vertices.len() + k];
        assert!((got - mid).length() < 1e-12, "edge {a}-{b}: {got} vs {mid}");
    }
    assert!(checked > 50);
    assert_eq!(corner_edges, 2);
    assert_eq!(levels[1].triangles, s.triangles);
}

/// The six-face open mesh around the interior edge (0, 1), both of whose ends lie on the
/// boundary, symmetric under x -> 1 - x and y -> -y: wings 2 (y > 0) and 3 (y < 0), and one
/// face across each of the edges (0, 2), (1, 2), (0, 3), (1, 3).
fn bent_strip() -> Mesh {
    let vertices = vec![
        DVec3::new(0.0, 0.0, 0.0),
        DVec3::new(1.0, 0.0, 0.0),
        DVec3::new(0.5, 1.0, 0.3),
        DVec3::new(0.5, -1.0, 0.3),
        DVec3::new(-0.5, 1.0, 0.7),
        DVec3::new(1.5, 1.0, 0.7),
        DVec3::new(-0.5, -1.0, 0.7),
        DVec3::new(1.5, -1.0, 0.7),
    ];
    let triangles = vec![
        [0, 1, 2],
        [1, 0, 3],
        [0, 2, 4],
        [2, 1, 5],
        [3, 0, 6],
        [1, 3, 7],
    ];
    Mesh {
        vertices,
        triangles,
        normals: vec![],
    }
}

#[test]
fn butterfly_edge_between_boundary_vertices() {
    let m = bent_strip();
    check_mesh(&m).unwrap();
    let rings = Rings::new(&m).unwrap();
    assert!((0..8).all(|v| rings.boundary[v]));
    let p = |i: usize| m.vertices[i];
    for w in [0.0, 1.0 / 16.0, -0.03] {
        let got = butterfly_point(&m, &rings, 0, 1, w);
        // The full stencil: every outer vertex exists here, tension points are 2a - b, 2b - a.
        let want = (p(0) + p(1)) * (0.5 - w)
            + (p(2) + p(3)) * (0.125 + 2.0 * w)
            + (p(4) + p(5) + p(6) + p(7)) * (-0.0625 - w)
            + (p(0) + p(1)) * w;
        assert!((got - want).length() < 1e-15, "w {w}: {got} vs {want}");
        // Symmetric configuration, symmetric answer.
        assert!((got.x - 0.5).abs() < 1e-15 && got.y.abs() < 1e-15, "{got}");
        // Either orientation of the edge gives the same point.
        assert_eq!(got, butterfly_point(&m, &rings, 1, 0, w));
    }
    // With the outer faces removed the four outer vertices are ghosts (reflections), and the
    // single quad's diagonal gets its midpoint whatever the wings.
    let quad = Mesh {
        vertices: m.vertices[..4].to_vec(),
        triangles: vec![[0, 1, 2], [1, 0, 3]],
        normals: vec![],
    };
    let rq = Rings::new(&quad).unwrap();
    for w in [0.0, 0.05] {
        let got = butterfly_point(&quad, &rq, 0, 1, w);
        assert!((got - DVec3::new(0.5, 0.0, 0.0)).length() < 1e-15, "{got}");
    }
    // Levels: face counts, the old vertices kept, and the mirror symmetry kept at every level.
    let levels = butterfly(&m, 3, 0.0).unwrap();
    for (k, l) in levels.iter().enumerate() {
        assert_eq!(l.triangles.len(), 6 << (2 * k));
        assert_eq!(&l.vertices[..8], &m.vertices[..]);
        let key = |v: DVec3| {
            (
                (v.x * 1e9).round() as i64,
                (v.y * 1e9).round() as i64,
                (v.z * 1e9).round() as i64,
            )
        };
        let set: std::collections::HashSet<_> = l.vertices.iter().map(|&v| key(v)).collect();
        for v in &l.vertices {
            assert!(
                set.contains(&key(DVec3::new(1.0 - v.x, v.y, v.z))),
                "level {k}: {v}"
            );
            assert!(
                set.contains(&key(DVec3::new(v.x, -v.y, v.z))),
                "level {k}: {v}"
            );
        }
    }
}

#[test]
fn butterfly_strip_stays_planar() {
    // A zig-zag strip: every vertex on the boundary, every diagonal an interior edge between
    // two boundary vertices.
    let n = 7u32;
    let mut vertices = Vec::new();
    for i in 0..=n {
        let x = i as f64 + 0.17 * ((i * 5) % 3) as f64;
        vertices.push(DVec3::new(x, 0.1 * (i % 2) as f64, -0.5));
        vertices.push(DVec3::new(x + 0.4, 1.0 + 0.05 * (i % 3) as f64, -0.5));
    }
    let mut triangles = Vec::new();
    for i in 0..n {
        let (a, b, c, d) = (2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 1);
        triangles.push([a, b, c]);
        triangles.push([a, c, d]);
    }
    let strip = Mesh {
        vertices,
        triangles,
        normals: vec![],
    };
    for w in [0.0, 1.0 / 16.0] {
        let levels = butterfly(&strip, 3, w).unwrap();
        for (k, l) in levels.iter().enumerate() {
            assert_eq!(l.triangles.len(), strip.triangles.len() << (2 * k));
            for v in &l.vertices {
                assert!((v.z + 0.5).abs() < 1e-12, "w {w}, level {k}: {v}");
            }
        }
    }
}

#[test]
fn butterfly_closed_mesh_and_blend_identities() {
    let (m, s) = icosahedron_surface();
    let imp = subdivide(&s, &m, 3, &SubdivisionSettings::default()).unwrap();
    let bf = butterfly(&m, 3, 0.0).unwrap();
    for k in 0..=3 {
        let (a, b) = (&imp[k].0, &bf[k]);
        assert_eq!(a.triangles, b.triangles);
        assert!(b.is_closed_oriented());
        let b0 = blend(a, b, 0.0).unwrap();
        let b1 = blend(a, b, 1.0).unwrap();
        assert_eq!(&b0, a);
        assert_eq!(&b1, b);
        let h = blend(a, b, 0.5).unwrap();
        for i in 0..a.vertices.len() {
            let e = 0.5 * (a.vertices[i] + b.vertices[i]);
            assert!((h.vertices[i] - e).length() < 1e-15);
        }
    }
    // Regular icosahedron: butterfly points lie on a sphere by symmetry per level (valence 5
    // stencil at level 1 is symmetric), and stay near the sphere.
    for p in &bf[1].vertices {
        assert!((p.length() - 0.9).abs() < 0.1);
    }
}
