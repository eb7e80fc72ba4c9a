//! One reduced body: its basis, modal state `(z, zdot)`, Rayleigh
//! damping, warping switch and manipulation constraints, stepped by the
//! implicit modal integrator (Eq. 31, or Eq. 33 when constrained) with
//! warped or linear loads (Eq. 30 / 25). The per-node rotations and
//! displacements are kept for the current state, computed once whenever
//! it changes. All per-step buffers are sized at construction (and by
//! [`ModalSystem::set_constraints`]), so a step allocates nothing; a
//! refused step leaves the state as it was.

use nalgebra::{DMatrix, DVector};

use super::basis::check_finite;
use super::constraints::ConstraintSet;
use super::integrate::{Damping, assemble};
use super::warp::NodeFrames;
use super::{ModalBasis, ModalError, Stabilization};
use crate::math::{Real, Vector};

/// A body simulated in a modal basis, with modal warping on or off.
#[derive(Debug, Clone)]
pub struct ModalSystem {
    basis: ModalBasis,
    damping: Damping,
    warping: bool,
    z: DVector<Real>,
    zdot: DVector<Real>,
    constraints: Option<ConstraintSet>,
    /// `F_z` of the last step.
    force: DVector<Real>,
    /// Diagonal of `A_z`.
    a: DVector<Real>,
    /// `b_z`.
    b: DVector<Real>,
    dzdot: DVector<Real>,
    /// The nodes' rotations and displacements at `z`.
    frames: NodeFrames,
}

impl ModalSystem {
    /// A body at rest (`z = zdot = 0`) in `basis`. With `warping` the
    /// modal-warping path (Eq. 26-30) is used, without it the linear
    /// modal model (Eq. 25), so that the two can be compared.
    pub fn new(basis: ModalBasis, damping: Damping, warping: bool) -> Self {
        let l = basis.mode_count();
        let frames = NodeFrames::new(&basis);
        Self {
            basis,
            damping,
            warping,
            z: DVector::zeros(l),
            zdot: DVector::zeros(l),
            constraints: None,
            force: DVector::zeros(l),
            a: DVector::zeros(l),
            b: DVector::zeros(l),
            dzdot: DVector::zeros(l),
            frames,
        }
    }

    /// The basis.
    pub fn basis(&self) -> &ModalBasis {
        &self.basis
    }

    /// The damping.
    pub fn damping(&self) -> Damping {
        self.damping
    }

    /// Whether modal warping is on.
    pub fn warping(&self) -> bool {
        self.warping
    }

    /// Turns modal warping on or off (takes effect from the next step and
    /// the next displacement query).
    pub fn set_warping(&mut self, warping: bool) {
        self.warping = warping;
        self.frames.update(&self.basis, &self.z, warping);
    }

    /// The modal amplitudes `z`.
    pub fn amplitudes(&self) -> &DVector<Real> {
        &self.z
    }

    /// The modal velocities `zdot`.
    pub fn velocities(&self) -> &DVector<Real> {
        &self.zdot
    }

    /// The modal force `F_z` the last step used (Eq. 30's right-hand
    /// side, or Eq. 25's when not warping); zero before the first step.
    pub fn modal_force(&self) -> &DVector<Real> {
        &self.force
    }

    /// Sets the modal state (a restart, or an initial deformation).
    ///
    /// # Errors
    /// [`ModalError`] when a vector is not of length l or not finite; the
    /// state is then unchanged.
    pub fn set_state(&mut self, z: &DVector<Real>, zdot: &DVector<Real>) -> Result<(), ModalError> {
        let l = self.basis.mode_count();
        for (what, v) in [("z", z), ("zdot", zdot)] {
            if v.len() != l {
                return Err(ModalError::Shape {
                    what,
                    expected_rows: l,
                    expected_cols: 1,
                    got_rows: v.len(),
                    got_cols: 1,
                });
            }
            check_finite(what, v)?;
        }
        self.z.copy_from(z);
        self.zdot.copy_from(zdot);
        self.frames.update(&self.basis, &self.z, self.warping);
        Ok(())
    }

    /// Sets the manipulation constraints `A_c z = b_c` (Eq. 32): `rows`
    /// is `k x l` (at most [`super::MAX_CONSTRAINTS`] rows; 0 rows clears
    /// them), `targets` has length k. Dependent rows are accepted and
    /// met in the least-squares sense (see [`Self::constraint_rank`]).
    ///
    /// # Errors
    /// [`ModalError`] when the sizes disagree, an entry is not finite or
    /// there are too many rows; the previous constraints then remain.
    pub fn set_constraints(
        &mut self,
        rows: &DMatrix<Real>,
        targets: &DVector<Real>,
        stabilization: Stabilization,
    ) -> Result<(), ModalError> {
        let set = ConstraintSet::new(rows, targets, stabilization, self.basis.mode_count())?;
        self.constraints = (rows.nrows() > 0).then_some(set);
        Ok(())
    }

