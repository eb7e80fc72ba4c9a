//! The seam between the world and its systems: the [`Simulated`] trait,
//! what every system of a step shares ([`StepEnv`]), the report of an
//! invalid value, and the particle-change types. It imports no kind of
//! system; each kind's adapter (`fluid.rs`, `solid.rs`, `modal.rs`)
//! implements the trait by calling the system's own methods, so that the
//! systems never import the world.

use crate::cancel::Cancel;
use crate::efg::Grab;
use crate::frame::{BodyPose, FieldKind, SolidSurface};
use crate::geometry::TriMesh;
use crate::math::{Real, Vector};
use crate::scene::Scene;
use crate::stats::StageTimer;
use crate::world::outcome::{StepError, StepInfo};
use crate::world::saved::{StateError, SystemState};

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
        "systems[{system}] has no particle with id {particle}: its ids run below {count}, and \
         the id of a particle removed is never given again"
    )]
    NoParticle {
        /// Index of the system in the scene.
        system: usize,
        /// The id asked for.
        particle: usize,
        /// The ids the system has given: its particles' ids run below it.
        count: usize,
    },
}

/// Why particles cannot be added; nothing was queued.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InsertError {
    /// The index names no system the world steps.
    #[error(
        "systems[{system}] is not a particle system of this world; name the index of the \
         scene's fluid"
    )]
    NoSystem {
        /// The index asked for.
        system: usize,
    },
    /// The system keeps a fixed set of particles.
    #[error(
        "systems[{system}] is {kind}, which cannot take new particles; add particles to the \
         scene's fluid"
    )]
    Unsupported {
        /// Index of the system in the scene.
        system: usize,
        /// What the system is.
        kind: &'static str,
    },
    /// Positions and velocities differ in number.
    #[error(
        "{positions} positions but {velocities} velocities: give one velocity per new particle"
    )]
    Lengths {
        /// Positions given.
        positions: usize,
        /// Velocities given.
        velocities: usize,
    },
    /// The system would hold more particles than the memory its scene
    /// was admitted with allows.
    #[error(
        "systems[{system}] would hold {count} particles, more than the {capacity} it was built \
         with (the memory the scene was admitted with); remove particles first or add fewer"
    )]
    Capacity {
        /// Index of the system in the scene.
        system: usize,
        /// Particles it would hold after the step's changes.
        count: usize,
        /// The most it may hold.
        capacity: usize,
    },
    /// A new particle is not one the scene could hold.
    #[error("systems[{system}]: {reason}")]
    Invalid {
        /// Index of the system in the scene.
        system: usize,
        /// What is wrong, naming the particle (`positions[i]`,
        /// `velocities[i]`).
        reason: String,
    },
    /// The system has given every id a `u32` holds (ids are never
    /// reused).
    #[error(
        "systems[{system}] has given {next_id} particle ids, the most it can; it takes no new \
         particle"
    )]
    IdsExhausted {
        /// Index of the system in the scene.
        system: usize,
        /// The id the next particle would get.
        next_id: u32,
    },
}

/// Why a change of particles (removals and new particles together) was
/// refused: the removal's or the insertion's error.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ChangeError {
    /// The removal was refused.
    #[error(transparent)]
    Remove(#[from] RemoveError),
    /// The new particles were refused.
    #[error(transparent)]
    Insert(#[from] InsertError),
}

/// The particle changes of one system asked for since its last step:
/// removals by id and new particles, kept from the request to the start
/// of the next step, where the system applies them all at once (removals
/// first, then the new particles in order), never inside a solve.
#[derive(Debug, Clone, Default)]
pub(crate) struct ParticleChanges {
    /// Ids to remove, sorted and distinct.
    removed: Vec<u32>,
    /// New particles' positions, in the order they get their ids.
    inserted_positions: Vec<Vector>,
    /// New particles' velocities.
    inserted_velocities: Vec<Vector>,
}

impl ParticleChanges {
    /// Marks `ids` of a system whose ids run below `count` for removal,
    /// after checking all of them: on error nothing is marked. (Whether
    /// an id below `count` is a live particle is the system's check.)
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
        // Below `count`, itself an id count: each fits a u32.
        self.removed.extend(ids.iter().map(|&id| id as u32));
        self.removed.sort_unstable();
        self.removed.dedup();
        Ok(())
    }

    /// Queues new particles (checked by the caller).
    pub(crate) fn insert(&mut self, positions: &[Vector], velocities: &[Vector]) {
        self.inserted_positions.extend_from_slice(positions);
        self.inserted_velocities.extend_from_slice(velocities);
    }

    /// The ids marked for removal, in order.
    pub(crate) fn marked_ids(&self) -> Vec<u32> {
        self.removed.clone()
    }

    /// How many ids are marked for removal.
    pub(crate) fn removed_count(&self) -> usize {
        self.removed.len()
    }

    /// The new particles queued: positions and velocities.
    pub(crate) fn inserted(&self) -> (&[Vector], &[Vector]) {
        (&self.inserted_positions, &self.inserted_velocities)
    }

    /// The changes, leaving none queued.
    pub(crate) fn take(&mut self) -> Self {
        std::mem::take(self)
    }

    /// Whether nothing is queued.
    pub(crate) fn is_empty(&self) -> bool {
        self.removed.is_empty() && self.inserted_positions.is_empty()
    }

    /// The removals and the new particles, taken apart.
    pub(crate) fn into_parts(self) -> (Vec<u32>, Vec<Vector>, Vec<Vector>) {
        (
            self.removed,
            self.inserted_positions,
            self.inserted_velocities,
        )
    }
}

