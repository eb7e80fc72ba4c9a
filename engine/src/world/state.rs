//! A world's state, for snapshots: taken from each system and restored
//! into a world built from the same scene, which then steps on, bit for
//! bit, as the one it was taken from.

use super::World;
use super::saved::{StateError, SystemState, WorldState, check_layout, describe};
use super::system::System;
use crate::math::Real;
use crate::scene::{Checked, Footprint};

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
