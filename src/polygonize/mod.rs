//! Polygonizers: from a [`Field`] and a [`Lattice`] to a [`Mesh`] and [`Stats`].
//!
//! All of them share the lattice, the case table ([`table`]) and the edge-vertex arithmetic
//! ([`cell`]), so they produce the same triangles wherever they find the surface: the dense
//! polygonizer is the reference the others are tested against.

pub mod bricks;
pub mod cell;
pub mod dense;
pub mod octree;
pub mod sparse;
pub mod subdivision;
pub mod table;
pub mod tracking;

pub use table::{Ambiguity, CaseTable};

use crate::error::{Error, Result};
use crate::field::{gradients_by_differences, Field};
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
    /// Compute gradients by central differences of batched values (for fields that only have
    /// values, e.g. Python callables), with this step as a fraction of the smallest cell side.
    /// `None`: use the field's own gradient.
    pub difference_gradients: Option<f64>,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            ambiguity: Ambiguity::Separate,
            normals: true,
            batch: 1 << 18,
            memory_limit: 8 << 30,
            difference_gradients: None,
        }
    }
}

/// Exact counts and timings of one polygonization.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Stats {
    /// Field values computed at lattice points (each point at most once).
    pub evaluations: u64,
    /// Points at which gradients were computed for normals (values, for difference gradients).
    pub normal_evaluations: u64,
    /// Lattice points, (nx+1)(ny+1)(nz+1): what plain marching cubes evaluates.
    pub lattice_points: u64,
    /// Cells examined.
    pub cells_visited: u64,
    /// Cells that produced triangles.
    pub cells_crossed: u64,
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
    let [x, y, z] = l.cells.map(|c| c as u64);
    8 * (x * y + y * z + z * x)
}

/// Errors when `bytes` exceed the limit.
pub fn check_memory(bytes: u64, limit: u64) -> Result<()> {
    if bytes > limit {
        return Err(Error::TooMuchMemory {
            name: "resolution",
            needed_mib: bytes.div_ceil(1 << 20),
            limit_mib: limit >> 20,
        });
    }
    Ok(())
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
        field.values(p, o);
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

/// Fills `mesh.normals` from the field's gradient (batched), falling back to face normals where
/// the gradient vanishes.
pub fn compute_normals<F: Field + ?Sized>(
    field: &F,
    lattice: &Lattice,
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
    let batch = settings.batch.max(1);
    match settings.difference_gradients {
        Some(frac) => {
            let h = frac * lattice.cell.min_element();
            let b = (batch / 6).max(1);
            for (p, o) in mesh.vertices.chunks(b).zip(g.chunks_mut(b)) {
                gradients_by_differences(field, p, h, o);
            }
            stats.normal_evaluations += 6 * mesh.vertices.len() as u64;
        }
        None => {
            for (p, o) in mesh.vertices.chunks(batch).zip(g.chunks_mut(batch)) {
                field.gradients(p, o);
            }
            stats.normal_evaluations += mesh.vertices.len() as u64;
        }
    }
    // Normalise in parallel chunks; count vanishing gradients and find the first non-finite one.
    const CHUNK: usize = 4096;
    let (zero, bad) = g
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(c, chunk)| {
            let (mut zero, mut bad) = (0usize, None);
            for (k, gi) in chunk.iter_mut().enumerate() {
                if !gi.is_finite() {
                    bad = bad.or(Some(c * CHUNK + k));
                    continue;
                }
                let l = gi.length();
                if l > 0.0 {
                    *gi *= 1.0 / l;
                } else {
                    zero += 1;
                }
            }
            (zero, bad)
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

/// Concatenates `parts` into one new vector, copying in parallel into its uninitialised
/// capacity: its fresh pages are first touched (and faulted in) by all threads at once, and
/// nothing is written twice.
pub(crate) fn gather<T: Copy + Send + Sync, P: AsRef<[T]> + Sync>(parts: &[P]) -> Vec<T> {
    let total: usize = parts.iter().map(|p| p.as_ref().len()).sum();
    let mut out: Vec<T> = crate::memory::with_capacity_huge(total);
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
                di.write(*si);
            }
        });
    // SAFETY: the slices cover out[..total] exactly (their lengths sum to total) and every
    // element was written above.
    unsafe { out.set_len(total) };
    out
}
