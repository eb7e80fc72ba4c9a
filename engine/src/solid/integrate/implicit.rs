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
//! Cholesky of the assembled `H` (`direct.rs`), or by Jacobi-
//! preconditioned conjugate gradients (`linalg::cg`), matrix-free: `K w`
//! is the exact directional derivative of the forces (`forces.rs`), never
//! assembled. A direction of negative curvature (a buckling tangent)
//! makes Cholesky fail, and that step falls back to CG, which the same
//! curvature ends early with the descent made so far; the line search
//! guarantees `Phi` decreases.
//!
//! Contact with obstacles and walls is a penalty energy inside `Phi`
//! ([`Penalty`]): `U` includes it, `K` its stiffness `k n n^T`, so the
//! step never ends on a projection that stores strain (`contact.rs`).
//!
//! Implicit midpoint ([`ImplicitScheme::Midpoint`]) reuses the same solve:
//! its midpoint velocity `v_m = v + (dt/2) a(x + (dt/2) v_m)` is a backward
//! Euler step of `dt / 2`, and `x+ = x + dt v_m`, `v+ = 2 v_m - v` follow.

use super::super::body::Body;
use super::super::contact::Penalty;
use super::super::forces::{InternalForces, Split};
use super::super::material::StressState;
use super::super::params::{ImplicitParams, ImplicitScheme, LinearSolver, STATIC_PERIODS};
use super::SolidStep;
use super::direct::Direct;
use crate::cancel::{Cancel, Cancelled};
use crate::linalg::cg::{self, Stopping, Termination};
use crate::linalg::linop::par_sum;
use crate::linalg::{LinOp, Parallel, Precond, Space};
use crate::math::{Real, Vector};
use crate::stats::{Stage, StageTimer};
use nalgebra::Matrix3;
use rayon::prelude::*;

/// The implicit integrator: its settings, and the solve's vectors kept
/// between steps so that a step does not allocate.
#[derive(Debug, Clone)]
pub(in crate::solid) struct Implicit {
    settings: ImplicitParams,
    /// The forces and stress states at the last point `Phi` was
    /// evaluated at.
    pub(super) forces: InternalForces,
    v_new: Vec<Vector>,
    x_new: Vec<Vector>,
    trial: Vec<Vector>,
    /// `grad Phi` at `v_new`.
    gradient: Vec<Vector>,
    /// Newton direction.
    direction: Vec<Vector>,
    /// `-grad Phi`, CG's right-hand side.
    rhs: Vec<Vector>,
    /// `grad Phi` at a line search trial.
    trial_gradient: Vec<Vector>,
    /// Inverse Jacobi diagonal.
    inverse_diagonal: Vec<Real>,
    /// `dt^2` times each particle's contact stiffness at the iterate
    /// (zero away from obstacles).
    contact: Vec<Matrix3<Real>>,
    /// The Hessian product's scratch.
    product: ProductBuffers,
    cg: cg::Workspace<Vector, Parallel>,
    /// The assembled Hessian and its factorisation.
    direct: Direct,
    /// Whether [`LinearSolver::Auto`] has switched this body to Cholesky
    /// after CG failed to converge on it.
    pub(in crate::solid) escalated: bool,
}

/// Most particles of a 3D body that [`LinearSolver::Auto`] switches to
/// Cholesky when CG does not converge: the factor of a 2.8k-particle bar
/// takes 49 MiB and 0.26 s per Newton step, and grows as `n^1.4` (see
/// [`LinearSolver::Cholesky`]). Larger bodies stay on CG and report the
/// steps that did not converge.
pub const AUTO_FACTOR_LIMIT: usize = 5000;

/// The matrix-free Hessian product's scratch: the split of pass 1 and the
/// gathered damping forces.
#[derive(Debug, Clone, Default)]
struct ProductBuffers {
    split: Split,
    damping: Vec<Vector>,
}

/// `|slope| / |Phi|` below which a line search step's change of `Phi` is
/// lost in rounding: well above `f64::EPSILON` times the particle counts
/// met, far below any decrease that matters.
const ROUNDING: Real = 1e-10;

