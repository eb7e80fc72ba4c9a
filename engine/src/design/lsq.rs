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
    pub(crate) fn reset(&mut self, jacobian: bool) {
        self.residuals.clear();
        self.terms.clear();
        self.offsets.clear();
        self.offsets.push(0);
        self.columns.clear();
        self.values.clear();
        self.jacobian = jacobian;
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

    /// Row `k`'s columns and values.
    pub(crate) fn entries(&self, k: usize) -> (&[u32], &[Real]) {
        let r = self.offsets[k] as usize..self.offsets[k + 1] as usize;
        (&self.columns[r.clone()], &self.values[r])
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
            let (cs, vs) = j.entries(k);
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
        let (cs, vs) = j.entries(k);
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
    pub linear_iterations: u64,
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
    let mut blocks = LineBlocks::new(problem.lines(), n);
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
            linear_iterations: run.linear_iterations,
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
        blocks.assemble(&rows, &diag);
        let accepted = loop {
            iterations += 1;
            run.iteration += 1;
            blocks.factor(&diag, mu);
            run.linear_iterations +=
                cg.solve(&rows, &jt, &diag, mu, &blocks, &g, &mut step, params);
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
        blocks: &LineBlocks,
        g: &[Real],
        d: &mut [Real],
        params: &SolverParams,
    ) -> u64 {
        let Self { r, z, p, q, jp } = self;
        jp.resize(j.residuals.len(), 0.0);
        d.fill(0.0);
        for (r, g) in r.iter_mut().zip(g) {
            *r = -g;
        }
        blocks.apply(r, z);
        p.copy_from_slice(z);
        let mut rz = dot(r, z);
        let stop = params.linear_tolerance.powi(2) * dot(r, r);
        let mut iterations = 0;
        while iterations < params.max_linear_iterations {
            iterations += 1;
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
            blocks.apply(r, z);
            let rz_next = dot(r, z);
            let beta = rz_next / rz;
            rz = rz_next;
            for (p, z) in p.iter_mut().zip(z.iter()) {
                *p = z + beta * *p;
            }
        }
        u64::from(iterations)
    }
}

/// The blocks of `J^T J + mu D` that couple the unknowns of one line
/// (a particle component across a motion's frames), Cholesky-factored:
/// the acceleration terms couple frames only along lines, so their
/// stiffness, which grows as frames crowd together, is inverted exactly
/// and conjugate gradients see only the spatial coupling. With one frame
/// this is the diagonal (Jacobi) preconditioner.
#[derive(Debug)]
struct LineBlocks {
    lines: usize,
    /// Unknowns per line.
    length: usize,
    /// `J^T J` restricted to each line, `length x length`, row-major.
    blocks: Vec<Real>,
    /// Their Cholesky factors with the damping added.
    factors: Vec<Real>,
}

impl LineBlocks {
    fn new(lines: usize, n: usize) -> Self {
        let length = n.div_ceil(lines.max(1));
        Self {
            lines,
            length,
            blocks: vec![0.0; lines * length * length],
            factors: vec![0.0; lines * length * length],
        }
    }

    /// Accumulates the line blocks from `J`'s rows; the diagonal is
    /// `diag` (already floored).
    fn assemble(&mut self, j: &Rows, diag: &[Real]) {
        let (lines, length) = (self.lines, self.length);
        let size = length * length;
        self.blocks.fill(0.0);
        if length > 1 {
            let rows = j.residuals.len();
            let chunk = rows.div_ceil(rayon::current_num_threads().max(1)).max(1);
            let partial: Vec<Vec<Real>> = (0..rows.div_ceil(chunk))
                .into_par_iter()
                .map(|c| {
                    let mut blocks = vec![0.0; lines * size];
                    let mut entries: Vec<(u32, u32, Real)> = Vec::new();
                    for k in c * chunk..((c + 1) * chunk).min(rows) {
                        let (cs, vs) = j.entries(k);
                        // A row within one frame adds only to diagonals.
                        let first = cs.first().map_or(0, |&c| c as usize / lines);
                        if cs.iter().all(|&c| c as usize / lines == first) {
                            continue;
                        }
                        entries.clear();
                        entries.extend(cs.iter().zip(vs).map(|(&c, &v)| {
                            let c = c as usize;
                            ((c % lines) as u32, (c / lines) as u32, v)
                        }));
                        entries.sort_unstable_by_key(|e| (e.0, e.1));
                        let mut start = 0;
                        while start < entries.len() {
                            let line = entries[start].0;
                            let end =
                                start + entries[start..].iter().take_while(|e| e.0 == line).count();
                            let block = &mut blocks[line as usize * size..][..size];
                            for a in &entries[start..end] {
                                for b in &entries[start..end] {
                                    if a.1 != b.1 {
                                        block[a.1 as usize * length + b.1 as usize] += a.2 * b.2;
                                    }
                                }
                            }
                            start = end;
                        }
                    }
                    blocks
                })
                .collect();
            for p in partial {
                for (b, v) in self.blocks.iter_mut().zip(p) {
                    *b += v;
                }
            }
        }
        for (c, d) in diag.iter().enumerate() {
            let (line, at) = (c % lines, c / lines);
            self.blocks[line * size + at * length + at] = *d;
        }
        // Unknowns past the end of the last line (none in practice) keep
        // a unit diagonal so every block is definite.
        for c in diag.len()..lines * length {
            let (line, at) = (c % lines, c / lines);
            self.blocks[line * size + at * length + at] = 1.0;
        }
    }

    /// Factors each block with `mu D` added to its diagonal.
    fn factor(&mut self, diag: &[Real], mu: Real) {
        let (lines, length) = (self.lines, self.length);
        let size = length * length;
        self.factors
            .par_chunks_mut(size)
            .zip(self.blocks.par_chunks(size))
            .enumerate()
            .for_each(|(line, (f, b))| {
                f.copy_from_slice(b);
                for at in 0..length {
                    let c = at * lines + line;
                    let d = diag.get(c).copied().unwrap_or(1.0);
                    f[at * length + at] += mu * d;
                }
                cholesky_in_place(f, length);
            });
    }

    /// `z = B^-1 r`, line by line.
    fn apply(&self, r: &[Real], z: &mut [Real]) {
        let (lines, length) = (self.lines, self.length);
        let size = length * length;
        if length == 1 {
            for ((z, r), f) in z.iter_mut().zip(r).zip(&self.factors) {
                *z = r / (f * f);
            }
            return;
        }
        let solved: Vec<Vec<Real>> = self
            .factors
            .par_chunks(size)
            .enumerate()
            .map(|(line, f)| {
                let mut y: Vec<Real> = (0..length)
                    .map(|at| r.get(at * lines + line).copied().unwrap_or(0.0))
                    .collect();
                cholesky_solve(f, length, &mut y);
                y
            })
            .collect();
        for (line, y) in solved.iter().enumerate() {
            for (at, v) in y.iter().enumerate() {
                if let Some(z) = z.get_mut(at * lines + line) {
                    *z = *v;
                }
            }
        }
    }
}

/// Lower Cholesky factor of the symmetric `n x n` matrix `a` (row-major),
/// in place. A non-positive pivot (the block is only semi-definite in
/// rounding) is replaced by a tiny positive one.
fn cholesky_in_place(a: &mut [Real], n: usize) {
    for k in 0..n {
        let mut d = a[k * n + k];
        for m in 0..k {
            d -= a[k * n + m] * a[k * n + m];
        }
        let d = d.max(1e-300).sqrt();
        a[k * n + k] = d;
        for i in k + 1..n {
            let mut v = a[i * n + k];
            for m in 0..k {
                v -= a[i * n + m] * a[k * n + m];
            }
            a[i * n + k] = v / d;
        }
    }
}

/// Solves `L L^T y = b` in place with the factor from
/// [`cholesky_in_place`].
fn cholesky_solve(l: &[Real], n: usize, y: &mut [Real]) {
    for i in 0..n {
        let mut v = y[i];
        for m in 0..i {
            v -= l[i * n + m] * y[m];
        }
        y[i] = v / l[i * n + i];
    }
    for i in (0..n).rev() {
        let mut v = y[i];
        for m in i + 1..n {
            v -= l[m * n + i] * y[m];
        }
        y[i] = v / l[i * n + i];
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
            rows.push(
                Term::Handle,
                10.0 * (x[1] - x[0] * x[0]),
                [(0, -20.0 * x[0]), (1, 10.0)],
            );
            rows.push(Term::Rigidity, 1.0 - x[0], [(0, -1.0)]);
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
        let info = minimise(&Rosenbrock, &mut x, &params, &mut run, &mut |_| {
            ControlFlow::Continue(())
        })
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
                rows.push(Term::Volume, Real::NAN * x[0], [(0, 1.0)]);
            }
        }
        let mut x = [1.0];
        let err = minimise(
            &Broken,
            &mut x,
            &SolverParams::default(),
            &mut RunState::default(),
            &mut |_| ControlFlow::Continue(()),
        )
        .expect_err("NaN");
        assert!(
            matches!(err, DesignError::Diverged { term: "volume", .. }),
            "{err}"
        );
    }
}
