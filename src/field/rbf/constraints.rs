//! Constraint placement for variational surfaces (Cuno et al. §4.1, Turk & O'Brien): every data
//! point `q_i` is a boundary constraint (value 0) and `q_i + d_i n_i` a normal constraint (value
//! `w_i`), with `d_i` shrunk until no other data point is closer to the normal constraint than
//! `q_i` itself; in thin parts of the body also inner constraints ([`crate::field::rbf::thin`]). Also the
//! checks on the data (count, finiteness, duplicates, coplanarity) and vertex normals of
//! triangle meshes.

use crate::error::{check_finite_points, Error, Result};
use crate::field::rbf::duplicates;
use crate::field::rbf::thin;
use crate::spatial::Grid;
use glam::DVec3;
use rayon::prelude::*;

/// How constraint points are placed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConstraintSettings {
    /// Offset of normal constraints along the normal. `None`: [`default_offset`], 0.015 for data
    /// whose bounding box has largest side 2 (the papers' [-1, 1]³), scaled with the data (0.0075
    /// × the largest side), at most [`D_OVER_SPACING`] × the data's typical spacing.
    pub d: Option<f64>,
    /// Value at normal constraints. `None`: `w_over_d × d`.
    pub w: Option<f64>,
    /// Ratio w/d used when `w` is `None` (Cuno: 3/4).
    pub w_over_d: f64,
    /// Apply Cuno's rule: shrink `d_i` until no other data point is nearer to the normal constraint.
    pub shrink: bool,
    /// Data points at most this far apart are merged (see [`crate::field::rbf::duplicates`]). `None`:
    /// [`duplicates::default_tolerance`], 0.1 % of the data's typical spacing.
    pub merge_distance: Option<f64>,
    /// Inner constraints in thin parts ([`crate::field::rbf::thin`]): another sheet of the surface is looked
    /// for behind each data point within this multiple of `d`; 0 (default) places none. At 6
    /// they keep legs thinner than 4d whole, but on such legs the fit grows sheets far from the
    /// data (docs/variational.md, "Thin parts").
    pub thin_reach_over_d: f64,
    /// Normal constraints for only one data point (the first) per cell of a grid of this many
    /// typical spacings; 0 or `None` (default) places one for every data point. Fewer normal
    /// constraints make a partition fit cheaper, but they hold the field's sign near the data:
    /// with one per 2 spacings (about one data point in ten) fits of 10⁶ points grew small
    /// bubbles (docs/variational.md).
    pub normal_cell_over_spacing: Option<f64>,
}

/// Normals facing each other more than this (cosine of the angle between them) belong to two
/// sheets of the surface.
const FACING_COS: f64 = -0.5;

impl Default for ConstraintSettings {
    fn default() -> Self {
        ConstraintSettings {
            d: None,
            w: None,
            w_over_d: 0.75,
            shrink: true,
            merge_distance: None,
            thin_reach_over_d: 0.0,
            normal_cell_over_spacing: None,
        }
    }
}

/// Constraint points and values: the first `boundary` entries are the data points (value 0), the
/// next `normal_of.len()` the normal constraints (of every data point, or at scan scale of a
/// subset, see [`ConstraintSettings::normal_cell_over_spacing`]), in the order of their data
/// points, and the rest the inner constraints of thin parts ([`crate::field::rbf::thin`]), in the order of
/// their data points.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Constraints {
    /// The constraint points.
    pub points: Vec<DVec3>,
    /// The value the surface takes at each point.
    pub values: Vec<f64>,
    /// The offset `d_i` used for each data point (after shrinking).
    pub offsets: Vec<f64>,
    /// Number of boundary constraints (= data points, after merging near-duplicates).
    pub boundary: usize,
    /// The data point of each normal constraint, increasing (empty without normals; a
    /// [`PartitionSurface::cut`](crate::field::rbf::partition::PartitionSurface::cut) keeps none).
    pub normal_of: Vec<u32>,
    /// Number of data points merged into others (see [`crate::field::rbf::duplicates`]).
    pub merged: usize,
}

