//! A scene's elastic solid as the object of a design: its shape sampled
//! by design particles, its embedded surface and its simulation particles
//! following the designed field, so a result plays back through the
//! world's normal frames.

use super::body::{DesignBody, Embedding};
use super::constraints::Context;
use super::{DesignError, DesignParams};
use crate::frame::{Frame, SolidSurface};
use crate::geometry::Shape;
use crate::math::{Real, Vector};
use crate::scene::{SystemSpec, solid_defaults};
use crate::solid::embedded::{DeformedSurface, EmbeddedSurface};
use crate::world::World;

/// What constraints on `world`'s scene are checked against.
pub fn context(world: &World) -> Context {
    let mut solids = vec![None; world.scene().systems.len()];
    for (system, solid) in world.solids() {
        solids[system] = Some(solid.len());
    }
    Context {
        dim: world.scene().dimension,
        solids,
    }
}

/// A solid of a world set up for design.
#[derive(Debug)]
pub struct DesignTarget {
    system: usize,
    body: DesignBody,
    surface: Option<EmbeddedSurface>,
    /// The simulation particles' shape functions.
    particles: Embedding,
}

impl DesignTarget {
    /// Samples solid `system` of `world` at rest.
    ///
    /// # Errors
    /// [`DesignError::Parameter`] when `system` is not an elastic solid,
    /// and the errors of [`DesignBody::new`] and [`DesignBody::embed`].
    pub fn new(world: &World, system: usize, params: &DesignParams) -> Result<Self, DesignError> {
        let scene = world.scene();
        let dim = scene.dimension;
        let not_solid = || DesignError::Parameter {
            field: "system",
            message: format!(
                "system {system} is not an elastic solid of this scene; design one of its \
                 solids"
            ),
        };
        let Some(spec) = scene.systems.get(system).and_then(SystemSpec::as_solid) else {
            return Err(not_solid());
        };
        let solid = world
            .solids()
            .find(|(s, _)| *s == system)
            .map(|(_, solid)| solid)
            .ok_or_else(not_solid)?;
        let at = format!("systems[{system}].shape");
        let shape = crate::scene::body_shape(&spec.shape, dim, &at).map_err(|e| {
            DesignError::Parameter {
                field: "shape",
                message: e.to_string(),
            }
        })?;
        let (centre, rotation) =
            crate::scene::shape_pose(spec.position, spec.orientation, &shape, dim);
        let rest = solid.rest_positions().to_vec();
        let body = DesignBody::new(
            &shape,
            centre,
            rotation.to_rotation_matrix(),
            dim,
            params,
            Some((system, rest.clone())),
        )?;
        let particles = body.embed(&rest)?;
        let subdivisions = spec
            .surface
            .as_ref()
            .map_or(solid_defaults::SURFACE_SUBDIVISIONS, |s| s.subdivisions);
        let surface = match (&shape, dim) {
            (Shape::Capsule { .. } | Shape::Plane { .. }, _) | (_, 2) => None,
            _ => spec
                .surface_mesh(&shape, dim, subdivisions)
                .map(|mesh| body.surface(&mesh))
                .transpose()?,
        };
        Ok(Self {
            system,
            body,
            surface,
            particles,
        })
    }

    /// The index of the designed solid's system in the scene.
    pub fn system(&self) -> usize {
        self.system
    }

    /// The design particles sampled in the solid's shape and their field.
    pub fn body(&self) -> &DesignBody {
        &self.body
    }

    /// The surface deformed by the design displacements `u` (3D shapes
    /// with a surface).
    pub fn surface(&self, u: &[Vector]) -> Option<SolidSurface> {
        let surface = self.surface.as_ref()?;
        let positions: Vec<Vector> = self.body.rest().iter().zip(u).map(|(x, u)| x + u).collect();
        let mut deformed = DeformedSurface::new();
        surface.update(&positions, &[], &mut deformed).ok()?;
        Some(SolidSurface {
            system: self.system,
            mesh: deformed.to_mesh(surface.triangles()),
            normals: deformed.normals,
        })
    }

    /// `world`'s current frame with this solid posed by `u`, stamped with
    /// the design time `time`: playback through the normal frame stream.
    pub fn frame(&self, world: &World, u: &[Vector], time: Real) -> Frame {
        let mut frame = world.frame();
        frame.time = time;
        let mut posed = Vec::new();
        self.particles.deform(u, &mut posed);
        if let (Some(range), Some(positions)) = (
            frame.solids.iter().find(|r| r.system == self.system),
            frame.fields.first_mut(),
        ) {
            for (k, x) in posed.iter().enumerate() {
                let at = (range.first + k) * 3;
                for a in 0..3 {
                    positions.values[at + a] = x[a] as f32;
                }
            }
        }
        if let Some(surface) = self.surface(u) {
            frame.solid_surfaces.retain(|s| s.system != self.system);
            frame.solid_surfaces.push(surface);
            frame.solid_surfaces.sort_by_key(|s| s.system);
        }
        frame
    }
}
