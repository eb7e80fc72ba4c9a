//! The static route: a shell's equilibrium under loads and supports, by
//! Newton's method on the assembled sparse tangent (faer's sparse
//! Cholesky), in load steps, or the linearised problem in one step. It is
//! what the validation problems are solved with (the Scordelis–Lo roof,
//! clamped plates, `engine/tests/shells.rs`).

use super::assembly::{Assembly, GrabBlocks, Load, Support};
use super::error::ShellError;
use super::model::ShellModel;
use crate::cancel::Cancel;
use crate::linalg::sparse::SparseCholesky;
use crate::math::{Real, Vector};

/// How the static route solves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticParams {
    /// Penalty scale `beta` of the supports (see `assembly.rs`).
    pub penalty: Real,
    /// Solve the linearised problem (one Newton step from the reference,
    /// small deflections) instead of the nonlinear one.
    pub linear: bool,
    /// Equal load increments, each solved to the tolerance.
    pub load_steps: usize,
    /// Newton stops when the residual is this fraction of the load.
    pub tolerance: Real,
    /// Most Newton iterations per load step.
    pub max_iterations: usize,
}

impl Default for StaticParams {
    /// `beta = 10`, nonlinear, one load step, residual 1e-8 of the load
    /// within 30 iterations.
    fn default() -> Self {
        Self {
            penalty: 10.0,
            linear: false,
            load_steps: 1,
            tolerance: 1e-8,
            max_iterations: 30,
        }
    }
}

/// A static solve's result.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticSolution {
    /// Nodal displacement coefficients (the surface moves by
    /// `sum_I N_I u_I`; see [`ShellModel::displacement_at`]).
    pub displacement: Vec<Vector>,
    /// Newton iterations of each load step.
    pub iterations: Vec<usize>,
    /// The nonlinear residual over the load at the end (for the linear
    /// route, how far its answer is from equilibrium).
    pub residual: Real,
}

impl ShellModel {
    /// Solves for the static equilibrium under `load` with `supports`
    /// (see `assembly.rs` for how supports hold); checks `cancel` every
    /// iteration.
    ///
    /// # Errors
    /// [`ShellError`]: a parameter out of range, a support or load off
    /// the chart, a singular tangent (too few supports, or buckling), a
    /// folded surface, no convergence, cancellation.
    pub fn solve_static(
        &self,
        load: &Load,
        supports: &[Support],
        params: &StaticParams,
        cancel: &Cancel,
    ) -> Result<StaticSolution, ShellError> {
        if !(params.tolerance > 0.0 && params.tolerance.is_finite()) {
            return Err(ShellError::Parameter {
                what: "tolerance",
                got: params.tolerance,
                range: "a finite value > 0",
            });
        }
        if params.load_steps == 0 || params.max_iterations == 0 {
            return Err(ShellError::Parameter {
                what: "load_steps and max_iterations",
                got: 0.0,
                range: "at least 1 each",
            });
        }
        let mut assembly =
            Assembly::new(self, supports, &[], params.penalty, GrabBlocks::InPattern)?;
        let load = self.load_vector(load)?;
        let load_norm = load.iter().map(|f| f.norm_squared()).sum::<Real>().sqrt();
        let mut u = vec![Vector::zeros(); self.node_count()];
        let mut solver = SparseCholesky::default();
        let mut iterations = Vec::with_capacity(params.load_steps);
        let steps = if params.linear { 1 } else { params.load_steps };
        let mut residual = 0.0;
        for step in 1..=steps {
            let scale = step as Real / steps as Real;
            let mut taken = 0;
            loop {
                cancel.check().map_err(|_| ShellError::Cancelled)?;
                let (mut r, _) = assembly.forces(self, &u)?;
                for (rk, f) in r.iter_mut().zip(&load) {
                    *rk -= scale * f;
                }
                residual = r.iter().map(|v| v.norm_squared()).sum::<Real>().sqrt()
                    / (scale * load_norm).max(Real::MIN_POSITIVE);
                let done = if params.linear {
                    taken == 1
                } else {
                    residual <= params.tolerance
                };
                if done {
                    break;
                }
                if taken == params.max_iterations {
                    return Err(ShellError::NotConverged {
                        iterations: taken,
                        residual,
                    });
                }
                let assembly = &assembly;
                let delta = solver
                    .solve(
                        &assembly.pattern,
                        |node, column| assembly.column(self, node, column, 1.0, 0.0),
                        r.iter().flat_map(|v| [-v[0], -v[1], -v[2]]),
                    )
                    .ok_or(ShellError::Singular)?;
                for (uk, d) in u.iter_mut().zip(delta.chunks_exact(3)) {
                    *uk += Vector::new(d[0], d[1], d[2]);
                }
                taken += 1;
            }
            iterations.push(taken);
        }
        Ok(StaticSolution {
            displacement: u,
            iterations,
            residual,
        })
    }
}
