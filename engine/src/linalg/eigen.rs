//! The lowest modes of the generalised symmetric eigenproblem
//! `K x = lambda M x`, the modal analysis of Guo–Qin Section 5.3.1: the
//! columns of their modal displacement matrix `Psi` are the `x`, the
//! diagonal of `Lambda` the `lambda`, for the stiffness `K` and mass `M`
//! of the Element-Free Galerkin discretisation (their Eq. 24).
//!
//! faer's partial eigensolver (Krylov–Schur) finds the eigenvalues of
//! largest magnitude of a symmetric operator, and the lowest modes are
//! the ones wanted, so the problem is shifted and inverted. With
//! `sigma > 0`, `K_s = K + sigma M` is positive definite even for a free
//! body (whose `K` has six zero eigenvalues); it is factorised once,
//! `K_s = G G^T` with `G = P^T L` (faer's sparse Cholesky, fill-reducing
//! permutation `P`), and the operator is
//!
//! `A = G^-1 M G^-T`,
//!
//! symmetric and congruent to `M`, hence positive definite, with
//! eigenvalues `mu = 1 / (lambda + sigma)`: the lowest `lambda` are its
//! largest `mu`. An eigenvector `y` of `A` gives `x = G^-T y / sqrt(mu)`,
//! already M-normalised (`x^T M x = y^T A y / mu = 1`) and M-orthogonal
//! to the others to rounding, since the Ritz vectors `y` are orthonormal.
//!
//! This transform rather than `C^T K_s^-1 C` with a factor `M = C C^T`:
//! it needs one factorisation instead of two (no simplicial factor of a
//! consistent `M` to force), applies `M` only as a product (the same code
//! for a lumped and a consistent mass), and costs per step two triangular
//! solves with `L` and one product with `M`, where the other costs two
//! with `L` and two with `M`'s factor.
//!
//! Everything runs with faer's global parallelism (factorisation, solves,
//! the Krylov basis); the product with a consistent `M` runs on one
//! thread.

use super::sparse::{BlockPattern, Factor, FactorError};
use crate::cancel::{Cancel, Cancelled};
use crate::math::Real;
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::linalg::{temp_mat_scratch, temp_mat_zeroed};
use faer::mat::AsMatMut;
use faer::matrix_free::LinOp;
use faer::matrix_free::eigen::{
    PartialEigenParams, partial_self_adjoint_eigen, partial_self_adjoint_eigen_scratch,
};
use faer::prelude::{Reborrow, ReborrowMut};
use faer::{Col, ColRef, Mat, MatMut, MatRef, Par, Side};

/// Smallest Krylov basis: faer's own floor (twice its 32-vector minimum
/// restart size). A problem no larger than the basis is solved densely,
/// which is then as cheap and exact, and which faer's Krylov–Schur does
/// not handle (it wants a basis smaller than the dimension).
const MIN_KRYLOV: usize = 64;

/// Krylov vectors per wanted mode. With two, Guo–Qin's 27 x 5 x 5 beam
/// clamped through a finely sampled face returned duplicated Ritz
/// vectors for 60 modes and never returned for 64: a square section
/// bends alike in y and z, so its modes come in near pairs, and with so
/// little room past the wanted ones faer's single-vector Krylov–Schur
/// lost one of a pair and its reorthogonalisation then spun on a vector
/// the basis already held. With three both counts return
/// (`efg::tests::the_table_1_beam_gives_its_paired_modes`).
const KRYLOV_PER_MODE: usize = 3;

/// Vectors in the Krylov basis that a search for `count` modes keeps: the
/// eigensolver's largest workspace besides the factor, which a memory
/// estimate made before the build counts.
pub fn basis_vectors(count: usize) -> usize {
    MIN_KRYLOV.max(KRYLOV_PER_MODE * count)
}

/// Power steps that estimate `||A||` for the tolerance: faer's tolerance
/// is absolute, on the operator's scale. A Rayleigh quotient after four
/// steps from a random start weighs each eigenvalue by its ninth power,
/// which is within a small factor of the largest, and never above it, so
/// the tolerance comes out at worst somewhat tighter than asked.
const POWER_STEPS: usize = 4;

/// An eigenvalue at or below this fraction of the mean eigenvalue
/// `trace(K) / trace(M)` is a zero (rigid-body) mode. Rounding leaves a
/// rigid mode near `n eps` times the largest eigenvalue, a few times the
/// mean, so about 1e-12 of it at the sizes meshless bodies have; the
/// lowest elastic mode of a 3D body of `n` degrees of freedom is about
/// `n^(-2/3)` of the mean, and of a slender beam such as Guo–Qin's (1,008
/// nodes, 63 along) still about 1e-6 of it. The threshold sits between,
/// three orders of magnitude from each.
const ZERO_MODE: Real = 1e-9;

/// The factor an operator's output is scaled by once the work is
/// cancelled: see [`ShiftInvert::apply`].
const VANISHING: Real = 1e-150;

/// The mass matrix `M` of `K x = lambda M x`.
#[derive(Debug, Clone, Copy)]
pub enum Mass<'a> {
    /// Consistent: values over the same [`BlockPattern`] as the stiffness
    /// (as [`BlockPattern::assemble`] writes them), symmetric positive
    /// definite.
    Consistent(&'a [Real]),
    /// Lumped: the diagonal, one positive entry per scalar degree of
    /// freedom.
    Lumped(&'a [Real]),
}

/// What [`lowest_modes`] computes and how accurately.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EigenParams {
    /// Modes wanted, the lowest first; from 1 to the dimension.
    pub count: usize,
    /// Relative accuracy: each mode's residual in the shifted and
    /// inverted problem, `||A y - mu y||`, at most this times `||A||`
    /// (faer's Krylov–Schur criterion, scaled). Eigenvalue errors go as
    /// its square; in `(0, 1)`.
    pub tolerance: Real,
    /// The shift `sigma` (positive; units of an eigenvalue), or `None`
    /// for `trace(K) / trace(M) / n`: that mean eigenvalue over the
    /// dimension `n` lies below the lowest elastic mode of a 3D body
    /// (about `n^(-2/3)` of the mean), so the lowest modes keep their
    /// separation after the inversion, while `K + sigma M` stays
    /// conditioned like `n` times the largest over the mean eigenvalue,
    /// far from what rounding would spoil. Set it for a body whose lowest
    /// modes are far below that (a very slender beam converges faster
    /// with `sigma` near its first mode).
    pub shift: Option<Real>,
}

