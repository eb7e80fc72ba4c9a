//! The linear route (Guo–Qin's Eq. 24, `M u'' + C u' + K u = F` with `M`
//! and `K` constant, the paper's own choice for its shells): the energy's
//! second-order expansion at the reference, so that each step is one
//! solve with a matrix that only a new time step changes. Factorised once, a step costs two passes over the
//! pattern that each multiply `K` and `M` together (the second checks the
//! solve) and two triangular solves instead of Newton's assemblies and
//! factorisations.
//!
//! Grabs come and go without a new assembly or factor: their springs
//! stay out of `K`'s pattern, and the step adds them as the low-rank term
//! they are (`sum_c k_c w_c w_c^T`, three to nine springs a grab, each
//! `w_c` a stencil's coefficients along an axis) by the
//! Sherman–Morrison–Woodbury identity: with `A` the factored matrix,
//! `Z = A^-1 W` (one solve per spring, once per factor and set of grabs)
//! and `S = D^-1 + W^T Z`,
//! `(A + W D W^T)^-1 b = y - Z S^-1 W^T y` for `y = A^-1 b`.
//!
//! What it gives up: the strains are linear in the displacement, so a
//! rotation stretches (a cantilever bent past a few percent of its length
//! lengthens, and a spinning shell swells). For small deflections about
//! the reference (vibration, a balloon's few percent, interactive pokes)
//! it agrees with the nonlinear route to the square of the strain.

use super::{Integrator, ShellDynamics, ShellStep, norm};
use crate::cancel::Cancel;
use crate::linalg::sparse::{BlockPattern, SparseCholesky};
use crate::math::{Real, Vector};
use crate::shell::assembly::Assembly;
use crate::shell::error::ShellError;
use crate::shell::model::ShellModel;
use nalgebra::{DMatrix, DVector};

/// The constant matrices of the linear route and what its factor is of.
#[derive(Debug, Clone)]
pub(super) struct Linear {
    /// `K` at the reference with the supports' springs (the grabs' are
    /// apart), in the pattern's order.
    stiffness: Vec<Real>,
    /// The consistent mass `M`, in the pattern's order.
    mass: Vec<Real>,
    /// The springs' forces at zero displacement, and their energy there.
    rest: Vec<Vector>,
    rest_energy: Real,
    /// The `(stiffness, mass)` scales of the matrix the solver holds the
    /// factor of, if it holds one of this route's.
    pub(super) factored: Option<(Real, Real)>,
    /// The grabs' springs against that factor, once a step with grabs
    /// needed them.
    grabbed: Option<Grabbed>,
}

/// What the Woodbury identity needs of the grabs' springs for one factor:
/// `Z = A^-1 W`, a column per spring, and the Cholesky factor of
/// `S = D^-1 + W^T Z`.
#[derive(Debug, Clone)]
struct Grabbed {
    z: Vec<Vec<Vector>>,
    capacitance: nalgebra::Cholesky<Real, nalgebra::Dyn>,
}

/// `values` (over `pattern`) times `v`.
fn multiply(pattern: &BlockPattern, values: &[Real], v: &[Vector]) -> Vec<Vector> {
    vectors(&pattern.product(values, &flat(v)))
}

/// Nodal vectors as the solver's scalars, three a node.
fn scalars(v: &[Vector]) -> impl Iterator<Item = Real> + '_ {
    v.iter().flat_map(|x| [x[0], x[1], x[2]])
}

/// [`scalars`], gathered.
fn flat(v: &[Vector]) -> Vec<Real> {
    scalars(v).collect()
}

/// The solver's scalars as nodal vectors (the inverse of [`flat`]).
fn vectors(y: &[Real]) -> Vec<Vector> {
    y.chunks_exact(3)
        .map(|c| Vector::new(c[0], c[1], c[2]))
        .collect()
}

impl Linear {
    /// The matrices of `model` held as `assembly` holds it, which is left
    /// with the energy's Hessians at the reference.
    ///
    /// # Errors
    /// [`ShellError::Folded`] for a reference surface that folds.
    pub(super) fn new(assembly: &mut Assembly, model: &ShellModel) -> Result<Self, ShellError> {
        let n = model.node_count();
        assembly.forces(model, &vec![Vector::zeros(); n])?;
        let (mut stiffness, mut mass) = (Vec::new(), Vec::new());
        let held = &*assembly;
        held.pattern.assemble(&mut stiffness, |node, column| {
            held.column(model, node, column, 1.0, 0.0)
        });
        held.pattern.assemble(&mut mass, |node, column| {
            held.column(model, node, column, 0.0, 1.0)
        });
        let (rest, rest_energy) = held.springs_at_rest(n);
        Ok(Self {
            stiffness,
            mass,
            rest,
            rest_energy,
            factored: None,
            grabbed: None,
        })
    }

