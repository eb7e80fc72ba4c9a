//! Time integration of an elastic solid: explicit symplectic Euler split
//! into sub-steps below the stability limit, or implicit backward Euler
//! solved by Newton's method (see `implicit.rs`).

use super::elastic::ElasticSolid;
use super::params::Integrator;
use crate::math::{Real, Vector};
use rayon::prelude::*;

/// How one step of a solid went.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SolidStep {
    pub substeps: u32,
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
}

impl ElasticSolid {
    /// Advances by `dt` under `gravity`.
    pub fn step(&mut self, dt: Real, gravity: &Vector, max_substeps: u32) -> SolidStep {
        match self.params.integrator {
            Integrator::Explicit { cfl } => {
                let limit = self.params.stable_dt(cfl);
                let wanted = (dt / limit).ceil().max(1.0);
                let count = wanted.min(max_substeps.max(1) as Real);
                let sub = dt / count;
                for _ in 0..count as u32 {
                    self.explicit_substep(sub, gravity);
                }
                SolidStep {
                    substeps: count as u32,
                    min_substep: sub,
                    capped: wanted > count,
                    ..SolidStep::default()
                }
            }
            Integrator::Implicit(settings) => {
                let report = self.implicit_step(dt, gravity, &settings);
                SolidStep {
                    substeps: 1,
                    min_substep: dt,
                    capped: false,
                    iterations: report.newton + report.cg,
                    newton_iterations: report.newton,
                    cholesky_fallbacks: report.fallbacks,
                    residual: report.residual,
                }
            }
        }
    }

    /// One symplectic Euler sub-step: forces at the current state,
    /// velocities, then positions.
    fn explicit_substep(&mut self, dt: Real, gravity: &Vector) {
        let velocities = std::mem::take(&mut self.velocities);
        self.internal_forces(None, Some(&velocities), false);
        self.velocities = velocities;
        let forces = &self.scratch.forces;
        self.velocities
            .par_iter_mut()
            .zip(self.positions.par_iter_mut())
            .zip(forces.par_iter().zip(&self.masses).zip(&self.fixed))
            .for_each(|((v, x), ((f, m), fixed))| {
                if !fixed {
                    *v += (f / *m + gravity) * dt;
                    *x += *v * dt;
                }
            });
        self.finish_substep();
    }

    /// After positions moved: collisions, and plastic flow with the
    /// strains of the force evaluation.
    pub(super) fn finish_substep(&mut self) {
        let radius = 0.5 * self.params.spacing;
        self.obstacles.resolve(
            self.params.dim,
            radius,
            self.params.friction,
            &self.fixed,
            &mut self.positions,
            &mut self.velocities,
        );
        self.flow();
    }
}
