//! Which primitives reach which block ([`BlockLists`]): one compressed list per z-layer of
//! blocks, made from the primitives that may reach the layer (`layer_candidates`) by the exact
//! sphere-box test of [`blocks_reached`], with a relative margin on each radius so that
//! rounding never leaves out a primitive that adds a non-zero term.

use super::hints::Hints;
use super::BlobField;
use crate::field::BLOCK_POINTS;
use crate::lattice::Lattice;
use glam::DVec3;
use std::ops::Range;
use std::sync::Arc;

/// Which primitives reach which block of a lattice (for [`BlockField`](crate::field::BlockField)): one compressed list per
/// z-layer of blocks, each block's primitives in index order; all layers
/// ([`BlockField::blocks`](crate::field::BlockField::blocks)) or a few at a time ([`BlockField::keep_layers`](crate::field::BlockField::keep_layers)).
pub struct BlockLists {
    /// Blocks per axis.
    pub(super) dims: [u32; 3],
    /// The z-layer of `layers[0]`.
    pub(super) first: u32,
    /// Per z-layer from `first`: `start` (one more than the layer's blocks) and `items`
    /// (shared with the lists the `kept` module keeps between calls, when they are those).
    pub(super) layers: Arc<Vec<Layer>>,
    /// Whether `layers` holds every z-layer ([`BlockField::keep_layers`](crate::field::BlockField::keep_layers) then keeps them all).
    pub(super) whole: bool,
    /// The primitives that may reach each z-layer (`layer_candidates`), kept while layers are
    /// still to be listed (empty once every layer is).
    pub(super) candidates: (Vec<u32>, Vec<u32>),
    /// How each block's sign was found in the last call, with lists kept between calls.
    pub(super) hints: Option<Arc<Hints>>,
}

impl BlockLists {
    /// The primitives that may reach block `b` (in a layer held), in index order.
    #[inline]
    pub fn list(&self, b: [u32; 3]) -> &[u32] {
        let (start, items) = &self.layers[(b[2] - self.first) as usize];
        let k = (b[0] + self.dims[0] * b[1]) as usize;
        &items[start[k] as usize..start[k + 1] as usize]
    }

    /// Total entries over the lists held.
    pub fn entries(&self) -> usize {
        self.layers.iter().map(|(_, i)| i.len()).sum()
    }

    /// Bytes held (capacities).
    pub fn bytes(&self) -> usize {
        let words = self.layers.iter().map(|(s, i)| s.capacity() + i.capacity());
        4 * (words.sum::<usize>() + self.candidates.0.capacity() + self.candidates.1.capacity())
    }
}

/// The lists of one z-layer of blocks: `start` (one more than the layer's blocks) and `items`.
pub(super) type Layer = (Vec<u32>, Vec<u32>);

impl BlobField {
    /// The lists of z-layer `bz` of blocks (`start`, one more than the layer's blocks, and
    /// `items`) from the primitives `here` that may reach it, each at its position in
    /// `centers` with its radius grown by `slack`; `sides` are the blocks' box coordinates per
    /// axis.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn layer_lists(
        &self,
        lattice: &Lattice,
        dims: [u32; 3],
        sides: &[Vec<(f64, f64)>; 3],
        bz: u32,
        here: &[u32],
        (centers, slack): (&[DVec3], f64),
    ) -> Layer {
        let per_layer = (dims[0] * dims[1]) as usize;
        let mut pairs: Vec<(u32, u32)> = Vec::new();
        for &i in here {
            let (c, rm) = (centers[i as usize], margin(self.radii[i as usize] + slack));
            blocks_reached(lattice, dims, sides, bz, (c, rm), |k| pairs.push((k, i)));
        }
        // Counting sort by block, stable: each list stays in index order.
        let mut start = vec![0u32; per_layer + 1];
        for &(k, _) in &pairs {
            start[k as usize + 1] += 1;
        }
        for k in 0..per_layer {
            start[k + 1] += start[k];
        }
        let mut items = vec![0u32; pairs.len()];
        let mut cursor = start.clone();
        for &(k, i) in &pairs {
            items[cursor[k as usize] as usize] = i;
            cursor[k as usize] += 1;
        }
        (start, items)
    }
}