/// The static scheme's step: [`STATIC_PERIODS`] times the time the
/// fastest elastic wave takes to cross the body's rest extent.
fn static_step(body: &Body) -> Real {
    let rest = body.rest_positions();
    let (min, max) = rest.iter().fold(
        (
            Vector::repeat(Real::INFINITY),
            Vector::repeat(Real::NEG_INFINITY),
        ),
        |(lo, hi), x| (lo.inf(x), hi.sup(x)),
    );
    let extent = (max - min).norm().max(body.params.spacing);
    STATIC_PERIODS * extent / body.params.wave_speed()
}

fn dot(a: &[Vector], b: &[Vector]) -> Real {
    Parallel::dot(a, b)
}

impl Implicit {
    /// The integrator with `settings`, its buffers sized by the first
    /// step.
    pub fn new(settings: ImplicitParams) -> Self {
        Self {
            settings,
            forces: InternalForces::default(),
            v_new: Vec::new(),
            x_new: Vec::new(),
            trial: Vec::new(),
            gradient: Vec::new(),
            direction: Vec::new(),
            rhs: Vec::new(),
            trial_gradient: Vec::new(),
            inverse_diagonal: Vec::new(),
            contact: Vec::new(),
            product: ProductBuffers::default(),
            cg: cg::Workspace::default(),
            direct: Direct::default(),
            escalated: false,
        }
    }

    fn resize(&mut self, n: usize, edges: usize) {
        for v in [
            &mut self.v_new,
            &mut self.x_new,
            &mut self.trial,
            &mut self.gradient,
            &mut self.direction,
            &mut self.rhs,
            &mut self.trial_gradient,
            &mut self.product.damping,
        ] {
            v.resize(n, Vector::zeros());
        }
        self.inverse_diagonal.resize(n, 0.0);
        self.contact.resize(n, Matrix3::zeros());
        self.product.split.resize(n, edges);
    }

    /// Bytes held by the last sparse Cholesky factor.
    pub fn cholesky_factor_bytes(&self) -> usize {
        self.direct.factor_bytes()
    }

    /// One step of the settings' scheme; stops at the next Newton or CG iteration
    /// once `cancel` is raised, `body` as it was (the step only writes it
    /// after Newton ends).
    pub fn step(
        &mut self,
        body: &mut Body,
        dt: Real,
        gravity: &Vector,
        cancel: &Cancel,
        timer: &mut StageTimer,
    ) -> Result<SolidStep, Cancelled> {
        // Midpoint: a backward Euler solve over `dt / 2` gives the
        // midpoint velocity `v_m`; then `x+ = x + dt v_m`,
        // `v+ = 2 v_m - v`.
        // Static: a step so long that inertia no longer counts, from rest,
        // ending at rest.
        let (h, advance) = match self.settings.scheme {
            ImplicitScheme::BackwardEuler => (dt, dt),
            ImplicitScheme::Midpoint => (0.5 * dt, dt),
            ImplicitScheme::Static => {
                body.velocities.fill(Vector::zeros());
                let h = static_step(body).max(dt);
                (h, h)
            }
        };
        let report = timer.time(Stage::SolidSolve, || self.solve(body, h, gravity, cancel))?;
        let scheme = self.settings.scheme;
        let v_new = &self.v_new;
        timer.time(Stage::SolidIntegrate, || {
            match scheme {
                ImplicitScheme::BackwardEuler => body.velocities.clone_from(v_new),
                ImplicitScheme::Midpoint => body
                    .velocities
                    .par_iter_mut()
                    .zip(v_new)
                    .for_each(|(v, v_mid)| *v = v_mid * 2.0 - *v),
                ImplicitScheme::Static => {}
            }
            body.positions
                .par_iter_mut()
                .zip(v_new)
                .for_each(|(x, v)| *x += v * advance);
        });
        let states = &self.forces.states;
        timer.time(Stage::SolidContact, || {
            let p = &body.params;
            // Field by field: the penalty reads the obstacles while the
            // positions move.
            if let Some(penalty) = Penalty::new(&body.obstacles, p.dim, p.spacing, p.young, h) {
                penalty.finish(
                    h,
                    body.params.friction,
                    &body.masses,
                    &body.fixed,
                    &mut body.positions,
                    &mut body.velocities,
                );
            }
            body.flow(states);
        });
        Ok(SolidStep {
            min_substep: dt,
            ..report
        })
    }

