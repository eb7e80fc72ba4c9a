//! Particles stored in the Z order of their grid cells.
//!
//! Every pass gathers over neighbours, so what it costs is mostly where
//! the neighbours' data sits in memory. Particles start in the scene's
//! lattice order, where z-neighbours lie a whole slab apart, and a flow
//! mixes them further every step. Sorting the particle arrays by the
//! Z-order key of their cells (see [`crate::neighbors::zorder`]) puts
//! particles that are close in space close in memory. The sort is
//! repeated every [`Fluid::REORDER_EVERY`] sub-steps; `ids` keeps each
//! slot's particle id so frames and errors speak of particles, not slots.

use super::{Fluid, PressureSolver};
use crate::math::Vector;
use crate::neighbors::zorder;
use rayon::prelude::*;

/// `values[k] <- values[order[k]]`.
pub(super) fn gather<T: Copy + Send + Sync>(values: &mut Vec<T>, order: &[u32]) {
    if values.len() == order.len() {
        *values = order.par_iter().map(|&k| values[k as usize]).collect();
    }
}

impl Fluid {
    /// Sub-steps between two sorts: the sort costs about one neighbour
    /// search, and a flow takes tens of sub-steps to scramble the order.
    pub const REORDER_EVERY: u32 = 32;

    /// Sorts the particles into Z order if [`Self::REORDER_EVERY`]
    /// sub-steps have passed since the last sort. Call between steps.
    pub fn reorder_if_due(&mut self) {
        if self.substeps_since_reorder >= Self::REORDER_EVERY {
            self.reorder();
        }
    }

    /// Sorts the particles into the Z order of their cells, then rebuilds
    /// what refers to slots (neighbour lists and the solver's factors).
    pub(super) fn reorder(&mut self) {
        self.substeps_since_reorder = 0;
        let order = zorder(
            &self.positions,
            &self.grid.origin(),
            self.params.support_radius,
        );
        gather(&mut self.positions, &order);
        gather(&mut self.velocities, &order);
        gather(&mut self.densities, &order);
        gather(&mut self.pressures, &order);
        gather(&mut self.accelerations, &order);
        gather(&mut self.ids, &order);
        self.permute_solver(&order);
        self.find_neighbors();
        if let PressureSolver::Dfsph(_) = self.params.solver {
            self.compute_factors();
        }
    }

    /// Each slot's particle id: the particle's index in the scene's order.
    pub fn ids(&self) -> &[u32] {
        &self.ids
    }

    /// One value of `N` scalars per particle, in particle-id order:
    /// `value(slot)` is read for each slot and written where its id puts
    /// it, straight into the one output buffer.
    pub fn in_id_order<const N: usize>(&self, value: impl Fn(usize) -> [f32; N]) -> Vec<f32> {
        let mut out = vec![0.0; self.ids.len() * N];
        for (slot, &id) in self.ids.iter().enumerate() {
            let at = id as usize * N;
            out[at..at + N].copy_from_slice(&value(slot));
        }
        out
    }

    /// The position of the particle with id `id`.
    pub fn position_of(&self, id: usize) -> Option<Vector> {
        self.ids
            .iter()
            .position(|&k| k as usize == id)
            .map(|slot| self.positions[slot])
    }
}
