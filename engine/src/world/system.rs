//! The systems a world steps, behind one small trait: what the world asks
//! of a fluid or a solid (step, save and restore, the first invalid value,
//! its frame fields, particle removal), implemented by adapters that call
//! each system's own methods, so that the systems never import the world.
//!
//! Adding a kind of system: a variant of [`System`] with its arm in
//! [`System::simulated`] and [`System::simulated_mut`], and an adapter
//! implementing [`Simulated`]. Adding a frame field: its values in each
//! adapter's [`Simulated::write_field`].

// Dispatch over systems and frame fields must name every variant: a new
// kind or field that some arm forgets is a compile-time warning, not a
// silently empty field.
#![warn(clippy::wildcard_enum_match_arm)]

use super::modal::ModalEntry;
use super::watch::EnergyWatch;
use super::{StepError, StepInfo};
use crate::cancel::Cancel;
use crate::fluid::{FluidState, FluidSystem, Invalid};
use crate::frame::FieldKind;
use crate::geometry::TriMesh;
use crate::math::{Real, Vector};
use crate::solid::embedded::EmbeddedSurface;
use crate::solid::{ElasticSolid, SolidState};
use crate::stats::StageTimer;
use crate::surface::SurfaceExtractor;

/// What every system of a step shares: the step's length, gravity and
/// limits, its number (for errors), and the flag that stops it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct StepEnv<'a> {
    /// Time advanced, s.
    pub dt: Real,
    /// m/s^2.
    pub gravity: Vector,
    /// Courant number of the fluid's stability limit.
    pub cfl: Real,
    /// Upper bound on a system's sub-steps.
    pub max_substeps: u32,
    /// The step being taken (steps completed plus one).
    pub step: u64,
    /// Read before every sub-step (and by the solids' solvers); once
    /// raised the system returns [`StepError::Cancelled`].
    pub cancel: &'a Cancel,
}

impl StepEnv<'_> {
    /// The error of this step cancelled.
    pub(crate) fn cancelled(&self) -> StepError {
        StepError::Cancelled { step: self.step }
    }

    /// [`StepError::Cancelled`] once the step's flag is raised.
    pub(crate) fn check(&self) -> Result<(), StepError> {
        self.cancel.check().map_err(|_| self.cancelled())
    }
}

/// Why particles cannot be removed; nothing was marked.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RemoveError {
    /// The index names no system the world steps.
    #[error(
        "systems[{system}] is not a particle system of this world; name the index of the \
         scene's fluid (rigid bodies belong to the fluid)"
    )]
    NoSystem {
        /// The index asked for.
        system: usize,
    },
    /// The system keeps a fixed set of particles.
    #[error(
        "systems[{system}] is {kind}, which cannot remove particles yet; remove particles \
         from the scene's fluid"
    )]
    Unsupported {
        /// Index of the system in the scene.
        system: usize,
        /// What the system is.
        kind: &'static str,
    },
    /// An id is not one of the system's particles.
    #[error(
        "systems[{system}] has no particle with id {particle}: its {count} particles have ids \
         below {count}"
    )]
    NoParticle {
        /// Index of the system in the scene.
        system: usize,
        /// The id asked for.
        particle: usize,
        /// The system's particle count.
        count: usize,
    },
}

/// Particles of one system marked for removal, by id: kept from the
/// request to the start of the next step, where the system drops them all
/// at once.
#[derive(Debug, Clone, Default)]
pub(crate) struct RemovalMask {
    /// One flag per particle id; empty while nothing is marked.
    marked: Vec<bool>,
}

impl RemovalMask {
    /// Marks `ids` of a system of `count` particles, after checking all
    /// of them: on error nothing is marked.
    pub(crate) fn mark(
        &mut self,
        system: usize,
        count: usize,
        ids: &[usize],
    ) -> Result<(), RemoveError> {
        if let Some(&particle) = ids.iter().find(|&&id| id >= count) {
            return Err(RemoveError::NoParticle {
                system,
                particle,
                count,
            });
        }
        if ids.is_empty() {
            return Ok(());
        }
        self.marked.resize(count, false);
        for &id in ids {
            self.marked[id] = true;
        }
        Ok(())
    }

    /// The ids marked, in order.
    pub(crate) fn marked_ids(&self) -> Vec<u32> {
        (0..self.marked.len() as u32)
            .filter(|&id| self.marked[id as usize])
            .collect()
    }