    /// Solves the backward Euler step of length `dt` for its velocities,
    /// left in `self.v_new` (the body unchanged), and reports the
    /// iterations and residual.
    fn solve(
        &mut self,
        body: &Body,
        dt: Real,
        gravity: &Vector,
        cancel: &Cancel,
    ) -> Result<SolidStep, Cancelled> {
        self.resize(body.len(), body.topology.owner.len());
        self.v_new.clone_from(&body.velocities);
        let settings = self.settings;
        let (mut newton, mut cg, mut fallbacks) = (0, 0, 0);
        let mut residual = Real::INFINITY;
        // The gravity impulse of the step, `dt |M g|`, floors the scale: a
        // body settled under gravity starts a step with a residual near
        // rounding noise, which a relative tolerance would ask Newton to
        // resolve further.
        let impulse = dt
            * gravity.norm()
            * body
                .masses
                .iter()
                .zip(&body.fixed)
                .filter(|(_, fixed)| !**fixed)
                .map(|(m, _)| m * m)
                .sum::<Real>()
                .sqrt();
        let mut first = None;
        let contact = penalty(body, dt);
        for _ in 0..settings.max_newton_iterations.max(1) {
            cancel.check()?;
            // Phi at the iterate; leaves the forces and states there.
            let phi = objective(
                body,
                &mut self.forces,
                contact.as_ref(),
                dt,
                gravity,
                &self.v_new,
                &mut self.x_new,
            );
            gradient(
                body,
                &self.forces.forces,
                contact.as_ref(),
                dt,
                gravity,
                &self.v_new,
                &self.x_new,
                &mut self.gradient,
            );
            let norm = dot(&self.gradient, &self.gradient).sqrt();
            let scale = *first.get_or_insert(norm.max(impulse));
            residual = if scale > 0.0 { norm / scale } else { 0.0 };
            if residual <= settings.newton_tolerance {
                break;
            }
            newton += 1;
            self.contact_stiffness(body, contact.as_ref(), dt);
            let factorises = self.escalated || settings.linear_solver.factorises(body.params.dim);
            let mut direct = factorises
                && self.direct.direction(
                    body,
                    &self.forces.states,
                    &self.contact,
                    dt,
                    &self.gradient,
                    &mut self.direction,
                );
            if !direct {
                fallbacks += u32::from(factorises);
                let (iterations, converged) = self.cg_direction(body, dt, cancel)?;
                cg += iterations;
                // Auto chose CG and CG ran to its cap: the problem is too
                // ill-conditioned for it (a slender 3D beam), so factorise
                // from now on, where the body is small enough.
                if !converged
                    && !factorises
                    && settings.linear_solver == LinearSolver::Auto
                    && body.len() <= AUTO_FACTOR_LIMIT
                {
                    self.escalated = true;
                    direct = self.direct.direction(
                        body,
                        &self.forces.states,
                        &self.contact,
                        dt,
                        &self.gradient,
                        &mut self.direction,
                    );
                    fallbacks += u32::from(!direct);
                }
            }
            if !self.line_search(body, contact.as_ref(), dt, gravity, phi) {
                break;
            }
        }
        Ok(SolidStep {
            substeps: 1,
            min_substep: dt,
            capped: false,
            iterations: newton + cg,
            newton_iterations: newton,
            cholesky_fallbacks: fallbacks,
            residual,
            unconverged: residual > settings.newton_tolerance,
        })
    }

    /// `dt^2 K_c` at the iterate `self.x_new` into `self.contact`.
    fn contact_stiffness(&mut self, body: &Body, contact: Option<&Penalty<'_>>, dt: Real) {
        let x = &self.x_new;
        self.contact.par_iter_mut().enumerate().for_each(|(i, k)| {
            *k = match contact {
                Some(c) if !body.fixed[i] => c.stiffness_matrix(body.masses[i], &x[i]) * (dt * dt),
                _ => Matrix3::zeros(),
            };
        });
    }

