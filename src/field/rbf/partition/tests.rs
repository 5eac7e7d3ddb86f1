use super::*;
use crate::field::rbf::PatchCentres;
use crate::testing::{gradient_error, random_points};

/// `n` points on a torus (major radius 0.6, minor 0.25, axis z) with outward normals.
fn torus_data(n: usize, seed: u64) -> (Vec<DVec3>, Vec<DVec3>) {
    let uv = random_points(n, 0.0, 1.0, seed);
    let tau = std::f64::consts::TAU;
    uv.iter()
        .map(|q| {
            let (u, v) = (q.x * tau, q.y * tau);
            let ring = DVec3::new(u.cos(), u.sin(), 0.0);
            let normal = ring * v.cos() + DVec3::Z * v.sin();
            (ring * 0.6 + normal * 0.25, normal)
        })
        .unzip()
}

/// Patch `i`'s value and gradient at `x`.
fn patch_at(s: &PartitionSurface, i: usize, x: DVec3) -> (f64, DVec3) {
    let (mut v, mut g) = ([0.0], [DVec3::ZERO]);
    let all = &s.centres;
    let scratch = &mut crate::field::rbf::kernel::Centres::default();
    let fit = &s.patches[i].fit;
    fit.eval_on_this_thread(all, scratch, &[x], &mut v, Some(&mut g));
    (v[0], g[0])
}

/// Asserts that `s` takes every constraint's value to 1e-9 of the largest; returns that.
fn assert_interpolates(s: &PartitionSurface) -> f64 {
    let c = s.constraints();
    let mut v = vec![0.0; c.points.len()];
    s.values(&c.points, &mut v);
    let scale = c.values.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let err = v
        .iter()
        .zip(&c.values)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(err <= 1e-9 * scale, "{err}");
    scale
}

pub(super) fn torus_surface() -> PartitionSurface {
    let (p, n) = torus_data(3000, 5);
    PartitionSurface::fit(&p, &n, &Default::default(), &Default::default()).unwrap()
}

#[test]
fn interpolates_every_constraint() {
    let s = torus_surface();
    assert!(s.patches().len() > 20, "{} patches", s.patches().len());
    let scale = assert_interpolates(&s);
    assert!(s.residual() <= 1e-9 * scale);
    // Inside the tube negative, in the hole and far out positive.
    assert!(s.value(DVec3::new(0.6, 0.0, 0.0)) < 0.0);
    assert!(s.value(DVec3::ZERO) > 0.0);
    assert!(s.value(DVec3::new(0.0, 0.95, 0.3)) > 0.0);
}

#[test]
fn thinned_normal_constraints_keep_interpolation_and_the_sign_of_space() {
    let (p, n) = torus_data(20_000, 3);
    let placement = constraints::ConstraintSettings {
        normal_cell_over_spacing: Some(constraints::NORMAL_CELL_OVER_SPACING),
        ..Default::default()
    };
    let s = PartitionSurface::fit(&p, &n, &placement, &Default::default()).unwrap();
    let c = s.constraints();
    assert!(c.normal_of.len() < p.len() / 3, "{}", c.normal_of.len());
    assert_interpolates(&s);
    let torus = |x: DVec3| DVec3::new(x.truncate().length() - 0.6, x.z, 0.0).length() - 0.25;
    // The sign of the torus's distance wherever that distance exceeds the offset.
    let d = c.offsets.iter().fold(0.0f64, |a, &o| a.max(o));
    let grid = random_points(4000, -1.0, 1.0, 11);
    let mut checked = 0;
    for x in grid.iter().filter(|x| torus(**x).abs() > 2.0 * d) {
        assert_eq!(s.value(*x).signum(), torus(*x).signum(), "at {x}");
        checked += 1;
    }
    assert!(checked > 3000, "{checked}");
    assert!(s.patches().iter().any(|p| p.inside == 0));
}

#[test]
fn interpolate_reproduces_values() {
    let p = random_points(2000, -1.0, 1.0, 8);
    let v: Vec<f64> = p.iter().map(|q| (3.0 * q.x).sin() + q.y * q.z).collect();
    let s = PartitionSurface::interpolate(&p, &v, None, &Default::default()).unwrap();
    let mut f = vec![0.0; p.len()];
    s.values(&p, &mut f);
    let err = f
        .iter()
        .zip(&v)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(err <= 1e-9, "{err}");
}