impl Constraints {
    /// The data point constraint `i` belongs to, for constraints up to the normal ones; for
    /// the inner constraints of thin parts, their rank among them modulo the data points (a key
    /// spread like the data's, for hashing).
    pub fn data_point(&self, i: usize) -> usize {
        let (b, normals) = (self.boundary, self.normal_of.len());
        if i < b {
            i
        } else if i < b + normals {
            self.normal_of[i - b] as usize
        } else {
            (i - b - normals) % b.max(1)
        }
    }
}

/// Largest side of the axis-aligned bounding box.
pub fn largest_side(points: &[DVec3]) -> f64 {
    let (lo, hi) = bounding_box(points);
    (hi - lo).max_element()
}

/// The bounding box of the points within [`crate::spatial::OUTSIDE`] extents of their bulk
/// ([`crate::spatial::Bulk`]): the box of all points unless a few lie far from the rest. The
/// default bounds and the default offset of the normal constraints are taken from it.
pub fn bulk_bounding_box(points: &[DVec3]) -> (DVec3, DVec3) {
    match crate::spatial::Bulk::of(points) {
        Some(bulk) => bulk.bounding_box(points).0,
        None => bounding_box(points),
    }
}

/// The largest side of [`bulk_bounding_box`].
pub fn bulk_largest_side(points: &[DVec3]) -> f64 {
    let (lo, hi) = bulk_bounding_box(points);
    (hi - lo).max_element()
}

/// Axis-aligned bounding box (min, max).
pub fn bounding_box(points: &[DVec3]) -> (DVec3, DVec3) {
    points.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    )
}

/// Checks a point set for interpolation: at least 4 points, all finite, not all in one plane.
pub fn check_points(name: &'static str, points: &[DVec3]) -> Result<()> {
    if points.len() < 4 {
        return Err(Error::invalid(
            name,
            format!("need at least 4 points, got {}", points.len()),
        ));
    }
    check_finite_points(name, points)?;
    crate::spatial::check_far(name, points)?;
    let extent = largest_side(points);
    if extent == 0.0 {
        return Err(Error::invalid(name, "all points coincide"));
    }
    // Plane through three well-spread points; all points within a tiny distance of it = coplanar.
    let p0 = points[0];
    let far = |from: &dyn Fn(DVec3) -> f64| {
        points
            .iter()
            .copied()
            .max_by(|a, b| from(*a).total_cmp(&from(*b)))
            .unwrap()
    };
    let p1 = far(&|p| (p - p0).length_squared());
    let axis = (p1 - p0).normalize();
    let p2 = far(&|p| (p - p0).reject_from_normalized(axis).length_squared());
    let normal = (p1 - p0).cross(p2 - p0);
    let tol = 1e-9 * extent;
    if normal.length() <= tol * extent {
        return Err(Error::invalid(name, "all points lie on one line"));
    }
    let normal = normal.normalize();
    let off_plane = points
        .iter()
        .map(|p| (*p - p0).dot(normal).abs())
        .fold(0.0, f64::max);
    if off_plane <= tol {
        return Err(Error::invalid(
            name,
            "all points lie in one plane; a closed surface needs points spanning 3-D",
        ));
    }
    Ok(())
}

/// `e`, or, when `e` says the system could not be solved and some of `points` lie more than
/// [`crate::spatial::OUTSIDE`] extents from their bulk, an error naming argument `name` that says
/// so: the distances, not the spacing, are then what the system cannot hold.
pub fn diagnose_far(name: &'static str, points: &[DVec3], e: Error) -> Error {
    if !matches!(e, Error::SingularSystem { .. }) {
        return e;
    }
    match crate::spatial::Bulk::of(points).and_then(|b| b.beyond(points, crate::spatial::OUTSIDE)) {
        Some(b) => Error::invalid(
            name,
            format!("{b}: the fit cannot hold both scales ({e}); remove the far points or fit them separately"),
        ),
        None => e,
    }
}

