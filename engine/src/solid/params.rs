//! The knobs of an elastic solid, each trading speed for accuracy or
//! naming a physical property.

use super::fracture::FractureParams;
use super::material::Material;
use crate::approx::mls::Order;
use crate::math::Real;
use serde::{Deserialize, Serialize};

/// How a solid advances in time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Integrator {
    /// Symplectic Euler: cheap per step, stable only below the elastic
    /// wave limit `cfl * spacing / c_p`, which the step is split to obey.
    Explicit {
        /// The Courant number: the sub-step as a fraction of the wave
        /// limit `spacing / c_p`.
        cfl: Real,
    },
    /// Backward Euler or implicit midpoint ([`ImplicitScheme`]), each step
    /// solved by Newton's method on the tangent stiffness: stable at any
    /// step, at the cost of several force evaluations.
    Implicit(ImplicitParams),
}

/// The implicit integrator's solver settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ImplicitParams {
    /// Newton stops when the backward Euler residual (the momentum
    /// imbalance) has fallen to this fraction of its value at the start of
    /// the step, or of the step's gravity impulse `dt |M g|` where that is
    /// larger (a body settled under gravity starts each step with a
    /// residual near rounding noise, which it could not reduce further).
    pub newton_tolerance: Real,
    /// Most Newton iterations per step (at least one runs); a step that
    /// reaches it keeps its last iterate and reports the residual left.
    pub max_newton_iterations: u32,
    /// Conjugate gradients stop at this residual relative to the
    /// right-hand side.
    pub cg_tolerance: Real,
    /// Most conjugate-gradient iterations per Newton step's linear solve
    /// (when CG solves it, or when Cholesky falls back to it).
    pub max_cg_iterations: u32,
    /// How each Newton step's linear system is solved.
    #[serde(default)]
    pub linear_solver: LinearSolver,
    /// The implicit scheme.
    #[serde(default)]
    pub scheme: ImplicitScheme,
}

/// The implicit integrator's time discretisation. Both solve the same
/// Newton problem once per step; they differ in what they do to motion.
/// On a free block spinning at 2 rad/s (engine/tests/solids.rs, 5 ms
/// steps, no material damping), backward Euler keeps 96.2 % of the
/// angular momentum and 92.5 % of the kinetic energy after 2 s, midpoint
/// 100.000 % and 99.9 %.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ImplicitScheme {
    /// `v+ = v + dt a(x + dt v+)`: first order, and its numerical damping
    /// (growing with `dt` times the frequency) removes every vibration
    /// the step does not resolve, and slows rigid rotation too. The robust
    /// choice for stiff bodies and large steps, and for reaching a static
    /// state.
    #[default]
    BackwardEuler,
    /// Implicit midpoint, `v+ = v + dt a((x + x+) / 2)`: second order,
    /// symplectic and free of numerical damping (energy is conserved for
    /// linear elasticity and angular momentum always), so vibrations the
    /// step does not resolve persist rather than decay. Solved as a
    /// backward Euler step of `dt / 2` extrapolated to `dt`, at the same
    /// cost.
    Midpoint,
    /// Static equilibrium: each step solves `f(x) + M g = 0` for the
    /// positions by Newton and leaves the body at rest there (a
    /// quasi-static load path; inertia plays no part). Posed as a backward
    /// Euler step whose length is `STATIC_PERIODS` (10^4) times the time
    /// an elastic wave takes to cross the body, so that the inertia term is
    /// below a millionth of the stiffness. Needs anchors: a free body has
    /// no equilibrium under gravity.
    Static,
}

/// Elastic crossing times in the static scheme's step (see
/// [`ImplicitScheme::Static`]).
pub const STATIC_PERIODS: Real = 1e4;

impl Default for ImplicitParams {
    fn default() -> Self {
        Self {
            newton_tolerance: 1e-6,
            max_newton_iterations: 20,
            cg_tolerance: 1e-3,
            max_cg_iterations: 200,
            linear_solver: LinearSolver::default(),
            scheme: ImplicitScheme::default(),
        }
    }
}

