//! Polygonizers: from a [`Field`] and a [`Lattice`] to a [`Mesh`] and [`Stats`].
//!
//! One entry, [`polygonize`], runs the algorithm a [`Method`] names with that method's
//! settings (each holds the shared [`Settings`]) and returns a [`Polygonized`]: the mesh, the
//! key of each vertex's lattice edge when [`Settings::keys`] asks for them, and the stats. The
//! algorithms live in their modules: [`dense`] (the reference), [`sparse`], [`octree`] and
//! [`tracking`]. Sparse and tracking of every component use the field's block bounds, which
//! [`Field::block_field`] gives; a field without them is refused, never polygonized another way.
//!
//! All of them share the lattice, the case table (`table`) and the edge-vertex arithmetic
//! (`cell`), so they produce the same triangles wherever they find the surface: the dense
//! polygonizer is the reference the others are tested against.
//!
//! ```
//! use glam::DVec3;
//! use implicitmesh::field::analytic::Sphere;
//! use implicitmesh::lattice::Lattice;
//! use implicitmesh::polygonize::{polygonize, octree::OctreeSettings, Method, Settings};
//!
//! let sphere = Sphere { center: DVec3::ZERO, radius: 0.8 };
//! let lattice = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 32).unwrap();
//! let dense = polygonize(&sphere, &lattice, &Method::Dense(Settings::default())).unwrap();
//! let octree = polygonize(&sphere, &lattice, &Method::Octree(OctreeSettings::default())).unwrap();
//! assert_eq!(octree.mesh.triangles.len(), dense.mesh.triangles.len());
//! assert!(octree.stats.evaluations < dense.stats.evaluations);
//! assert!(dense.keys.is_none());
//! ```

pub(crate) mod bits;
pub(crate) mod bricks;
pub(crate) mod cell;
pub mod dense;
pub mod octree;
pub mod project;
pub mod sparse;
pub(crate) mod table;
pub mod tracking;
pub mod weld;

pub use table::{Ambiguity, CaseTable};

use crate::error::{Error, Result};
use crate::field::Field;
use crate::lattice::Lattice;
use crate::mesh::Mesh;
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

/// Settings shared by the polygonizers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// How ambiguous cube faces are split (Triquet §4.5).
    pub ambiguity: Ambiguity,
    /// Compute vertex normals from the field's gradient.
    pub normals: bool,
    /// Target number of points per batched field call.
    pub batch: usize,
    /// Refuse lattices whose memory estimate exceeds this many bytes.
    pub memory_limit: u64,
    /// Move each vertex onto the zero set by one bounded Newton step ([`project`]) before the
    /// normals are computed.
    pub project: bool,
    /// Also return the key of each vertex's lattice edge ([`Lattice::whole_edge_key`]), in
    /// [`Polygonized::keys`]: what welds the meshes of windows of one lattice.
    pub keys: bool,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            ambiguity: Ambiguity::Separate,
            normals: true,
            batch: 1 << 18,
            memory_limit: crate::memory::DEFAULT_MEMORY_LIMIT,
            project: false,
            keys: false,
        }
    }
}

/// The polygonizer [`polygonize`] runs, with its settings.
#[derive(Clone, Debug, PartialEq)]
pub enum Method {
    /// Plain marching cubes over every cell ([`dense`]): the reference.
    Dense(Settings),
    /// The dense mesh from only the blocks the field's bounds cannot rule out ([`sparse`]);
    /// needs a field with block bounds ([`Field::block_field`], a blob field).
    Sparse(Settings),
    /// Hierarchical sampling with the rejection test ([`octree`]).
    Octree(octree::OctreeSettings),
    /// Surface tracking from seeds ([`tracking`]); [`tracking::Components::All`] needs a field
    /// with block bounds. [`tracking::TrackingSettings::for_field`] makes the settings the field
    /// calls for.
    Tracking(tracking::TrackingSettings),
}

impl Method {
    /// The settings every method shares.
    pub fn settings(&self) -> &Settings {
        match self {
            Method::Dense(s) | Method::Sparse(s) => s,
            Method::Octree(o) => &o.common,
            Method::Tracking(t) => &t.common,
        }
    }

