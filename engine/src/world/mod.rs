//! The running world: the systems a scene built, the clock, and the step.
//!
//! `system.rs` holds the systems (the fluid, the elastic solids) behind
//! one small trait, each addressed by its index in the scene, with the
//! removal masks of systems whose particle counts change; `build.rs`
//! turns a scene into a world. A step runs in named stages: between-step
//! changes of the particle slots (removals, sorting), then each system in
//! turn (the fluid first, then the solids in scene order), then the clock.

mod build;
mod modal;
mod state;
mod system;
#[cfg(test)]
mod tests;
pub mod watch;

pub use state::{StateError, SystemState, WorldState};
pub use system::RemoveError;

use crate::cancel::Cancel;
use crate::efg::{Grab, GrabError, ModalSolid};
use crate::fluid::Fluid;
use crate::frame::{BodyPose, FieldData, FieldKind, Frame, SolidRange, SolidSurface};
use crate::math::{Real, vector};
use crate::scene::{Scene, shape_axes};
use crate::solid::ElasticSolid;
use crate::solid::embedded::{DeformedSurface, EmbeddingMethod};
use crate::stats::StageTimer;
use system::{FluidEntry, StepEnv, System};

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
    /// Of `solver_iterations`, the implicit solids' Newton and CG
    /// iterations.
    pub solid_iterations: u32,
    /// The implicit solids' worst final Newton residual (relative; see
    /// `SolidStep::residual`).
    pub solid_residual: Real,
    /// Solves that stopped at their iteration cap above their tolerance:
    /// DFSPH pressure solves and implicit solids' Newton solves. Nonzero
    /// means the step is not as accurate as the scene asked.
    pub unconverged: u32,
}

impl StepInfo {
    /// A step of `dt` before any system took part in it.
    fn start(dt: Real) -> Self {
        Self {
            substeps: 0,
            min_substep: dt,
            capped: false,
            solver_iterations: 0,
            density_error: 0.0,
            solid_iterations: 0,
            solid_residual: 0.0,
            unconverged: 0,
        }
    }

    /// Adds one system's share: the most sub-steps and the shortest of
    /// any system, the iterations of all.
    fn merge(&mut self, system: &StepInfo) {
        self.substeps = self.substeps.max(system.substeps);
        self.min_substep = self.min_substep.min(system.min_substep);
        self.capped |= system.capped;
        self.solver_iterations += system.solver_iterations;
        self.density_error = self.density_error.max(system.density_error);
        self.solid_iterations += system.solid_iterations;
        self.solid_residual = self.solid_residual.max(system.solid_residual);
        self.unconverged += system.unconverged;
    }
}