/// Checks data for interpolation: points as [`check_points`], one finite value per point.
pub fn check_points_and_values(points: &[DVec3], values: &[f64]) -> Result<()> {
    check_points("points", points)?;
    if values.len() != points.len() {
        return Err(Error::invalid(
            "values",
            format!(
                "need one value per point: {} values, {} points",
                values.len(),
                points.len()
            ),
        ));
    }
    crate::error::check_finite_values("values", values)
}

/// `merge_distance` if it is `None` or finite and non-negative.
pub fn check_merge_distance(merge_distance: Option<f64>) -> Result<Option<f64>> {
    match merge_distance {
        Some(t) if !(t.is_finite() && t >= 0.0) => Err(Error::invalid(
            "merge_distance",
            format!("must be finite and non-negative, got {t}"),
        )),
        t => Ok(t),
    }
}

/// Interpolation data with near-duplicate points merged (their values averaged, see
/// [`duplicates`]): constraints with no normal constraints.
pub fn interpolation_data(
    points: &[DVec3],
    values: &[f64],
    merge_distance: Option<f64>,
) -> Result<Constraints> {
    check_points_and_values(points, values)?;
    let merge = duplicates::merge(points, check_merge_distance(merge_distance)?);
    let (points, values) = if merge.merged() > 0 {
        (merge.points(points), merge.means(values))
    } else {
        (points.to_vec(), values.to_vec())
    };
    Ok(Constraints {
        boundary: points.len(),
        points,
        values,
        offsets: vec![],
        normal_of: vec![],
        merged: merge.merged(),
    })
}

/// Unit normals from `normals`, refusing non-finite or zero-length ones.
pub fn unit_normals(name: &'static str, normals: &[DVec3]) -> Result<Vec<DVec3>> {
    check_finite_points(name, normals)?;
    if let Some(i) = normals.par_iter().position_first(|n| n.length() < 1e-300) {
        return Err(Error::invalid(name, format!("normal {i} has zero length")));
    }
    Ok(normals.par_iter().map(|n| *n / n.length()).collect())
}

/// The default offset `d` is at most this many times the data's typical spacing (median
/// nearest-neighbour distance, [`duplicates::typical_spacing`]).
pub const D_OVER_SPACING: f64 = 6.0;

/// A cell side, in typical spacings, for [`ConstraintSettings::normal_cell_over_spacing`]: one
/// data point in about ten keeps its normal constraint.
pub const NORMAL_CELL_OVER_SPACING: f64 = 2.0;

/// From this many points on, the default offset is capped by the spacing (fewer points lie
/// further apart than 0.0075 × the largest side / [`D_OVER_SPACING`]).
const SPACING_CAP_POINTS: usize = 10_000;

/// The default offset of the normal constraints: 0.0075 × the largest side of the bounding box
/// of the bulk ([`bulk_bounding_box`]),
/// at most [`D_OVER_SPACING`] × the typical spacing. A partition fit's patches hold a fixed
/// number of constraints, so their support shrinks with the spacing, and an offset
/// large against the support leaves the field on the inner side of the data free to change
/// sign (small bubbles and handles at 10⁶ points).
pub fn default_offset(points: &[DVec3]) -> f64 {
    let grid = (points.len() >= SPACING_CAP_POINTS).then(|| Grid::new(points, 0.0));
    default_offset_on(points, grid.as_ref())
}

/// [`default_offset`], with the grid `Grid::new(points, 0.0)` when there are at least
/// [`SPACING_CAP_POINTS`] points.
fn default_offset_on(points: &[DVec3], grid: Option<&Grid>) -> f64 {
    let nominal = 0.0075 * bulk_largest_side(points);
    let Some(grid) = grid.filter(|_| points.len() >= SPACING_CAP_POINTS) else {
        return nominal;
    };
    let spacing = duplicates::typical_spacing(points, grid);
    if spacing > 0.0 {
        nominal.min(D_OVER_SPACING * spacing)
    } else {
        nominal
    }
}