    /// Solves `H d = -grad Phi` into `self.direction` by preconditioned
    /// CG; returns the CG iterations and whether CG stopped short of its
    /// cap (converged, or ended on negative curvature), or [`Cancelled`]
    /// when `cancel` stopped the solve.
    fn cg_direction(
        &mut self,
        body: &Body,
        dt: Real,
        cancel: &Cancel,
    ) -> Result<(u32, bool), Cancelled> {
        let model = body.model();
        // Jacobi preconditioner: the mass, the damping and a stiffness
        // estimate from the squared gradient weights touching each
        // particle.
        let stiffness = body.params.wave_modulus();
        let t = &body.topology;
        let g = t.gradients.all_weights();
        let contact = &self.contact;
        self.inverse_diagonal
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
                let m = body.masses[i];
                *d = 1.0
                    / (m * (1.0 + 4.0 * dt * model.damping)
                        + dt * dt * stiffness * spread
                        + contact[i].trace());
            });
        self.rhs
            .par_iter_mut()
            .zip(&self.gradient)
            .for_each(|(r, g)| *r = -g);
        let params = cg::Params {
            tolerance: self.settings.cg_tolerance,
            max_iterations: self.settings.max_cg_iterations,
            stopping: Stopping::Residual,
            // A NaN runs on to the cap; the line search then rejects it.
            non_finite_breaks: false,
            // The first direction already non-convex: take the
            // preconditioned gradient, which the line search shortens as
            // needed.
            descend_on_first_breakdown: true,
        };
        let mut hessian = Hessian {
            body,
            states: &self.forces.states,
            contact: &self.contact,
            dt,
            buffers: &mut self.product,
        };
        let info = cg::solve(
            &mut hessian,
            &Jacobi(&self.inverse_diagonal),
            &self.rhs,
            &mut self.direction,
            &params,
            &mut self.cg,
            cancel,
        );
        match info.termination {
            Termination::Cancelled => Err(Cancelled),
            Termination::Converged | Termination::Breakdown { .. } => Ok((info.iterations, true)),
            Termination::IterationLimit => Ok((info.iterations, false)),
        }
    }

    /// Backtracking (Armijo) search along `self.direction` from
    /// `self.v_new`; moves `self.v_new` and returns whether it found a
    /// better point.
    ///
    /// Near convergence the decrease Newton predicts, `slope / 2`, sinks
    /// below the rounding error of `Phi` (a sum over every particle), and
    /// Armijo's test becomes a coin toss that stalls Newton at a residual
    /// of about 1e-6 while an exact (Cholesky) direction would still
    /// converge quadratically. There a trial is judged by the residual
    /// norm instead, which a Newton step near a minimum reduces.
    fn line_search(
        &mut self,
        body: &Body,
        contact: Option<&Penalty<'_>>,
        dt: Real,
        gravity: &Vector,
        phi: Real,
    ) -> bool {
        let slope = dot(&self.gradient, &self.direction).min(0.0);
        let below_rounding = -slope <= ROUNDING * phi.abs();
        let norm = dot(&self.gradient, &self.gradient);
        let mut step = 1.0;
        for _ in 0..30 {
            self.trial
                .par_iter_mut()
                .zip(self.v_new.par_iter().zip(&self.direction))
                .for_each(|(t, (v, d))| *t = v + d * step);
            let value = objective(
                body,
                &mut self.forces,
                contact,
                dt,
                gravity,
                &self.trial,
                &mut self.x_new,
            );
            let better = value.is_finite()
                && (value <= phi + 1e-4 * step * slope
                    || below_rounding && {
                        // `objective` left the forces at the trial point.
                        gradient(
                            body,
                            &self.forces.forces,
                            contact,
                            dt,
                            gravity,
                            &self.trial,
                            &self.x_new,
                            &mut self.trial_gradient,
                        );
                        dot(&self.trial_gradient, &self.trial_gradient) < norm
                    });
            if better {
                std::mem::swap(&mut self.v_new, &mut self.trial);
                return true;
            }
            step *= 0.5;
        }
        false
    }
}

/// `Phi(v_new)`, with `x_new = x + dt v_new` written out and the forces
/// and stress states evaluated there into `forces`.
fn objective(
    body: &Body,
    forces: &mut InternalForces,
    contact: Option<&Penalty<'_>>,
    dt: Real,
    gravity: &Vector,
    v_new: &[Vector],
    x_new: &mut [Vector],
) -> Real {
    x_new
        .par_iter_mut()
        .zip(&body.positions)
        .zip(v_new)
        .for_each(|((out, x), v)| *out = x + v * dt);
    let potential = forces.evaluate(body, Some(x_new), Some(v_new), true);
    let x_new = &*x_new;
    let kinetic = par_sum(v_new.len(), |i| {
        let (a, b, m) = (&v_new[i], &body.velocities[i], body.masses[i]);
        let touching = match contact {
            Some(c) if !body.fixed[i] => c.energy(m, &x_new[i]),
            _ => 0.0,
        };
        0.5 * m * (a - b).norm_squared() - dt * m * gravity.dot(a) + touching
    });
    kinetic + potential + dt * body.model().dissipation(v_new)
}