/// The linear solver of the implicit integrator's Newton steps,
/// `(M + dt^2 Hess U + dt D) dv = -grad Phi`.
///
/// CG's iteration count grows with the square root of the condition
/// number, which for a slender body in bending grows as `(L / H)^2
/// (L / dx)^2`. On a 1 m x 0.1 m 2D cantilever (E = 1.5e8 Pa) at 16
/// particles across, CG leaves Newton stalled at a residual of order 1
/// and a tip deflection half the true one, while Cholesky converges in 3
/// Newton steps, 30 to 170 times faster; at 8 across both converge and
/// Cholesky is still 20 to 50 times faster (2 cores; `cargo bench -p
/// meshless-engine --bench solid_direct`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LinearSolver {
    /// Jacobi-preconditioned conjugate gradients, matrix-free: memory
    /// linear in the particle count and no set-up, but its iterations
    /// (capped by `max_cg_iterations`) grow with the stiffness contrast
    /// and the slenderness of the body.
    ConjugateGradient,
    /// The Hessian assembled in `dim x dim` blocks and factorised by sparse
    /// Cholesky under an approximate-minimum-degree ordering: every Newton
    /// step exact, whatever the conditioning. The pattern and ordering are
    /// computed once per topology; the factor is recomputed every Newton
    /// step. Its fill grows slowly in 2D (2.6k particles: 0.04 s per
    /// Newton step) but about as `n^1.4` in 3D, its time as `n^1.9`: on a
    /// 0.5 x 0.1 x 0.1 m bar, 0.26 s and 49 MiB at 2.8k particles, 4.2 s
    /// and 430 MiB at 11k, where CG (which converges on so stocky a body)
    /// is 3 times faster. Past about 10k particles in 3D choose CG unless
    /// the body is slender. Where the Hessian is not positive definite
    /// (buckling under compression) the factorisation fails and that Newton
    /// step falls back to CG.
    Cholesky,
    /// Cholesky in 2D, CG in 3D: the faster of the two except for slender
    /// 3D bodies (a 1k-particle cube: CG 22 ms per implicit step, Cholesky
    /// 140 ms; `cargo bench -p meshless-engine --bench solid`). Where CG
    /// runs to `max_cg_iterations` without converging (a slender 3D
    /// cantilever: +29 to +35 % deflection error that varied from run to
    /// run, when auto stayed on CG), a body of up to
    /// `AUTO_FACTOR_LIMIT` (5,000) particles switches to Cholesky for good.
    #[default]
    Auto,
}

impl LinearSolver {
    /// Whether a solid in `dim` dimensions factorises.
    pub fn factorises(self, dim: usize) -> bool {
        match self {
            Self::Cholesky => true,
            Self::ConjugateGradient => false,
            Self::Auto => dim == 2,
        }
    }
}

/// Plastic flow (tutorial Section 7.3, Eq. 69, after Müller et al. 2004
/// and Gross & Pfister 2007).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plasticity {
    /// `c_yield`: elastic strain norm above which the material flows.
    #[serde(rename = "yield")]
    pub yield_strain: Real,
    /// `c_creep` in (0, 1]: the share of the elastic strain absorbed per
    /// step while yielding.
    pub creep: Real,
    /// `c_max`: the largest plastic strain norm a particle stores.
    pub max: Real,
    /// When a particle's total strain norm exceeds this, the reference
    /// shape moves to the current one and the shape functions are
    /// recomputed (large plastic deformation); `None` never re-bases.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rebase: Option<Real>,
}

/// Everything a solid needs besides its particles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolidParams {
    /// 2 or 3.
    pub dim: usize,
    /// Particle spacing, m; each particle stands for `spacing^dim` of
    /// material.
    pub spacing: Real,
    /// kg/m^3.
    pub density: Real,
    /// Young's modulus, Pa (scales the hourglass term).
    pub young: Real,
    /// The constitutive law: Lamé parameters and volume stiffness
    /// (tutorial Section 7.1).
    pub material: Material,
    /// MLS basis order of the displacement gradient.
    pub order: Order,
    /// MLS support radius h, m.
    pub support: Real,
    /// Weight of the hourglass (zero-energy mode) penalty relative to
    /// Young's modulus; 0 turns it off.
    pub hourglass: Real,
    /// Rate of the pairwise velocity damping, 1/s; 0 is undamped.
    pub damping: Real,
    /// Coulomb friction against obstacles and walls.
    pub friction: Real,
    /// How the solid advances in time.
    pub integrator: Integrator,
    /// Plastic flow (tutorial Eq. 69); `None` keeps the solid elastic.
    pub plasticity: Option<Plasticity>,
    /// Cracks (tutorial Section 7.3); `None` never cracks.
    pub fracture: Option<FractureParams>,
}

impl SolidParams {
    /// Mass and volume of one particle.
    pub fn particle_volume(&self) -> Real {
        self.spacing.powi(self.dim as i32)
    }

    /// Stiffness that sets the fastest wave, Pa.
    pub fn wave_modulus(&self) -> Real {
        self.material.wave_modulus() + self.hourglass * self.young
    }

    /// Speed of the fastest elastic wave, m/s.
    pub fn wave_speed(&self) -> Real {
        (self.wave_modulus() / self.density).sqrt()
    }

    /// The explicit step limit: the wave limit `cfl * spacing / c_p` and,
    /// with damping, `cfl / damping`.
    pub fn stable_dt(&self, cfl: Real) -> Real {
        let wave = cfl * self.spacing / self.wave_speed();
        if self.damping > 0.0 {
            wave.min(cfl / self.damping)
        } else {
            wave
        }
    }
}
