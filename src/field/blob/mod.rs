//! Blob fields of point primitives (Triquet et al. §4.2): the potential
//! F(p) = Σ A_i w(d_i/R_i), with w a compact profile ([`BlobKernel`]: by default Triquet's
//! (1 − q²)², else the SPH cubic spline or Wendland C2) that is 0 for d_i ≥ R_i, and the surface
//! F = threshold. The field the polygonizers see is `threshold − F`, negative inside. With the
//! default profile its gradient is −∇F = Σ (4A_i/R_i²)(1 − d_i²/R_i²)(p − c_i) (the paper's eq. 2
//! has the wrong factor and sign).
//!
//! Evaluation looks only at the primitives listed in the point's voxel ([`VoxelGrid`], built on
//! the first point query: the sparse polygonizer without normals never needs it). The
//! hand-written vector paths serve the default profile; the others run the generic loops.
//!
//! The field by phase: `build` makes and moves it, `point` answers point queries, `plane` splats
//! lattice values plane by plane (the dense polygonizer), `lists` says which primitives reach
//! which block, `signs` (with `interior`) proves blocks of one sign, `block` splats the values
//! of the others; `hints` and `kept` carry lists and proofs from one frame to the next, `single`
//! computes values in f32, `ellipsoids` the anisotropic kernels.

pub mod anisotropy;
mod block;
mod build;
pub mod densities;
pub mod ellipsoids;
mod hints;
mod interior;
mod kept;
pub mod kernel;
mod lists;
pub mod particles;
mod plane;
mod point;
mod signs;
mod single;
pub mod tiles;
pub mod voxels;

use block::BlockCoords;
pub use build::PerPrimitive;
use hints::Proof;
pub use lists::BlockLists;
use lists::{block_range, block_sides, layer_candidates, margin};
use point::map_points;
use signs::{both_signs, splatted_proof};
pub use single::Precision;

use super::{Block, BlockField, BlockSign, Field, BLOCK_POINTS};
use crate::field::blob::kernel::{with_profile, BlobKernel};
use crate::field::blob::voxels::VoxelGrid;
use crate::lattice::Lattice;
use crate::simd::Isa;
use glam::DVec3;
use rayon::prelude::*;
use std::ops::Range;
use std::sync::Arc;

/// Settings of a blob field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlobSettings {
    /// Voxel side as a multiple of the mean radius of influence (default 0.5; the trade-off
    /// is in `notebooks/triquet_blobs.ipynb`). Smaller voxels give evaluations fewer primitives
    /// to look at and the grid more list entries to hold.
    pub voxel_size: f64,
    /// The profile every primitive sums (default [`BlobKernel::Triquet`]).
    pub kernel: BlobKernel,
    /// The float type of the field's values (default [`Precision::Double`]): point queries,
    /// lattice values and block values all use it. Gradients are f64 in both.
    pub precision: Precision,
}

impl Default for BlobSettings {
    fn default() -> Self {
        BlobSettings {
            voxel_size: 0.5,
            kernel: BlobKernel::Triquet,
            precision: Precision::Double,
        }
    }
}

/// A blob field: point primitives with compact polynomial kernels.
#[derive(Clone, Debug, Default)]
pub struct BlobField {
    centers: Vec<DVec3>,
    radii: Vec<f64>,
    /// 1 / R² per primitive.
    inv_r2: Vec<f64>,
    strengths: Vec<f64>,
    /// The same numbers packed per primitive for point queries (one cache line each), built on
    /// the first point query ([`BlobField::packed`]) and refilled in place once built: block
    /// values and gradients read the arrays above.
    packed: std::sync::OnceLock<Vec<Packed>>,
    threshold: f64,
    settings: BlobSettings,
    /// The voxel lists, built by [`BlobField::grid`] on first use and rebuilt in place by
    /// [`BlobField::update`] once built.
    grid: std::sync::OnceLock<VoxelGrid>,
    /// Block lists kept from one polygonization to the next on the same lattice (an
    /// animation's frames): see the `kept` module.
    kept: kept::Kept,
    /// Ellipsoidal kernels (the `ellipsoids` module), when the field has them.
    shapes: Option<Arc<ellipsoids::Shapes>>,
}

/// One primitive as point queries read it.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(64))]
struct Packed {
    center: DVec3,
    /// 1 / R².
    inv_r2: f64,
    /// A.
    strength: f64,
}

