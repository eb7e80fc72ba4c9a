//! Full nonlinear EFG dynamics (Guo–Qin, Section 5.1, Eq. 15-20): the
//! nodal coefficients of an [`EfgSolid`] stepped whole, with Green's strain
//! and the Saint Venant–Kirchhoff energy, where the modal path
//! ([`super::ModalSolid`]) steps a reduced, linearised state.
//!
//! At a Gauss point with weight `w` and the shape-function gradients
//! `grad phi_I` of the nodes it sees (the coefficient integrals: stored
//! once by the build's quadrature table, never re-evaluated here):
//!
//! ```text
//! F = I + sum_I u_I (x) grad phi_I            deformation gradient
//! E = (F^T F - I) / 2                         Green's strain (Eq. 18)
//! S = lambda tr(E) I + 2 mu E                 stress (Eq. 19)
//! W = sum_g w (lambda/2 tr(E)^2 + mu E:E)     energy (Eq. 20)
//! dW/du_I = sum_g w P grad phi_I,  P = F S    (minus the internal force)
//! A_aJbL = dP_aJ/dF_bL = delta_ab S_JL + lambda F_aJ F_bL
//!          + mu F_aL F_bJ + mu (F F^T)_ab delta_JL
//! K_(Ia)(Kb) = sum_g w A_aJbL phi_I,J phi_K,L  consistent tangent
//! ```
//!
//! Eq. 18 as extracted reads `eps = grad u + grad u^T + grad u^T grad u`,
//! twice Green's `E`; with it Eq. 20 is four times the energy whose
//! derivative is Eq. 19's stress. Both are read here with the factor
//! one half (`E` above), the form whose small-strain limit is the linear
//! stiffness of `assemble.rs`; the test
//! `the_tangent_at_rest_is_the_linear_stiffness` pins that limit.
//!
//! A step is backward Euler written as a minimisation (the incremental
//! potential): with `u~ = u_n + h v_n`, Rayleigh damping `D = a M + b K_0`
//! (`K_0` the rest stiffness) and the penalty `K_p` of the fixed regions,
//!
//! ```text
//! Pi(u) = |u - u~|_M^2 / (2 h^2) + |u - u_n|_D^2 / (2 h) + W(u)
//!         + u^T K_p u / 2 + springs(u) - f^T u,
//! ```
//!
//! minimised by Newton's method on the consistent mass `M` with a
//! backtracking line search on `Pi`; `v_(n+1) = (u - u_n) / h`. Without
//! inertia (`h = None`) the same minimisation is the static equilibrium.
//! Where the tangent is indefinite (a compressed, buckling region: the
//! St Venant–Kirchhoff energy is not convex) the Cholesky factorisation
//! fails and the step adds `sigma M` with `sigma` growing tenfold until it
//! succeeds, a direction of descent that the line search then sizes.

use super::EfgSolid;
use super::assemble::{self, Integral};
use crate::cancel::Cancel;
use crate::linalg::{BlockColumn, SparseCholesky};
use crate::math::{Brief, Real, Vector};
use rayon::prelude::*;

/// The knobs of the Newton solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NewtonParams {
    /// Converged once a full Newton step moves no node by more than
    /// `tolerance * cell`.
    pub tolerance: Real,
    /// Newton iterations per step at most.
    pub max_iterations: usize,
    /// Rayleigh damping `(a, b)` of `D = a M + b K_0`.
    pub damping: (Real, Real),
}

impl Default for NewtonParams {
    /// Tolerance `1e-6` cells, 30 iterations, no damping.
    fn default() -> Self {
        Self {
            tolerance: 1e-6,
            max_iterations: 30,
            damping: (0.0, 0.0),
        }
    }
}

