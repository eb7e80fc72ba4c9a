//! Symplectic Euler for elastic solids: forces at the current state,
//! then velocities, then positions, each step split into sub-steps below
//! the elastic wave limit ([`SolidParams::stable_dt`]).
//!
//! [`SolidParams::stable_dt`]: crate::solid::SolidParams::stable_dt

use super::super::body::Body;
use super::super::forces::InternalForces;
use super::{SolidStep, finish_substep};
use crate::cancel::{Cancel, Cancelled};
use crate::math::{Real, Vector};
use crate::stats::{Stage, StageTimer};
use rayon::prelude::*;

/// The explicit integrator: its Courant number and the force buffers.
#[derive(Debug, Clone)]
pub(in crate::solid) struct Explicit {
    /// Fraction of the stability limit each sub-step takes.
    cfl: Real,
    pub(super) forces: InternalForces,
}

impl Explicit {
    /// The integrator at Courant number `cfl`.
    pub fn new(cfl: Real) -> Self {
        Self {
            cfl,
            forces: InternalForces::default(),
        }
    }

    /// Advances by `dt` in sub-steps of at most the stability limit, or
    /// in `max_substeps` when it would take more (reported as capped).
    /// Stops before the next sub-step once `cancel` is raised, `body`
    /// part-way through the step.
    pub fn step(
        &mut self,
        body: &mut Body,
        dt: Real,
        gravity: &Vector,
        max_substeps: u32,
        cancel: &Cancel,
        timer: &mut StageTimer,
    ) -> Result<SolidStep, Cancelled> {
        let limit = body.stable_dt(self.cfl);
        let wanted = (dt / limit).ceil().max(1.0);
        let count = wanted.min(max_substeps.max(1) as Real);
        let sub = dt / count;
        for _ in 0..count as u32 {
            cancel.check()?;
            self.substep(body, sub, gravity, timer);
        }
        Ok(SolidStep {
            substeps: count as u32,
            min_substep: sub,
            capped: wanted > count,
            ..SolidStep::default()
        })
    }

    /// One symplectic Euler sub-step: forces at the current state,
    /// velocities, then positions.
    fn substep(&mut self, body: &mut Body, dt: Real, gravity: &Vector, timer: &mut StageTimer) {
        timer.time(Stage::SolidForces, || {
            self.forces
                .evaluate(body, None, Some(&body.velocities), false);
        });
        let forces = &self.forces.forces;
        timer.time(Stage::SolidIntegrate, || {
            body.velocities
                .par_iter_mut()
                .zip(body.positions.par_iter_mut())
                .zip(forces.par_iter().zip(&body.masses).zip(&body.fixed))
                .for_each(|((v, x), ((f, m), fixed))| {
                    if !fixed {
                        *v += (f / *m + gravity) * dt;
                        *x += *v * dt;
                    }
                });
        });
        timer.time(Stage::SolidContact, || {
            finish_substep(body, &self.forces.states);
        });
    }
}
