//! The running world: the systems a scene built, the clock, and the step.

use crate::approx::Kernel;
use crate::fluid::{
    BodyState, BoxWalls, DfsphParams, Fluid, FluidParams, FluidState, Motion, Oscillation,
    PressureSolver, RigidBodies, RigidBody, Rotation, Slip, Tait,
};
use crate::frame::{BodyPose, FieldData, Frame, SolidRange, SolidSurface};
use crate::geometry::{Shape, TriMesh};
use crate::math::{Real, Vector, vector};
use crate::neighbors::{Periodic, UniformGrid};
use crate::scene::{
    FieldKind, FluidSpec, MotionKind, RigidBodySpec, Scene, SceneError, ShapeSpec, SlipKind,
    SolverKind, SystemSpec, WallModel, build_solid,
};
use crate::solid::embedded::{DeformedSurface, EmbeddedSurface, EmbeddingMethod};
use crate::solid::{ElasticSolid, Obstacle, SolidState};
use crate::stats::StageTimer;
use crate::surface::SurfaceExtractor;

/// Where a world is in time.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Clock {
    /// Steps completed.
    pub step: u64,
    /// Simulated time, s.
    pub time: Real,
}

/// How the last step was carried out.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepInfo {
    /// Sub-steps the step was split into.
    pub substeps: u32,
    /// Shortest sub-step, s.
    pub min_substep: Real,
    /// Whether `max_substeps` capped the split, so sub-steps exceeded the
    /// stability limit.
    pub capped: bool,
    /// Pressure-solver iterations over all sub-steps (0 for WCSPH).
    pub solver_iterations: u32,
    /// Worst average density error after a sub-step's pressure solve
    /// (fraction of rho_0; 0 for WCSPH).
    pub density_error: Real,
}

/// A step failed; the world is left as it was before the step.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StepError {
    #[error(
        "the {quantity} of particle {particle} left its valid range ({value:e}) in sub-step \
         {substep} of step {step}; the simulation is unstable: lower time.dt, time.cfl or the \
         stiffness, or raise time.max_substeps"
    )]
    Unstable {
        quantity: &'static str,
        particle: usize,
        value: f64,
        step: u64,
        substep: u32,
    },
    #[error(
        "the {quantity} of particle {particle} (of the solid in systems[{system}]) left its \
         valid range ({value:e}) in step {step}; the solid is unstable: lower time.dt or its \
         cfl, raise time.max_substeps, or set integrator = \"implicit\""
    )]
    SolidUnstable {
        system: usize,
        quantity: &'static str,
        particle: usize,
        value: f64,
        step: u64,
    },
}

/// An elastic solid of the scene and its state before the current step.
#[derive(Debug, Clone)]
struct SolidSystem {
    /// Index of its system in the scene.
    system: usize,
    solid: ElasticSolid,
    backup: SolidState,
    /// Its embedded surface, when the scene asks for one.
    surface: Option<EmbeddedSurface>,
}

/// State of one scene: its systems and clock. Stepped by [`World::step`].
#[derive(Debug, Clone)]
pub struct World {
    scene: Scene,
    clock: Clock,
    last_step: StepInfo,
    fluid: Option<Fluid>,
    /// Fluid state at the start of the current step, restored when the
    /// step fails.
    backup: FluidState,
    timer: StageTimer,
    frame_fields: Vec<FieldKind>,
    /// Meshes the fluid's surface into each frame, when the scene asks.
    surface: Option<SurfaceExtractor>,
    solids: Vec<SolidSystem>,
}

