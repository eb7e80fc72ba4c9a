//! Reduced (modal) dynamics of an elastic body, after Guo & Qin,
//! "Meshless Methods for Physics-Based Modeling and Simulation of
//! Deformable Models", Sec. 5.3.1-5.3.3, with the modal warping of
//! Choi & Ko 2005 ("Modal warping: real-time simulation of large
//! rotational deformation and manipulation").
//!
//! The Element-Free Galerkin body computes, once, the `l` lowest modes of
//! `K x = lambda M x` (M-orthonormal, so the equations of motion
//! decouple, Eq. 25) and the rotation modes `W` (Eq. 27); this module
//! steps the `l` modal amplitudes instead of the `3n` nodal unknowns.
//!
//! - `basis.rs`: [`ModalBasis`], the validated eigenvalues, mode shapes
//!   and rotation modes, stored per node;
//! - `integrate.rs`: [`Damping`] (Rayleigh) and the implicit step
//!   Eq. 31;
//! - `warp.rs`: [`rotation_integral`], the warped displacements and the
//!   rotated loads (Eq. 26-30);
//! - `constraints.rs`: manipulation constraints, Eq. 32-33, with
//!   [`Stabilization`] and their Schur-complement solve;
//! - `system.rs`: [`ModalSystem`], which owns all of the above and the
//!   state;
//! - `error.rs`: [`ModalError`].

mod basis;
mod constraints;
mod error;
#[cfg(test)]
mod fixtures;
mod integrate;
mod system;
mod warp;

pub use basis::{EIGENVALUE_TOLERANCE, ModalBasis};
pub use constraints::{MAX_CONSTRAINTS, Stabilization};
pub use error::ModalError;
pub use integrate::Damping;
pub use system::ModalSystem;
pub use warp::rotation_integral;