/// Why a system refused its runtime grabs; it keeps the grabs it had.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct GrabRefusal {
    /// The grab at fault, its index counting the scene's grabs first
    /// (`None`: the grabs together).
    pub index: Option<usize>,
    /// Why, and what to change.
    pub reason: String,
}

/// A particle value that left its valid range, as a system reports it
/// (for a fluid's body, `particle` is the body's index among its bodies).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Invalid {
    /// What left its range ("position", "velocity", "displacement", ...).
    pub quantity: &'static str,
    /// The particle, by its id in the system.
    pub particle: usize,
    /// The offending value (a norm for vectors).
    pub value: Real,
}

/// What the world asks of each system. Everything kind-specific the
/// world does (step, save, frames, surfaces, snapshots, particle changes)
/// goes through here, so that [`crate::world::World`] holds no loop over
/// one kind.
pub(crate) trait Simulated {
    /// Index of the system in the scene.
    fn index(&self) -> usize;

    /// What the system is, for people ("fluid", "solid", "modal solid"),
    /// as snapshots and errors name it.
    fn kind_name(&self) -> &'static str;

    /// Particles the system holds: its share of a frame's fields.
    fn particle_count(&self) -> usize;

    /// Whether frames list the system's particles as a solid's
    /// ([`crate::frame::Frame::solids`]).
    fn is_solid(&self) -> bool;

    /// Between steps, before step `step`: applies the particle changes
    /// marked since the last step and anything else that changes the
    /// particle slots (a solid's resampling); returns the particles
    /// added.
    ///
    /// # Errors
    /// A [`StepError`] when the changes cannot be made; the system is
    /// then as it was.
    fn start_step(&mut self, step: u64) -> Result<u32, StepError>;

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
    /// particle, in the order frames list its particles. A field the
    /// system has no physics for is filled (documented at each arm), so
    /// every field spans all particles.
    fn write_field(&self, kind: FieldKind, out: &mut Vec<f32>);

    /// Appends each particle's stable id, in the order of
    /// [`Self::write_field`].
    fn write_ids(&self, out: &mut Vec<u32>);

    /// The system's deformed surface, for a frame's `solid_surfaces`.
    fn solid_surface(&self) -> Option<SolidSurface> {
        None
    }

    /// The system's crack faces, for a frame's `crack_surfaces`.
    fn crack_surface(&self) -> Option<SolidSurface> {
        None
    }

    /// The free surface of a fluid, for a frame's `surface`.
    fn fluid_surface(&self) -> Option<TriMesh> {
        None
    }

    /// Appends the poses of the rigid bodies the system carries.
    fn write_body_poses(&self, _out: &mut Vec<BodyPose>) {}

    /// Marks particles for removal at the start of the next step.
    fn mark_removed(&mut self, ids: &[usize]) -> Result<(), RemoveError>;

    /// The changes queued for the next step, for a system whose particles
    /// change (`None`: a fixed set), so that a caller can put them back
    /// when a later part of one request is refused.
    fn pending_changes(&mut self) -> Option<&mut ParticleChanges> {
        None
    }

    /// Queues new particles for the start of the next step, after
    /// checking them against `scene`; returns the ids they will get.
    fn mark_inserted(
        &mut self,
        _scene: &Scene,
        _positions: &[Vector],
        _velocities: &[Vector],
    ) -> Result<std::ops::Range<u32>, InsertError> {
        Err(InsertError::Unsupported {
            system: self.index(),
            kind: self.kind_article(),
        })
    }

    /// How many grabs the system's scene holds it by, or `None` for a
    /// kind no grab holds.
    fn scene_grab_count(&self) -> Option<usize> {
        None
    }

    /// The grabs set at runtime, besides the scene's.
    fn runtime_grabs(&self) -> Vec<Grab> {
        Vec::new()
    }

    /// Holds the scene's grabs and `grabs` from the next step.
    ///
    /// # Errors
    /// [`GrabRefusal`]; the grabs before then stay.
    fn set_runtime_grabs(&mut self, grabs: &[Grab]) -> Result<(), GrabRefusal> {
        if grabs.is_empty() {
            Ok(())
        } else {
            Err(GrabRefusal {
                index: None,
                reason: format!("{} holds no grab", self.kind_article()),
            })
        }
    }

    /// The kind with its article, for errors ("an elastic solid").
    fn kind_article(&self) -> &'static str;

    /// The system's state, for a snapshot (between steps).
    fn capture(&self) -> SystemState;

    /// Moves the system to `state`, taken from a system of the same kind
    /// and index (the caller matched them), after checking it against
    /// `scene`.
    ///
    /// # Errors
    /// [`StateError`] when the state does not fit; the system may then be
    /// partly changed, and the caller drops the whole world.
    fn restore_state(&mut self, state: &SystemState, scene: &Scene) -> Result<(), StateError>;
}
