//! Thin shells (Guo–Qin, Sections 4.2 and 5.2): a Kirchhoff–Love shell
//! whose nodes live on a chart's 2D parametric domain, placed by a
//! quadtree (`geometry/quadtree`), with MLS shape functions and their
//! second derivatives (`approx/mls/hessian.rs`) and the geometrically
//! nonlinear membrane and bending energy of Cirak et al. 2000.
//!
//! - `kirchhoff.rs`: the energy at one point from the fundamental forms,
//!   with its exact gradient and Hessian;
//! - `model.rs`: [`ShellModel`], the discretisation of a chart and the
//!   reference surface carried by the nodes;
//! - `assembly.rs`: loads, penalty supports, internal forces, and the
//!   tangent and mass over one sparse pattern;
//! - `statics.rs`: the static route (Newton on the sparse tangent, in
//!   load steps);
//! - `vibration.rs`: free vibration, the lowest modes about the
//!   reference;
//! - `embedded.rs`: points carried by the shell (an input mesh's
//!   vertices), and a mesh's conformal chart as a shell's surface;
//! - `dynamics.rs`: [`ShellDynamics`], implicit time stepping (backward
//!   Euler or Newmark, Rayleigh damping, Newton per step);
//! - `nodal.rs`: each node's share of the mass and the strain energy,
//!   for frames that list the nodes as particles;
//! - `error.rs`: [`ShellError`].

mod assembly;
mod dynamics;
mod embedded;
mod error;
pub mod kirchhoff;
mod model;
mod nodal;
mod statics;
mod vibration;

pub use assembly::{Grab, Load, Support, SupportKind};
pub use dynamics::{
    DynamicParams, Integrator, Mechanics, ShellDynamics, ShellEnergy, ShellState, ShellStep,
};
pub use embedded::Embedded;
pub use error::ShellError;
pub use model::{Material, ShapeRow, ShellModel, ShellParams, ShellSurface, Stencil, SurfacePoint};
pub use statics::{StaticParams, StaticSolution};
pub use vibration::ShellModes;
