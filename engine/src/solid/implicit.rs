//! Backward Euler for elastic solids, posed as a minimisation (after
//! Gast et al. 2015) so that a line search keeps Newton robust at steps
//! far beyond the explicit limit. The end-of-step velocity `v+` minimises
//!
//! ```text
//! Phi(v+) = 1/2 |v+ - v|_M^2 + U(x + dt v+) + dt/2 v+^T D v+ - dt v+^T M g
//! ```
//!
//! whose gradient `M (v+ - v) - dt f(x + dt v+) - dt f_d(v+) - dt M g` is
//! the backward Euler residual. Each Newton step solves `H dv = -grad Phi`
//! with `H = M - dt^2 K + dt D`, as [`LinearSolver`] chooses: by sparse
//! Cholesky of the assembled `H` (`hessian.rs`), or by Jacobi-
//! preconditioned conjugate gradients, matrix-free: `K w` is the exact
//! directional derivative of the forces (`forces.rs`), never assembled.
//! A direction of negative curvature (a buckling tangent) makes Cholesky
//! fail, and that step falls back to CG, which the same curvature ends
//! early with the descent made so far; the line search guarantees `Phi`
//! decreases.

use super::elastic::ElasticSolid;
use super::forces::Split;
use super::hessian::DirectSolver;
use super::params::ImplicitParams;
use crate::math::{Real, Vector};
use rayon::prelude::*;

/// The solve's vectors, kept between steps so a step does not allocate.
#[derive(Debug, Clone, Default)]
pub(super) struct Buffers {
    v_new: Vec<Vector>,
    x_new: Vec<Vector>,
    trial: Vec<Vector>,
    /// `grad Phi` at `v_new`.
    gradient: Vec<Vector>,
    /// Newton direction.
    direction: Vec<Vector>,
    /// CG residual, preconditioned residual, search direction, `H p`.
    r: Vec<Vector>,
    z: Vec<Vector>,
    p: Vec<Vector>,
    hp: Vec<Vector>,
    /// Inverse Jacobi diagonal.
    inverse_diagonal: Vec<Real>,
    damping: Vec<Vector>,
    split: Split,
    /// The assembled Hessian and its factorisation.
    direct: DirectSolver,
}

/// How one backward Euler solve went.
#[derive(Debug, Clone, Copy)]
pub(super) struct NewtonReport {
    pub newton: u32,
    /// Conjugate-gradient iterations, all Newton steps together.
    pub cg: u32,
    /// Newton steps whose Cholesky factorisation failed (`H` not positive
    /// definite) and that were solved by CG instead.
    pub fallbacks: u32,
    /// The final residual relative to the first, or to the step's gravity
    /// impulse where that is larger.
    pub residual: Real,
}

impl Buffers {
    fn resize(&mut self, n: usize, edges: usize) {
        for v in [
            &mut self.v_new,
            &mut self.x_new,
            &mut self.trial,
            &mut self.gradient,
            &mut self.direction,
            &mut self.r,
            &mut self.z,
            &mut self.p,
            &mut self.hp,
            &mut self.damping,
        ] {
            v.resize(n, Vector::zeros());
        }
        self.inverse_diagonal.resize(n, 0.0);
        self.split.resize(n, edges);
    }
}

/// `|slope| / |Phi|` below which a line search step's change of `Phi` is
/// lost in rounding: well above `f64::EPSILON` times the particle counts
/// met, far below any decrease that matters.
const ROUNDING: Real = 1e-10;

fn dot(a: &[Vector], b: &[Vector]) -> Real {
    a.par_iter().zip(b).map(|(a, b)| a.dot(b)).sum()
}

