//! Frames: immutable snapshots of the particle fields a scene asked for,
//! and the kinds of field a frame can carry.
//!
//! Adding a field: a [`FieldKind`] variant here (its name and component
//! count) and its values in each system's field writer
//! (`world/system.rs`).

use crate::geometry::TriMesh;
use crate::math::Real;
use serde::{Deserialize, Serialize};

/// A particle field a frame can carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FieldKind {
    /// Particle positions, m (3 components).
    Position,
    /// Particle velocities, m/s (3 components).
    Velocity,
    /// Densities, kg/m^3.
    Density,
    /// Pressures, Pa.
    Pressure,
    /// Masses, kg (per metre of depth in 2D).
    Mass,
    /// Volumes `m / rho`, m^3 (m^2 in 2D): their sum is the body's or
    /// fluid's volume.
    Volume,
    /// Kinetic energies `m |v|^2 / 2`, J.
    KineticEnergy,
    /// Stored elastic energy, J: a solid particle's strain energy
    /// `V W(F)`, a fluid particle's compression energy under the Tait
    /// equation, `m int_rho0^rho p / rho^2 drho` (0 for DFSPH, which has no
    /// equation of state).
    ElasticEnergy,
    /// Each particle's stable id within its system (an integer): kept
    /// while other particles leave or join, so a client follows a particle
    /// from frame to frame. Frames carry ids as integers, in
    /// [`Frame::ids`], not among the real-valued [`Frame::fields`].
    Id,
    /// The fragment of a fracturing solid each particle is in: 0 for the
    /// body as built, and each part a crack cuts off takes the next
    /// number (0 in a solid that cannot crack, NaN for a fluid, which has
    /// no fragments).
    Fragment,
}

impl FieldKind {
    /// Scalars per particle.
    pub fn components(self) -> usize {
        match self {
            Self::Position | Self::Velocity => 3,
            Self::Density
            | Self::Pressure
            | Self::Mass
            | Self::Volume
            | Self::KineticEnergy
            | Self::ElasticEnergy
            | Self::Id
            | Self::Fragment => 1,
        }
    }

    /// Lower-case name, as in scene files and exported files.
    pub fn name(self) -> &'static str {
        match self {
            Self::Position => "position",
            Self::Velocity => "velocity",
            Self::Density => "density",
            Self::Pressure => "pressure",
            Self::Mass => "mass",
            Self::Volume => "volume",
            Self::KineticEnergy => "kinetic_energy",
            Self::ElasticEnergy => "elastic_energy",
            Self::Id => "id",
            Self::Fragment => "fragment",
        }
    }

    /// Whether the field's values are integers ([`Self::Id`]), carried in
    /// [`Frame::ids`] rather than as f32 in [`Frame::fields`].
    pub fn is_integer(self) -> bool {
        self == Self::Id
    }
}

/// One particle field, `components` f32 per particle, particle-major.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldData {
    /// Which field.
    pub kind: FieldKind,
    /// Scalars per particle ([`FieldKind::components`]).
    pub components: usize,
    /// `components` values per particle, particle after particle.
    pub values: Vec<f32>,
}

/// A snapshot of a world after a step.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Steps completed since the world was built.
    pub step: u64,
    /// Simulated time, s.
    pub time: Real,
    /// Sub-steps the last step was split into, and the shortest of them.
    pub substeps: u32,
    /// The shortest sub-step, s.
    pub substep_dt: Real,
    /// Pressure-solver iterations of the last step (0 for WCSPH).
    pub solver_iterations: u32,
    /// Worst average density error of the last step's solves (fraction).
    pub density_error: Real,
    /// Whether `time.max_substeps` capped the last step's split, so its
    /// sub-steps exceeded the stability limit.
    pub capped: bool,
    /// Solves of the last step that stopped at their iteration cap above
    /// their tolerance (DFSPH pressure, implicit solids' Newton).
    pub unconverged: u32,
    /// Particles the systems gained at the start of the last step (a
    /// resampling solid's splits, a fluid's queued insertions), with ids
    /// after their system's last.
    pub added: u32,
    /// Particles over all systems: the length of each field.
    pub particle_count: usize,
    /// Positions first, then the requested real-valued fields in scene
    /// order.
    pub fields: Vec<FieldData>,
    /// Each particle's stable id within its system, in the order of
    /// `fields`, when the scene's output names [`FieldKind::Id`].
    pub ids: Option<Vec<u32>>,
    /// Every rigid body's pose, in scene order (empty without bodies).
    pub bodies: Vec<BodyPose>,
    /// The fluid's surface, when the scene asks for it (`output.surface`).
    pub surface: Option<TriMesh>,
    /// Where each elastic solid's particles sit in `fields` (after the
    /// fluid's), in scene order.
    pub solids: Vec<SolidRange>,
    /// The deformed surface of every solid that embeds one, in scene
    /// order.
    pub solid_surfaces: Vec<SolidSurface>,
    /// The crack faces of every fracturing solid that has cracks, in
    /// scene order: each crack's two faces, each deformed with the
    /// material on its side (tutorial Section 7.3).
    pub crack_surfaces: Vec<SolidSurface>,
}

/// A solid's embedded surface as deformed in a frame.
#[derive(Debug, Clone, PartialEq)]
pub struct SolidSurface {
    /// Index of the solid's system in the scene.
    pub system: usize,
    /// The deformed mesh.
    pub mesh: TriMesh,
    /// Unit normal per vertex.
    pub normals: Vec<crate::math::Vector>,
}

/// The particles of one solid in a frame: `count` of them from `first`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SolidRange {
    /// Index of the solid's system in the scene.
    pub system: usize,
    /// Its first particle in the frame's fields.
    pub first: usize,
    /// How many particles it has.
    pub count: usize,
}

/// Where a rigid body is and how it moves, in the world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyPose {
    /// Index of the body's system in the scene.
    pub system: usize,
    /// Centre (of mass), m.
    pub position: [Real; 3],
    /// Unit quaternion `[x, y, z, w]` turning the body frame into the
    /// world frame; for a mesh body, the frame of its file (moved to the
    /// centroid), as the scene's orientation gives it.
    pub orientation: [Real; 4],
    /// Velocity of the centre, m/s.
    pub velocity: [Real; 3],
    /// rad/s.
    pub angular_velocity: [Real; 3],
}

impl Frame {
    /// The field of a kind, if the frame carries it.
    pub fn field(&self, kind: FieldKind) -> Option<&FieldData> {
        self.fields.iter().find(|f| f.kind == kind)
    }
}
