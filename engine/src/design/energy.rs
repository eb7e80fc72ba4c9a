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