impl Default for EigenParams {
    /// Guo–Qin's 64 modes, to `1e-10`, the shift from the matrices.
    fn default() -> Self {
        Self {
            count: 64,
            tolerance: 1e-10,
            shift: None,
        }
    }
}

/// The lowest modes of `K x = lambda M x`.
#[derive(Debug, Clone, PartialEq)]
pub struct Modes {
    /// The eigenvalues `lambda` (squared angular frequencies), ascending.
    /// Rigid-body modes come out at zero to rounding, either sign.
    pub eigenvalues: Vec<Real>,
    /// The mode shapes `x`, column-major: mode `j` is
    /// `vectors[j * n..(j + 1) * n]` for dimension `n`. M-orthonormal:
    /// `x_i^T M x_j = delta_ij`, so that modal amplitudes decouple
    /// (Guo–Qin Eq. 25).
    pub vectors: Vec<Real>,
    /// How many of the modes are zero (rigid-body) modes: eigenvalues at
    /// or below `1e-9` of the mean eigenvalue `trace(K) / trace(M)`. Six
    /// for a free body, none for a clamped one; the modal integration
    /// treats them apart (no stiffness, no oscillation).
    pub zero_modes: usize,
}

/// Why [`lowest_modes`] found no modes. Each says what to change.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EigenError {
    /// An input's length disagrees with the pattern.
    #[error("{what}: expected {expected} values for the pattern, got {got}")]
    Length {
        /// Which input.
        what: &'static str,
        /// What the pattern needs.
        expected: usize,
        /// Its length.
        got: usize,
    },
    /// No mode, or more than the problem has, was asked for.
    #[error(
        "asked for {count} modes of a problem with {size} degrees of freedom; ask for 1 to {size}"
    )]
    Count {
        /// Modes asked for.
        count: usize,
        /// The dimension.
        size: usize,
    },
    /// The tolerance is not a relative one.
    #[error("tolerance {0} is not in (0, 1); use a relative tolerance such as 1e-10")]
    Tolerance(Real),
    /// The shift is not positive and finite.
    #[error(
        "shift {0} is not positive and finite; leave it unset to have it chosen from the matrices"
    )]
    Shift(Real),
    /// An input holds a NaN or an infinity.
    #[error("{what}: value {index} is {value}; every value must be finite")]
    NotFinite {
        /// Which input.
        what: &'static str,
        /// Where in it.
        index: usize,
        /// The value.
        value: Real,
    },
    /// A lumped mass, or a diagonal entry of a consistent one, is not
    /// positive: `M` is not positive definite.
    #[error(
        "the mass at degree of freedom {dof} is {value}; every particle needs a positive mass \
         (check densities and quadrature weights)"
    )]
    MassNotPositive {
        /// The degree of freedom.
        dof: usize,
        /// Its mass (the diagonal entry).
        value: Real,
    },
    /// A consistent mass is not positive definite, though its diagonal
    /// is: a mode of `A` came out with `x^T M x <= 0`.
    #[error(
        "the consistent mass is not positive definite (a mode's M-norm squared is {0:e}); \
         check its assembly and quadrature, or lump it"
    )]
    MassIndefinite(Real),
    /// The stiffness has a negative diagonal entry, so it is not
    /// positive semi-definite.
    #[error(
        "the stiffness's diagonal at degree of freedom {dof} is {value}; a stiffness must be \
         positive semi-definite (check material constants and the assembly)"
    )]
    StiffnessDiagonal {
        /// The degree of freedom.
        dof: usize,
        /// The entry.
        value: Real,
    },
    /// The stiffness is zero: there is nothing to analyse.
    #[error("the stiffness is zero; assemble it before asking for its modes")]
    ZeroStiffness,
    /// `K + sigma M` did not factorise: `K` has an eigenvalue below
    /// `-sigma` or `M` is not positive definite.
    #[error(
        "K + {shift:e} M is not positive definite (its Cholesky factorisation failed at degree \
         of freedom {dof}): the stiffness is indefinite or the mass is not positive definite; \
         check their assembly"
    )]
    NotPositiveDefinite {
        /// The shift `sigma`.
        shift: Real,
        /// Where the factorisation failed (not necessarily the cause).
        dof: usize,
    },
    /// A mode came out clearly below zero: the stiffness is indefinite.
    #[error(
        "the stiffness has the negative eigenvalue {eigenvalue:e} (the mean eigenvalue is \
         {mean:e}); a stiffness must be positive semi-definite (check the assembly, the \
         quadrature and the material constants)"
    )]
    NegativeEigenvalue {
        /// The eigenvalue.
        eigenvalue: Real,
        /// The scale it is measured against, `trace(K) / trace(M)`.
        mean: Real,
    },
    /// Krylov–Schur ran out of restarts before every mode converged.
    #[error(
        "{converged} of {requested} modes converged to the tolerance {tolerance:e}; raise \
         `tolerance` or ask for fewer modes"
    )]
    NotConverged {
        /// Modes that converged.
        converged: usize,
        /// Modes asked for.
        requested: usize,
        /// The relative tolerance.
        tolerance: Real,
    },
    /// Memory for the factor or the Krylov basis could not be had.
    #[error(
        "out of memory for the factorisation or the Krylov basis; ask for fewer modes or use \
         fewer particles"
    )]
    OutOfMemory,
    /// The work was cancelled.
    #[error(transparent)]
    Cancelled(#[from] Cancelled),
}

