//! Block lists kept between polygonizations of one lattice, for animation: the field moves a
//! little ([`BlobField::update`]) and is polygonized again over the same blocks.
//!
//! From the second call on one lattice on, the lists of every z-layer of blocks are made for
//! each primitive at a reference position with its radius grown by a slack (an eighth of the
//! largest radius), and kept. A primitive within the slack of its reference position reaches
//! no block beyond those lists, so the lists still hold every primitive reaching each block (in
//! index order, with a few that reach nothing: their terms are zero, and the values, signs,
//! vertices and normals are those of the exact lists, bit for bit). Each later call moves the
//! reference of every primitive that went farther to where it is. When at most one primitive
//! in [`RELIST_ABOVE`] did, the blocks the old or the new grown sphere of such a primitive
//! reaches are relisted (their old list without the moved primitives, merged with those that
//! reach them now); when more did, the z-layers those spheres reach are made again from every
//! primitive. The other blocks keep their lists. A change in the number of primitives or in a
//! radius, or another lattice, makes them all again.
//!
//! Beside the lists, the proof that settled each block's sign in the last call (the `hints`
//! module), which the next call tries first.
//!
//! Lists are kept for fields of up to [`KEEP_PRIMITIVES`] primitives; the first call on a
//! lattice makes them as a one-off polygonization does (exact, a few layers at a time).

use super::hints::Hints;
use super::lists::{block_range, block_sides, blocks_reached, layer_candidates, margin, Layer};
use super::BlobField;
use crate::lattice::Lattice;
use glam::DVec3;
use rayon::prelude::*;
use std::sync::{Arc, Mutex};

/// The slack of the kept lists, as a fraction of the largest radius.
const SLACK: f64 = 0.125;

/// When more than one primitive in this many moved beyond the slack, the layers they reach are
/// remade from all primitives; fewer, the blocks they reach are relisted from their old lists.
const RELIST_ABOVE: usize = 4;

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
    /// The proofs of the blocks' signs in the last call.
    hints: Arc<Hints>,
}

