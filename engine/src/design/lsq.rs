//! Levenberg–Marquardt for the optimiser's sparse nonlinear least squares.
//!
//! Every energy of Eq. 78 and Eq. 85 is a weighted sum of squares of
//! residuals that are polynomials in the unknowns (linear for handles,
//! velocities and accelerations; quadratic for rigidity, `grad f^T grad f -
//! I`; cubic for volume, `det grad f - 1`; piecewise for obstacles), so
//! `E(x) = |r(x)|^2` and Gauss–Newton's model `|r + J d|^2` is exact for
//! the linear terms and needs no second derivatives for the rest. Each
//! iteration solves
//!
//! ```text
//! (J^T J + mu D) d = -J^T r,       D = diag(J^T J)
//! ```
//!
//! by conjugate gradients on products with `J` and `J^T` (both kept as
//! sparse rows; `J^T J` is never formed), preconditioned by the diagonal.
//! The damping `mu` follows Nielsen (1999): shrunk after a step that
//! lowered the energy, by how well the model predicted it, and doubled in
//! growth after one that did not (which is then retried). Starting from
//! the previous solution (a handle dragged a little), the first step is
//! nearly a Gauss–Newton step and one or two suffice.
//!
//! Why not a crate: the well-kept ones (argmin, levenberg-marquardt) work
//! on dense Jacobians, and a motion's has thousands of columns of which
//! each row touches a hundred. The sparse linear algebra here is two
//! loops; the optimiser's numerics are the product.

use super::DesignError;
use super::params::SolverParams;
use super::progress::{Energies, Observer, Progress, SolveInfo};
use crate::math::Real;
use rayon::prelude::*;
use std::ops::ControlFlow;

/// Which energy a residual belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Term {
    Handle,
    Rigidity,
    Volume,
    Velocity,
    Acceleration,
    Obstacle,
}

impl Term {
    pub(crate) fn name(self) -> &'static str {
        match self {
            Self::Handle => "handle",
            Self::Rigidity => "rigidity",
            Self::Volume => "volume",
            Self::Velocity => "velocity",
            Self::Acceleration => "acceleration",
            Self::Obstacle => "obstacle",
        }
    }

    fn slot(self, e: &mut Energies) -> &mut Real {
        match self {
            Self::Handle => &mut e.handle,
            Self::Rigidity => &mut e.rigidity,
            Self::Volume => &mut e.volume,
            Self::Velocity => &mut e.velocity,
            Self::Acceleration => &mut e.acceleration,
            Self::Obstacle => &mut e.obstacle,
        }
    }
}

/// Residuals and, when asked for, their Jacobian as sparse rows.
#[derive(Debug, Clone, Default)]
pub(crate) struct Rows {
    pub residuals: Vec<Real>,
    pub terms: Vec<Term>,
    offsets: Vec<u32>,
    columns: Vec<u32>,
    values: Vec<Real>,
    jacobian: bool,
}

impl Rows {
    fn clear(&mut self, jacobian: bool) {
        self.residuals.clear();
        self.terms.clear();
        self.offsets.clear();
        self.offsets.push(0);
        self.columns.clear();
        self.values.clear();
        self.jacobian = jacobian;
    }

    /// Whether the entries are wanted (else only residuals are kept).
    pub fn wants_jacobian(&self) -> bool {
        self.jacobian
    }

    /// Appends a residual and its derivative entries `(column, value)`.
    pub fn push(
        &mut self,
        term: Term,
        residual: Real,
        entries: impl IntoIterator<Item = (u32, Real)>,
    ) {
        self.residuals.push(residual);
        self.terms.push(term);
        if self.jacobian {
            for (c, v) in entries {
                self.columns.push(c);
                self.values.push(v);
            }
        }
        self.offsets.push(self.columns.len() as u32);
    }

    fn append(&mut self, other: &Rows) {
        let base = self.columns.len() as u32;
        self.residuals.extend_from_slice(&other.residuals);
        self.terms.extend_from_slice(&other.terms);
        self.offsets
            .extend(other.offsets[1..].iter().map(|o| o + base));
        self.columns.extend_from_slice(&other.columns);
        self.values.extend_from_slice(&other.values);
    }

    fn energies(&self) -> Energies {
        let mut e = Energies::default();
        for (r, t) in self.residuals.iter().zip(&self.terms) {
            *t.slot(&mut e) += r * r;
        }
        e
    }

    fn row(&self, k: usize) -> (&[u32], &[Real]) {
        let r = self.offsets[k] as usize..self.offsets[k + 1] as usize;
        (&self.columns[r.clone()], &self.values[r])
    }
}

