//! A uniform grid of voxels, each listing the primitives whose sphere of influence touches it
//! (Triquet et al. §4.3). Stored flat (compressed rows: one offset array and one item array), so
//! there is no allocation per voxel, and rebuilt in place when the primitives move: the arrays
//! keep their capacity, so a steady-state animation allocates nothing. Both passes of a
//! rebuild (counting and filling) run in parallel over slabs of voxel z-layers: a slab's voxels,
//! counts and list entries are each one contiguous range, and every slab walks the primitives
//! in index order, so the lists are the same whatever the number of threads.

use glam::DVec3;
use rayon::prelude::*;

/// Voxel grid over the spheres of influence of a set of primitives.
#[derive(Clone, Debug, Default)]
pub struct VoxelGrid {
    origin: DVec3,
    size: f64,
    /// 1 / size (a voxel lookup multiplies instead of dividing).
    inv_size: f64,
    dims: [u32; 3],
    /// `start[v]..start[v + 1]` indexes `items` for voxel v.
    start: Vec<u32>,
    items: Vec<u32>,
    /// Per-voxel fill cursor used while building.
    cursor: Vec<u32>,
}

/// Largest number of voxels a grid may have (the voxel size is grown to stay under it).
pub const MAX_VOXELS: u64 = 1 << 24;

impl VoxelGrid {
    /// Rebuilds the grid for spheres (`centers[i]`, `radii[i]`) with voxels of side `size`
    /// (grown if needed to keep at most [`MAX_VOXELS`] voxels), reusing the arrays.
    pub fn rebuild(&mut self, centers: &[DVec3], radii: &[f64], size: f64) {
        if centers.is_empty() {
            self.dims = [0; 3];
            self.start.clear();
            self.start.push(0);
            self.items.clear();
            return;
        }
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for (c, r) in centers.iter().zip(radii) {
            lo = lo.min(*c - DVec3::splat(*r));
            hi = hi.max(*c + DVec3::splat(*r));
        }
        let extent = (hi - lo).max(DVec3::splat(1e-12));
        let mut size = size.max(1e-12);
        loop {
            let d = (extent / size).ceil();
            if d.x * d.y * d.z <= MAX_VOXELS as f64 {
                break;
            }
            size *= 1.25;
        }
        let dims = (extent / size).ceil().max(DVec3::ONE);
        self.dims = [dims.x as u32, dims.y as u32, dims.z as u32];
        self.origin = lo;
        self.size = size;
        self.inv_size = 1.0 / size;
        let nvox = self.dims.iter().map(|&d| d as usize).product::<usize>();
        // A counting pass and a fill pass over the runs of voxels each primitive touches (found
        // again in the second pass: storing them would take more memory than the lists).
        self.start.clear();
        self.start.resize(nvox + 1, 0);
        let (origin, dims) = (self.origin, self.dims);
        let slabs = slabs(dims);
        let layer = dims[0] as usize * dims[1] as usize;
        let counts = split(
            &mut self.start[..nvox],
            slabs.iter().map(|z| z.len() * layer),
        );
        counts
            .into_par_iter()
            .zip(slabs.par_iter())
            .for_each(|(counts, z)| {
                let base = z.start as usize * layer;
                slab_runs(origin, size, dims, centers, radii, z, |_, first, count| {
                    for s in &mut counts[first - base..first - base + count] {
                        *s += 1;
                    }
                });
            });
        let mut total = 0u32;
        for s in self.start.iter_mut() {
            let c = *s;
            *s = total;
            total += c;
        }
        self.items.clear();
        self.items.resize(total as usize, 0);
        self.cursor.clear();
        self.cursor.extend_from_slice(&self.start[..nvox]);
        let start = &self.start;
        let items = split(
            &mut self.items,
            slabs.iter().map(|z| {
                (start[z.end as usize * layer] - start[z.start as usize * layer]) as usize
            }),
        );
        let cursors = split(&mut self.cursor, slabs.iter().map(|z| z.len() * layer));
        items
            .into_par_iter()
            .zip(cursors)
            .zip(slabs.par_iter())
            .for_each(|((items, cursor), z)| {
                let (base, first_item) = (
                    z.start as usize * layer,
                    start[z.start as usize * layer] as usize,
                );
                slab_runs(origin, size, dims, centers, radii, z, |i, first, count| {
                    for c in &mut cursor[first - base..first - base + count] {
                        items[*c as usize - first_item] = i as u32;
                        *c += 1;
                    }
                });
            });
    }

