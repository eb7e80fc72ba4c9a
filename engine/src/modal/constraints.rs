//! Manipulation constraints on the modal amplitudes (Guo & Qin Sec.
//! 5.3.3): `k` linear rows `C = A_c z - b_c = 0` (Eq. 32) - a position
//! constraint at a material point is the 3 rows `Phi(x_c) Psi`, an
//! orientation constraint the 3 rows `1/2 curl Phi(x_c) Psi`, which the
//! caller builds - enforced through Lagrange multipliers on the implicit
//! step, Eq. 33:
//! `[[A_z, A_c^T], [A_c, 0]] [dzdot; lambda h] = [b_z; r]`.
//!
//! `C = 0` is replaced by the damped `Cddot + 2 eta Cdot + gamma^2 C = 0`
//! (Baumgarte stabilisation, the paper's [20]). Eq. 33 writes its
//! discretisation at the start of the step, `r = h (-2 eta Cdot0 -
//! gamma^2 C0)`, which is explicit in the constraint error and diverges
//! unless `h gamma < 2` and `eta h < 1 - (h gamma)^2 / 4` (the
//! determinant of its 2x2 update is `1 - 2 eta h`). We evaluate the same
//! equation at the end of the step (`Cdot1 = Cdot0 + A_c dzdot`,
//! `C1 = C0 + h Cdot1`), which keeps the matrix of Eq. 33 and only
//! changes `r` to
//! `r = -h (2 eta Cdot0 + gamma^2 (C0 + h Cdot0)) / (1 + 2 eta h + h^2 gamma^2)`:
//! equal to Eq. 33's to first order in `h`, and stable for every
//! `eta, gamma >= 0`: its 2x2 update has determinant
//! `1 / (1 + 2 eta h + h^2 gamma^2) <= 1` and meets the Jury conditions
//! (large `gamma` projects `C` to 0 in one step, large `eta` freezes
//! `Cdot`; `eta = gamma` gives the double root `1 / (1 + gamma h)`). `Cdot = A_c zdot`: targets are treated as fixed
//! within a step, as in the paper.
//!
//! `A_z` is diagonal, so the system is solved through the `k x k` Schur
//! complement `S = A_c A_z^-1 A_c^T`:
//! `S mu = A_c A_z^-1 b_z - r`, `dzdot = A_z^-1 (b_z - A_c^T mu)`.
//! `S` is factored by Cholesky with diagonal pivoting, which also reveals
//! its rank: dependent rows (the same point grabbed twice, more rows than
//! modes) leave pivots at rounding level. Then `mu` is taken as a
//! least-squares solution: all of them differ by null vectors of `S`,
//! which are null vectors of `A_c^T`, so they apply the same force
//! `A_c^T mu`. Consistent duplicates act as one constraint; conflicting
//! ones meet halfway (their targets are met in the least-squares sense).

use nalgebra::{DMatrix, DVector};

use super::ModalError;
use super::basis::check_finite;
use crate::linalg::dense::{cholesky_in_place, cholesky_solve};
use crate::math::Real;

/// Most constraint rows accepted: Eq. 33 is solved densely (`O(k^2 l +
/// k^3)` per factorisation); the paper needs at most 20 (Sec. 5.3.3),
/// and 64 rows are 21 grabbed points - more handles than a user drags.
pub const MAX_CONSTRAINTS: usize = 64;

/// A pivot of the Schur complement below this fraction of its largest
/// diagonal counts as zero: the row is a combination of the rows pivoted
/// before it. Exact duplicates leave `~k eps`; two rows count as
/// dependent when they differ by less than about `sqrt(1e-10) = 1e-5`
/// in direction, where their multipliers would be ~1e10 anyway.
const RANK_TOLERANCE: Real = 1e-10;

/// The Baumgarte factors of `Cddot + 2 eta Cdot + gamma^2 C = 0`: `gamma`
/// (1/s) is the rate at which a violated constraint is pulled back,
/// `eta` (1/s) its damping (`eta = gamma` is critical).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stabilization {
    eta: Real,
    gamma: Real,
}

