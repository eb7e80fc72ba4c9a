//! Frames: immutable snapshots of the particle fields a scene asked for.

use crate::geometry::TriMesh;
use crate::math::Real;
use crate::scene::FieldKind;

/// One particle field, `components` f32 per particle, particle-major.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldData {
    pub kind: FieldKind,
    pub components: usize,
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
    pub substep_dt: Real,
    /// Pressure-solver iterations of the last step (0 for WCSPH).
    pub solver_iterations: u32,
    /// Worst average density error of the last step's solves (fraction).
    pub density_error: Real,
    pub particle_count: usize,
    /// Positions first, then the requested fields in scene order.
    pub fields: Vec<FieldData>,
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
}

/// A solid's embedded surface as deformed in a frame.
#[derive(Debug, Clone, PartialEq)]
pub struct SolidSurface {
    /// Index of the solid's system in the scene.
    pub system: usize,
    pub mesh: TriMesh,
    /// Unit normal per vertex.
    pub normals: Vec<crate::math::Vector>,
}

/// The particles of one solid in a frame: `count` of them from `first`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SolidRange {
    /// Index of the solid's system in the scene.
    pub system: usize,
    pub first: usize,
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
