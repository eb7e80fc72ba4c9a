//! Preconditioned conjugate gradients (Hestenes & Stiefel 1952; Saad,
//! *Iterative Methods for Sparse Linear Systems*, Algorithm 9.1), the one
//! CG of the engine: the implicit solid's Newton steps and the optimiser's
//! damped normal equations both call it.
//!
//! The callers differ in how they stop and in what a direction of
//! non-positive curvature means, and each must keep the bits its results
//! were made with, so both are [`Params`]: the stopping rule compares
//! norms or their squares ([`Stopping`]), a non-finite curvature may or
//! may not end the solve, and a breakdown at the first iteration may
//! return the preconditioned right-hand side (a descent direction for the
//! minimisation `A x = b` poses) instead of zero. The caller owns the
//! [`Workspace`], so a solve allocates nothing once it is sized, and
//! passes the [`Cancel`] of the work it is part of, read before every
//! operator application.

use super::linop::{Element, LinOp, Precond, Space};
use crate::cancel::Cancel;
use crate::math::Real;
use std::marker::PhantomData;

/// When the solve has converged.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stopping {
    /// `sqrt(r . r) <= tolerance * sqrt(b . b)`.
    Residual,
    /// `r . r <= tolerance^2 * (b . b)`: the same rule in squares, which
    /// rounds differently.
    SquaredResidual,
}

/// The solver's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// Residual relative to the right-hand side at which to stop.
    pub tolerance: Real,
    /// Operator applications at most.
    pub max_iterations: u32,
    /// How the residual is compared with the tolerance.
    pub stopping: Stopping,
    /// Whether a non-finite curvature `p . A p` ends the solve like a
    /// non-positive one; without it, a NaN runs on to the iteration cap.
    pub non_finite_breaks: bool,
    /// Whether a breakdown at the first iteration returns `M^-1 b`, the
    /// preconditioned steepest-descent direction, instead of zero.
    pub descend_on_first_breakdown: bool,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            tolerance: 1e-8,
            max_iterations: 1000,
            stopping: Stopping::Residual,
            non_finite_breaks: true,
            descend_on_first_breakdown: false,
        }
    }
}

/// Why the solve ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Termination {
    /// The stopping rule held.
    Converged,
    /// [`Params::max_iterations`] ran out first.
    IterationLimit,
    /// A search direction had non-positive (or, when
    /// [`Params::non_finite_breaks`], non-finite) curvature: `A` is not
    /// positive definite along it. `x` holds the progress made before it.
    Breakdown {
        /// `p . A p` of that direction.
        curvature: Real,
    },
    /// The caller's [`Cancel`] was raised; `x` holds the progress made
    /// before it, which the caller discards.
    Cancelled,
}

/// How a solve went.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Info {
    /// Operator applications, the breaking one included.
    pub iterations: u32,
    /// Why it ended.
    pub termination: Termination,
}

/// The solver's vectors: residual `r`, preconditioned residual `z`,
/// search direction `p` and `A p`, over elements `E` in space `S`. Kept
/// by the caller between solves; sized to the system on each, which
/// allocates only when it grows.
#[derive(Debug, Clone)]
pub struct Workspace<E, S> {
    r: Vec<E>,
    z: Vec<E>,
    p: Vec<E>,
    q: Vec<E>,
    space: PhantomData<S>,
}

impl<E, S> Default for Workspace<E, S> {
    fn default() -> Self {
        Self {
            r: Vec::new(),
            z: Vec::new(),
            p: Vec::new(),
            q: Vec::new(),
            space: PhantomData,
        }
    }
}

impl<E: Element, S> Workspace<E, S> {
    fn resize(&mut self, n: usize) {
        for v in [&mut self.r, &mut self.z, &mut self.p, &mut self.q] {
            v.resize(n, E::zero());
        }
    }
}