    /// The springs' pull after a grab moved.
    pub(super) fn springs_moved(&mut self, assembly: &Assembly, nodes: usize) {
        (self.rest, self.rest_energy) = assembly.springs_at_rest(nodes);
    }

    /// The grabs were replaced: their pull, and their low-rank term
    /// anew at the next step.
    pub(super) fn grabs_changed(&mut self, assembly: &Assembly, nodes: usize) {
        self.springs_moved(assembly, nodes);
        self.grabbed = None;
    }

    /// `values v` for a matrix over the pattern whose stiffness part is
    /// `stiffness K` (`K` alone, or the factored matrix), plus that
    /// multiple of the grabs' springs `W D W^T v`, which `K` leaves out.
    fn apply(
        &self,
        assembly: &Assembly,
        values: &[Real],
        v: &[Vector],
        stiffness: Real,
    ) -> Vec<Vector> {
        let mut out = multiply(&assembly.pattern, values, v);
        if stiffness != 0.0 {
            for spring in assembly.grab_springs() {
                spring.add_gradient(stiffness * spring.stiffness() * spring.value(v), &mut out);
            }
        }
        out
    }

    /// `(K x + W D W^T x, M z)`: the stiffness with the grabs' springs
    /// and the mass, read in one pass over the pattern (see
    /// [`BlockPattern::product_pair`]).
    fn pair(&self, assembly: &Assembly, x: &[Vector], z: &[Vector]) -> (Vec<Vector>, Vec<Vector>) {
        let (kx, mz) =
            assembly
                .pattern
                .product_pair(&self.stiffness, &flat(x), &self.mass, &flat(z));
        let mut kx = vectors(&kx);
        for spring in assembly.grab_springs() {
            spring.add_gradient(spring.stiffness() * spring.value(x), &mut kx);
        }
        (kx, vectors(&mz))
    }

    /// `K u` plus the springs' pull at rest, and the energy
    /// `1/2 u.K u + f_rest.u + U_rest`.
    pub(super) fn forces(&self, assembly: &Assembly, u: &[Vector]) -> (Vec<Vector>, Real) {
        let mut f = self.apply(assembly, &self.stiffness, u, 1.0);
        let mut energy = self.rest_energy;
        for ((fk, uk), rk) in f.iter_mut().zip(u).zip(&self.rest) {
            energy += 0.5 * fk.dot(uk) + rk.dot(uk);
            *fk += rk;
        }
        (f, energy)
    }

    /// `(stiffness K + mass M) v`; a matrix whose scale is zero is not
    /// multiplied (most calls want `K` or `M` alone).
    pub(super) fn product(
        &self,
        assembly: &Assembly,
        v: &[Vector],
        stiffness: Real,
        mass: Real,
    ) -> Vec<Vector> {
        let mut out = vec![Vector::zeros(); v.len()];
        if stiffness != 0.0 {
            for (o, p) in out
                .iter_mut()
                .zip(self.apply(assembly, &self.stiffness, v, 1.0))
            {
                *o += stiffness * p;
            }
        }
        if mass != 0.0 {
            for (o, p) in out
                .iter_mut()
                .zip(multiply(&assembly.pattern, &self.mass, v))
            {
                *o += mass * p;
            }
        }
        out
    }

    /// Solves `(A + ks W D W^T) x = rhs` for the factored `A = ks K + ms
    /// M` and the grabs' springs `W D W^T`, by the Woodbury identity
    /// (see the module's comment); `None` for a singular system.
    fn solve(
        &mut self,
        solver: &mut SparseCholesky,
        assembly: &Assembly,
        rhs: &[Vector],
        stiffness: Real,
    ) -> Option<Vec<Vector>> {
        let pattern = &assembly.pattern;
        let mut solve = |b: &[Vector]| -> Option<Vec<Vector>> {
            Some(vectors(solver.solve_factored(pattern, scalars(b))?))
        };
        let mut y = solve(rhs)?;
        let springs = assembly.grab_springs();
        if springs.is_empty() {
            return Some(y);
        }
        if self.grabbed.is_none() {
            let n = rhs.len();
            let z: Vec<Vec<Vector>> = springs
                .iter()
                .map(|spring| {
                    let mut w = vec![Vector::zeros(); n];
                    spring.add_gradient(1.0, &mut w);
                    solve(&w)
                })
                .collect::<Option<_>>()?;
            let r = springs.len();
            let capacitance = DMatrix::from_fn(r, r, |a, b| {
                let diagonal = if a == b {
                    1.0 / (stiffness * springs[a].stiffness())
                } else {
                    0.0
                };
                diagonal + springs[a].value(&z[b])
            });
            self.grabbed = Some(Grabbed {
                z,
                capacitance: capacitance.cholesky()?,
            });
        }
        let grabbed = self.grabbed.as_ref()?;
        let t = DVector::from_iterator(springs.len(), springs.iter().map(|s| s.value(&y)));
        let s = grabbed.capacitance.solve(&t);
        for (zc, sc) in grabbed.z.iter().zip(s.iter()) {
            for (yk, zk) in y.iter_mut().zip(zc) {
                *yk -= *sc * zk;
            }
        }
        Some(y)
    }