/// A sum of squares over groups of residuals that can be evaluated
/// independently (one per particle and frame, say).
pub(crate) trait LeastSquares: Sync {
    fn unknowns(&self) -> usize;
    fn groups(&self) -> usize;
    /// Appends group `g`'s residuals at `x` to `rows`.
    fn group(&self, g: usize, x: &[Real], rows: &mut Rows);
}

/// Groups per parallel task.
const GROUP_CHUNK: usize = 16;

fn evaluate(problem: &impl LeastSquares, x: &[Real], jacobian: bool, out: &mut Rows) {
    let parts: Vec<Rows> = (0..problem.groups().div_ceil(GROUP_CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut rows = Rows::default();
            rows.clear(jacobian);
            for g in c * GROUP_CHUNK..((c + 1) * GROUP_CHUNK).min(problem.groups()) {
                problem.group(g, x, &mut rows);
            }
            rows
        })
        .collect();
    out.clear(jacobian);
    for p in &parts {
        out.append(p);
    }
}

/// `J^T` as sparse rows over the unknowns, for parallel products.
#[derive(Debug, Default)]
struct Transposed {
    offsets: Vec<u32>,
    rows: Vec<u32>,
    values: Vec<Real>,
}

impl Transposed {
    fn build(&mut self, j: &Rows, n: usize) {
        self.offsets.clear();
        self.offsets.resize(n + 1, 0);
        for &c in &j.columns {
            self.offsets[c as usize + 1] += 1;
        }
        for k in 0..n {
            self.offsets[k + 1] += self.offsets[k];
        }
        let mut next: Vec<u32> = self.offsets[..n].to_vec();
        self.rows.resize(j.columns.len(), 0);
        self.values.resize(j.columns.len(), 0.0);
        for k in 0..j.residuals.len() {
            let (cs, vs) = j.row(k);
            for (&c, &v) in cs.iter().zip(vs) {
                let at = next[c as usize] as usize;
                self.rows[at] = k as u32;
                self.values[at] = v;
                next[c as usize] += 1;
            }
        }
    }

    /// `out = J^T w`.
    fn apply(&self, w: &[Real], out: &mut [Real]) {
        out.par_iter_mut().enumerate().for_each(|(c, o)| {
            let r = self.offsets[c] as usize..self.offsets[c + 1] as usize;
            *o = self.rows[r.clone()]
                .iter()
                .zip(&self.values[r])
                .map(|(&k, v)| v * w[k as usize])
                .sum();
        });
    }
}

/// `out = J v`.
fn apply_j(j: &Rows, v: &[Real], out: &mut [Real]) {
    out.par_iter_mut().enumerate().for_each(|(k, o)| {
        let (cs, vs) = j.row(k);
        *o = cs.iter().zip(vs).map(|(&c, a)| a * v[c as usize]).sum();
    });
}

