//! Levenberg–Marquardt for the optimiser's sparse nonlinear least squares.
//!
//! Every energy of Eq. 78 and Eq. 85 is a weighted sum of squares of
//! residuals that are polynomials in the unknowns (linear for handles,
//! velocities and accelerations; quadratic for rigidity, `grad f^T grad f -
//! I`; cubic for volume, `det grad f - 1`; piecewise for obstacles), so
//! `E(x) = |r(x)|^2`. Each iteration solves
//!
//! ```text
//! (J^T J + K^T K + mu D) d = -J^T r,       D = diag(J^T J + K^T K)
//! ```
//!
//! by conjugate gradients on products with `J`, `K` and their transposes
//! (the normal matrix is never formed), preconditioned by `LineBlocks`
//! (`normal.rs`, with the CG of [`crate::linalg::cg`]).
//! `K` holds *curvature rows* (residual zero): the positive part of the
//! second-order term `sum r_k grad^2 r_k` that Gauss–Newton drops (see
//! [`super::energy`]). Without them a stretched shape, whose rigidity
//! residuals are far from zero, gets steps that overshoot, and the solve
//! crawls; with them a drag frame converges in two or three iterations.
//! The damping `mu` follows Nielsen (1999): shrunk after a step that
//! lowered the energy, by how well the model predicted it, and doubled in
//! growth after one that did not. Before such a step is thrown away, the
//! minimum of the energy's parabola along it is tried, which costs one
//! evaluation instead of a new linear solve.
//!
//! **The Jacobian by blocks.** Each residual depends on the unknowns only
//! through a few *features* of a neighbourhood: the displacement gradient
//! at a quadrature point, or the field at a point. A block stores its
//! stencil once, column bases `b_j` and weights `w_j`, with features
//! `z_(a, c) = sum_j w_(j, c) x_(b_j + a)`, and each of its rows as a
//! derivative by the features; its Jacobian is that small matrix times the
//! stencil. A gradient block's seven to sixteen rows then cost one gather
//! and one scatter of its forty-odd neighbours, where explicit rows would
//! repeat the neighbours in every row.
//!
//! Why not a crate: the well-kept ones (argmin, levenberg-marquardt) work
//! on dense Jacobians, and a motion's has thousands of columns of which
//! each row touches a hundred. The optimiser's numerics are the product.
//!
//! - `rows.rs`: the residuals and the Jacobian by blocks (`Rows`,
//!   `Term`);
//! - `products.rs`: `J v`, `J^T w` and `diag(J^T J)` in parallel;
//! - `precond.rs`: the line-block preconditioner;
//! - `normal.rs`: the damped normal equations and their CG solve;
//! - here: the `LeastSquares` problem and `minimise`, the
//!   Levenberg–Marquardt iteration.

mod normal;
mod precond;
mod products;
mod rows;

pub(crate) use rows::{Rows, Term};

use super::DesignError;
use super::params::SolverParams;
use super::progress::{Energies, Observer, Progress, SolveInfo};
use crate::cancel::Cancel;
use crate::linalg::{Sequential, Space};
use crate::math::Real;
use normal::NormalEquations;
use precond::LineBlocks;
use products::Products;
use rayon::prelude::*;
use std::ops::ControlFlow;

/// `out = x + alpha step`.
fn step_from(x: &[Real], step: &[Real], alpha: Real, out: &mut [Real]) {
    for ((o, x), d) in out.iter_mut().zip(x).zip(step) {
        *o = x + alpha * d;
    }
}

/// A sum of squares over groups of residuals that can be evaluated
/// independently (one per particle and frame, say).
pub(crate) trait LeastSquares: Sync {
    fn unknowns(&self) -> usize;
    /// Unknowns `c` and `c + lines` belong to the same line (one particle
    /// component across frames); the preconditioner inverts each line's
    /// block of `J^T J` exactly. `unknowns()` for one line per unknown.
    fn lines(&self) -> usize {
        self.unknowns()
    }
    fn groups(&self) -> usize;
    /// Appends group `g`'s residuals at `x` to `rows`.
    fn group(&self, g: usize, x: &[Real], rows: &mut Rows);
}