    /// The method's name, as the Python package spells it: `"dense"`, `"sparse"`, `"octree"`
    /// or `"tracking"`.
    pub fn name(&self) -> &'static str {
        match self {
            Method::Dense(_) => "dense",
            Method::Sparse(_) => "sparse",
            Method::Octree(_) => "octree",
            Method::Tracking(_) => "tracking",
        }
    }
}

/// What [`polygonize`] returns.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Polygonized {
    /// The mesh (normals empty unless [`Settings::normals`]).
    pub mesh: Mesh,
    /// With [`Settings::keys`], the key of each vertex's lattice edge
    /// ([`Lattice::whole_edge_key`]), one per vertex; `None` otherwise.
    pub keys: Option<Vec<u64>>,
    /// Counts and timings.
    pub stats: Stats,
}

/// Polygonizes `field` over `lattice` with `method`.
///
/// Errors for [`Method::Sparse`], and [`Method::Tracking`] with
/// [`tracking::Components::All`], when the field has no block bounds
/// ([`Field::block_field`]); for a lattice whose estimated memory exceeds
/// [`Settings::memory_limit`]; when the field gives a value that is not finite; and when
/// interrupted ([`crate::cancel`]).
pub fn polygonize<F: Field + ?Sized>(
    field: &F,
    lattice: &Lattice,
    method: &Method,
) -> Result<Polygonized> {
    match method {
        Method::Dense(s) => dense::polygonize(field, lattice, s),
        Method::Octree(o) => octree::polygonize(field, lattice, o),
        Method::Sparse(s) => sparse::polygonize(needs_bounds(field, "sparse")?, lattice, s),
        Method::Tracking(t) => tracking::polygonize(field, lattice, t),
    }
}

/// The field's block bounds, or the error saying that `method` needs them.
pub(crate) fn needs_bounds<'a, F: Field + ?Sized>(
    field: &'a F,
    method: &str,
) -> Result<&'a dyn crate::field::DynBlockField> {
    field.block_field().ok_or_else(|| {
        Error::invalid(
            "method",
            format!(
                "{method:?} needs a field with block bounds such as a BlobField (it bounds the \
                 field over blocks of the lattice); use \"dense\" or \"octree\""
            ),
        )
    })
}

/// The step of central differences for the normals of a field that only has values (a Python
/// callable wrapped in [`crate::field::Differences`]), as a fraction of the smallest cell side.
pub const DIFFERENCE_STEP: f64 = 1e-3;

/// [`DIFFERENCE_STEP`] on `lattice`: the step, in field units, of central differences for the
/// normals of a field that only has values.
pub fn difference_step(lattice: &Lattice) -> f64 {
    DIFFERENCE_STEP * lattice.cell().min_element()
}

/// Exact counts and timings of one polygonization.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Stats {
    /// Field values computed at lattice points (a point computed twice, e.g. on the faces that
    /// blocks share, counts twice).
    pub evaluations: u64,
    /// Field evaluations for normals: [`Field::values_per_gradient`] per vertex (1 for a field's
    /// own gradient, the 6 values of central differences for [`crate::field::Differences`]).
    pub normal_evaluations: u64,
    /// Field evaluations for [`Settings::project`]: a value and a gradient per vertex.
    pub projection_evaluations: u64,
    /// Lattice points, (nx+1)(ny+1)(nz+1): what plain marching cubes evaluates.
    pub lattice_points: u64,
    /// Cells examined.
    pub cells_visited: u64,
    /// Cells that produced triangles.
    pub cells_crossed: u64,
    /// Octree: cells visited again or added where the rejection's premise failed (a dropped
    /// block held surface, or a sign inferred was wrong); 0 when it held.
    pub cells_repaired: u64,
    /// Per level of a hierarchy (octree), cells kept; empty for flat polygonizers.
    pub cells_per_level: Vec<u64>,
    /// Seconds per phase, in order.
    pub seconds: Vec<(&'static str, f64)>,
}