impl World {
    /// Builds the world of an already validated scene (see [`Scene::build`]).
    /// `shapes` holds the engine shape of each rigid body by system index.
    pub(crate) fn new(scene: Scene, mut shapes: Vec<Option<Shape>>) -> Self {
        let solids = build_solids(&scene, &shapes);
        // Bodies after the fluid: they take its spacing and kernels.
        let fluid = scene.fluid().map(|spec| {
            let bodies: Vec<(usize, &RigidBodySpec, Shape)> = scene
                .systems
                .iter()
                .enumerate()
                .filter_map(|(s, system)| match system {
                    SystemSpec::RigidBody(body) => Some((s, body, shapes.get_mut(s)?.take()?)),
                    SystemSpec::Fluid(_) | SystemSpec::Solid(_) => None,
                })
                .collect();
            build_fluid(&scene, spec, bodies)
        });
        let surface = match (&scene.output.surface, &fluid, scene.fluid()) {
            (Some(wanted), Some(built), Some(spec)) => {
                let (min, max) = scene.simulation_box(built.params.support_radius);
                Some(
                    SurfaceExtractor::new(
                        built.params.density_kernel,
                        wanted.cell(spec.spacing),
                        wanted.iso,
                        min,
                        max,
                    )
                    .expect("validated by Scene::validate"),
                )
            }
            _ => None,
        };
        let mut frame_fields = vec![FieldKind::Position];
        for &kind in &scene.output.fields {
            if !frame_fields.contains(&kind) {
                frame_fields.push(kind);
            }
        }
        Self {
            scene,
            clock: Clock::default(),
            last_step: StepInfo::default(),
            fluid,
            backup: FluidState::default(),
            timer: StageTimer::default(),
            frame_fields,
            surface,
            solids,
        }
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    pub fn clock(&self) -> Clock {
        self.clock
    }

    pub fn last_step(&self) -> StepInfo {
        self.last_step
    }

    /// Runs and seconds of each pass so far.
    pub fn stages(&self) -> &StageTimer {
        &self.timer
    }

    pub fn fluid(&self) -> Option<&Fluid> {
        self.fluid.as_ref()
    }

    /// The fluid, to set up an initial state a scene cannot describe (a
    /// velocity field, say) before stepping.
    pub fn fluid_mut(&mut self) -> Option<&mut Fluid> {
        self.fluid.as_mut()
    }

    /// Particles of every system: the fluid's, then each solid's in scene
    /// order, the order frames list them in.
    pub fn particle_count(&self) -> usize {
        self.fluid.as_ref().map_or(0, Fluid::len)
            + self.solids.iter().map(|s| s.solid.len()).sum::<usize>()
    }

    /// The elastic solids with their system indices, in scene order.
    pub fn solids(&self) -> impl Iterator<Item = (usize, &ElasticSolid)> {
        self.solids.iter().map(|s| (s.system, &s.solid))
    }

    /// The solid of system `system`, to set up a state a scene cannot
    /// describe (a deformed start, say).
    pub fn solid_mut(&mut self, system: usize) -> Option<&mut ElasticSolid> {
        self.solids
            .iter_mut()
            .find(|s| s.system == system)
            .map(|s| &mut s.solid)
    }

    /// Advances by `scene.time.dt`, split into sub-steps that respect the
    /// stability limit (up to `time.max_substeps`).
    ///
    /// # Errors
    /// [`StepError::Unstable`] when a sub-step produced NaN, infinity or a
    /// runaway speed; the world is then restored to its state before this
    /// step.
    pub fn step(&mut self) -> Result<StepInfo, StepError> {
        let dt = self.scene.time.dt;
        let mut info = StepInfo {
            substeps: 0,
            min_substep: dt,
            capped: false,
            solver_iterations: 0,
            density_error: 0.0,
        };
        if let Some(fluid) = &mut self.fluid {
            fluid.reorder_if_due();
            fluid.save(&mut self.backup);

            let gravity = vector(self.scene.gravity);
            let (min, max) = self.scene.simulation_box(fluid.params.support_radius);
            let time = &self.scene.time;
            let mut elapsed = 0.0;
            while dt - elapsed > dt * 1e-9 {
                let remaining = dt - elapsed;
                let limit = fluid.stable_dt(time.cfl);
                let budget = time.max_substeps - info.substeps;
                let wanted = (remaining / limit).ceil().max(1.0);
                if wanted > budget as Real {
                    info.capped = true;
                }
                let sub = remaining / wanted.min(budget as Real);
                fluid.substep(sub, &gravity, &min, &max, &mut self.timer);
                let solve = fluid.last_solve();
                info.solver_iterations += solve.density_iterations + solve.divergence_iterations;
                info.density_error = info.density_error.max(solve.density_error);
                info.substeps += 1;
                info.min_substep = info.min_substep.min(sub);
                elapsed += sub;
                if let Some(invalid) = fluid.first_invalid() {
                    fluid.restore(&self.backup);
                    return Err(StepError::Unstable {
                        quantity: invalid.quantity,
                        particle: invalid.particle,
                        value: invalid.value,
                        step: self.clock.step + 1,
                        substep: info.substeps,
                    });
                }
            }
        }
        self.step_solids(dt, &mut info)?;
        self.clock.step += 1;
        self.clock.time += dt;
        self.last_step = info;
        Ok(info)
    }

    /// Advances every solid by `dt`; on a blow-up restores all of them
    /// (and the fluid) to the start of the step.
    fn step_solids(&mut self, dt: Real, info: &mut StepInfo) -> Result<(), StepError> {
        let gravity = vector(self.scene.gravity);
        let max_substeps = self.scene.time.max_substeps;
        for s in &mut self.solids {
            s.solid.save(&mut s.backup);
        }
        for k in 0..self.solids.len() {
            let s = &mut self.solids[k];
            let step = s.solid.step(dt, &gravity, max_substeps);
            info.substeps = info.substeps.max(step.substeps);
            info.min_substep = info.min_substep.min(step.min_substep);
            info.capped |= step.capped;
            info.solver_iterations += step.iterations;
            if let Some((particle, quantity, value)) = s.solid.first_invalid() {
                let system = s.system;
                for s in &mut self.solids {
                    s.solid.restore(&s.backup);
                }
                if let Some(fluid) = &mut self.fluid {
                    fluid.restore(&self.backup);
                }
                return Err(StepError::SolidUnstable {
                    system,
                    quantity,
                    particle,
                    value,
                    step: self.clock.step + 1,
                });
            }
        }
        Ok(())
    }

    /// Whether the current step is one the scene publishes a frame for.
    pub fn is_frame_step(&self) -> bool {
        self.clock
            .step
            .is_multiple_of(u64::from(self.scene.output.frame_every))
    }

    /// The fields each frame carries, positions first.
    pub fn frame_fields(&self) -> &[FieldKind] {
        &self.frame_fields
    }

    /// A snapshot of the fields the scene asked for.
    pub fn frame(&self) -> Frame {
        let fields = self
            .frame_fields
            .iter()
            .map(|&kind| FieldData {
                kind,
                components: kind.components(),
                values: self.field_values(kind),
            })
            .collect();
        Frame {
            step: self.clock.step,
            time: self.clock.time,
            substeps: self.last_step.substeps,
            substep_dt: self.last_step.min_substep,
            solver_iterations: self.last_step.solver_iterations,
            density_error: self.last_step.density_error,
            particle_count: self.particle_count(),
            fields,
            bodies: self.body_poses(),
            surface: self.surface_mesh(),
            solids: self.solid_ranges(),
            solid_surfaces: self.solid_surfaces(),
        }
    }

    /// The surface of the fluid, when the scene asks for one: the colour
    /// field with each particle's volume `m / rho_i` from the last density
    /// pass.
    fn surface_mesh(&self) -> Option<TriMesh> {
        let (surface, fluid) = (self.surface.as_ref()?, self.fluid.as_ref()?);
        let volumes: Vec<Real> = fluid
            .densities
            .iter()
            .map(|&rho| fluid.params.mass / rho)
            .collect();
        Some(surface.extract(&fluid.positions, &volumes))
    }

    /// Pose and velocity of every rigid body, in scene order.
    pub fn body_poses(&self) -> Vec<BodyPose> {
        let Some(rigid) = self.fluid.as_ref().and_then(Fluid::bodies) else {
            return Vec::new();
        };
        rigid
            .bodies()
            .iter()
            .map(|b| {
                // The frame the scene gave the shape in, about the centre.
                let q = (b.state.orientation * shape_axes(&b.shape).inverse()).into_inner();
                BodyPose {
                    system: b.system,
                    position: b.state.position.into(),
                    orientation: [q.i, q.j, q.k, q.w],
                    velocity: b.state.velocity.into(),
                    angular_velocity: b.state.angular_velocity.into(),
                }
            })
            .collect()
    }

    /// The deformed surface of every solid that embeds one.
    pub fn solid_surfaces(&self) -> Vec<SolidSurface> {
        let mut gradients = Vec::new();
        self.solids
            .iter()
            .filter_map(|s| {
                let surface = s.surface.as_ref()?;
                if surface.method() == EmbeddingMethod::Gradients {
                    s.solid.displacement_gradients(&mut gradients);
                } else {
                    gradients.clear();
                }
                let mut deformed = DeformedSurface::new();
                // Lengths match by construction: the surface was built
                // from this solid's particles.
                surface
                    .update(&s.solid.positions, &gradients, &mut deformed)
                    .ok()?;
                Some(SolidSurface {
                    system: s.system,
                    mesh: deformed.to_mesh(surface.triangles()),
                    normals: deformed.normals,
                })
            })
            .collect()
    }

    /// Where each solid's particles sit in the frame's fields.
    pub fn solid_ranges(&self) -> Vec<SolidRange> {
        let mut first = self.fluid.as_ref().map_or(0, Fluid::len);
        self.solids
            .iter()
            .map(|s| {
                let range = SolidRange {
                    system: s.system,
                    first,
                    count: s.solid.len(),
                };
                first += range.count;
                range
            })
            .collect()
    }

    fn field_values(&self, kind: FieldKind) -> Vec<f32> {
        let mut values = match &self.fluid {
            // Frames list particles by id, whatever order the fluid keeps.
            Some(fluid) => {
                let vectors = |v: &[Vector]| fluid.in_id_order(|k| v[k].map(|c| c as f32).into());
                let scalars = |s: &[Real]| fluid.in_id_order(|k| [s[k] as f32]);
                match kind {
                    FieldKind::Position => vectors(&fluid.positions),
                    FieldKind::Velocity => vectors(&fluid.velocities),
                    FieldKind::Density => scalars(&fluid.densities),
                    FieldKind::Pressure => scalars(&fluid.pressures),
                }
            }
            None => Vec::new(),
        };
        for s in &self.solids {
            let solid = &s.solid;
            let vectors = |v: &[Vector], out: &mut Vec<f32>| {
                out.extend(v.iter().flat_map(|x| [x.x as f32, x.y as f32, x.z as f32]));
            };
            match kind {
                FieldKind::Position => vectors(&solid.positions, &mut values),
                FieldKind::Velocity => vectors(&solid.velocities, &mut values),
                FieldKind::Density => {
                    values.extend(solid.densities().into_iter().map(|d| d as f32))
                }
                FieldKind::Pressure => {
                    values.extend(solid.pressures().into_iter().map(|p| p as f32))
                }
            }
        }
        values
    }
}

/// The engine shape of a scene's shape (the shape at field `at`); in 2D a
/// box's z extent is unused. Reads mesh files.
///
/// # Errors
/// A mesh that cannot be read or does not bound a solid (see
/// [`crate::scene::mesh_shape`]).
pub(crate) fn body_shape(spec: &ShapeSpec, dim: usize, at: &str) -> Result<Shape, SceneError> {
    Ok(match spec {
        ShapeSpec::Box { half_extents } => Shape::Box {
            half_extents: vector(*half_extents),
        },
        ShapeSpec::Sphere { radius } => Shape::Sphere { radius: *radius },
        ShapeSpec::Capsule {
            half_length,
            radius,
        } => Shape::Capsule {
            half_length: *half_length,
            radius: *radius,
        },
        ShapeSpec::Plane { normal, offset } => {
            let mut n = vector(*normal);
            if dim == 2 {
                n.z = 0.0;
            }
            // Scaling the normal to unit length scales the offset with it.
            let length = n.norm();
            Shape::Plane {
                normal: n / length,
                offset: offset / length,
            }
        }
        ShapeSpec::Mesh { path, scale } => crate::scene::mesh_shape(path, *scale, at)?,
    })
}

/// The rotation from a body's frame to the frame its shape was given in:
/// a mesh's principal axes in its file, the identity for the primitives.
fn shape_axes(shape: &Shape) -> Rotation {
    match shape {
        Shape::Mesh(solid) => solid.axes(),
        _ => Rotation::identity(),
    }
}

/// A body's initial position and orientation; in 2D in the plane z = 0.
/// The scene's orientation turns the shape as given (a mesh as in its
/// file); the body frame is turned further onto the shape's principal axes.
pub(crate) fn body_pose(spec: &RigidBodySpec, shape: &Shape, dim: usize) -> (Vector, Rotation) {
    shape_pose(spec.position, spec.orientation, shape, dim)
}

/// [`body_pose`] from a scene position and rotation vector.
pub(crate) fn shape_pose(
    position: [Real; 3],
    orientation: [Real; 3],
    shape: &Shape,
    dim: usize,
) -> (Vector, Rotation) {
    let mut position = vector(position);
    if dim == 2 {
        position.z = 0.0;
    }
    (
        position,
        Rotation::from_scaled_axis(vector(orientation)) * shape_axes(shape),
    )
}

/// The solids of a validated scene, each colliding with the domain walls
/// and the scene's static rigid bodies.
fn build_solids(scene: &Scene, shapes: &[Option<Shape>]) -> Vec<SolidSystem> {
    let dim = scene.dimension;
    let obstacles: Vec<Obstacle> = scene
        .systems
        .iter()
        .zip(shapes)
        .filter_map(|(system, shape)| match (system, shape) {
            (SystemSpec::RigidBody(body), Some(shape)) if body.motion == MotionKind::Static => {
                let (position, orientation) = body_pose(body, shape, dim);
                Some(Obstacle {
                    shape: shape.clone(),
                    position,
                    orientation,
                })
            }
            _ => None,
        })
        .collect();
    let walls = (vector(scene.domain.min), vector(scene.domain.max));
    scene
        .systems
        .iter()
        .zip(shapes)
        .enumerate()
        .filter_map(|(system, (spec, shape))| match (spec, shape) {
            (SystemSpec::Solid(spec), Some(shape)) => {
                let (solid, surface) = build_solid(spec, shape, dim, walls, obstacles.clone());
                Some(SolidSystem {
                    system,
                    solid,
                    backup: SolidState::default(),
                    surface,
                })
            }
            _ => None,
        })
        .collect()
}

fn build_body(
    system: usize,
    spec: &RigidBodySpec,
    shape: Shape,
    fluid: &FluidSpec,
    dim: usize,
) -> RigidBody {
    let motion = match spec.motion {
        MotionKind::Static => Motion::Static,
        MotionKind::Kinematic => Motion::Kinematic {
            velocity: vector(spec.velocity),
            angular_velocity: vector(spec.angular_velocity),
            oscillation: spec.oscillation.map(|o| Oscillation {
                amplitude: vector(o.amplitude),
                frequency: o.frequency,
            }),
        },
        MotionKind::Dynamic => {
            // Validated: dynamic bodies are bounded and have a density.
            let density = spec.density.unwrap_or(fluid.rest_density);
            Motion::Dynamic {
                mass: density * shape.volume(dim).unwrap_or(0.0),
                inertia: shape.inertia(density, dim).unwrap_or_else(Vector::zeros),
            }
        }
    };
    let slip = match spec.slip {
        SlipKind::Free => Slip::Free,
        SlipKind::No => Slip::No {
            viscosity: spec.viscosity.unwrap_or(fluid.viscosity),
        },
    };
    let (position, orientation) = body_pose(spec, &shape, dim);
    let velocity = if spec.motion == MotionKind::Dynamic {
        vector(spec.velocity)
    } else {
        Vector::zeros()
    };
    let state = BodyState {
        position,
        orientation,
        velocity,
        angular_velocity: if spec.motion == MotionKind::Dynamic {
            vector(spec.angular_velocity)
        } else {
            Vector::zeros()
        },
        time: 0.0,
    };
    RigidBody::new(shape, motion, slip, spec.hollow, system, dim, state)
}

fn build_fluid(
    scene: &Scene,
    spec: &FluidSpec,
    body_specs: Vec<(usize, &RigidBodySpec, Shape)>,
) -> Fluid {
    let h = spec.support_radius();
    let dim = scene.dimension;
    let density_kernel = Kernel::new(spec.density_kernel, dim, h);
    let gradient_kernel = Kernel::new(spec.gradient_kernel, dim, h);
    let params = FluidParams {
        support_radius: h,
        density_kernel,
        gradient_kernel,
        eos: Tait {
            stiffness: spec.stiffness,
            gamma: spec.gamma,
            rest_density: spec.rest_density,
            negative_scale: spec.negative_pressure_scale,
        },
        xsph: spec.xsph,
        viscosity: spec.viscosity,
        viscosity_model: spec.viscosity_model,
        mass: FluidParams::lattice_mass(spec.spacing, &density_kernel, spec.rest_density),
        spacing: spec.spacing,
        solver: match spec.solver {
            SolverKind::Wcsph => PressureSolver::Wcsph,
            SolverKind::Dfsph => PressureSolver::Dfsph(DfsphParams {
                density_tolerance: spec.density_tolerance,
                divergence_tolerance: spec.divergence_tolerance,
                max_iterations: spec.max_solver_iterations,
            }),
        },
    };
    let (min, max) = scene.simulation_box(h);
    let periodic_axes = scene.periodic_axes();
    let walls = match spec.walls {
        WallModel::Solid => Some(
            BoxWalls::new(
                min,
                max,
                spec.spacing,
                params.mass,
                &density_kernel,
                &gradient_kernel,
            )
            .without_axes(periodic_axes),
        ),
        WallModel::Reflect => None,
    };
    let bodies: Vec<RigidBody> = body_specs
        .into_iter()
        .map(|(s, body, shape)| build_body(s, body, shape, spec, dim))
        .collect();
    // Bodies carve the fluid blocks: no particle starts within half a
    // spacing of a body's surface or inside it.
    let clear = 0.5 * spec.spacing;
    let (positions, velocities): (Vec<Vector>, Vec<Vector>) = spec
        .lattice(dim)
        .map(|(x, block)| (vector(x), vector(spec.blocks[block].velocity)))
        .chain(spec.particles.iter().map(|p| {
            let (mut x, mut v) = (vector(p.position), vector(p.velocity));
            if dim == 2 {
                (x.z, v.z) = (0.0, 0.0);
            }
            (x, v)
        }))
        .filter(|(x, _)| bodies.iter().all(|b| b.excluded_distance(x) >= clear))
        .unzip();
    let grid = UniformGrid::with_periodic(min, max, h, periodic_axes)
        .expect("validated by Scene::validate");
    let periodic = Periodic::new(min, max, periodic_axes);
    let mut fluid = Fluid::new(params, positions, velocities, walls, grid.clone(), periodic);
    if !bodies.is_empty() {
        fluid.attach_bodies(RigidBodies::new(bodies, &params, &min, &max, grid));
    }
    fluid
}
