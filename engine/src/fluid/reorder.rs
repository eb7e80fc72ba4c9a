//! Slots and particle ids: particles stored in the Z order of their grid
//! cells, and removed between steps.
//!
//! Every pass gathers over neighbours, so what it costs is mostly where
//! the neighbours' data sits in memory. Particles start in the scene's
//! lattice order, where z-neighbours lie a whole slab apart, and a flow
//! mixes them further every step. Sorting the particle arrays by the
//! Z-order key of their cells (see [`crate::neighbors::zorder`]) puts
//! particles that are close in space close in memory. The sort is
//! repeated every [`Fluid::REORDER_EVERY`] sub-steps; `ids` keeps each
//! slot's particle id so frames and errors speak of particles, not slots.
//!
//! Ids are always `0..n`: removing particles renumbers the survivors in
//! their id order, so frames stay dense.

use super::{Fluid, FluidSystem};
use crate::math::Vector;
use crate::neighbors::zorder;
use rayon::prelude::*;

/// `values[k] <- values[order[k]]` for an array of one value per slot of
/// `slots` slots; an array of another length (scratch a scene does not
/// use) is left alone.
pub(in crate::fluid) fn gather<T: Copy + Send + Sync>(
    values: &mut Vec<T>,
    order: &[u32],
    slots: usize,
) {
    if values.len() == slots {
        *values = order.par_iter().map(|&k| values[k as usize]).collect();
    }
}

impl Fluid {
    /// Sub-steps between two sorts: the sort costs about one neighbour
    /// search, and a flow takes tens of sub-steps to scramble the order.
    pub const REORDER_EVERY: u32 = 32;

    /// Sorts the particles into the Z order of their cells and rebuilds
    /// the neighbour lists; returns the order (slot `k` now holds what
    /// slot `order[k]` held), which the solver's scratch must follow.
    pub(in crate::fluid) fn reorder(&mut self) -> Vec<u32> {
        self.substeps_since_reorder = 0;
        let order = zorder(
            &self.positions,
            &self.grid.origin(),
            self.params.support_radius,
        );
        self.gather_slots(&order, order.len());
        self.find_neighbors();
        order
    }

    /// Keeps the particles whose id `removed` does not mark, in their slot
    /// order, and renumbers their ids in id order. Returns the kept slots
    /// (slot `k` now holds what slot `kept[k]` held). Neighbour lists and
    /// densities are stale until the caller rebuilds them.
    pub(in crate::fluid) fn retain(&mut self, removed: &[bool]) -> Vec<u32> {
        let kept: Vec<u32> = (0..self.ids.len() as u32)
            .filter(|&slot| !removed[self.ids[slot as usize] as usize])
            .collect();
        // Each surviving id's rank among the survivors.
        let mut next = 0;
        let renumbered: Vec<u32> = removed
            .iter()
            .map(|&gone| {
                let id = next;
                next += u32::from(!gone);
                id
            })
            .collect();
        self.gather_slots(&kept, removed.len());
        // Scratch, overwritten before it is read: only its length counts.
        self.smoothed_velocities.truncate(kept.len());
        for id in &mut self.ids {
            *id = renumbered[*id as usize];
        }
        kept
    }

    /// Moves the per-slot state of `slots` slots to the slots `order`
    /// gives.
    fn gather_slots(&mut self, order: &[u32], slots: usize) {
        gather(&mut self.positions, order, slots);
        gather(&mut self.velocities, order, slots);
        gather(&mut self.densities, order, slots);
        gather(&mut self.pressures, order, slots);
        gather(&mut self.accelerations, order, slots);
        gather(&mut self.ids, order, slots);
    }

    /// Each slot's particle id: the particle's index in the scene's order.
    pub fn ids(&self) -> &[u32] {
        &self.ids
    }

    /// One value of `N` scalars per particle, in particle-id order:
    /// `value(slot)` is read for each slot and written where its id puts
    /// it, straight into the `N` values per particle appended to `out`.
    pub fn in_id_order<const N: usize>(
        &self,
        out: &mut Vec<f32>,
        value: impl Fn(usize) -> [f32; N],
    ) {
        let start = out.len();
        out.resize(start + self.ids.len() * N, 0.0);
        for (slot, &id) in self.ids.iter().enumerate() {
            let at = start + id as usize * N;
            out[at..at + N].copy_from_slice(&value(slot));
        }
    }

    /// The position of the particle with id `id`.
    pub fn position_of(&self, id: usize) -> Option<Vector> {
        self.ids
            .iter()
            .position(|&k| k as usize == id)
            .map(|slot| self.positions[slot])
    }
}

impl FluidSystem {
    /// Sorts the particles into Z order if [`Fluid::REORDER_EVERY`]
    /// sub-steps have passed since the last sort. Call between steps.
    pub fn reorder_if_due(&mut self) {
        if self.fluid.substeps_since_reorder >= Fluid::REORDER_EVERY {
            self.reorder();
        }
    }

    /// Sorts the particles into the Z order of their cells, then rebuilds
    /// what refers to slots (neighbour lists and the solver's scratch).
    pub(in crate::fluid) fn reorder(&mut self) {
        let slots = self.fluid.len();
        let order = self.fluid.reorder();
        let solver = self.pressure.solver_mut();
        solver.follow(&order, slots);
        solver.rebuild(&self.fluid);
    }
}
