//! Plain marching cubes over the whole lattice: the reference polygonizer.
//!
//! The lattice is swept slab by slab along z. Field values come in batches of whole z-planes (one
//! batched field call per batch), edge vertices are made once per crossed lattice edge and shared
//! by the four cells around the edge, and only two planes of edge-vertex indices are kept, so the
//! working memory grows with one plane, not with the lattice.

use super::cell::{case_index, corner_offset, edge_origin, emit_triangles};
use super::{check_memory, compute_normals, estimate_triangles, CaseTable, Settings, Stats};
use crate::error::Result;
use crate::field::Field;
use crate::lattice::{edge_crossing, Lattice};
use crate::mesh::Mesh;
use glam::DVec3;
use std::time::Instant;

const NONE: u32 = u32::MAX;

/// Supplies the values of successive z-planes, evaluating several planes per field call.
struct Planes<'a, F: ?Sized> {
    field: &'a F,
    lattice: Lattice,
    per_batch: u32,
    /// Planes `first..first + count` are in `values`.
    first: u32,
    count: u32,
    values: Vec<f64>,
    points: Vec<DVec3>,
    batch: usize,
}

impl<F: Field + ?Sized> Planes<'_, F> {
    fn plane_len(&self) -> usize {
        let p = self.lattice.points_per_axis();
        p[0] as usize * p[1] as usize
    }

    /// Values of plane `k` (planes must be requested in increasing order).
    fn plane(&mut self, k: u32, stats: &mut Stats) -> Result<&[f64]> {
        let n = self.plane_len();
        if k >= self.first + self.count {
            let t = Instant::now();
            let last = self.lattice.cells[2];
            self.first = k;
            self.count = self.per_batch.min(last + 1 - k);
            let n_values = self.count as usize * self.plane_len();
            self.values.resize(n_values, 0.0);
            // Whole planes at once; in batches for fields that are called per batch.
            let per = ((self.batch / self.plane_len()).max(1)) as u32;
            let mut z = k;
            while z < k + self.count {
                let z1 = (z + per).min(k + self.count);
                let off = (z - k) as usize * self.plane_len();
                let len = (z1 - z) as usize * self.plane_len();
                self.field.lattice_values(
                    &self.lattice,
                    z,
                    z1,
                    &mut self.points,
                    &mut self.values[off..off + len],
                );
                if let Some(i) = self.values[off..off + len]
                    .iter()
                    .position(|v| !v.is_finite())
                {
                    let p = self.lattice.points_per_axis();
                    let (pl, r) = (i / self.plane_len(), i % self.plane_len());
                    let q = self.lattice.point([
                        (r % p[0] as usize) as u32,
                        (r / p[0] as usize) as u32,
                        z + pl as u32,
                    ]);
                    return Err(crate::Error::FieldNotFinite {
                        x: q.x,
                        y: q.y,
                        z: q.z,
                    });
                }
                z = z1;
            }
            stats.evaluations += n_values as u64;
            stats.add_time("evaluate", t);
        }
        let off = (k - self.first) as usize * n;
        Ok(&self.values[off..off + n])
    }
}

