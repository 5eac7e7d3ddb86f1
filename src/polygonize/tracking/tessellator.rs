//! The [`Tessellator`]: both tracking engines with their caches kept between calls, and the
//! one-shot calls [`polygonize`] and [`polygonize_bounded`].

use super::blocks::BlockTracking;
use super::cells::CellTracking;
use super::TrackingSettings;
use crate::error::Result;
use crate::field::{BlockField, Field};
use crate::lattice::Lattice;
use crate::mesh::Mesh;
use crate::polygonize::sparse::TriangleIndex;
use crate::polygonize::Stats;

/// Caches and buffers kept between calls, for animation: polygonize, move the field, polygonize
/// again — in steady state nothing is reallocated.
#[derive(Default)]
pub struct Tessellator {
    /// Tracking cell by cell: time-stamped brick caches.
    cells: CellTracking,
    /// Tracking block by block ([`Tessellator::polygonize_blocks`]).
    blocks: BlockTracking,
}

impl Tessellator {
    pub fn new() -> Self {
        Self::default()
    }

    /// The mesh of the last call cell by cell.
    pub fn mesh(&self) -> &Mesh {
        self.cells.mesh()
    }

    /// Bytes held by the caches and buffers (capacities), to check that memory stays flat.
    pub fn capacity_bytes(&self) -> usize {
        self.cells.capacity_bytes() + self.blocks.capacity_bytes()
    }

    /// Tracks the surface cell by cell from the seeds walked from `settings.starts` and from
    /// `settings.seed_cells`: the components that hold a seed ([`super::Components::Seeded`];
    /// `Components::All` needs a field with block bounds: [`Tessellator::polygonize_bounded`]).
    /// The mesh is valid until the next call.
    pub fn polygonize<F: Field + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        settings: &TrackingSettings,
    ) -> Result<(&Mesh, Stats)> {
        self.cells.polygonize(field, lattice, settings)
    }

    /// [`Tessellator::polygonize`] for a field with block bounds (a blob field), which finds
    /// every component with [`super::Components::All`]: after the walk from the seeds, the
    /// blocks of 7³ cells that the bounds cannot rule out are evaluated (each block at once, as
    /// [`crate::polygonize::sparse`] does), and the walk goes on from their crossed cells it
    /// did not reach. The mesh is then the dense mesh, triangle for triangle and bit for bit
    /// (up to the order of vertices and triangles).
    pub fn polygonize_bounded<F: BlockField + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        settings: &TrackingSettings,
    ) -> Result<(&Mesh, Stats)> {
        self.cells.polygonize_bounded(field, lattice, settings)
    }

    /// [`Tessellator::polygonize_bounded`] block by block, for fields that evaluate whole
    /// blocks of the lattice (blob fields): seeds walked by the same rule, then the walk block
    /// by block. The mesh is the same (up to the order of vertices and triangles); more points
    /// are evaluated (whole blocks of 8³, vectorised), in much less time. The triangles come
    /// beside the mesh, as `I`.
    pub fn polygonize_blocks<F: BlockField + ?Sized, I: TriangleIndex>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        settings: &TrackingSettings,
    ) -> Result<(Mesh, Vec<[I; 3]>, Stats)> {
        self.blocks.polygonize(field, lattice, settings)
    }
}

/// One-shot tracking polygonization (see [`Tessellator::polygonize`]): the components that
/// hold a seed.
pub fn polygonize<F: Field + ?Sized>(
    field: &F,
    lattice: &Lattice,
    settings: &TrackingSettings,
) -> Result<(Mesh, Stats)> {
    let mut t = Tessellator::new();
    let (m, s) = t.polygonize(field, lattice, settings)?;
    Ok((m.clone(), s))
}

/// [`polygonize_bounded`], with the key of each vertex's lattice edge
/// ([`Lattice::whole_edge_key`]), one per vertex.
pub fn polygonize_bounded_keyed<F: BlockField + ?Sized>(
    field: &F,
    lattice: &Lattice,
    settings: &TrackingSettings,
) -> Result<(Mesh, Vec<u64>, Stats)> {
    let mut t = Tessellator::new();
    t.cells.keyed = true;
    let (m, s) = t.polygonize_bounded(field, lattice, settings)?;
    let m = m.clone();
    Ok((m, std::mem::take(&mut t.cells.edge_keys), s))
}

/// One-shot tracking polygonization of a field with block bounds (see
/// [`Tessellator::polygonize_bounded`]).
pub fn polygonize_bounded<F: BlockField + ?Sized>(
    field: &F,
    lattice: &Lattice,
    settings: &TrackingSettings,
) -> Result<(Mesh, Stats)> {
    let mut t = Tessellator::new();
    let (m, s) = t.polygonize_bounded(field, lattice, settings)?;
    Ok((m.clone(), s))
}
