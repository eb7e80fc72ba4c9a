//! Scene -> world: the runtime systems of a validated scene, and only
//! those it names. The scene is data and never imports the world, so
//! [`Scene::build`] lives here.

use super::modal::ModalEntry;
use super::system::{FluidEntry, RemovalMask, SolidEntry, System};
use super::watch::EnergyWatch;
use super::{Clock, StepInfo, World};
use crate::approx::Kernel;
use crate::expression::VectorField;
use crate::fluid::{
    BoxWalls, Dfsph, DfsphParams, FluidParams, FluidState, FluidSystem, Pressure, Tait, Wcsph,
};
use crate::frame::FieldKind;
use crate::geometry::Shape;
use crate::math::{Vector, vector};
use crate::neighbors::{Periodic, UniformGrid};
use crate::rigid::{BodyState, Motion, Oscillation, RigidBodies, RigidBody, Slip};
use crate::scene::{
    BuildOptions, Checked, FluidSpec, MotionKind, Prepared, RigidBodySpec, SampledSolid, Scene,
    SceneError, SlipKind, SolidSpec, SolverKind, SystemSpec, WallModel, body_pose,
};
use crate::solid::embedded::EmbeddedSurface;
use crate::solid::{ElasticSolid, Obstacle, Obstacles, SolidState};
use crate::stats::StageTimer;
use crate::surface::SurfaceExtractor;

impl Scene {
    /// Validates the scene and builds its world: only the systems and
    /// fields the scene names.
    ///
    /// # Errors
    /// See [`Scene::validate`].
    pub fn build(&self, options: &BuildOptions) -> Result<World, SceneError> {
        self.clone().check(options).map(Checked::build)
    }
}

impl Checked {
    /// Builds the world of the checked scene.
    pub fn build(self) -> World {
        World::new(self.scene, self.systems)
    }
}

impl World {
    /// Builds the world of an already validated scene (see [`Scene::build`])
    /// from what its check made of each system, by system index.
    fn new(scene: Scene, mut prepared: Vec<Prepared>) -> Self {
        let solids = build_solids(&scene, &mut prepared);
        let modal = build_modal_solids(&scene, &mut prepared);
        // Bodies after the fluid: they take its spacing and kernels.
        let fluid = scene
            .systems
            .iter()
            .enumerate()
            .find_map(|(index, system)| {
                let SystemSpec::Fluid(spec) = system else {
                    return None;
                };
                let bodies: Vec<(usize, &RigidBodySpec, Shape)> = scene
                    .systems
                    .iter()
                    .enumerate()
                    .filter_map(|(s, system)| match system {
                        SystemSpec::RigidBody(body) => {
                            match prepared.get_mut(s).map(std::mem::take) {
                                Some(Prepared::Body(shape)) => Some((s, body, shape)),
                                _ => None,
                            }
                        }
                        SystemSpec::Fluid(_) | SystemSpec::Solid(_) | SystemSpec::ModalSolid(_) => {
                            None
                        }
                    })
                    .collect();
                Some(build_fluid(&scene, index, spec, bodies))
            });
        let mut frame_fields = vec![FieldKind::Position];
        for &kind in &scene.output.fields {
            if !frame_fields.contains(&kind) {
                frame_fields.push(kind);
            }
        }
        // Step order: the fluid first, then the solids in scene order.
        let mut solids: Vec<System> = solids
            .into_iter()
            .map(|solid| System::Solid(Box::new(solid)))
            .chain(modal.into_iter().map(|m| System::Modal(Box::new(m))))
            .collect();
        solids.sort_by_key(|s| s.simulated().index());
        let systems = fluid
            .map(|fluid| System::Fluid(Box::new(fluid)))
            .into_iter()
            .chain(solids)
            .collect();
        Self {
            scene,
            clock: Clock::default(),
            last_step: StepInfo::default(),
            timer: StageTimer::default(),
            frame_fields,
            systems,
        }
    }
}

