//! The residuals of the energies shared by shapes and motions, in
//! unknowns scaled by the spacing (`x = u / s`), so that every residual
//! and derivative is of order one whatever the model's size.
//!
//! With `G_j = s grad phi_j(x_i)` and `F = I + sum_j x_j G_j^T` (Eq. 32):
//!
//! - rigidity (Eq. 76): `C = F^T F - I`, the entries `a <= b` with
//!   off-diagonals scaled by `sqrt 2` so their squares sum to `|C|_F^2`;
//!   `dC_ab / dx_(j,c) = F_ca G_jb + F_cb G_ja`;
//! - volume (Eq. 77): `det F - 1`, `d det F / dx_(j,c) = (cof F G_j)_c`.
//!
//! A 2D field keeps `F_zz = 1`, so the 3x3 determinant and cofactor are
//! the 2x2 ones on the plane.

use super::lsq::{Rows, Term};
use crate::math::{Real, Vector};
use nalgebra::Matrix3;

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

/// Pushes the rigidity and volume residuals of one particle: `f` is its
/// `F`, `terms` its `(column base, G_j)` pairs, `rigidity` and `volume`
/// the square roots of the weights (times the particle's volume).
pub(crate) fn push_shape_terms(
    rows: &mut Rows,
    dim: usize,
    f: &Matrix3<Real>,
    terms: &[(usize, Vector)],
    rigidity: Real,
    volume: Real,
) {
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
                let entries = terms.iter().flat_map(|&(base, g)| {
                    (0..dim).map(move |cc| {
                        let value = f[(cc, a)] * g[b] + f[(cc, b)] * g[a];
                        ((base + cc) as u32, scale * value)
                    })
                });
                rows.push(Term::Rigidity, scale * c[(a, b)], entries);
            }
        }
    }
    if volume > 0.0 {
        let cof = crate::solid::cofactor(f);
        let entries = terms.iter().flat_map(|&(base, g)| {
            let d = cof * g;
            (0..dim).map(move |cc| ((base + cc) as u32, volume * d[cc]))
        });
        rows.push(Term::Volume, volume * (f.determinant() - 1.0), entries);
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
            assert_eq!(count, dim * (dim + 1) / 2 + 1);
            let h = 1e-6;
            for c in 0..n {
                let (mut up, mut down) = (x.clone(), x.clone());
                up[c] += h;
                down[c] -= h;
                let (ru, rd) = (residuals(&up), residuals(&down));
                for k in 0..count {
                    let numeric = (ru.residuals[k] - rd.residuals[k]) / (2.0 * h);
                    let (cols, vals) = at.entries(k);
                    let analytic: Real = cols
                        .iter()
                        .zip(vals)
                        .filter(|(col, _)| **col as usize == c)
                        .map(|(_, v)| v)
                        .sum();
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
}