impl BlobField {
    /// The primitives' centres.
    pub fn centers(&self) -> &[DVec3] {
        &self.centers
    }
    /// The primitives' radii (each primitive acts up to this distance from its centre).
    pub fn radii(&self) -> &[f64] {
        &self.radii
    }
    /// The primitives' strengths.
    pub fn strengths(&self) -> &[f64] {
        &self.strengths
    }
    /// The threshold: the surface is where the summed potential equals it.
    pub fn threshold(&self) -> f64 {
        self.threshold
    }
    /// The voxel lists of the primitives, built on the first call.
    pub fn grid(&self) -> &VoxelGrid {
        self.grid.get_or_init(|| {
            let mut grid = VoxelGrid::default();
            grid.rebuild(&self.centers, &self.radii, self.voxel_side());
            grid
        })
    }
    /// The settings the field was made with.
    pub fn settings(&self) -> BlobSettings {
        self.settings
    }
    /// Sets the precision of the field's values ([`BlobSettings::precision`]).
    pub fn set_precision(&mut self, precision: Precision) {
        self.settings.precision = precision;
    }

    /// Bounding box of the spheres of influence (None when there are no primitives).
    pub fn bounding_box(&self) -> Option<(DVec3, DVec3)> {
        if self.centers.is_empty() {
            return None;
        }
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for (c, r) in self.centers.iter().zip(&self.radii) {
            lo = lo.min(*c - DVec3::splat(*r));
            hi = hi.max(*c + DVec3::splat(*r));
        }
        Some((lo, hi))
    }
}

/// Block lists longer than this take the voxel lists for gradients, when they are built.
const LONG_BLOCK_LIST: usize = 64;

impl Field for BlobField {
    /// The primitives' centres, each walking at most its largest radius in cells, plus 2.
    fn starts(&self, cell: f64) -> Option<crate::field::Starts> {
        let rmax = self.radii().iter().fold(0.0f64, |a, r| a.max(*r));
        Some(crate::field::Starts {
            points: self.centers().to_vec(),
            max_walk: (rmax / cell).ceil() as u32 + 2,
        })
    }
    /// A blob field bounds its values over blocks of the lattice.
    fn block_field(&self) -> Option<&dyn crate::field::DynBlockField> {
        Some(self)
    }
    /// An upper bound on |∇f| over all space: one primitive's gradient is at most
    /// A·max|w′| / R (for the default profile at d = R/√3, where it is 8A / (3√3 R)); near any
    /// point only the primitives of its voxel list act, so the bound is the largest sum over one
    /// list. With this as the octree's safety factor, its rejection test never rejects a block
    /// the surface crosses.
    fn gradient_bound(&self) -> Option<f64> {
        if let Some(s) = &self.shapes {
            return Some(self.shaped_gradient_bound(s));
        }
        let k = self.settings.kernel.max_slope();
        Some(
            self.grid()
                .max_list_sum(|i| k * self.strengths[i as usize].abs() / self.radii[i as usize]),
        )
    }

    /// Splats every primitive into the lattice points of its sphere of influence, plane by plane
    /// in parallel, row by row over the x-range the sphere covers. Each point accumulates the
    /// primitives in index order with the same arithmetic as [`BlobField::potential`] (terms
    /// that do not reach the point add +0.0, which changes nothing), so the values are
    /// bit-identical to [`Field::values`].
    fn lattice_values(
        &self,
        lattice: &Lattice,
        z0: u32,
        z1: u32,
        _points: &mut Vec<DVec3>,
        out: &mut [f64],
    ) {
        self.splat_lattice(lattice, z0, z1, out)
    }

    #[inline]
    fn value(&self, p: DVec3) -> f64 {
        if let Some(s) = &self.shapes {
            return self.shaped_value(s, p);
        }
        match self.settings.precision {
            Precision::Double => self.threshold - self.potential(p),
            Precision::Single => {
                with_profile!(self.settings.kernel, K => self.value_single::<K>(p))
            }
        }
    }

    #[inline]
    fn gradient(&self, p: DVec3) -> DVec3 {
        self.gradient_at(p)
    }

    /// The batch loops call the point functions inlined: a call per point (the trait's default)
    /// costs as much as the terms themselves here.
    fn values(&self, points: &[DVec3], out: &mut [f64]) {
        if let Some(s) = &self.shapes {
            return map_points(points, out, |p| self.shaped_value(s, p));
        }
        match self.settings.precision {
            Precision::Double => {
                with_profile!(self.settings.kernel, K => map_points(points, out, |p| {
                    self.threshold - self.potential_with::<K>(p)
                }))
            }
            Precision::Single => {
                with_profile!(self.settings.kernel, K => map_points(points, out, |p| {
                    self.value_single::<K>(p)
                }))
            }
        }
    }

    fn gradients(&self, points: &[DVec3], out: &mut [DVec3]) {
        with_profile!(self.settings.kernel, K => map_points(points, out, |p| {
            self.gradient_over::<K>(self.grid().candidates(p), p)
        }));
    }
}

impl BlockField for BlobField {
    type Blocks = BlockLists;