    /// The primitives that may influence point `p` (empty outside the grid).
    #[inline(always)]
    pub fn candidates(&self, p: DVec3) -> &[u32] {
        let q = (p - self.origin) * self.inv_size;
        if !(q.x >= 0.0 && q.y >= 0.0 && q.z >= 0.0) {
            return &[];
        }
        let (x, y, z) = (q.x as u32, q.y as u32, q.z as u32);
        let [dx, dy, dz] = self.dims;
        if x >= dx || y >= dy || z >= dz {
            return &[];
        }
        let v = (x as usize) + dx as usize * (y as usize + dy as usize * z as usize);
        &self.items[self.start[v] as usize..self.start[v + 1] as usize]
    }

    /// The largest sum of `weight(i)` over the primitives `i` of one voxel's list (0 when
    /// there are no voxels).
    pub fn max_list_sum(&self, weight: impl Fn(u32) -> f64) -> f64 {
        self.start
            .windows(2)
            .map(|w| {
                self.items[w[0] as usize..w[1] as usize]
                    .iter()
                    .map(|&i| weight(i))
                    .sum::<f64>()
            })
            .fold(0.0, f64::max)
    }

    /// Voxels per axis.
    pub fn dims(&self) -> [u32; 3] {
        self.dims
    }

    /// Side of a voxel.
    pub fn voxel_size(&self) -> f64 {
        self.size
    }

    /// Total entries over all voxel lists.
    pub fn entries(&self) -> usize {
        self.items.len()
    }

    /// Bytes held by the grid's arrays (capacity).
    pub fn capacity_bytes(&self) -> usize {
        4 * (self.start.capacity() + self.items.capacity() + self.cursor.capacity())
    }
}

/// Voxel z-layers per slab of a parallel rebuild: at most [`SLABS_PER_THREAD`] slabs per thread,
/// each of at least one layer.
fn slabs(dims: [u32; 3]) -> Vec<std::ops::Range<u32>> {
    let count = (rayon::current_num_threads() * SLABS_PER_THREAD).clamp(1, dims[2].max(1) as usize);
    (0..count as u32)
        .map(|k| {
            let cut = |k: u32| (k as u64 * dims[2] as u64 / count as u64) as u32;
            cut(k)..cut(k + 1)
        })
        .collect()
}

/// Slabs per thread (uneven work: the primitives are rarely spread evenly in z).
const SLABS_PER_THREAD: usize = 4;

/// `v` cut into consecutive slices of the given lengths.
fn split<T>(mut v: &mut [T], lengths: impl Iterator<Item = usize>) -> Vec<&mut [T]> {
    lengths
        .map(|n| {
            let (a, b) = std::mem::take(&mut v).split_at_mut(n);
            v = b;
            a
        })
        .collect()
}

/// Calls `f(i, first, count)` for every run of voxels of z-layers `z` that sphere i touches,
/// in index order of the spheres.
fn slab_runs(
    origin: DVec3,
    size: f64,
    dims: [u32; 3],
    centers: &[DVec3],
    radii: &[f64],
    z: &std::ops::Range<u32>,
    mut f: impl FnMut(usize, usize, usize),
) {
    for (i, (c, r)) in centers.iter().zip(radii).enumerate() {
        voxels_touching(origin, size, dims, *c, *r, z.clone(), |first, count| {
            f(i, first, count)
        });
    }
}