/// A step failed; the world is left as it was before the step.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StepError {
    /// The fluid blew up.
    #[error(
        "the {quantity} of particle {particle} left its valid range ({value:e}) in sub-step \
         {substep} of step {step}; the simulation is unstable: lower time.dt, time.cfl or the \
         stiffness, or raise time.max_substeps"
    )]
    Unstable {
        /// What left its range ("position", "velocity", ...).
        quantity: &'static str,
        /// The particle's id (or a body's index among the fluid's bodies).
        particle: usize,
        /// The offending value (a norm for vectors).
        value: f64,
        /// The step that failed.
        step: u64,
        /// The sub-step of it that failed, from 1.
        substep: u32,
    },
    /// An elastic solid blew up.
    #[error(
        "the {quantity} of particle {particle} (of the solid in systems[{system}]) left its \
         valid range ({value:e}) in step {step}; the solid is unstable: lower time.dt or its \
         cfl, raise time.max_substeps, or set integrator = \"implicit\""
    )]
    SolidUnstable {
        /// Index of the solid's system in the scene.
        system: usize,
        /// What left its range ("position", "velocity", ...).
        quantity: &'static str,
        /// The particle, in the solid's order.
        particle: usize,
        /// The offending value (a norm for vectors).
        value: f64,
        /// The step that failed.
        step: u64,
    },
    /// An elastic solid's particle was squeezed to a sliver of its volume
    /// or turned inside out ([`crate::solid::ElasticSolid::MIN_VOLUME_RATIO`]).
    #[error(
        "particle {particle} of the solid in systems[{system}] was squeezed to {ratio:.3} of its \
         volume in step {step} (below the {limit} a solid allows; 0 or less is inside out): the \
         solid collapsed; {advice}"
    )]
    Collapsed {
        /// Index of the solid's system in the scene.
        system: usize,
        /// The particle, in the solid's order.
        particle: usize,
        /// Its volume ratio `det F`.
        ratio: f64,
        /// The smallest ratio allowed.
        limit: f64,
        /// What to change, for the solid's material.
        advice: &'static str,
        /// The step that failed.
        step: u64,
    },
    /// A fluid particle was compressed beyond the band a fluid allows
    /// ([`watch::MAX_COMPRESSION`]).
    #[error(
        "the density of fluid particle {particle} reached {ratio:.3} times the rest density in \
         step {step}, beyond the {limit} a fluid allows: the pressure solve is not holding the \
         fluid; lower time.dt or raise time.max_substeps, raise the stiffness (wcsph) or lower \
         density_tolerance (dfsph)"
    )]
    Compressed {
        /// The particle's id.
        particle: usize,
        /// Its density over the rest density.
        ratio: Real,
        /// The largest ratio allowed.
        limit: Real,
        /// The step that failed.
        step: u64,
    },
    /// The fluid gained mechanical energy with nothing to supply it
    /// ([`watch::MAX_ENERGY_GAIN`]).
    #[error(
        "the fluid's mechanical energy rose by {gained:.3e} J since it started ({:.1} % of its \
         scale, beyond the {:.0} % allowed) in step {step}, with no moving wall or body to supply \
         it: the scheme is adding energy; {advice}", 100.0 * fraction, 100.0 * limit
    )]
    EnergyGained {
        /// Joules gained (per metre of depth in 2D).
        gained: Real,
        /// What to change, for the fluid's pressure solver.
        advice: &'static str,
        /// The gain as a fraction of the energy scale.
        fraction: Real,
        /// The largest fraction allowed.
        limit: Real,
        /// The step that failed.
        step: u64,
    },
    /// An elastic solid gained mechanical energy with nothing to supply it
    /// ([`watch::MAX_ENERGY_GAIN`]).
    #[error(
        "the solid in systems[{system}] gained {gained:.3e} J of mechanical energy since it \
         started ({:.1} % of its scale, beyond the {:.0} % allowed) in step {step}: the step is \
         adding energy; {advice}", 100.0 * fraction, 100.0 * limit
    )]
    SolidEnergyGained {
        /// Index of the solid's system in the scene.
        system: usize,
        /// Joules gained (per metre of depth in 2D).
        gained: Real,
        /// The gain as a fraction of the energy scale.
        fraction: Real,
        /// The largest fraction allowed.
        limit: Real,
        /// What to change, for the solid's integrator and its solve.
        advice: &'static str,
        /// The step that failed.
        step: u64,
    },
    /// The step's [`Cancel`] was raised before it finished (see
    /// [`World::step_cancellable`]): not a fault, the step can be taken
    /// again.
    #[error("step {step} was cancelled before it finished; the world is as it was before the step")]
    Cancelled {
        /// The step that was cancelled (steps completed plus one).
        step: u64,
    },
    /// The step counter is at its largest value (a restored snapshot can
    /// put it there): one more step would wrap it to 0, and frames,
    /// checkpoints and progress would count from there. Refused before
    /// anything changes.
    #[error(
        "the world is at step {step}, the largest step count there is, and takes no more steps \
         (the counter never wraps); reset the session or restore an earlier snapshot"
    )]
    CounterFull {
        /// The step the world is at: [`u64::MAX`].
        step: u64,
    },
}

/// Why grabs were refused; the previous ones stay.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GrabsError {
    /// The system is not a modal solid.
    #[error(
        "systems[{system}] is not a modal solid of this world; grabs hold points of a system \
         with kind = \"modal_solid\""
    )]
    NotModal {
        /// The index asked for.
        system: usize,
    },
    /// The solid refused a grab.
    #[error("systems[{system}]: {source}")]
    Grab {
        /// The solid's index.
        system: usize,
        /// Why.
        source: GrabError,
    },
}