/// The primitives per z-layer of blocks, in index order, as compressed rows (`start` has one
/// more entry than there are `layers`): primitive i in every layer of `layers_of(i)`, a range
/// holding every layer its sphere may reach.
pub(super) fn layer_candidates(
    layers: u32,
    primitives: usize,
    layers_of: impl Fn(usize) -> std::ops::Range<u32>,
) -> (Vec<u32>, Vec<u32>) {
    let mut start = vec![0u32; layers as usize + 1];
    for i in 0..primitives {
        for z in layers_of(i) {
            start[z as usize + 1] += 1;
        }
    }
    for z in 0..layers as usize {
        start[z + 1] += start[z];
    }
    let mut cursor = start.clone();
    let mut items = vec![0u32; start[layers as usize] as usize];
    for i in 0..primitives {
        for z in layers_of(i) {
            items[cursor[z as usize] as usize] = i as u32;
            cursor[z as usize] += 1;
        }
    }
    (start, items)
}

/// Calls `reached(bx + dims[0]·by)` for each block of z-layer `bz` whose box the sphere at `c`
/// of radius `rm` reaches (the test every block list is made with), in ascending order; `sides`
/// are the blocks' box coordinates per axis ([`block_sides`]).
#[inline]
pub(super) fn blocks_reached(
    lattice: &Lattice,
    dims: [u32; 3],
    sides: &[Vec<(f64, f64)>; 3],
    bz: u32,
    (c, rm): (DVec3, f64),
    mut reached: impl FnMut(u32),
) {
    let (zlo, zhi) = sides[2][bz as usize];
    if c.z + rm < zlo || c.z - rm > zhi {
        return;
    }
    let xs = block_range(lattice, dims, c, rm, 0);
    let ys = block_range(lattice, dims, c, rm, 1);
    let r2 = rm * rm;
    // The squared distance to each block's box as `box_distances2` sums it, (x² + y²) + z²,
    // from the gaps per axis; a row whose y² + z² exceeds r² has no block within reach (the
    // rounded sums are monotone).
    let gz2 = gap2(c.z, sides[2][bz as usize]);
    for by in ys {
        let gy2 = gap2(c.y, sides[1][by as usize]);
        if gy2 + gz2 > r2 {
            continue;
        }
        for bx in xs.clone() {
            let gx2 = gap2(c.x, sides[0][bx as usize]);
            if (gx2 + gy2) + gz2 <= r2 {
                reached(bx + dims[0] * by);
            }
        }
    }
}

/// Candidate blocks along axis `a` for a sphere at `c` of radius `rm` (one more on each side
/// for rounding), for the exact sphere-box test; `dims` blocks per axis.
pub(super) fn block_range(
    lattice: &Lattice,
    dims: [u32; 3],
    c: DVec3,
    rm: f64,
    a: usize,
) -> Range<u32> {
    let span = lattice.cell()[a] * (BLOCK_POINTS - 1) as f64;
    let lo = floor((c[a] - rm - lattice.origin()[a]) / span) - 1.0;
    let hi = floor((c[a] + rm - lattice.origin()[a]) / span) + 1.0;
    let hi = hi.min((dims[a] - 1) as f64);
    if hi < 0.0 || lo > hi {
        return 0..0;
    }
    lo.max(0.0) as u32..hi as u32 + 1
}

/// The lowest and highest coordinate of the blocks' boxes per axis ([`block_box`]).
pub(super) fn block_sides(lattice: &Lattice, dims: [u32; 3]) -> [Vec<(f64, f64)>; 3] {
    std::array::from_fn(|a| {
        (0..dims[a])
            .map(|k| {
                let (lo, hi) = block_box(lattice, [k; 3]);
                (lo[a], hi[a])
            })
            .collect()
    })
}

