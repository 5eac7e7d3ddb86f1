//! Subdivision of a control mesh onto an implicit surface (Jin, Sun & Peng 2003), the modified
//! butterfly scheme it is blended with (Zorin, Schröder & Sweldens 1996), and the blend itself.
//!
//! The control mesh is a triangle mesh whose vertices lie on the surface (typically the mesh the
//! surface was fitted to). Each level splits every triangle into four at its edge midpoints
//! ([`split`]) and moves the new midpoints onto the zero set by Newton steps along the gradient
//! (`project`), the "second way" of Jin §3: every level starts from vertices already on the
//! surface, so the midpoints start close to it; Newton starts from the middle of the Hermite
//! curve along the edge with the end normals (`hermite_midpoint`), closer still. Old vertices
//! keep their index and their exact coordinates, so level `k` is a sub-mesh of level `k + 1`.
//!
//! [`butterfly`] makes the same connectivity with positions from the modified butterfly scheme,
//! so that vertex `i` of both meshes corresponds and [`blend`] can mix them (Jin §4).
//!
//! One idea per file: [`SubdivisionSettings`] and [`LevelStats`] (`settings`), the checks of the
//! control mesh and the level count (`checks`), the 1-to-4 [`split`], the counted batched calls
//! of the field (`evaluator`), Newton's projection with its line-search fallback (`projection`),
//! the level loop of [`subdivide`] (`implicit`), [`butterfly`] and [`blend`].
//!
//! One [`subdivide`] serves every [`Field`](crate::field::Field): values and gradients come from
//! one [`Field::values_gradients`](crate::field::Field::values_gradients) call per Newton step;
//! a field that only has values is wrapped in [`Differences`](crate::field::Differences), with
//! the step [`difference_step`] by default.
//!
//! Progress ([`crate::cancel::advance`]) counts vertices placed: the control mesh's vertices
//! once their normals are evaluated, then every new vertex once Newton or the fallback has
//! placed it, so the count ends at the vertex count of the finest level ([`vertex_count`]).

mod blend;
mod butterfly;
mod checks;
mod evaluator;
mod implicit;
mod projection;
mod settings;
mod split;
#[cfg(test)]
mod tests;

pub use blend::blend;
pub use butterfly::butterfly;
pub use checks::{check_mesh, vertex_count, MAX_LEVELS};
pub use implicit::{difference_step, subdivide};
pub use projection::Projection;
pub use settings::{LevelStats, SubdivisionSettings};
pub use split::split;
