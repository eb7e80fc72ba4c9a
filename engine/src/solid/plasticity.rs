//! Plastic flow (tutorial Section 7.3; Müller et al. 2004 with the update
//! of Gross & Pfister 2007): each particle stores a plastic strain
//! `eps_p`, the elastic strain is `eps - eps_p` (Eq. 69), and after each
//! step
//!
//! ```text
//! eps_e = eps - eps_p
//! if |eps_e| > c_yield:   eps_p += c_creep eps_e
//! if |eps_p| > c_max:     eps_p *= c_max / |eps_p|
//! ```
//!
//! with Frobenius norms. For large flow the reference shape is re-based
//! on the current one (`X <- X + u`, `u <- 0`) and the shape functions
//! recomputed; the plastic strain then loses the total strain it was
//! measured against (`eps_p <- eps_p - eps`), so the elastic strain is
//! unchanged at that instant (exact for small rotations).

use super::body::Body;
use super::material::StressState;
use super::topology::Topology;

impl Body {
    /// Applies the plastic update with `states`, the stress states of the
    /// positions before the last move, and re-bases when a strain passed
    /// the threshold.
    pub(super) fn flow(&mut self, states: &[StressState]) {
        let (Some(rule), Some(plastic)) = (self.params.plasticity, self.plastic.as_mut()) else {
            return;
        };
        let mut rebase = false;
        for (p, state) in plastic.iter_mut().zip(states) {
            let elastic = state.e;
            if elastic.norm() > rule.yield_strain {
                *p += elastic * rule.creep;
            }
            let norm = p.norm();
            if norm > rule.max {
                *p *= rule.max / norm;
            }
            if let Some(limit) = rule.rebase {
                rebase |= (elastic + *p).norm() > limit;
            }
        }
        if rebase {
            self.rebase();
        }
    }

    /// Moves the reference shape to the current one and recomputes the
    /// shape functions there. Keeps the old reference if the new one
    /// cannot carry an MLS fit (it always can: every particle is its own
    /// neighbour), so a rebase never fails a step.
    fn rebase(&mut self) {
        let states = self.current_states();
        let Ok(topology) = Topology::build(
            &self.positions,
            self.params.dim,
            self.params.order,
            self.params.support,
        ) else {
            return;
        };
        if let Some(plastic) = self.plastic.as_mut() {
            for (p, state) in plastic.iter_mut().zip(&states) {
                let total = state.e + *p;
                *p -= total;
            }
        }
        for (v, state) in self.volumes.iter_mut().zip(&states) {
            *v *= state.det.max(1e-6);
        }
        self.rest.clone_from(&self.positions);
        self.topology = topology;
    }
}
