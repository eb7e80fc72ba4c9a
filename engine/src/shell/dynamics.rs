//! Implicit time stepping of a shell (Guo–Qin Section 5.2 integrate
//! implicitly: a thin shell's bending and membrane frequencies lie far
//! apart, and an explicit step would be bound by the membrane's). Each
//! step solves for the end-of-step displacement by Newton's method on the
//! assembled sparse tangent, faer's sparse Cholesky:
//!
//! ```text
//! M a1 + C v1 + f(u1) = f_ext,     C = alpha M + beta K   (Rayleigh)
//! ```
//!
//! with `a1`, `v1` from `u1` by one of two integrators, the knob that
//! trades accuracy for robustness:
//!
//! - **backward Euler** (`v1 = (u1 - u0)/h`, `a1 = (v1 - v0)/h`): first
//!   order; damps a mode of frequency `omega` by about `(omega h)^2 / 2`
//!   per step, so huge steps settle to equilibrium instead of ringing.
//!   The choice for interactive use.
//! - **Newmark's average acceleration** (`beta = 1/4`, `gamma = 1/2`):
//!   second order, unconditionally stable for linear systems and without
//!   numerical damping (a linear system's energy is conserved); the
//!   period lengthens by about `(omega h)^2 / 12`. The choice for
//!   accuracy.
//!
//! Both write `a1 = c_a (u1 - u0) + a*`, `v1 = c_v (u1 - u0) + v*`, so
//! the Newton tangent is `(1 + beta c_v) K + (c_a + alpha c_v) M` (the
//! stiffness damping's own change with `u` left out). Where that is
//! indefinite (buckling, snap-through, a stiff grab yanking the shell),
//! a multiple of the mass is added until it factors. A step that fails
//! (no convergence, a fold, cancellation) leaves the state as it was.
//!
//! A second knob, [`Mechanics`], trades the geometric nonlinearity for
//! speed: the linear route (`linear.rs`) keeps `K` at the reference, so a
//! step is one solve with a factor kept between steps.

use super::assembly::{Assembly, Grab, GrabBlocks, Load, Support};
use super::error::ShellError;
use super::model::ShellModel;
use crate::cancel::Cancel;
use crate::linalg::sparse::SparseCholesky;
use crate::math::{Real, Vector, bounds};
use linear::Linear;
use serde::{Deserialize, Serialize};

mod linear;

/// The most mass a Newton iteration adds to an indefinite tangent, in
/// units of the step's own inertia `c_a M`: past it the step is refused
/// (the tangent of a shell that needs more is not a shell's).
const MAX_SHIFT: Real = 1e8;

/// How a step relates velocity and acceleration to displacement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Integrator {
    /// First order, numerically damped: robust at any step.
    #[default]
    BackwardEuler,
    /// Newmark's average acceleration: second order, energy-conserving
    /// for linear systems.
    Newmark,
}

/// How the internal forces follow the displacement: the knob that trades
/// large deformations for speed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mechanics {
    /// Kirchhoff–Love's energy of the deformed surface: large deflections
    /// and rotations right; Newton on the tangent each step.
    #[default]
    Nonlinear,
    /// Its expansion to second order at the reference (Guo–Qin's Eq. 24:
    /// `M`, `K` constant): small displacements only, a rotation
    /// stretches; one solve per step with a factor kept between steps.
    Linear,
}

/// The dynamic route's parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DynamicParams {
    /// Time step.
    pub dt: Real,
    /// The integrator.
    pub integrator: Integrator,
    /// Nonlinear or linear mechanics.
    pub mechanics: Mechanics,
    /// Rayleigh damping's mass coefficient `alpha` (1/time).
    pub mass_damping: Real,
    /// Rayleigh damping's stiffness coefficient `beta` (time).
    pub stiffness_damping: Real,
    /// Penalty scale of the supports (as the static route's).
    pub penalty: Real,
    /// Newton stops when the residual is this fraction of the largest of
    /// the internal, inertial, external and support or grab forces (now
    /// and at the step's start) and the momentum per step.
    pub tolerance: Real,
    /// Most Newton iterations per step.
    pub max_iterations: usize,
}

impl DynamicParams {
    /// Steps of `dt` by backward Euler, no damping, supports' `beta = 10`,
    /// Newton to 1e-7 within 20 iterations (round-off in the penalties
    /// leaves residuals of a few 1e-9 of the forces).
    pub fn new(dt: Real) -> Self {
        Self {
            dt,
            integrator: Integrator::BackwardEuler,
            mechanics: Mechanics::Nonlinear,
            mass_damping: 0.0,
            stiffness_damping: 0.0,
            penalty: 10.0,
            tolerance: 1e-7,
            max_iterations: 20,
        }
    }