    /// The flags, if anything is marked, leaving the mask empty.
    pub(crate) fn take(&mut self) -> Option<Vec<bool>> {
        (!self.marked.is_empty()).then(|| std::mem::take(&mut self.marked))
    }
}

/// What the world asks of each system.
pub(crate) trait Simulated {
    /// Index of the system in the scene.
    fn index(&self) -> usize;

    /// Particles the system holds: its share of a frame's fields.
    fn particle_count(&self) -> usize;

    /// Between steps: applies the particle removals marked since the last
    /// step and anything else that changes the particle slots.
    fn start_step(&mut self);

    /// Keeps the state a failed step goes back to.
    fn save(&mut self);

    /// Goes back to the state kept by [`Self::save`].
    fn restore(&mut self);

    /// Advances by `env.dt` in sub-steps within the system's stability
    /// limit, checking its state at its chokepoints and `env.cancel`
    /// before each sub-step (and iteration of a solve). A failed or
    /// cancelled step is reported, not undone: the world restores every
    /// system.
    fn step(&mut self, env: &StepEnv, timer: &mut StageTimer) -> Result<StepInfo, StepError>;

    /// The first particle value that left its valid range, if any.
    fn first_invalid(&self) -> Option<Invalid>;

    /// Appends the system's values of a field, `kind.components()` per
    /// particle, in the order frames list its particles.
    fn write_field(&self, kind: FieldKind, out: &mut Vec<f32>);

    /// Appends each particle's stable id, in the order of
    /// [`Self::write_field`].
    fn write_ids(&self, out: &mut Vec<u32>);

    /// Marks particles for removal at the start of the next step.
    fn mark_removed(&mut self, ids: &[usize]) -> Result<(), RemoveError>;
}

/// A system of the world (each boxed: their sizes differ by kilobytes).
#[derive(Debug, Clone)]
pub(crate) enum System {
    /// The scene's fluid, with its rigid bodies.
    Fluid(Box<FluidEntry>),
    /// An elastic solid.
    Solid(Box<SolidEntry>),
    /// A modal EFG solid.
    Modal(Box<ModalEntry>),
}

impl System {
    /// The system behind the trait the world steps it through.
    pub(crate) fn simulated(&self) -> &dyn Simulated {
        match self {
            Self::Fluid(fluid) => fluid.as_ref(),
            Self::Solid(solid) => solid.as_ref(),
            Self::Modal(modal) => modal.as_ref(),
        }
    }

    /// [`Self::simulated`], to step or change it.
    pub(crate) fn simulated_mut(&mut self) -> &mut dyn Simulated {
        match self {
            Self::Fluid(fluid) => fluid.as_mut(),
            Self::Solid(solid) => solid.as_mut(),
            Self::Modal(modal) => modal.as_mut(),
        }
    }
}

/// The fluid of a scene as the world keeps it.
#[derive(Debug, Clone)]
pub(crate) struct FluidEntry {
    /// Index of its system in the scene.
    pub index: usize,
    /// The fluid and its pressure solver.
    pub fluid: FluidSystem,
    /// Fluid state at the start of the current step, restored when the
    /// step fails.
    pub backup: FluidState,
    /// The box its particles stay in (see `Scene::simulation_box`).
    pub bounds: (Vector, Vector),
    /// Meshes the fluid's surface into each frame, when the scene asks.
    pub surface: Option<SurfaceExtractor>,
    /// Particles to remove at the start of the next step.
    pub removal: RemovalMask,
    /// The energy the fluid started from, which it may not exceed.
    pub watch: EnergyWatch,
}

impl FluidEntry {
    /// The surface of the fluid, when the scene asks for one: the colour
    /// field with each particle's volume `m / rho_i` from the last density
    /// pass.
    pub(crate) fn surface_mesh(&self) -> Option<TriMesh> {
        let (surface, fluid) = (self.surface.as_ref()?, self.fluid.fluid());
        let volumes: Vec<Real> = fluid
            .densities
            .iter()
            .map(|&rho| fluid.params.mass / rho)
            .collect();
        Some(surface.extract(&fluid.positions, &volumes))
    }
}

impl Simulated for FluidEntry {
    fn index(&self) -> usize {
        self.index
    }

    fn particle_count(&self) -> usize {
        self.fluid.fluid().len()
    }

    fn start_step(&mut self) {
        if let Some(removed) = self.removal.take() {
            self.fluid.remove(&removed);
            self.watch.restart();
        }
        self.fluid.reorder_if_due();
    }

