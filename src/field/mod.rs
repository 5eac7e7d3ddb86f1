//! Scalar fields whose zero set is the surface: negative inside, positive outside.
//!
//! Every polygonizer takes a [`Field`]. Batched evaluation ([`Field::values`]) is the hot path: the
//! polygonizers gather the points they need into batches and call it from the thread that called
//! them (never from inside a rayon worker), so a field may itself split a batch over rayon — and a
//! field backed by a foreign runtime (the Python binding's callable field) may lock that runtime.
//!
//! A field also says where surface tracking may start ([`Field::starts`]) and whether it bounds
//! its values over blocks of the lattice ([`Field::block_field`], a [`BlockField`]): the
//! polygonizers take these decisions from the field. The wrappers (`&F`, [`Counting`]) forward
//! every method of the trait; [`Differences`] replaces the gradients and forwards the rest but
//! the gradient bound and the block bounds, which are not those of its gradients.

pub mod analytic;
pub mod blob;
pub mod differences;
pub mod rbf;
pub mod scan;

use crate::lattice::Lattice;
use glam::DVec3;
use rayon::prelude::*;
use std::ops::Range;

pub use differences::Differences;

/// Points per rayon task in the default batched implementations.
pub const PAR_CHUNK: usize = 512;

/// A scalar field over 3-D space, negative inside the surface and positive outside.
pub trait Field: Sync {
    /// Value at one point.
    fn value(&self, p: DVec3) -> f64;

    /// Gradient at one point. The default uses central differences with step [`Field::fd_step`].
    fn gradient(&self, p: DVec3) -> DVec3 {
        let h = self.fd_step();
        let d = |e: DVec3| (self.value(p + e * h) - self.value(p - e * h)) / (2.0 * h);
        DVec3::new(d(DVec3::X), d(DVec3::Y), d(DVec3::Z))
    }

    /// Step used by finite-difference gradients.
    fn fd_step(&self) -> f64 {
        1e-6
    }

    /// An upper bound of |∇f| over all space, where the field knows one (`None`: unknown). The
    /// octree's default safety factor is derived from it.
    fn gradient_bound(&self) -> Option<f64> {
        None
    }

    /// Values at many points: `out[i] = value(points[i])`. The default splits the batch over rayon.
    fn values(&self, points: &[DVec3], out: &mut [f64]) {
        assert_eq!(points.len(), out.len());
        points
            .par_chunks(PAR_CHUNK)
            .zip(out.par_chunks_mut(PAR_CHUNK))
            .for_each(|(p, o)| {
                for (pi, oi) in p.iter().zip(o.iter_mut()) {
                    *oi = self.value(*pi);
                }
            });
    }

    /// Gradients at many points. The default splits the batch over rayon.
    fn gradients(&self, points: &[DVec3], out: &mut [DVec3]) {
        assert_eq!(points.len(), out.len());
        points
            .par_chunks(PAR_CHUNK)
            .zip(out.par_chunks_mut(PAR_CHUNK))
            .for_each(|(p, o)| {
                for (pi, oi) in p.iter().zip(o.iter_mut()) {
                    *oi = self.gradient(*pi);
                }
            });
    }

    /// Values and gradients at many points. The default calls [`Field::values`], then
    /// [`Field::gradients`]; fields that compute both at once override it.
    fn values_gradients(&self, points: &[DVec3], values: &mut [f64], gradients: &mut [DVec3]) {
        self.values(points, values);
        self.gradients(points, gradients);
    }

    /// Field values that one point of [`Field::values_gradients`] costs, as evaluation counts
    /// report them: 1 by default, 7 for central differences of values ([`Differences`]).
    fn values_per_value_gradient(&self) -> u64 {
        1
    }

    /// Field values that one point of [`Field::gradients`] costs, as evaluation counts report
    /// them: 1 by default, 6 for central differences of values ([`Differences`]).
    fn values_per_gradient(&self) -> u64 {
        1
    }

