//! # meshless-engine
//!
//! The numerics of meshless: kernels and approximations, neighbour search,
//! SPH fluids, rigid bodies, MLS solids, scenes, frames and file export. A
//! plain library with no networking: embed it in any program.
//!
//! The data flow is `Scene` (validated description) -> [`Scene::build`] ->
//! [`World`] (state, stepped by [`World::step`]) -> [`Frame`] (snapshot of
//! the fields a subscriber asked for). A long step or design solve stops
//! early when another thread raises its [`Cancel`]
//! ([`World::step_cancellable`]).

pub mod approx;
pub mod cancel;
pub mod design;
pub mod efg;
pub mod expression;
pub mod fluid;
pub mod frame;
pub mod geometry;
pub mod io;
pub mod linalg;
pub mod math;
pub mod modal;
pub mod neighbors;
pub mod rigid;
pub mod scene;
pub mod shell;
pub mod snapshot;
pub mod solid;
pub mod stats;
pub mod surface;
#[cfg(test)]
mod testing;
pub mod world;

pub use cancel::{Cancel, Cancelled, RaiseOnDrop};
pub use frame::{BodyPose, FieldData, FieldKind, Frame, SolidRange, SolidSurface};
pub use scene::{Budget, BuildOptions, Scene, SceneError};
pub use world::{
    Clock, ControlError, Controls, StateError, StepError, StepInfo, SystemState, World, WorldState,
};