    fn validate(&self) -> Result<(), ShellError> {
        let check = |what, got: Real, ok: bool, range| {
            if ok {
                Ok(())
            } else {
                Err(ShellError::Parameter { what, got, range })
            }
        };
        check(
            "dt",
            self.dt,
            self.dt > 0.0 && self.dt.is_finite(),
            "a finite time > 0",
        )?;
        for (what, got) in [
            ("mass_damping", self.mass_damping),
            ("stiffness_damping", self.stiffness_damping),
        ] {
            check(
                what,
                got,
                got >= 0.0 && got.is_finite(),
                "a finite value >= 0",
            )?;
        }
        check(
            "tolerance",
            self.tolerance,
            self.tolerance > 0.0 && self.tolerance < 1.0,
            "a value in (0, 1)",
        )?;
        check(
            "max_iterations",
            self.max_iterations as Real,
            self.max_iterations > 0,
            "at least 1",
        )
    }
}

/// What one step took.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShellStep {
    /// Newton iterations.
    pub iterations: usize,
    /// Final residual over the force scale.
    pub residual: Real,
}

/// Energies of the current state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShellEnergy {
    /// `1/2 v^T M v`.
    pub kinetic: Real,
    /// Membrane and bending energy, the supports' and grabs' springs
    /// included.
    pub strain: Real,
    /// Work the (dead) external load has done, `f_ext . u`.
    pub work: Real,
}

/// Everything a shell's next steps read from its past: a snapshot's
/// share of a shell, restored bit for bit by [`ShellDynamics::restore`].
#[derive(Debug, Clone, PartialEq)]
pub struct ShellState {
    /// Nodal displacement coefficients.
    pub displacement: Vec<Vector>,
    /// Nodal velocity coefficients.
    pub velocity: Vec<Vector>,
    /// Nodal acceleration coefficients (Newmark's next step reads them).
    pub acceleration: Vec<Vector>,
    /// Simulated time.
    pub time: Real,
}

/// A shell stepped in time (see the module's documentation).
#[derive(Debug, Clone)]
pub struct ShellDynamics {
    model: ShellModel,
    /// The largest extent of the reference nodes: the length that
    /// round-off is measured against.
    size: Real,
    supports: Vec<Support>,
    assembly: Assembly,
    load: Vec<Vector>,
    params: DynamicParams,
    /// The linear route's matrices, under [`Mechanics::Linear`].
    linear: Option<Linear>,
    solver: SparseCholesky,
    displacement: Vec<Vector>,
    velocity: Vec<Vector>,
    acceleration: Vec<Vector>,
    time: Real,
}

pub(super) fn norm(v: &[Vector]) -> Real {
    v.iter().map(|x| x.norm_squared()).sum::<Real>().sqrt()
}

impl ShellDynamics {
    /// The shell of `model` at rest in its reference configuration, held
    /// by `supports`, under the dead load `load`.
    ///
    /// # Errors
    /// [`ShellError`]: a parameter out of range, no mass (density 0), a
    /// support or load off the chart.
    pub fn new(
        model: ShellModel,
        supports: &[Support],
        load: &Load,
        params: DynamicParams,
    ) -> Result<Self, ShellError> {
        params.validate()?;
        if model.material().density <= 0.0 {
            return Err(ShellError::Parameter {
                what: "density",
                got: model.material().density,
                range: "a value > 0 (a shell in motion needs mass)",
            });
        }
        let grab_blocks = match params.mechanics {
            Mechanics::Nonlinear => GrabBlocks::InPattern,
            Mechanics::Linear => GrabBlocks::Apart,
        };
        let mut assembly = Assembly::new(&model, supports, &[], params.penalty, grab_blocks)?;
        let linear = match params.mechanics {
            Mechanics::Nonlinear => None,
            Mechanics::Linear => Some(Linear::new(&mut assembly, &model)?),
        };
        let load = model.load_vector(load)?;
        let n = model.node_count();
        let (lo, hi) = bounds(model.reference());
        let size = (hi - lo).max();
        let mut dynamics = Self {
            model,
            size,
            supports: supports.to_vec(),
            assembly,
            load,
            params,
            linear,
            solver: SparseCholesky::default(),
            displacement: vec![Vector::zeros(); n],
            velocity: vec![Vector::zeros(); n],
            acceleration: vec![Vector::zeros(); n],
            time: 0.0,
        };
        dynamics.set_state(vec![Vector::zeros(); n], vec![Vector::zeros(); n])?;
        Ok(dynamics)
    }

