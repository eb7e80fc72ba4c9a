//! The running world: the systems a scene built, the clock, and the step.
//!
//! `system/` holds the systems, one adapter per kind (fluid, elastic
//! solid, modal solid) behind one small trait, each addressed by its
//! index in the scene; the world reaches them only through that trait (or
//! a typed accessor where a caller needs the kind). `build.rs` turns a
//! scene into a world, `state.rs` a world into a snapshot and back,
//! `controls.rs` holds the runtime controls (grabs), `outcome.rs` what a
//! step reports. A step runs in named stages: between-step changes of the
//! particle slots (removals, sorting), then each system in turn (the
//! fluid first, then the solids in scene order), then the clock.

mod build;
mod controls;
mod outcome;
mod saved;
mod state;
mod system;
#[cfg(test)]
mod tests;
pub mod watch;

pub use controls::{Control, ControlError, ControlKind, Controls};
pub use outcome::{StepError, StepInfo};
pub use saved::{Clock, StateError, SystemState, WorldState};
pub use system::{ChangeError, InsertError, RemoveError};

use crate::cancel::Cancel;
use crate::efg::ModalSolid;
use crate::fluid::Fluid;
use crate::frame::{BodyPose, FieldData, FieldKind, Frame, SolidRange, SolidSurface};
use crate::math::{Real, Vector, vector};
use crate::scene::Scene;
use crate::shell::ShellDynamics;
use crate::solid::ElasticSolid;
use crate::stats::StageTimer;
use system::{StepEnv, System};

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
    /// The runtime controls in force (grabs), by name.
    controls: Controls,
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
        self.systems
            .iter()
            .find_map(System::as_fluid)
            .map(|f| f.fluid.fluid())
    }

    /// The fluid, to set up an initial state a scene cannot describe (a
    /// velocity field, say) before stepping.
    pub fn fluid_mut(&mut self) -> Option<&mut Fluid> {
        self.systems
            .iter_mut()
            .find_map(System::as_fluid_mut)
            .map(|f| f.fluid.fluid_mut())
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
        self.systems
            .iter()
            .filter_map(System::as_solid)
            .map(|s| (s.index, &s.solid))
    }

    /// The modal solids with their system indices, in scene order.
    pub fn modal_solids(&self) -> impl Iterator<Item = (usize, &ModalSolid)> {
        self.systems
            .iter()
            .filter_map(System::as_modal)
            .map(|m| (m.index, &m.solid))
    }

    /// The shells with their system indices, in scene order.
    pub fn shells(&self) -> impl Iterator<Item = (usize, &ShellDynamics)> {
        self.systems
            .iter()
            .filter_map(System::as_shell)
            .map(|s| (s.index, &s.dynamics))
    }

    /// The solid of system `system`, to set up a state a scene cannot
    /// describe (a deformed start, say).
    pub fn solid_mut(&mut self, system: usize) -> Option<&mut ElasticSolid> {
        let entry = self.system_mut(system)?.as_solid_mut()?;
        // An edited state is a new start for the energy watch.
        entry.watch.restart();
        Some(&mut entry.solid)
    }

    /// Marks particles of system `system` (its index in the scene) for
    /// removal, by particle id; they leave at the start of the next step,
    /// never during one, and frames until then still carry them. The
    /// survivors keep their ids (a removed id is never given again), frames
    /// list them in id order, and their densities and pressures are those
    /// of the new neighbourhoods.
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

    /// Adds particles to system `system` (its index in the scene) at
    /// `positions` moving at `velocities`: they join at the start of the
    /// next step, after that step's removals, never during one, and get
    /// the ids returned (the next ids in order; ids are never reused).
    /// A new particle's density and pressure are those of its
    /// neighbourhood, and every neighbour's are recomputed with it. In 2D
    /// the z components are dropped.
    ///
    /// # Errors
    /// [`InsertError`] when the scene has no particle system at `system`,
    /// when that system cannot take particles, when a position lies
    /// outside the domain or crowds others (as the scene's own particles
    /// would), a velocity is not finite, or the system would hold more
    /// particles than it was built with; nothing is queued then.
    pub fn insert_particles(
        &mut self,
        system: usize,
        positions: &[[Real; 3]],
        velocities: &[[Real; 3]],
    ) -> Result<std::ops::Range<u32>, InsertError> {
        let positions: Vec<Vector> = positions.iter().map(|&x| vector(x)).collect();
        let velocities: Vec<Vector> = velocities.iter().map(|&v| vector(v)).collect();
        let scene = &self.scene;
        self.systems
            .iter_mut()
            .find(|s| s.simulated().index() == system)
            .ok_or(InsertError::NoSystem { system })?
            .simulated_mut()
            .mark_inserted(scene, &positions, &velocities)
    }

    /// Removes particles of system `system` by id and adds new ones, all
    /// or nothing: [`Self::remove_particles`] then
    /// [`Self::insert_particles`] (so a removal frees room for a new
    /// particle), both taking effect at the start of the next step.
    /// Returns the ids the new particles get.
    ///
    /// # Errors
    /// [`ChangeError`] with the removal's or the insertion's error; the
    /// changes queued before the call are then as they were.
    pub fn change_particles(
        &mut self,
        system: usize,
        remove: &[usize],
        positions: &[[Real; 3]],
        velocities: &[[Real; 3]],
    ) -> Result<std::ops::Range<u32>, ChangeError> {
        let before = self
            .system_mut(system)
            .and_then(|s| s.simulated_mut().pending_changes().map(|c| c.clone()));
        if !remove.is_empty() {
            self.remove_particles(system, remove)?;
        }
        self.insert_particles(system, positions, velocities)
            .map_err(|e| {
                let pending = self
                    .system_mut(system)
                    .and_then(|s| s.simulated_mut().pending_changes());
                if let (Some(pending), Some(before)) = (pending, before) {
                    *pending = before;
                }
                e.into()
            })
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
        // Stage 1, between steps: removals, insertions, resampling and
        // sorting change the particle slots, so they happen here, never
        // during a solve.
        let mut info = StepInfo::start(env.dt);
        for system in &mut self.systems {
            info.added += system.simulated_mut().start_step(env.step)?;
        }
        // Stage 2: each system in turn, saved first, so that a blow-up in
        // any of them puts back every system stepped so far.
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
            added: self.last_step.added,
            particle_count: self.particle_count(),
            fields,
            ids: self
                .frame_fields
                .contains(&FieldKind::Id)
                .then(|| self.particle_ids()),
            bodies: self.body_poses(),
            surface: self
                .systems
                .iter()
                .find_map(|s| s.simulated().fluid_surface()),
            solids: self.solid_ranges(),
            solid_surfaces: self.solid_surfaces(),
            crack_surfaces: self.crack_surfaces(),
        }
    }

    /// Pose and velocity of every rigid body, in scene order.
    pub fn body_poses(&self) -> Vec<BodyPose> {
        let mut poses = Vec::new();
        for system in &self.systems {
            system.simulated().write_body_poses(&mut poses);
        }
        poses
    }

    /// The deformed surface of every solid that embeds one, in scene
    /// order (the order the solids step in).
    pub fn solid_surfaces(&self) -> Vec<SolidSurface> {
        self.systems
            .iter()
            .filter_map(|s| s.simulated().solid_surface())
            .collect()
    }

    /// The crack faces of every solid that has cracks, in scene order.
    pub fn crack_surfaces(&self) -> Vec<SolidSurface> {
        self.systems
            .iter()
            .filter_map(|s| s.simulated().crack_surface())
            .collect()
    }

    /// Where each solid's particles sit in the frame's fields.
    pub fn solid_ranges(&self) -> Vec<SolidRange> {
        let mut first = 0;
        let mut ranges = Vec::new();
        for system in &self.systems {
            let system = system.simulated();
            let count = system.particle_count();
            if system.is_solid() {
                ranges.push(SolidRange {
                    system: system.index(),
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

    /// The system at index `system` of the scene, if it is one the world
    /// steps (rigid bodies belong to the fluid).
    fn system(&self, system: usize) -> Option<&System> {
        self.systems
            .iter()
            .find(|s| s.simulated().index() == system)
    }

    /// [`Self::system`], to change it.
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
