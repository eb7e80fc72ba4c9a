//! SPH fluids: the weakly compressible solver of the Adams–Wicke tutorial
//! (Section 6, Algorithm 5) with the Tait equation of state.

mod dfsph;
mod eos;
mod reorder;
mod viscosity;
mod walls;
mod wcsph;

pub use dfsph::{DfsphParams, SolveInfo};
pub use eos::Tait;
pub use viscosity::ViscosityModel;
pub use walls::BoxWalls;
pub use wcsph::{Fluid, FluidParams, FluidState, Invalid, PressureSolver};
