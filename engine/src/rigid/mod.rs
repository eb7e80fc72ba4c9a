//! Rigid bodies: their shapes, motion and state (`body.rs`), and their
//! two-way coupling with an SPH fluid through boundary samples
//! (`coupling.rs`, Akinci et al. 2012).
//!
//! A fluid owns its bodies ([`crate::fluid::Fluid::bodies`]); what the
//! coupling needs from the fluid arrives as [`BoundaryParams`], so this
//! module does not depend on the fluid's types.

mod body;
mod coupling;

pub use body::{BodyState, Motion, Oscillation, RigidBody, Rotation, Slip};
pub use coupling::{BoundaryParams, RigidBodies};