/// What a Newton solve did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NewtonInfo {
    /// Iterations run.
    pub iterations: usize,
    /// Whether the last step met the tolerance.
    pub converged: bool,
    /// `|grad Pi|` at the end, over `|f| + E cell^2` (the load, and the
    /// force a unit strain puts on an octant's face): a relative residual.
    pub residual: Real,
    /// Factorisations that failed (an indefinite tangent) and were
    /// retried with `sigma M` added.
    pub shifts: usize,
}

/// Why a nonlinear step failed; the state is then unchanged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NonlinearError {
    /// A time step that is not positive and finite.
    #[error("the time step {0} must be positive and finite")]
    BadStep(Brief),
    /// A load or state of the wrong length or with a non-finite entry.
    #[error("a {what} has {got} entries or a non-finite one; it needs {expected}")]
    BadVector {
        /// Which.
        what: &'static str,
        /// Its length.
        got: usize,
        /// 3 x nodes.
        expected: usize,
    },
    /// The tangent could not be factored even with the mass added (40
    /// tenfold shifts in one iteration).
    #[error(
        "the nonlinear EFG tangent could not be factored (still not positive definite with \
         {sigma} M added); use a shorter step or a finer octree"
    )]
    Factor {
        /// The last shift tried.
        sigma: Brief,
    },
    /// The solve met a non-finite value.
    #[error("the nonlinear EFG solve met a non-finite value; use a shorter step")]
    NonFinite,
    /// Cancelled.
    #[error("the nonlinear EFG solve was cancelled")]
    Cancelled,
}

/// A stiff spring holding a material point: `k/2 |sum_I phi_I u_I - d|^2`
/// (a position grab as a penalty).
#[derive(Debug, Clone, PartialEq)]
pub struct Spring {
    /// The nodes whose shape functions reach the point, ascending.
    pub nodes: Vec<u32>,
    /// Their values there.
    pub values: Vec<Real>,
    /// The displacement asked for.
    pub target: Vector,
    /// Its stiffness (force per length).
    pub stiffness: Real,
}

/// What a step is asked to do: its length (`None`: the static
/// equilibrium), the nodal load (3 n: gravity's weights and any other)
/// and the springs.
#[derive(Debug, Clone, Copy)]
pub struct StepInput<'a> {
    /// The time step, or `None` for a static solve.
    pub h: Option<Real>,
    /// Nodal forces, 3 per node.
    pub load: &'a [Real],
    /// Grabs as springs.
    pub springs: &'a [Spring],
}

/// The full state: nodal coefficients and their rates, `3 n` each.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct NonlinearState {
    /// Displacement coefficients `u`.
    pub displacements: Vec<Real>,
    /// Their velocities.
    pub velocities: Vec<Real>,
}

impl NonlinearState {
    /// At rest, for `nodes` nodes.
    pub fn rest(nodes: usize) -> Self {
        Self {
            displacements: vec![0.0; 3 * nodes],
            velocities: vec![0.0; 3 * nodes],
        }
    }
}

/// Bytes the solver holds per Gauss point (its stress, energy and
/// tangent), for the admission's estimate.
pub(super) const POINT_BYTES: usize = std::mem::size_of::<PointState>();

/// `A_aJbL` flattened `[a][J][b][L]`.
type Tangent = [Real; 81];

/// Per Gauss point: `P` (row-major `[a][J]`), its energy density times the
/// weight, and (when asked) `A`.
#[derive(Debug, Clone, Copy)]
struct PointState {
    p: [[Real; 3]; 3],
    energy: Real,
    a: Tangent,
}

impl Default for PointState {
    fn default() -> Self {
        Self {
            p: [[0.0; 3]; 3],
            energy: 0.0,
            a: [0.0; 81],
        }
    }
}