impl Stabilization {
    /// The factors `eta` and `gamma`.
    ///
    /// # Errors
    /// [`ModalError::Coefficient`] when one is negative or not finite.
    pub fn new(eta: Real, gamma: Real) -> Result<Self, ModalError> {
        for (name, value) in [("eta", eta), ("gamma", gamma)] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(ModalError::Coefficient { name, value });
            }
        }
        Ok(Self { eta, gamma })
    }

    /// The damping factor `eta`.
    pub fn eta(&self) -> Real {
        self.eta
    }

    /// The stiffness factor `gamma`.
    pub fn gamma(&self) -> Real {
        self.gamma
    }

    /// The constraint row of Eq. 33's right-hand side for one constraint
    /// of value `c` and rate `cdot`, evaluated at the end of the step
    /// (module comment).
    fn rate_change(&self, h: Real, c: Real, cdot: Real) -> Real {
        let g2 = self.gamma * self.gamma;
        -h * (2.0 * self.eta * cdot + g2 * (c + h * cdot)) / (1.0 + 2.0 * self.eta * h + h * h * g2)
    }
}

/// The rows, targets and factors of a constraint set, with the scratch
/// its solve needs (sized once, so a step allocates nothing).
#[derive(Debug, Clone)]
pub(super) struct ConstraintSet {
    /// `A_c^T`, `l x k`: column `i` is row `i` of `A_c`, contiguous.
    rows_t: DMatrix<Real>,
    /// `b_c`.
    targets: DVector<Real>,
    stabilization: Stabilization,
    /// `A_z^-1 A_c^T` for the factored step.
    scaled_t: DMatrix<Real>,
    /// `S`, then its pivoted Cholesky factor in the lower triangle (rows
    /// and columns in pivot order).
    factor: DMatrix<Real>,
    /// Pivot order: position `j` of the factor is constraint `perm[j]`.
    perm: Vec<usize>,
    /// Remaining pivots during the factorisation.
    pivots: Vec<Real>,
    /// Rank of `S`, once factored.
    rank: Option<usize>,
    /// The step the factor belongs to (`A_z` depends only on it).
    factored_for: Option<Real>,
    /// `L^T L` (row-major `rank x rank`, factored) when rank-deficient.
    gram: Vec<Real>,
    /// Right-hand side, then solution, in pivot order.
    work: DVector<Real>,
    /// The multipliers `mu = lambda h`, in constraint order.
    mu: DVector<Real>,
}

impl ConstraintSet {
    /// A set of the `k x l` rows `A_c` and the `k` targets `b_c`
    /// (Eq. 32).
    pub(super) fn new(
        rows: &DMatrix<Real>,
        targets: &DVector<Real>,
        stabilization: Stabilization,
        modes: usize,
    ) -> Result<Self, ModalError> {
        let k = rows.nrows();
        if k > MAX_CONSTRAINTS {
            return Err(ModalError::TooManyConstraints {
                got: k,
                max: MAX_CONSTRAINTS,
            });
        }
        if rows.ncols() != modes {
            return Err(ModalError::Shape {
                what: "constraint rows",
                expected_rows: k,
                expected_cols: modes,
                got_rows: k,
                got_cols: rows.ncols(),
            });
        }
        check_finite("constraint rows", rows)?;
        check_targets(targets, k)?;
        Ok(Self {
            rows_t: rows.transpose(),
            targets: targets.clone(),
            stabilization,
            scaled_t: DMatrix::zeros(modes, k),
            factor: DMatrix::zeros(k, k),
            perm: (0..k).collect(),
            pivots: vec![0.0; k],
            rank: None,
            factored_for: None,
            gram: vec![0.0; k * k],
            work: DVector::zeros(k),
            mu: DVector::zeros(k),
        })
    }

    /// Replaces the targets `b_c` (a dragged handle moves them every
    /// frame); the factor stays valid, it does not depend on them.
    pub(super) fn set_targets(&mut self, targets: &DVector<Real>) -> Result<(), ModalError> {
        check_targets(targets, self.targets.len())?;
        self.targets.copy_from(targets);
        Ok(())
    }

    /// The rank of `S` at the last factorisation.
    pub(super) fn rank(&self) -> Option<usize> {
        self.rank
    }

    /// `|A_c z - b_c|`, the Euclidean norm of the violation (Eq. 32).
    pub(super) fn violation(&self, z: &DVector<Real>) -> Real {
        self.rows_t
            .column_iter()
            .zip(self.targets.iter())
            .map(|(row, target)| (row.dot(z) - target).powi(2))
            .sum::<Real>()
            .sqrt()
    }