/// State of one scene: its systems and clock. Stepped by [`World::step`].
#[derive(Debug, Clone)]
pub struct World {
    scene: Scene,
    clock: Clock,
    last_step: StepInfo,
    timer: StageTimer,
    frame_fields: Vec<FieldKind>,
    /// The systems in step order, which is also the order frames list
    /// their particles in: the fluid first, then each solid in scene
    /// order.
    systems: Vec<System>,
}

impl World {
    /// The scene the world was built from.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Steps completed and simulated time.
    pub fn clock(&self) -> Clock {
        self.clock
    }

    /// How the last step was carried out.
    pub fn last_step(&self) -> StepInfo {
        self.last_step
    }

    /// Runs and seconds of each pass so far.
    pub fn stages(&self) -> &StageTimer {
        &self.timer
    }

    /// The fluid, if the scene has one.
    pub fn fluid(&self) -> Option<&Fluid> {
        self.fluid_entry().map(|f| f.fluid.fluid())
    }

    /// The fluid, to set up an initial state a scene cannot describe (a
    /// velocity field, say) before stepping.
    pub fn fluid_mut(&mut self) -> Option<&mut Fluid> {
        self.systems.iter_mut().find_map(|s| match s {
            System::Fluid(f) => Some(f.fluid.fluid_mut()),
            System::Solid(_) | System::Modal(_) => None,
        })
    }

    /// Particles of every system: the fluid's, then each solid's in scene
    /// order, the order frames list them in.
    pub fn particle_count(&self) -> usize {
        self.systems
            .iter()
            .map(|s| s.simulated().particle_count())
            .sum()
    }

    /// The elastic solids with their system indices, in scene order.
    pub fn solids(&self) -> impl Iterator<Item = (usize, &ElasticSolid)> {
        self.systems.iter().filter_map(|s| match s {
            System::Solid(s) => Some((s.index, &s.solid)),
            System::Fluid(_) | System::Modal(_) => None,
        })
    }

    /// The modal solids with their system indices, in scene order.
    pub fn modal_solids(&self) -> impl Iterator<Item = (usize, &ModalSolid)> {
        self.systems.iter().filter_map(|s| match s {
            System::Modal(m) => Some((m.index, &m.solid)),
            System::Fluid(_) | System::Solid(_) => None,
        })
    }

    /// Holds `grabs` on the modal solid of system `system` besides the
    /// scene's own (Section 5.3.3), replacing those set before; they act
    /// from the next step.
    ///
    /// # Errors
    /// [`GrabsError`] when `system` is not a modal solid or a grab is
    /// refused; the previous grabs then stay.
    pub fn set_grabs(&mut self, system: usize, grabs: &[Grab]) -> Result<(), GrabsError> {
        match self.system_mut(system) {
            Some(System::Modal(m)) => m
                .set_grabs(grabs)
                .map_err(|source| GrabsError::Grab { system, source }),
            _ => Err(GrabsError::NotModal { system }),
        }
    }

    /// [`Self::set_grabs`] for every modal solid at once, all or nothing:
    /// `grabs` by system (a modal solid it does not name holds only the
    /// scene's grabs).
    ///
    /// # Errors
    /// [`GrabsError`] for the first system refused; every solid then
    /// keeps the grabs it had.
    pub fn set_all_grabs(
        &mut self,
        grabs: &std::collections::BTreeMap<usize, Vec<Grab>>,
    ) -> Result<(), GrabsError> {
        if let Some(&system) = grabs
            .keys()
            .find(|s| !self.modal_solids().any(|(m, _)| m == **s))
        {
            return Err(GrabsError::NotModal { system });
        }
        let mut done: Vec<(usize, Vec<Grab>)> = Vec::new();
        for system in &mut self.systems {
            let System::Modal(m) = system else { continue };
            let before = m.extra_grabs().to_vec();
            let wanted = grabs.get(&m.index).map_or(&[][..], Vec::as_slice);
            if let Err(source) = m.set_grabs(wanted) {
                let failed = m.index;
                for (index, previous) in done {
                    if let Some(System::Modal(m)) = self.system_mut(index) {
                        // They held before: they hold again.
                        let _ = m.set_grabs(&previous);
                    }
                }
                return Err(GrabsError::Grab {
                    system: failed,
                    source,
                });
            }
            done.push((m.index, before));
        }
        Ok(())
    }