/// Saint Venant–Kirchhoff at a deformation gradient `f` (`f[a][J]`):
/// the energy density, `P = F S` and, with `tangent`, `A = dP/dF`.
fn st_venant_kirchhoff(
    f: &[[Real; 3]; 3],
    (lambda, mu): (Real, Real),
    tangent: bool,
) -> (Real, [[Real; 3]; 3], Tangent) {
    let mut e = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let c: Real = (0..3).map(|k| f[k][i] * f[k][j]).sum();
            e[i][j] = 0.5 * (c - if i == j { 1.0 } else { 0.0 });
        }
    }
    let tr = e[0][0] + e[1][1] + e[2][2];
    let mut s = [[0.0; 3]; 3];
    let mut ee = 0.0;
    for i in 0..3 {
        for j in 0..3 {
            s[i][j] = 2.0 * mu * e[i][j] + if i == j { lambda * tr } else { 0.0 };
            ee += e[i][j] * e[i][j];
        }
    }
    let psi = 0.5 * lambda * tr * tr + mu * ee;
    let mut p = [[0.0; 3]; 3];
    for a in 0..3 {
        for j in 0..3 {
            p[a][j] = (0..3).map(|k| f[a][k] * s[k][j]).sum();
        }
    }
    let mut at = [0.0; 81];
    if tangent {
        let mut fft = [[0.0; 3]; 3];
        for a in 0..3 {
            for b in 0..3 {
                fft[a][b] = (0..3).map(|k| f[a][k] * f[b][k]).sum();
            }
        }
        for a in 0..3 {
            for j in 0..3 {
                for b in 0..3 {
                    for l in 0..3 {
                        let mut v = lambda * f[a][j] * f[b][l] + mu * f[a][l] * f[b][j];
                        if a == b {
                            v += s[j][l];
                        }
                        if j == l {
                            v += mu * fft[a][b];
                        }
                        at[((a * 3 + j) * 3 + b) * 3 + l] = v;
                    }
                }
            }
        }
    }
    (psi, p, at)
}

/// The deformation gradient at a point from its row and the flat `u`.
fn deformation_gradient(row: &super::Row<'_>, u: &[Real]) -> [[Real; 3]; 3] {
    let mut f = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for (&node, g) in row.nodes.iter().zip(row.gradients) {
        let n = node as usize;
        for a in 0..3 {
            let ua = u[3 * n + a];
            for j in 0..3 {
                f[a][j] += ua * g[j];
            }
        }
    }
    f
}

/// The Saint Venant–Kirchhoff energy of an EFG solid's nodal coefficients
/// and its derivatives, over the solid's Gauss points; scratch held for
/// reuse from iterate to iterate.
#[derive(Debug, Clone, Default)]
pub struct Hyperelastic {
    points: Vec<PointState>,
}

impl Hyperelastic {
    /// Evaluates every Gauss point at `u` (in parallel): returns `W(u)`
    /// and keeps `P` (and `A` with `tangent`) for [`Self::gradient`] and
    /// [`Self::tangent_column`].
    pub fn evaluate(&mut self, solid: &EfgSolid, u: &[Real], tangent: bool) -> Real {
        let volume = &solid.volume;
        let lame = assemble::lame(solid.material().young, solid.material().poisson);
        self.points
            .resize(volume.table.len(), PointState::default());
        self.points.par_iter_mut().enumerate().for_each(|(q, out)| {
            let f = deformation_gradient(&volume.table.row(q), u);
            let (psi, p, a) = st_venant_kirchhoff(&f, lame, tangent);
            let w = volume.weights[q];
            out.energy = w * psi;
            out.p = p;
            if tangent {
                out.a = a;
            }
        });
        self.points.iter().map(|p| p.energy).sum()
    }

    /// `dW/du` at the last [`Self::evaluate`]: `sum_g w P grad phi_I` per
    /// node (the internal force with its sign flipped), into `out` (3 n).
    pub fn gradient(&self, solid: &EfgSolid, out: &mut [Real]) {
        let volume = &solid.volume;
        out.par_chunks_mut(3).enumerate().for_each(|(n, out)| {
            out.fill(0.0);
            for &q in volume.points_of(n) {
                let q = q as usize;
                let row = volume.table.row(q);
                let Ok(i) = row.nodes.binary_search(&(n as u32)) else {
                    continue;
                };
                let g = row.gradients[i];
                let w = volume.weights[q];
                let p = &self.points[q].p;
                for (a, out) in out.iter_mut().enumerate() {
                    *out += w * (p[a][0] * g[0] + p[a][1] * g[1] + p[a][2] * g[2]);
                }
            }
        });
    }