impl Stats {
    /// Evaluations as a percentage of plain marching cubes.
    pub fn evaluation_percent(&self) -> f64 {
        100.0 * self.evaluations as f64 / self.lattice_points.max(1) as f64
    }
    /// Adds time to a phase.
    pub fn add_time(&mut self, phase: &'static str, since: Instant) {
        let s = since.elapsed().as_secs_f64();
        match self.seconds.iter_mut().find(|(p, _)| *p == phase) {
            Some((_, t)) => *t += s,
            None => self.seconds.push((phase, s)),
        }
    }
    /// Total seconds over all phases.
    pub fn total_seconds(&self) -> f64 {
        self.seconds.iter().map(|(_, s)| s).sum()
    }
}

/// Bytes per output triangle (indices, plus half a vertex with position and normal).
const BYTES_PER_TRIANGLE: u64 = 12 + 24;

/// A rough upper estimate of output triangles for a lattice: a surface as large as a few times
/// the box's own surface. Used only to refuse absurd resolutions before running out of memory.
pub fn estimate_triangles(l: &Lattice) -> u64 {
    let [x, y, z] = l.cells().map(|c| c as u64);
    8 * (x * y + y * z + z * x)
}

/// Errors when `bytes` exceed the limit (the lattice's `resolution` is what asks for them).
pub fn check_memory(bytes: u64, limit: u64) -> Result<()> {
    crate::error::check_memory("resolution", bytes, limit)
}

/// Evaluates `points` through the field in batches and checks the values are finite.
pub fn evaluate<F: Field + ?Sized>(
    field: &F,
    points: &[DVec3],
    out: &mut [f64],
    batch: usize,
) -> Result<()> {
    for (p, o) in points
        .chunks(batch.max(1))
        .zip(out.chunks_mut(batch.max(1)))
    {
        crate::cancel::check()?;
        field.values(p, o);
        crate::cancel::advance(p.len() as u64)?;
        if let Some(i) = o.iter().position(|v| !v.is_finite()) {
            return Err(Error::FieldNotFinite {
                x: p[i].x,
                y: p[i].y,
                z: p[i].z,
            });
        }
    }
    Ok(())
}

/// Where a normal is zero (the gradient vanishes), the mean normal of the vertex's triangles.
pub fn fill_vanishing_normals(mesh: &mut Mesh) {
    if !mesh.normals.contains(&DVec3::ZERO) {
        return;
    }
    let f = mesh.face_normals_at_vertices();
    for (gi, fi) in mesh.normals.iter_mut().zip(f) {
        if *gi == DVec3::ZERO {
            *gi = fi;
        }
    }
}

/// Projects the vertices ([`Settings::project`]), then computes the normals: the last step of
/// the polygonizers whose normals come from the field's gradient.
pub fn finish_mesh<F: Field + ?Sized>(
    field: &F,
    mesh: &mut Mesh,
    lattice: &Lattice,
    settings: &Settings,
    stats: &mut Stats,
) -> Result<()> {
    project::project_vertices(field, mesh, lattice, settings, stats)?;
    compute_normals(field, mesh, settings, stats)
}

/// Fills `mesh.normals` from the field's gradient (batched), falling back to face normals where
/// the gradient vanishes.
pub fn compute_normals<F: Field + ?Sized>(
    field: &F,
    mesh: &mut Mesh,
    settings: &Settings,
    stats: &mut Stats,
) -> Result<()> {
    let t = Instant::now();
    if !settings.normals {
        mesh.normals.clear();
        return Ok(());
    }
    // Zeroed in parallel: the fresh pages are faulted in by all threads.
    let mut g: Vec<DVec3> = crate::memory::with_capacity_huge(mesh.vertices.len());
    (0..mesh.vertices.len())
        .into_par_iter()
        .map(|_| DVec3::ZERO)
        .collect_into_vec(&mut g);
    // Batches of `settings.batch` field values: fewer gradients when each costs several values.
    let per_gradient = field.values_per_gradient();
    let batch = (settings.batch / per_gradient as usize).max(1);
    for (p, o) in mesh.vertices.chunks(batch).zip(g.chunks_mut(batch)) {
        crate::cancel::check()?;
        field.gradients(p, o);
        crate::cancel::advance(per_gradient * p.len() as u64)?;
    }
    stats.normal_evaluations += per_gradient * mesh.vertices.len() as u64;
    // Normalise in parallel chunks; count vanishing gradients and find the first non-finite one.
    const CHUNK: usize = 4096;
    let (zero, bad) = g
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(c, chunk)| {
            let (zero, bad) = normalize(chunk);
            (zero, bad.map(|k| c * CHUNK + k))
        })
        .reduce(
            || (0, None),
            |a, b| {
                (
                    a.0 + b.0,
                    match (a.1, b.1) {
                        (Some(x), Some(y)) => Some(x.min(y)),
                        (x, y) => x.or(y),
                    },
                )
            },
        );
    if let Some(i) = bad {
        let p = mesh.vertices[i];
        return Err(Error::FieldNotFinite {
            x: p.x,
            y: p.y,
            z: p.z,
        });
    }
    mesh.normals = g;
    if zero > 0 {
        fill_vanishing_normals(mesh);
    }
    stats.add_time("normals", t);
    Ok(())
}