/// The `params.count` lowest modes of `K x = lambda M x` (Guo–Qin
/// Section 5.3.1) for the `stiffness` `K` (values over `pattern`,
/// symmetric positive semi-definite) and the `mass` `M`: see the module
/// documentation for the method. `cancel` is read before and after each
/// large step and at every application of the operator; once raised, the
/// eigensolver finishes its current restart in a few cheap steps and
/// [`EigenError::Cancelled`] is returned. Runs with faer's global
/// parallelism.
///
/// # Errors
/// [`EigenError`] for inputs of the wrong length or not finite, a count
/// out of range, a tolerance or shift out of range, a mass not positive
/// definite, a stiffness not positive semi-definite, no convergence,
/// memory, or cancellation. Nothing panics on bad input.
pub fn lowest_modes(
    pattern: &BlockPattern,
    stiffness: &[Real],
    mass: Mass<'_>,
    params: &EigenParams,
    cancel: &Cancel,
) -> Result<Modes, EigenError> {
    let n = pattern.size();
    check(pattern, stiffness, mass, params)?;
    cancel.check()?;
    let diagonal: Vec<usize> = pattern.diagonal().collect();
    let trace_k: Real = diagonal.iter().map(|&i| stiffness[i]).sum();
    let trace_m: Real = match mass {
        Mass::Consistent(m) => diagonal.iter().map(|&i| m[i]).sum(),
        Mass::Lumped(d) => d.iter().sum(),
    };
    if trace_k == 0.0 {
        return Err(EigenError::ZeroStiffness);
    }
    let mean = trace_k / trace_m;
    let shift = params.shift.unwrap_or(mean / n as Real);
    if !(shift > 0.0 && shift.is_finite()) {
        return Err(EigenError::Shift(shift));
    }

    let mut shifted = Vec::new();
    shifted
        .try_reserve_exact(stiffness.len())
        .map_err(|_| EigenError::OutOfMemory)?;
    shifted.extend_from_slice(stiffness);
    match mass {
        Mass::Consistent(m) => {
            for (k, m) in shifted.iter_mut().zip(m) {
                *k += shift * m;
            }
        }
        Mass::Lumped(d) => {
            for (&i, d) in diagonal.iter().zip(d) {
                shifted[i] += shift * d;
            }
        }
    }
    let factor = pattern.factorize(&shifted).map_err(|e| match e {
        FactorError::NotPositiveDefinite { dof } => EigenError::NotPositiveDefinite { shift, dof },
        FactorError::OutOfMemory => EigenError::OutOfMemory,
    })?;
    drop(shifted);
    cancel.check()?;

    let op = ShiftInvert {
        pattern,
        factor: &factor,
        mass,
        cancel,
    };
    let par = faer::get_global_parallelism();
    let krylov_dim = basis_vectors(params.count);
    let (mu, y) = if n > krylov_dim {
        krylov(&op, params.count, krylov_dim, params.tolerance, par)?
    } else {
        dense(&op, params.count, par)?
    };
    cancel.check()?;
    modes(&op, &mu, y, shift, mean, params.tolerance, par)
}

/// The checks on the inputs that need no factorisation: lengths, ranges,
/// finiteness, and the diagonals (a positive semi-definite matrix has no
/// negative diagonal entry, a positive definite one no non-positive one).
fn check(
    pattern: &BlockPattern,
    stiffness: &[Real],
    mass: Mass<'_>,
    params: &EigenParams,
) -> Result<(), EigenError> {
    let n = pattern.size();
    let (mass_what, mass_values, mass_len) = match mass {
        Mass::Consistent(m) => ("consistent mass", m, pattern.nnz()),
        Mass::Lumped(d) => ("lumped mass", d, n),
    };
    for (what, got, expected) in [
        ("stiffness", stiffness.len(), pattern.nnz()),
        (mass_what, mass_values.len(), mass_len),
    ] {
        if got != expected {
            return Err(EigenError::Length {
                what,
                expected,
                got,
            });
        }
    }
    if params.count == 0 || params.count > n {
        return Err(EigenError::Count {
            count: params.count,
            size: n,
        });
    }
    if !(params.tolerance > 0.0 && params.tolerance < 1.0) {
        return Err(EigenError::Tolerance(params.tolerance));
    }
    if let Some(shift) = params.shift
        && !(shift > 0.0 && shift.is_finite())
    {
        return Err(EigenError::Shift(shift));
    }
    for (what, values) in [("stiffness", stiffness), (mass_what, mass_values)] {
        if let Some((index, &value)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(EigenError::NotFinite { what, index, value });
        }
    }
    for (dof, i) in pattern.diagonal().enumerate() {
        let value = match mass {
            Mass::Consistent(m) => m[i],
            Mass::Lumped(d) => d[dof],
        };
        if value <= 0.0 {
            return Err(EigenError::MassNotPositive { dof, value });
        }
        if stiffness[i] < 0.0 {
            return Err(EigenError::StiffnessDiagonal {
                dof,
                value: stiffness[i],
            });
        }
    }
    Ok(())
}

/// The shifted and inverted operator `A = G^-1 M G^-T`, with
/// `K + sigma M = G G^T`.
#[derive(Debug)]
struct ShiftInvert<'a> {
    pattern: &'a BlockPattern,
    factor: &'a Factor<'a>,
    mass: Mass<'a>,
    cancel: &'a Cancel,
}