    /// Sets the nodal displacements and velocities, and the acceleration
    /// they imply (`M a = f_ext - f(u) - C v`, which Newmark's first step
    /// reads).
    ///
    /// # Errors
    /// [`ShellError::Parameter`] for a length other than the node count,
    /// or a non-finite value; [`ShellError::Folded`] or
    /// [`ShellError::Singular`] for a state with no acceleration. The
    /// state is unchanged on error.
    pub fn set_state(
        &mut self,
        displacement: Vec<Vector>,
        velocity: Vec<Vector>,
    ) -> Result<(), ShellError> {
        let n = self.model.node_count();
        for (what, v) in [("displacement", &displacement), ("velocity", &velocity)] {
            if v.len() != n || !v.iter().all(|x| x.iter().all(|c| c.is_finite())) {
                return Err(ShellError::Parameter {
                    what,
                    got: v.len() as Real,
                    range: "one finite vector per node",
                });
            }
        }
        let (f, _) = self.internal_forces(&displacement)?;
        let damping = self.product(
            &velocity,
            self.params.stiffness_damping,
            self.params.mass_damping,
        );
        let rhs = self
            .load
            .iter()
            .zip(&f)
            .zip(&damping)
            .flat_map(|((l, f), c)| {
                let r = l - f - c;
                [r[0], r[1], r[2]]
            });
        let (assembly, model) = (&self.assembly, &self.model);
        // The mass's factor replaces the linear route's.
        if let Some(linear) = &mut self.linear {
            linear.factored = None;
        }
        let acceleration = self
            .solver
            .solve(
                &assembly.pattern,
                |node, column| assembly.column(model, node, column, 0.0, 1.0),
                rhs,
            )
            .ok_or(ShellError::Singular)?
            .chunks_exact(3)
            .map(|c| Vector::new(c[0], c[1], c[2]))
            .collect();
        self.displacement = displacement;
        self.velocity = velocity;
        self.acceleration = acceleration;
        Ok(())
    }

    /// Advances one step of `dt`.
    ///
    /// # Errors
    /// [`ShellError::NotConverged`], [`ShellError::Folded`],
    /// [`ShellError::Singular`] or [`ShellError::Cancelled`]; the state
    /// is then unchanged.
    pub fn step(&mut self, cancel: &Cancel) -> Result<ShellStep, ShellError> {
        if self.linear.is_some() {
            return self.step_linear(cancel);
        }
        let p = self.params;
        let h = p.dt;
        // a1 = c_a du + a*, v1 = c_v du + v*.
        let (c_a, c_v, a_star, v_star) = self.kinematics();
        let (u0, v0) = (&self.displacement, &self.velocity);
        let mut u1: Vec<Vector> = u0.iter().zip(v0).map(|(u, v)| u + h * v).collect();
        // The momentum a step carries, M v0 / h, is a force scale too: a
        // shell moving freely has no other.
        let momentum = norm(&self.assembly.product(&self.model, v0, 0.0, 1.0)) / h;
        let kinematics = |u1: &[Vector]| -> (Vec<Vector>, Vec<Vector>) {
            let du = u1.iter().zip(u0).map(|(a, b)| a - b);
            let a1 = du.clone().zip(&a_star).map(|(d, a)| c_a * d + a).collect();
            let v1 = du.zip(&v_star).map(|(d, v)| c_v * d + v).collect();
            (a1, v1)
        };
        let mut iterations = 0;
        let mut start = 0.0;
        let (u1, a1, v1, iterations, residual) = loop {
            cancel.check().map_err(|_| ShellError::Cancelled)?;
            let (f, _) = self.assembly.forces(&self.model, &u1)?;
            let springs = self.assembly.spring_force_norm();
            let (a1, v1) = kinematics(&u1);
            let model = &self.model;
            let inertia = self.assembly.product(model, &a1, 0.0, 1.0);
            let damping = self
                .assembly
                .product(model, &v1, p.stiffness_damping, p.mass_damping);
            let r: Vec<Vector> = f
                .iter()
                .zip(&self.load)
                .zip(inertia.iter().zip(&damping))
                .map(|((f, l), (i, c))| f - l + i + c)
                .collect();
            // The forces at the step's start stay a scale as the shell
            // comes to rest (everything else then tends to zero).
            if iterations == 0 {
                start = norm(&f).max(springs);
            }
            let scale = norm(&f)
                .max(springs)
                .max(start)
                .max(momentum)
                .max(norm(&self.load))
                .max(norm(&inertia))
                .max(Real::MIN_POSITIVE);
            let residual = norm(&r) / scale;
            if residual <= p.tolerance {
                break (u1, a1, v1, iterations, residual);
            }
            if iterations == p.max_iterations {
                return Err(ShellError::NotConverged {
                    iterations,
                    residual,
                });
            }
            let (ks, ms) = (1.0 + p.stiffness_damping * c_v, c_a + p.mass_damping * c_v);
            let assembly = &self.assembly;
            let rhs: Vec<Real> = r.iter().flat_map(|v| [-v[0], -v[1], -v[2]]).collect();
            // Where the tangent is indefinite (a shell buckling, snapping
            // through, or yanked by a stiff grab), more of the mass is
            // added until it factors: a shorter step's tangent, which
            // Newton still converges with, in more iterations.
            let mut shift = 0.0;
            let delta = loop {
                let solved = self.solver.solve(
                    &assembly.pattern,
                    |node, column| assembly.column(model, node, column, ks, ms + shift),
                    rhs.iter().copied(),
                );
                match solved {
                    Some(delta) => break delta,
                    None if shift < MAX_SHIFT * ms => {
                        shift = if shift == 0.0 { ms } else { 10.0 * shift };
                    }
                    None => return Err(ShellError::Singular),
                }
            };
            let correction = delta.iter().fold(0.0 as Real, |m, d| m.max(d.abs()));
            for (uk, d) in u1.iter_mut().zip(delta.chunks_exact(3)) {
                *uk += Vector::new(d[0], d[1], d[2]);
            }
            iterations += 1;
            // A correction at round-off of the shell's size, or a tolerance
            // of the step's motion, is converged however small the forces
            // (a shell at rest has no force to measure against).
            let moved = u1
                .iter()
                .zip(u0)
                .fold(0.0 as Real, |m, (a, b)| m.max((a - b).amax()));
            if correction <= 1e-12 * self.size || correction <= p.tolerance * moved {
                let (a1, v1) = kinematics(&u1);
                break (u1, a1, v1, iterations, residual);
            }
        };
        self.displacement = u1;
        self.velocity = v1;
        self.acceleration = a1;
        self.time += h;
        Ok(ShellStep {
            iterations,
            residual,
        })
    }