/// Scales each vector of `g` to unit length, bit for bit `v * (1.0 / v.length())`; vectors of
/// length zero stay zero and non-finite ones stay as they are. Returns the number of zero
/// vectors and the index of the first non-finite one.
pub(crate) fn normalize(g: &mut [DVec3]) -> (usize, Option<usize>) {
    normalize_with(crate::simd::Isa::detect(), g)
}

/// [`normalize`] with the vector path of `isa`, which the CPU must have.
fn normalize_with(isa: crate::simd::Isa, g: &mut [DVec3]) -> (usize, Option<usize>) {
    let done = match isa {
        // SAFETY: the caller passes an instruction set the CPU has.
        #[cfg(target_arch = "x86_64")]
        crate::simd::Isa::Avx512 => unsafe { normalize_avx512(g) },
        // SAFETY: as above.
        #[cfg(target_arch = "x86_64")]
        crate::simd::Isa::Avx2 => unsafe { normalize_avx2(g) },
        crate::simd::Isa::Generic => 0,
    };
    normalize_from(g, done)
}

/// The scalar loop of [`normalize`] over `g[start..]` (indices counted from `g[0]`).
fn normalize_from(g: &mut [DVec3], start: usize) -> (usize, Option<usize>) {
    let (mut zero, mut bad) = (0, None);
    for (k, v) in g.iter_mut().enumerate().skip(start) {
        if !v.is_finite() {
            bad = bad.or(Some(k));
            continue;
        }
        let l = v.length();
        if l > 0.0 {
            *v *= 1.0 / l;
        } else {
            zero += 1;
        }
    }
    (zero, bad)
}

/// [`normalize`] `V::LANES` vectors at a time, up to the first group holding a vector that is
/// zero or not of finite length; returns how many vectors it normalized (the rest is left to
/// the scalar loop). The same operations in the same order, so the same bits.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn normalize_lanes<V: crate::simd::lanes::F64s>(g: &mut [DVec3]) -> usize {
    let all = (1u32 << V::LANES) - 1;
    let mut done = 0;
    // SAFETY (every vector operation below): the caller runs where V's feature is.
    unsafe {
        for c in g.chunks_exact_mut(V::LANES) {
            let (mut x, mut y, mut z) = ([0.0; 8], [0.0; 8], [0.0; 8]);
            for (k, p) in c.iter().enumerate() {
                (x[k], y[k], z[k]) = (p.x, p.y, p.z);
            }
            let (vx, vy, vz) = (V::load(&x), V::load(&y), V::load(&z));
            // DVec3::length: ((x·x + y·y) + z·z).sqrt().
            let l = vx.mul(vx).add(vy.mul(vy)).add(vz.mul(vz)).sqrt();
            // 0 < l < ∞ in every lane (false for NaN); otherwise the scalar loop takes over.
            if l.gt(V::splat(0.0)) & l.lt(V::splat(f64::INFINITY)) != all {
                break;
            }
            let inv = V::splat(1.0).div(l);
            vx.mul(inv).store(&mut x);
            vy.mul(inv).store(&mut y);
            vz.mul(inv).store(&mut z);
            for (k, v) in c.iter_mut().enumerate() {
                *v = DVec3::new(x[k], y[k], z[k]);
            }
            done += V::LANES;
        }
    }
    done
}