/// The solids of a validated scene (taking their particles and surfaces
/// from `prepared`), each colliding with the domain walls and the scene's
/// static rigid bodies.
fn build_solids(scene: &Scene, prepared: &mut [Prepared]) -> Vec<SolidEntry> {
    let dim = scene.dimension;
    let obstacles: Vec<Obstacle> = scene
        .systems
        .iter()
        .zip(prepared.iter())
        .filter_map(|(system, prepared)| match (system, prepared) {
            (SystemSpec::RigidBody(body), Prepared::Body(shape))
                if body.motion == MotionKind::Static =>
            {
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
        .zip(prepared.iter_mut())
        .enumerate()
        .filter_map(|(system, (spec, prepared))| {
            let SystemSpec::Solid(spec) = spec else {
                return None;
            };
            let Prepared::Solid(sampled) = std::mem::take(prepared) else {
                return None;
            };
            let (solid, surface) = build_solid(spec, sampled, dim, walls, obstacles.clone());
            Some(SolidEntry {
                index: system,
                solid,
                backup: SolidState::default(),
                surface,
                watch: EnergyWatch::default(),
            })
        })
        .collect()
}

/// The modal solids of a validated scene, taken from `prepared` (their
/// check built them).
fn build_modal_solids(scene: &Scene, prepared: &mut [Prepared]) -> Vec<ModalEntry> {
    scene
        .systems
        .iter()
        .zip(prepared.iter_mut())
        .enumerate()
        .filter_map(|(index, (spec, prepared))| {
            let SystemSpec::ModalSolid(spec) = spec else {
                return None;
            };
            let Prepared::Modal(solid) = std::mem::take(prepared) else {
                return None;
            };
            Some(ModalEntry {
                index,
                backup: solid.state(),
                scene_grabs: solid.grabs().to_vec(),
                solid: *solid,
                playback: spec.playback,
                watch: EnergyWatch::default(),
            })
        })
        .collect()
}

/// Builds the engine solid of a validated spec from the particles and
/// surface its check made, colliding with the domain's walls and
/// `obstacles`.
fn build_solid(
    spec: &SolidSpec,
    sampled: SampledSolid,
    dim: usize,
    walls: (Vector, Vector),
    obstacles: Vec<Obstacle>,
) -> (ElasticSolid, Option<EmbeddedSurface>) {
    let (rest, velocities): (Vec<Vector>, Vec<Vector>) = sampled.particles.into_iter().unzip();
    let fixed = rest.iter().map(|x| spec.anchored(x, dim)).collect();
    let obstacles = Obstacles {
        shapes: obstacles,
        walls: Some(walls),
    };
    let surface = sampled.surface;
    let solid = ElasticSolid::new(spec.params(dim), rest, velocities, fixed, obstacles)
        .expect("validated by Scene::validate");
    (solid, surface)
}

/// The rigid body of system `system`, coupled to `fluid`.
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

/// The fluid of a validated scene (system `index`) with its rigid bodies.
fn build_fluid(
    scene: &Scene,
    index: usize,
    spec: &FluidSpec,
    body_specs: Vec<(usize, &RigidBodySpec, Shape)>,
) -> FluidEntry {
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
    };
    let pressure = match spec.solver {
        SolverKind::Wcsph => Pressure::Wcsph(Wcsph),
        SolverKind::Dfsph => Pressure::Dfsph(Box::new(Dfsph::new(DfsphParams {
            density_tolerance: spec.density_tolerance,
            divergence_tolerance: spec.divergence_tolerance,
            max_iterations: spec.max_solver_iterations,
        }))),
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
        )
        .map(|walls| match spec.wall_slip {
            SlipKind::Free => walls,
            SlipKind::No => {
                let velocity = spec
                    .wall_velocity
                    .by_wall()
                    .map(|sides| sides.map(|(_, v)| v.map_or(Vector::zeros(), vector)));
                walls.with_friction(
                    spec.spacing,
                    params.mass,
                    &gradient_kernel,
                    spec.viscosity_model,
                    velocity,
                )
            }
        }),
        WallModel::Reflect => None,
    };
    let parse = |texts: &Option<[String; 3]>| {
        texts
            .as_ref()
            .map(|t| VectorField::parse(t).expect("validated by Scene::check"))
    };
    let velocity_field = parse(&spec.velocity_field);
    let bodies: Vec<RigidBody> = body_specs
        .into_iter()
        .map(|(s, body, shape)| build_body(s, body, shape, spec, dim))
        .collect();
    // Bodies carve the fluid blocks: no particle starts within half a
    // spacing of a body's surface or inside it.
    let clear = 0.5 * spec.spacing;
    let (positions, velocities): (Vec<Vector>, Vec<Vector>) = spec
        .lattice(dim)
        .map(|(x, block)| {
            let x = vector(x);
            let v = velocity_field
                .as_ref()
                .map_or(vector(spec.blocks[block].velocity), |field| field.eval(&x));
            (x, v)
        })
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
    let mut fluid = FluidSystem::new(
        params,
        pressure,
        positions,
        velocities,
        walls,
        grid.clone(),
        periodic,
    );
    if let Some(force) = parse(&spec.body_force) {
        fluid.set_body_force(force);
    }
    if !bodies.is_empty() {
        fluid.attach_bodies(RigidBodies::new(
            bodies,
            &params.boundary(),
            &min,
            &max,
            grid,
        ));
    }
    let surface = scene.output.surface.as_ref().map(|wanted| {
        SurfaceExtractor::new(
            params.density_kernel,
            wanted.cell(spec.spacing),
            wanted.iso,
            min,
            max,
        )
        .expect("validated by Scene::validate")
    });
    FluidEntry {
        index,
        fluid,
        backup: FluidState::default(),
        bounds: (min, max),
        surface,
        removal: RemovalMask::default(),
        watch: EnergyWatch::default(),
    }
}
