//! Element-Free Galerkin (EFG) solids on octree nodes (Guo–Qin, Sections
//! 3, 4.1 and 5.1): the discretisation that the modal solids
//! ([`crate::modal`]) reduce.
//!
//! The pipeline, each stage timed in [`EfgSolid::timings`]:
//!
//! 1. an [`Octree`](crate::geometry::Octree) adapted to an
//!    [`ImplicitSurface`](crate::geometry::ImplicitSurface) places the nodes and
//!    their cubic supports (Section 4.1.1);
//! 2. Gauss points on cells cut from its terminal octants
//!    ([`Quadrature`], Section 4.1.2);
//! 3. MLS shape functions with the tensor-product weight (Eq. 12-13) at
//!    those points ([`ShapeTable`]);
//! 4. the consistent mass, the linear stiffness, the penalty for fixed
//!    regions and body loads (`assemble.rs`, Eq. 16-17), the fixed regions
//!    integrated over the solid's own boundary (`boundary.rs`);
//! 5. the lowest modes and the rotation modes at the nodes, the modal
//!    basis that [`crate::modal::ModalSystem`] steps (`reduce.rs`,
//!    Section 5.3);
//! 6. [`ModalSolid`] (`body.rs`): all of the above behind one build, with
//!    the reduced state, the embedded surface (`skin.rs`) and the user's
//!    grabs, as a world steps it. Between stages 1 and 2 the build bounds
//!    what the rest will hold from the octree ([`Estimate`],
//!    `estimate.rs`) and asks its host to admit it; every stage's loops
//!    read the build's cancel flag.
//!
//! Every knob that trades speed for accuracy is a field of [`EfgParams`]:
//! the cell size (octree depth, hence the node count), `alpha`, the basis
//! order, the quadrature order and cell subdivision, the mass form and the
//! penalty.

mod assemble;
mod body;
mod boundary;
mod estimate;
mod nonlinear;
mod quadrature;
mod reduce;
mod shape;
mod skin;
mod solid;

pub use assemble::lame;
pub use body::{
    Dynamics, Grab, GrabError, ModalParams, ModalSolid, ModalState, MotionError, StepReport,
};
pub use boundary::{Anchor, MAX_FIXED_POINTS, Pose, TooManyPoints};
pub use estimate::Estimate;
pub use nonlinear::{
    NewtonInfo, NewtonParams, NonlinearError, NonlinearSolver, NonlinearState, Spring, StepInput,
    strain_energy_shares,
};
pub use quadrature::{MAX_ORDER, Quadrature};
pub use shape::{CoverError, Row, ShapeTable};
pub use skin::{DeformedSkin, SkinBuffers, SkinInput};
pub use solid::{EfgError, EfgParams, EfgSolid, FixedSurface, MassForm, Material};

#[cfg(test)]
mod tests;
