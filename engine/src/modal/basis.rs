//! The precomputed modal basis of a body (Guo & Qin Sec. 5.3.1): the
//! eigenvalues `Lambda` of `K x = lambda M x`, the M-orthonormal mode
//! shapes `Psi` at the nodes and the rotation-vector matrix `W` (Eq. 27,
//! `w_I = W_I z`), validated once so that the per-step code never checks.
//!
//! Storage: `Psi` and `W` are kept transposed, as `l x 3n` nalgebra
//! (column-major) matrices. Column `3I + a` then holds the `l`
//! coefficients of scalar dof `(I, a)` contiguously, so a node's three
//! dofs are one run of `3l` reals, and a chunk of nodes (the parallel
//! unit) is one contiguous `l x 3m` slab: `Psi z` over it is one
//! dense matrix-vector product and `Psi^T f` another. A column-major `3n x l`
//! `Psi` would instead stride by `3n` between a node's coefficients.

use nalgebra::{DMatrix, DVector, Dim, Dyn, Matrix, MatrixView, RawStorage, U3};

use super::ModalError;
use crate::math::{Real, Vector};

/// Relative rounding allowance for negative eigenvalues: an eigensolver
/// returns the rigid modes of a free body at about `eps * lambda_max *
/// cond` instead of 0, well inside `1e-8 * lambda_max`; the floor of
/// `1e-8` (per second squared, a period of about 6e4 s) admits that noise
/// when every kept mode is rigid. Accepted values are clamped to 0.
pub const EIGENVALUE_TOLERANCE: Real = 1e-8;

/// Eigenvalues, mode shapes and rotation modes of one body, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct ModalBasis {
    /// `Lambda` (length l), clamped to `>= 0`.
    eigenvalues: DVector<Real>,
    /// `Psi^T`, `l x 3n` (see the module comment).
    psi_t: DMatrix<Real>,
    /// `W^T`, `l x 3n`.
    w_t: DMatrix<Real>,
}

impl ModalBasis {
    /// A basis from the eigenvalues (length l, the diagonal of `K_z` in
    /// Eq. 30), the mode shapes `psi` (`3n x l`: row `3I + a` maps the
    /// modal amplitudes to component `a` of node `I`'s MLS coefficient)
    /// and the rotation modes `w` (`3n x l`, Eq. 27 at the nodes). The
    /// eigenvalues need not be sorted.
    ///
    /// # Errors
    /// [`ModalError`] when a size disagrees, an entry is not finite, or an
    /// eigenvalue is below `-EIGENVALUE_TOLERANCE * max(max |lambda|, 1)`.
    pub fn new(
        eigenvalues: &DVector<Real>,
        psi: &DMatrix<Real>,
        w: &DMatrix<Real>,
    ) -> Result<Self, ModalError> {
        let modes = eigenvalues.len();
        let rows = psi.nrows();
        if !rows.is_multiple_of(3) {
            return Err(ModalError::NodeRows { rows });
        }
        if rows == 0 || modes == 0 {
            return Err(ModalError::Empty {
                nodes: rows / 3,
                modes,
            });
        }
        for (what, m) in [("psi", psi), ("w", w)] {
            if m.shape() != (rows, modes) {
                return Err(ModalError::Shape {
                    what,
                    expected_rows: rows,
                    expected_cols: modes,
                    got_rows: m.nrows(),
                    got_cols: m.ncols(),
                });
            }
            check_finite(what, m)?;
        }
        check_finite("eigenvalues", eigenvalues)?;
        let largest = eigenvalues.iter().fold(1.0, |m: Real, v| m.max(v.abs()));
        let tolerance = EIGENVALUE_TOLERANCE * largest;
        if let Some((index, &value)) = eigenvalues
            .iter()
            .enumerate()
            .find(|(_, v)| **v < -tolerance)
        {
            return Err(ModalError::NegativeEigenvalue {
                index,
                value,
                tolerance,
            });
        }
        Ok(Self {
            eigenvalues: eigenvalues.map(|v| v.max(0.0)),
            psi_t: psi.transpose(),
            w_t: w.transpose(),
        })
    }

    /// Node count n.
    pub fn node_count(&self) -> usize {
        self.psi_t.ncols() / 3
    }

    /// Mode count l.
    pub fn mode_count(&self) -> usize {
        self.eigenvalues.len()
    }

    /// `Lambda`, the modal stiffnesses `K_z` (Eq. 30), clamped to `>= 0`.
    pub fn eigenvalues(&self) -> &DVector<Real> {
        &self.eigenvalues
    }

