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
//! (the normal matrix is never formed), preconditioned by `LineBlocks`.
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

use super::DesignError;
use super::params::SolverParams;
use super::progress::{Energies, Observer, Progress, SolveInfo};
use crate::math::Real;
use rayon::prelude::*;
use std::ops::{ControlFlow, Range};

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

/// Features per block at most: a 3x3 gradient.
const MAX_FEATURES: usize = 9;

/// Rows of a block that spans frames (a keyframe, velocity, obstacle or
/// acceleration block has one per dimension, or one per obstacle) that
/// the preconditioner couples across frames; larger ones, which no
/// energy here makes, would count only on the diagonal.
const MAX_ROWS: usize = 8;

/// Where a block's rows, stencil and matrix start.
#[derive(Debug, Clone, Copy)]
struct Block {
    row: u32,
    stencil: u32,
    /// Weights are `q` per stencil entry, so their start differs.
    weight: u32,
    matrix: u32,
    /// Unknowns per stencil entry (the dimension).
    dim: u8,
    /// Weights per stencil entry.
    q: u8,
}

impl Block {
    fn features(&self) -> usize {
        usize::from(self.dim) * usize::from(self.q)
    }
}

/// Residuals and, when asked for, their Jacobian by blocks.
#[derive(Debug, Clone, Default)]
pub(crate) struct Rows {
    pub residuals: Vec<Real>,
    pub terms: Vec<Term>,
    blocks: Vec<Block>,
    bases: Vec<u32>,
    weights: Vec<Real>,
    /// Each block's rows' derivatives by its features, row-major.
    matrix: Vec<Real>,
    jacobian: bool,
}

impl Rows {
    pub(crate) fn reset(&mut self, jacobian: bool) {
        self.residuals.clear();
        self.terms.clear();
        self.blocks.clear();
        self.bases.clear();
        self.weights.clear();
        self.matrix.clear();
        self.jacobian = jacobian;
    }

    /// Starts a block: the rows pushed next depend on the unknowns
    /// through features `z_(a, c) = sum_j w_(j, c) x_(b_j + a)`, `a <
    /// dim`, `c < q`, over the `stencil` entries `(b_j, w_j)` (the first
    /// `q` weights of each are used). `q` is 1 (a field value) or `dim`
    /// (a gradient).
    pub fn block(
        &mut self,
        dim: usize,
        q: usize,
        stencil: impl IntoIterator<Item = (usize, [Real; 3])>,
    ) {
        // An internal invariant, not input: the products are specialised
        // for these shapes.
        assert!(
            (1..=3).contains(&dim) && (q == 1 || q == dim),
            "a block has dim 1 to 3 and one or dim weights per entry"
        );
        if !self.jacobian {
            return;
        }
        self.blocks.push(Block {
            row: self.residuals.len() as u32,
            stencil: self.bases.len() as u32,
            weight: self.weights.len() as u32,
            matrix: self.matrix.len() as u32,
            dim: dim as u8,
            q: q as u8,
        });
        for (base, w) in stencil {
            self.bases.push(base as u32);
            self.weights.extend_from_slice(&w[..q]);
        }
    }

    /// Appends a residual of the current block and its derivative by the
    /// block's features, feature `(a, c)` at `a * q + c`.
    pub fn push(&mut self, term: Term, residual: Real, derivative: &[Real]) {
        self.residuals.push(residual);
        self.terms.push(term);
        if self.jacobian {
            debug_assert_eq!(
                Some(derivative.len()),
                self.blocks.last().map(Block::features)
            );
            self.matrix.extend_from_slice(derivative);
        }
    }

    fn append(&mut self, other: &Rows) {
        let (row, stencil, weight, matrix) = (
            self.residuals.len() as u32,
            self.bases.len() as u32,
            self.weights.len() as u32,
            self.matrix.len() as u32,
        );
        self.residuals.extend_from_slice(&other.residuals);
        self.terms.extend_from_slice(&other.terms);
        self.blocks.extend(other.blocks.iter().map(|b| Block {
            row: b.row + row,
            stencil: b.stencil + stencil,
            weight: b.weight + weight,
            matrix: b.matrix + matrix,
            ..*b
        }));
        self.bases.extend_from_slice(&other.bases);
        self.weights.extend_from_slice(&other.weights);
        self.matrix.extend_from_slice(&other.matrix);
    }