    /// The solid of system `system`, to set up a state a scene cannot
    /// describe (a deformed start, say).
    pub fn solid_mut(&mut self, system: usize) -> Option<&mut ElasticSolid> {
        match self.system_mut(system)? {
            System::Solid(s) => {
                // An edited state is a new start for the energy watch.
                s.watch.restart();
                Some(&mut s.solid)
            }
            System::Fluid(_) | System::Modal(_) => None,
        }
    }

    /// Marks particles of system `system` (its index in the scene) for
    /// removal, by particle id; they leave at the start of the next step,
    /// never during one, and frames until then still carry them. Then the
    /// survivors' ids are renumbered in order (frames stay dense), and
    /// their densities and pressures are those of the new neighbourhoods.
    /// A step that fails after removing them keeps the removal: the
    /// removal is part of the state the step started from.
    ///
    /// # Errors
    /// [`RemoveError`] when the scene has no particle system at `system`,
    /// when that system cannot remove particles, or when an id is not one
    /// of its particles; nothing is marked then.
    pub fn remove_particles(&mut self, system: usize, ids: &[usize]) -> Result<(), RemoveError> {
        self.system_mut(system)
            .ok_or(RemoveError::NoSystem { system })?
            .simulated_mut()
            .mark_removed(ids)
    }

    /// Advances by `scene.time.dt`, split into sub-steps that respect the
    /// stability limit (up to `time.max_substeps`).
    ///
    /// # Errors
    /// [`StepError::Unstable`] when a sub-step produced NaN, infinity or a
    /// runaway speed, [`StepError::SolidUnstable`] when a solid did; the
    /// world is then restored to its state before this step.
    pub fn step(&mut self) -> Result<StepInfo, StepError> {
        // A flag no one else holds is never raised.
        self.step_cancellable(&Cancel::new())
    }