/// The penalty contact of `body` for a solve of step `h`, if it has
/// obstacles.
fn penalty(body: &Body, h: Real) -> Option<Penalty<'_>> {
    let p = &body.params;
    Penalty::new(&body.obstacles, p.dim, p.spacing, p.young, h)
}

/// `grad Phi = M (v+ - v) - dt (f + f_c + M g)` with the internal forces
/// `f` at `v_new` and the contact forces `f_c` at `x_new`; zero at
/// anchored particles.
#[allow(clippy::too_many_arguments)]
fn gradient(
    body: &Body,
    f: &[Vector],
    contact: Option<&Penalty<'_>>,
    dt: Real,
    gravity: &Vector,
    v_new: &[Vector],
    x_new: &[Vector],
    out: &mut [Vector],
) {
    out.par_iter_mut().enumerate().for_each(|(i, r)| {
        *r = if body.fixed[i] {
            Vector::zeros()
        } else {
            let m = body.masses[i];
            let touching = contact.map_or_else(Vector::zeros, |c| c.force(m, &x_new[i]));
            (v_new[i] - body.velocities[i]) * m - (f[i] + touching + gravity * m) * dt
        };
    });
}

/// `H = M - dt^2 K - dt dF_d/dv`, matrix-free, with `K` linearised about
/// `states` (those of the current Newton iterate).
struct Hessian<'a> {
    body: &'a Body,
    states: &'a [StressState],
    /// `dt^2 K_c` per particle.
    contact: &'a [Matrix3<Real>],
    dt: Real,
    buffers: &'a mut ProductBuffers,
}

impl LinOp<Vector> for Hessian<'_> {
    /// `y = H p = M p - dt^2 K p + dt^2 K_c p - dt f_d(p)`.
    fn apply(&mut self, p: &[Vector], y: &mut [Vector]) {
        let body = self.body;
        let dt = self.dt;
        let b = &mut *self.buffers;
        let model = body.model();
        model.derivative_pass(p, self.states, &mut b.split);
        model.gather(&b.split, y);
        if model.damping > 0.0 {
            model.damping_pass(p, &mut b.split);
            model.gather(&b.split, &mut b.damping);
        }
        let damped = model.damping > 0.0;
        let damping = &b.damping;
        let contact = self.contact;
        y.par_iter_mut().enumerate().for_each(|(i, h)| {
            *h = if body.fixed[i] {
                Vector::zeros()
            } else {
                let mut v = p[i] * body.masses[i] - *h * (dt * dt) + contact[i] * p[i];
                if damped {
                    v -= damping[i] * dt;
                }
                v
            };
        });
    }
}

/// `H p` by the matrix-free product about `states`, to check the
/// assembled Hessian against.
#[cfg(test)]
pub(super) fn hessian_product(
    body: &Body,
    states: &[StressState],
    contact: &[Matrix3<Real>],
    dt: Real,
    p: &[Vector],
) -> Vec<Vector> {
    let mut buffers = ProductBuffers::default();
    buffers.split.resize(body.len(), body.topology.owner.len());
    buffers.damping.resize(body.len(), Vector::zeros());
    let mut out = vec![Vector::zeros(); body.len()];
    Hessian {
        body,
        states,
        contact,
        dt,
        buffers: &mut buffers,
    }
    .apply(p, &mut out);
    out
}

/// The Jacobi preconditioner, `z = D^-1 r` by the inverse diagonal.
struct Jacobi<'a>(&'a [Real]);

impl Precond<Vector> for Jacobi<'_> {
    fn apply(&self, r: &[Vector], z: &mut [Vector]) {
        z.par_iter_mut()
            .zip(r)
            .zip(self.0)
            .for_each(|((z, r), d)| *z = r * *d);
    }
}
