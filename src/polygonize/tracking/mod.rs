//! Surface tracking (Triquet et al. §4.4): starting from seed cells, visit only cells the surface
//! crosses, entering a neighbour only through a face whose corners change sign (known from the
//! case table, §4.6). Because the lattice, the table and the edge arithmetic are those of the
//! dense polygonizer, the mesh equals the dense mesh on every component that holds a seed.
//!
//! Seeds come from [`TrackingSettings`]: walks from start points (e.g. blob centres or data
//! points) to the first cell the surface crosses, and seed cells. Two engines walk the same
//! cells from the same seeds:
//! - cell by cell, with corner values, edge vertices and marks in time-stamped bricks of 8³
//!   lattice points kept between calls ([`Tessellator::polygonize`], any [`Field`]);
//! - block by block, over the blocks of 7³ cells of [`super::sparse`], each evaluated at once
//!   and flooded with bit arithmetic ([`Tessellator::polygonize_blocks`], a [`BlockField`]
//!   such as a blob field).
//!
//! A walk reaches only the components that hold a seed ([`Components::Seeded`]): for a field
//! without block bounds (a variational surface, a Python callable), a component no seed walk
//! reaches (e.g. the inner surface of a cavity) is not found. For a [`BlockField`],
//! [`Components::All`] finds every component: the blocks that the field's bounds cannot rule
//! out (which hold every crossed cell) are searched for crossed cells the walk did not reach,
//! and the walk goes on from them; the mesh is then the dense mesh, triangle for triangle and
//! bit for bit.
//!
//! The modules: the seed walks (`walker`), the two engines (`cells`, `blocks`, each using the
//! walker), and the [`Tessellator`] holding both (`tessellator`).
//!
//!
//! [`Field`]: crate::field::Field
//! [`BlockField`]: crate::field::BlockField
//!
//! ```
//! use glam::DVec3;
//! use implicitmesh::field::blob::{BlobField, PerPrimitive, BlobSettings};
//! use implicitmesh::lattice::Lattice;
//! use implicitmesh::polygonize::tracking::{Tessellator, TrackingSettings};
//! use implicitmesh::polygonize::{polygonize, Method, Settings};
//!
//! // Two blobs far apart: seeding one cell of the first finds only the first.
//! let centers = [DVec3::new(-0.5, 0.0, 0.0), DVec3::new(0.5, 0.0, 0.0)];
//! let blobs = BlobField::new(
//!     &centers,
//!     PerPrimitive::All(0.3),
//!     PerPrimitive::All(1.0),
//!     0.5,
//!     BlobSettings::default(),
//! )
//! .unwrap();
//! let lattice = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 40).unwrap();
//! // x from -0.35 to -0.3: the first blob's surface (at x = -0.338) crosses the cell.
//! let settings = TrackingSettings {
//!     seed_cells: vec![[13, 20, 20]],
//!     ..Default::default()
//! };
//! let mut tess = Tessellator::new();
//! let (mesh, triangles, _) = tess
//!     .polygonize_blocks::<_, u32>(&blobs, &lattice, &settings)
//!     .unwrap();
//! let both = polygonize(&blobs, &lattice, &Method::Dense(Settings::default()))
//!     .unwrap()
//!     .mesh;
//! let first = both.triangles.iter().filter(|t| both.vertices[t[0] as usize].x < 0.0);
//! assert_eq!(triangles.len(), first.count());
//! assert!(mesh.vertices.iter().all(|v| v.x < 0.0));
//! // Cell by cell: the same triangles.
//! let (cells, _) = tess.polygonize(&blobs, &lattice, &settings).unwrap();
//! assert_eq!(cells.triangles.len(), triangles.len());
//! ```

mod blocks;
mod cells;
mod settings;
mod tessellator;
mod walker;

#[cfg(test)]
mod tests;

pub use settings::{Components, TrackingSettings};
pub(crate) use tessellator::polygonize;
pub use tessellator::Tessellator;
pub(in crate::polygonize) use walker::FACE_STEP;