    /// Moves the targets `b_c` of the constraints (a dragged handle),
    /// without refactoring.
    ///
    /// # Errors
    /// [`ModalError::NoConstraints`] when none are set, or a shape or
    /// finiteness error; the targets are then unchanged.
    pub fn set_constraint_targets(&mut self, targets: &DVector<Real>) -> Result<(), ModalError> {
        self.constraints
            .as_mut()
            .ok_or(ModalError::NoConstraints)?
            .set_targets(targets)
    }

    /// Removes every constraint.
    pub fn clear_constraints(&mut self) {
        self.constraints = None;
    }

    /// `|A_c z - b_c|` at the current state; 0 without constraints.
    pub fn constraint_violation(&self) -> Real {
        self.constraints
            .as_ref()
            .map_or(0.0, |c| c.violation(&self.z))
    }

    /// The rank of the constraint rows' Schur complement at the last
    /// step: below the row count when rows are dependent (then met in
    /// the least-squares sense). `None` without constraints or before
    /// the first constrained step.
    pub fn constraint_rank(&self) -> Option<usize> {
        self.constraints.as_ref().and_then(ConstraintSet::rank)
    }

    /// Advances the state by `h` under the nodal loads (one force per
    /// node, world frame): modal force at the current amplitudes
    /// (Eq. 30 / 25), then the implicit step Eq. 31, constrained by
    /// Eq. 33 when constraints are set; `zdot1 = zdot0 + dzdot`,
    /// `z1 = z0 + h zdot1`.
    ///
    /// # Errors
    /// [`ModalError`] when `h` is not positive and finite, the loads are
    /// not one finite vector per node, or the result overflows; the
    /// state is then unchanged.
    pub fn step(&mut self, h: Real, nodal_loads: &[Vector]) -> Result<(), ModalError> {
        if !(h.is_finite() && h > 0.0) {
            return Err(ModalError::TimeStep { h });
        }
        let n = self.basis.node_count();
        if nodal_loads.len() != n {
            return Err(ModalError::LoadCount {
                expected: n,
                got: nodal_loads.len(),
            });
        }
        if let Some(node) = nodal_loads
            .iter()
            .position(|f| !f.iter().all(|v| v.is_finite()))
        {
            return Err(ModalError::LoadNotFinite { node });
        }
        self.frames
            .modal_force(&self.basis, nodal_loads, &mut self.force);
        let state = (&self.z, &self.zdot);
        assemble(
            h,
            self.basis.eigenvalues(),
            self.damping,
            &self.force,
            state,
            &mut self.a,
            &mut self.b,
        );
        match &mut self.constraints {
            Some(c) => c.solve(h, &self.a, &self.b, state, &mut self.dzdot),
            None => {
                self.dzdot.copy_from(&self.b);
                self.dzdot.component_div_assign(&self.a);
            }
        }
        let finite = (0..self.z.len()).all(|j| {
            let v = self.zdot[j] + self.dzdot[j];
            v.is_finite() && (self.z[j] + h * v).is_finite()
        });
        if !finite {
            return Err(ModalError::Overflow);
        }
        self.zdot += &self.dzdot;
        self.z.axpy(h, &self.zdot, 1.0);
        self.frames.update(&self.basis, &self.z, self.warping);
        Ok(())
    }

    /// The nodal displacements at the current state (one per node):
    /// warped `(int_0^1 R(s w_I) ds) Psi_I z` when warping is on (Choi &
    /// Ko 2005), linear `Psi_I z` when off.
    pub fn displacements(&self) -> &[Vector] {
        self.frames.displacements()
    }

    /// The linear displacements `u^L = Psi z` at the current state, `3n`
    /// values (`3I + a` is component `a` of node `I`), whether or not
    /// warping is on.
    pub fn linear_displacements(&self) -> &[Real] {
        self.frames.linear()
    }

    /// Node `node`'s velocity at the current state: with warping on,
    /// `R(w_I) Psi_I zdot`, the local frame's velocity turned with the
    /// frame (Choi & Ko's kinematics, `du = R(w) du^L`, of which the warped
    /// displacement is the integral along the straight path); `Psi_I zdot`
    /// with it off. Leaving the local velocity unturned while warping is
    /// wrong by `|R(w_I) - I| ~ |w_I|`: first order in the rotation (a
    /// spinning body's frames showed its velocity at the rest pose).
    ///
    /// # Panics
    /// When `node >= n`.
    pub fn node_velocity(&self, node: usize) -> Vector {
        self.frames.rotation(node) * self.basis.linear_displacement(node, &self.zdot)
    }