    /// The state, for a snapshot.
    pub fn state(&self) -> ShellState {
        ShellState {
            displacement: self.displacement.clone(),
            velocity: self.velocity.clone(),
            acceleration: self.acceleration.clone(),
            time: self.time,
        }
    }

    /// Moves the shell to `state` as [`Self::state`] gave it, nothing
    /// recomputed, so that the steps after it are those after the
    /// snapshot, bit for bit.
    ///
    /// # Errors
    /// [`ShellError::Parameter`] for a length other than the node count or
    /// a value not finite; the state is then unchanged.
    pub fn restore(&mut self, state: ShellState) -> Result<(), ShellError> {
        let n = self.model.node_count();
        for (what, v) in [
            ("displacement", &state.displacement),
            ("velocity", &state.velocity),
            ("acceleration", &state.acceleration),
        ] {
            if v.len() != n || !v.iter().all(|x| x.iter().all(|c| c.is_finite())) {
                return Err(ShellError::Parameter {
                    what,
                    got: v.len() as Real,
                    range: "one finite vector per node",
                });
            }
        }
        if !state.time.is_finite() {
            return Err(ShellError::Parameter {
                what: "time",
                got: state.time,
                range: "a finite time",
            });
        }
        self.displacement = state.displacement;
        self.velocity = state.velocity;
        self.acceleration = state.acceleration;
        self.time = state.time;
        Ok(())
    }

    /// The time step.
    pub fn time_step(&self) -> Real {
        self.params.dt
    }

    /// Steps of `dt` from now on (nothing is assembled per step length).
    ///
    /// # Errors
    /// [`ShellError::Parameter`] for a step not finite and positive; the
    /// step is then unchanged.
    pub fn set_time_step(&mut self, dt: Real) -> Result<(), ShellError> {
        let params = DynamicParams { dt, ..self.params };
        params.validate()?;
        self.params = params;
        if let Some(linear) = &mut self.linear {
            linear.factored = None;
        }
        Ok(())
    }