#[test]
fn patches_hold_every_constraint_of_their_support() {
    let s = torus_surface();
    let c = s.constraints();
    let t = s.octree();
    assert_eq!(s.patches().len(), t.leaves.len());
    for (i, p) in s.patches().iter().enumerate() {
        let inside = c
            .points
            .iter()
            .filter(|q| (**q - p.centre).length_squared() <= p.radius * p.radius)
            .count();
        assert_eq!(p.inside, inside, "patch {i}");
        if p.inside == 0 {
            assert_eq!(p.size, empty::PLANE_POINTS, "patch {i}");
        } else {
            assert!(p.size >= p.inside.max(16), "patch {i}");
        }
        assert!(
            p.size <= s.settings().max_patch * 3 / 2,
            "patch {i}: {}",
            p.size
        );
        // Its centres are the constraints it interpolates, by index (a plane's are its own).
        match p.fit.centres() {
            PatchCentres::Shared(index) => {
                assert_eq!(index.len(), p.size, "patch {i}");
                assert_eq!(p.fit.normalized_weights().len(), p.size, "patch {i}");
                let within = |&k: &u32| {
                    let j = s.constraint_at(k) as usize;
                    (c.points[j] - p.centre).length_squared() <= p.radius * p.radius
                };
                assert_eq!(index.iter().filter(|j| within(j)).count(), p.inside);
            }
            PatchCentres::Own(own) => {
                assert_eq!((p.inside, own.len()), (0, empty::PLANE_POINTS), "patch {i}")
            }
        }
        // The patch interpolates every constraint inside its support.
        for (q, v) in c.points.iter().zip(&c.values) {
            if (*q - p.centre).length_squared() <= p.radius * p.radius {
                assert!((patch_at(&s, i, *q).0 - v).abs() <= 1e-11, "patch {i}");
            }
        }
        // Each patch's ball covers its leaf (with room: the weight is positive on the leaf).
        let leaf = &t.nodes[t.leaves[i] as usize];
        assert_eq!(leaf.centre, p.centre);
        assert!(p.radius >= s.settings().overlap * leaf.half_diagonal());
    }
    for &k in &t.leaves {
        assert!(t.nodes[k as usize].end - t.nodes[k as usize].start <= 96);
    }
}

#[test]
fn weights_sum_to_one_and_cover_lists_are_complete() {
    let s = torus_surface();
    let (lo, hi) = s.octree().cube();
    let mut pts = random_points(2000, lo.x, hi.x, 9);
    pts.extend_from_slice(&s.constraints().points[..500]);
    for x in pts {
        let w = s.weights_at(x);
        assert!(!w.is_empty());
        let total: f64 = w.iter().map(|(_, w)| w).sum();
        assert!((total - 1.0).abs() < 1e-12, "{total}");
        // Brute force: every patch whose support holds x is listed.
        let all: Vec<u32> = (0..s.patches().len() as u32)
            .filter(|&i| {
                let p = &s.patches()[i as usize];
                blend::weight(x, p.centre, p.radius).0 > 0.0
            })
            .collect();
        assert_eq!(w.iter().map(|(i, _)| *i).collect::<Vec<_>>(), all);
    }
}

#[test]
fn gradient_matches_central_differences() {
    let s = torus_surface();
    let mut pts = random_points(300, -0.95, 0.95, 12);
    let inner = gradient_error(&s, &pts, 1e-6);
    // And points outside the cube, where f is its value at the nearest point of the cube: a
    // longer step.
    let far = random_points(20, 3.0, 4.0, 13);
    let outer = gradient_error(&s, &far, 1e-4);
    assert!(inner < 1e-5 && outer < 1e-5, "{inner} {outer}");
    pts.extend(far);
    // Batched gradients are the single-point ones.
    let mut g = vec![DVec3::ZERO; pts.len()];
    s.gradients(&pts, &mut g);
    for (p, gi) in pts.iter().zip(&g) {
        assert_eq!(s.gradient(*p), *gi);
    }
}