impl ShiftInvert<'_> {
    /// `y = M x`.
    fn mass_times(&self, x: MatRef<'_, Real>, mut y: MatMut<'_, Real>) {
        match self.mass {
            Mass::Consistent(m) => self.pattern.multiply(m, x, y),
            Mass::Lumped(d) => {
                for j in 0..x.ncols() {
                    for (i, d) in d.iter().enumerate() {
                        y[(i, j)] = d * x[(i, j)];
                    }
                }
            }
        }
    }

    /// Scratch for one application to `ncols` columns.
    fn scratch(&self, ncols: usize, par: Par) -> StackReq {
        StackReq::all_of(&[
            temp_mat_scratch::<Real>(self.pattern.size(), ncols),
            self.factor.scratch(ncols, par),
        ])
    }
}

impl LinOp<Real> for ShiftInvert<'_> {
    fn apply_scratch(&self, rhs_ncols: usize, par: Par) -> StackReq {
        self.scratch(rhs_ncols, par)
    }

    fn nrows(&self) -> usize {
        self.pattern.size()
    }

    fn ncols(&self) -> usize {
        self.pattern.size()
    }

    /// `out = G^-1 M G^-T rhs`. Once cancelled, `out` is instead `rhs`
    /// times a vanishing diagonal, which costs nothing: faer offers no
    /// way out between restarts, but the Krylov–Schur residual of every
    /// Ritz pair is the norm of the last Lanczos vector, which then
    /// vanishes too, so faer locks everything at the end of its current
    /// restart and returns; the caller discards the result. The diagonal
    /// is distinct (`1 + i/n`) so that the Lanczos vectors never become
    /// exactly dependent, which faer's reorthogonalisation would not
    /// survive.
    fn apply(
        &self,
        mut out: MatMut<'_, Real>,
        rhs: MatRef<'_, Real>,
        par: Par,
        stack: &mut MemStack,
    ) {
        if self.cancel.is_cancelled() {
            let n = rhs.nrows() as Real;
            for j in 0..rhs.ncols() {
                for i in 0..rhs.nrows() {
                    out[(i, j)] = rhs[(i, j)] * (1.0 + i as Real / n) * VANISHING;
                }
            }
            return;
        }
        let (mut t, stack) = temp_mat_zeroed::<Real, _, _>(rhs.nrows(), rhs.ncols(), stack);
        let mut t = t.as_mat_mut();
        t.copy_from(rhs);
        self.factor.solve_gt(t.rb_mut(), par, stack);
        self.mass_times(t.rb(), out.rb_mut());
        self.factor.solve_g(out, par, stack);
    }

    /// The operator is real: its conjugate is itself.
    fn conj_apply(
        &self,
        out: MatMut<'_, Real>,
        rhs: MatRef<'_, Real>,
        par: Par,
        stack: &mut MemStack,
    ) {
        self.apply(out, rhs, par, stack);
    }
}

/// The `count` largest eigenvalues of `op` (descending) and their
/// orthonormal eigenvectors, by faer's Krylov–Schur with a basis of
/// `krylov_dim` vectors and a tolerance `tolerance` relative to an
/// estimate of `||op||`.
fn krylov(
    op: &ShiftInvert<'_>,
    count: usize,
    krylov_dim: usize,
    tolerance: Real,
    par: Par,
) -> Result<(Vec<Real>, Mat<Real>), EigenError> {
    let n = op.pattern.size();
    let params = PartialEigenParams {
        max_dim: krylov_dim,
        ..Default::default()
    };
    let mut memory = MemBuffer::try_new(StackReq::any_of(&[
        op.scratch(1, par),
        partial_self_adjoint_eigen_scratch(op, count, par, params),
    ]))
    .map_err(|_| EigenError::OutOfMemory)?;
    let stack = MemStack::new(&mut memory);
    let start = start_vector(n);
    let norm = norm_estimate(op, start.as_ref(), par, stack);
    op.cancel.check()?;
    let mut vectors = Mat::<Real>::zeros(n, count);
    let mut values = vec![0.0; count];
    let info = partial_self_adjoint_eigen(
        vectors.as_mut(),
        &mut values,
        op,
        start.as_ref(),
        tolerance * norm,
        par,
        stack,
        params,
    );
    op.cancel.check()?;
    if info.n_converged_eigen < count {
        return Err(EigenError::NotConverged {
            converged: info.n_converged_eigen,
            requested: count,
            tolerance,
        });
    }
    Ok((values, vectors))
}

/// An estimate of `||op||` from below: `||op v||` for the unit `v` that
/// [`POWER_STEPS`] power steps from `start` reach.
fn norm_estimate(
    op: &ShiftInvert<'_>,
    start: ColRef<'_, Real>,
    par: Par,
    stack: &mut MemStack,
) -> Real {
    let mut v = start.to_owned();
    let mut w = Col::<Real>::zeros(start.nrows());
    let mut norm = 0.0;
    for _ in 0..POWER_STEPS {
        let length = v.norm_l2();
        for x in v.iter_mut() {
            *x /= length;
        }
        op.apply(w.as_mat_mut(), v.as_mat(), par, stack);
        norm = w.norm_l2();
        std::mem::swap(&mut v, &mut w);
    }
    norm
}

/// The `count` largest eigenvalues of `op` (descending) and their
/// orthonormal eigenvectors, from the whole operator as a dense matrix:
/// for problems no larger than a Krylov basis.
fn dense(
    op: &ShiftInvert<'_>,
    count: usize,
    par: Par,
) -> Result<(Vec<Real>, Mat<Real>), EigenError> {
    let n = op.pattern.size();
    let mut memory = MemBuffer::try_new(op.scratch(n, par)).map_err(|_| EigenError::OutOfMemory)?;
    let mut a = Mat::<Real>::zeros(n, n);
    op.apply(
        a.as_mut(),
        Mat::<Real>::identity(n, n).as_ref(),
        par,
        MemStack::new(&mut memory),
    );
    op.cancel.check()?;
    // Rounding leaves `a` a little unsymmetric; the eigensolver reads one
    // triangle, so average the two.
    let a = Mat::<Real>::from_fn(n, n, |i, j| 0.5 * (a[(i, j)] + a[(j, i)]));
    let evd = a
        .self_adjoint_eigen(Side::Lower)
        .map_err(|_| EigenError::NotConverged {
            converged: 0,
            requested: count,
            tolerance: Real::EPSILON,
        })?;
    let (values, vectors) = (evd.S().column_vector(), evd.U());
    Ok((
        (0..count).map(|j| values[n - 1 - j]).collect(),
        Mat::from_fn(n, count, |i, j| vectors[(i, n - 1 - j)]),
    ))
}

