//! SPH fluids: the weakly compressible solver of the Adams–Wicke tutorial
//! (Section 6, Algorithm 5) with the Tait equation of state, DFSPH, the
//! domain's walls and rigid bodies coupled both ways.

mod dfsph;
mod eos;
mod reorder;
mod rigid_body;
mod rigid_boundary;
mod viscosity;
mod walls;
mod wcsph;

pub use dfsph::{DfsphParams, SolveInfo};
pub use eos::Tait;
pub use rigid_body::{BodyState, Motion, Oscillation, RigidBody, Rotation, Slip};
pub use rigid_boundary::RigidBodies;
pub use viscosity::ViscosityModel;
pub use walls::BoxWalls;
pub use wcsph::{Fluid, FluidParams, FluidState, Invalid, PressureSolver};
