//! Rigid bodies: their shapes, motion and state (`body.rs`), and their
//! two-way coupling with an SPH fluid through boundary samples
//! (`coupling.rs`, Akinci et al. 2012), whose one layer of samples drags
//! the fluid as a full ghost lattice would (`ghosts.rs`).
//!
//! A fluid owns its bodies ([`crate::fluid::Fluid::bodies`]); what the
//! coupling needs from the fluid arrives as [`BoundaryParams`], so this
//! module does not depend on the fluid's types.

mod body;
mod coupling;
mod ghosts;

pub use body::{BodyState, Motion, Oscillation, RigidBody, Rotation, Slip};
pub use coupling::{BoundaryParams, RigidBodies};
pub use ghosts::GhostDepth;