/// The modes from the eigenpairs `(mu, y)` of `op`, `mu` descending:
/// `lambda = 1 / mu - sigma`, `x = G^-T y / sqrt(mu)`.
fn modes(
    op: &ShiftInvert<'_>,
    mu: &[Real],
    mut y: Mat<Real>,
    shift: Real,
    mean: Real,
    tolerance: Real,
    par: Par,
) -> Result<Modes, EigenError> {
    let count = mu.len();
    for (converged, &m) in mu.iter().enumerate() {
        if m <= 0.0 {
            return Err(EigenError::MassIndefinite(m));
        }
        // With finite inputs faer's results are finite; this keeps a NaN
        // from reaching the caller if that ever fails.
        if !(m.is_finite() && (1.0 / m).is_finite()) {
            return Err(EigenError::NotConverged {
                converged,
                requested: count,
                tolerance,
            });
        }
    }
    let mut memory =
        MemBuffer::try_new(op.factor.scratch(count, par)).map_err(|_| EigenError::OutOfMemory)?;
    op.factor
        .solve_gt(y.as_mut(), par, MemStack::new(&mut memory));
    for (j, &m) in mu.iter().enumerate() {
        let scale = m.sqrt().recip();
        for x in y.col_mut(j).iter_mut() {
            *x *= scale;
        }
    }
    // The vectors are M-orthonormal only to about the tolerance: a
    // locked Ritz vector's residual is not orthogonal to the vectors
    // found after it. One Cholesky QR in the M inner product,
    // `X <- X R^-1` with `X^T M X = R^T R`, brings that to rounding and
    // moves each vector by no more than its own error.
    let mut mx = Mat::<Real>::zeros(y.nrows(), count);
    op.mass_times(y.as_ref(), mx.as_mut());
    let gram = y.transpose() * &mx;
    let r = gram.llt(Side::Lower).map_err(|_| {
        EigenError::MassIndefinite(
            gram.diagonal()
                .column_vector()
                .iter()
                .copied()
                .fold(Real::INFINITY, Real::min),
        )
    })?;
    solve_lower_triangular_in_place(r.L(), y.as_mut().transpose_mut(), par);
    let eigenvalues: Vec<Real> = mu.iter().map(|m| m.recip() - shift).collect();
    if let Some(&eigenvalue) = eigenvalues.first()
        && eigenvalue < -ZERO_MODE * mean
    {
        return Err(EigenError::NegativeEigenvalue { eigenvalue, mean });
    }
    Ok(Modes {
        zero_modes: eigenvalues
            .iter()
            .take_while(|&&l| l <= ZERO_MODE * mean)
            .count(),
        vectors: (0..count).flat_map(|j| y.col(j).iter().copied()).collect(),
        eigenvalues,
    })
}

