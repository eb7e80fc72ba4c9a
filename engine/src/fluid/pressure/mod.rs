//! Pressure solvers: how a fluid's sub-step turns densities into pressure
//! and motion. Each solver is one file that owns its parameters and its
//! scratch and implements `PressureSolver`; [`Pressure`] names the
//! solvers a scene can choose, and its one `match` is the only place that
//! lists them.
//!
//! Adding a solver: a file here with a type implementing
//! `PressureSolver`, a variant of [`Pressure`] with its arm in
//! `Pressure::solver` and `Pressure::solver_mut`, and the scene's
//! `SolverKind` that chooses it.

mod dfsph;
mod wcsph;

pub use dfsph::{Dfsph, DfsphParams};
pub use wcsph::Wcsph;

use super::{Fluid, FluidParams};
use crate::cancel::{Cancel, Cancelled};
use crate::math::{Real, Vector};
use crate::stats::StageTimer;

/// The pressure solver of a fluid, with its parameters and scratch.
#[derive(Debug, Clone)]
pub enum Pressure {
    /// Weakly compressible SPH with the Tait equation (Algorithm 5).
    Wcsph(Wcsph),
    /// Divergence-free SPH (Bender & Koschier 2015), iterated to a density
    /// tolerance (boxed: its scratch is most of the enum).
    Dfsph(Box<Dfsph>),
}

impl Pressure {
    /// The solver, to call through `PressureSolver`.
    pub(in crate::fluid) fn solver(&self) -> &dyn PressureSolver {
        match self {
            Self::Wcsph(solver) => solver,
            Self::Dfsph(solver) => solver.as_ref(),
        }
    }

    /// Whether pressure comes from the Tait equation of state (WCSPH), so
    /// that compression stores energy; DFSPH's pressure is a constraint
    /// force and stores none.
    pub fn has_equation_of_state(&self) -> bool {
        matches!(self, Self::Wcsph(_))
    }

    /// The solver, to step or update through `PressureSolver`.
    pub(in crate::fluid) fn solver_mut(&mut self) -> &mut dyn PressureSolver {
        match self {
            Self::Wcsph(solver) => solver,
            Self::Dfsph(solver) => solver.as_mut(),
        }
    }
}

/// What a pressure solver does for its fluid. The fluid calls it with its
/// particles; the solver keeps nothing of theirs but scratch it can
/// rebuild and a warm start carried from one sub-step to the next, which
/// a failed or cancelled step puts back with the fluid's state.
pub(in crate::fluid) trait PressureSolver {
    /// Sizes the scratch for the fluid's particles and computes what the
    /// solver derives from their densities (pressures, factors): after the
    /// fluid was built, bodies were attached or particles removed, each
    /// time after a fresh density pass.
    fn init(&mut self, fluid: &mut Fluid);

    /// The largest sub-step the solver allows now, given the fastest
    /// particle or body surface `v_max` and the largest acceleration
    /// `a_max` (the fluid adds the viscous limit, which every solver
    /// obeys).
    fn stable_dt(&self, fluid: &Fluid, cfl: Real, v_max: Real, a_max: Real) -> Real;

    /// Particle speeds above this count as a blow-up: the solver's model
    /// is void there.
    fn speed_limit(&self, params: &FluidParams) -> Real;

    /// One sub-step of length `dt`, reflecting particles off the walls of
    /// `[min, max]`, each pass timed under its stage. A solver that
    /// iterates reads `cancel` every iteration and stops with
    /// [`Cancelled`], the fluid part-way through the sub-step.
    #[allow(clippy::too_many_arguments)]
    fn substep(
        &mut self,
        fluid: &mut Fluid,
        dt: Real,
        gravity: &Vector,
        min: &Vector,
        max: &Vector,
        timer: &mut StageTimer,
        cancel: &Cancel,
    ) -> Result<(), Cancelled>;

    /// The particles moved slots (a sort or a removal): slot `k` now holds
    /// what slot `order[k]` of `slots` held. Scratch carried from one
    /// sub-step to the next follows its particles.
    fn follow(&mut self, order: &[u32], slots: usize);

    /// Rebuilds what the solver derives from the neighbour lists, after
    /// they were rebuilt between sub-steps (a sort, a restored state).
    fn rebuild(&mut self, fluid: &Fluid);

    /// Copies what the next sub-step starts from (a warm start) into
    /// `out`, reusing its buffer.
    fn save(&self, out: &mut Vec<Real>);

    /// Puts back what [`Self::save`] kept, so that a step taken again
    /// computes what the first attempt would have.
    fn restore(&mut self, saved: &[Real]);
}

/// What the solves of the last sub-step achieved.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SolveInfo {
    /// Iterations of the constant-density solve.
    pub density_iterations: u32,
    /// Average density error after the constant-density solve (fraction).
    pub density_error: Real,
    /// Iterations of the divergence-free solve.
    pub divergence_iterations: u32,
    /// Average density change rate times the sub-step after the
    /// divergence solve (fraction).
    pub divergence_error: Real,
    /// Solves that stopped at their iteration cap above their tolerance
    /// (0, 1 or 2).
    pub unconverged: u32,
}