    fn save(&mut self) {
        self.fluid.save(&mut self.backup);
    }

    fn restore(&mut self) {
        self.fluid.restore(&self.backup);
    }

    /// Sub-steps of at most the fluid's stable step (up to
    /// `env.max_substeps` of them), checked after each; the flag is read
    /// before each.
    fn step(&mut self, env: &StepEnv, timer: &mut StageTimer) -> Result<StepInfo, StepError> {
        let dt = env.dt;
        let mut info = StepInfo::start(dt);
        self.watch.begin(&self.fluid, &env.gravity, &self.bounds);
        let (min, max) = self.bounds;
        let mut elapsed = 0.0;
        while dt - elapsed > dt * 1e-9 {
            env.check()?;
            let remaining = dt - elapsed;
            let limit = self.fluid.stable_dt(env.cfl, &env.gravity);
            let budget = env.max_substeps - info.substeps;
            let wanted = (remaining / limit).ceil().max(1.0);
            if wanted > budget as Real {
                info.capped = true;
            }
            let sub = remaining / wanted.min(budget as Real);
            self.fluid
                .substep(sub, &env.gravity, &min, &max, timer, env.cancel)
                .map_err(|_| env.cancelled())?;
            let solve = self.fluid.fluid().last_solve();
            info.solver_iterations += solve.density_iterations + solve.divergence_iterations;
            info.density_error = info.density_error.max(solve.density_error);
            info.unconverged += solve.unconverged;
            info.substeps += 1;
            info.min_substep = info.min_substep.min(sub);
            elapsed += sub;
            if let Some(invalid) = self.first_invalid() {
                return Err(StepError::Unstable {
                    quantity: invalid.quantity,
                    particle: invalid.particle,
                    value: invalid.value,
                    step: env.step,
                    substep: info.substeps,
                });
            }
        }
        self.watch.check(&self.fluid, &env.gravity, env.step)?;
        Ok(info)
    }

    fn first_invalid(&self) -> Option<Invalid> {
        self.fluid.first_invalid()
    }

    fn write_field(&self, kind: FieldKind, out: &mut Vec<f32>) {
        // Frames list particles by id, whatever order the fluid keeps.
        let fluid = self.fluid.fluid();
        let vectors = |v: &[Vector], out: &mut Vec<f32>| {
            fluid.in_id_order(out, |k| v[k].map(|c| c as f32).into())
        };
        let scalars = |s: &[Real], out: &mut Vec<f32>| fluid.in_id_order(out, |k| [s[k] as f32]);
        match kind {
            FieldKind::Position => vectors(&fluid.positions, out),
            FieldKind::Velocity => vectors(&fluid.velocities, out),
            FieldKind::Density => scalars(&fluid.densities, out),
            FieldKind::Pressure => scalars(&fluid.pressures, out),
            FieldKind::Mass => fluid.in_id_order(out, |_| [fluid.params.mass as f32]),
            FieldKind::Volume => {
                fluid.in_id_order(out, |k| [(fluid.params.mass / fluid.densities[k]) as f32])
            }
            FieldKind::KineticEnergy => fluid.in_id_order(out, |k| {
                [(0.5 * fluid.params.mass * fluid.velocities[k].norm_squared()) as f32]
            }),
            FieldKind::Id => fluid.in_id_order(out, |k| [fluid.ids()[k] as f32]),
            FieldKind::ElasticEnergy => {
                let stored = self.fluid.pressure().has_equation_of_state();
                fluid.in_id_order(out, |k| {
                    let e = if stored {
                        fluid.params.mass * fluid.params.eos.energy(fluid.densities[k])
                    } else {
                        0.0
                    };
                    [e as f32]
                })
            }
        }
    }

    fn write_ids(&self, out: &mut Vec<u32>) {
        let mut ids = self.fluid.fluid().ids().to_vec();
        ids.sort_unstable();
        out.extend(ids);
    }

    fn mark_removed(&mut self, ids: &[usize]) -> Result<(), RemoveError> {
        let count = self.particle_count();
        self.removal.mark(self.index, count, ids)
    }
}