    /// Values at every lattice point of the z-planes `z0..z1`, x fastest, then y, then z; the
    /// points are [`Lattice::point`]. Fields with a faster way to fill a grid (a blob field
    /// splats each primitive into its box) override this; they must return the same bits as
    /// [`Field::values`] at those points, so that every polygonizer sees the same values.
    /// The default builds the points and calls [`Field::values`].
    fn lattice_values(
        &self,
        lattice: &Lattice,
        z0: u32,
        z1: u32,
        points: &mut Vec<DVec3>,
        out: &mut [f64],
    ) {
        let p = lattice.points_per_axis();
        points.clear();
        for z in z0..z1 {
            for y in 0..p[1] {
                for x in 0..p[0] {
                    points.push(lattice.point([x, y, z]));
                }
            }
        }
        self.values(points, out);
    }

    /// Points near the surface from which surface tracking walks to it when no seeds are given
    /// (blob centres, a fit's data points), and how far a walk may go, for lattices of cells of
    /// smallest side `cell`; `None` (the default) when the field knows none.
    fn starts(&self, cell: f64) -> Option<Starts> {
        let _ = cell;
        None
    }

    /// The field with its block bounds ([`BlockField`], erased to [`DynBlockField`]) when it has
    /// them: what lets the polygonizers that need bounds (sparse, tracking of every component)
    /// take a field known only as a [`Field`]. `None` by default.
    fn block_field(&self) -> Option<&dyn DynBlockField> {
        None
    }
}

/// Where surface tracking starts when the caller gives no seeds ([`Field::starts`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Starts {
    /// Points each walk starts from, to the first cell the surface crosses.
    pub points: Vec<DVec3>,
    /// Cells a walk goes at most in one direction.
    pub max_walk: u32,
}

/// Points per axis of one block of the sparse polygonizer: blocks of 7³ cells, 8³ points, so that
/// a block's point row is one vector of eight `f64` and a z-plane's signs are one `u64`.
pub const BLOCK_POINTS: usize = 8;

/// What a [`BlockField`] tells about one block of lattice points.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlockSign {
    /// Every point of the block is outside (f > 0): no cell of the block is crossed.
    Outside,
    /// Every point of the block is inside (f < 0).
    Inside,
    /// The values were written: the surface may cross the block.
    Mixed,
}

/// One block of lattice points (see [`BlockField`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Block {
    /// Block coordinates.
    pub index: [u32; 3],
    /// Its lowest lattice point.
    pub lo: [u32; 3],
    /// Points per axis, each at most [`BLOCK_POINTS`] (fewer at the lattice's upper sides).
    pub n: [u32; 3],
}

/// A field that can bound its values over a box of lattice points cheaply, so that the sparse
/// polygonizer ([`crate::polygonize::sparse`]) skips the blocks of the lattice that the surface
/// cannot cross. The values it writes must have the same bits as [`Field::values`] (and the
/// same as [`Field::lattice_values`]), so that the sparse mesh equals the dense one.
pub trait BlockField: Field {
    /// What the field prepares once per lattice (e.g. which primitives reach which block).
    type Blocks: Send + Sync;

    /// Prepares the blocks of `lattice`: block `(bx, by, bz)` holds the lattice points
    /// `7·b .. 7·b + 8` along each axis (fewer at the lattice's upper sides), `blocks` per axis.
    fn blocks(&self, lattice: &Lattice, blocks: [u32; 3]) -> Self::Blocks;

    /// [`BlockField::blocks`] to be filled a few z-layers of blocks at a time by
    /// [`BlockField::keep_layers`], so that the data of the whole lattice is never held at
    /// once. By default the data of every layer, and [`BlockField::keep_layers`] does nothing.
    fn blocks_by_layers(&self, lattice: &Lattice, blocks: [u32; 3]) -> Self::Blocks {
        self.blocks(lattice, blocks)
    }

    /// Makes `blocks` (from [`BlockField::blocks_by_layers`]) hold the data of the z-layers
    /// `layers` of blocks, and releases that of the others: only blocks in these layers may be
    /// asked for until the next call.
    fn keep_layers(&self, blocks: &mut Self::Blocks, lattice: &Lattice, layers: Range<u32>) {
        let _ = (blocks, lattice, layers);
    }

    /// For `block`, from bounds alone (no values): [`BlockSign::Outside`] or
    /// [`BlockSign::Inside`] when every point provably has that sign, otherwise
    /// [`BlockSign::Mixed`] (the surface may cross the block).
    fn block_sign(&self, blocks: &Self::Blocks, lattice: &Lattice, block: &Block) -> BlockSign;