    /// Adds column `n` of the consistent tangent `d^2 W / du^2` at the
    /// last [`Self::evaluate`] (with `tangent`) to `out`, in the pattern
    /// of [`EfgSolid::pattern`].
    pub fn tangent_column(&self, volume: &Integral, n: usize, out: &mut BlockColumn<'_>) {
        for &q in volume.points_of(n) {
            let q = q as usize;
            let row = volume.table.row(q);
            let Ok(i_n) = row.nodes.binary_search(&(n as u32)) else {
                continue;
            };
            let w = volume.weights[q];
            let gn = row.gradients[i_n];
            let a = &self.points[q].a;
            // t[a][b][L] = w sum_J A_aJbL phi_n,J
            let mut t = [0.0; 27];
            for aa in 0..3 {
                for j in 0..3 {
                    let gj = w * gn[j];
                    for b in 0..3 {
                        for l in 0..3 {
                            t[(aa * 3 + b) * 3 + l] += a[((aa * 3 + j) * 3 + b) * 3 + l] * gj;
                        }
                    }
                }
            }
            for (i_m, &m) in row.nodes.iter().enumerate().skip(i_n) {
                let Some(slot) = out.slot(m) else { continue };
                let gm = row.gradients[i_m];
                for aa in 0..3 {
                    for b in 0..3 {
                        let k = (aa * 3 + b) * 3;
                        out.add(
                            slot,
                            aa,
                            b,
                            t[k] * gm[0] + t[k + 1] * gm[1] + t[k + 2] * gm[2],
                        );
                    }
                }
            }
        }
    }
}

/// The scratch of nonlinear steps on one solid: the penalty matrix, the
/// per-point stresses and tangents, the factorisation and the vectors.
/// Build it once per solid and reuse it from step to step.
#[derive(Debug, Clone, Default)]
pub struct NonlinearSolver {
    penalty: Vec<Real>,
    elastic: Hyperelastic,
    cholesky: SparseCholesky,
    gradient: Vec<Real>,
    work: Vec<Real>,
    trial: Vec<Real>,
}

/// What one potential needs besides `u`: the step, the previous state and
/// the loads.
struct Terms<'a> {
    /// `1 / h^2` and `1 / h` (zero for a static solve).
    inv_h2: Real,
    inv_h: Real,
    /// `u~ = u_n + h v_n` and `u_n`.
    predicted: &'a [Real],
    previous: &'a [Real],
    load: &'a [Real],
    springs: &'a [Spring],
    damping: (Real, Real),
}

impl NonlinearSolver {
    /// The scratch for `solid` (assembles the penalty of its fixed
    /// regions once).
    pub fn new(solid: &EfgSolid) -> Self {
        let mut penalty = Vec::new();
        let beta = solid.penalty_stiffness();
        solid.pattern().assemble(&mut penalty, |n, out| {
            if let Some(fixed) = solid.fixed_integral() {
                assemble::product_column(fixed, beta, n, out);
            }
        });
        Self {
            penalty,
            ..Self::default()
        }
    }

    /// Bytes it holds: the penalty's values, the factor, the per-point
    /// stresses and tangents and the vectors.
    pub fn bytes(&self) -> usize {
        let real = std::mem::size_of::<Real>();
        (self.penalty.len() + self.gradient.len() + self.work.len() + self.trial.len()) * real
            + self.cholesky.factor_bytes()
            + self.elastic.points.len() * std::mem::size_of::<PointState>()
    }