    /// [`Self::step`], stopped by another thread raising `cancel`: the
    /// flag is read before every sub-step, implicit solid's Newton
    /// iteration and CG iteration, so the step ends within one of them
    /// (one step can run for seconds: a large `time.dt` in up to
    /// `time.max_substeps` sub-steps, a stiff implicit solid). An
    /// uncancelled step computes exactly what [`Self::step`] does.
    ///
    /// # Errors
    /// As [`Self::step`], and [`StepError::Cancelled`] when `cancel` was
    /// raised before the step finished (or before it began). The world is
    /// then as it was before the step, its clock included, and the same
    /// step can be taken again. [`StepError::CounterFull`] at step
    /// [`u64::MAX`], with nothing changed.
    pub fn step_cancellable(&mut self, cancel: &Cancel) -> Result<StepInfo, StepError> {
        let Some(next) = self.clock.step.checked_add(1) else {
            return Err(StepError::CounterFull {
                step: self.clock.step,
            });
        };
        let time = &self.scene.time;
        let env = StepEnv {
            dt: time.dt,
            gravity: vector(self.scene.gravity),
            cfl: time.cfl,
            max_substeps: time.max_substeps,
            step: next,
            cancel,
        };
        // Before stage 1, whose removals a cancelled step would not undo.
        if cancel.is_cancelled() {
            return Err(StepError::Cancelled { step: env.step });
        }
        // Stage 1, between steps: removals and sorting change the particle
        // slots, so they happen here, never during a solve.
        for system in &mut self.systems {
            system.simulated_mut().start_step();
        }
        // Stage 2: each system in turn, saved first, so that a blow-up in
        // any of them puts back every system stepped so far.
        let mut info = StepInfo::start(env.dt);
        for k in 0..self.systems.len() {
            let system = self.systems[k].simulated_mut();
            system.save();
            match system.step(&env, &mut self.timer) {
                Ok(step) => info.merge(&step),
                Err(error) => {
                    for system in &mut self.systems[..=k] {
                        system.simulated_mut().restore();
                    }
                    return Err(error);
                }
            }
        }
        // Stage 3: the clock.
        self.clock.step = next;
        self.clock.time += env.dt;
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
            .filter(|kind| !kind.is_integer())
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
            capped: self.last_step.capped,
            unconverged: self.last_step.unconverged,
            particle_count: self.particle_count(),
            fields,
            ids: self
                .frame_fields
                .contains(&FieldKind::Id)
                .then(|| self.particle_ids()),
            bodies: self.body_poses(),
            surface: self.fluid_entry().and_then(FluidEntry::surface_mesh),
            solids: self.solid_ranges(),
            solid_surfaces: self.solid_surfaces(),
        }
    }

    /// Pose and velocity of every rigid body, in scene order.
    pub fn body_poses(&self) -> Vec<BodyPose> {
        let Some(rigid) = self.fluid().and_then(Fluid::bodies) else {
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
        let modal = self.systems.iter().filter_map(|s| match s {
            System::Modal(m) => m.surface(),
            System::Fluid(_) | System::Solid(_) => None,
        });
        let mut surfaces: Vec<SolidSurface> = self
            .systems
            .iter()
            .filter_map(|s| match s {
                System::Solid(s) => Some(s),
                System::Fluid(_) | System::Modal(_) => None,
            })
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
                    system: s.index,
                    mesh: deformed.to_mesh(surface.triangles()),
                    normals: deformed.normals,
                })
            })
            .chain(modal)
            .collect();
        surfaces.sort_by_key(|s| s.system);
        surfaces
    }

    /// Where each solid's particles sit in the frame's fields.
    pub fn solid_ranges(&self) -> Vec<SolidRange> {
        let mut first = 0;
        let mut ranges = Vec::new();
        for system in &self.systems {
            let count = system.simulated().particle_count();
            if let System::Solid(_) | System::Modal(_) = system {
                ranges.push(SolidRange {
                    system: system.simulated().index(),
                    first,
                    count,
                });
            }
            first += count;
        }
        ranges
    }

    /// The values of one field, each system's particles in turn, whether
    /// or not the scene's output asks for it (as frames carry them).
    pub fn field_values(&self, kind: FieldKind) -> Vec<f32> {
        let mut values = Vec::new();
        for system in &self.systems {
            system.simulated().write_field(kind, &mut values);
        }
        values
    }

    /// Each particle's stable id within its system, in frame order.
    pub fn particle_ids(&self) -> Vec<u32> {
        let mut ids = Vec::with_capacity(self.particle_count());
        for system in &self.systems {
            system.simulated().write_ids(&mut ids);
        }
        ids
    }

    fn fluid_entry(&self) -> Option<&FluidEntry> {
        self.systems.iter().find_map(|s| match s {
            System::Fluid(f) => Some(f.as_ref()),
            System::Solid(_) | System::Modal(_) => None,
        })
    }

    /// The system at index `system` of the scene, if it is one the world
    /// steps (rigid bodies belong to the fluid).
    fn system_mut(&mut self, system: usize) -> Option<&mut System> {
        self.systems
            .iter_mut()
            .find(|s| s.simulated().index() == system)
    }
}

/// The step counter never wraps: a world at step [`u64::MAX`] refuses to
/// step, and is left exactly as it was.
#[cfg(test)]
mod counter_tests {
    use super::{Clock, StepError};
    use crate::scene::{BuildOptions, Scene};

    #[test]
    fn a_world_at_the_largest_step_refuses_to_step_and_changes_nothing() {
        let scene = Scene::from_toml_str(
            r#"
            [domain]
            min = [0.0, 0.0, 0.0]
            max = [1.0, 1.0, 1.0]
            [time]
            dt = 0.001
            [[systems]]
            kind = "fluid"
            spacing = 0.1
            stiffness = 1000.0
            [[systems.blocks]]
            region = { min = [0.0, 0.0, 0.0], max = [0.3, 0.3, 0.3] }
            "#,
        )
        .expect("scene");
        let mut world = scene.build(&BuildOptions::default()).expect("world");
        world.clock = Clock {
            step: u64::MAX - 1,
            time: 1.0,
        };
        world.step().expect("the last step the counter holds");
        let last = world.clock();
        assert_eq!(last.step, u64::MAX);
        let before = world.frame();
        let refused = world.step().expect_err("a step past u64::MAX");
        assert_eq!(refused, StepError::CounterFull { step: u64::MAX });
        assert!(refused.to_string().contains("never wraps"), "{refused}");
        assert_eq!(world.clock(), last, "the clock is unchanged");
        let after = world.frame();
        assert_eq!(
            (after.step, &after.fields),
            (before.step, &before.fields),
            "the state is unchanged"
        );
    }
}
