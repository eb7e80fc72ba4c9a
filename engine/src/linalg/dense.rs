//! Dense Cholesky factorisation and solve of small symmetric blocks (the
//! optimiser's line preconditioner inverts one per particle component).
//!
//! Why not faer's dense Cholesky: it sums in another order, which would
//! change the bits of every result the optimiser has produced; these
//! blocks are small (one row per frame of a motion) and plain loops serve.

use crate::math::Real;

/// Lower Cholesky factor of the symmetric `n x n` matrix `a` (row-major),
/// in place: the lower triangle becomes `L` with `L L^T = a`, the upper
/// one is left as it was. A non-positive pivot (a block only
/// semi-definite in rounding) is replaced by a tiny positive one, so the
/// factor always exists.
pub fn cholesky_in_place(a: &mut [Real], n: usize) {
    for k in 0..n {
        let mut d = a[k * n + k];
        for m in 0..k {
            d -= a[k * n + m] * a[k * n + m];
        }
        let d = d.max(1e-300).sqrt();
        a[k * n + k] = d;
        for i in k + 1..n {
            let mut v = a[i * n + k];
            for m in 0..k {
                v -= a[i * n + m] * a[k * n + m];
            }
            a[i * n + k] = v / d;
        }
    }
}

/// Solves `L L^T y = b` in place (`y` holds `b` on entry) with the factor
/// from [`cholesky_in_place`].
pub fn cholesky_solve(l: &[Real], n: usize, y: &mut [Real]) {
    for i in 0..n {
        let mut v = y[i];
        for m in 0..i {
            v -= l[i * n + m] * y[m];
        }
        y[i] = v / l[i * n + i];
    }
    for i in (0..n).rev() {
        let mut v = y[i];
        for m in i + 1..n {
            v -= l[m * n + i] * y[m];
        }
        y[i] = v / l[i * n + i];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::uniform;

    #[test]
    fn a_factored_spd_block_solves_to_rounding() {
        let mut seed = 5;
        for n in [1, 2, 7, 24] {
            let b: Vec<Real> = (0..n * n).map(|_| uniform(&mut seed) - 0.5).collect();
            let mut a = vec![0.0; n * n];
            for i in 0..n {
                for j in 0..n {
                    a[i * n + j] = (0..n).map(|k| b[k * n + i] * b[k * n + j]).sum::<Real>();
                }
                a[i * n + i] += 1.0;
            }
            let rhs: Vec<Real> = (0..n).map(|_| uniform(&mut seed)).collect();
            let mut factor = a.clone();
            cholesky_in_place(&mut factor, n);
            let mut y = rhs.clone();
            cholesky_solve(&factor, n, &mut y);
            let residual = (0..n)
                .map(|i| ((0..n).map(|j| a[i * n + j] * y[j]).sum::<Real>() - rhs[i]).powi(2))
                .sum::<Real>()
                .sqrt();
            let scale = rhs.iter().map(|v| v * v).sum::<Real>().sqrt();
            let limit = 8.0 * Real::EPSILON * (n * n) as Real * scale;
            assert!(residual <= limit, "n = {n}: {residual:e} > {limit:e}");
        }
    }

    #[test]
    fn a_singular_block_still_factors() {
        let mut a = vec![1.0, 1.0, 1.0, 1.0];
        cholesky_in_place(&mut a, 2);
        assert!(a.iter().all(|v| v.is_finite()), "{a:?}");
        assert!(a[3] > 0.0, "the zero pivot is floored: {a:?}");
    }
}