    /// The energy `state` holds besides gravity's: kinetic
    /// `v^T M v / 2`, Saint Venant–Kirchhoff `W(u)` and the fixed
    /// regions' penalty `u^T K_p u / 2`, J (what the world's energy watch
    /// measures).
    pub fn stored_energy(&self, solid: &EfgSolid, state: &NonlinearState) -> Real {
        let (u, v) = (&state.displacements, &state.velocities);
        let mut work = vec![0.0; u.len()];
        multiply(solid, solid.consistent_mass(), v, &mut work);
        let kinetic = 0.5 * dot(v, &work);
        multiply(solid, &self.penalty, u, &mut work);
        let penalty = 0.5 * dot(u, &work);
        let strain: Real = strain_energy_shares(solid, u).iter().sum();
        kinetic + strain + penalty
    }

    /// The Saint Venant–Kirchhoff energy `W(u)` (no penalty, no load).
    pub fn strain_energy(&mut self, solid: &EfgSolid, u: &[Real]) -> Real {
        self.elastic.evaluate(solid, u, false)
    }

    /// `dW/du` at `u` into `out`.
    pub fn strain_gradient(&mut self, solid: &EfgSolid, u: &[Real], out: &mut [Real]) {
        self.elastic.evaluate(solid, u, false);
        self.elastic.gradient(solid, out);
    }

    /// `d^2 W / du^2` at `u` in the pattern's order.
    pub fn strain_tangent(&mut self, solid: &EfgSolid, u: &[Real]) -> Vec<Real> {
        self.elastic.evaluate(solid, u, true);
        let mut values = Vec::new();
        let elastic = &self.elastic;
        solid.pattern().assemble(&mut values, |n, out| {
            elastic.tangent_column(&solid.volume, n, out);
        });
        values
    }

    /// The static equilibrium under `load` alone (no springs, no
    /// cancel), from `state`, in at most `max_iterations` Newton
    /// iterations: [`Self::step`] with no time step.
    ///
    /// # Errors
    /// As [`Self::step`].
    pub fn solve_static(
        &mut self,
        solid: &EfgSolid,
        state: &mut NonlinearState,
        load: &[Real],
        max_iterations: usize,
    ) -> Result<NewtonInfo, NonlinearError> {
        let input = StepInput {
            h: None,
            load,
            springs: &[],
        };
        let params = NewtonParams {
            max_iterations,
            ..NewtonParams::default()
        };
        self.step(solid, state, input, &params, &Cancel::new())
    }

