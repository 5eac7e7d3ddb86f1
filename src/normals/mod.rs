//! Normals of points that have none: unit normals, consistent across the whole cloud and
//! pointing out of the body the points enclose (or, for open data, toward the sensors or up).
//!
//! The steps, one file each:
//!
//! 1. [`local`]: principal component analysis over each point's `k` nearest neighbours gives an
//!    unoriented normal, and the nearest few neighbours are kept as a graph.
//! 2. [`patches`]: neighbours whose planes agree and that lie along them (not across a thin
//!    part) are joined into patches, each oriented consistently within.
//! 3. [`orient`]: patches vote on their relative signs along their boundaries; the strongest
//!    votes first join them into pieces (a maximum spanning forest of patches). The pieces are
//!    then joined the same way with every edge voting (not only the sure ones): the bodies.
//! 4. [`outward`]: each body turned outward — toward its viewpoints, or by the sign of the
//!    winding number on it (closed data), or up (open data).
//!
//! Everything runs in the [`PointTree`]'s leaf order on rayon's threads, except the two
//! union–find passes, which are sequential and linear.

pub mod local;
pub mod orient;
pub mod outward;
pub mod patches;

use crate::error::{Error, Result};
use crate::knn::PointTree;
use glam::DVec3;
pub use outward::Viewpoints;

/// Settings of [`estimate_normals`].
#[derive(Clone, Debug, PartialEq)]
pub struct NormalSettings {
    /// Neighbours of each local plane, the point itself included (at least 3).
    pub neighbours: usize,
    /// Two neighbours join one patch when their normals are within this angle, in degrees (as
    /// lines).
    pub patch_angle: f64,
    /// An edge whose direction has a cosine above this with either normal runs across the
    /// surface (a thin part's two sides), not along it: it joins nothing and votes for nothing.
    pub across: f64,
    /// An edge between two patches votes when their normals are within this angle (as lines),
    /// in degrees.
    pub vote_angle: f64,
}

impl Default for NormalSettings {
    fn default() -> Self {
        NormalSettings {
            neighbours: 20,
            patch_angle: 30.0,
            across: 0.6,
            vote_angle: 60.0,
        }
    }
}

impl NormalSettings {
    /// The settings of the second joining, in which every edge not across votes.
    fn every_edge(&self) -> NormalSettings {
        NormalSettings {
            vote_angle: 90.0,
            ..self.clone()
        }
    }
}

/// Normals and what the estimate found.
#[derive(Clone, Debug)]
pub struct Estimated {
    /// Unit normals, in the caller's order.
    pub normals: Vec<DVec3>,
    /// Patches (step 2).
    pub patches: usize,
    /// Bodies that nothing joined (step 3), each oriented on its own.
    pub bodies: usize,
    /// Bodies with at least [`Estimated::significant`] points.
    pub large_bodies: usize,
    /// The size from which a body counts as large: max(2 · neighbours, N / 1000).
    pub significant: usize,
    /// With viewpoints: points whose normal faces away from their viewpoint.
    pub facing_away: usize,
}

/// Checks the points: finite, at least `neighbours` of them, not all on one line or plane.
fn check(points: &[DVec3], viewpoints: Viewpoints<'_>, settings: &NormalSettings) -> Result<()> {
    crate::error::check_finite_points("points", points)?;
    let k = settings.neighbours;
    if k < 3 {
        return Err(Error::invalid(
            "neighbours",
            format!("must be at least 3, got {k}"),
        ));
    }
    if points.len() < k {
        return Err(Error::invalid(
            "points",
            format!(
                "need at least `neighbours` ({k}) points, got {}",
                points.len()
            ),
        ));
    }
    match viewpoints {
        Viewpoints::One(v) => crate::error::check_finite_points("viewpoints", &[v])?,
        Viewpoints::PerPoint(v) => {
            if v.len() != points.len() {
                return Err(Error::invalid(
                    "viewpoints",
                    format!(
                        "need one (3,) viewpoint or one per point: {} for {} points",
                        v.len(),
                        points.len()
                    ),
                ));
            }
            crate::error::check_finite_points("viewpoints", v)?;
        }
        Viewpoints::None => {}
    }
    let extents = extents(points);
    if extents[1] <= 1e-9 * extents[2] {
        return Err(Error::invalid(
            "points",
            "all points lie on one line: they have no normal",
        ));
    }
    if extents[0] <= 1e-9 * extents[2] {
        return Err(Error::invalid(
            "points",
            "all points lie on one plane: which side is outward is not defined (give the plane's normal yourself)",
        ));
    }
    Ok(())
}

