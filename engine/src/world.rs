//! The running world: the systems a scene built, the clock, and the step.

use crate::approx::Kernel;
use crate::fluid::{BoxWalls, DfsphParams, Fluid, FluidParams, FluidState, PressureSolver, Tait};
use crate::frame::{FieldData, Frame};
use crate::geometry::TriMesh;
use crate::math::{Real, Vector, vector};
use crate::neighbors::UniformGrid;
use crate::scene::{FieldKind, FluidSpec, Scene, SolverKind, SystemSpec, WallModel};
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
}

impl World {
    /// Builds the world of an already validated scene (see [`Scene::build`]).
    pub(crate) fn new(scene: Scene) -> Self {
        let mut fluid = None;
        let mut surface = None;
        for system in &scene.systems {
            match system {
                SystemSpec::Fluid(spec) => {
                    let built = build_fluid(&scene, spec);
                    if let Some(wanted) = &scene.output.surface {
                        let (min, max) = scene.simulation_box(built.params.support_radius);
                        surface = Some(
                            SurfaceExtractor::new(
                                built.params.density_kernel,
                                wanted.cell(spec.spacing),
                                wanted.iso,
                                min,
                                max,
                            )
                            .expect("validated by Scene::validate"),
                        );
                    }
                    fluid = Some(built);
                }
            }
        }
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

    pub fn particle_count(&self) -> usize {
        self.fluid.as_ref().map_or(0, Fluid::len)
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
        self.clock.step += 1;
        self.clock.time += dt;
        self.last_step = info;
        Ok(info)
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
            surface: self.surface_mesh(),
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

    fn field_values(&self, kind: FieldKind) -> Vec<f32> {
        let Some(fluid) = &self.fluid else {
            return Vec::new();
        };
        let vectors = |v: &[Vector]| v.iter().flat_map(|p| p.iter().map(|&c| c as f32)).collect();
        let scalars = |s: &[Real]| s.iter().map(|&c| c as f32).collect();
        match kind {
            FieldKind::Position => vectors(&fluid.positions),
            FieldKind::Velocity => vectors(&fluid.velocities),
            FieldKind::Density => scalars(&fluid.densities),
            FieldKind::Pressure => scalars(&fluid.pressures),
        }
    }
}

fn build_fluid(scene: &Scene, spec: &FluidSpec) -> Fluid {
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
    let walls = match spec.walls {
        WallModel::Solid => Some(BoxWalls::new(
            min,
            max,
            spec.spacing,
            params.mass,
            &density_kernel,
            &gradient_kernel,
        )),
        WallModel::Reflect => None,
    };
    let (positions, velocities): (Vec<Vector>, Vec<Vector>) = spec
        .lattice(dim)
        .map(|(x, block)| (vector(x), vector(spec.blocks[block].velocity)))
        .unzip();
    let grid = UniformGrid::new(min, max, h).expect("validated by Scene::validate");
    Fluid::new(params, positions, velocities, walls, grid)
}
