//! Bases the modal tests share: a seeded random one and the exact
//! infinitesimal-rotation one.

use nalgebra::{DMatrix, DVector};

use super::ModalBasis;
use crate::math::{Real, Vector};
use crate::testing::uniform;

/// `n` nodes, `l` modes with the given eigenvalues, seeded random mode
/// shapes and rotation modes in `[-0.5, 0.5)`; returns the basis and the
/// `3n x l` mode shapes it was built from.
pub fn random_basis(n: usize, eigenvalues: &[Real], seed: u64) -> (ModalBasis, DMatrix<Real>) {
    let mut seed = seed;
    let l = eigenvalues.len();
    let psi = DMatrix::from_fn(3 * n, l, |_, _| uniform(&mut seed) - 0.5);
    let w = DMatrix::from_fn(3 * n, l, |_, _| 0.2 * (uniform(&mut seed) - 0.5));
    let basis = ModalBasis::new(&DVector::from_column_slice(eigenvalues), &psi, &w)
        .expect("a random basis is valid");
    (basis, psi)
}

/// The three rigid rotation modes of nodes at `positions`: mode `a`
/// displaces node `I` by `e_a x x_I` and rotates it by `e_a`, so the
/// amplitudes `z = w` give `u^L_I = w x x_I` and `w_I = w` (an
/// infinitesimal rotation about the origin). Returns the basis and its
/// mode shapes.
pub fn rotation_basis(positions: &[Vector]) -> (ModalBasis, DMatrix<Real>) {
    let n = positions.len();
    let mut psi = DMatrix::zeros(3 * n, 3);
    let mut w = DMatrix::zeros(3 * n, 3);
    for (i, x) in positions.iter().enumerate() {
        for a in 0..3 {
            let u = Vector::ith(a, 1.0).cross(x);
            psi.fixed_view_mut::<3, 1>(3 * i, a).copy_from(&u);
            w[(3 * i + a, a)] = 1.0;
        }
    }
    let basis = ModalBasis::new(&DVector::zeros(3), &psi, &w).expect("rigid modes are valid");
    (basis, psi)
}

/// `n` seeded points in the cube `[-1, 1)^3`.
pub fn points(n: usize, seed: u64) -> Vec<Vector> {
    let mut seed = seed;
    (0..n)
        .map(|_| {
            Vector::new(
                2.0 * uniform(&mut seed) - 1.0,
                2.0 * uniform(&mut seed) - 1.0,
                2.0 * uniform(&mut seed) - 1.0,
            )
        })
        .collect()
}

/// Stacks nodal vectors into one `3n` vector.
pub fn flatten(v: &[Vector]) -> DVector<Real> {
    DVector::from_iterator(3 * v.len(), v.iter().flat_map(|x| x.iter().copied()))
}