    /// For `block`: the sign [`BlockField::block_sign`] gives when it is one, otherwise the
    /// values at point `block.lo + (i, j, k)` written to `out[i + 8 j + 64 k]` and
    /// [`BlockSign::Mixed`].
    fn block_values(
        &self,
        blocks: &Self::Blocks,
        lattice: &Lattice,
        block: &Block,
        out: &mut [f64; 512],
    ) -> BlockSign;

    /// Gradients at `points`, all inside `block` (the vertices it owns), as [`Field::gradients`]
    /// computes them.
    fn block_gradients(
        &self,
        blocks: &Self::Blocks,
        block: &Block,
        points: &[DVec3],
        out: &mut [DVec3],
    ) {
        let _ = (blocks, block);
        for (p, o) in points.iter().zip(out) {
            *o = self.gradient(*p);
        }
    }
}

/// What a [`BlockField`] prepares for a lattice ([`BlockField::Blocks`]), behind `dyn Any`.
pub type AnyBlocks = Box<dyn std::any::Any + Send + Sync>;

/// A [`BlockField`] with its prepared blocks erased to [`AnyBlocks`], so that it can be used as
/// a trait object (`dyn DynBlockField` is itself a [`BlockField`]). Implemented for every
/// `BlockField` whose blocks are `'static`; [`Field::block_field`] returns it. Each method is the
/// `BlockField` method of the same name without `dyn_`, on the blocks that
/// [`DynBlockField::dyn_blocks`] or [`DynBlockField::dyn_blocks_by_layers`] of the same field
/// made.
#[allow(missing_docs)]
pub trait DynBlockField: Field {
    fn dyn_blocks(&self, lattice: &Lattice, blocks: [u32; 3]) -> AnyBlocks;
    fn dyn_blocks_by_layers(&self, lattice: &Lattice, blocks: [u32; 3]) -> AnyBlocks;
    fn dyn_keep_layers(&self, blocks: &mut AnyBlocks, lattice: &Lattice, layers: Range<u32>);
    fn dyn_block_sign(&self, blocks: &AnyBlocks, lattice: &Lattice, block: &Block) -> BlockSign;
    fn dyn_block_values(
        &self,
        blocks: &AnyBlocks,
        lattice: &Lattice,
        block: &Block,
        out: &mut [f64; 512],
    ) -> BlockSign;
    fn dyn_block_gradients(
        &self,
        blocks: &AnyBlocks,
        block: &Block,
        points: &[DVec3],
        out: &mut [DVec3],
    );
}

/// The blocks `blocks` as `B` made them.
fn blocks_of<B: BlockField>(blocks: &AnyBlocks) -> &B::Blocks
where
    B::Blocks: 'static,
{
    blocks
        .downcast_ref()
        .expect("the blocks come from the same field's dyn_blocks")
}

impl<B: BlockField> DynBlockField for B
where
    B::Blocks: 'static,
{
    fn dyn_blocks(&self, lattice: &Lattice, blocks: [u32; 3]) -> AnyBlocks {
        Box::new(self.blocks(lattice, blocks))
    }
    fn dyn_blocks_by_layers(&self, lattice: &Lattice, blocks: [u32; 3]) -> AnyBlocks {
        Box::new(self.blocks_by_layers(lattice, blocks))
    }
    fn dyn_keep_layers(&self, blocks: &mut AnyBlocks, lattice: &Lattice, layers: Range<u32>) {
        let blocks = blocks
            .downcast_mut()
            .expect("the blocks come from the same field's dyn_blocks");
        self.keep_layers(blocks, lattice, layers)
    }
    fn dyn_block_sign(&self, blocks: &AnyBlocks, lattice: &Lattice, block: &Block) -> BlockSign {
        self.block_sign(blocks_of::<B>(blocks), lattice, block)
    }
    fn dyn_block_values(
        &self,
        blocks: &AnyBlocks,
        lattice: &Lattice,
        block: &Block,
        out: &mut [f64; 512],
    ) -> BlockSign {
        self.block_values(blocks_of::<B>(blocks), lattice, block, out)
    }
    fn dyn_block_gradients(
        &self,
        blocks: &AnyBlocks,
        block: &Block,
        points: &[DVec3],
        out: &mut [DVec3],
    ) {
        self.block_gradients(blocks_of::<B>(blocks), block, points, out)
    }
}