/// An elastic solid of the scene as the world keeps it.
#[derive(Debug, Clone)]
pub(crate) struct SolidEntry {
    /// Index of its system in the scene.
    pub index: usize,
    /// The solid.
    pub solid: ElasticSolid,
    /// Its state at the start of the current step.
    pub backup: SolidState,
    /// Its embedded surface, when the scene asks for one.
    pub surface: Option<EmbeddedSurface>,
    /// The energy the solid started from, which it may not exceed.
    pub watch: EnergyWatch,
}

impl Simulated for SolidEntry {
    fn index(&self) -> usize {
        self.index
    }

    fn particle_count(&self) -> usize {
        self.solid.len()
    }

    /// A solid's particles never change slots.
    fn start_step(&mut self) {}

    fn save(&mut self) {
        self.solid.save(&mut self.backup);
    }

    fn restore(&mut self) {
        self.solid.restore(&self.backup);
    }

    /// The solid sub-steps itself, reading the flag at each sub-step or
    /// Newton and CG iteration; its state is checked after the step.
    fn step(&mut self, env: &StepEnv, _timer: &mut StageTimer) -> Result<StepInfo, StepError> {
        let solid = &self.solid;
        self.watch.begin_with(|| {
            (
                solid.mechanical_energy(&env.gravity, env.dt),
                solid.energy_scale(&env.gravity),
            )
        });
        let step = self
            .solid
            .step_cancellable(env.dt, &env.gravity, env.max_substeps, env.cancel)
            .map_err(|_| env.cancelled())?;
        let info = StepInfo {
            substeps: step.substeps,
            min_substep: step.min_substep,
            capped: step.capped,
            solver_iterations: step.iterations,
            density_error: 0.0,
            solid_iterations: step.iterations,
            solid_residual: step.residual,
            unconverged: u32::from(step.unconverged),
        };
        if let Some(invalid) = self.first_invalid() {
            return Err(StepError::SolidUnstable {
                system: self.index,
                quantity: invalid.quantity,
                particle: invalid.particle,
                value: invalid.value,
                step: env.step,
            });
        }
        if let Some((particle, ratio)) = self.solid.collapsed() {
            return Err(StepError::Collapsed {
                system: self.index,
                particle,
                ratio,
                limit: ElasticSolid::MIN_VOLUME_RATIO,
                advice: self.solid.collapse_advice(),
                step: env.step,
            });
        }
        self.watch.check_solid(
            &self.solid,
            self.index,
            &env.gravity,
            env.dt,
            step.unconverged,
            env.step,
        )?;
        Ok(info)
    }

    fn first_invalid(&self) -> Option<Invalid> {
        let (particle, quantity, value) = self.solid.first_invalid()?;
        Some(Invalid {
            quantity,
            particle,
            value,
        })
    }

    fn write_field(&self, kind: FieldKind, out: &mut Vec<f32>) {
        let solid = &self.solid;
        let vectors = |v: &[Vector], out: &mut Vec<f32>| {
            out.extend(v.iter().flat_map(|x| [x.x as f32, x.y as f32, x.z as f32]));
        };
        match kind {
            FieldKind::Position => vectors(&solid.positions, out),
            FieldKind::Velocity => vectors(&solid.velocities, out),
            FieldKind::Density => out.extend(solid.densities().into_iter().map(|d| d as f32)),
            FieldKind::Pressure => out.extend(solid.pressures().into_iter().map(|p| p as f32)),
            FieldKind::Mass => out.extend(solid.masses().iter().map(|&m| m as f32)),
            FieldKind::Volume => out.extend(
                solid
                    .masses()
                    .iter()
                    .zip(solid.densities())
                    .map(|(m, rho)| (m / rho) as f32),
            ),
            FieldKind::KineticEnergy => out.extend(
                solid
                    .masses()
                    .iter()
                    .zip(&solid.velocities)
                    .map(|(m, v)| (0.5 * m * v.norm_squared()) as f32),
            ),
            FieldKind::ElasticEnergy => {
                out.extend(solid.elastic_energies().into_iter().map(|e| e as f32));
            }
            // Exact below 2^24; frames carry ids as integers.
            FieldKind::Id => out.extend((0..solid.len()).map(|id| id as f32)),
        }
    }

    /// A solid's particles never change: their ids are their indices.
    fn write_ids(&self, out: &mut Vec<u32>) {
        out.extend(0..self.solid.len() as u32);
    }

    fn mark_removed(&mut self, _ids: &[usize]) -> Result<(), RemoveError> {
        Err(RemoveError::Unsupported {
            system: self.index,
            kind: "an elastic solid",
        })
    }
}