    /// Node `node`'s rotation vector `w_I = W_I z` at the current state.
    ///
    /// # Panics
    /// When `node >= n`.
    pub fn rotation_vector(&self, node: usize) -> Vector {
        self.frames.rotation_vector(node)
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Rotation3;

    use super::*;
    use crate::modal::fixtures::{flatten, points, random_basis, rotation_basis};

    #[test]
    fn a_rigid_rotation_field_warps_to_an_exact_rotation() {
        let positions = points(40, 3);
        let (basis, _) = rotation_basis(&positions);
        let w = Vector::new(0.2, -0.5, 0.7).normalize(); // 1 rad
        let mut system = ModalSystem::new(basis, Damping::new(0.0, 0.0).expect("valid"), true);
        system
            .set_state(
                &DVector::from_column_slice(w.as_slice()),
                &DVector::zeros(3),
            )
            .expect("valid");
        let warped = system.displacements().to_vec();
        system.set_warping(false);
        let linear = system.displacements();
        let rotation = Rotation3::new(w);
        for (i, x) in positions.iter().enumerate() {
            assert_eq!(system.rotation_vector(i), w, "node {i}'s rotation vector");
            let moved = x + warped[i];
            let error = (moved - rotation * x).norm();
            assert!(error < 1e-12, "node {i}: |x + u - R x| = {error:e}");
            let stretch = moved.norm() - x.norm();
            assert!(
                stretch.abs() < 1e-12,
                "node {i}: warped length changed by {stretch:e}"
            );
            // u^L = w x x: |x + u^L|^2 = |x|^2 + |w x x|^2.
            let linear_stretch = (x + linear[i]).norm() - x.norm();
            let off_axis = w.cross(x).norm();
            assert!(
                linear_stretch > 0.3 * off_axis * off_axis / x.norm(),
                "node {i}: linear length grew by only {linear_stretch:e} (off axis {off_axis})"
            );
        }
    }

    #[test]
    fn without_rotation_the_warped_force_is_the_linear_one() {
        // 1100 nodes: five parallel chunks, the last one partial.
        let n = 1100;
        let (basis, psi) = random_basis(n, &[0.0, 1.0, 4.0, 9.0], 8);
        let loads = points(n, 9);
        let reference = psi.tr_mul(&flatten(&loads));
        let mut system = ModalSystem::new(basis, Damping::new(0.1, 0.0).expect("valid"), true);
        system.step(1e-3, &loads).expect("valid step");
        let error = (system.modal_force() - &reference).norm() / reference.norm();
        assert!(error < 1e-12, "warped force at w = 0 differs by {error:e}");
        // The step moved z, so the nodal displacements are Psi z.
        system.set_warping(false);
        let expected = &psi * system.amplitudes();
        let error = (flatten(system.displacements()) - &expected).norm() / expected.norm();
        assert!(
            error < 1e-12,
            "linear displacements differ from Psi z by {error:e}"
        );
    }

    #[test]
    fn loads_are_rotated_into_the_local_frames() {
        let positions = points(30, 4);
        let (basis, psi) = rotation_basis(&positions);
        let w = Vector::new(-0.4, 0.9, 0.3);
        let rotation = Rotation3::new(w);
        let local = points(30, 5);
        let world: Vec<Vector> = local.iter().map(|g| rotation * g).collect();
        let reference = psi.tr_mul(&flatten(&local));
        let mut system = ModalSystem::new(basis, Damping::new(0.0, 0.0).expect("valid"), true);
        system
            .set_state(
                &DVector::from_column_slice(w.as_slice()),
                &DVector::zeros(3),
            )
            .expect("valid");
        system.step(1e-3, &world).expect("valid step");
        let error = (system.modal_force() - &reference).norm() / reference.norm();
        assert!(
            error < 1e-12,
            "Psi^T R^T F differs from Psi^T g by {error:e}"
        );
        let linear = psi.tr_mul(&flatten(&world));
        assert!(
            (&linear - &reference).norm() > 0.1 * reference.norm(),
            "the rotation should change the unwarped force"
        );
    }

    #[test]
    fn a_refused_step_keeps_the_state() {
        let (basis, _) = random_basis(3, &[1.0, 2.0], 1);
        let mut system = ModalSystem::new(basis, Damping::new(0.0, 0.0).expect("valid"), true);
        let (z, zdot) = (
            DVector::from_column_slice(&[0.1, 0.2]),
            DVector::from_column_slice(&[-1.0, 1.0]),
        );
        system.set_state(&z, &zdot).expect("valid");
        let displaced = system.displacements().to_vec();
        let loads = vec![Vector::new(1.0, 2.0, 3.0); 3];
        for h in [0.0, -1e-3, Real::NAN, Real::INFINITY] {
            assert!(
                matches!(system.step(h, &loads), Err(ModalError::TimeStep { .. })),
                "h = {h}"
            );
        }
        assert_eq!(
            system.step(1e-3, &loads[..2]),
            Err(ModalError::LoadCount {
                expected: 3,
                got: 2
            })
        );
        let mut bad = loads.clone();
        bad[1].y = Real::NAN;
        assert_eq!(
            system.step(1e-3, &bad),
            Err(ModalError::LoadNotFinite { node: 1 })
        );
        let huge = vec![Vector::new(Real::MAX, Real::MAX, Real::MAX); 3];
        assert_eq!(system.step(1.0, &huge), Err(ModalError::Overflow));
        assert_eq!((system.amplitudes(), system.velocities()), (&z, &zdot));
        assert_eq!(system.displacements(), displaced.as_slice());
        assert!(matches!(
            system.set_state(&DVector::zeros(3), &zdot),
            Err(ModalError::Shape { what: "z", .. })
        ));
        system.step(1e-3, &loads).expect("a valid step still runs");
    }
}