impl BlobField {
    /// The lists of every layer of the blocks `dims` of `lattice`, kept and brought up to date
    /// (see the module), and the blocks' proofs in the last call (the `hints` module); `None`
    /// on the first call on a lattice, and for large fields.
    pub(super) fn kept_lists(
        &self,
        lattice: &Lattice,
        dims: [u32; 3],
    ) -> Option<(Arc<Vec<Layer>>, Arc<Hints>)> {
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
            let blocks = dims.iter().map(|&d| d as usize).product();
            if k.hints.len() != blocks {
                k.hints = Arc::new(Hints::new(blocks));
            }
            let all = vec![true; dims[2] as usize];
            self.remake_layers(lattice, dims, k, &all);
        } else {
            let moved = self.moved_primitives(k);
            if moved.len() > n / RELIST_ABOVE {
                let dirty = self.move_references(lattice, dims, k, &moved);
                self.remake_layers(lattice, dims, k, &dirty);
            } else if !moved.is_empty() {
                self.relist_blocks(lattice, dims, k, &moved);
            }
        }
        Some((Arc::clone(&k.layers), Arc::clone(&k.hints)))
    }

    /// The primitives farther than the slack from their reference position, in index order.
    fn moved_primitives(&self, k: &KeptLists) -> Vec<usize> {
        let s2 = k.slack * k.slack;
        (0..self.centers.len())
            .into_par_iter()
            .with_min_len(4096)
            .filter(|&i| (self.centers[i] - k.refs[i]).length_squared() > s2)
            .collect()
    }

    /// Moves the reference of each primitive of `moved` to its position; returns the z-layers
    /// of blocks that its old or its new grown sphere may reach.
    fn move_references(
        &self,
        lattice: &Lattice,
        dims: [u32; 3],
        k: &mut KeptLists,
        moved: &[usize],
    ) -> Vec<bool> {
        let mut dirty = vec![false; dims[2] as usize];
        for &i in moved {
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

    /// Moves the reference of each primitive of `moved` (in index order) to its position and
    /// brings the lists of the blocks its old or its new grown sphere reaches up to date: each
    /// such block's list without the moved primitives, merged with those whose new sphere
    /// reaches it (the same test as [`BlobField::layer_lists`], so the lists a remake would
    /// make); the other blocks' lists are copied. In parallel over the z-layers changed.
    fn relist_blocks(&self, lattice: &Lattice, dims: [u32; 3], k: &mut KeptLists, moved: &[usize]) {
        let per_layer = (dims[0] * dims[1]) as usize;
        let sides = block_sides(lattice, dims);
        let mut dirty = vec![false; per_layer * dims[2] as usize];
        let mut is_moved = vec![false; self.centers.len()];
        // (block, primitive) for each block a moved primitive's new sphere reaches.
        let mut entrants: Vec<(u32, u32)> = Vec::new();
        for &i in moved {
            let rm = margin(self.radii[i] + k.slack);
            let (old, new) = (k.refs[i], self.centers[i]);
            for z in block_range(lattice, dims, old, rm, 2) {
                let first = z as usize * per_layer;
                blocks_reached(lattice, dims, &sides, z, (old, rm), |b| {
                    dirty[first + b as usize] = true;
                });
            }
            for z in block_range(lattice, dims, new, rm, 2) {
                let first = z as usize * per_layer;
                blocks_reached(lattice, dims, &sides, z, (new, rm), |b| {
                    dirty[first + b as usize] = true;
                    entrants.push(((first + b as usize) as u32, i as u32));
                });
            }
            k.refs[i] = new;
            is_moved[i] = true;
        }
        // Stable: each block's entrants stay in index order.
        entrants.sort_by_key(|&(b, _)| b);
        let (dirty, is_moved, entrants) = (&dirty[..], &is_moved[..], &entrants[..]);
        Arc::make_mut(&mut k.layers)
            .par_iter_mut()
            .enumerate()
            .filter(|(z, _)| dirty[z * per_layer..(z + 1) * per_layer].contains(&true))
            .for_each(|(z, layer)| {
                let first = z * per_layer;
                let from = entrants.partition_point(|&(b, _)| (b as usize) < first);
                let to = entrants.partition_point(|&(b, _)| (b as usize) < first + per_layer);
                let here = (&dirty[first..first + per_layer], &entrants[from..to]);
                *layer = relist_layer(layer, first as u32, here, is_moved);
            });
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

/// The lists of a z-layer of blocks (`first`: the number of its first block) after a
/// relisting ([`BlobField::relist_blocks`]): the blocks marked in `dirty` lose the primitives
/// marked in `is_moved` and gain their `entrants` (ascending by block, each block's in index
/// order); the others keep their lists.
fn relist_layer(
    (start, items): &Layer,
    first: u32,
    (dirty, entrants): (&[bool], &[(u32, u32)]),
    is_moved: &[bool],
) -> Layer {
    let mut new_start = Vec::with_capacity(start.len());
    let mut new_items = Vec::with_capacity(items.len() + entrants.len());
    new_start.push(0u32);
    let mut e = 0;
    for (b, &changed) in dirty.iter().enumerate() {
        let old = &items[start[b] as usize..start[b + 1] as usize];
        if changed {
            let end = e + entrants[e..].partition_point(|&(g, _)| g == first + b as u32);
            let mut gained = entrants[e..end].iter().map(|&(_, i)| i).peekable();
            for &i in old.iter().filter(|&&i| !is_moved[i as usize]) {
                while let Some(j) = gained.next_if(|&j| j < i) {
                    new_items.push(j);
                }
                new_items.push(i);
            }
            new_items.extend(gained);
            e = end;
        } else {
            new_items.extend_from_slice(old);
        }
        new_start.push(new_items.len() as u32);
    }
    debug_assert_eq!(e, entrants.len());
    (new_start, new_items)
}

#[cfg(test)]
mod tests {
    use crate::field::blob::{BlobField, BlobSettings, PerPrimitive, Precision};
    use crate::lattice::Lattice;
    use crate::polygonize::{sparse, Settings};
    use glam::{DVec3, Vec3Swizzles};
    use std::sync::Arc;

    /// Particles on a jittered lattice of spacing 0.1: a slab and a ball above it.
    fn particles() -> Vec<DVec3> {
        let mut rng = crate::testing::Lcg::new(12345);
        let mut jitter = move || (rng.uniform() - 0.5) * 0.02;
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

    fn lattice() -> Lattice {
        Lattice::new(
            DVec3::new(-0.3, -0.3, -0.3),
            DVec3::new(1.8, 1.8, 1.5),
            [70, 70, 60],
        )
        .unwrap()
    }

    /// Asserts that the sparse mesh of `moving` is that of a new field of the particles `p` (in
    /// its precision), array for array and bit for bit, and not empty.
    fn assert_mesh_of_a_new_field(
        moving: &BlobField,
        p: &[DVec3],
        lattice: &Lattice,
        settings: &Settings,
        k: usize,
    ) {
        let crate::polygonize::Polygonized {
            mesh: got,
            stats: _,
            ..
        } = sparse::polygonize(moving, lattice, settings).unwrap();
        let fresh = field(p, moving.settings().precision);
        let crate::polygonize::Polygonized {
            mesh: want,
            stats: _,
            ..
        } = sparse::polygonize(&fresh, lattice, settings).unwrap();
        assert!(!want.triangles.is_empty());
        assert_eq!(got.triangles, want.triangles, "frame {k}");
        let bits = |v: &[DVec3]| {
            v.iter()
                .map(|q| q.to_array().map(f64::to_bits))
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(&got.vertices), bits(&want.vertices), "frame {k}");
        assert_eq!(bits(&got.normals), bits(&want.normals), "frame {k}");
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
        let lattice = lattice();
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
                    assert_mesh_of_a_new_field(&moving, &p, &lattice, &settings, k);
                    kept += moving.kept.0.lock().unwrap().refs.len().min(1);
                }
                // Kept from the second frame on.
                assert_eq!(kept, 7);
            }
        }
    }

    /// The lists relisted block by block (few primitives moved far) are those that making every
    /// layer again from the same reference positions gives, entry for entry: over frames where
    /// a few primitives jump across the lattice, leave it, come back into it, and move within
    /// the slack; and where many move (the layers remade).
    #[test]
    fn relisted_blocks_are_the_lists_made_again() {
        use super::KeptLists;
        let p0 = particles();
        let n = p0.len();
        let lattice = lattice();
        let dims = crate::polygonize::sparse::block_grid(&lattice).dims;
        let mut f = field(&p0, Precision::Double);
        let mut p = p0.clone();
        let mut relisted = 0;
        for k in 0..10usize {
            for (i, q) in p.iter_mut().enumerate() {
                let s = (i * 7 + k * 13) % 101;
                *q += match (k, s) {
                    // Far out of the lattice and back in.
                    (3, 0..=4) => DVec3::new(0.0, 0.0, 9.0),
                    (4, 0..=4) => DVec3::new(0.0, 0.0, -9.0),
                    // Across the lattice.
                    (_, 5..=9) => {
                        DVec3::new(0.37, -0.21, 0.11) * if k % 2 == 0 { 1.0 } else { -1.0 }
                    }
                    // Within the slack, or everything at frame 8.
                    _ if k == 8 => DVec3::new(0.05, 0.0, 0.0),
                    _ => DVec3::new(0.001, -0.002, 0.0015),
                };
            }
            f.update(&p, None, None).unwrap();
            let moved = {
                let k = f.kept.0.lock().unwrap();
                let s2 = k.slack * k.slack;
                (0..n)
                    .filter(|&i| !k.refs.is_empty() && (p[i] - k.refs[i]).length_squared() > s2)
                    .count()
            };
            if moved > 0 && moved <= n / super::RELIST_ABOVE {
                relisted += 1;
            }
            let layers = f.kept_lists(&lattice, dims);
            if k == 0 {
                assert!(layers.is_none());
                continue;
            }
            let kept = layers.unwrap().0;
            let guard = f.kept.0.lock().unwrap();
            let mut again = KeptLists {
                on: guard.on,
                refs: guard.refs.clone(),
                radii: guard.radii.clone(),
                slack: guard.slack,
                layers: Arc::new(vec![Default::default(); dims[2] as usize]),
                hints: Default::default(),
            };
            drop(guard);
            f.remake_layers(&lattice, dims, &mut again, &vec![true; dims[2] as usize]);
            assert!(kept.iter().map(|l| l.1.len()).sum::<usize>() > 0);
            assert!(*kept == *again.layers, "frame {k}");
        }
        assert!(relisted >= 6, "{relisted}");
    }

    /// Hints that no longer fit (the particles moved far between frames: blocks crossed in the
    /// last frame are now inside or outside, and blocks proved inside or outside are now crossed)
    /// give the mesh of a new field, bit for bit, in both precisions; after a frame, blocks of
    /// every kind of hint are recorded.
    #[test]
    fn stale_hints_give_the_meshes_of_new_fields() {
        use crate::field::blob::hints::Proof;
        let p0 = particles();
        let ball_from = 16 * 16 * 4;
        let lattice = lattice();
        // (every particle, the ball too): all moved by half a block and more, then the ball
        // alone far across, into the slab, and back.
        let z = DVec3::ZERO;
        let moves = [
            (z, z),
            (z, z),
            (DVec3::new(0.08, 0.05, -0.09), z),
            (z, DVec3::new(-0.6, -0.5, 0.0)),
            (z, DVec3::new(0.0, 0.0, -0.8)),
            (z, DVec3::new(0.05, 0.05, -0.8)),
            (z, z),
        ];
        for precision in [Precision::Double, Precision::Single] {
            let mut moving = field(&p0, precision);
            for (k, &(all, ball)) in moves.iter().enumerate() {
                let mut p = p0.clone();
                for (i, q) in p.iter_mut().enumerate() {
                    *q += all + if i >= ball_from { ball } else { z };
                }
                moving.update(&p, None, None).unwrap();
                assert_mesh_of_a_new_field(&moving, &p, &lattice, &Settings::default(), k);
                if k >= 1 {
                    let kept = moving.kept.0.lock().unwrap();
                    let hints: Vec<Proof> =
                        (0..kept.hints.len()).map(|b| kept.hints.get(b)).collect();
                    let all = [Proof::Pairs, Proof::Octants, Proof::Crossed];
                    for proof in [Proof::Unknown].into_iter().chain(all) {
                        assert!(hints.contains(&proof), "frame {k}: no {proof:?}");
                    }
                    assert!(
                        hints.iter().any(|h| matches!(h, Proof::OneSign { .. })),
                        "frame {k}: no OneSign"
                    );
                }
            }
        }
    }
}