/// Places boundary and normal constraints for `points` with `normals` (one per point, any
/// non-zero length).
pub fn place(
    points: &[DVec3],
    normals: &[DVec3],
    settings: &ConstraintSettings,
) -> Result<Constraints> {
    place_capped(points, normals, settings, None)
}

/// As [`place`], with an optional per-point cap on w_i/d_i (see [`crease_caps`]).
pub fn place_capped(
    points: &[DVec3],
    normals: &[DVec3],
    settings: &ConstraintSettings,
    caps: Option<&[f64]>,
) -> Result<Constraints> {
    check_points("points", points)?;
    if normals.len() != points.len() {
        return Err(Error::invalid(
            "normals",
            format!(
                "need one normal per point: {} normals for {} points",
                normals.len(),
                points.len()
            ),
        ));
    }
    let normals = unit_normals("normals", normals)?;
    let merge = duplicates::merge(points, check_merge_distance(settings.merge_distance)?);
    crate::cancel::check()?;
    if merge.merged() > 0 {
        let points = merge.points(points);
        let normals = merge.normals(&normals);
        let caps = caps.map(|c| merge.minima(c));
        let mut c = place_distinct(&points, &normals, settings, caps.as_deref())?;
        c.merged = merge.merged();
        return Ok(c);
    }
    place_distinct(points, &normals, settings, caps)
}

/// As [`place_capped`], for distinct points with unit normals.
fn place_distinct(
    points: &[DVec3],
    normals: &[DVec3],
    settings: &ConstraintSettings,
    caps: Option<&[f64]>,
) -> Result<Constraints> {
    // The grid that finds the default offset's spacing, kept for the shrinking below when that
    // needs the same cells.
    let mut spacing_grid = (settings.d.is_none() && points.len() >= SPACING_CAP_POINTS)
        .then(|| Grid::new(points, 0.0));
    let d = settings
        .d
        .unwrap_or_else(|| default_offset_on(points, spacing_grid.as_ref()));
    if !settings.shrink {
        spacing_grid = None;
    }
    if !(d.is_finite() && d > 0.0) {
        return Err(Error::invalid(
            "d",
            format!("must be positive and finite, got {d}"),
        ));
    }
    let w = match settings.w {
        Some(w) => w,
        None => settings.w_over_d * d,
    };
    if !(w.is_finite() && w != 0.0) {
        return Err(Error::invalid(
            "w",
            format!("must be finite and non-zero, got {w}"),
        ));
    }
    let ratio = w / d;
    crate::cancel::check()?;

    let mut offsets = vec![d; points.len()];
    if settings.shrink {
        // The points nearer than d_i to q_i + d_i n_i lie in the grid's cells within d_i of it
        // (searched with a radius a little larger, for the rounding of squared distances).
        // Points taken in the grid's order: each query reads the cells the one before read.
        let grid = match spacing_grid.take() {
            Some(g) if g.is_grid_of(d) => g,
            _ => Grid::new(points, d),
        };
        let shrunk: Vec<f64> = grid
            .order()
            .par_iter()
            .map(|&i| {
                let i = i as usize;
                let mut di = d;
                for _ in 0..60 {
                    let p = points[i] + normals[i] * di;
                    let nearer = grid.any_within(p, di * (1.0 + 1e-9), |j, q| {
                        j as usize != i && (q - p).length() < di
                    });
                    if !nearer {
                        break;
                    }
                    di *= 0.5;
                }
                di
            })
            .collect();
        for (&i, di) in grid.order().iter().zip(shrunk) {
            offsets[i as usize] = di;
        }
    }

    crate::cancel::check()?;
    let inner = if settings.thin_reach_over_d > 0.0 {
        let depths =
            thin::depths_behind(points, normals, settings.thin_reach_over_d * d, FACING_COS);
        let keep = thin::inner_points(points, normals, &depths);
        keep.into_iter().map(|i| (i, 0.5 * depths[i])).collect()
    } else {
        Vec::new()
    };

    crate::cancel::check()?;
    let n = points.len();
    let normal_of = normal_points(points, settings)?;
    let ratio_at = |i: usize| match caps {
        Some(c) if ratio > 0.0 => ratio.min(c[i]),
        _ => ratio,
    };
    // The data points, their normal constraints, then the inner ones (written in parallel).
    let cpoints: Vec<DVec3> = points
        .par_iter()
        .copied()
        .chain(normal_of.par_iter().map(|&i| {
            let i = i as usize;
            points[i] + normals[i] * offsets[i]
        }))
        .chain(inner.par_iter().map(|&(i, h)| points[i] - normals[i] * h))
        .collect();
    let values: Vec<f64> = rayon::iter::repeat_n(0.0, n)
        .chain(normal_of.par_iter().map(|&i| {
            let i = i as usize;
            ratio_at(i) * offsets[i]
        }))
        .chain(inner.par_iter().map(|&(i, h)| -ratio_at(i) * h))
        .collect();
    Ok(Constraints {
        points: cpoints,
        values,
        offsets,
        boundary: n,
        normal_of,
        merged: 0,
    })
}