/// The points' root-mean-square extents along their principal axes, smallest first.
fn extents(points: &[DVec3]) -> [f64; 3] {
    let n = points.len() as f64;
    let mean = points.iter().copied().sum::<DVec3>() / n;
    let mut c = glam::DMat3::ZERO;
    for p in points {
        let d = *p - mean;
        c += glam::DMat3::from_cols(d * d.x, d * d.y, d * d.z);
    }
    let c = c * (1.0 / n);
    // Eigenvalues of the symmetric 3×3 matrix (trigonometric solution).
    let q = (c.x_axis.x + c.y_axis.y + c.z_axis.z) / 3.0;
    let p1 = c.y_axis.x.powi(2) + c.z_axis.x.powi(2) + c.z_axis.y.powi(2);
    let p2 =
        (c.x_axis.x - q).powi(2) + (c.y_axis.y - q).powi(2) + (c.z_axis.z - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    if p == 0.0 {
        let e = q.max(0.0).sqrt();
        return [e, e, e];
    }
    let b = (c - glam::DMat3::from_diagonal(DVec3::splat(q))) * (1.0 / p);
    let r = (b.determinant() / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let e1 = q + 2.0 * p * phi.cos();
    let e3 = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
    let e2 = 3.0 * q - e1 - e3;
    [e3, e2, e1].map(|e| e.max(0.0).sqrt())
}

/// Unit normals of `points`, consistently oriented and outward (see the module's
/// documentation). Errors name the argument: points that are not finite, fewer than
/// `neighbours`, or all on one line or plane; viewpoints not finite or of the wrong count.
/// Progress: one unit per point of the local step ([`crate::cancel`]).
pub fn estimate_normals(
    points: &[DVec3],
    viewpoints: Viewpoints<'_>,
    settings: &NormalSettings,
) -> Result<Estimated> {
    check(points, viewpoints, settings)?;
    let tree = PointTree::new(points)?;
    let position = tree.positions();
    let local = local::local_planes(&tree, &position, settings.neighbours)?;
    let (sorted, order, ..) = tree.layout();
    let (roots, mut normals, _) = patches::grow_patches(sorted, &local, settings);
    crate::cancel::check()?;
    let patches = roots
        .iter()
        .enumerate()
        .filter(|&(s, &r)| r as usize == s)
        .count();
    let turn = |normals: &mut [DVec3], turn: &[bool]| {
        for (n, &t) in normals.iter_mut().zip(turn) {
            if t {
                *n = -*n;
            }
        }
    };
    let pieces = orient::join_patches(sorted, &local, &roots, &normals, settings)?;
    turn(&mut normals, &pieces.turn);
    let joined = orient::join_patches(
        sorted,
        &local,
        &pieces.piece,
        &normals,
        &settings.every_edge(),
    )?;
    turn(&mut normals, &joined.turn);
    // Bodies numbered densely.
    let mut id = vec![u32::MAX; sorted.len()];
    let mut count = 0usize;
    let mut size = Vec::new();
    let body: Vec<u32> = joined
        .piece
        .iter()
        .map(|&r| {
            let r = r as usize;
            if id[r] == u32::MAX {
                id[r] = count as u32;
                count += 1;
                size.push(0usize);
            }
            size[id[r] as usize] += 1;
            id[r]
        })
        .collect();
    let view = |s: usize| match viewpoints {
        Viewpoints::None => None,
        Viewpoints::One(v) => Some(v),
        Viewpoints::PerPoint(v) => Some(v[order[s] as usize]),
    };
    let out = outward::outward(sorted, &normals, &local, &body, count, view)?;
    let mut result = vec![DVec3::ZERO; sorted.len()];
    let mut facing_away = 0;
    for (s, n) in normals.iter().enumerate() {
        let n = if out[body[s] as usize] { -*n } else { *n };
        if let Some(v) = view(s) {
            facing_away += usize::from((v - sorted[s]).dot(n) < 0.0);
        }
        result[order[s] as usize] = n;
    }
    let significant = (2 * settings.neighbours).max(points.len() / 1000);
    Ok(Estimated {
        normals: result,
        patches,
        bodies: count,
        large_bodies: size.iter().filter(|&&s| s >= significant).count(),
        significant,
        facing_away,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{fibonacci_sphere, random_points, thin_box};

    /// A torus of radii 1 and r, sampled on a twisted grid, with its outward normals.
    fn torus(r: f64, n: usize) -> (Vec<DVec3>, Vec<DVec3>) {
        let m = (n as f64 * r).sqrt() as usize;
        let big = n / m;
        let mut p = Vec::new();
        let mut nn = Vec::new();
        for i in 0..big {
            for j in 0..m {
                let u = std::f64::consts::TAU * i as f64 / big as f64;
                let v = std::f64::consts::TAU * (j as f64 + 0.37 * i as f64) / m as f64;
                let c = DVec3::new(u.cos(), u.sin(), 0.0);
                let out = c * v.cos() + DVec3::Z * v.sin();
                p.push(c + out * r);
                nn.push(out);
            }
        }
        (p, nn)
    }

    fn wrong(normals: &[DVec3], truth: &[DVec3]) -> usize {
        normals
            .iter()
            .zip(truth)
            .filter(|(a, b)| a.dot(**b) <= 0.0)
            .count()
    }

    #[test]
    fn a_sphere_and_a_thin_torus_are_oriented_outward() {
        let s = fibonacci_sphere(20_000);
        let e = estimate_normals(&s, Viewpoints::None, &NormalSettings::default()).unwrap();
        assert_eq!(wrong(&e.normals, &s), 0);
        assert!(e.normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-12));
        assert_eq!(e.large_bodies, 1);
        let (p, truth) = torus(0.08, 30_000);
        let e = estimate_normals(&p, Viewpoints::None, &NormalSettings::default()).unwrap();
        assert_eq!(wrong(&e.normals, &truth), 0);
    }

    #[test]
    fn a_thin_plate_is_oriented_outward_on_both_sides() {
        let h = 0.01;
        let (p, truth) = thin_box(h, 1.5 * h);
        let e = estimate_normals(&p, Viewpoints::None, &NormalSettings::default()).unwrap();
        // Only at the box's edges may a normal point in.
        let inner = |p: &DVec3| {
            p.x > 2.0 * h && p.x < 1.0 - 2.0 * h && p.y > 2.0 * h && p.y < 1.0 - 2.0 * h
        };
        let wrong_inner = p
            .iter()
            .zip(e.normals.iter().zip(&truth))
            .filter(|(q, (n, t))| inner(q) && n.dot(**t) <= 0.0)
            .count();
        assert_eq!(wrong_inner, 0);
    }

    #[test]
    fn two_spheres_are_two_bodies_each_outward() {
        let a = fibonacci_sphere(5000);
        let mut p: Vec<DVec3> = a.clone();
        p.extend(a.iter().map(|q| *q * 0.5 + DVec3::new(4.0, 0.0, 0.0)));
        let truth: Vec<DVec3> = a.iter().chain(a.iter()).copied().collect();
        let e = estimate_normals(&p, Viewpoints::None, &NormalSettings::default()).unwrap();
        assert_eq!(e.large_bodies, 2);
        assert_eq!(wrong(&e.normals, &truth), 0);
    }

    #[test]
    fn a_height_field_faces_its_viewpoint_or_up() {
        let xy = random_points(20_000, -1.0, 1.0, 7);
        let p: Vec<DVec3> = xy
            .iter()
            .map(|q| DVec3::new(q.x, q.y, 0.2 * (2.0 * q.x).sin() * q.y + 0.002 * q.z))
            .collect();
        let up = |e: &Estimated| e.normals.iter().filter(|n| n.z <= 0.0).count();
        let e = estimate_normals(&p, Viewpoints::None, &NormalSettings::default()).unwrap();
        assert_eq!(up(&e), 0);
        let below = Viewpoints::One(DVec3::new(0.0, 0.0, -3.0));
        let e = estimate_normals(&p, below, &NormalSettings::default()).unwrap();
        assert_eq!(e.normals.iter().filter(|n| n.z >= 0.0).count(), 0);
        assert_eq!(e.facing_away, 0);
    }

    #[test]
    fn bad_points_are_refused_naming_the_argument() {
        let s = NormalSettings::default();
        let few = fibonacci_sphere(10);
        let line: Vec<DVec3> = (0..100).map(|i| DVec3::splat(i as f64)).collect();
        let plane: Vec<DVec3> = random_points(100, -1.0, 1.0, 1)
            .iter()
            .map(|p| DVec3::new(p.x, p.y, p.x - p.y))
            .collect();
        for p in [few, line, plane] {
            assert!(matches!(
                estimate_normals(&p, Viewpoints::None, &s),
                Err(Error::InvalidArgument { name: "points", .. })
            ));
        }
        let mut nan = fibonacci_sphere(100);
        nan[3].x = f64::NAN;
        assert!(matches!(
            estimate_normals(&nan, Viewpoints::None, &s),
            Err(Error::NotFinite {
                name: "points",
                index: 3
            })
        ));
        let ok = fibonacci_sphere(100);
        assert!(matches!(
            estimate_normals(&ok, Viewpoints::PerPoint(&ok[..5]), &s),
            Err(Error::InvalidArgument {
                name: "viewpoints",
                ..
            })
        ));
    }
}