    /// One backward-Euler step of `input.h` (or, with `None`, the static
    /// equilibrium) from `state` under `input`'s load and springs, minimising the incremental
    /// potential by Newton's method. On success `state` holds the new
    /// displacements and velocities; an unconverged solve (iteration cap
    /// or a line search that found no decrease) still moves it and says so
    /// in [`NewtonInfo::converged`].
    ///
    /// # Errors
    /// [`NonlinearError`]: a bad step or vector, a tangent that no shift
    /// makes factorable, a non-finite value, cancellation; `state` is then
    /// unchanged.
    pub fn step(
        &mut self,
        solid: &EfgSolid,
        state: &mut NonlinearState,
        input: StepInput<'_>,
        params: &NewtonParams,
        cancel: &Cancel,
    ) -> Result<NewtonInfo, NonlinearError> {
        let StepInput { h, load, springs } = input;
        let dofs = 3 * solid.nodes().len();
        if let Some(h) = h
            && !(h.is_finite() && h > 0.0)
        {
            return Err(NonlinearError::BadStep(Brief(h)));
        }
        for (what, v) in [
            ("load", load),
            ("displacement", &state.displacements[..]),
            ("velocity", &state.velocities[..]),
        ] {
            if v.len() != dofs || !v.iter().all(|x| x.is_finite()) {
                return Err(NonlinearError::BadVector {
                    what,
                    got: v.len(),
                    expected: dofs,
                });
            }
        }
        let previous = state.displacements.clone();
        let predicted: Vec<Real> = match h {
            Some(h) => previous
                .iter()
                .zip(&state.velocities)
                .map(|(u, v)| u + h * v)
                .collect(),
            None => previous.clone(),
        };
        let terms = Terms {
            inv_h2: h.map_or(0.0, |h| 1.0 / (h * h)),
            inv_h: h.map_or(0.0, |h| 1.0 / h),
            predicted: &predicted,
            previous: &previous,
            load,
            springs,
            damping: params.damping,
        };
        let mut u = predicted.clone();
        let cell = solid.params().cell;
        let mut info = NewtonInfo::default();
        let load_norm = load.iter().map(|f| f * f).sum::<Real>().sqrt();
        let mut pi = self.potential(solid, &terms, &u, true);
        let mut sigma: Real = 0.0;
        for _ in 0..params.max_iterations {
            if cancel.is_cancelled() {
                return Err(NonlinearError::Cancelled);
            }
            info.iterations += 1;
            // Gradient and tangent at u (the points hold A from `potential`).
            self.gradient_into(solid, &terms, &u);
            let mass_scale = terms.inv_h2 + terms.damping.0 * terms.inv_h;
            let b_scale = terms.damping.1 * terms.inv_h;
            let mut tries = 0;
            let dir = loop {
                let elastic = &self.elastic;
                let penalty = &self.penalty;
                let mass = solid.consistent_mass();
                let stiffness = solid.stiffness();
                let shift = sigma;
                let column = |n: usize, out: &mut BlockColumn<'_>| {
                    elastic.tangent_column(&solid.volume, n, out);
                    for s in springs {
                        spring_column(s, n, out);
                    }
                };
                // The matrices held over the pattern (penalty, mass, rest
                // stiffness) are added to the assembled tangent before it
                // is factored.
                let rhs = self.gradient.iter().map(|g| -g);
                let solved = self.cholesky.solve_with(
                    solid.pattern(),
                    column,
                    |values| {
                        values
                            .par_iter_mut()
                            .zip(penalty.par_iter())
                            .zip(mass.par_iter().zip(stiffness.par_iter()))
                            .for_each(|((v, p), (m, k))| {
                                *v += p + (mass_scale + shift) * m + b_scale * k;
                            });
                    },
                    rhs,
                );
                match solved {
                    Some(d) => break d.to_vec(),
                    None => {
                        info.shifts += 1;
                        tries += 1;
                        if tries > 40 {
                            return Err(NonlinearError::Factor {
                                sigma: Brief(sigma),
                            });
                        }
                        sigma = if sigma == 0.0 {
                            1e-6 * mean_ratio(solid) + 1e-3 * terms.inv_h2
                        } else {
                            10.0 * sigma
                        };
                    }
                }
            };
            // Keep a shift that was needed, but let it decay.
            sigma *= 0.1;
            if sigma < 1e-12 * mean_ratio(solid) {
                sigma = 0.0;
            }
            if !dir.iter().all(|d| d.is_finite()) {
                return Err(NonlinearError::NonFinite);
            }
            let step_max = dir
                .chunks_exact(3)
                .map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt())
                .fold(0.0, Real::max);
            if step_max <= params.tolerance * cell {
                // Below the tolerance the potential's change is at its
                // rounding floor, where a line search cannot judge it.
                axpy(&mut u, 1.0, &dir);
                info.converged = true;
                break;
            }
            let slope: Real = dir.iter().zip(&self.gradient).map(|(d, g)| d * g).sum();
            let mut alpha = 1.0;
            let mut accepted = false;
            let mut trial = std::mem::take(&mut self.trial);
            for _ in 0..30 {
                trial.clear();
                trial.extend(u.iter().zip(&dir).map(|(u, d)| u + alpha * d));
                let candidate = self.potential(solid, &terms, &trial, true);
                if candidate.is_finite() && candidate <= pi + 1e-4 * alpha * slope.min(0.0) {
                    pi = candidate;
                    accepted = true;
                    break;
                }
                alpha *= 0.5;
            }
            if !accepted {
                self.trial = trial;
                // No decrease along the Newton direction: at the rounding
                // floor of Pi, or a failure; the residual says which.
                self.potential(solid, &terms, &u, true);
                break;
            }
            std::mem::swap(&mut u, &mut trial);
            self.trial = trial;
        }
        // The points at the final u (the loop may leave them at a trial).
        self.potential(solid, &terms, &u, false);
        self.gradient_into(solid, &terms, &u);
        let scale = load_norm + solid.material().young * cell * cell;
        let grad_norm = self.gradient.iter().map(|g| g * g).sum::<Real>().sqrt();
        info.residual = if scale > 0.0 {
            grad_norm / scale
        } else {
            grad_norm
        };
        if !u.iter().all(|x| x.is_finite()) {
            return Err(NonlinearError::NonFinite);
        }
        if let Some(h) = h {
            for ((v, u), u0) in state.velocities.iter_mut().zip(&u).zip(&previous) {
                *v = (u - u0) / h;
            }
        }
        state.displacements = u;
        Ok(info)
    }

    /// `Pi(u)`; evaluates the points (with their tangents when asked).
    fn potential(&mut self, solid: &EfgSolid, t: &Terms<'_>, u: &[Real], tangent: bool) -> Real {
        let w = self.elastic.evaluate(solid, u, tangent);
        let n = u.len();
        let mass = solid.consistent_mass();
        self.work.resize(n, 0.0);
        let mut pi = w;
        let du: Vec<Real> = u.iter().zip(t.predicted).map(|(a, b)| a - b).collect();
        if t.inv_h2 > 0.0 {
            multiply(solid, mass, &du, &mut self.work);
            pi += 0.5 * t.inv_h2 * dot(&du, &self.work);
        }
        let (a, b) = t.damping;
        if t.inv_h > 0.0 && (a > 0.0 || b > 0.0) {
            let dv: Vec<Real> = u.iter().zip(t.previous).map(|(a, b)| a - b).collect();
            multiply(solid, mass, &dv, &mut self.work);
            pi += 0.5 * t.inv_h * a * dot(&dv, &self.work);
            multiply(solid, solid.stiffness(), &dv, &mut self.work);
            pi += 0.5 * t.inv_h * b * dot(&dv, &self.work);
        }
        multiply(solid, &self.penalty, u, &mut self.work);
        pi += 0.5 * dot(u, &self.work);
        for s in t.springs {
            let r = spring_residual(s, u);
            pi += 0.5 * s.stiffness * r.norm_squared();
        }
        pi - dot(t.load, u)
    }

    /// `grad Pi(u)` into `self.gradient`, from the points as the last
    /// [`Self::potential`] at `u` left them.
    fn gradient_into(&mut self, solid: &EfgSolid, t: &Terms<'_>, u: &[Real]) {
        let n = u.len();
        self.gradient.resize(n, 0.0);
        self.work.resize(n, 0.0);
        self.elastic.gradient(solid, &mut self.gradient);
        let mass = solid.consistent_mass();
        let (a, b) = t.damping;
        if t.inv_h2 > 0.0 {
            let du: Vec<Real> = u.iter().zip(t.predicted).map(|(a, b)| a - b).collect();
            multiply(solid, mass, &du, &mut self.work);
            axpy(&mut self.gradient, t.inv_h2, &self.work);
        }
        if t.inv_h > 0.0 && (a > 0.0 || b > 0.0) {
            let dv: Vec<Real> = u.iter().zip(t.previous).map(|(a, b)| a - b).collect();
            multiply(solid, mass, &dv, &mut self.work);
            axpy(&mut self.gradient, t.inv_h * a, &self.work);
            multiply(solid, solid.stiffness(), &dv, &mut self.work);
            axpy(&mut self.gradient, t.inv_h * b, &self.work);
        }
        multiply(solid, &self.penalty, u, &mut self.work);
        axpy(&mut self.gradient, 1.0, &self.work);
        for s in t.springs {
            let r = spring_residual(s, u) * s.stiffness;
            for (&node, &phi) in s.nodes.iter().zip(&s.values) {
                for c in 0..3 {
                    self.gradient[3 * node as usize + c] += phi * r[c];
                }
            }
        }
        axpy(&mut self.gradient, -1.0, t.load);
    }
}