/// Polygonizes `field` over every cell of `lattice` with plain marching cubes.
pub fn polygonize<F: Field + ?Sized>(
    field: &F,
    lattice: &Lattice,
    settings: &Settings,
) -> Result<(Mesh, Stats)> {
    let [nx, ny, nz] = lattice.cells;
    let [px, py, _] = lattice.points_per_axis();
    let plane = px as u64 * py as u64;
    let per_batch = ((settings.batch as u64 / plane).max(1)).min(nz as u64 + 1) as u32;
    // Working memory: the batch of planes (points and values), two planes of values and five
    // planes of edge indices; plus the output.
    let working = per_batch as u64 * plane * 32 + plane * (16 + 5 * 4);
    check_memory(
        working + estimate_triangles(lattice) * super::BYTES_PER_TRIANGLE,
        settings.memory_limit,
    )?;

    let table = CaseTable::get(settings.ambiguity);
    let mut stats = Stats {
        lattice_points: lattice.num_points(),
        ..Default::default()
    };
    let mut planes = Planes {
        field,
        lattice: *lattice,
        per_batch,
        first: 0,
        count: 0,
        values: vec![],
        points: vec![],
        batch: settings.batch,
    };
    let mut mesh = Mesh::default();
    let (pxu, nxu, nyu) = (px as usize, nx as usize, ny as usize);
    let plane_len = pxu * py as usize;
    // Edge-vertex indices: x-edges and y-edges of the lower and upper plane of the slab, z-edges
    // of the slab.
    let mut xe = [vec![NONE; nxu * py as usize], vec![NONE; nxu * py as usize]];
    let mut ye = [vec![NONE; pxu * nyu], vec![NONE; pxu * nyu]];
    let mut ze = vec![NONE; plane_len];
    let mut lo = planes.plane(0, &mut stats)?.to_vec();
    let mut hi = vec![0.0; plane_len];

    let t = Instant::now();
    plane_vertices(lattice, 0, &lo, &mut xe[0], &mut ye[0], &mut mesh.vertices);
    stats.add_time("triangulate", t);
    for k in 0..nz {
        hi.copy_from_slice(planes.plane(k + 1, &mut stats)?);
        let t = Instant::now();
        let (xlo, xhi) = xe.split_at_mut(1);
        let (ylo, yhi) = ye.split_at_mut(1);
        plane_vertices(
            lattice,
            k + 1,
            &hi,
            &mut xhi[0],
            &mut yhi[0],
            &mut mesh.vertices,
        );
        // z-edges between the planes.
        for j in 0..py {
            for i in 0..px {
                let idx = j as usize * pxu + i as usize;
                let (a, b) = (lo[idx], hi[idx]);
                ze[idx] = if (a < 0.0) != (b < 0.0) {
                    let pa = lattice.point([i, j, k]);
                    let pb = lattice.point([i, j, k + 1]);
                    mesh.vertices.push(edge_crossing(pa, pb, a, b));
                    (mesh.vertices.len() - 1) as u32
                } else {
                    NONE
                };
            }
        }
        let (xs, ys) = ([&xlo[0], &xhi[0]], [&ylo[0], &yhi[0]]);
        for j in 0..ny as usize {
            for i in 0..nxu {
                let mut v = [0.0; 8];
                for (c, vc) in v.iter_mut().enumerate() {
                    let o = corner_offset(c);
                    let idx = (j + o[1] as usize) * pxu + i + o[0] as usize;
                    *vc = if o[2] == 0 { lo[idx] } else { hi[idx] };
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
                        let (o, axis) = edge_origin(e);
                        let (x, y, z) = (i + o[0] as usize, j + o[1] as usize, o[2] as usize);
                        match axis {
                            0 => xs[z][y * nxu + x],
                            1 => ys[z][y * pxu + x],
                            _ => ze[y * pxu + x],
                        }
                    },
                    &mut mesh.triangles,
                );
            }
        }
        std::mem::swap(&mut lo, &mut hi);
        xe.swap(0, 1);
        ye.swap(0, 1);
        stats.add_time("triangulate", t);
    }
    stats.cells_visited = lattice.num_cells();
    debug_assert!(mesh.triangles.iter().flatten().all(|&v| v != NONE));
    compute_normals(field, lattice, &mut mesh, settings, &mut stats)?;
    Ok((mesh, stats))
}