/// The data points that get a normal constraint, increasing: every one, or the first of each
/// cell of [`ConstraintSettings::normal_cell_over_spacing`] typical spacings.
fn normal_points(points: &[DVec3], settings: &ConstraintSettings) -> Result<Vec<u32>> {
    let every = || (0..points.len() as u32).collect();
    let cells = match settings.normal_cell_over_spacing {
        Some(c) if !(c.is_finite() && c >= 0.0) => {
            return Err(Error::invalid(
                "normal_cell_over_spacing",
                format!("must be finite and non-negative, got {c}"),
            ))
        }
        Some(c) => c,
        None => 0.0,
    };
    if cells == 0.0 {
        return Ok(every());
    }
    let spacing = duplicates::typical_spacing(points, &Grid::new(points, 0.0));
    if spacing <= 0.0 {
        return Ok(every());
    }
    let grid = Grid::new(points, cells * spacing);
    let mut first = grid.first_of_each_cell();
    first.par_sort_unstable();
    Ok(first)
}

/// Per-vertex caps on w_i/d_i for a mesh: 0.9 × the smallest cosine between the vertex normal
/// and the normals of the faces around it, at least 0.5 (lower caps at the corners of a CAD part
/// made the fitted field negative far from the data).
///
/// The normal constraint q + d n lies only d·cos θ from the plane of an adjacent face whose
/// normal makes the angle θ with n. On smooth meshes cos θ ≈ 1 and the cap (≈ 0.9) is above
/// Cuno's w/d = 3/4, so nothing changes; at a sharp crease (fandisk) w = 0.75 d would exceed the
/// distance to the surface and break the pseudo-distance property |f| ≤ distance that the octree
/// polygonizer relies on, so w is lowered there.
pub fn crease_caps(vertices: &[DVec3], faces: &[[u32; 3]], normals: &[DVec3]) -> Vec<f64> {
    let mut cmin = vec![1.0f64; vertices.len()];
    for f in faces {
        let [a, b, c] = f.map(|v| vertices[v as usize]);
        let nf = (b - a).cross(c - a).normalize_or_zero();
        for &v in f {
            let v = v as usize;
            cmin[v] = cmin[v].min(normals[v].dot(nf));
        }
    }
    cmin.iter().map(|c| (0.9 * c).max(0.5)).collect()
}

/// A triangle mesh's vertices, faces and vertex normals.
pub type MeshWithNormals = (Vec<DVec3>, Vec<[u32; 3]>, Vec<DVec3>);