/// A pseudo-random start vector in `[-1, 1)^n` (SplitMix64, fixed seed):
/// random so that it has a component along every mode (a structured one
/// could be orthogonal to a symmetric structure's antisymmetric modes),
/// fixed so that runs are repeatable.
fn start_vector(n: usize) -> Col<Real> {
    let mut state: u64 = 0x9e37_79b9_7f4a_7c15;
    Col::from_fn(n, |_| {
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        (z >> 11) as Real / (1u64 << 52) as Real - 1.0
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector, Matrix3, SymmetricEigen, Vector3};

    /// Uniform numbers in `[0, 1)` from a seed, for the tests' geometry
    /// and weights.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> Real {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^= z >> 31;
            (z >> 11) as Real / (1u64 << 53) as Real
        }
    }

    /// One matrix by block columns: block column `n` holds `(m, block)`
    /// for its block rows `m >= n`.
    type Blocks = Vec<Vec<(u32, Matrix3<Real>)>>;

    /// A truss on a jittered grid of `nx x ny x nz` nodes (one 3x3 block
    /// each), every node joined by an axial spring to its up to 26
    /// neighbours: braced so, the truss is rigid, and its stiffness has
    /// exactly the six rigid-body modes as null space, unless the nodes
    /// of the bottom layer are `clamped` to the ground by isotropic
    /// springs. The jitter and random spring constants make the spectrum
    /// simple. The consistent mass gives each spring's two ends
    /// `w/3` and each other `w/6` (a bar's consistent mass), so it is
    /// positive definite with the pattern's off-diagonal blocks; the
    /// lumped mass is its row sums.
    struct Truss {
        pattern: BlockPattern,
        stiffness: Blocks,
        mass: Blocks,
        size: usize,
    }

    impl Truss {
        fn new(nx: usize, ny: usize, nz: usize, clamped: bool, seed: u64) -> Self {
            let mut rng = Rng(seed);
            let index = |x: usize, y: usize, z: usize| (x + nx * (y + ny * z)) as u32;
            let nodes = nx * ny * nz;
            let mut position = vec![Vector3::zeros(); nodes];
            for z in 0..nz {
                for y in 0..ny {
                    for x in 0..nx {
                        let jitter = Vector3::new(rng.next(), rng.next(), rng.next());
                        position[index(x, y, z) as usize] =
                            Vector3::new(x as Real, y as Real, z as Real) + 0.3 * jitter;
                    }
                }
            }
            let mut stiffness: Blocks = (0..nodes as u32)
                .map(|n| vec![(n, Matrix3::zeros())])
                .collect();
            let mut mass = stiffness.clone();
            for z in 0..nz {
                for y in 0..ny {
                    for x in 0..nx {
                        let a = index(x, y, z);
                        if clamped && z == 0 {
                            stiffness[a as usize][0].1 += Matrix3::identity() * (1.0 + rng.next());
                        }
                        for (dx, dy, dz) in (0..27).map(|k| (k % 3, k / 3 % 3, k / 9)) {
                            let (x2, y2, z2) = (x + dx, y + dy, z + dz);
                            if (dx, dy, dz) == (1, 1, 1)
                                || x2 == 0
                                || y2 == 0
                                || z2 == 0
                                || x2 > nx
                                || y2 > ny
                                || z2 > nz
                            {
                                continue;
                            }
                            let b = index(x2 - 1, y2 - 1, z2 - 1);
                            if b <= a {
                                continue;
                            }
                            let d = (position[b as usize] - position[a as usize]).normalize();
                            let k = (1.0 + rng.next()) * d * d.transpose();
                            let w = 1.0 + rng.next();
                            for (blocks, diagonal, off) in [
                                (&mut stiffness, k, -k),
                                (
                                    &mut mass,
                                    Matrix3::identity() * (w / 3.0),
                                    Matrix3::identity() * (w / 6.0),
                                ),
                            ] {
                                blocks[a as usize][0].1 += diagonal;
                                blocks[b as usize][0].1 += diagonal;
                                blocks[a as usize].push((b, off));
                            }
                        }
                    }
                }
            }
            for column in stiffness.iter_mut().chain(mass.iter_mut()) {
                column.sort_by_key(|&(m, _)| m);
            }
            let rows: Vec<Vec<u32>> = stiffness
                .iter()
                .map(|c| c.iter().map(|&(m, _)| m).collect())
                .collect();
            Self {
                pattern: BlockPattern::new(3, &rows).expect("pattern"),
                stiffness,
                mass,
                size: 3 * nodes,
            }
        }

        fn values(&self, blocks: &Blocks) -> Vec<Real> {
            let mut values = Vec::new();
            self.pattern.assemble(&mut values, |n, out| {
                for &(m, block) in &blocks[n] {
                    let slot = out.slot(m).expect("in the pattern");
                    for a in 0..3 {
                        for b in 0..3 {
                            out.add(slot, a, b, block[(b, a)]);
                        }
                    }
                }
            });
            values
        }

        fn dense(&self, blocks: &Blocks) -> DMatrix<Real> {
            let mut dense = DMatrix::zeros(self.size, self.size);
            for (n, column) in blocks.iter().enumerate() {
                for &(m, block) in column {
                    let m = m as usize;
                    dense.fixed_view_mut::<3, 3>(3 * m, 3 * n).copy_from(&block);
                    dense
                        .fixed_view_mut::<3, 3>(3 * n, 3 * m)
                        .copy_from(&block.transpose());
                }
            }
            dense
        }

        /// The lumped mass: the consistent one's row sums.
        fn lumped(&self) -> Vec<Real> {
            let mut sums = vec![0.0; self.size];
            for (n, column) in self.mass.iter().enumerate() {
                for &(m, block) in column {
                    let m = m as usize;
                    for (b, row) in block.row_iter().enumerate() {
                        sums[3 * m + b] += row.sum();
                    }
                    if m != n {
                        for (a, column) in block.column_iter().enumerate() {
                            sums[3 * n + a] += column.sum();
                        }
                    }
                }
            }
            sums
        }
    }

    /// All eigenvalues (ascending) and M-orthonormal eigenvectors of
    /// `K x = lambda M x`, densely: `L^-1 K L^-T z = lambda z` with
    /// `M = L L^T`, `x = L^-T z`.
    fn reference(k: &DMatrix<Real>, m: &DMatrix<Real>) -> (Vec<Real>, DMatrix<Real>) {
        let l = m.clone().cholesky().expect("M positive definite").l();
        let a = l.solve_lower_triangular(k).expect("invertible");
        let c = l
            .solve_lower_triangular(&a.transpose())
            .expect("invertible");
        let c = (&c + c.transpose()) * 0.5;
        let eigen = SymmetricEigen::new(c);
        let mut order: Vec<usize> = (0..k.nrows()).collect();
        order.sort_by(|&i, &j| eigen.eigenvalues[i].total_cmp(&eigen.eigenvalues[j]));
        let z = DMatrix::from_fn(k.nrows(), k.nrows(), |i, j| {
            eigen.eigenvectors[(i, order[j])]
        });
        let x = l
            .transpose()
            .solve_upper_triangular(&z)
            .expect("invertible");
        (order.iter().map(|&i| eigen.eigenvalues[i]).collect(), x)
    }

    fn mode(modes: &Modes, size: usize, j: usize) -> DMatrix<Real> {
        DMatrix::from_column_slice(size, 1, &modes.vectors[j * size..(j + 1) * size])
    }

    /// The largest deviation of `X^T M X` from the identity.
    fn m_orthonormality(modes: &Modes, m: &DMatrix<Real>) -> Real {
        let count = modes.eigenvalues.len();
        let x = DMatrix::from_column_slice(m.nrows(), count, &modes.vectors);
        let gram = x.transpose() * m * x;
        (gram - DMatrix::identity(count, count)).abs().max()
    }

    /// Checks `modes` against the dense reference: eigenvalues to `1e-9`
    /// relative (absolute `1e-9` times the largest for the first `zero`
    /// ones, rigid modes), vectors (past `zero`) parallel to the
    /// reference's in the M inner product, residuals `K x - lambda M x`
    /// small beside `K x`, and M-orthonormality to `1e-10`.
    fn compare(modes: &Modes, k: &DMatrix<Real>, m: &DMatrix<Real>, zero: usize, what: &str) {
        let (values, vectors) = reference(k, m);
        let count = modes.eigenvalues.len();
        let largest = modes.eigenvalues[count - 1];
        assert!(
            modes.eigenvalues.is_sorted(),
            "{what}: not ascending: {:?}",
            modes.eigenvalues
        );
        for (j, (&got, &want)) in modes.eigenvalues.iter().zip(&values).enumerate() {
            let x = mode(modes, k.nrows(), j);
            let kx = k * &x;
            let residual = (&kx - m * &x * got).norm();
            if j < zero {
                assert!(
                    got.abs() <= 1e-12 * largest,
                    "{what}: rigid mode {j} at {got:e}, largest {largest:e}"
                );
                assert!(
                    kx.norm() <= 1e-10 * largest * (m * &x).norm(),
                    "{what}: rigid mode {j} has energy: |K x| = {:e}",
                    kx.norm()
                );
                continue;
            }
            assert!(
                (got - want).abs() <= 1e-9 * want,
                "{what}: eigenvalue {j}: {got:e}, reference {want:e}"
            );
            let overlap = (x.transpose() * m * vectors.column(j))[(0, 0)].abs();
            assert!(
                (overlap - 1.0).abs() <= 1e-7,
                "{what}: mode {j}: |x^T M x_ref| = {overlap}"
            );
            assert!(
                residual <= 1e-7 * kx.norm(),
                "{what}: mode {j}: |K x - lambda M x| = {residual:e}, |K x| = {:e}",
                kx.norm()
            );
        }
        let deviation = m_orthonormality(modes, m);
        assert!(deviation <= 1e-10, "{what}: |X^T M X - I| = {deviation:e}");
    }

    fn solve(truss: &Truss, mass: &[Real], lumped: bool, count: usize) -> Modes {
        let stiffness = truss.values(&truss.stiffness);
        let mass = if lumped {
            Mass::Lumped(mass)
        } else {
            Mass::Consistent(mass)
        };
        let params = EigenParams {
            count,
            ..Default::default()
        };
        lowest_modes(&truss.pattern, &stiffness, mass, &params, &Cancel::new()).expect("modes")
    }

    /// Both masses of a truss as the solver takes them and as dense
    /// matrices: `(values, dense, lumped)` for each.
    fn masses(truss: &Truss) -> [(Vec<Real>, DMatrix<Real>, bool); 2] {
        let lumped = truss.lumped();
        [
            (truss.values(&truss.mass), truss.dense(&truss.mass), false),
            (
                lumped.clone(),
                DMatrix::from_diagonal(&DVector::from_vec(lumped)),
                true,
            ),
        ]
    }

    #[test]
    fn a_clamped_truss_has_the_dense_reference_modes() {
        // 144 degrees of freedom, above the Krylov basis: faer's
        // Krylov–Schur on the shifted and inverted operator.
        let truss = Truss::new(4, 4, 3, true, 1);
        let k = truss.dense(&truss.stiffness);
        for (values, m, lumped) in masses(&truss) {
            let modes = solve(&truss, &values, lumped, 10);
            assert_eq!(modes.zero_modes, 0, "clamped: no rigid mode");
            compare(
                &modes,
                &k,
                &m,
                0,
                if lumped { "lumped" } else { "consistent" },
            );
        }
    }

    #[test]
    fn a_free_truss_has_six_zero_modes_then_the_reference_ones() {
        // Free: K has the six rigid-body modes as null space; K + sigma M
        // is still positive definite, and its six largest inverted
        // eigenvalues 1 / sigma give them back at zero.
        let truss = Truss::new(4, 3, 3, false, 2);
        let k = truss.dense(&truss.stiffness);
        for (values, m, lumped) in masses(&truss) {
            let modes = solve(&truss, &values, lumped, 14);
            let what = if lumped {
                "free, lumped"
            } else {
                "free, consistent"
            };
            assert_eq!(modes.zero_modes, 6, "{what}: {:?}", modes.eigenvalues);
            compare(&modes, &k, &m, 6, what);
        }
    }

    #[test]
    fn a_problem_within_one_krylov_basis_is_solved_densely() {
        // 48 degrees of freedom, no more than the 64-vector basis: every
        // mode at once, then a few.
        let truss = Truss::new(2, 2, 4, true, 3);
        let k = truss.dense(&truss.stiffness);
        for (values, m, lumped) in masses(&truss) {
            for count in [48, 5] {
                let modes = solve(&truss, &values, lumped, count);
                compare(&modes, &k, &m, 0, &format!("dense, {count} modes"));
            }
        }
    }

    #[test]
    fn many_modes_are_m_orthonormal() {
        // 30 of 180 modes of a free truss: the Ritz vectors come from
        // many restarts, and rigid and elastic modes mix in one basis.
        let truss = Truss::new(5, 4, 3, false, 4);
        for (values, m, lumped) in masses(&truss) {
            let modes = solve(&truss, &values, lumped, 30);
            let deviation = m_orthonormality(&modes, &m);
            assert!(
                deviation <= 1e-10,
                "lumped {lumped}: |X^T M X - I| = {deviation:e}"
            );
            assert_eq!(modes.zero_modes, 6);
        }
    }

    #[test]
    fn bad_inputs_are_clear_errors() {
        let truss = Truss::new(2, 2, 2, true, 5);
        let n = truss.size;
        let stiffness = truss.values(&truss.stiffness);
        let lumped = truss.lumped();
        let run = |k: &[Real], mass: Mass<'_>, count: usize| {
            let params = EigenParams {
                count,
                ..Default::default()
            };
            lowest_modes(&truss.pattern, k, mass, &params, &Cancel::new())
        };
        assert_eq!(
            run(&stiffness, Mass::Lumped(&lumped), n + 1),
            Err(EigenError::Count {
                count: n + 1,
                size: n
            })
        );
        assert_eq!(
            run(&stiffness, Mass::Lumped(&lumped), 0),
            Err(EigenError::Count { count: 0, size: n })
        );
        assert_eq!(
            run(&stiffness[1..], Mass::Lumped(&lumped), 3),
            Err(EigenError::Length {
                what: "stiffness",
                expected: stiffness.len(),
                got: stiffness.len() - 1
            })
        );
        assert_eq!(
            run(&stiffness, Mass::Consistent(&lumped), 3),
            Err(EigenError::Length {
                what: "consistent mass",
                expected: stiffness.len(),
                got: n
            })
        );
        let mut bad = lumped.clone();
        bad[4] = 0.0;
        assert_eq!(
            run(&stiffness, Mass::Lumped(&bad), 3),
            Err(EigenError::MassNotPositive { dof: 4, value: 0.0 })
        );
        bad[4] = -1.0;
        assert_eq!(
            run(&stiffness, Mass::Lumped(&bad), 3),
            Err(EigenError::MassNotPositive {
                dof: 4,
                value: -1.0
            })
        );
        bad[4] = Real::NAN;
        assert!(matches!(
            run(&stiffness, Mass::Lumped(&bad), 3),
            Err(EigenError::NotFinite {
                what: "lumped mass",
                index: 4,
                ..
            })
        ));
        // Indefinite with a positive diagonal: K - c M for c between its
        // two lowest eigenvalues. With the default (small) shift,
        // K + sigma M is indefinite too and does not factorise.
        let m = truss.dense(&truss.mass);
        let (values, _) = reference(&truss.dense(&truss.stiffness), &m);
        let between = 0.5 * (values[0] + values[1]);
        let consistent = truss.values(&truss.mass);
        let indefinite: Vec<Real> = stiffness
            .iter()
            .zip(&consistent)
            .map(|(k, m)| k - between * m)
            .collect();
        match run(&indefinite, Mass::Consistent(&consistent), 3) {
            Err(EigenError::NotPositiveDefinite { .. } | EigenError::NegativeEigenvalue { .. }) => {
            }
            other => panic!("an indefinite K gave {other:?}"),
        }
        // With a shift that makes K + sigma M positive definite again, the
        // negative mode is found and refused.
        let params = EigenParams {
            count: 3,
            shift: Some(2.0 * between),
            ..Default::default()
        };
        match lowest_modes(
            &truss.pattern,
            &indefinite,
            Mass::Consistent(&consistent),
            &params,
            &Cancel::new(),
        ) {
            Err(EigenError::NegativeEigenvalue { eigenvalue, .. }) => {
                assert!(
                    (eigenvalue + (between - values[0])).abs() <= 1e-8 * between,
                    "{eigenvalue:e} != {:e}",
                    values[0] - between
                );
            }
            other => panic!("an indefinite K with a large shift gave {other:?}"),
        }
        let mut negative = stiffness.clone();
        let first = truss.pattern.diagonal().nth(5).expect("a diagonal");
        negative[first] = -1.0;
        assert_eq!(
            run(&negative, Mass::Lumped(&lumped), 3),
            Err(EigenError::StiffnessDiagonal {
                dof: 5,
                value: -1.0
            })
        );
        for tolerance in [0.0, 1.0, Real::NAN] {
            let params = EigenParams {
                count: 3,
                tolerance,
                ..Default::default()
            };
            assert!(matches!(
                lowest_modes(
                    &truss.pattern,
                    &stiffness,
                    Mass::Lumped(&lumped),
                    &params,
                    &Cancel::new()
                ),
                Err(EigenError::Tolerance(_))
            ));
        }
        let zero = vec![0.0; stiffness.len()];
        assert_eq!(
            run(&zero, Mass::Lumped(&lumped), 3),
            Err(EigenError::ZeroStiffness)
        );
    }

    #[test]
    fn a_raised_cancel_stops_the_work() {
        let truss = Truss::new(4, 4, 3, true, 6);
        let stiffness = truss.values(&truss.stiffness);
        let lumped = truss.lumped();
        let cancel = Cancel::new();
        cancel.cancel();
        let params = EigenParams {
            count: 10,
            ..Default::default()
        };
        assert_eq!(
            lowest_modes(
                &truss.pattern,
                &stiffness,
                Mass::Lumped(&lumped),
                &params,
                &cancel
            ),
            Err(EigenError::Cancelled(Cancelled))
        );
        // Raised inside Krylov–Schur: the operator vanishes, and faer
        // locks every Ritz pair at the end of the restart instead of
        // running out of restarts, so it returns at once; `krylov` then
        // refuses the result.
        let factor = truss
            .pattern
            .factorize(&stiffness)
            .expect("clamped: definite");
        let cancel = Cancel::new();
        let op = ShiftInvert {
            pattern: &truss.pattern,
            factor: &factor,
            mass: Mass::Lumped(&lumped),
            cancel: &cancel,
        };
        let par = faer::get_global_parallelism();
        let (count, n) = (10, truss.size);
        let params = PartialEigenParams {
            max_dim: MIN_KRYLOV,
            ..Default::default()
        };
        let mut memory = MemBuffer::new(StackReq::any_of(&[
            op.scratch(1, par),
            partial_self_adjoint_eigen_scratch(&op, count, par, params),
        ]));
        let stack = MemStack::new(&mut memory);
        let start = start_vector(n);
        let norm = norm_estimate(&op, start.as_ref(), par, stack);
        cancel.cancel();
        let mut vectors = Mat::<Real>::zeros(n, count);
        let mut values = vec![0.0; count];
        let info = partial_self_adjoint_eigen(
            vectors.as_mut(),
            &mut values,
            &op,
            start.as_ref(),
            1e-10 * norm,
            par,
            stack,
            params,
        );
        assert_eq!(info.n_converged_eigen, count, "faer ran out of restarts");
        assert_eq!(
            krylov(&op, count, MIN_KRYLOV, 1e-10, par).map(|_| ()),
            Err(EigenError::Cancelled(Cancelled))
        );
    }
}