/// Each node's share `sum_g phi_I(x_g) w_g psi(F_g)` of the strain energy
/// `W(u)`: the shape functions sum to one, so the shares sum to `W`.
pub fn strain_energy_shares(solid: &EfgSolid, u: &[Real]) -> Vec<Real> {
    let volume = &solid.volume;
    let lame = assemble::lame(solid.material().young, solid.material().poisson);
    let energies: Vec<Real> = (0..volume.table.len())
        .into_par_iter()
        .map(|q| {
            let f = deformation_gradient(&volume.table.row(q), u);
            volume.weights[q] * st_venant_kirchhoff(&f, lame, false).0
        })
        .collect();
    (0..solid.nodes().len())
        .into_par_iter()
        .map(|n| {
            volume
                .points_of(n)
                .iter()
                .map(|&q| {
                    let row = volume.table.row(q as usize);
                    row.nodes
                        .binary_search(&(n as u32))
                        .map_or(0.0, |i| row.values[i] * energies[q as usize])
                })
                .sum()
        })
        .collect()
}

/// `F` at a point from its row and nodal vectors `u`.
pub(super) fn gradient_at(row: &super::Row<'_>, u: &[Vector]) -> nalgebra::Matrix3<Real> {
    let mut f = nalgebra::Matrix3::identity();
    for (&node, g) in row.nodes.iter().zip(row.gradients) {
        f += u[node as usize] * g.transpose();
    }
    f
}