/// Calls `f(first, count)` for every run of consecutive voxels (along x) in z-layers `layers`
/// whose boxes intersect the sphere (c, r).
fn voxels_touching(
    origin: DVec3,
    size: f64,
    dims: [u32; 3],
    c: DVec3,
    r: f64,
    layers: std::ops::Range<u32>,
    mut f: impl FnMut(usize, usize),
) {
    // The radius gets a relative margin of 1e-9 so that rounding can only add a voxel (a
    // primitive listed in a voxel it misses adds +0.0 to a sum), never drop one.
    let r = r * (1.0 + 1e-9);
    let lo = ((c - DVec3::splat(r) - origin) / size)
        .floor()
        .max(DVec3::ZERO);
    let hi = ((c + DVec3::splat(r) - origin) / size).floor();
    let clamp = |v: f64, d: u32| (v as i64).clamp(0, d as i64 - 1) as u32;
    let (x0, y0, z0) = (
        clamp(lo.x, dims[0]),
        clamp(lo.y, dims[1]),
        clamp(lo.z, dims[2]),
    );
    let (x1, y1, z1) = (
        clamp(hi.x, dims[0]),
        clamp(hi.y, dims[1]),
        clamp(hi.z, dims[2]),
    );
    let (z0, z1) = (z0.max(layers.start), z1.min(layers.end.saturating_sub(1)));
    if layers.is_empty() || z0 > z1 {
        return;
    }
    // Row by row: the voxels of row (y, z) that the sphere reaches form one run in x, from the
    // distance between the centre and the row's box in y and z.
    let r2 = r * r;
    let inv = 1.0 / size;
    let gap = |c: f64, lo: f64| (lo - c).max(c - (lo + size)).max(0.0);
    for z in z0..=z1 {
        let gz = gap(c.z, origin.z + z as f64 * size);
        for y in y0..=y1 {
            let gy = gap(c.y, origin.y + y as f64 * size);
            let rest = r2 - gy * gy - gz * gz;
            if rest < 0.0 {
                continue;
            }
            let h = rest.sqrt();
            // Truncation is floor here: both are clamped at 0 first (no libm call per row).
            let xa = clamp(((c.x - h - origin.x) * inv).max(0.0), dims[0]).max(x0);
            let xb = clamp(((c.x + h - origin.x) * inv).max(0.0), dims[0]).min(x1);
            let row = dims[0] as usize * (y as usize + dims[1] as usize * z as usize);
            if xa <= xb {
                f(xa as usize + row, (xb - xa + 1) as usize);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance from `c` to the box of voxel `v`.
    fn distance(g: &VoxelGrid, v: usize, c: DVec3) -> f64 {
        let [dx, dy, _] = g.dims;
        let (dx, dy) = (dx as usize, dy as usize);
        let idx = DVec3::new(
            (v % dx) as f64,
            ((v / dx) % dy) as f64,
            (v / (dx * dy)) as f64,
        );
        let lo = g.origin + idx * g.size;
        (c.clamp(lo, lo + DVec3::splat(g.size)) - c).length()
    }

    #[test]
    fn lists_hold_exactly_the_voxels_each_sphere_touches() {
        let mut rng = crate::testing::Lcg::new(7);
        let mut next = || rng.uniform();
        let centers: Vec<DVec3> = (0..300)
            .map(|_| DVec3::new(next(), next(), next()) * 2.0 - 1.0)
            .collect();
        let radii: Vec<f64> = (0..300).map(|_| 0.02 + 0.3 * next()).collect();
        for size in [0.04, 0.1, 0.37] {
            let mut g = VoxelGrid::default();
            g.rebuild(&centers, &radii, size);
            let nvox = g.dims.iter().map(|&d| d as usize).product::<usize>();
            for v in 0..nvox {
                let list = &g.items[g.start[v] as usize..g.start[v + 1] as usize];
                assert!(list.windows(2).all(|w| w[0] < w[1]), "in primitive order");
                for (i, (c, r)) in centers.iter().zip(&radii).enumerate() {
                    let d = distance(&g, v, *c);
                    let listed = list.binary_search(&(i as u32)).is_ok();
                    if d <= *r {
                        assert!(
                            listed,
                            "voxel {v} misses primitive {i} (distance {d}, r {r})"
                        );
                    } else if listed {
                        assert!(d <= r * (1.0 + 1e-6), "voxel {v} lists far primitive {i}");
                    }
                }
            }
            // Point lookups land in the voxel whose box holds the point.
            for _ in 0..1000 {
                let p = DVec3::new(next(), next(), next()) * 2.6 - 1.3;
                let list = g.candidates(p);
                for (i, (c, r)) in centers.iter().zip(&radii).enumerate() {
                    if (p - *c).length() < *r {
                        assert!(list.contains(&(i as u32)), "point {p} misses primitive {i}");
                    }
                }
            }
        }
    }
}
