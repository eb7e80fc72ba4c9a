//! The residuals of the energies shared by shapes and motions, in
//! unknowns scaled by the spacing (`x = u / s`), so that every residual
//! and derivative is of order one whatever the model's size.
//!
//! With `G_j = s grad phi_j(x_i)` and `F = I + sum_j x_j G_j^T` (Eq. 32),
//! each particle's residuals form one block of [`Rows`] whose features are
//! the entries of `F - I`, and each residual's derivative is given by `F`:
//!
//! - rigidity (Eq. 76): `C = F^T F - I`, the entries `a <= b` with
//!   off-diagonals scaled by `sqrt 2` so their squares sum to `|C|_F^2`;
//!   `dC_ab / dF_cd = [d = a] F_cb + [d = b] F_ca`;
//! - volume (Eq. 77): `det F - 1`, `d det F / dF = cof F`.
//!
//! **Curvature rows.** Gauss–Newton keeps `J^T J` of the Hessian `2 (J^T J
//! + sum_k r_k grad^2 r_k)` and drops the rest, which is small only where
//! the residuals are. A stretched shape's rigidity residuals are of order
//! one, so the dropped part matters. For rigidity it is, with weight `w`,
//!
//! ```text
//! sum_ab w C_ab d2C_ab[dF, dF] = 2 w tr(C dF^T dF) = sum_c 2 w dF_c C dF_c^T
//! ```
//!
//! over the rows `dF_c` of `dF`, since `d2(F^T F)[dF, dF] = 2 dF^T dF`.
//! With `C = sum_k lambda_k q_k q_k^T`, its part on the positive
//! eigenvalues is a sum of squares, `sum_(c, k) (sqrt(2 w lambda_k) dF_c .
//! q_k)^2`: rows with residual zero that add exactly that curvature to the
//! model and nothing to the gradient. The negative part (a compressed
//! direction) is left out, which keeps the model convex; so is the
//! volume's, `(det F - 1) d2 det F`, which is indefinite.
//!
//! A 2D field keeps `F_zz = 1`, so the 3x3 determinant and cofactor are
//! the 2x2 ones on the plane.

use super::lsq::{Rows, Term};
use crate::math::{Real, Vector};
use nalgebra::{Matrix3, SymmetricEigen};

/// `F = I + sum_j x_j G_j^T` over `(column base of j, G_j)`, reading `x`.
pub(crate) fn deformation_gradient(
    dim: usize,
    terms: impl Iterator<Item = (usize, Vector)>,
    x: &[Real],
) -> Matrix3<Real> {
    let mut f = Matrix3::identity();
    for (base, g) in terms {
        for a in 0..dim {
            let xa = x[base + a];
            for b in 0..dim {
                f[(a, b)] += xa * g[b];
            }
        }
    }
    f
}