impl BlockField for dyn DynBlockField + '_ {
    type Blocks = AnyBlocks;
    fn blocks(&self, lattice: &Lattice, blocks: [u32; 3]) -> AnyBlocks {
        self.dyn_blocks(lattice, blocks)
    }
    fn blocks_by_layers(&self, lattice: &Lattice, blocks: [u32; 3]) -> AnyBlocks {
        self.dyn_blocks_by_layers(lattice, blocks)
    }
    fn keep_layers(&self, blocks: &mut AnyBlocks, lattice: &Lattice, layers: Range<u32>) {
        self.dyn_keep_layers(blocks, lattice, layers)
    }
    fn block_sign(&self, blocks: &AnyBlocks, lattice: &Lattice, block: &Block) -> BlockSign {
        self.dyn_block_sign(blocks, lattice, block)
    }
    fn block_values(
        &self,
        blocks: &AnyBlocks,
        lattice: &Lattice,
        block: &Block,
        out: &mut [f64; 512],
    ) -> BlockSign {
        self.dyn_block_values(blocks, lattice, block, out)
    }
    fn block_gradients(
        &self,
        blocks: &AnyBlocks,
        block: &Block,
        points: &[DVec3],
        out: &mut [DVec3],
    ) {
        self.dyn_block_gradients(blocks, block, points, out)
    }
}

impl<F: Field + ?Sized> Field for &F {
    fn value(&self, p: DVec3) -> f64 {
        (**self).value(p)
    }
    fn gradient(&self, p: DVec3) -> DVec3 {
        (**self).gradient(p)
    }
    fn fd_step(&self) -> f64 {
        (**self).fd_step()
    }
    fn gradient_bound(&self) -> Option<f64> {
        (**self).gradient_bound()
    }
    fn values(&self, points: &[DVec3], out: &mut [f64]) {
        (**self).values(points, out)
    }
    fn gradients(&self, points: &[DVec3], out: &mut [DVec3]) {
        (**self).gradients(points, out)
    }
    fn values_gradients(&self, points: &[DVec3], values: &mut [f64], gradients: &mut [DVec3]) {
        (**self).values_gradients(points, values, gradients)
    }
    fn values_per_value_gradient(&self) -> u64 {
        (**self).values_per_value_gradient()
    }
    fn values_per_gradient(&self) -> u64 {
        (**self).values_per_gradient()
    }
    fn lattice_values(
        &self,
        lattice: &Lattice,
        z0: u32,
        z1: u32,
        points: &mut Vec<DVec3>,
        out: &mut [f64],
    ) {
        (**self).lattice_values(lattice, z0, z1, points, out)
    }
    fn starts(&self, cell: f64) -> Option<Starts> {
        (**self).starts(cell)
    }
    fn block_field(&self) -> Option<&dyn DynBlockField> {
        (**self).block_field()
    }
}

/// Gradients by central differences using only batched [`Field::values`] calls: one batch of
/// `6 × points.len()` evaluations. For fields that only have batched values (such as a Python
/// callable).
pub fn gradients_by_differences<F: Field + ?Sized>(
    field: &F,
    points: &[DVec3],
    h: f64,
    out: &mut [DVec3],
) {
    let mut probes = Vec::with_capacity(points.len() * 6);
    for &p in points {
        for e in [DVec3::X, DVec3::Y, DVec3::Z] {
            probes.push(p + e * h);
            probes.push(p - e * h);
        }
    }
    let mut v = vec![0.0; probes.len()];
    field.values(&probes, &mut v);
    for (i, o) in out.iter_mut().enumerate() {
        let s = &v[6 * i..6 * i + 6];
        *o = DVec3::new(s[0] - s[1], s[2] - s[3], s[4] - s[5]) / (2.0 * h);
    }
}

/// A field that counts the values it is asked for (values only, including those of
/// [`Field::values_gradients`], [`Field::lattice_values`] and block values), for tests and stats.
/// It forwards every method of [`Field`] to the field it wraps; with a [`BlockField`] inside,
/// [`Field::block_field`] gives the counting field itself.
pub struct Counting<F> {
    /// The field counted.
    pub inner: F,
    /// Values computed so far.
    pub count: std::sync::atomic::AtomicU64,
}