    /// `dzdot` of Eq. 33 for step `h`, with `a` the diagonal of `A_z`,
    /// `b` = `b_z` and the state `(z0, zdot0)` at the start of the step.
    pub(super) fn solve(
        &mut self,
        h: Real,
        a: &DVector<Real>,
        b: &DVector<Real>,
        (z0, zdot0): (&DVector<Real>, &DVector<Real>),
        dzdot: &mut DVector<Real>,
    ) {
        if self.factored_for != Some(h) {
            self.factorize(a);
            self.factored_for = Some(h);
        }
        // The unconstrained solution A_z^-1 b_z first.
        dzdot.copy_from(b);
        dzdot.component_div_assign(a);
        for (j, &i) in self.perm.iter().enumerate() {
            let row = self.rows_t.column(i);
            let c = row.dot(z0) - self.targets[i];
            let cdot = row.dot(zdot0);
            self.work[j] = row.dot(dzdot) - self.stabilization.rate_change(h, c, cdot);
        }
        self.solve_schur();
        dzdot.gemv(-1.0, &self.scaled_t, &self.mu, 1.0);
    }

    /// Builds `S = A_c A_z^-1 A_c^T` and factors it with diagonal
    /// pivoting; when rank-deficient, also factors the normal matrix
    /// `L^T L` of the least-squares solve.
    fn factorize(&mut self, a: &DVector<Real>) {
        self.scaled_t.copy_from(&self.rows_t);
        for (m, mut row) in self.scaled_t.row_iter_mut().enumerate() {
            row /= a[m];
        }
        self.factor.gemm_tr(1.0, &self.rows_t, &self.scaled_t, 0.0);
        let rank = pivoted_cholesky(&mut self.factor, &mut self.perm, &mut self.pivots);
        self.rank = Some(rank);
        if rank < self.perm.len() {
            let l = &self.factor;
            let k = l.nrows();
            for c in 0..rank {
                for d in 0..rank {
                    self.gram[c * rank + d] = (c.max(d)..k).map(|i| l[(i, c)] * l[(i, d)]).sum();
                }
            }
            cholesky_in_place(&mut self.gram[..rank * rank], rank);
        }
    }

    /// `mu` from `S mu = g` with `g` in `work` (pivot order), by the
    /// factor `P L L^T P^T` of `S`. Full rank: two triangular solves.
    /// Rank `r < k` (`L` is `k x r`): the least-squares `y = B^T mu` of
    /// `B y = g`, `B = P L`, from `(L^T L) y = L^T g`, then
    /// `mu = P [L1^-T y; 0]` with `L1` the leading `r x r` block.
    fn solve_schur(&mut self) {
        let l = &self.factor;
        let k = l.nrows();
        let r = self.rank.unwrap_or(0);
        let g = &mut self.work;
        if r == k {
            for i in 0..k {
                let v = g[i] - (0..i).map(|m| l[(i, m)] * g[m]).sum::<Real>();
                g[i] = v / l[(i, i)];
            }
        } else {
            // t = L^T g overwrites the leading r entries (t_c needs
            // g_i for i >= c only, so ascending c is safe).
            for c in 0..r {
                g[c] = (c..k).map(|i| l[(i, c)] * g[i]).sum();
            }
            cholesky_solve(&self.gram[..r * r], r, &mut g.as_mut_slice()[..r]);
            g.rows_mut(r, k - r).fill(0.0);
        }
        for i in (0..r).rev() {
            let v = g[i] - (i + 1..r).map(|m| l[(m, i)] * g[m]).sum::<Real>();
            g[i] = v / l[(i, i)];
        }
        for (j, &i) in self.perm.iter().enumerate() {
            self.mu[i] = g[j];
        }
    }
}

/// Lower Cholesky factor of the symmetric positive semi-definite `s` in
/// place with diagonal pivoting (largest remaining pivot first), so that
/// `P^T S P = L L^T` with `L` in the lower triangle of the first `rank`
/// columns; rows and columns of `s` are swapped as pivots are chosen and
/// `perm` records the order. Stops at the first pivot below
/// [`RANK_TOLERANCE`] times the largest diagonal and returns the rank.
fn pivoted_cholesky(s: &mut DMatrix<Real>, perm: &mut [usize], pivots: &mut [Real]) -> usize {
    let k = s.nrows();
    for (i, (p, d)) in perm.iter_mut().zip(pivots.iter_mut()).enumerate() {
        *p = i;
        *d = s[(i, i)];
    }
    let floor = RANK_TOLERANCE * pivots.iter().fold(0.0, |m: Real, &d| m.max(d));
    for j in 0..k {
        let p = (j..k).fold(j, |p, i| if pivots[i] > pivots[p] { i } else { p });
        if pivots[p] <= floor {
            return j;
        }
        if p != j {
            s.swap_rows(j, p);
            s.swap_columns(j, p);
            perm.swap(j, p);
            pivots.swap(j, p);
        }
        let d = pivots[j].sqrt();
        s[(j, j)] = d;
        for i in j + 1..k {
            let v = (s[(i, j)] - (0..j).map(|m| s[(i, m)] * s[(j, m)]).sum::<Real>()) / d;
            s[(i, j)] = v;
            pivots[i] -= v * v;
        }
    }
    k
}