    /// Replaces the grabs (none to release them all): their points are
    /// pulled from the next step on. Under nonlinear mechanics the
    /// grabs' sparsity is new, so the assembly is rebuilt; the linear
    /// route keeps its matrices and its factor and takes the springs as a
    /// low-rank term. To drag a grab, [`Self::move_grab`].
    ///
    /// # Errors
    /// [`ShellError`] for a grab off the chart, a stiffness out of range
    /// or a target not finite; the grabs are then as they were.
    pub fn set_grabs(&mut self, grabs: &[Grab]) -> Result<(), ShellError> {
        match &mut self.linear {
            Some(linear) => {
                self.assembly.replace_grabs(&self.model, grabs)?;
                linear.grabs_changed(&self.assembly, self.model.node_count());
            }
            None => {
                self.assembly = Assembly::new(
                    &self.model,
                    &self.supports,
                    grabs,
                    self.params.penalty,
                    GrabBlocks::InPattern,
                )?;
            }
        }
        Ok(())
    }

    /// Moves grab `index` (in the order [`Self::set_grabs`] was given)
    /// to `target`, turned by `rotation`: each given where the grab was
    /// set with one, and only there.
    ///
    /// # Errors
    /// [`ShellError::Parameter`] for no such grab, a target or rotation
    /// given or left out against how the grab was set, or a value not
    /// finite.
    pub fn move_grab(
        &mut self,
        index: usize,
        target: Option<Vector>,
        rotation: Option<Vector>,
    ) -> Result<(), ShellError> {
        let finite = |v: &Vector| v.iter().all(|c| c.is_finite());
        if !target.as_ref().is_none_or(finite) || !rotation.as_ref().is_none_or(finite) {
            return Err(ShellError::Parameter {
                what: "grab target",
                got: Real::NAN,
                range: "a finite point and rotation",
            });
        }
        if self.assembly.move_grab(index, target, rotation) {
            if let Some(linear) = &mut self.linear {
                linear.springs_moved(&self.assembly, self.model.node_count());
            }
            Ok(())
        } else {
            Err(ShellError::Parameter {
                what: "grab index",
                got: index as Real,
                range: "the index of a grab set by set_grabs, with a target and a rotation \
                        where it was set with them",
            })
        }
    }

    /// The energies of the current state.
    ///
    /// # Errors
    /// [`ShellError::Folded`] where the surface folds flat.
    pub fn energy(&mut self) -> Result<ShellEnergy, ShellError> {
        let (_, strain) = self.internal_forces(&self.displacement.clone())?;
        let mv = self.product(&self.velocity, 0.0, 1.0);
        let kinetic = 0.5
            * self
                .velocity
                .iter()
                .zip(&mv)
                .map(|(v, m)| v.dot(m))
                .sum::<Real>();
        let work = self
            .load
            .iter()
            .zip(&self.displacement)
            .map(|(f, u)| f.dot(u))
            .sum();
        Ok(ShellEnergy {
            kinetic,
            strain,
            work,
        })
    }

    /// The internal and spring forces at `u` and the energy, by the
    /// route's mechanics.
    fn internal_forces(&mut self, u: &[Vector]) -> Result<(Vec<Vector>, Real), ShellError> {
        match &self.linear {
            Some(linear) => Ok(linear.forces(&self.assembly, u)),
            None => self.assembly.forces(&self.model, u),
        }
    }

    /// `(stiffness K + mass M) v`, by the route's mechanics.
    fn product(&self, v: &[Vector], stiffness: Real, mass: Real) -> Vec<Vector> {
        match &self.linear {
            Some(linear) => linear.product(&self.assembly, v, stiffness, mass),
            None => self.assembly.product(&self.model, v, stiffness, mass),
        }
    }

    /// The total external force's magnitude, `sum_I |f_I|`: a scale of
    /// the work the load can do.
    pub fn load_magnitude(&self) -> Real {
        self.load.iter().map(|f| f.norm()).sum()
    }

    /// The shell's discretisation.
    pub fn model(&self) -> &ShellModel {
        &self.model
    }

    /// Bytes held by the Cholesky factor of the last step's matrix (kept
    /// between steps under linear mechanics): a closed surface's fills
    /// far more of its matrix than an open one's, and every linear step
    /// reads it twice (the two triangular solves).
    pub fn factor_bytes(&self) -> usize {
        self.solver.factor_bytes()
    }

    /// Nodal displacement coefficients.
    pub fn displacement(&self) -> &[Vector] {
        &self.displacement
    }

    /// Nodal velocity coefficients.
    pub fn velocity(&self) -> &[Vector] {
        &self.velocity
    }

    /// Simulated time.
    pub fn time(&self) -> Real {
        self.time
    }
}