/// Solves `A x = b` from `x = 0` by conjugate gradients preconditioned
/// with `M`, the reductions and updates run as `S` says; stops before the
/// next operator application once `cancel` is raised.
///
/// # Panics
/// When `x` and `b` differ in length.
pub fn solve<E, S, A, M>(
    op: &mut A,
    precond: &M,
    b: &[E],
    x: &mut [E],
    params: &Params,
    work: &mut Workspace<E, S>,
    cancel: &Cancel,
) -> Info
where
    E: Element,
    S: Space<E>,
    A: LinOp<E> + ?Sized,
    M: Precond<E> + ?Sized,
{
    assert_eq!(x.len(), b.len(), "CG: x and b differ in length");
    work.resize(b.len());
    let Workspace { r, z, p, q, .. } = work;
    S::zero(x);
    S::copy(b, r);
    precond.apply(r, z);
    S::copy(z, p);
    let mut rz = S::dot(r, z);
    let stopping = params.stopping;
    let threshold = match stopping {
        Stopping::Residual => params.tolerance * S::dot(r, r).sqrt(),
        Stopping::SquaredResidual => params.tolerance.powi(2) * S::dot(r, r),
    };
    let converged = |r: &[E]| match stopping {
        Stopping::Residual => S::dot(r, r).sqrt() <= threshold,
        Stopping::SquaredResidual => S::dot(r, r) <= threshold,
    };
    let mut iterations = 0;
    while iterations < params.max_iterations {
        if cancel.is_cancelled() {
            return Info {
                iterations,
                termination: Termination::Cancelled,
            };
        }
        iterations += 1;
        op.apply(p, q);
        let curvature = S::dot(p, q);
        if curvature <= 0.0 || params.non_finite_breaks && !curvature.is_finite() {
            if iterations == 1 && params.descend_on_first_breakdown {
                S::copy(z, x);
            }
            return Info {
                iterations,
                termination: Termination::Breakdown { curvature },
            };
        }
        let alpha = rz / curvature;
        S::add_scaled(x, p, alpha);
        S::sub_scaled(r, q, alpha);
        if converged(r) {
            return Info {
                iterations,
                termination: Termination::Converged,
            };
        }
        precond.apply(r, z);
        let rz_next = S::dot(r, z);
        let beta = rz_next / rz;
        rz = rz_next;
        S::scale_add(p, z, beta);
    }
    Info {
        iterations,
        termination: Termination::IterationLimit,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::linop::{Parallel, Sequential};
    use crate::math::Vector;
    use crate::testing::uniform;

    /// A dense symmetric matrix, row-major.
    struct Dense {
        n: usize,
        a: Vec<Real>,
    }

    impl Dense {
        /// `B^T B + n I` with `B` uniform in [-1, 1): symmetric, positive
        /// definite, condition number of order a few.
        fn spd(n: usize, seed: &mut u64) -> Self {
            let b: Vec<Real> = (0..n * n).map(|_| 2.0 * uniform(seed) - 1.0).collect();
            let mut a = vec![0.0; n * n];
            for i in 0..n {
                for j in 0..n {
                    a[i * n + j] = (0..n).map(|k| b[k * n + i] * b[k * n + j]).sum::<Real>();
                }
                a[i * n + i] += n as Real;
            }
            Self { n, a }
        }

        fn diagonal(&self) -> Vec<Real> {
            (0..self.n).map(|i| self.a[i * self.n + i]).collect()
        }
    }

    impl LinOp<Real> for Dense {
        fn apply(&mut self, x: &[Real], y: &mut [Real]) {
            for (i, y) in y.iter_mut().enumerate() {
                *y = (0..self.n).map(|j| self.a[i * self.n + j] * x[j]).sum();
            }
        }
    }

    /// The dense matrix acting on each component of particle vectors.
    impl LinOp<Vector> for Dense {
        fn apply(&mut self, x: &[Vector], y: &mut [Vector]) {
            for (i, y) in y.iter_mut().enumerate() {
                *y = (0..self.n).map(|j| x[j] * self.a[i * self.n + j]).sum();
            }
        }
    }

    /// `z = D^-1 r`.
    struct Jacobi(Vec<Real>);

    impl<E: Element> Precond<E> for Jacobi {
        fn apply(&self, r: &[E], z: &mut [E]) {
            for ((z, r), d) in z.iter_mut().zip(r).zip(&self.0) {
                *z = *r * (1.0 / d);
            }
        }
    }

    /// No preconditioning.
    struct Identity;

    impl<E: Element> Precond<E> for Identity {
        fn apply(&self, r: &[E], z: &mut [E]) {
            z.copy_from_slice(r);
        }
    }

    fn norm(v: &[Real]) -> Real {
        v.iter().map(|v| v * v).sum::<Real>().sqrt()
    }

    /// Solved to the limit of rounding, CG's answer has the backward error
    /// of a direct solve: `|A x - b| <= eps n |b|`, up to the matrix's
    /// (small) condition number.
    fn tight(n: usize) -> Params {
        Params {
            tolerance: Real::EPSILON,
            max_iterations: 10 * n as u32,
            ..Params::default()
        }
    }

    #[test]
    fn an_spd_system_is_solved_to_rounding_in_both_spaces_and_stopping_rules() {
        let mut seed = 3;
        for n in [1, 4, 17, 60] {
            let mut a = Dense::spd(n, &mut seed);
            let b: Vec<Real> = (0..n).map(|_| uniform(&mut seed) - 0.5).collect();
            let jacobi = Jacobi(a.diagonal());
            let limit = 4.0 * Real::EPSILON * n as Real * norm(&b);
            for stopping in [Stopping::Residual, Stopping::SquaredResidual] {
                let params = Params {
                    stopping,
                    ..tight(n)
                };
                let mut x = vec![0.0; n];
                let mut work = Workspace::<Real, Sequential>::default();
                let info = solve(
                    &mut a,
                    &jacobi,
                    &b,
                    &mut x,
                    &params,
                    &mut work,
                    &Cancel::new(),
                );
                let mut ax = vec![0.0; n];
                a.apply(&x, &mut ax);
                let residual: Vec<Real> = ax.iter().zip(&b).map(|(ax, b)| ax - b).collect();
                assert!(
                    norm(&residual) <= limit,
                    "n = {n}, {stopping:?}: |Ax - b| = {:e} > {limit:e} ({info:?})",
                    norm(&residual)
                );
                assert!(info.iterations <= params.max_iterations, "{info:?}");
            }

            // Particle vectors in parallel: each component is its own
            // system with the same matrix.
            let bv: Vec<Vector> = b
                .iter()
                .map(|&v| Vector::new(v, -2.0 * v, 0.5 * v))
                .collect();
            let mut xv = vec![Vector::zeros(); n];
            let mut work = Workspace::<Vector, Parallel>::default();
            let info = solve(
                &mut a,
                &jacobi,
                &bv,
                &mut xv,
                &tight(n),
                &mut work,
                &Cancel::new(),
            );
            let mut axv = vec![Vector::zeros(); n];
            a.apply(&xv, &mut axv);
            let error = axv
                .iter()
                .zip(&bv)
                .map(|(ax, b)| (ax - b).norm_squared())
                .sum::<Real>()
                .sqrt();
            let scale = bv.iter().map(Vector::norm_squared).sum::<Real>().sqrt();
            let limit = 4.0 * Real::EPSILON * n as Real * scale;
            assert!(
                error <= limit,
                "n = {n}, vectors: |Ax - b| = {error:e} > {limit:e} ({info:?})"
            );
        }
    }

    #[test]
    fn the_iteration_cap_ends_the_solve() {
        let mut seed = 11;
        let n = 30;
        let mut a = Dense::spd(n, &mut seed);
        let b: Vec<Real> = (0..n).map(|_| uniform(&mut seed)).collect();
        let mut work = Workspace::<Real, Sequential>::default();
        for cap in [0, 1, 3] {
            let params = Params {
                tolerance: 0.0,
                max_iterations: cap,
                ..Params::default()
            };
            let mut x = vec![1.0; n];
            let info = solve(
                &mut a,
                &Identity,
                &b,
                &mut x,
                &params,
                &mut work,
                &Cancel::new(),
            );
            assert_eq!(
                info,
                Info {
                    iterations: cap,
                    termination: Termination::IterationLimit
                }
            );
            if cap == 0 {
                assert!(x.iter().all(|&x| x == 0.0), "starts from zero: {x:?}");
            }
        }
    }

    /// `A = -I`: the first direction already has negative curvature.
    struct Negative;

    impl LinOp<Real> for Negative {
        fn apply(&mut self, x: &[Real], y: &mut [Real]) {
            for (y, x) in y.iter_mut().zip(x) {
                *y = -x;
            }
        }
    }

    /// An operator whose products are NaN.
    struct Broken;

    impl LinOp<Real> for Broken {
        fn apply(&mut self, _: &[Real], y: &mut [Real]) {
            y.fill(Real::NAN);
        }
    }

    #[test]
    fn non_positive_curvature_stops_with_zero_or_the_preconditioned_gradient() {
        let b = [1.0, -2.0, 4.0];
        let jacobi = Jacobi(vec![2.0, 4.0, 8.0]);
        let mut work = Workspace::<Real, Sequential>::default();
        for descend in [false, true] {
            let params = Params {
                descend_on_first_breakdown: descend,
                ..Params::default()
            };
            let mut x = [9.0; 3];
            let info = solve(
                &mut Negative,
                &jacobi,
                &b,
                &mut x,
                &params,
                &mut work,
                &Cancel::new(),
            );
            assert_eq!(info.iterations, 1);
            assert!(
                matches!(info.termination, Termination::Breakdown { curvature } if curvature < 0.0),
                "{info:?}"
            );
            let expected = if descend { [0.5, -0.5, 0.5] } else { [0.0; 3] };
            assert_eq!(x, expected, "descend = {descend}");
        }
    }

    #[test]
    fn a_non_finite_curvature_breaks_only_when_asked() {
        let b = [1.0, 2.0];
        let mut work = Workspace::<Real, Sequential>::default();
        let params = Params {
            max_iterations: 5,
            ..Params::default()
        };
        let info = solve(
            &mut Broken,
            &Identity,
            &b,
            &mut [0.0; 2],
            &params,
            &mut work,
            &Cancel::new(),
        );
        assert_eq!(info.iterations, 1);
        assert!(
            matches!(info.termination, Termination::Breakdown { curvature } if curvature.is_nan()),
            "{info:?}"
        );
        let params = Params {
            non_finite_breaks: false,
            ..params
        };
        let info = solve(
            &mut Broken,
            &Identity,
            &b,
            &mut [0.0; 2],
            &params,
            &mut work,
            &Cancel::new(),
        );
        assert_eq!(
            info,
            Info {
                iterations: 5,
                termination: Termination::IterationLimit
            }
        );
    }

    /// `A = diag(1, 2, ...)`, raising `cancel` on its `after`-th
    /// application, as another thread would mid-solve.
    struct Interrupting {
        cancel: Cancel,
        after: u32,
        applied: u32,
    }

    impl LinOp<Real> for Interrupting {
        fn apply(&mut self, x: &[Real], y: &mut [Real]) {
            for (k, (y, x)) in y.iter_mut().zip(x).enumerate() {
                *y = (k + 1) as Real * x;
            }
            self.applied += 1;
            if self.applied == self.after {
                self.cancel.cancel();
            }
        }
    }

    #[test]
    fn a_raised_cancel_stops_before_the_next_product() {
        let cancel = Cancel::new();
        let mut op = Interrupting {
            cancel: cancel.clone(),
            after: 3,
            applied: 0,
        };
        // Ten distinct eigenvalues: ten iterations to converge.
        let params = Params {
            tolerance: 0.0,
            max_iterations: 100,
            ..Params::default()
        };
        let mut work = Workspace::<Real, Sequential>::default();
        let b = [1.0; 10];
        let mut x = [0.0; 10];
        let info = solve(&mut op, &Identity, &b, &mut x, &params, &mut work, &cancel);
        assert_eq!(
            info,
            Info {
                iterations: 3,
                termination: Termination::Cancelled
            }
        );
        assert_eq!(op.applied, 3, "no product after the flag was raised");
        let info = solve(&mut op, &Identity, &b, &mut x, &params, &mut work, &cancel);
        assert_eq!(info.iterations, 0, "raised before the solve: {info:?}");
    }
}