/// Groups per parallel task.
const GROUP_CHUNK: usize = 16;

/// `problem`'s residuals at `x` (and their Jacobian, when asked for)
/// into `out`, groups evaluated in parallel and appended in order.
fn evaluate(problem: &impl LeastSquares, x: &[Real], jacobian: bool, out: &mut Rows) {
    let parts: Vec<Rows> = (0..problem.groups().div_ceil(GROUP_CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut rows = Rows::default();
            rows.reset(jacobian);
            for g in c * GROUP_CHUNK..((c + 1) * GROUP_CHUNK).min(problem.groups()) {
                problem.group(g, x, &mut rows);
            }
            rows
        })
        .collect();
    out.reset(jacobian);
    for p in &parts {
        out.append(p);
    }
}

/// Where this solve sits in a longer run, for progress reports.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct RunState {
    pub iteration: u32,
    pub linear_iterations: u64,
    pub frames: usize,
    pub inserted: usize,
    pub sampling_error: Option<Real>,
}

/// Minimises `|r(x)|^2` from `x`, overwriting it with the result.
/// `cancel` is read at every iteration, every damped retry within one and
/// every CG iteration, so a large problem stops within one of them.
///
/// # Errors
/// [`DesignError::Cancelled`] when the observer breaks or `cancel` is
/// raised (`x` then holds the last accepted iterate);
/// [`DesignError::Diverged`] naming the first term whose energy is not
/// finite.
pub(crate) fn minimise(
    problem: &impl LeastSquares,
    x: &mut [Real],
    params: &SolverParams,
    run: &mut RunState,
    observer: &mut Observer<'_>,
    cancel: &Cancel,
) -> Result<SolveInfo, DesignError> {
    let cancelled = |run: &RunState| DesignError::Cancelled {
        iteration: run.iteration,
    };
    let n = problem.unknowns();
    let mut rows = Rows::default();
    let mut trial_rows = Rows::default();
    let mut products = Products::default();
    let mut g = vec![0.0; n];
    let mut diag = vec![0.0; n];
    let mut step = vec![0.0; n];
    let mut trial = vec![0.0; n];
    let mut normal = NormalEquations::default();
    let mut blocks = LineBlocks::new(problem.lines(), n);
    let mut mu: Real = 1e-4;
    let mut growth: Real = 2.0;
    let mut converged = false;
    let mut iterations = 0;
    let (mut energies, mut gradient_norm);
    loop {
        if cancel.is_cancelled() {
            return Err(cancelled(run));
        }
        evaluate(problem, x, true, &mut rows);
        energies = rows.energies();
        check_finite(&energies, run.iteration)?;
        let energy = energies.total();
        products.split(&rows, n);
        products.apply_jt(&rows, &rows.residuals, &mut g);
        gradient_norm = g.iter().fold(0.0, |m: Real, v| m.max(v.abs()));
        let report = Progress {
            iteration: run.iteration,
            energies,
            gradient_norm,
            linear_iterations: run.linear_iterations,
            frames: run.frames,
            inserted: run.inserted,
            sampling_error: run.sampling_error,
        };
        if let ControlFlow::Break(()) = observer(&report) {
            return Err(cancelled(run));
        }
        if gradient_norm <= params.tolerance * (1.0 + energy) {
            converged = true;
            break;
        }
        if iterations >= params.max_iterations {
            break;
        }
        // D = diag(J^T J), floored so that unknowns no residual touches
        // stay put instead of making the system singular.
        products.diagonal(&rows, &mut diag);
        let floor = 1e-12 * diag.iter().fold(0.0, |m: Real, v| m.max(*v)).max(1e-300);
        diag.iter_mut().for_each(|d| *d = d.max(floor));
        blocks.assemble(&rows, &diag);
        let accepted = loop {
            if cancel.is_cancelled() {
                return Err(cancelled(run));
            }
            iterations += 1;
            run.iteration += 1;
            blocks.factor(&diag, mu);
            run.linear_iterations += normal
                .solve(
                    &rows,
                    &mut products,
                    &diag,
                    mu,
                    &blocks,
                    &g,
                    &mut step,
                    params,
                    cancel,
                )
                .map_err(|_| cancelled(run))?;
            step_from(x, &step, 1.0, &mut trial);
            evaluate(problem, &trial, false, &mut trial_rows);
            let new_energy = trial_rows.energies().total();
            // Model decrease: -(2 g.d + d^T J^T J d) = -(g.d) + mu d^T D d
            // at the CG solution; computed directly, it is robust to an
            // inexact solve.
            let jd = normal.jd(&rows, &products, &step);
            let predicted = -(2.0 * Sequential::dot(&g, &step) + Sequential::dot(jd, jd));
            if new_energy.is_finite() && new_energy < energy {
                let rho = (energy - new_energy) / predicted.max(Real::MIN_POSITIVE);
                mu *= (1.0 - (2.0 * rho - 1.0).powi(3)).max(1.0 / 3.0);
                growth = 2.0;
                x.copy_from_slice(&trial);
                break Some(new_energy);
            }
            // The model still misses curvature where the volume's or a
            // compressed rigidity's second-order terms matter: before a
            // new damped solve, try the minimum of the energy's parabola
            // along this step, which costs one evaluation.
            let slope = 2.0 * Sequential::dot(&g, &step);
            let curvature = new_energy - energy - slope;
            if new_energy.is_finite() && slope < 0.0 && curvature > 0.0 {
                let alpha = (-slope / (2.0 * curvature)).clamp(0.1, 0.9);
                step_from(x, &step, alpha, &mut trial);
                evaluate(problem, &trial, false, &mut trial_rows);
                let shorter = trial_rows.energies().total();
                if shorter.is_finite() && shorter < energy {
                    // Accepted, but the model was poor: damp the next step.
                    mu *= 2.0;
                    growth = 2.0;
                    step.iter_mut().for_each(|d| *d *= alpha);
                    x.copy_from_slice(&trial);
                    break Some(shorter);
                }
            }
            mu *= growth;
            growth *= 2.0;
            if mu > 1e16 || iterations >= params.max_iterations {
                break None;
            }
        };
        let step_size = step.iter().fold(0.0, |m: Real, v| m.max(v.abs()));
        match accepted {
            // No step lowers the energy: a minimum up to rounding.
            None => {
                converged = mu > 1e16;
                evaluate(problem, x, false, &mut rows);
                energies = rows.energies();
                break;
            }
            Some(new_energy) => {
                if energy - new_energy <= params.tolerance * energy || step_size <= params.tolerance
                {
                    converged = true;
                    evaluate(problem, x, true, &mut rows);
                    energies = rows.energies();
                    products.split(&rows, n);
                    products.apply_jt(&rows, &rows.residuals, &mut g);
                    gradient_norm = g.iter().fold(0.0, |m: Real, v| m.max(v.abs()));
                    break;
                }
            }
        }
    }
    Ok(SolveInfo {
        iterations,
        energies,
        gradient_norm,
        linear_iterations: run.linear_iterations,
        converged,
        frames: run.frames,
        inserted: run.inserted,
        sampling_error: run.sampling_error,
    })
}