#[test]
fn same_bits_whatever_the_batch_and_threads() {
    let s = torus_surface();
    let pts = random_points(5000, -1.2, 1.2, 14);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut v = vec![0.0; pts.len()];
            s.values(&pts, &mut v);
            v
        })
    };
    let (one, four) = (run(1), run(4));
    assert_eq!(
        one.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        four.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
    for k in (0..pts.len()).step_by(97) {
        assert_eq!(s.value(pts[k]).to_bits(), one[k].to_bits());
    }
}

#[test]
fn refuses_bad_settings_and_memory() {
    let (p, n) = torus_data(500, 3);
    let fit = |s: PartitionSettings| PartitionSurface::fit(&p, &n, &Default::default(), &s);
    let named = |s: PartitionSettings| match fit(s) {
        Err(Error::InvalidArgument { name, .. }) => name,
        other => panic!("{other:?}"),
    };
    let d = PartitionSettings::default();
    assert_eq!(named(PartitionSettings { overlap: 1.0, ..d }), "overlap");
    assert_eq!(
        named(PartitionSettings {
            max_per_leaf: 2,
            ..d
        }),
        "max_per_leaf"
    );
    assert_eq!(
        named(PartitionSettings { min_points: 3, ..d }),
        "min_points"
    );
    assert_eq!(named(PartitionSettings { max_patch: 50, ..d }), "max_patch");
    assert!(matches!(
        fit(PartitionSettings {
            fit: crate::field::rbf::FitSettings {
                memory_limit: 1 << 16,
                ..d.fit
            },
            ..d
        }),
        Err(Error::TooMuchMemory { .. })
    ));
}

/// The parts give back a surface that evaluates to the same bits, with the same octree and
/// cover; parts no fit makes are refused.
#[test]
fn parts_give_back_the_same_surface() {
    let s = torus_surface();
    let back = PartitionSurface::from_parts(s.parts()).unwrap();
    assert_eq!(back.parts(), s.parts());
    assert_eq!((&back.cover_start, &back.cover), (&s.cover_start, &s.cover));
    let q = random_points(5000, -1.0, 1.0, 9);
    let (mut a, mut b) = (vec![0.0; q.len()], vec![0.0; q.len()]);
    s.values(&q, &mut a);
    back.values(&q, &mut b);
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&a), bits(&b));
    let mut bad = s.parts();
    bad.patches[3].radius = -1.0;
    assert!(PartitionSurface::from_parts(bad).is_err());
    let mut bad = s.parts();
    bad.constraints.values.pop();
    assert!(PartitionSurface::from_parts(bad).is_err());
}

/// Outside the octree's cube f is its value at the nearest point of the cube (same bits), its
/// gradient has no component along the clamped axes, and it is positive outside the torus.
#[test]
fn outside_the_cube_the_field_is_its_value_at_the_nearest_point_of_the_cube() {
    let s = torus_surface();
    let (lo, hi) = s.octree().cube();
    let mut outside = 0;
    for x in random_points(400, -3.0, 3.0, 15) {
        let p = x.clamp(lo, hi);
        assert_eq!(s.value(x).to_bits(), s.value(p).to_bits(), "{x}");
        let (gx, gp) = (s.gradient(x), s.gradient(p));
        for a in 0..3 {
            let expected = if x[a] == p[a] { gp[a] } else { 0.0 };
            assert_eq!(gx[a].to_bits(), expected.to_bits(), "{x} axis {a}");
        }
        if x != p {
            assert!(s.value(x) > 0.0, "{x}");
            outside += 1;
        }
    }
    assert!(outside > 300, "{outside}");
}