impl ElasticSolid {
    /// One backward Euler step.
    pub(super) fn implicit_step(
        &mut self,
        dt: Real,
        gravity: &Vector,
        settings: &ImplicitParams,
    ) -> NewtonReport {
        let mut b = std::mem::take(&mut self.scratch.implicit);
        b.resize(self.len(), self.topology.owner.len());
        b.v_new.clone_from(&self.velocities);
        let mut report = NewtonReport {
            newton: 0,
            cg: 0,
            fallbacks: 0,
            residual: Real::INFINITY,
        };
        // The gravity impulse of the step, `dt |M g|`, floors the scale: a
        // body settled under gravity starts a step with a residual near
        // rounding noise, which a relative tolerance would ask Newton to
        // resolve further.
        let impulse = dt
            * gravity.norm()
            * self
                .masses
                .iter()
                .zip(&self.fixed)
                .filter(|(_, fixed)| !**fixed)
                .map(|(m, _)| m * m)
                .sum::<Real>()
                .sqrt();
        let mut first = None;
        for _ in 0..settings.max_newton_iterations.max(1) {
            // Phi at the iterate; leaves the forces and states there.
            let phi = self.objective(dt, gravity, &b.v_new, &mut b.x_new);
            self.residual(dt, gravity, &b.v_new, &mut b.gradient);
            let norm = dot(&b.gradient, &b.gradient).sqrt();
            let scale = *first.get_or_insert(norm.max(impulse));
            report.residual = if scale > 0.0 { norm / scale } else { 0.0 };
            if report.residual <= settings.newton_tolerance {
                break;
            }
            report.newton += 1;
            let factorises = settings.linear_solver.factorises(self.params.dim);
            let direct = factorises
                && self.direct_direction(dt, &mut b.direct, &b.gradient, &mut b.direction);
            if !direct {
                report.fallbacks += u32::from(factorises);
                report.cg += self.cg_direction(dt, settings, &mut b);
            }
            if !self.line_search(dt, gravity, phi, &mut b) {
                break;
            }
        }
        self.velocities.clone_from(&b.v_new);
        self.positions
            .par_iter_mut()
            .zip(&self.velocities)
            .for_each(|(x, v)| *x += v * dt);
        self.scratch.implicit = b;
        self.finish_substep();
        report
    }

    /// Bytes held by the implicit integrator's last sparse Cholesky factor
    /// (0 before one was computed): the direct solver's dominant memory.
    pub fn cholesky_factor_bytes(&self) -> usize {
        self.scratch.implicit.direct.factor_bytes()
    }

    /// `H p` by the matrix-free product at the current stress states, to
    /// check the assembled Hessian against.
    #[cfg(test)]
    pub(super) fn hessian_product(&self, dt: Real, p: &[Vector]) -> Vec<Vector> {
        let mut b = Buffers::default();
        b.resize(self.len(), self.topology.owner.len());
        b.p.copy_from_slice(p);
        self.apply_hessian(dt, &mut b);
        b.hp
    }

    /// `grad Phi = M (v+ - v) - dt (f + M g)` with the forces in
    /// `scratch.forces`; zero at anchored particles.
    fn residual(&self, dt: Real, gravity: &Vector, v_new: &[Vector], out: &mut [Vector]) {
        let f = &self.scratch.forces;
        out.par_iter_mut().enumerate().for_each(|(i, r)| {
            *r = if self.fixed[i] {
                Vector::zeros()
            } else {
                let m = self.masses[i];
                (v_new[i] - self.velocities[i]) * m - (f[i] + gravity * m) * dt
            };
        });
    }

    /// Solves `H d = -grad Phi` into `b.direction` by preconditioned CG;
    /// returns the CG iterations.
    fn cg_direction(&self, dt: Real, settings: &ImplicitParams, b: &mut Buffers) -> u32 {
        let model = self.model();
        // Jacobi preconditioner: the mass, the damping and a stiffness
        // estimate from the squared gradient weights touching each
        // particle.
        let stiffness = self.params.wave_modulus();
        let t = &self.topology;
        let g = t.gradients.all_weights();
        b.inverse_diagonal
            .par_iter_mut()
            .enumerate()
            .for_each(|(i, d)| {
                let spread: Real = t.sum_g[i].norm_squared() * model.volumes[i]
                    + t.incoming(i)
                        .iter()
                        .map(|&e| {
                            let e = e as usize;
                            g[e].norm_squared() * model.volumes[t.owner[e] as usize]
                        })
                        .sum::<Real>();
                let m = self.masses[i];
                *d = 1.0 / (m * (1.0 + 4.0 * dt * model.damping) + dt * dt * stiffness * spread);
            });

        b.direction.fill(Vector::zeros());
        let rhs_norm = dot(&b.gradient, &b.gradient).sqrt();
        b.r.par_iter_mut()
            .zip(&b.gradient)
            .for_each(|(r, g)| *r = -g);
        precondition(&b.r, &b.inverse_diagonal, &mut b.z);
        b.p.clone_from(&b.z);
        let mut rz = dot(&b.r, &b.z);
        let mut iterations = 0;
        for _ in 0..settings.max_cg_iterations {
            iterations += 1;
            self.apply_hessian(dt, b);
            let curvature = dot(&b.p, &b.hp);
            if curvature <= 0.0 {
                if iterations == 1 {
                    // The first direction is already non-convex: take the
                    // preconditioned gradient, which the line search
                    // shortens as needed.
                    b.direction.clone_from(&b.z);
                }
                break;
            }
            let alpha = rz / curvature;
            b.direction
                .par_iter_mut()
                .zip(&b.p)
                .for_each(|(d, p)| *d += p * alpha);
            b.r.par_iter_mut()
                .zip(&b.hp)
                .for_each(|(r, h)| *r -= h * alpha);
            if dot(&b.r, &b.r).sqrt() <= settings.cg_tolerance * rhs_norm {
                break;
            }
            precondition(&b.r, &b.inverse_diagonal, &mut b.z);
            let rz_new = dot(&b.r, &b.z);
            let beta = rz_new / rz;
            rz = rz_new;
            b.p.par_iter_mut()
                .zip(&b.z)
                .for_each(|(p, z)| *p = z + *p * beta);
        }
        iterations
    }