/// Targets must be `k` finite values.
fn check_targets(targets: &DVector<Real>, k: usize) -> Result<(), ModalError> {
    if targets.len() != k {
        return Err(ModalError::Shape {
            what: "constraint targets",
            expected_rows: k,
            expected_cols: 1,
            got_rows: targets.len(),
            got_cols: 1,
        });
    }
    check_finite("constraint targets", targets)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vector;
    use crate::modal::fixtures::random_basis;
    use crate::modal::{Damping, ModalSystem};

    const H: Real = 1e-2;

    /// Five modes (two rigid) of four nodes under a constant load, warping
    /// off, with the 3 rows of a position constraint at a material point
    /// (`Phi(x_c) Psi` with shape-function values `phi`).
    fn grabbed() -> (ModalSystem, DMatrix<Real>, Vec<Vector>) {
        let (basis, psi) = random_basis(4, &[0.0, 0.0, 30.0, 80.0, 200.0], 21);
        let phi = [0.1, 0.4, 0.3, 0.2];
        let rows = DMatrix::from_fn(3, 5, |a, j| {
            (0..4).map(|i| phi[i] * psi[(3 * i + a, j)]).sum()
        });
        let system = ModalSystem::new(basis, Damping::new(0.1, 1e-3).expect("valid"), false);
        (system, rows, vec![Vector::new(0.0, -1.0, 0.5); 4])
    }

    fn target() -> DVector<Real> {
        DVector::from_column_slice(&[0.05, -0.02, 0.03])
    }

    fn constrain(
        system: &mut ModalSystem,
        rows: &DMatrix<Real>,
        b: &DVector<Real>,
        eta: Real,
        gamma: Real,
    ) {
        let stabilization = Stabilization::new(eta, gamma).expect("valid");
        system
            .set_constraints(rows, b, stabilization)
            .expect("valid constraints");
    }

    #[test]
    fn a_grabbed_point_reaches_its_target() {
        let (mut system, rows, loads) = grabbed();
        // eta = gamma: critically damped, C_n ~ n / (1 + gamma h)^n.
        constrain(&mut system, &rows, &target(), 20.0, 20.0);
        let start = system.constraint_violation();
        let mut reached = None;
        for step in 1..=200 {
            system.step(H, &loads).expect("valid step");
            let c = system.constraint_violation();
            match reached {
                None if c < 1e-6 * start => reached = Some(step),
                Some(_) => assert!(c < 1e-6 * start, "step {step}: |C| rose back to {c:e}"),
                None => {}
            }
        }
        let reached = reached.expect("the target within 200 steps");
        assert!(reached <= 120, "|C| < 1e-6 |C0| only after {reached} steps");
        assert_eq!(system.constraint_rank(), Some(3));
    }

    #[test]
    fn extreme_stabilisation_stays_bounded() {
        for (eta, gamma) in [(0.0, 0.0), (0.0, 1e8), (1e8, 0.0), (1e8, 1e8)] {
            let (mut system, rows, loads) = grabbed();
            constrain(&mut system, &rows, &target(), eta, gamma);
            let start = system.constraint_violation();
            for step in 0..300 {
                system.step(H, &loads).expect("valid step");
                let largest = system.amplitudes().amax().max(system.velocities().amax());
                assert!(
                    largest.is_finite() && largest < 1e3,
                    "eta {eta}, gamma {gamma}, step {step}: state reached {largest:e}"
                );
            }
            let end = system.constraint_violation();
            if gamma > 0.0 && eta < gamma * gamma * H {
                assert!(
                    end < 1e-9 * start,
                    "eta {eta}, gamma {gamma}: |C| {start} -> {end:e}"
                );
            } else {
                // From rest with no pull back, Cdot stays 0: C is held.
                assert!(
                    (end - start).abs() < 1e-6 * start,
                    "eta {eta}, gamma {gamma}: |C| {start} -> {end}"
                );
            }
        }
    }

    #[test]
    fn duplicated_constraints_act_as_one() {
        let (mut single, rows, loads) = grabbed();
        constrain(&mut single, &rows, &target(), 20.0, 20.0);
        let (mut double, _, _) = grabbed();
        let twice = DMatrix::from_fn(6, 5, |i, j| rows[(i % 3, j)]);
        let both = DVector::from_fn(6, |i, _| target()[i % 3]);
        constrain(&mut double, &twice, &both, 20.0, 20.0);
        for step in 0..50 {
            single.step(H, &loads).expect("valid step");
            double.step(H, &loads).expect("valid step");
            let gap = (single.amplitudes() - double.amplitudes()).norm();
            assert!(
                gap < 1e-10,
                "step {step}: duplicated constraints drift by {gap:e}"
            );
        }
        assert_eq!(double.constraint_rank(), Some(3));
    }

    #[test]
    fn conflicting_duplicates_meet_halfway() {
        let (mut system, rows, loads) = grabbed();
        let twice = DMatrix::from_fn(6, 5, |i, j| rows[(i % 3, j)]);
        let (d1, d2) = (target(), DVector::from_column_slice(&[-0.01, 0.04, 0.0]));
        let both = DVector::from_fn(6, |i, _| if i < 3 { d1[i] } else { d2[i - 3] });
        constrain(&mut system, &twice, &both, 20.0, 20.0);
        for _ in 0..200 {
            system.step(H, &loads).expect("valid step");
        }
        let reached = &rows * system.amplitudes();
        let mean = (&d1 + &d2) * 0.5;
        let error = (&reached - &mean).norm();
        assert!(
            error < 1e-6 * mean.norm(),
            "point at {reached:?}, mean target {mean:?}"
        );
        assert_eq!(system.constraint_rank(), Some(3));
    }

    #[test]
    fn dragging_the_target_needs_no_refactoring() {
        let (mut system, rows, loads) = grabbed();
        constrain(&mut system, &rows, &target(), 20.0, 20.0);
        let moved = DVector::from_column_slice(&[0.0, 0.1, -0.05]);
        for _ in 0..150 {
            system.step(H, &loads).expect("valid step");
        }
        system
            .set_constraint_targets(&moved)
            .expect("three targets");
        for _ in 0..150 {
            system.step(H, &loads).expect("valid step");
        }
        let error = (&rows * system.amplitudes() - &moved).norm();
        assert!(
            error < 1e-6 * moved.norm(),
            "dragged point misses by {error:e}"
        );
        assert!(matches!(
            system.set_constraint_targets(&DVector::zeros(2)),
            Err(ModalError::Shape { .. })
        ));
        system.clear_constraints();
        assert_eq!(
            system.set_constraint_targets(&moved),
            Err(ModalError::NoConstraints)
        );
    }

    #[test]
    fn too_many_or_malformed_constraints_are_refused() {
        let (mut system, rows, loads) = grabbed();
        constrain(&mut system, &rows, &target(), 20.0, 20.0);
        let k = MAX_CONSTRAINTS + 1;
        let many = DMatrix::from_fn(k, 5, |i, j| rows[(i % 3, j)]);
        let stabilization = Stabilization::new(1.0, 1.0).expect("valid");
        assert_eq!(
            system.set_constraints(&many, &DVector::zeros(k), stabilization),
            Err(ModalError::TooManyConstraints {
                got: k,
                max: MAX_CONSTRAINTS
            })
        );
        let narrow = DMatrix::zeros(3, 4);
        assert!(matches!(
            system.set_constraints(&narrow, &target(), stabilization),
            Err(ModalError::Shape {
                what: "constraint rows",
                ..
            })
        ));
        let mut nan = rows.clone();
        nan[(1, 2)] = Real::NAN;
        assert!(matches!(
            system.set_constraints(&nan, &target(), stabilization),
            Err(ModalError::NotFinite { row: 1, col: 2, .. })
        ));
        assert!(matches!(
            Stabilization::new(-1.0, 0.0),
            Err(ModalError::Coefficient { name: "eta", .. })
        ));
        assert!(matches!(
            Stabilization::new(0.0, Real::INFINITY),
            Err(ModalError::Coefficient { name: "gamma", .. })
        ));
        // The first set is still in force.
        system.step(H, &loads).expect("valid step");
        assert_eq!(system.constraint_rank(), Some(3));
    }

    #[test]
    fn the_end_of_step_stabilisation_agrees_with_eq_33_to_first_order() {
        let s = Stabilization::new(3.0, 7.0).expect("valid");
        let (c, cdot) = (0.4, -1.3);
        let paper = |h: Real| -h * (2.0 * s.eta() * cdot + s.gamma().powi(2) * c);
        let gap = |h: Real| (s.rate_change(h, c, cdot) - paper(h)).abs();
        for h in [1e-3, 1e-4] {
            let ratio = gap(h) / gap(0.5 * h);
            assert!(
                (ratio - 4.0).abs() < 0.1,
                "h = {h}: gap ratio {ratio} (second order is 4)"
            );
        }
    }
}
