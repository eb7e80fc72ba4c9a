//! MLS elastic solids (tutorial Section 7; Müller et al. 2004): a body
//! sampled by particles, its displacement gradient estimated by MLS in
//! material coordinates, Green–Saint-Venant strain, Hooke's law and
//! forces that are exact derivatives of the strain energy, with volume
//! conservation, hourglass control, damping, anchors, obstacles,
//! plasticity, and explicit or implicit integration.
//!
//! - `body.rs`: a solid's particles, reference shape and state;
//! - `elastic.rs`: [`ElasticSolid`], a body with its integrator;
//! - `material.rs`: strain, stress and energy (Eq. 61-65);
//! - `topology.rs`: the Lagrangian neighbourhoods, built once;
//! - `forces.rs`: the force passes and their linearisation;
//! - `integrate/`: time stepping, each integrator owning its buffers
//!   (explicit, implicit, and the implicit one's assembled Hessian and
//!   sparse Cholesky solve);
//! - `plasticity.rs`: Eq. 69 and the reference-shape update;
//! - `cracking.rs`: the body's fracture update (what `fracture/` holds);
//! - `resampling.rs`: particles split where cracks hid their neighbours
//!   (Eq. 71);
//! - `contact.rs`: obstacles and walls;
//! - `embedded.rs`: high-resolution surfaces that follow the particles
//!   (Section 7.2);
//! - `fracture/`: cracks that start, run and cut the particles' pairs,
//!   and the fragments they leave (Section 7.3).

mod body;
mod contact;
mod cracking;
mod elastic;
pub mod embedded;
mod forces;
pub mod fracture;
mod integrate;
mod material;
mod params;
mod plasticity;
mod resampling;
mod snapshot;
mod topology;

pub use body::{Body, SolidError, SolidState};
pub use contact::{Obstacle, Obstacles};
pub use elastic::ElasticSolid;
pub use fracture::{Fracture, FractureError, FractureParams, FractureSnapshot, FractureStep};
pub use integrate::SolidStep;
pub use material::{Hyperelastic, Material, StressState, cofactor, green_strain};
pub use params::{
    ImplicitParams, ImplicitScheme, Integrator, LinearSolver, Plasticity, SolidParams,
};
pub use resampling::{Resample, ResampleError};
pub use snapshot::SolidSnapshot;