/// `sum_I phi_I u_I - d` of a spring.
fn spring_residual(s: &Spring, u: &[Real]) -> Vector {
    let mut x = -s.target;
    for (&node, &phi) in s.nodes.iter().zip(&s.values) {
        let n = node as usize;
        x += Vector::new(u[3 * n], u[3 * n + 1], u[3 * n + 2]) * phi;
    }
    x
}

/// Adds a spring's `k phi_I phi_J delta_ab` to column `n` (pairs the
/// pattern lacks are left out: the tangent is then approximate there, and
/// the line search still decreases `Pi`).
fn spring_column(s: &Spring, n: usize, out: &mut BlockColumn<'_>) {
    let Ok(i_n) = s.nodes.binary_search(&(n as u32)) else {
        return;
    };
    for (i_m, &m) in s.nodes.iter().enumerate().skip(i_n) {
        let Some(slot) = out.slot(m) else { continue };
        let v = s.stiffness * s.values[i_n] * s.values[i_m];
        for a in 0..3 {
            out.add(slot, a, a, v);
        }
    }
}

/// `tr K_0 / tr M`: the scale of the shift `sigma`.
fn mean_ratio(solid: &EfgSolid) -> Real {
    let diag = |values: &[Real]| -> Real { solid.pattern().diagonal().map(|i| values[i]).sum() };
    let m = diag(solid.consistent_mass());
    if m > 0.0 {
        diag(solid.stiffness()) / m
    } else {
        1.0
    }
}

fn multiply(solid: &EfgSolid, values: &[Real], x: &[Real], y: &mut [Real]) {
    solid.pattern().multiply(
        values,
        faer::MatRef::from_column_major_slice(x, x.len(), 1),
        faer::MatMut::from_column_major_slice_mut(y, x.len(), 1),
    );
}

fn dot(a: &[Real], b: &[Real]) -> Real {
    a.iter().zip(b).map(|(a, b)| a * b).sum()
}

fn axpy(y: &mut [Real], a: Real, x: &[Real]) {
    for (y, x) in y.iter_mut().zip(x) {
        *y += a * x;
    }
}