/// Checks a triangle mesh and returns its vertices with exact duplicates merged, the faces
/// re-indexed, and area-weighted vertex normals (the average of the adjacent faces' normals,
/// weighted by area). Errors on out-of-range or repeated indices and on vertices that no face uses.
pub fn mesh_vertices_normals(vertices: &[DVec3], faces: &[[u32; 3]]) -> Result<MeshWithNormals> {
    check_finite_points("vertices", vertices)?;
    if faces.is_empty() {
        return Err(Error::invalid("faces", "the mesh has no faces"));
    }
    for (k, f) in faces.iter().enumerate() {
        if let Some(&bad) = f.iter().find(|&&v| v as usize >= vertices.len()) {
            return Err(Error::invalid(
                "faces",
                format!(
                    "face {k} refers to vertex {bad}, but there are {} vertices",
                    vertices.len()
                ),
            ));
        }
        if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
            return Err(Error::invalid(
                "faces",
                format!("face {k} repeats a vertex: {f:?}"),
            ));
        }
    }
    // Merge vertices with identical coordinates (seams of meshes read from STL/OBJ files).
    let mut order: Vec<u32> = (0..vertices.len() as u32).collect();
    let key = |i: u32| {
        let p = vertices[i as usize];
        // + 0.0 turns -0.0 into 0.0, so the two zeros merge.
        [
            (p.x + 0.0).to_bits(),
            (p.y + 0.0).to_bits(),
            (p.z + 0.0).to_bits(),
        ]
    };
    order.sort_unstable_by_key(|&i| key(i));
    let mut remap = vec![0u32; vertices.len()];
    let mut merged: Vec<DVec3> = Vec::with_capacity(vertices.len());
    let mut first_of: Vec<u32> = Vec::with_capacity(vertices.len());
    for (pos, &i) in order.iter().enumerate() {
        if pos == 0 || key(order[pos - 1]) != key(i) {
            merged.push(vertices[i as usize]);
            first_of.push(i);
        }
        remap[i as usize] = (merged.len() - 1) as u32;
    }
    // Keep the original order of first occurrence for the merged vertices.
    let mut by_first: Vec<u32> = (0..merged.len() as u32).collect();
    by_first.sort_unstable_by_key(|&m| first_of[m as usize]);
    let mut rank = vec![0u32; merged.len()];
    for (r, &m) in by_first.iter().enumerate() {
        rank[m as usize] = r as u32;
    }
    let out_vertices: Vec<DVec3> = by_first.iter().map(|&m| merged[m as usize]).collect();
    let out_faces: Vec<[u32; 3]> = faces
        .iter()
        .map(|f| f.map(|v| rank[remap[v as usize] as usize]))
        .collect();
    if let Some(k) = out_faces
        .iter()
        .position(|f| f[0] == f[1] || f[1] == f[2] || f[0] == f[2])
    {
        return Err(Error::invalid(
            "faces",
            format!("face {k} has two corners at the same position"),
        ));
    }
    let mut normals = vec![DVec3::ZERO; out_vertices.len()];
    let mut used = vec![false; out_vertices.len()];
    for f in &out_faces {
        let [a, b, c] = f.map(|v| out_vertices[v as usize]);
        let n = (b - a).cross(c - a); // length = twice the area: area weighting
        for &v in f {
            normals[v as usize] += n;
            used[v as usize] = true;
        }
    }
    if let Some(i) = used.iter().position(|u| !u) {
        let original = by_first[i];
        return Err(Error::invalid(
            "vertices",
            format!(
                "vertex {} is not used by any face",
                first_of[original as usize]
            ),
        ));
    }
    for (i, n) in normals.iter_mut().enumerate() {
        let l = n.length();
        // Not `l <= 0.0`: a NaN length is refused too.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        if !(l > 0.0) {
            return Err(Error::invalid(
                "faces",
                format!("the faces around vertex {i} cancel out: its normal is undefined"),
            ));
        }
        *n /= l;
    }
    Ok((out_vertices, out_faces, normals))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube_points() -> Vec<DVec3> {
        (0..8)
            .map(|k| DVec3::new((k & 1) as f64, ((k >> 1) & 1) as f64, ((k >> 2) & 1) as f64))
            .collect()
    }

    #[test]
    fn refuses_bad_point_sets() {
        assert!(check_points("points", &cube_points()[..3]).is_err());
        let flat: Vec<DVec3> = (0..10)
            .map(|i| DVec3::new(i as f64, (i * i) as f64, 0.0))
            .collect();
        assert!(check_points("points", &flat).is_err());
        assert!(check_points("points", &cube_points()).is_ok());
    }

    #[test]
    fn merges_duplicates_before_placing() {
        let mut pts = cube_points();
        let mut normals: Vec<DVec3> = pts.iter().map(|p| *p - DVec3::splat(0.5)).collect();
        pts.push(pts[3] + DVec3::splat(1e-12));
        normals.push(normals[3]);
        let c = place(&pts, &normals, &ConstraintSettings::default()).unwrap();
        assert_eq!((c.boundary, c.merged), (8, 1));
        assert_eq!(&c.points[..8], &cube_points()[..]);
        assert!(matches!(
            place(
                &pts,
                &normals,
                &ConstraintSettings {
                    merge_distance: Some(-1.0),
                    ..Default::default()
                }
            ),
            Err(Error::InvalidArgument {
                name: "merge_distance",
                ..
            })
        ));
    }

    #[test]
    fn grid_search_gives_the_all_pairs_offsets_and_duplicates() {
        use crate::testing::random_points;
        // Clustered points (a dense blob inside a sparse cloud), so that many offsets shrink.
        let mut pts = random_points(1500, -1.0, 1.0, 31);
        pts.extend(random_points(1500, -0.05, 0.05, 32));
        let normals = random_points(3000, -1.0, 1.0, 33);
        let d = 0.03;
        let c = place(
            &pts,
            &normals,
            &ConstraintSettings {
                d: Some(d),
                ..Default::default()
            },
        )
        .unwrap();
        // The rule with every pair of points.
        let mut shrunk = 0;
        for i in 0..pts.len() {
            let n = normals[i].normalize();
            let mut di = d;
            for _ in 0..60 {
                let p = pts[i] + n * di;
                let ok = (0..pts.len()).all(|j| {
                    j == i
                        || (pts[j] - pts[i]).length_squared() > 4.0 * d * d
                        || (pts[j] - p).length() >= di
                });
                if ok {
                    break;
                }
                di *= 0.5;
            }
            assert_eq!(c.offsets[i].to_bits(), di.to_bits(), "point {i}");
            shrunk += (di < d) as usize;
        }
        assert!(shrunk > 100, "{shrunk}");
        // Duplicates: each joins its group's smallest index, as all pairs find it.
        let mut dup = pts.clone();
        dup.push(pts[2000] + DVec3::splat(1e-13));
        dup.push(pts[17]);
        let m = crate::field::rbf::duplicates::merge(&dup, Some(1e-12));
        assert_eq!((m.into[3000], m.into[3001], m.merged()), (2000, 17, 2));
    }

    #[test]
    fn inner_constraints_follow_the_normal_ones_with_negative_values() {
        use std::f64::consts::TAU;
        // A cylinder 0.04 across with caps: thin for a reach of 6d = 0.09.
        let mut pts = Vec::new();
        let mut normals = Vec::new();
        for k in 0..20 {
            for a in 0..8 {
                let phi = TAU * (a as f64 + 0.5 * (k % 2) as f64) / 8.0;
                let dir = DVec3::new(phi.cos(), phi.sin(), 0.0);
                pts.push(dir * 0.02 + DVec3::Z * (0.02 * k as f64));
                normals.push(dir);
            }
        }
        let settings = ConstraintSettings {
            d: Some(0.015),
            thin_reach_over_d: 6.0,
            ..Default::default()
        };
        let c = place(&pts, &normals, &settings).unwrap();
        let n = pts.len();
        assert!(c.points.len() > 2 * n + 10, "{}", c.points.len() - 2 * n);
        assert!(c.values[2 * n..].iter().all(|v| *v < 0.0));
        // Off by default: Cuno's constraints only.
        let plain = place(
            &pts,
            &normals,
            &ConstraintSettings {
                d: Some(0.015),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(plain.points.len(), 2 * n);
        assert_eq!(plain.points[..], c.points[..2 * n]);
    }

    #[test]
    fn shrinks_offsets_near_other_points() {
        let mut pts = cube_points();
        let mut normals: Vec<DVec3> = pts.iter().map(|p| *p - DVec3::splat(0.5)).collect();
        // A point right above point 0's normal constraint forces its d to shrink.
        pts.push(DVec3::new(-0.02, -0.02, -0.02));
        normals.push(DVec3::ONE);
        let c = place(
            &pts,
            &normals,
            &ConstraintSettings {
                d: Some(0.05),
                ..Default::default()
            },
        )
        .unwrap();
        assert!(c.offsets[0] < 0.05);
        for i in 0..pts.len() {
            let p = c.points[pts.len() + i];
            for (j, q) in pts.iter().enumerate() {
                if j != i {
                    assert!((*q - p).length() >= c.offsets[i]);
                }
            }
            assert!((c.values[pts.len() + i] - 0.75 * c.offsets[i]).abs() < 1e-15);
        }
    }

    #[test]
    fn normal_constraints_of_one_point_per_cell() {
        let p = crate::testing::fibonacci_sphere(20_000);
        let every = place(&p, &p, &ConstraintSettings::default()).unwrap();
        assert_eq!(every.normal_of, (0..20_000).collect::<Vec<u32>>());
        let thinned = ConstraintSettings {
            normal_cell_over_spacing: Some(NORMAL_CELL_OVER_SPACING),
            ..Default::default()
        };
        let c = place(&p, &p, &thinned).unwrap();
        let k = c.normal_of.len();
        assert!(k > 500 && k < 10_000, "{k} normal constraints");
        assert!(c.normal_of.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(c.points.len(), 20_000 + k);
        assert_eq!(&c.points[..20_000], &p[..]);
        // Each normal constraint lies on its data point's normal, at that point's offset, with
        // the same offsets as when every point has one.
        assert_eq!(c.offsets, every.offsets);
        for (slot, &j) in c.normal_of.iter().enumerate() {
            let j = j as usize;
            assert_eq!(c.points[20_000 + slot], every.points[20_000 + j]);
            assert_eq!(c.values[20_000 + slot], every.values[20_000 + j]);
            assert_eq!(c.data_point(20_000 + slot), j);
        }
        // Every data point has a normal constraint within a few cells' reach.
        let reach =
            4.0 * NORMAL_CELL_OVER_SPACING * duplicates::typical_spacing(&p, &Grid::new(&p, 0.0));
        let kept: Vec<DVec3> = c.normal_of.iter().map(|&j| p[j as usize]).collect();
        let grid = Grid::new(&kept, reach);
        assert!(p.iter().all(|q| grid.any_within(*q, reach, |_, _| true)));
        let bad = ConstraintSettings {
            normal_cell_over_spacing: Some(-1.0),
            ..Default::default()
        };
        assert!(place(&p, &p, &bad).is_err());
    }

    #[test]
    fn default_offset_is_capped_by_the_spacing() {
        // A unit sphere and two far points: the largest side (40) puts 0.0075 × side far above
        // 6 spacings of the sphere's points.
        let spread = |n: usize| {
            let mut p = crate::testing::fibonacci_sphere(n);
            p.push(DVec3::new(20.0, 0.0, 0.0));
            p.push(DVec3::new(-20.0, 0.0, 0.0));
            p
        };
        let p = spread(20_000);
        let spacing = duplicates::typical_spacing(&p, &Grid::new(&p, 0.0));
        let d = default_offset(&p);
        assert!(spacing > 0.0 && d < 0.0075 * 40.0);
        assert_eq!(d, D_OVER_SPACING * spacing);
        let c = place(&p, &p, &ConstraintSettings::default()).unwrap();
        assert!(c.offsets.iter().all(|&o| o <= d));
        // Below SPACING_CAP_POINTS the offset is the nominal one.
        let few = spread(SPACING_CAP_POINTS - 3);
        assert_eq!(default_offset(&few), 0.0075 * largest_side(&few));
    }
}