    /// Lists, per block, the primitives whose sphere of influence reaches its box (with a
    /// relative margin of 1e-9 on R², so that rounding never leaves out a primitive that adds
    /// a non-zero term at one of its points). Built per z-layer of blocks in parallel, each
    /// layer from the primitives whose candidate layers hold it (`layer_candidates`).
    fn blocks(&self, lattice: &Lattice, dims: [u32; 3]) -> BlockLists {
        let mut lists = self.blocks_by_layers(lattice, dims);
        if lists.whole {
            return lists;
        }
        self.keep_layers(&mut lists, lattice, 0..dims[2]);
        lists.candidates = Default::default();
        lists
    }

    /// The candidates of each z-layer (4 bytes for each layer a primitive's sphere may reach),
    /// no lists yet.
    ///
    /// From the second call on one lattice on, the lists of every layer, kept for the next
    /// call and remade only where primitives moved far (the `kept` module).
    fn blocks_by_layers(&self, lattice: &Lattice, dims: [u32; 3]) -> BlockLists {
        if let Some((layers, hints)) = self.kept_lists(lattice, dims) {
            return BlockLists {
                dims,
                first: 0,
                layers,
                whole: true,
                candidates: Default::default(),
                hints: Some(hints),
            };
        }
        let candidates = layer_candidates(dims[2], self.centers.len(), |i| {
            block_range(lattice, dims, self.centers[i], margin(self.radii[i]), 2)
        });
        BlockLists {
            dims,
            first: 0,
            layers: Default::default(),
            whole: false,
            candidates,
            hints: None,
        }
    }

    /// Lists the blocks of `layers`, in parallel over the layers, after releasing the lists
    /// held (nothing to do when the lists hold every layer).
    fn keep_layers(&self, blocks: &mut BlockLists, lattice: &Lattice, layers: Range<u32>) {
        if blocks.whole {
            return;
        }
        blocks.layers = Default::default();
        blocks.first = layers.start;
        let dims = blocks.dims;
        let sides = block_sides(lattice, dims);
        let (start, candidates) = &blocks.candidates;
        let at = (&self.centers[..], 0.0);
        blocks.layers = Arc::new(
            layers
                .into_par_iter()
                .map(|bz| {
                    let here =
                        &candidates[start[bz as usize] as usize..start[bz as usize + 1] as usize];
                    self.layer_lists(lattice, dims, &sides, bz, here, at)
                })
                .collect(),
        );
    }

    /// Bounds F over the block from each listed primitive's nearest and farthest distance to
    /// the block's box; when the bounds leave the threshold out (by a margin of 1e-9 of the
    /// strengths' sum, far above rounding), the block has one sign.
    fn block_sign(&self, blocks: &BlockLists, lattice: &Lattice, block: &Block) -> BlockSign {
        self.block_sign_by(blocks, lattice, block, Proof::Unknown).0
    }

    /// The sign of [`BlockField::block_sign`] when it is one; otherwise splats the listed
    /// primitives row by row, with the same arithmetic and order as the dense splat. With lists
    /// kept between calls, the proof that settled the block in the last call goes first, and
    /// a block crossed then is splatted at once (the `hints` module).
    fn block_values(
        &self,
        blocks: &BlockLists,
        lattice: &Lattice,
        block: &Block,
        out: &mut [f64; 512],
    ) -> BlockSign {
        let Block { index: b, lo, n } = *block;
        let k = (b[0] + blocks.dims[0] * (b[1] + blocks.dims[1] * b[2])) as usize;
        let hint = blocks.hints.as_ref().map_or(Proof::Unknown, |h| h.get(k));
        let (sign, proof) = self.block_sign_by(blocks, lattice, block, hint);
        if sign == BlockSign::Mixed {
            let list = blocks.list(b);
            self.splat_block(Isa::detect(), list, &BlockCoords::new(lattice, lo, n), out);
        }
        if let Some(h) = &blocks.hints {
            h.set(k, splatted_proof(sign, proof, hint, || both_signs(out, n)));
        }
        sign
    }

    /// Eight points at a time over the block's list with AVX-512, four with AVX2 (the same
    /// operations in the same order as [`Field::gradient`], so the same bits).
    fn block_gradients(
        &self,
        blocks: &BlockLists,
        block: &Block,
        points: &[DVec3],
        out: &mut [DVec3],
    ) {
        let list = blocks.list(block.index);
        // A block much larger than the primitives (a coarse lattice) lists far more of them than
        // reach any one point: the voxel lists are shorter then (the same terms, the same bits),
        // when they are built (they are not built for this: at particle scale they take several
        // times the memory of the block lists).
        if list.len() > LONG_BLOCK_LIST && self.grid.get().is_some() {
            self.gradients(points, out);
            return;
        }
        self.gradients_over(Isa::detect(), list, points, out);
    }
}