    fn energies(&self) -> Energies {
        let mut e = Energies::default();
        for (r, t) in self.residuals.iter().zip(&self.terms) {
            *t.slot(&mut e) += r * r;
        }
        e
    }

    /// Block `b`'s rows and stencil entries.
    fn ranges(&self, b: usize) -> (Range<usize>, Range<usize>) {
        let this = &self.blocks[b];
        let (row_end, stencil_end) = match self.blocks.get(b + 1) {
            Some(next) => (next.row as usize, next.stencil as usize),
            None => (self.residuals.len(), self.bases.len()),
        };
        (
            this.row as usize..row_end,
            this.stencil as usize..stencil_end,
        )
    }

    /// The weights of stencil entry `s` of block `b`.
    fn weights_of(&self, b: usize, s: usize) -> &[Real] {
        let block = &self.blocks[b];
        let q = usize::from(block.q);
        let start = block.weight as usize + (s - block.stencil as usize) * q;
        &self.weights[start..start + q]
    }

    /// Starts a block of the field's value at a point, `sum_j c_j
    /// x_(b_j + .)`, over `(b_j, c_j)`: a handle, keyframe, velocity,
    /// acceleration or obstacle.
    pub fn value_block(&mut self, dim: usize, entries: &[(usize, Real)]) {
        self.block(dim, 1, entries.iter().map(|&(b, c)| (b, [c, 0.0, 0.0])));
    }

    /// Block `b`'s features of `v`.
    fn gather(&self, b: usize, stencil: Range<usize>, v: &[Real]) -> [Real; MAX_FEATURES] {
        match (self.blocks[b].dim, self.blocks[b].q) {
            (3, 3) => self.gather_fixed::<3, 3>(b, stencil, v),
            (3, 1) => self.gather_fixed::<3, 1>(b, stencil, v),
            (2, 2) => self.gather_fixed::<2, 2>(b, stencil, v),
            (2, 1) => self.gather_fixed::<2, 1>(b, stencil, v),
            _ => self.gather_fixed::<1, 1>(b, stencil, v),
        }
    }

    /// [`Self::gather`] with the block's shape known to the compiler,
    /// which unrolls the inner loops: the products spend their time here.
    fn gather_fixed<const D: usize, const Q: usize>(
        &self,
        b: usize,
        stencil: Range<usize>,
        v: &[Real],
    ) -> [Real; MAX_FEATURES] {
        let start = self.blocks[b].weight as usize;
        let bases = &self.bases[stencil];
        let weights = &self.weights[start..start + bases.len() * Q];
        let mut z = [0.0; MAX_FEATURES];
        for (&base, w) in bases.iter().zip(weights.chunks_exact(Q)) {
            let x = &v[base as usize..base as usize + D];
            for a in 0..D {
                for c in 0..Q {
                    z[a * Q + c] += w[c] * x[a];
                }
            }
        }
        z
    }

    /// `out[b_j + a] += sum_c w_(j, c) y_(a, c)` over block `b`'s stencil.
    fn scatter(&self, b: usize, stencil: Range<usize>, y: &[Real], out: &mut [Real]) {
        match (self.blocks[b].dim, self.blocks[b].q) {
            (3, 3) => self.scatter_fixed::<3, 3>(b, stencil, y, out),
            (3, 1) => self.scatter_fixed::<3, 1>(b, stencil, y, out),
            (2, 2) => self.scatter_fixed::<2, 2>(b, stencil, y, out),
            (2, 1) => self.scatter_fixed::<2, 1>(b, stencil, y, out),
            _ => self.scatter_fixed::<1, 1>(b, stencil, y, out),
        }
    }

    fn scatter_fixed<const D: usize, const Q: usize>(
        &self,
        b: usize,
        stencil: Range<usize>,
        y: &[Real],
        out: &mut [Real],
    ) {
        let start = self.blocks[b].weight as usize;
        let bases = &self.bases[stencil];
        let weights = &self.weights[start..start + bases.len() * Q];
        let y = &y[..D * Q];
        for (&base, w) in bases.iter().zip(weights.chunks_exact(Q)) {
            let out = &mut out[base as usize..base as usize + D];
            for a in 0..D {
                let mut sum = 0.0;
                for c in 0..Q {
                    sum += w[c] * y[a * Q + c];
                }
                out[a] += sum;
            }
        }
    }

