//! A world's state as a snapshot holds it: the clock and each system's
//! state, with what the world keeps around a system between steps
//! (particles marked for removal, the energy a system started from), and
//! why a state cannot be restored. Plain data, shared by the world
//! (`state.rs`) and the systems' adapters, importing neither.

use crate::efg::ModalState;
use crate::fluid::FluidSnapshot;
use crate::math::{Real, Vector};
use crate::scene::{Scene, SceneError};
use crate::shell::ShellState;
use crate::snapshot::SnapshotError;
use crate::solid::SolidSnapshot;

/// Where a world is in time.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Clock {
    /// Steps completed.
    pub step: u64,
    /// Simulated time, s.
    pub time: Real,
}

/// Everything a world's next steps read from its past.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldState {
    /// Steps completed and simulated time.
    pub clock: Clock,
    /// One per particle system, in step order (the fluid first, then the
    /// solids in scene order).
    pub systems: Vec<SystemState>,
}

/// One system's state, with its index in the scene.
#[derive(Debug, Clone, PartialEq)]
pub enum SystemState {
    /// The fluid and its rigid bodies.
    Fluid {
        /// Index of the system in the scene.
        index: usize,
        /// The particles and bodies.
        fluid: FluidSnapshot,
        /// Particle ids marked for removal at the next step.
        removals: Vec<u32>,
        /// New particles (position, velocity) queued for the next step, in
        /// the order they get their ids.
        insertions: Vec<(Vector, Vector)>,
        /// The energy watch's start `(E_0, scale)`, if measured.
        energy_start: Option<(Real, Real)>,
    },
    /// An elastic solid.
    Solid {
        /// Index of the system in the scene.
        index: usize,
        /// Its particles.
        solid: SolidSnapshot,
        /// The energy watch's start `(E_0, scale)`, if measured.
        energy_start: Option<(Real, Real)>,
    },
    /// A modal solid: its reduced state, or its full one under nonlinear
    /// dynamics (its grabs belong to whoever set them, and are set again
    /// after a restore).
    Modal {
        /// Index of its system in the scene.
        index: usize,
        /// Modal amplitudes and velocities.
        state: ModalState,
    },
    /// A shell: its nodal displacements, velocities and accelerations
    /// and its clock.
    Shell {
        /// Index of its system in the scene.
        index: usize,
        /// Its state.
        state: ShellState,
    },
}

impl SystemState {
    /// Index of the system in the scene.
    pub fn index(&self) -> usize {
        match self {
            Self::Fluid { index, .. }
            | Self::Solid { index, .. }
            | Self::Modal { index, .. }
            | Self::Shell { index, .. } => *index,
        }
    }

    /// What the system is, as errors name it.
    pub fn kind_name(&self) -> &'static str {
        match self {
            Self::Fluid { .. } => "fluid",
            Self::Solid { .. } => "solid",
            Self::Modal { .. } => "modal solid",
            Self::Shell { .. } => "shell",
        }
    }
}

/// Why a state cannot be restored into a world.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StateError {
    /// The systems differ in number, kind or index from the world's.
    #[error(
        "the snapshot's systems ({got}) are not the scene's particle systems ({expected}): it \
         was taken in another scene"
    )]
    Systems {
        /// The world's systems, e.g. "fluid 0, solid 1".
        expected: String,
        /// The snapshot's.
        got: String,
    },
    /// The clock's time is not finite.
    #[error("the snapshot's time is not finite ({time})")]
    Time {
        /// The time it holds.
        time: Real,
    },
    /// A fluid's positions fail the checks a scene's own particles pass
    /// (outside the domain, piled into one spot).
    #[error("systems[{system}]: {source}")]
    Layout {
        /// Index of the system in the scene.
        system: usize,
        /// The check that failed, naming the position.
        source: SceneError,
    },
    /// The new particles a snapshot queued are not ones the system takes.
    #[error("systems[{system}]: the queued insertions are refused: {reason}")]
    Insertions {
        /// Index of the system in the scene.
        system: usize,
        /// Why, as the insertion would have been refused.
        reason: String,
    },
    /// One system's state does not fit it.
    #[error("systems[{system}]: {source}")]
    System {
        /// Index of the system in the scene.
        system: usize,
        /// What does not fit.
        source: SnapshotError,
    },
}

impl StateError {
    /// A state of another kind than the system's: `expected` names the
    /// system's kind and index.
    pub(crate) fn kind(expected: (&'static str, usize), state: &SystemState) -> Self {
        Self::Systems {
            expected: describe(std::iter::once(expected)),
            got: describe(std::iter::once((state.kind_name(), state.index()))),
        }
    }
}

/// "fluid 0, solid 1" for a list of systems.
pub(crate) fn describe<'a>(systems: impl Iterator<Item = (&'static str, usize)> + 'a) -> String {
    let names: Vec<String> = systems.map(|(k, i)| format!("{k} {i}")).collect();
    if names.is_empty() {
        "none".into()
    } else {
        names.join(", ")
    }
}

/// Checks a restored fluid's positions as the scene checks its own
/// particles ([`Scene::check_fluid_positions`]), so that a forged state
/// cannot pile particles whose neighbour lists grow with the square of
/// the pile; returns the neighbour pairs they make, by estimate. A scene
/// without a fluid has nothing to check (the systems' mismatch is
/// reported by `World::restored`).
pub(crate) fn check_layout(
    scene: &Scene,
    system: usize,
    fluid: &FluidSnapshot,
) -> Result<Real, StateError> {
    let Some(spec) = scene.fluid() else {
        return Ok(0.0);
    };
    scene
        .check_fluid_positions(
            spec,
            fluid.positions.iter().map(|p| [p.x, p.y, p.z]),
            &|i| format!("positions[{i}]"),
        )
        .map_err(|source| StateError::Layout { system, source })
}
