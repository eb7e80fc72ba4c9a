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
//! Ids are stable: a removed particle's id is never reused and the
//! survivors keep theirs, so a client follows a particle by id from frame
//! to frame. Frames list particles in id order; once ids have gaps, each
//! slot's rank among the live ids says where.

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

    /// Keeps the particles whose id is not in `removed` (sorted), in their
    /// slot order; the survivors keep their ids. Returns the kept slots
    /// (slot `k` now holds what slot `kept[k]` held). Neighbour lists and
    /// densities are stale until the caller rebuilds them.
    pub(in crate::fluid) fn retain(&mut self, removed: &[u32]) -> Vec<u32> {
        let slots = self.ids.len();
        let kept: Vec<u32> = (0..slots as u32)
            .filter(|&slot| removed.binary_search(&self.ids[slot as usize]).is_err())
            .collect();
        self.gather_slots(&kept, slots);
        // Scratch, overwritten before it is read: only its length counts.
        self.smoothed_velocities.truncate(kept.len());
        self.rank_ids();
        kept
    }

    /// Appends particles at `positions` moving at `velocities`, with the
    /// next ids in order, at rest density and pressure zero until the
    /// caller recomputes them. Returns the first new id.
    pub(in crate::fluid) fn append(&mut self, positions: &[Vector], velocities: &[Vector]) -> u32 {
        let first = self.next_id;
        let n = self.ids.len() + positions.len();
        self.positions.extend_from_slice(positions);
        self.velocities.extend_from_slice(velocities);
        self.densities.resize(n, self.params.eos.rest_density);
        self.pressures.resize(n, 0.0);
        self.accelerations.resize(n, Vector::zeros());
        if !self.smoothed_velocities.is_empty() {
            // Scratch: only its length counts.
            self.smoothed_velocities.resize(n, Vector::zeros());
        }
        self.ids.extend(first..first + positions.len() as u32);
        self.next_id = first + positions.len() as u32;
        // The new ids are the largest: they rank last.
        if !self.ranks.is_empty() {
            let live = self.ranks.len() as u32;
            self.ranks.extend(live..live + positions.len() as u32);
        }
        first
    }

    /// Each slot's rank among the live ids, or nothing while the ids are
    /// `0..len` (their own ranks).
    pub(in crate::fluid) fn rank_ids(&mut self) {
        self.ranks.clear();
        if self.next_id as usize == self.ids.len() {
            return;
        }
        let mut by_id: Vec<u32> = (0..self.ids.len() as u32).collect();
        by_id.sort_unstable_by_key(|&slot| self.ids[slot as usize]);
        self.ranks.resize(self.ids.len(), 0);
        for (rank, &slot) in by_id.iter().enumerate() {
            self.ranks[slot as usize] = rank as u32;
        }
    }

    /// The id the next particle would get; every id below it was given
    /// once, and those of removed particles are never given again.
    pub fn next_id(&self) -> u32 {
        self.next_id
    }

    /// Whether a particle with id `id` is in the fluid.
    pub fn is_live(&self, id: usize) -> bool {
        id < self.next_id as usize && self.slot_of(id).is_some()
    }

    /// The slot of the particle with id `id`.
    fn slot_of(&self, id: usize) -> Option<usize> {
        self.ids.iter().position(|&k| k as usize == id)
    }

    /// Where frames list the particle in `slot`: its rank among the live
    /// ids.
    fn rank(&self, slot: usize) -> usize {
        if self.ranks.is_empty() {
            self.ids[slot] as usize
        } else {
            self.ranks[slot] as usize
        }
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
        gather(&mut self.ranks, order, slots);
    }

    /// Each slot's particle id: the particle's index in the scene's order,
    /// kept while others leave.
    pub fn ids(&self) -> &[u32] {
        &self.ids
    }

    /// One value of `N` scalars per particle, in particle-id order:
    /// `value(slot)` is read for each slot and written where its id's
    /// rank puts it, straight into the `N` values per particle appended
    /// to `out`.
    pub fn in_id_order<T: Copy + Default, const N: usize>(
        &self,
        out: &mut Vec<T>,
        value: impl Fn(usize) -> [T; N],
    ) {
        let start = out.len();
        out.resize(start + self.ids.len() * N, T::default());
        for slot in 0..self.ids.len() {
            let at = start + self.rank(slot) * N;
            out[at..at + N].copy_from_slice(&value(slot));
        }
    }

    /// The position of the particle with id `id`.
    pub fn position_of(&self, id: usize) -> Option<Vector> {
        self.slot_of(id).map(|slot| self.positions[slot])
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