    /// Block `b`'s matrix, `rows x features`.
    fn matrix_of(&self, b: usize, rows: usize) -> &[Real] {
        let block = &self.blocks[b];
        let start = block.matrix as usize;
        &self.matrix[start..start + rows * block.features()]
    }

    /// `d r_k / d x_c`, for tests.
    #[cfg(test)]
    pub(crate) fn derivative(&self, k: usize, c: usize) -> Real {
        let b = self.blocks.partition_point(|b| b.row as usize <= k) - 1;
        let (rows, stencil) = self.ranges(b);
        let block = self.blocks[b];
        let dim = usize::from(block.dim);
        let row = &self.matrix_of(b, rows.len())[(k - rows.start) * block.features()..];
        stencil
            .filter(|&s| (self.bases[s] as usize..self.bases[s] as usize + dim).contains(&c))
            .map(|s| column_entry(row, c - self.bases[s] as usize, self.weights_of(b, s)))
            .sum()
    }
}

/// The entry of a block's Jacobian in `row` (its derivative by the
/// features) and the column of component `a` of a stencil entry with
/// weights `w`: `sum_c row_(a, c) w_c`.
fn column_entry(row: &[Real], a: usize, w: &[Real]) -> Real {
    let q = w.len();
    row[a * q..(a + 1) * q]
        .iter()
        .zip(w)
        .map(|(r, w)| r * w)
        .sum()
}

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

/// The Jacobian's blocks split into one contiguous run per thread, with a
/// scratch vector each for the scattered products.
#[derive(Debug, Default)]
struct Products {
    /// Block boundaries of the runs.
    runs: Vec<usize>,
    scratch: Vec<Vec<Real>>,
}

impl Products {
    /// Splits `j`'s blocks into runs of about equal work.
    fn split(&mut self, j: &Rows, n: usize) {
        let parts = rayon::current_num_threads().max(1);
        let work = |b: usize| {
            let (rows, stencil) = j.ranges(b);
            rows.len() * j.blocks[b].features() + stencil.len() * j.blocks[b].features()
        };
        let total: usize = (0..j.blocks.len()).map(work).sum();
        self.runs.clear();
        self.runs.push(0);
        let mut done = 0;
        for b in 0..j.blocks.len() {
            done += work(b);
            if done * parts >= total * self.runs.len() && self.runs.len() < parts {
                self.runs.push(b + 1);
            }
        }
        if *self.runs.last().unwrap_or(&0) != j.blocks.len() {
            self.runs.push(j.blocks.len());
        }
        self.scratch.resize_with(self.runs.len() - 1, Vec::new);
        for s in &mut self.scratch {
            s.clear();
            s.resize(n, 0.0);
        }
    }

    /// `out = J v`; each run writes its own rows.
    fn apply_j(&self, j: &Rows, v: &[Real], out: &mut [Real]) {
        let mut slices = Vec::with_capacity(self.runs.len());
        let mut rest = &mut out[..];
        let mut at = 0;
        for w in self.runs.windows(2) {
            let end = j
                .blocks
                .get(w[1])
                .map_or(j.residuals.len(), |b| b.row as usize);
            let (head, tail) = rest.split_at_mut(end - at);
            slices.push((w[0]..w[1], at, head));
            rest = tail;
            at = end;
        }
        slices.into_par_iter().for_each(|(blocks, first, out)| {
            for b in blocks {
                let (rows, stencil) = j.ranges(b);
                let z = j.gather(b, stencil, v);
                let p = j.blocks[b].features();
                let m = j.matrix_of(b, rows.len());
                for (k, row) in rows.clone().zip(m.chunks_exact(p)) {
                    out[k - first] = row.iter().zip(&z).map(|(a, z)| a * z).sum();
                }
            }
        });
    }