    /// `b.hp = H b.p = M p - dt^2 K p - dt f_d(p)`, with `K` linearised
    /// about the stress states of the current Newton iterate.
    fn apply_hessian(&self, dt: Real, b: &mut Buffers) {
        let model = self.model();
        model.derivative_pass(&b.p, &self.scratch.states, &mut b.split);
        model.gather(&b.split, &mut b.hp);
        if model.damping > 0.0 {
            model.damping_pass(&b.p, &mut b.split);
            model.gather(&b.split, &mut b.damping);
        }
        let damped = model.damping > 0.0;
        let p = &b.p;
        let damping = &b.damping;
        b.hp.par_iter_mut().enumerate().for_each(|(i, h)| {
            *h = if self.fixed[i] {
                Vector::zeros()
            } else {
                let mut v = p[i] * self.masses[i] - *h * (dt * dt);
                if damped {
                    v -= damping[i] * dt;
                }
                v
            };
        });
    }

    /// Backtracking (Armijo) search along `b.direction` from `b.v_new`;
    /// moves `b.v_new` and returns whether it found a better point.
    ///
    /// Near convergence the decrease Newton predicts, `slope / 2`, sinks
    /// below the rounding error of `Phi` (a sum over every particle), and
    /// Armijo's test becomes a coin toss that stalls Newton at a residual
    /// of about 1e-6 while an exact (Cholesky) direction would still
    /// converge quadratically. There a trial is judged by the residual
    /// norm instead, which a Newton step near a minimum reduces.
    fn line_search(&mut self, dt: Real, gravity: &Vector, phi: Real, b: &mut Buffers) -> bool {
        let slope = dot(&b.gradient, &b.direction).min(0.0);
        let below_rounding = -slope <= ROUNDING * phi.abs();
        let norm = dot(&b.gradient, &b.gradient);
        let mut step = 1.0;
        for _ in 0..30 {
            b.trial
                .par_iter_mut()
                .zip(b.v_new.par_iter().zip(&b.direction))
                .for_each(|(t, (v, d))| *t = v + d * step);
            let value = self.objective(dt, gravity, &b.trial, &mut b.x_new);
            let better = value.is_finite()
                && (value <= phi + 1e-4 * step * slope
                    || below_rounding && {
                        // `objective` left the forces at the trial point.
                        self.residual(dt, gravity, &b.trial, &mut b.r);
                        dot(&b.r, &b.r) < norm
                    });
            if better {
                std::mem::swap(&mut b.v_new, &mut b.trial);
                return true;
            }
            step *= 0.5;
        }
        false
    }

    /// `Phi(v_new)`, with `x_new = x + dt v_new` written out and the
    /// forces and stress states evaluated there.
    fn objective(
        &mut self,
        dt: Real,
        gravity: &Vector,
        v_new: &[Vector],
        x_new: &mut [Vector],
    ) -> Real {
        x_new
            .par_iter_mut()
            .zip(&self.positions)
            .zip(v_new)
            .for_each(|((out, x), v)| *out = x + v * dt);
        let potential = self.internal_forces(Some(x_new), Some(v_new), true);
        let kinetic: Real = v_new
            .par_iter()
            .zip(&self.velocities)
            .zip(&self.masses)
            .map(|((a, b), m)| 0.5 * m * (a - b).norm_squared() - dt * m * gravity.dot(a))
            .sum();
        kinetic + potential + dt * self.model().dissipation(v_new)
    }
}

/// `z = D^-1 r` with the inverse diagonal.
fn precondition(r: &[Vector], inverse_diagonal: &[Real], z: &mut [Vector]) {
    z.par_iter_mut()
        .zip(r)
        .zip(inverse_diagonal)
        .for_each(|((z, r), d)| *z = r * *d);
}