    /// The linear (local-frame) displacement of node `node`,
    /// `u^L_I = Psi_I z` (Eq. 29's `u^L = Psi z^L`).
    ///
    /// # Panics
    /// When `node >= n` or `z.len() != l`.
    pub fn linear_displacement(&self, node: usize, z: &DVector<Real>) -> Vector {
        node_block(&self.psi_t, node).tr_mul(z)
    }

    /// `Psi_I^T`, `l x 3`: node `node`'s displacement in every mode.
    ///
    /// # Panics
    /// When `node >= n`.
    pub fn displacement_block(&self, node: usize) -> MatrixView<'_, Real, Dyn, U3> {
        node_block(&self.psi_t, node)
    }

    /// `W_I^T`, `l x 3`: node `node`'s rotation vector in every mode.
    ///
    /// # Panics
    /// When `node >= n`.
    pub fn rotation_block(&self, node: usize) -> MatrixView<'_, Real, Dyn, U3> {
        node_block(&self.w_t, node)
    }

    /// `Psi^T` as its column-major values (`l x 3n`), for the per-step
    /// products.
    pub(super) fn psi_t(&self) -> &[Real] {
        self.psi_t.as_slice()
    }

    /// `W^T` as its column-major values (`l x 3n`).
    pub(super) fn w_t(&self) -> &[Real] {
        self.w_t.as_slice()
    }
}

/// The `l x 3` block of a transposed basis matrix that belongs to `node`.
fn node_block(t: &DMatrix<Real>, node: usize) -> MatrixView<'_, Real, Dyn, U3> {
    t.fixed_columns::<3>(3 * node)
}

/// The first non-finite entry of `m` (named `what`) as an error.
pub(super) fn check_finite<R: Dim, C: Dim, S: RawStorage<Real, R, C>>(
    what: &'static str,
    m: &Matrix<Real, R, C, S>,
) -> Result<(), ModalError> {
    for col in 0..m.ncols() {
        for row in 0..m.nrows() {
            let value = m[(row, col)];
            if !value.is_finite() {
                return Err(ModalError::NotFinite {
                    what,
                    row,
                    col,
                    value,
                });
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shapes(n: usize, l: usize) -> DMatrix<Real> {
        DMatrix::from_fn(3 * n, l, |r, c| (r + 2 * c) as Real * 0.1)
    }

    #[test]
    fn malformed_bases_are_refused_by_what_is_wrong() {
        let lambda = DVector::from_column_slice(&[0.0, 4.0]);
        let (psi, w) = (shapes(3, 2), shapes(3, 2));
        assert_eq!(
            ModalBasis::new(&lambda, &DMatrix::zeros(7, 2), &w),
            Err(ModalError::NodeRows { rows: 7 })
        );
        assert_eq!(
            ModalBasis::new(
                &DVector::zeros(0),
                &DMatrix::zeros(9, 0),
                &DMatrix::zeros(9, 0)
            ),
            Err(ModalError::Empty { nodes: 3, modes: 0 })
        );
        assert!(matches!(
            ModalBasis::new(&lambda, &psi, &shapes(2, 2)),
            Err(ModalError::Shape {
                what: "w",
                got_rows: 6,
                ..
            })
        ));
        assert!(matches!(
            ModalBasis::new(&DVector::zeros(3), &psi, &w),
            Err(ModalError::Shape {
                what: "psi",
                expected_cols: 3,
                ..
            })
        ));
        let mut nan = psi.clone();
        nan[(4, 1)] = Real::NAN;
        assert!(matches!(
            ModalBasis::new(&lambda, &nan, &w),
            Err(ModalError::NotFinite {
                what: "psi",
                row: 4,
                col: 1,
                ..
            })
        ));
        let unstable = DVector::from_column_slice(&[-1e-3, 4.0]);
        assert!(matches!(
            ModalBasis::new(&unstable, &psi, &w),
            Err(ModalError::NegativeEigenvalue { index: 0, .. })
        ));
    }

    #[test]
    fn rounding_below_zero_is_a_rigid_mode() {
        let lambda = DVector::from_column_slice(&[-1e-9, 4.0e3]);
        let basis = ModalBasis::new(&lambda, &shapes(2, 2), &shapes(2, 2)).expect("valid");
        assert_eq!(basis.eigenvalues().as_slice(), &[0.0, 4.0e3]);
        assert_eq!((basis.node_count(), basis.mode_count()), (2, 2));
        // Node 1's displacement is rows 3..6 of Psi times z.
        let z = DVector::from_column_slice(&[1.0, -2.0]);
        let expected = shapes(2, 2).rows(3, 3) * &z;
        let error = (basis.linear_displacement(1, &z)
            - Vector::from_column_slice(expected.as_slice()))
        .norm();
        assert!(error < 1e-14, "node 1's displacement is off by {error:e}");
    }
}
