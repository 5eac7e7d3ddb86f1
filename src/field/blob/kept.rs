//! Block lists kept between polygonizations of one lattice, for animation: the field moves a
//! little ([`BlobField::update`]) and is polygonized again over the same blocks.
//!
//! From the second call on one lattice on, the lists of every z-layer of blocks are made for
//! each primitive at a reference position with its radius grown by a slack (an eighth of the
//! largest radius), and kept. A primitive within the slack of its reference position reaches
//! no block beyond those lists, so the lists still hold every primitive reaching each block (in
//! index order, with a few that reach nothing: their terms are zero, and the values, signs,
//! vertices and normals are those of the exact lists, bit for bit). Each later call moves the
//! reference of every primitive that went farther to where it is, and remakes the layers that
//! the old or the new grown sphere of such a primitive reaches; the other layers are kept as
//! they are. A change in the number of primitives or in a radius, or another lattice, makes
//! them all again.
//!
//! Lists are kept for fields of up to [`KEEP_PRIMITIVES`] primitives; the first call on a
//! lattice makes them as a one-off polygonization does (exact, a few layers at a time).

use super::{block_range, block_sides, layer_candidates, margin, BlobField, Layer};
use crate::lattice::Lattice;
use glam::DVec3;
use rayon::prelude::*;
use std::sync::{Arc, Mutex};

/// The slack of the kept lists, as a fraction of the largest radius.
const SLACK: f64 = 0.125;

/// Fields of more primitives keep no lists (their lists take hundreds of megabytes).
pub(super) const KEEP_PRIMITIVES: usize = 1 << 20;

/// The kept lists of a field, behind a lock (the polygonizers see the field by reference;
/// a call that finds it taken makes its own lists). A clone of a field keeps nothing.
#[derive(Default)]
pub(super) struct Kept(Mutex<KeptLists>);

impl Clone for Kept {
    fn clone(&self) -> Self {
        Kept::default()
    }
}

impl std::fmt::Debug for Kept {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Kept")
    }
}

/// What is kept.
#[derive(Default)]
struct KeptLists {
    /// The lattice and blocks per axis of the last call.
    on: Option<(Lattice, [u32; 3])>,
    /// The reference positions the lists were made from (empty: no lists yet).
    refs: Vec<DVec3>,
    /// The radii they were made with.
    radii: Vec<f64>,
    /// The slack of every radius.
    slack: f64,
    layers: Arc<Vec<Layer>>,
}

impl BlobField {
    /// The lists of every layer of the blocks `dims` of `lattice`, kept and brought up to date
    /// (see the module); `None` on the first call on a lattice, and for large fields.
    pub(super) fn kept_lists(&self, lattice: &Lattice, dims: [u32; 3]) -> Option<Arc<Vec<Layer>>> {
        let n = self.centers.len();
        if n == 0 || n > KEEP_PRIMITIVES {
            return None;
        }
        // Busy (another call on this field holds them): that call makes its lists as usual.
        let mut guard = self.kept.0.try_lock().ok()?;
        let k = &mut *guard;
        if k.on != Some((*lattice, dims)) {
            *k = KeptLists {
                on: Some((*lattice, dims)),
                ..Default::default()
            };
            return None;
        }
        let slack = SLACK * self.radii.iter().fold(0.0f64, |m, &r| m.max(r));
        let same_radii = k.radii.len() == n
            && k.radii
                .iter()
                .zip(&self.radii)
                .all(|(a, b)| a.to_bits() == b.to_bits());
        if k.refs.len() != n || !same_radii || k.slack != slack {
            k.refs.clear();
            k.refs.extend_from_slice(&self.centers);
            k.radii.clear();
            k.radii.extend_from_slice(&self.radii);
            k.slack = slack;
            k.layers = Arc::new(vec![Default::default(); dims[2] as usize]);
            let all = vec![true; dims[2] as usize];
            self.remake_layers(lattice, dims, k, &all);
        } else {
            let dirty = self.move_references(lattice, dims, k);
            if dirty.contains(&true) {
                self.remake_layers(lattice, dims, k, &dirty);
            }
        }
        Some(Arc::clone(&k.layers))
    }

    /// Moves the reference of each primitive farther than the slack from it to its position;
    /// returns the z-layers of blocks that its old or its new grown sphere may reach.
    fn move_references(&self, lattice: &Lattice, dims: [u32; 3], k: &mut KeptLists) -> Vec<bool> {
        let mut dirty = vec![false; dims[2] as usize];
        let s2 = k.slack * k.slack;
        let moved: Vec<usize> = (0..self.centers.len())
            .into_par_iter()
            .filter(|&i| (self.centers[i] - k.refs[i]).length_squared() > s2)
            .collect();
        for i in moved {
            let rm = margin(self.radii[i] + k.slack);
            for c in [k.refs[i], self.centers[i]] {
                for z in block_range(lattice, dims, c, rm, 2) {
                    dirty[z as usize] = true;
                }
            }
            k.refs[i] = self.centers[i];
        }
        dirty
    }

