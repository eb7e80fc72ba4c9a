//! What a solve reports while it runs and when it ends, and how it is
//! cancelled: the caller's observer sees every iteration and returns
//! [`ControlFlow::Break`] to stop, or another thread raises the
//! [`Cancel`](crate::Cancel) of a `solve_*_cancellable`, which the solver
//! also reads within iterations.

use crate::math::Real;
use std::ops::ControlFlow;

/// The weighted energy of each term (Eq. 78, Eq. 85), dimensionless
/// (see [`super::params`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Energies {
    /// Handles, or keyframes in a motion.
    pub handle: Real,
    /// Rigidity, Eq. 76.
    pub rigidity: Real,
    /// Volume preservation, Eq. 77.
    pub volume: Real,
    /// Velocities at keyframe times, Eq. 82 (motion only).
    pub velocity: Real,
    /// Acceleration at frame times, Eq. 83 (motion only).
    pub acceleration: Real,
    /// Obstacle penetration, Eq. 84 (motion only).
    pub obstacle: Real,
}

impl Energies {
    /// The sum of the terms: the energy the solver minimises.
    pub fn total(&self) -> Real {
        self.handle
            + self.rigidity
            + self.volume
            + self.velocity
            + self.acceleration
            + self.obstacle
    }

    /// The terms by name, in a fixed order.
    pub fn named(&self) -> [(&'static str, Real); 6] {
        [
            ("handle", self.handle),
            ("rigidity", self.rigidity),
            ("volume", self.volume),
            ("velocity", self.velocity),
            ("acceleration", self.acceleration),
            ("obstacle", self.obstacle),
        ]
    }
}

/// One solver iteration.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Progress {
    /// Iterations so far over every solve of this run (a motion solves
    /// again after each inserted frame).
    pub iteration: u32,
    /// Each term's weighted energy at this iteration.
    pub energies: Energies,
    /// Largest entry of the energy's gradient.
    pub gradient_norm: Real,
    /// Conjugate-gradient iterations so far over the whole run.
    pub linear_iterations: u64,
    /// Frames of a motion (1 for a shape).
    pub frames: usize,
    /// Frames inserted by adaptive sampling so far.
    pub inserted: usize,
    /// Largest error between frames at the last check (motion only).
    pub sampling_error: Option<Real>,
}

/// Receives progress; `Break` cancels the solve. `Send`, because a solve
/// runs on a thread of rayon's pool (see `design::on_pool`).
pub type Observer<'a> = dyn FnMut(&Progress) -> ControlFlow<()> + Send + 'a;

/// How a solve ended.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SolveInfo {
    /// Solver iterations of the last solve (for a motion, the one after
    /// the last inserted frames).
    pub iterations: u32,
    /// Each term's weighted energy at the end.
    pub energies: Energies,
    /// Largest entry of the energy's gradient at the end.
    pub gradient_norm: Real,
    /// Conjugate-gradient iterations over the whole run.
    pub linear_iterations: u64,
    /// The tolerance was reached before the iteration limit.
    pub converged: bool,
    /// Frames of the result (1 for a shape).
    pub frames: usize,
    /// Frames inserted by adaptive sampling over the run.
    pub inserted: usize,
    /// Largest error between frames at the end (motion only).
    pub sampling_error: Option<Real>,
}
