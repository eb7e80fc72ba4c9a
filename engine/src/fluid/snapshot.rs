//! A fluid's state as a snapshot keeps it: what the next step reads from
//! the last one, never scratch. Restoring one into a fluid built from the
//! same scene makes the fluid step on, bit for bit, as the one it was
//! taken from (the neighbour lists and solver factors are derived from the
//! state, as after a failed step's rollback).

use super::FluidSystem;
use crate::math::{Real, Vector};
use crate::rigid::BodyState;
use crate::snapshot::{SnapshotError, check_finite, check_length, check_vectors};

/// The evolving state of a fluid and its rigid bodies, per slot in the
/// fluid's own (Z) order.
#[derive(Debug, Clone, PartialEq)]
pub struct FluidSnapshot {
    /// Each slot's particle id: distinct, each below `next_id`.
    pub ids: Vec<u32>,
    /// The id the next particle would get (ids of removed particles are
    /// never given again).
    pub next_id: u32,
    /// Positions, m.
    pub positions: Vec<Vector>,
    /// Velocities, m/s.
    pub velocities: Vec<Vector>,
    /// Densities of the last density pass, kg/m^3.
    pub densities: Vec<Real>,
    /// Pressures of the last pressure pass, Pa.
    pub pressures: Vec<Real>,
    /// Largest acceleration of the last sub-step, read by the next
    /// stability limit, m/s^2.
    pub max_acceleration: Real,
    /// Sub-steps since the particles were last sorted.
    pub substeps_since_reorder: u32,
    /// The pressure solver's warm start (empty for WCSPH).
    pub warm_start: Vec<Real>,
    /// The rigid bodies' moving parts, in the fluid's body order.
    pub bodies: Vec<BodyState>,
}

impl FluidSnapshot {
    /// Whether the snapshot fits a fluid built with `built` particles and
    /// `bodies` rigid bodies whose solver keeps `warm` warm-start values
    /// per particle.
    fn check(&self, built: usize, bodies: usize, warm: usize) -> Result<(), SnapshotError> {
        let n = self.ids.len();
        if n > built {
            return Err(SnapshotError::TooMany {
                got: n,
                limit: built,
            });
        }
        // Sorted, not flagged: `next_id` grows with every particle ever
        // added, so memory follows the particles, not the ids given.
        let mut sorted = self.ids.clone();
        sorted.sort_unstable();
        let distinct = sorted.windows(2).all(|w| w[0] < w[1]);
        if !distinct || sorted.last().is_some_and(|&last| last >= self.next_id) {
            return Err(SnapshotError::Ids {
                next_id: self.next_id,
            });
        }
        check_vectors("positions", &self.positions, n)?;
        check_vectors("velocities", &self.velocities, n)?;
        check_length("densities", self.densities.len(), n)?;
        check_length("pressures", self.pressures.len(), n)?;
        check_length("warm_start", self.warm_start.len(), warm * n)?;
        check_length("bodies", self.bodies.len(), bodies)?;
        if let Some(index) = self
            .densities
            .iter()
            .position(|&d| !(d > 0.0 && d.is_finite()))
        {
            return Err(SnapshotError::Invalid {
                what: "densities",
                index,
                value: self.densities[index],
            });
        }
        check_finite("pressures", &self.pressures)?;
        check_finite("warm_start", &self.warm_start)?;
        check_finite("max_acceleration", &[self.max_acceleration])?;
        for (index, body) in self.bodies.iter().enumerate() {
            let q = body.orientation.quaternion();
            let finite = [body.position, body.velocity, body.angular_velocity]
                .iter()
                .all(|v| v.iter().all(|c| c.is_finite()))
                && body.time.is_finite()
                && q.coords.iter().all(|c| c.is_finite());
            // A stored unit quaternion is unit to round-off; anything
            // further off is not one this engine wrote.
            let unit = (q.norm() - 1.0).abs() < 1e-9;
            if !(finite && unit) {
                return Err(SnapshotError::Invalid {
                    what: "rigid body state",
                    index,
                    value: q.norm(),
                });
            }
        }
        Ok(())
    }
}

impl FluidSystem {
    /// The state a snapshot keeps.
    pub fn snapshot(&self) -> FluidSnapshot {
        let fluid = &self.fluid;
        let mut warm_start = Vec::new();
        self.pressure.solver().save(&mut warm_start);
        let mut bodies = Vec::new();
        if let Some(rigid) = &fluid.rigid {
            rigid.save(&mut bodies);
        }
        FluidSnapshot {
            ids: fluid.ids.clone(),
            next_id: fluid.next_id,
            positions: fluid.positions.clone(),
            velocities: fluid.velocities.clone(),
            densities: fluid.densities.clone(),
            pressures: fluid.pressures.clone(),
            max_acceleration: fluid.max_acceleration,
            substeps_since_reorder: fluid.substeps_since_reorder,
            warm_start,
            bodies,
        }
    }

    /// Puts `state` back into a fluid built from the scene it was taken
    /// in: particles removed since the build are dropped, the state
    /// copied, the neighbour lists and solver factors derived from it.
    ///
    /// # Errors
    /// [`SnapshotError`] when the state does not fit this fluid (counts,
    /// ids, non-finite values); the fluid is then unchanged.
    pub fn restore_snapshot(&mut self, state: &FluidSnapshot) -> Result<(), SnapshotError> {
        let built = self.fluid.len();
        let bodies = self.fluid.rigid.as_ref().map_or(0, |r| r.bodies().len());
        let mut warm = Vec::new();
        self.pressure.solver().save(&mut warm);
        let per_particle = warm.len().checked_div(built).unwrap_or(0);
        state.check(built, bodies, per_particle)?;
        let n = state.ids.len();
        if n < built {
            // Drop the surplus particles (the last slots), so every
            // per-slot buffer, the solver's included, has `n` slots.
            let mut removed = self.fluid.ids[n..].to_vec();
            removed.sort_unstable();
            self.remove(&removed);
        }
        let fluid = &mut self.fluid;
        fluid.ids.clone_from(&state.ids);
        fluid.next_id = state.next_id;
        fluid.rank_ids();
        fluid.positions.clone_from(&state.positions);
        fluid.velocities.clone_from(&state.velocities);
        fluid.densities.clone_from(&state.densities);
        fluid.pressures.clone_from(&state.pressures);
        fluid.max_acceleration = state.max_acceleration;
        fluid.substeps_since_reorder = state.substeps_since_reorder;
        if let Some(rigid) = &mut fluid.rigid {
            rigid.restore(&state.bodies);
        }
        fluid.find_neighbors();
        let solver = self.pressure.solver_mut();
        solver.restore(&state.warm_start);
        solver.rebuild(&self.fluid);
        Ok(())
    }
}
