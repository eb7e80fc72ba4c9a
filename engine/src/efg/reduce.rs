//! From an assembled EFG solid to its modal basis (Guo–Qin, Sections
//! 5.3.1-5.3.2): the lowest modes of `K x = lambda M x` and the rotation
//! modes `W = 1/2 curl Phi Psi` at the nodes (Eq. 27) that modal warping
//! reads.
//!
//! The curl of `u = sum_J phi_J u_J` is `sum_J grad phi_J x u_J`, so at
//! node `I` the rotation vector of mode `j` is
//! `w_I = 1/2 sum_J grad phi_J(x_I) x Psi_J,j`: one row of shape-function
//! gradients per node, evaluated once.

use super::solid::{EfgError, EfgSolid, MassForm};
use crate::cancel::Cancel;
use crate::linalg::eigen::{self, EigenParams, Mass, Modes};
use crate::math::{Real, Vector};
use crate::modal::ModalBasis;
use nalgebra::{DMatrix, DVector};

/// Quadrature points summed between two reads of the cancel flag.
const POINTS_PER_CHECK: usize = 4096;

impl EfgSolid {
    /// The `count` lowest modes to relative accuracy `tolerance`, with the
    /// mass form of the parameters.
    ///
    /// # Errors
    /// [`EfgError::Eigen`] from the eigensolver (count out of range, no
    /// convergence, cancellation, ...).
    pub fn modes(&self, count: usize, tolerance: Real, cancel: &Cancel) -> Result<Modes, EfgError> {
        let lumped: Vec<Real>;
        let mass = match self.params().mass {
            MassForm::Consistent => Mass::Consistent(self.consistent_mass()),
            MassForm::Lumped => {
                lumped = self.node_masses().iter().flat_map(|m| [*m; 3]).collect();
                Mass::Lumped(&lumped)
            }
        };
        let params = EigenParams {
            count,
            tolerance,
            shift: Some(self.elastic_shift(cancel)?),
        };
        Ok(eigen::lowest_modes(
            self.pattern(),
            self.stiffness(),
            mass,
            &params,
            cancel,
        )?)
    }

    /// The eigensolver's shift: `trace(K) / trace(M) / n` (see
    /// [`EigenParams::shift`]) over the elastic stiffness alone. The
    /// penalty of a fixed region adds `1e4 E / cell`-sized entries to K's
    /// diagonal; in the trace they made the shift thousands of times the
    /// lowest modes, which the inversion then crowded together and the
    /// Krylov iteration could not separate (the clamped beam of Guo–Qin's
    /// Table 1 ran for minutes). `trace(K) = (lambda + 4 mu) int sum_I
    /// |grad phi_I|^2` for the linear isotropic K.
    /// Reads `cancel` every [`POINTS_PER_CHECK`] points.
    fn elastic_shift(&self, cancel: &Cancel) -> Result<Real, EfgError> {
        let (lambda, mu) = super::lame(self.material().young, self.material().poisson);
        let table = &self.volume.table;
        let (mut gradients, mut values) = (0.0, 0.0);
        for q in 0..table.len() {
            if q.is_multiple_of(POINTS_PER_CHECK) {
                cancel.check().map_err(|_| EfgError::Cancelled)?;
            }
            let row = table.row(q);
            let w = self.volume.weights[q];
            gradients += w * row.gradients.iter().map(|g| g.norm_squared()).sum::<Real>();
            values += w * row.values.iter().map(|v| v * v).sum::<Real>();
        }
        let trace_k = (lambda + 4.0 * mu) * gradients;
        let trace_m = 3.0
            * match self.params().mass {
                MassForm::Consistent => self.material().density * values,
                MassForm::Lumped => self.node_masses().iter().sum::<Real>(),
            };
        Ok(trace_k / trace_m / (3 * self.nodes().len()) as Real)
    }

    /// The rotation modes of `modes` at the nodes, `3n x l` (Eq. 27).
    ///
    /// # Errors
    /// [`EfgError::Cover`] when a node's own position is not covered well
    /// enough (cannot happen for a discretisation that built).
    pub fn rotation_modes(&self, modes: &Modes) -> Result<DMatrix<Real>, EfgError> {
        self.rotation_modes_cancellable(modes, &Cancel::new())
    }

    /// [`Self::rotation_modes`], reading `cancel` per node of the table
    /// and per mode.
    fn rotation_modes_cancellable(
        &self,
        modes: &Modes,
        cancel: &Cancel,
    ) -> Result<DMatrix<Real>, EfgError> {
        let positions: Vec<Vector> = self.nodes().iter().map(|n| n.position).collect();
        let table = self.shape_table_cancellable(&positions, cancel)?;
        let n = 3 * positions.len();
        let count = modes.eigenvalues.len();
        let mut w = DMatrix::zeros(n, count);
        for j in 0..count {
            cancel.check().map_err(|_| EfgError::Cancelled)?;
            let psi = &modes.vectors[j * n..(j + 1) * n];
            for i in 0..positions.len() {
                let row = table.row(i);
                let mut curl = Vector::zeros();
                for (&m, g) in row.nodes.iter().zip(row.gradients) {
                    let m = 3 * m as usize;
                    curl += g.cross(&Vector::new(psi[m], psi[m + 1], psi[m + 2]));
                }
                for a in 0..3 {
                    w[(3 * i + a, j)] = 0.5 * curl[a];
                }
            }
        }
        Ok(w)
    }

    /// The modal basis of the `count` lowest modes: what a
    /// [`crate::modal::ModalSystem`] steps.
    ///
    /// # Errors
    /// As [`EfgSolid::modes`] and [`EfgSolid::rotation_modes`], and
    /// [`EfgError::Modal`] should the basis fail validation.
    pub fn modal_basis(
        &self,
        count: usize,
        tolerance: Real,
        cancel: &Cancel,
    ) -> Result<(Modes, ModalBasis), EfgError> {
        let modes = self.modes(count, tolerance, cancel)?;
        let basis = self.basis_of(&modes, cancel)?;
        Ok((modes, basis))
    }

    /// The modal basis of `modes`: their rotation modes, and both
    /// validated.
    ///
    /// # Errors
    /// As [`EfgSolid::rotation_modes`], [`EfgError::Modal`] should the
    /// basis fail validation, and [`EfgError::Cancelled`].
    pub fn basis_of(&self, modes: &Modes, cancel: &Cancel) -> Result<ModalBasis, EfgError> {
        let w = self.rotation_modes_cancellable(modes, cancel)?;
        let n = w.nrows();
        let psi = DMatrix::from_column_slice(n, modes.eigenvalues.len(), &modes.vectors);
        Ok(ModalBasis::new(
            &DVector::from_column_slice(&modes.eigenvalues),
            &psi,
            &w,
        )?)
    }
}