/// The patches whose support holds no constraint are planes with the torus's sign on their
/// whole support (checked at its centre and 6 points on its rim), growing away from the data.
#[test]
fn empty_patches_carry_the_sign_of_space() {
    let s = torus_surface();
    let torus = |x: DVec3| DVec3::new(x.truncate().length() - 0.6, x.z, 0.0).length() - 0.25;
    let mut planes = 0;
    for (i, p) in s
        .patches()
        .iter()
        .enumerate()
        .filter(|(_, p)| p.inside == 0)
    {
        planes += 1;
        let side = torus(p.centre).signum();
        let rim = [
            DVec3::X,
            DVec3::NEG_X,
            DVec3::Y,
            DVec3::NEG_Y,
            DVec3::Z,
            DVec3::NEG_Z,
        ];
        for x in std::iter::once(p.centre).chain(rim.iter().map(|e| p.centre + *e * p.radius)) {
            let (v, g) = patch_at(&s, i, x);
            assert_eq!(v.signum(), side, "{} at {x}", p.centre);
            // The slope w/d = 3/4 along the direction away from the nearest data point.
            assert!((g.length() - 0.75).abs() < 1e-9);
        }
    }
    assert!(planes > 10, "{planes}");
}

#[test]
fn a_set_token_stops_every_stage_before_the_patches() {
    let (p, n) = torus_data(3000, 5);
    let stopped = crate::cancel::Token::new();
    stopped.stop();
    let interrupted = |r: Result<()>| matches!(r, Err(crate::error::Error::Interrupted));
    // Placement, then the supports, each with the token set: neither gets to the patches.
    let placed = crate::cancel::run_under(stopped.clone(), || {
        constraints::place(&p, &n, &Default::default()).map(|_| ())
    });
    assert!(interrupted(placed));
    let c = constraints::place(&p, &n, &Default::default()).unwrap();
    let settings = PartitionSettings::default();
    let tree = PartitionSurface::tree(&c, &settings).unwrap();
    let levels = PartitionSurface::levels(&tree, &c, &settings).unwrap();
    let supports = |token: crate::cancel::Token| {
        crate::cancel::run_under(token, || {
            patches::supports(&tree, &c.points, &levels, &settings, None).map(|_| ())
        })
    };
    assert!(interrupted(supports(stopped.clone())));
    // And the octree and the coarse levels, which come before the supports.
    let (tree2, levels2) = crate::cancel::run_under(stopped, || {
        (
            PartitionSurface::tree(&c, &settings).map(|_| ()),
            PartitionSurface::levels(&tree, &c, &settings).map(|_| ()),
        )
    });
    assert!(interrupted(tree2) && interrupted(levels2));
    assert!(supports(crate::cancel::Token::new()).is_ok());
}

/// The fitted patches are gathered in the memory they were fitted into (at 10⁷ points a second
/// vector of them would add a few hundred MB to the fit's peak).
#[test]
fn patches_are_gathered_in_place() {
    let s = torus_surface();
    assert_eq!(
        std::mem::size_of::<Option<Patch>>(),
        std::mem::size_of::<Patch>()
    );
    let fitted: Vec<Option<Patch>> = s.patches().iter().cloned().map(Some).collect();
    let memory = fitted.as_ptr() as usize;
    let patches = patches::into_patches(fitted);
    assert_eq!(patches.as_ptr() as usize, memory);
    assert_eq!(patches.len(), s.patches().len());
}

/// A whole surface keeps its constraint points once, in the octree's order, and gives them
/// back in the constraints' order: those placement gives; its parts give the same surface.
#[test]
fn constraint_points_are_kept_once_and_given_back_in_order() {
    let (p, n) = torus_data(3000, 5);
    let s = PartitionSurface::fit(&p, &n, &Default::default(), &Default::default()).unwrap();
    assert!(s.constraints.points.is_empty());
    let placed = constraints::place(&p, &n, &Default::default()).unwrap();
    assert_eq!(*s.constraint_points(), placed.points[..]);
    assert_eq!(s.constraints().points, placed.points);
    assert_eq!(s.constraint_count(), placed.points.len());
    assert_eq!(
        s.data_bounding_box(),
        constraints::bounding_box(&placed.points[..placed.boundary])
    );
    let back = PartitionSurface::from_parts(s.parts()).unwrap();
    assert!(back.constraints.points.is_empty());
    assert_eq!(back.constraints().points, placed.points);
    let x = random_points(500, -1.0, 1.0, 3);
    let (mut a, mut b) = (vec![0.0; x.len()], vec![0.0; x.len()]);
    s.values(&x, &mut a);
    back.values(&x, &mut b);
    assert_eq!(a, b);
}
