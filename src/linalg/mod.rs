//! Dense linear algebra for the variational fits: the Cholesky factorization and the small dense
//! kernels of partition-of-unity patches, and the saddle-point solve of an interpolation system.

pub mod cholesky;
pub mod saddle;
pub mod small_dense;