/// Pushes the rigidity, curvature and volume rows of one particle as one
/// block: `f` is its `F`, `terms` its `(column base, G_j)` pairs,
/// `rigidity` and `volume` the square roots of the weights (times the
/// particle's volume).
pub(crate) fn push_shape_terms(
    rows: &mut Rows,
    dim: usize,
    f: &Matrix3<Real>,
    terms: &[(usize, Vector)],
    rigidity: Real,
    volume: Real,
) {
    rows.block(dim, dim, terms.iter().map(|&(base, g)| (base, g.into())));
    let features = dim * dim;
    let mut d = [0.0; 9];
    let c = f.transpose() * f - Matrix3::identity();
    if rigidity > 0.0 {
        for a in 0..dim {
            for b in a..dim {
                let scale = rigidity
                    * if a == b {
                        1.0
                    } else {
                        std::f64::consts::SQRT_2
                    };
                d.fill(0.0);
                for cc in 0..dim {
                    d[cc * dim + a] += scale * f[(cc, b)];
                    d[cc * dim + b] += scale * f[(cc, a)];
                }
                rows.push(Term::Rigidity, scale * c[(a, b)], &d[..features]);
            }
        }
        let eigen = SymmetricEigen::new(c);
        for (lambda, q) in eigen
            .eigenvalues
            .iter()
            .zip(eigen.eigenvectors.column_iter())
        {
            if *lambda <= 0.0 {
                continue;
            }
            let scale = rigidity * (2.0 * lambda).sqrt();
            for cc in 0..dim {
                d.fill(0.0);
                for b in 0..dim {
                    d[cc * dim + b] = scale * q[b];
                }
                rows.push(Term::Rigidity, 0.0, &d[..features]);
            }
        }
    }
    if volume > 0.0 {
        let cof = crate::solid::cofactor(f);
        for cc in 0..dim {
            for b in 0..dim {
                d[cc * dim + b] = volume * cof[(cc, b)];
            }
        }
        rows.push(
            Term::Volume,
            volume * (f.determinant() - 1.0),
            &d[..features],
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The residuals of Eq. 76-77 and their derivatives against central
    /// differences, in 3D and 2D, at a strongly deformed state.
    #[test]
    fn rigidity_and_volume_derivatives_match_differences() {
        for dim in [3, 2] {
            let g = [
                Vector::new(0.3, -0.2, 0.5),
                Vector::new(-0.4, 0.1, 0.2),
                Vector::new(0.1, 0.6, -0.3),
            ];
            let terms: Vec<(usize, Vector)> = g
                .iter()
                .enumerate()
                .map(|(j, g)| {
                    let mut g = *g;
                    if dim == 2 {
                        g.z = 0.0;
                    }
                    (j * dim, g)
                })
                .collect();
            let n = terms.len() * dim;
            let x: Vec<Real> = (0..n).map(|k| 0.3 * ((k * 7 % 5) as Real - 2.0)).collect();
            let residuals = |x: &[Real]| {
                let f = deformation_gradient(dim, terms.iter().copied(), x);
                let mut rows = Rows::default();
                rows.reset(true);
                push_shape_terms(&mut rows, dim, &f, &terms, 1.3, 0.7);
                rows
            };
            let at = residuals(&x);
            let count = at.residuals.len();
            // Rigidity, then curvature rows (residual zero, checked in
            // the test below), then volume.
            let rigidity = dim * (dim + 1) / 2;
            let checked: Vec<usize> = (0..rigidity).chain([count - 1]).collect();
            assert!(at.residuals[rigidity..count - 1].iter().all(|r| *r == 0.0));
            let h = 1e-6;
            for c in 0..n {
                let (mut up, mut down) = (x.clone(), x.clone());
                up[c] += h;
                down[c] -= h;
                let (ru, rd) = (residuals(&up), residuals(&down));
                for &k in &checked {
                    let numeric = (ru.residuals[k] - rd.residuals[k]) / (2.0 * h);
                    let analytic = at.derivative(k, c);
                    assert!(
                        (numeric - analytic).abs() < 1e-6 * (1.0 + numeric.abs()),
                        "dim {dim}, residual {k}, unknown {c}: {analytic} vs {numeric}"
                    );
                }
            }
            // Rigid: a rotation leaves both residuals at zero.
            let f = nalgebra::Rotation3::from_scaled_axis(Vector::new(0.0, 0.0, 0.7)).into_inner();
            let mut rows = Rows::default();
            rows.reset(true);
            push_shape_terms(&mut rows, dim, &f, &terms, 1.0, 1.0);
            assert!(
                rows.residuals.iter().all(|r| r.abs() < 1e-12),
                "{:?}",
                rows.residuals
            );
        }
    }

    /// Where `C = F^T F - I` is positive definite (a stretch), the
    /// curvature rows complete the Gauss–Newton model: `J^T J + K^T K` is
    /// half the exact Hessian of the rigidity energy, checked against
    /// central differences of its gradient `2 J^T r`.
    #[test]
    fn curvature_rows_make_the_model_exact_under_stretch() {
        let dim = 3;
        // G_j = e_j, so the unknowns of "particle" b are column b of F - I.
        let terms: Vec<(usize, Vector)> = (0..3)
            .map(|j| {
                let mut g = Vector::zeros();
                g[j] = 1.0;
                (j * dim, g)
            })
            .collect();
        let f = Matrix3::new(1.4, 0.1, 0.0, 0.05, 1.3, 0.1, 0.0, 0.1, 1.5);
        let mut x = vec![0.0; 9];
        for a in 0..3 {
            for b in 0..3 {
                x[b * dim + a] = f[(a, b)] - if a == b { 1.0 } else { 0.0 };
            }
        }
        let rows_at = |x: &[Real]| {
            let f = deformation_gradient(dim, terms.iter().copied(), x);
            let mut rows = Rows::default();
            rows.reset(true);
            push_shape_terms(&mut rows, dim, &f, &terms, 1.3, 0.0);
            rows
        };
        let gradient = |x: &[Real]| -> Vec<Real> {
            let rows = rows_at(x);
            (0..9)
                .map(|c| {
                    (0..rows.residuals.len())
                        .map(|k| 2.0 * rows.residuals[k] * rows.derivative(k, c))
                        .sum()
                })
                .collect()
        };
        let at = rows_at(&x);
        assert_eq!(at.residuals.len(), 6 + 9, "three positive eigenvalues");
        let h = 1e-6;
        for e in 0..9 {
            let (mut up, mut down) = (x.clone(), x.clone());
            up[e] += h;
            down[e] -= h;
            let (gu, gd) = (gradient(&up), gradient(&down));
            for c in 0..9 {
                let exact = (gu[c] - gd[c]) / (2.0 * h);
                let model: Real = (0..at.residuals.len())
                    .map(|k| 2.0 * at.derivative(k, c) * at.derivative(k, e))
                    .sum();
                assert!(
                    (exact - model).abs() < 1e-5 * (1.0 + exact.abs()),
                    "({c}, {e}): model {model} vs exact {exact}"
                );
            }
        }
    }
}
