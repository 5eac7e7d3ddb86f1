//! The [`Tessellator`]: both tracking engines with their caches kept between calls, and the
//! one-shot call behind [`crate::polygonize::Method::Tracking`].

use super::blocks::BlockTracking;
use super::cells::CellTracking;
use super::{Components, TrackingSettings};
use crate::error::Result;
use crate::field::Field;
use crate::lattice::Lattice;
use crate::mesh::Mesh;
use crate::polygonize::sparse::TriangleIndex;
use crate::polygonize::{needs_bounds, Polygonized, Stats};

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
    /// A tessellator with empty caches.
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
    /// `settings.seed_cells`. With [`super::Components::Seeded`], the components that hold a
    /// seed, of any field. With [`super::Components::All`], for a field with block bounds
    /// ([`Field::block_field`], a blob field; any other is refused): after the walk from the
    /// seeds, the blocks of 7³ cells that the bounds cannot rule out are evaluated (each block
    /// at once, as [`crate::polygonize::sparse`] does), and the walk goes on from their crossed
    /// cells it did not reach; the mesh is then the dense mesh, triangle for triangle and bit
    /// for bit (up to the order of vertices and triangles). The mesh is valid until the next
    /// call.
    pub fn polygonize<F: Field + ?Sized>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        settings: &TrackingSettings,
    ) -> Result<(&Mesh, Stats)> {
        match settings.components {
            Components::Seeded => self.cells.polygonize(field, lattice, settings),
            Components::All => {
                let bounded = needs_bounds(field, "tracking")?;
                self.cells.polygonize_bounded(bounded, lattice, settings)
            }
        }
    }

    /// [`Tessellator::polygonize`] block by block, for a field with block bounds
    /// ([`Field::block_field`]; any other is refused) that evaluates whole blocks of the lattice
    /// (a blob field): seeds walked by the same rule, then the walk block by block. The mesh is
    /// the same (up to the order of vertices and triangles); more points are evaluated (whole
    /// blocks of 8³, vectorised), in much less time. The triangles come beside the mesh, as `I`.
    pub fn polygonize_blocks<F: Field + ?Sized, I: TriangleIndex>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        settings: &TrackingSettings,
    ) -> Result<(Mesh, Vec<[I; 3]>, Stats)> {
        let bounded = needs_bounds(field, "tracking")?;
        self.blocks.polygonize(bounded, lattice, settings)
    }
}

impl Tessellator {
    /// Tracks the surface block by block ([`Tessellator::polygonize_blocks`]) when `blocks` is
    /// asked for and the field has block bounds ([`Field::block_field`]), else cell by cell
    /// ([`Tessellator::polygonize`], the mesh copied out of the caches). The triangles come
    /// beside the mesh, as `I`, either way.
    pub fn track<F: Field + ?Sized, I: TriangleIndex>(
        &mut self,
        field: &F,
        lattice: &Lattice,
        settings: &TrackingSettings,
        blocks: bool,
    ) -> Result<(Mesh, Vec<[I; 3]>, Stats)> {
        if blocks && field.block_field().is_some() {
            return self.polygonize_blocks(field, lattice, settings);
        }
        let (m, stats) = self.polygonize(field, lattice, settings)?;
        // Runs of 4096 triangles, converted in parallel.
        let runs: Vec<&[[u32; 3]]> = m.triangles.chunks(4096).collect();
        let triangles = crate::polygonize::gather_map(&runs, |t| t.map(I::from_u32));
        let mesh = Mesh {
            vertices: m.vertices.clone(),
            triangles: Vec::new(),
            normals: m.normals.clone(),
        };
        Ok((mesh, triangles, stats))
    }
}

/// One-shot tracking polygonization cell by cell ([`Tessellator::polygonize`]), with the
/// vertices' edge keys when [`crate::polygonize::Settings::keys`] asks for them
/// ([`crate::polygonize::polygonize`] with [`crate::polygonize::Method::Tracking`]).
pub(crate) fn polygonize<F: Field + ?Sized>(
    field: &F,
    lattice: &Lattice,
    settings: &TrackingSettings,
) -> Result<Polygonized> {
    let mut t = Tessellator::new();
    let keyed = settings.common.keys;
    t.cells.keyed = keyed;
    let (m, stats) = t.polygonize(field, lattice, settings)?;
    let mesh = m.clone();
    Ok(Polygonized {
        mesh,
        keys: keyed.then(|| std::mem::take(&mut t.cells.edge_keys)),
        stats,
    })
}