/// Box of the lattice points of a block: its lowest point and its highest.
pub(super) fn block_box(lattice: &Lattice, b: [u32; 3]) -> (DVec3, DVec3) {
    let step = (BLOCK_POINTS - 1) as u32;
    let last = lattice.cells();
    let lo = [b[0] * step, b[1] * step, b[2] * step];
    let hi = std::array::from_fn(|a| (lo[a] + step).min(last[a]));
    (lattice.point(lo), lattice.point(hi))
}

/// The squared gap between `c` and the interval `(lo, hi)` along one axis, as
/// [`box_distances2`](super::signs::box_distances2) computes it (0 inside).
#[inline(always)]
fn gap2(c: f64, (lo, hi): (f64, f64)) -> f64 {
    let g = (lo - c).max(c - hi).max(0.0);
    g * g
}

/// A primitive's radius with the relative margin every block-list test uses.
#[inline(always)]
pub(super) fn margin(r: f64) -> f64 {
    r * (1.0 + 1e-9)
}

/// `x.floor()`, inlined (the baseline x86-64 target has no rounding instruction, and `floor`
/// is then a call into the C library): the truncation of `x`, less one below a negative
/// non-integer. Values of 2⁵² and more in magnitude (integers), and NaN, go to `f64::floor`.
#[inline(always)]
pub(super) fn floor(x: f64) -> f64 {
    if x.abs() < 4_503_599_627_370_496.0 {
        let t = x as i64 as f64;
        if t > x {
            t - 1.0
        } else {
            t
        }
    } else {
        x.floor()
    }
}

/// `x.ceil()`, inlined as [`floor`] is: −floor(−x).
#[inline(always)]
pub(super) fn ceil(x: f64) -> f64 {
    -floor(-x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::blob::kernel::BlobKernel;
    use crate::field::BlockField;
    use crate::lattice::Lattice;
    use crate::testing::sized_blobs;

    #[test]
    fn inlined_floor_and_ceil_are_the_library_ones() {
        let mut xs = vec![
            0.0, -0.0, 0.5, -0.5, 1.0, -1.0, 2.5, -2.5, 1e300, -1e300, 4.5e15,
        ];
        xs.extend([
            f64::MAX,
            f64::MIN,
            4_503_599_627_370_495.5,
            -4_503_599_627_370_495.5,
        ]);
        xs.extend((0..2000).map(|k| (k as f64 - 1000.0) * 0.37 + 1e-9 * k as f64));
        for x in xs {
            assert_eq!(floor(x), x.floor(), "{x}");
            assert_eq!(ceil(x), x.ceil(), "{x}");
        }
        assert!(floor(f64::NAN).is_nan());
    }

    /// Lists made a few z-layers at a time are the lists of the whole lattice, layer for
    /// layer, and only the layers asked for (and the candidates) are held.
    #[test]
    fn lists_by_layers_are_the_whole_lists() {
        let b = sized_blobs(300, 5, BlobKernel::Triquet);
        let l = Lattice::new(DVec3::splat(-1.0), DVec3::splat(1.0), [45, 38, 100]).unwrap();
        let dims = crate::polygonize::sparse::block_grid(&l).dims;
        // On a clone (which keeps no lists): a second call on the same field and lattice would
        // get the kept lists of every layer.
        let whole = b.clone().blocks(&l, dims);
        assert!(whole.candidates.1.is_empty());
        let mut lists = b.blocks_by_layers(&l, dims);
        assert_eq!(lists.entries(), 0);
        for layers in [0..3, 3..4, 4..dims[2], 7..9] {
            b.keep_layers(&mut lists, &l, layers.clone());
            assert_eq!(lists.layers.len(), layers.len());
            if layers.len() == 1 {
                assert!(lists.bytes() < whole.bytes());
            }
            let mut entries = 0;
            for z in layers {
                for (x, y) in (0..dims[0]).flat_map(|x| (0..dims[1]).map(move |y| (x, y))) {
                    assert_eq!(lists.list([x, y, z]), whole.list([x, y, z]));
                    entries += whole.list([x, y, z]).len();
                }
            }
            assert!(entries > 0);
            assert_eq!(lists.entries(), entries);
        }
    }
}