    /// Makes the lists of the layers marked `dirty` from the reference positions, in parallel
    /// over the layers.
    fn remake_layers(&self, lattice: &Lattice, dims: [u32; 3], k: &mut KeptLists, dirty: &[bool]) {
        let KeptLists {
            refs,
            slack,
            layers,
            ..
        } = k;
        let (refs, slack) = (&refs[..], *slack);
        let (start, candidates) = layer_candidates(dims[2], refs.len(), |i| {
            block_range(lattice, dims, refs[i], margin(self.radii[i] + slack), 2)
        });
        let sides = block_sides(lattice, dims);
        Arc::make_mut(layers)
            .par_iter_mut()
            .enumerate()
            .filter(|(z, _)| dirty[*z])
            .for_each(|(z, layer)| {
                let here = &candidates[start[z] as usize..start[z + 1] as usize];
                *layer = self.layer_lists(lattice, dims, &sides, z as u32, here, (refs, slack));
            });
    }
}

#[cfg(test)]
mod tests {
    use crate::field::blob::{BlobField, BlobSettings, PerPrimitive, Precision};
    use crate::lattice::Lattice;
    use crate::polygonize::{sparse, Settings};
    use glam::{DVec3, Vec3Swizzles};

    /// Particles on a jittered lattice of spacing 0.1: a slab and a ball above it.
    fn particles() -> Vec<DVec3> {
        let mut state = 12345u64;
        let mut jitter = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.02
        };
        let mut p = Vec::new();
        for i in 0..16 {
            for j in 0..16 {
                for k in 0..4 {
                    let q = DVec3::new(i as f64, j as f64, k as f64) * 0.1;
                    p.push(q + DVec3::new(jitter(), jitter(), jitter()));
                }
            }
        }
        for i in -3i32..=3 {
            for j in -3i32..=3 {
                for k in -3i32..=3 {
                    if i * i + j * j + k * k <= 9 {
                        let q = DVec3::new(
                            0.8 + i as f64 * 0.1,
                            0.8 + j as f64 * 0.1,
                            1.0 + k as f64 * 0.1,
                        );
                        p.push(q + DVec3::new(jitter(), jitter(), jitter()));
                    }
                }
            }
        }
        p
    }

    /// Frame `k`: the ball fallen by 0.03 k², every particle moved by a smooth wave.
    fn frame(p0: &[DVec3], k: usize, ball_from: usize) -> Vec<DVec3> {
        let t = k as f64;
        p0.iter()
            .enumerate()
            .map(|(i, &p)| {
                let fall = if i >= ball_from { 0.03 * t * t } else { 0.0 };
                let w = (p.yzx() * 7.0 + DVec3::splat(0.4 * t))
                    .to_array()
                    .map(f64::sin);
                p - DVec3::new(0.0, 0.0, fall) + DVec3::from_array(w) * 0.004
            })
            .collect()
    }

    fn field(p: &[DVec3], precision: Precision) -> BlobField {
        let settings = BlobSettings {
            precision,
            ..Default::default()
        };
        BlobField::new(
            p,
            PerPrimitive::All(0.2),
            PerPrimitive::All(1.0),
            0.9,
            settings,
        )
        .unwrap()
    }

    /// Every frame of a field moved in place (its lists kept, remade in part) has the mesh of a
    /// new field of the frame's particles, array for array and bit for bit, in both precisions,
    /// with and without normals; lists kept over frames where nothing moved far, and where
    /// the ball fell past the slack, and remade when the number of particles changes.
    #[test]
    fn frames_of_a_field_moved_in_place_are_those_of_new_fields() {
        let p0 = particles();
        let ball_from = 16 * 16 * 4;
        let lattice = Lattice::new(
            DVec3::new(-0.3, -0.3, -0.3),
            DVec3::new(1.8, 1.8, 1.5),
            [70, 70, 60],
        )
        .unwrap();
        for precision in [Precision::Double, Precision::Single] {
            for normals in [false, true] {
                let settings = Settings {
                    normals,
                    ..Default::default()
                };
                let mut moving = field(&p0, precision);
                let mut kept = 0;
                for k in 0..8 {
                    let mut p = frame(&p0, k, ball_from);
                    if k >= 6 {
                        p.truncate(p.len() - 5);
                    }
                    if k == 6 {
                        let r = vec![0.2; p.len()];
                        let (r, a) = (PerPrimitive::Each(&r), PerPrimitive::All(1.0));
                        moving.update(&p, Some(r), Some(a)).unwrap();
                    } else {
                        moving.update(&p, None, None).unwrap();
                    }
                    let (got, _) = sparse::polygonize(&moving, &lattice, &settings).unwrap();
                    let (want, _) =
                        sparse::polygonize(&field(&p, precision), &lattice, &settings).unwrap();
                    assert!(!want.triangles.is_empty());
                    assert_eq!(got.triangles, want.triangles, "frame {k}");
                    let bits = |v: &[DVec3]| {
                        v.iter()
                            .map(|q| q.to_array().map(f64::to_bits))
                            .collect::<Vec<_>>()
                    };
                    assert_eq!(bits(&got.vertices), bits(&want.vertices), "frame {k}");
                    assert_eq!(bits(&got.normals), bits(&want.normals), "frame {k}");
                    kept += moving.kept.0.lock().unwrap().refs.len().min(1);
                }
                // Kept from the second frame on.
                assert_eq!(kept, 7);
            }
        }
    }
}