fn check_finite(e: &Energies, iteration: u32) -> Result<(), DesignError> {
    match e.named().into_iter().find(|(_, v)| !v.is_finite()) {
        Some((term, _)) => Err(DesignError::Diverged {
            term,
            iteration,
            energies: *e,
        }),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rosenbrock's function as least squares, `r = (10 (y - x^2), 1 -
    /// x)`: the curved valley that defeats plain Gauss–Newton steps and
    /// that the damping must follow to the minimum at (1, 1).
    struct Rosenbrock;

    impl LeastSquares for Rosenbrock {
        fn unknowns(&self) -> usize {
            2
        }
        fn groups(&self) -> usize {
            1
        }
        fn group(&self, _: usize, x: &[Real], rows: &mut Rows) {
            // Features: the two unknowns themselves.
            rows.block(2, 1, [(0, [1.0, 0.0, 0.0])]);
            rows.push(
                Term::Handle,
                10.0 * (x[1] - x[0] * x[0]),
                &[-20.0 * x[0], 10.0],
            );
            rows.push(Term::Rigidity, 1.0 - x[0], &[-1.0, 0.0]);
        }
    }

    #[test]
    fn levenberg_marquardt_finds_rosenbrocks_minimum() {
        let mut x = [-1.2, 1.0];
        let params = SolverParams {
            tolerance: 1e-12,
            linear_tolerance: 1e-10,
            ..SolverParams::default()
        };
        let mut run = RunState::default();
        let info = minimise(
            &Rosenbrock,
            &mut x,
            &params,
            &mut run,
            &mut |_| ControlFlow::Continue(()),
            &Cancel::new(),
        )
        .expect("solves");
        assert!(
            (x[0] - 1.0).abs() < 1e-6 && (x[1] - 1.0).abs() < 1e-6,
            "{x:?} {info:?}"
        );
        assert!(info.converged && info.energies.total() < 1e-12, "{info:?}");
    }

    #[test]
    fn a_non_finite_energy_names_its_term() {
        struct Broken;
        impl LeastSquares for Broken {
            fn unknowns(&self) -> usize {
                1
            }
            fn groups(&self) -> usize {
                1
            }
            fn group(&self, _: usize, x: &[Real], rows: &mut Rows) {
                rows.block(1, 1, [(0, [1.0, 0.0, 0.0])]);
                rows.push(Term::Volume, Real::NAN * x[0], &[1.0]);
            }
        }
        let mut x = [1.0];
        let err = minimise(
            &Broken,
            &mut x,
            &SolverParams::default(),
            &mut RunState::default(),
            &mut |_| ControlFlow::Continue(()),
            &Cancel::new(),
        )
        .expect_err("NaN");
        assert!(
            matches!(err, DesignError::Diverged { term: "volume", .. }),
            "{err}"
        );
    }

    /// Rosenbrock, whose first trial point (inside the first iteration)
    /// has another thread raise the solve's flag and waits until it has.
    struct RaisedMidIteration {
        evaluations: std::sync::atomic::AtomicU32,
        inside: std::sync::Mutex<std::sync::mpsc::Sender<()>>,
        cancel: Cancel,
    }

    impl LeastSquares for RaisedMidIteration {
        fn unknowns(&self) -> usize {
            2
        }
        fn groups(&self) -> usize {
            1
        }
        fn group(&self, g: usize, x: &[Real], rows: &mut Rows) {
            let call = 1 + self
                .evaluations
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            if call == 2 {
                self.inside
                    .lock()
                    .expect("not poisoned")
                    .send(())
                    .expect("the canceller waits");
                let start = std::time::Instant::now();
                while !self.cancel.is_cancelled() {
                    assert!(
                        start.elapsed() < std::time::Duration::from_secs(10),
                        "the flag never went up"
                    );
                    std::thread::yield_now();
                }
            }
            Rosenbrock.group(g, x, rows);
        }
    }

    #[test]
    fn a_flag_raised_by_another_thread_stops_the_solve_within_its_iteration() {
        let cancel = Cancel::new();
        let (inside, entered) = std::sync::mpsc::channel();
        let canceller = {
            let cancel = cancel.clone();
            std::thread::spawn(move || {
                entered.recv().expect("the solve reaches its trial point");
                cancel.cancel();
            })
        };
        let problem = RaisedMidIteration {
            evaluations: 0.into(),
            inside: std::sync::Mutex::new(inside),
            cancel: cancel.clone(),
        };
        let mut reports = 0;
        let mut x = [-1.2, 1.0];
        let err = minimise(
            &problem,
            &mut x,
            &SolverParams::default(),
            &mut RunState::default(),
            // Never breaks: the flag alone stops the solve.
            &mut |_| {
                reports += 1;
                ControlFlow::Continue(())
            },
            &cancel,
        )
        .expect_err("cancelled");
        canceller.join().expect("the canceller ends");
        assert_eq!(err, DesignError::Cancelled { iteration: 1 });
        assert_eq!(reports, 1, "stopped before the next iteration's report");
    }
}
