//! A world's state, for snapshots: the clock and each system's state,
//! with what the world keeps around a system between steps (particles
//! marked for removal, the energy the fluid started from). Restoring it
//! into a world built from the same scene makes that world step on, bit
//! for bit, as the one it was taken from.

use super::system::{Simulated, System};
use super::{Clock, World};
use crate::efg::ModalState;
use crate::fluid::FluidSnapshot;
use crate::math::Real;
use crate::scene::{Checked, Footprint, Scene, SceneError};
use crate::snapshot::SnapshotError;
use crate::solid::SolidSnapshot;

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
}

impl SystemState {
    /// Index of the system in the scene.
    pub fn index(&self) -> usize {
        match self {
            Self::Fluid { index, .. } | Self::Solid { index, .. } | Self::Modal { index, .. } => {
                *index
            }
        }
    }

    /// What the system is, as [`Simulated::kind_name`] says it.
    pub fn kind_name(&self) -> &'static str {
        match self {
            Self::Fluid { .. } => "fluid",
            Self::Solid { .. } => "solid",
            Self::Modal { .. } => "modal solid",
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
    /// A state of another kind than `system`'s.
    pub(crate) fn kind(system: &dyn Simulated, state: &SystemState) -> Self {
        Self::Systems {
            expected: describe(std::iter::once((system.kind_name(), system.index()))),
            got: describe(std::iter::once((state.kind_name(), state.index()))),
        }
    }
}

/// "fluid 0, solid 1" for a list of systems.
fn describe<'a>(systems: impl Iterator<Item = (&'static str, usize)> + 'a) -> String {
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
/// reported by [`World::restored`]).
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

impl Checked {
    /// The memory the world of this scene moved to `state` holds, by
    /// estimate, with `state`'s fluid positions checked: the neighbour
    /// pairs come from the restored positions, not the scene's lattice.
    /// The world is built from the scene before it moves to the state,
    /// so the estimate is never below the scene's own.
    ///
    /// # Errors
    /// [`StateError::Layout`] for positions a scene could not hold.
    pub fn restored_footprint(&self, state: &WorldState) -> Result<Footprint, StateError> {
        let mut footprint = self.footprint();
        let dim = self.scene.dimension;
        for saved in &state.systems {
            let SystemState::Fluid { index, fluid, .. } = saved else {
                continue;
            };
            let Some(spec) = self.scene.fluid() else {
                continue;
            };
            let pairs = check_layout(&self.scene, *index, fluid)?;
            let (mut restored, mut built) = (Footprint::default(), Footprint::default());
            restored.add_fluid_pairs(fluid.positions.len() as Real, pairs);
            built.add_fluid(
                spec.particle_count(dim),
                spec.support_radius() / spec.spacing,
                dim,
            );
            footprint.bytes += (restored.bytes - built.bytes).max(0.0);
        }
        Ok(footprint)
    }
}

impl World {
    /// The world's state, for a snapshot (call between steps).
    pub fn state(&self) -> WorldState {
        WorldState {
            clock: self.clock,
            systems: self
                .systems
                .iter()
                .map(|s| s.simulated().capture())
                .collect(),
        }
    }

    /// This world, built from the scene `state` was taken in, moved to
    /// `state`. Taking the world by value means a state that fails part
    /// of the way leaves no half-restored world behind.
    ///
    /// # Errors
    /// [`StateError`] when the state is not one of this scene's: other
    /// systems, counts, ids, values that are not finite, or fluid
    /// positions the scene's own checks refuse.
    pub fn restored(mut self, state: &WorldState) -> Result<World, StateError> {
        let kinds = |s: &System| (s.simulated().kind_name(), s.simulated().index());
        let state_kinds = |s: &SystemState| (s.kind_name(), s.index());
        let matches = self.systems.len() == state.systems.len()
            && self
                .systems
                .iter()
                .zip(&state.systems)
                .all(|(a, b)| kinds(a) == state_kinds(b));
        if !matches {
            return Err(StateError::Systems {
                expected: describe(self.systems.iter().map(kinds)),
                got: describe(state.systems.iter().map(state_kinds)),
            });
        }
        if !state.clock.time.is_finite() {
            return Err(StateError::Time {
                time: state.clock.time,
            });
        }
        for (system, saved) in self.systems.iter_mut().zip(&state.systems) {
            system.simulated_mut().restore_state(saved, &self.scene)?;
        }
        self.clock = state.clock;
        Ok(self)
    }
}

#[cfg(test)]
mod tests {
    use super::{StateError, SystemState, WorldState};
    use crate::math::Vector;
    use crate::scene::{BuildOptions, Scene};
    use crate::snapshot::SnapshotError;

    /// A forged snapshot of a plastic solid whose re-based reference shape
    /// is piled onto one point (its checksum recomputed) is refused before
    /// any neighbourhood is searched: its 20,000 and more particles would
    /// otherwise make over 4e8 neighbour pairs. The shape it was built with, moved
    /// rigidly, restores.
    #[test]
    fn a_reference_shape_piled_onto_a_point_is_refused_before_its_neighbours() {
        let scene = Scene::from_toml_str(
            r#"
            [domain]
            min = [-1.0, -1.0, -1.0]
            max = [1.0, 1.0, 1.0]
            [time]
            dt = 0.001
            [[systems]]
            kind = "solid"
            shape = { type = "box", half_extents = [0.5, 0.5, 0.5] }
            position = [0.0, 0.0, 0.0]
            spacing = 0.035
            young = 1e5
            plasticity = { yield = 0.01, creep = 1.0, max = 0.5, rebase = 0.1 }
            "#,
        )
        .expect("scene");
        let world = scene.build(&BuildOptions::default()).expect("world");
        let mut state = world.state();
        fn reference(state: &mut WorldState) -> &mut Vec<Vector> {
            let Some(SystemState::Solid { solid, .. }) = state.systems.first_mut() else {
                panic!("a solid")
            };
            let (rest, _) = solid
                .reference
                .as_mut()
                .expect("a re-basing solid keeps it");
            assert!(rest.len() > 20_000, "{} particles", rest.len());
            rest
        }
        let mut moved = state.clone();
        for x in reference(&mut moved).iter_mut() {
            x.x += 0.1;
        }
        assert!(
            scene
                .build(&BuildOptions::default())
                .expect("world")
                .restored(&moved)
                .is_ok(),
            "the shape it was built with, moved, restores"
        );
        for x in reference(&mut state).iter_mut() {
            *x = Vector::new(0.25, 0.25, 0.25);
        }
        let refused = world.restored(&state).expect_err("a pile");
        assert!(
            matches!(
                refused,
                StateError::System {
                    source: SnapshotError::Crowded { .. },
                    ..
                }
            ),
            "{refused}"
        );
        assert!(refused.to_string().contains("crowded"), "{refused}");
    }
}