    /// `stiffness K + mass M`, in the pattern's order: the matrix the
    /// step factorises.
    fn combined(&self, stiffness: Real, mass: Real) -> Vec<Real> {
        self.stiffness
            .iter()
            .zip(&self.mass)
            .map(|(k, m)| stiffness * k + mass * m)
            .collect()
    }
}

impl ShellDynamics {
    /// One step of the linear route: with `a1 = c_a du + a*` and
    /// `v1 = c_v du + v*`, the equation of motion is linear in `du`:
    ///
    /// ```text
    /// ((1 + beta c_v) K + (c_a + alpha c_v) M) du
    ///     = F - f_rest - K (u0 + beta v*) - M (a* + alpha v*)
    /// ```
    ///
    /// solved with the factor kept from the last step of this length.
    pub(super) fn step_linear(&mut self, cancel: &Cancel) -> Result<ShellStep, ShellError> {
        cancel.check().map_err(|_| ShellError::Cancelled)?;
        let p = self.params;
        let (c_a, c_v, a_star, v_star) = self.kinematics();
        let (ks, ms) = (1.0 + p.stiffness_damping * c_v, c_a + p.mass_damping * c_v);
        let pattern = &self.assembly.pattern;
        let Some(linear) = self.linear.as_mut() else {
            return Err(ShellError::Singular);
        };
        if linear.factored != Some((ks, ms)) {
            linear.factored = None;
            linear.grabbed = None;
            if !self.solver.factorize(pattern, &linear.combined(ks, ms)) {
                return Err(ShellError::Singular);
            }
            linear.factored = Some((ks, ms));
        }
        let u0 = &self.displacement;
        let at_stiffness: Vec<Vector> = u0
            .iter()
            .zip(&v_star)
            .map(|(u, v)| u + p.stiffness_damping * v)
            .collect();
        let at_mass: Vec<Vector> = a_star
            .iter()
            .zip(&v_star)
            .map(|(a, v)| a + p.mass_damping * v)
            .collect();
        let (mut k, m) = linear.pair(&self.assembly, &at_stiffness, &at_mass);
        for (fk, rk) in k.iter_mut().zip(&linear.rest) {
            *fk += rk;
        }
        let rhs: Vec<Vector> = self
            .load
            .iter()
            .zip(k.iter().zip(&m))
            .map(|(l, (k, m))| l - k - m)
            .collect();
        let du = linear
            .solve(&mut self.solver, &self.assembly, &rhs, ks)
            .ok_or(ShellError::Singular)?;
        // The solve's own residual, against the largest of the terms the
        // right-hand side sums (the load, the stiffness's and the
        // inertia's; the last carries the step's momentum): round-off,
        // unless the factor is bad.
        let (k_du, m_du) = linear.pair(&self.assembly, &du, &du);
        let misfit: Vec<Vector> = k_du
            .iter()
            .zip(&m_du)
            .zip(&rhs)
            .map(|((k, m), r)| ks * k + ms * m - r)
            .collect();
        let scale = norm(&rhs)
            .max(norm(&k))
            .max(norm(&m))
            .max(norm(&self.load))
            .max(Real::MIN_POSITIVE);
        let residual = norm(&misfit) / scale;
        // A NaN residual (a non-finite solve) fails too.
        if residual.is_nan() || residual > p.tolerance {
            return Err(ShellError::NotConverged {
                iterations: 1,
                residual,
            });
        }
        let u1 = u0.iter().zip(&du).map(|(u, d)| u + d).collect();
        let a1 = du.iter().zip(&a_star).map(|(d, a)| c_a * d + a).collect();
        let v1 = du.iter().zip(&v_star).map(|(d, v)| c_v * d + v).collect();
        self.displacement = u1;
        self.velocity = v1;
        self.acceleration = a1;
        self.time += p.dt;
        Ok(ShellStep {
            iterations: 1,
            residual,
        })
    }

    /// The integrator's `c_a`, `c_v`, `a*` and `v*` for the next step (see
    /// [`ShellDynamics::step`]).
    pub(super) fn kinematics(&self) -> (Real, Real, Vec<Vector>, Vec<Vector>) {
        let h = self.params.dt;
        let (v0, a0) = (&self.velocity, &self.acceleration);
        match self.params.integrator {
            Integrator::BackwardEuler => (
                1.0 / (h * h),
                1.0 / h,
                v0.iter().map(|v| -v / h).collect(),
                vec![Vector::zeros(); v0.len()],
            ),
            Integrator::Newmark => (
                4.0 / (h * h),
                2.0 / h,
                v0.iter().zip(a0).map(|(v, a)| -4.0 * v / h - a).collect(),
                v0.iter().map(|v| -v).collect(),
            ),
        }
    }
}