/// [`normalize_lanes`] with AVX-512, eight vectors at a time.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn normalize_avx512(g: &mut [DVec3]) -> usize {
    // SAFETY: AVX-512F is enabled here.
    unsafe { normalize_lanes::<std::arch::x86_64::__m512d>(g) }
}

/// [`normalize_lanes`] with AVX2, four vectors at a time.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn normalize_avx2(g: &mut [DVec3]) -> usize {
    // SAFETY: AVX2 is enabled here.
    unsafe { normalize_lanes::<std::arch::x86_64::__m256d>(g) }
}

/// Concatenates `parts` into one new vector, copying in parallel into its uninitialised
/// capacity: its fresh pages are first touched (and faulted in) by all threads at once, and
/// nothing is written twice.
pub(crate) fn gather<T: Copy + Send + Sync, P: AsRef<[T]> + Sync>(parts: &[P]) -> Vec<T> {
    gather_map(parts, |t| *t)
}

/// [`gather`] with each element converted by `f` on the way.
pub(crate) fn gather_map<T: Sync, U: Send, P: AsRef<[T]> + Sync>(
    parts: &[P],
    f: impl Fn(&T) -> U + Sync,
) -> Vec<U> {
    let total: usize = parts.iter().map(|p| p.as_ref().len()).sum();
    let mut out: Vec<U> = crate::memory::with_capacity_huge(total);
    let mut rest = &mut out.spare_capacity_mut()[..total];
    let mut slices = Vec::with_capacity(parts.len());
    for p in parts {
        let (a, b) = rest.split_at_mut(p.as_ref().len());
        slices.push(a);
        rest = b;
    }
    slices
        .into_par_iter()
        .zip(parts.par_iter())
        .with_min_len(4)
        .for_each(|(d, s)| {
            for (di, si) in d.iter_mut().zip(s.as_ref()) {
                di.write(f(si));
            }
        });
    // SAFETY: the slices cover out[..total] exactly (their lengths sum to total) and every
    // element was written above.
    unsafe { out.set_len(total) };
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The normals of a field with gradients by central differences cost 6 values a vertex,
    /// and the stats count exactly the values the field was asked for.
    #[test]
    fn difference_normals_count_the_values_they_use() {
        let sphere = crate::field::analytic::Sphere {
            center: DVec3::new(0.05, -0.02, 0.01),
            radius: 0.6,
        };
        let lattice = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 16).unwrap();
        let counted = crate::field::Counting::new(&sphere);
        let f = crate::field::Differences::new(&counted, difference_step(&lattice)).unwrap();
        let Polygonized { mesh, stats, .. } =
            polygonize(&f, &lattice, &Method::Dense(Settings::default())).unwrap();
        assert!(!mesh.vertices.is_empty());
        assert_eq!(stats.normal_evaluations, 6 * mesh.vertices.len() as u64);
        assert_eq!(
            counted.evaluations(),
            stats.evaluations + stats.normal_evaluations
        );
    }

    /// Every vectorised path gives the scalar loop's bits, zero and non-finite vectors
    /// included, wherever they fall among the groups of four or eight.
    #[test]
    fn normalize_matches_the_scalar_loop() {
        let mut rng = crate::testing::Lcg::new(7);
        let mut next = || rng.uniform() * 2.0 - 1.0;
        for special in [None, Some(0), Some(13), Some(37), Some(39)] {
            for kind in 0..3 {
                let mut g: Vec<DVec3> = (0..41)
                    .map(|i| DVec3::new(next(), next(), next()) * 10f64.powi(i % 7 - 3))
                    .collect();
                if let Some(i) = special {
                    g[i] = [DVec3::ZERO, DVec3::new(f64::NAN, 0.0, 1.0), DVec3::INFINITY][kind];
                }
                let mut expected = g.clone();
                let counts = normalize_from(&mut expected, 0);
                let bits = |v: &[DVec3]| -> Vec<[u64; 3]> {
                    v.iter().map(|p| p.to_array().map(f64::to_bits)).collect()
                };
                for isa in crate::simd::Isa::available() {
                    let mut g = g.clone();
                    assert_eq!(normalize_with(isa, &mut g), counts);
                    assert_eq!(bits(&g), bits(&expected), "{special:?} {kind} {isa:?}");
                }
            }
        }
    }
}
