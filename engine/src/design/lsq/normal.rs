//! A Levenberg–Marquardt step's linear system, the damped normal
//! equations `(J^T J + mu D) d = -g`, solved by `linalg`'s preconditioned
//! conjugate gradients on products with `J` and `J^T` (the normal matrix
//! is never formed), preconditioned by [`LineBlocks`].

use super::super::params::SolverParams;
use super::precond::LineBlocks;
use super::products::Products;
use super::rows::Rows;
use crate::cancel::{Cancel, Cancelled};
use crate::linalg::cg::{self, Stopping, Termination};
use crate::linalg::{LinOp, Sequential};
use crate::math::Real;

/// `J^T J + mu D` as an operator.
struct Normal<'a> {
    j: &'a Rows,
    products: &'a mut Products,
    diag: &'a [Real],
    mu: Real,
    /// `J p`, one entry per residual.
    jp: &'a mut [Real],
}

impl LinOp<Real> for Normal<'_> {
    fn apply(&mut self, p: &[Real], q: &mut [Real]) {
        self.products.apply_j(self.j, p, self.jp);
        self.products.apply_jt(self.j, self.jp, q);
        let mu = self.mu;
        for ((q, p), d) in q.iter_mut().zip(p).zip(self.diag) {
            *q += mu * d * p;
        }
    }
}

/// The solve's vectors, kept across the iterations of a minimisation.
#[derive(Debug, Default)]
pub(super) struct NormalEquations {
    cg: cg::Workspace<Real, Sequential>,
    /// `-g`.
    rhs: Vec<Real>,
    /// `J p` inside the operator.
    jp: Vec<Real>,
    /// `J d` of a solution.
    jd: Vec<Real>,
}

impl NormalEquations {
    /// Solves `(J^T J + mu D) d = -g`, `D = diag`, into `d` to the
    /// relative residual `params.linear_tolerance` (compared in squares),
    /// stopping at a direction of non-positive or non-finite curvature;
    /// returns the CG iterations, or [`Cancelled`] once `cancel` stopped
    /// the solve.
    #[allow(clippy::too_many_arguments)]
    pub fn solve(
        &mut self,
        j: &Rows,
        products: &mut Products,
        diag: &[Real],
        mu: Real,
        blocks: &LineBlocks,
        g: &[Real],
        d: &mut [Real],
        params: &SolverParams,
        cancel: &Cancel,
    ) -> Result<u64, Cancelled> {
        self.jp.resize(j.residuals.len(), 0.0);
        self.rhs.clear();
        self.rhs.extend(g.iter().map(|g| -g));
        let params = cg::Params {
            tolerance: params.linear_tolerance,
            max_iterations: params.max_linear_iterations,
            stopping: Stopping::SquaredResidual,
            non_finite_breaks: true,
            descend_on_first_breakdown: false,
        };
        let mut op = Normal {
            j,
            products,
            diag,
            mu,
            jp: &mut self.jp,
        };
        let info = cg::solve(&mut op, blocks, &self.rhs, d, &params, &mut self.cg, cancel);
        match info.termination {
            Termination::Cancelled => Err(Cancelled),
            Termination::Converged
            | Termination::IterationLimit
            | Termination::Breakdown { .. } => Ok(u64::from(info.iterations)),
        }
    }

    /// `J d`.
    pub fn jd(&mut self, j: &Rows, products: &Products, d: &[Real]) -> &[Real] {
        self.jd.clear();
        self.jd.resize(j.residuals.len(), 0.0);
        products.apply_j(j, d, &mut self.jd);
        &self.jd
    }
}