fn dot(a: &[Real], b: &[Real]) -> Real {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Where this solve sits in a longer run, for progress reports.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct RunState {
    pub iteration: u32,
    pub frames: usize,
    pub inserted: usize,
    pub sampling_error: Option<Real>,
}

/// Minimises `|r(x)|^2` from `x`, overwriting it with the result.
///
/// # Errors
/// [`DesignError::Cancelled`] when the observer breaks (`x` then holds the
/// last accepted iterate); [`DesignError::Diverged`] naming the first term
/// whose energy is not finite.
pub(crate) fn minimise(
    problem: &impl LeastSquares,
    x: &mut [Real],
    params: &SolverParams,
    run: &mut RunState,
    observer: &mut Observer<'_>,
) -> Result<SolveInfo, DesignError> {
    let n = problem.unknowns();
    let mut rows = Rows::default();
    let mut trial_rows = Rows::default();
    let mut jt = Transposed::default();
    let mut g = vec![0.0; n];
    let mut diag = vec![0.0; n];
    let mut step = vec![0.0; n];
    let mut trial = vec![0.0; n];
    let mut cg = Cg::new(n);
    let mut mu: Real = 1e-4;
    let mut growth: Real = 2.0;
    let mut converged = false;
    let mut iterations = 0;
    let (mut energies, mut gradient_norm);
    loop {
        evaluate(problem, x, true, &mut rows);
        energies = rows.energies();
        check_finite(&energies, run.iteration)?;
        let energy = energies.total();
        jt.build(&rows, n);
        jt.apply(&rows.residuals, &mut g);
        gradient_norm = g.iter().fold(0.0, |m: Real, v| m.max(v.abs()));
        let report = Progress {
            iteration: run.iteration,
            energies,
            gradient_norm,
            frames: run.frames,
            inserted: run.inserted,
            sampling_error: run.sampling_error,
        };
        if let ControlFlow::Break(()) = observer(&report) {
            return Err(DesignError::Cancelled {
                iteration: run.iteration,
            });
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
        diag.par_iter_mut().enumerate().for_each(|(c, d)| {
            let r = jt.offsets[c] as usize..jt.offsets[c + 1] as usize;
            *d = jt.values[r].iter().map(|v| v * v).sum();
        });
        let floor = 1e-12 * diag.iter().fold(0.0, |m: Real, v| m.max(*v)).max(1e-300);
        diag.iter_mut().for_each(|d| *d = d.max(floor));
        let accepted = loop {
            iterations += 1;
            run.iteration += 1;
            cg.solve(&rows, &jt, &diag, mu, &g, &mut step, params);
            for ((t, x), d) in trial.iter_mut().zip(x.iter()).zip(&step) {
                *t = x + d;
            }
            evaluate(problem, &trial, false, &mut trial_rows);
            let new_energy = trial_rows.energies().total();
            // Model decrease: -(2 g.d + d^T J^T J d) = -(g.d) + mu d^T D d
            // at the CG solution; computed directly, it is robust to an
            // inexact solve.
            let jd = cg.jd(&rows, &step);
            let predicted = -(2.0 * dot(&g, &step) + dot(&jd, &jd));
            if new_energy.is_finite() && new_energy < energy {
                let rho = (energy - new_energy) / predicted.max(Real::MIN_POSITIVE);
                mu *= (1.0 - (2.0 * rho - 1.0).powi(3)).max(1.0 / 3.0);
                growth = 2.0;
                x.copy_from_slice(&trial);
                break Some(new_energy);
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
                    jt.build(&rows, n);
                    jt.apply(&rows.residuals, &mut g);
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
        converged,
        frames: run.frames,
        inserted: run.inserted,
        sampling_error: run.sampling_error,
    })
}

/// The energies of `x` without a Jacobian.
pub(crate) fn energies(problem: &impl LeastSquares, x: &[Real]) -> Energies {
    let mut rows = Rows::default();
    evaluate(problem, x, false, &mut rows);
    rows.energies()
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

/// Preconditioned conjugate gradients on `(J^T J + mu D) d = -g`.
#[derive(Debug)]
struct Cg {
    r: Vec<Real>,
    z: Vec<Real>,
    p: Vec<Real>,
    q: Vec<Real>,
    jp: Vec<Real>,
}

impl Cg {
    fn new(n: usize) -> Self {
        Self {
            r: vec![0.0; n],
            z: vec![0.0; n],
            p: vec![0.0; n],
            q: vec![0.0; n],
            jp: Vec::new(),
        }
    }

    fn jd(&mut self, j: &Rows, d: &[Real]) -> Vec<Real> {
        let mut out = vec![0.0; j.residuals.len()];
        apply_j(j, d, &mut out);
        out
    }

    #[allow(clippy::too_many_arguments)]
    fn solve(
        &mut self,
        j: &Rows,
        jt: &Transposed,
        diag: &[Real],
        mu: Real,
        g: &[Real],
        d: &mut [Real],
        params: &SolverParams,
    ) {
        let Self { r, z, p, q, jp } = self;
        jp.resize(j.residuals.len(), 0.0);
        d.fill(0.0);
        for (r, g) in r.iter_mut().zip(g) {
            *r = -g;
        }
        let precondition = |r: &[Real], z: &mut [Real]| {
            for ((z, r), d) in z.iter_mut().zip(r).zip(diag) {
                *z = r / (d * (1.0 + mu));
            }
        };
        precondition(r, z);
        p.copy_from_slice(z);
        let mut rz = dot(r, z);
        let stop = params.linear_tolerance.powi(2) * dot(r, r);
        for _ in 0..params.max_linear_iterations {
            apply_j(j, p, jp);
            jt.apply(jp, q);
            for ((q, p), d) in q.iter_mut().zip(p.iter()).zip(diag) {
                *q += mu * d * p;
            }
            let pq = dot(p, q);
            if pq <= 0.0 || !pq.is_finite() {
                break;
            }
            let alpha = rz / pq;
            for ((d, r), (p, q)) in d.iter_mut().zip(r.iter_mut()).zip(p.iter().zip(q.iter())) {
                *d += alpha * p;
                *r -= alpha * q;
            }
            if dot(r, r) <= stop {
                break;
            }
            precondition(r, z);
            let rz_next = dot(r, z);
            let beta = rz_next / rz;
            rz = rz_next;
            for (p, z) in p.iter_mut().zip(z.iter()) {
                *p = z + beta * *p;
            }
        }
    }
}
