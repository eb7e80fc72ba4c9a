//! Linear algebra shared by the solvers, free of any physics: the
//! operator and preconditioner seams, the one preconditioned conjugate
//! gradient, symmetric block sparse matrices with faer's Cholesky, and
//! dense Cholesky of small blocks.
//!
//! - `linop.rs`: [`LinOp`] (`y = A x`), [`Precond`] (`z = M^-1 r`) and
//!   the vector [`Space`]s they act in ([`Parallel`], [`Sequential`]);
//! - `cg.rs`: the PCG, with [`cg::Params`], [`cg::Info`] and a
//!   caller-owned [`cg::Workspace`];
//! - `sparse.rs`: [`BlockPattern`] (sparsity, symbolic analysis,
//!   assembly by block columns) and [`SparseCholesky`];
//! - `dense.rs`: Cholesky of small dense blocks;
//! - `eigen.rs`: the lowest modes of `K x = lambda M x` for modal
//!   analysis ([`eigen::lowest_modes`]), by shift-invert around one
//!   sparse Cholesky factorisation and faer's Krylov–Schur.

pub mod cg;
pub mod dense;
pub mod eigen;
pub mod linop;
pub mod sparse;

pub use linop::{Element, LinOp, Parallel, Precond, Sequential, Space};
pub use sparse::{BlockColumn, BlockPattern, SparseCholesky};
