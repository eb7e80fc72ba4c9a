//! Time integration of an elastic solid: the runtime integrators, each
//! owning the buffers its steps reuse, and what every step ends with.
//!
//! - `explicit.rs`: symplectic Euler, split into sub-steps below the
//!   stability limit;
//! - `implicit.rs`: backward Euler solved by Newton's method with a line
//!   search, its linear systems by the matrix-free Hessian product and
//!   CG;
//! - `direct.rs`: the assembled Hessian and its sparse Cholesky solve,
//!   the implicit integrator's other linear solver.
//!
//! A new integrator is a file here, a variant of [`Integrator`] with its
//! arms below, and its entry in the spec ([`params::Integrator`]).

mod direct;
mod explicit;
mod implicit;

use super::body::Body;
use super::material::StressState;
use super::params;
use crate::cancel::{Cancel, Cancelled};
use crate::math::{Real, Vector};
use crate::stats::StageTimer;
use explicit::Explicit;
use implicit::Implicit;

/// How one step of a solid went.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SolidStep {
    /// Sub-steps taken.
    pub substeps: u32,
    /// The shortest of them, s.
    pub min_substep: Real,
    /// Whether `max_substeps` capped an explicit split, so sub-steps
    /// exceeded the stability limit.
    pub capped: bool,
    /// Newton plus conjugate-gradient iterations (implicit only).
    pub iterations: u32,
    /// Newton iterations alone (implicit only).
    pub newton_iterations: u32,
    /// Newton iterations whose Cholesky factorisation failed (a Hessian
    /// that is not positive definite, as under buckling) and that CG
    /// solved instead (implicit with [`LinearSolver::Cholesky`] only).
    ///
    /// [`LinearSolver::Cholesky`]: super::LinearSolver::Cholesky
    pub cholesky_fallbacks: u32,
    /// Newton's final residual relative to its first, or to the step's
    /// gravity impulse `dt |M g|` where that is larger (implicit only).
    pub residual: Real,
    /// Whether Newton stopped at `max_newton_iterations` (or at a line
    /// search that could not descend) above `newton_tolerance`: the step
    /// is not the backward Euler solution it claims to be.
    pub unconverged: bool,
}

/// A solid's integrator as [`params::Integrator`] chose it, with its
/// buffers.
#[derive(Debug, Clone)]
pub(super) enum Integrator {
    Explicit(Explicit),
    /// Boxed: its buffers outweigh the explicit one's many times.
    Implicit(Box<Implicit>),
}

impl Integrator {
    /// The integrator `choice` names, its buffers empty until the first
    /// step sizes them.
    pub fn new(choice: &params::Integrator) -> Self {
        match *choice {
            params::Integrator::Explicit { cfl } => Self::Explicit(Explicit::new(cfl)),
            params::Integrator::Implicit(settings) => {
                Self::Implicit(Box::new(Implicit::new(settings)))
            }
        }
    }

    /// Advances `body` by `dt` under `gravity`, or stops at the next
    /// sub-step, Newton or CG iteration once `cancel` is raised.
    pub fn step(
        &mut self,
        body: &mut Body,
        dt: Real,
        gravity: &Vector,
        max_substeps: u32,
        cancel: &Cancel,
        timer: &mut StageTimer,
    ) -> Result<SolidStep, Cancelled> {
        match self {
            Self::Explicit(e) => e.step(body, dt, gravity, max_substeps, cancel, timer),
            Self::Implicit(i) => i.step(body, dt, gravity, cancel, timer),
        }
    }

    /// The stress states of the last force evaluation (empty before the
    /// first step).
    pub fn states(&self) -> &[StressState] {
        match self {
            Self::Explicit(e) => &e.forces.states,
            Self::Implicit(i) => &i.forces.states,
        }
    }

    /// Bytes held by the last sparse Cholesky factor, if any.
    pub fn cholesky_factor_bytes(&self) -> usize {
        match self {
            Self::Explicit(_) => 0,
            Self::Implicit(i) => i.cholesky_factor_bytes(),
        }
    }
}

/// After positions moved: collisions, and plastic flow with `states`, the
/// stress states of the force evaluation.
fn finish_substep(body: &mut Body, states: &[StressState]) {
    let radius = 0.5 * body.params.spacing;
    body.obstacles.resolve(
        body.params.dim,
        radius,
        body.params.friction,
        &body.fixed,
        &mut body.positions,
        &mut body.velocities,
    );
    body.flow(states);
}