impl<F> Counting<F> {
    /// `inner`, counted from zero.
    pub fn new(inner: F) -> Self {
        Counting {
            inner,
            count: std::sync::atomic::AtomicU64::new(0),
        }
    }
    /// Points evaluated so far.
    pub fn evaluations(&self) -> u64 {
        self.count.load(std::sync::atomic::Ordering::Relaxed)
    }
    fn add(&self, n: u64) {
        self.count
            .fetch_add(n, std::sync::atomic::Ordering::Relaxed);
    }
    /// The inner field's block bounds; only asked for after [`Field::block_field`] gave some.
    fn inner_blocks(&self) -> &dyn DynBlockField
    where
        F: Field,
    {
        self.inner
            .block_field()
            .expect("Counting::block_field is Some only when the inner field's is")
    }
}

impl<F: Field> Field for Counting<F> {
    fn value(&self, p: DVec3) -> f64 {
        self.add(1);
        self.inner.value(p)
    }
    fn gradient(&self, p: DVec3) -> DVec3 {
        self.inner.gradient(p)
    }
    fn fd_step(&self) -> f64 {
        self.inner.fd_step()
    }
    fn gradient_bound(&self) -> Option<f64> {
        self.inner.gradient_bound()
    }
    fn values(&self, points: &[DVec3], out: &mut [f64]) {
        self.add(points.len() as u64);
        self.inner.values(points, out)
    }
    fn gradients(&self, points: &[DVec3], out: &mut [DVec3]) {
        self.inner.gradients(points, out)
    }
    fn values_gradients(&self, points: &[DVec3], values: &mut [f64], gradients: &mut [DVec3]) {
        self.add(points.len() as u64);
        self.inner.values_gradients(points, values, gradients)
    }
    fn values_per_value_gradient(&self) -> u64 {
        self.inner.values_per_value_gradient()
    }
    fn values_per_gradient(&self) -> u64 {
        self.inner.values_per_gradient()
    }
    fn lattice_values(
        &self,
        lattice: &Lattice,
        z0: u32,
        z1: u32,
        points: &mut Vec<DVec3>,
        out: &mut [f64],
    ) {
        self.add(out.len() as u64);
        self.inner.lattice_values(lattice, z0, z1, points, out)
    }
    fn starts(&self, cell: f64) -> Option<Starts> {
        self.inner.starts(cell)
    }
    fn block_field(&self) -> Option<&dyn DynBlockField> {
        self.inner.block_field()?;
        Some(self)
    }
}

impl<F: Field> DynBlockField for Counting<F> {
    fn dyn_blocks(&self, lattice: &Lattice, blocks: [u32; 3]) -> AnyBlocks {
        self.inner_blocks().dyn_blocks(lattice, blocks)
    }
    fn dyn_blocks_by_layers(&self, lattice: &Lattice, blocks: [u32; 3]) -> AnyBlocks {
        self.inner_blocks().dyn_blocks_by_layers(lattice, blocks)
    }
    fn dyn_keep_layers(&self, blocks: &mut AnyBlocks, lattice: &Lattice, layers: Range<u32>) {
        self.inner_blocks().dyn_keep_layers(blocks, lattice, layers)
    }
    fn dyn_block_sign(&self, blocks: &AnyBlocks, lattice: &Lattice, block: &Block) -> BlockSign {
        self.inner_blocks().dyn_block_sign(blocks, lattice, block)
    }
    /// Counts the block's points when their values are written.
    fn dyn_block_values(
        &self,
        blocks: &AnyBlocks,
        lattice: &Lattice,
        block: &Block,
        out: &mut [f64; 512],
    ) -> BlockSign {
        let sign = self
            .inner_blocks()
            .dyn_block_values(blocks, lattice, block, out);
        if sign == BlockSign::Mixed {
            self.add(block.n.iter().map(|&v| v as u64).product::<u64>());
        }
        sign
    }
    fn dyn_block_gradients(
        &self,
        blocks: &AnyBlocks,
        block: &Block,
        points: &[DVec3],
        out: &mut [DVec3],
    ) {
        self.inner_blocks()
            .dyn_block_gradients(blocks, block, points, out)
    }
}