    /// `out = J^T w`, run by run into the scratch vectors, then summed.
    fn apply_jt(&mut self, j: &Rows, w: &[Real], out: &mut [Real]) {
        self.scratch
            .par_iter_mut()
            .zip(self.runs.par_windows(2))
            .for_each(|(scratch, run)| {
                scratch.fill(0.0);
                for b in run[0]..run[1] {
                    let (rows, stencil) = j.ranges(b);
                    let p = j.blocks[b].features();
                    let m = j.matrix_of(b, rows.len());
                    // y = A^T w over the block's rows, then scattered.
                    let mut y = [0.0; MAX_FEATURES];
                    for (row, w) in m.chunks_exact(p).zip(&w[rows]) {
                        for (y, a) in y.iter_mut().zip(row) {
                            *y += a * w;
                        }
                    }
                    j.scatter(b, stencil, &y, scratch);
                }
            });
        self.sum_into(out);
    }

    fn sum_into(&self, out: &mut [Real]) {
        out.fill(0.0);
        for s in &self.scratch {
            for (o, v) in out.iter_mut().zip(s) {
                *o += v;
            }
        }
    }

    /// `out = diag(J^T J)`: per stencil entry and component, the squared
    /// norm of its Jacobian column within the block.
    fn diagonal(&mut self, j: &Rows, out: &mut [Real]) {
        self.scratch
            .par_iter_mut()
            .zip(self.runs.par_windows(2))
            .for_each(|(scratch, run)| {
                scratch.fill(0.0);
                for b in run[0]..run[1] {
                    let (rows, stencil) = j.ranges(b);
                    let block = j.blocks[b];
                    let (dim, p) = (usize::from(block.dim), block.features());
                    let m = j.matrix_of(b, rows.len());
                    for s in stencil {
                        let base = j.bases[s] as usize;
                        let w = j.weights_of(b, s);
                        for a in 0..dim {
                            scratch[base + a] += m
                                .chunks_exact(p)
                                .map(|row| column_entry(row, a, w).powi(2))
                                .sum::<Real>();
                        }
                    }
                }
            });
        self.sum_into(out);
    }
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
    let mut products = Products::default();
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
        products.diagonal(&rows, &mut diag);
        let floor = 1e-12 * diag.iter().fold(0.0, |m: Real, v| m.max(*v)).max(1e-300);
        diag.iter_mut().for_each(|d| *d = d.max(floor));
        blocks.assemble(&rows, &diag);
        let accepted = loop {
            iterations += 1;
            run.iteration += 1;
            blocks.factor(&diag, mu);
            run.linear_iterations += cg.solve(
                &rows,
                &mut products,
                &diag,
                mu,
                &blocks,
                &g,
                &mut step,
                params,
            );
            step_from(x, &step, 1.0, &mut trial);
            evaluate(problem, &trial, false, &mut trial_rows);
            let new_energy = trial_rows.energies().total();
            // Model decrease: -(2 g.d + d^T J^T J d) = -(g.d) + mu d^T D d
            // at the CG solution; computed directly, it is robust to an
            // inexact solve.
            let jd = cg.jd(&rows, &products, &step);
            let predicted = -(2.0 * dot(&g, &step) + dot(&jd, &jd));
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
            let slope = 2.0 * dot(&g, &step);
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

    fn jd(&mut self, j: &Rows, products: &Products, d: &[Real]) -> Vec<Real> {
        let mut out = vec![0.0; j.residuals.len()];
        products.apply_j(j, d, &mut out);
        out
    }

    #[allow(clippy::too_many_arguments)]
    fn solve(
        &mut self,
        j: &Rows,
        products: &mut Products,
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
            products.apply_j(j, p, jp);
            products.apply_jt(j, jp, q);
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

    /// Accumulates the line blocks from `J`'s blocks; the diagonal is
    /// `diag` (already floored).
    fn assemble(&mut self, j: &Rows, diag: &[Real]) {
        let (lines, length) = (self.lines, self.length);
        let size = length * length;
        self.blocks.fill(0.0);
        if length > 1 {
            let count = j.blocks.len();
            let chunk = count.div_ceil(rayon::current_num_threads().max(1)).max(1);
            let partial: Vec<Vec<Real>> = (0..count.div_ceil(chunk))
                .into_par_iter()
                .map(|c| {
                    let mut blocks = vec![0.0; lines * size];
                    // (line, frame, column of J within the block).
                    let mut columns: Vec<(u32, u32, [Real; MAX_ROWS])> = Vec::new();
                    for b in c * chunk..((c + 1) * chunk).min(count) {
                        let (rows, stencil) = j.ranges(b);
                        let block = j.blocks[b];
                        // A block within one frame adds only to diagonals.
                        let frame = |s: usize| j.bases[s] as usize / lines;
                        let first = frame(stencil.start);
                        if stencil.clone().all(|s| frame(s) == first) || rows.len() > MAX_ROWS {
                            continue;
                        }
                        let (dim, p) = (usize::from(block.dim), block.features());
                        let m = j.matrix_of(b, rows.len());
                        columns.clear();
                        for s in stencil {
                            let base = j.bases[s] as usize;
                            let w = j.weights_of(b, s);
                            for a in 0..dim {
                                let mut column = [0.0; MAX_ROWS];
                                for (v, row) in column.iter_mut().zip(m.chunks_exact(p)) {
                                    *v = column_entry(row, a, w);
                                }
                                let c = base + a;
                                columns.push(((c % lines) as u32, (c / lines) as u32, column));
                            }
                        }
                        columns.sort_unstable_by_key(|e| (e.0, e.1));
                        let mut start = 0;
                        while start < columns.len() {
                            let line = columns[start].0;
                            let end =
                                start + columns[start..].iter().take_while(|e| e.0 == line).count();
                            let block = &mut blocks[line as usize * size..][..size];
                            for x in &columns[start..end] {
                                for y in &columns[start..end] {
                                    if x.1 != y.1 {
                                        block[x.1 as usize * length + y.1 as usize] +=
                                            dot(&x.2[..rows.len()], &y.2[..rows.len()]);
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
        )
        .expect_err("NaN");
        assert!(
            matches!(err, DesignError::Diverged { term: "volume", .. }),
            "{err}"
        );
    }

    /// Blocks of both kinds, overlapping stencils: the products and the
    /// diagonal by blocks against the Jacobian entry by entry.
    #[test]
    fn block_products_match_the_jacobian() {
        struct Mixed;
        impl LeastSquares for Mixed {
            fn unknowns(&self) -> usize {
                3 * 7
            }
            fn groups(&self) -> usize {
                40
            }
            fn group(&self, g: usize, _: &[Real], rows: &mut Rows) {
                let value = |k: usize| ((g * 31 + k * 17) % 13) as Real / 6.0 - 1.0;
                let stencil = (0..3).map(|j| {
                    let particle = (g + 2 * j) % 7;
                    (particle * 3, [value(j), value(j + 3), value(j + 6)])
                });
                let (q, rows_here) = if g.is_multiple_of(2) { (3, 5) } else { (1, 2) };
                rows.block(3, q, stencil);
                for r in 0..rows_here {
                    let derivative: Vec<Real> = (0..3 * q).map(|f| value(10 + r * 9 + f)).collect();
                    rows.push(Term::Rigidity, value(r), &derivative);
                }
            }
        }
        let n = Mixed.unknowns();
        let mut rows = Rows::default();
        evaluate(&Mixed, &vec![0.0; n], true, &mut rows);
        let m = rows.residuals.len();
        let dense: Vec<Vec<Real>> = (0..m)
            .map(|k| (0..n).map(|c| rows.derivative(k, c)).collect())
            .collect();
        let v: Vec<Real> = (0..n).map(|c| (c as Real * 0.37).sin()).collect();
        let w: Vec<Real> = (0..m).map(|k| (k as Real * 0.53).cos()).collect();
        for threads in [1, 2, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool");
            pool.install(|| {
                let mut products = Products::default();
                products.split(&rows, n);
                let mut jv = vec![0.0; m];
                products.apply_j(&rows, &v, &mut jv);
                let mut jtw = vec![0.0; n];
                products.apply_jt(&rows, &w, &mut jtw);
                let mut diag = vec![0.0; n];
                products.diagonal(&rows, &mut diag);
                for k in 0..m {
                    let expected = dot(&dense[k], &v);
                    assert!((jv[k] - expected).abs() < 1e-12, "J v, row {k}");
                }
                for c in 0..n {
                    let expected: Real = (0..m).map(|k| dense[k][c] * w[k]).sum();
                    assert!((jtw[c] - expected).abs() < 1e-12, "J^T w, column {c}");
                    let expected: Real = (0..m).map(|k| dense[k][c] * dense[k][c]).sum();
                    assert!((diag[c] - expected).abs() < 1e-12, "diagonal, column {c}");
                }
            });
        }
    }
}