/// Creates the vertices on the crossed x- and y-edges of plane `k`.
fn plane_vertices(
    lattice: &Lattice,
    k: u32,
    values: &[f64],
    xe: &mut [u32],
    ye: &mut [u32],
    vertices: &mut Vec<DVec3>,
) {
    let [nx, ny, _] = lattice.cells;
    let px = nx as usize + 1;
    for j in 0..=ny {
        for i in 0..nx {
            let a = values[j as usize * px + i as usize];
            let b = values[j as usize * px + i as usize + 1];
            xe[j as usize * nx as usize + i as usize] = if (a < 0.0) != (b < 0.0) {
                let pa = lattice.point([i, j, k]);
                let pb = lattice.point([i + 1, j, k]);
                vertices.push(edge_crossing(pa, pb, a, b));
                (vertices.len() - 1) as u32
            } else {
                NONE
            };
        }
    }
    for j in 0..ny {
        for i in 0..=nx {
            let a = values[j as usize * px + i as usize];
            let b = values[(j as usize + 1) * px + i as usize];
            ye[j as usize * px + i as usize] = if (a < 0.0) != (b < 0.0) {
                let pa = lattice.point([i, j, k]);
                let pb = lattice.point([i, j + 1, k]);
                vertices.push(edge_crossing(pa, pb, a, b));
                (vertices.len() - 1) as u32
            } else {
                NONE
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::analytic::{Sphere, Torus};
    use crate::polygonize::Ambiguity;

    fn cube(n: u32, h: f64) -> Lattice {
        Lattice::new(DVec3::splat(-h), DVec3::splat(h), [n, n, n]).unwrap()
    }

    #[test]
    fn sphere_is_closed_with_the_right_area() {
        let s = Sphere {
            center: DVec3::new(0.01, 0.02, -0.03),
            radius: 0.7,
        };
        for amb in [Ambiguity::Separate, Ambiguity::Join] {
            let settings = Settings {
                ambiguity: amb,
                batch: 1000, // several planes per batch and a partial last batch
                ..Default::default()
            };
            let (m, st) = polygonize(&s, &cube(64, 1.0), &settings).unwrap();
            assert!(m.is_closed_oriented());
            assert_eq!(m.euler_characteristic(), 2);
            let exact = 4.0 * std::f64::consts::PI * 0.49;
            assert!((m.area() - exact).abs() / exact < 0.01);
            assert!(m.volume() > 0.0);
            assert_eq!(st.evaluations, 65 * 65 * 65);
            assert_eq!(m.normals.len(), m.vertices.len());
        }
    }

    #[test]
    fn torus_has_genus_one() {
        let t = Torus {
            center: DVec3::new(0.013, -0.02, 0.007),
            major: 0.6,
            minor: 0.25,
        };
        let (m, _) = polygonize(&t, &cube(48, 1.0), &Settings::default()).unwrap();
        assert!(m.is_closed_oriented());
        assert_eq!(m.euler_characteristic(), 0);
    }

    #[test]
    fn anisotropic_lattice() {
        let s = Sphere {
            center: DVec3::ZERO,
            radius: 0.5,
        };
        let l = Lattice::new(
            DVec3::new(-1.0, -0.7, -0.6),
            DVec3::new(0.9, 0.8, 0.6),
            [37, 23, 19],
        )
        .unwrap();
        let (m, _) = polygonize(&s, &l, &Settings::default()).unwrap();
        assert!(m.is_closed_oriented());
        assert_eq!(m.euler_characteristic(), 2);
    }

    #[test]
    fn surface_cut_by_the_bounds_is_open() {
        let s = Sphere {
            center: DVec3::ZERO,
            radius: 1.2,
        };
        let (m, _) = polygonize(&s, &cube(16, 1.0), &Settings::default()).unwrap();
        assert!(!m.triangles.is_empty());
        assert!(!m.is_closed_oriented());
    }

    #[test]
    fn absurd_resolution_refused() {
        let s = Sphere {
            center: DVec3::ZERO,
            radius: 0.5,
        };
        let l = cube(1_000_000, 1.0);
        assert!(matches!(
            polygonize(&s, &l, &Settings::default()),
            Err(crate::error::Error::TooMuchMemory { .. })
        ));
    }
}
