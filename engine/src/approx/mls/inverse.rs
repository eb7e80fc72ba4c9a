//! Safe inversion of the small symmetric moment matrices: a symmetric
//! eigen-decomposition and a pseudo-inverse that drops the eigenvalues at
//! or below a relative threshold (the tutorial, Section 3.3, advises an
//! SVD; for a symmetric positive semi-definite matrix the eigen-
//! decomposition is that SVD). The caller sees the numerical rank and the
//! condition number, and falls back to a lower order when the rank is
//! short.

use super::basis::MAX_BASIS;
use crate::math::Real;
use nalgebra::{SMatrix, SymmetricEigen};

/// What the inversion found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Inversion {
    /// Eigenvalues above `tolerance * lambda_max`.
    pub rank: usize,
    /// `lambda_max / lambda_min`; infinite when `lambda_min <= 0`.
    pub condition: Real,
}

/// Row-major `n x n` storage for the largest basis.
pub(crate) type Square = [Real; MAX_BASIS * MAX_BASIS];

/// Writes the pseudo-inverse of the symmetric `n x n` matrix `m`
/// (row-major, first `n * n` entries) to `out`, dropping eigenvalues
/// `lambda <= tolerance * lambda_max`. `n` is at most [`MAX_BASIS`]; with
/// `n == 0` or a zero or non-finite matrix the rank is 0 and `out` zero.
pub(crate) fn pseudo_inverse(n: usize, m: &Square, tolerance: Real, out: &mut Square) -> Inversion {
    out[..n * n].fill(0.0);
    let singular = Inversion {
        rank: 0,
        condition: Real::INFINITY,
    };
    if n == 0 || n > MAX_BASIS || m[..n * n].iter().any(|v| !v.is_finite()) {
        return singular;
    }
    // Eigenvalues, and eigenvectors as columns of a row-major matrix.
    let mut lambda = [0.0; MAX_BASIS];
    let mut vectors: Square = [0.0; MAX_BASIS * MAX_BASIS];
    // nalgebra's eigen-decomposition needs a size known at compile time
    // (to work on the stack) that it can also shrink by one.
    macro_rules! decompose {
        ($($size:literal)*) => {
            match n {
                $($size => {
                    let eigen = SymmetricEigen::new(SMatrix::<Real, $size, $size>::from_row_slice(&m[..n * n]));
                    for k in 0..n {
                        lambda[k] = eigen.eigenvalues[k];
                        for r in 0..n {
                            vectors[r * n + k] = eigen.eigenvectors[(r, k)];
                        }
                    }
                })*
                _ => return singular,
            }
        };
    }
    decompose!(1 2 3 4 5 6 7 8 9 10);
    let lambda = &lambda[..n];
    let lambda_max = lambda.iter().fold(0.0, |a: Real, l| a.max(l.abs()));
    if !(lambda_max > 0.0 && lambda_max.is_finite()) {
        return singular;
    }
    let cut = tolerance * lambda_max;
    let mut rank = 0;
    for (k, &l) in lambda.iter().enumerate() {
        if l > cut {
            rank += 1;
            for r in 0..n {
                let vr = vectors[r * n + k] / l;
                for c in 0..n {
                    out[r * n + c] += vr * vectors[c * n + k];
                }
            }
        }
    }
    let lambda_min = lambda.iter().fold(Real::INFINITY, |a: Real, &l| a.min(l));
    let condition = if lambda_min > 0.0 {
        lambda_max / lambda_min
    } else {
        Real::INFINITY
    };
    Inversion { rank, condition }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A well-conditioned SPD matrix: the pseudo-inverse is the inverse
    /// (`A A^+ = I`) and the condition number is that of the spectrum.
    #[test]
    fn full_rank_gives_the_inverse() {
        let n = 4;
        // A = Q diag(1, 2, 5, 10) Q^T with a Householder Q.
        let v = [0.5, -0.5, 0.5, 0.5];
        let spectrum = [1.0, 2.0, 5.0, 10.0];
        let mut a: Square = [0.0; 100];
        for r in 0..n {
            for c in 0..n {
                let q = |i: usize, j: usize| (if i == j { 1.0 } else { 0.0 }) - 2.0 * v[i] * v[j];
                a[r * n + c] = (0..n).map(|k| q(r, k) * spectrum[k] * q(c, k)).sum();
            }
        }
        let mut inv: Square = [0.0; 100];
        let info = pseudo_inverse(n, &a, 1e-10, &mut inv);
        assert_eq!(info.rank, 4);
        assert!((info.condition - 10.0).abs() < 1e-12, "{}", info.condition);
        for r in 0..n {
            for c in 0..n {
                let prod: Real = (0..n).map(|k| a[r * n + k] * inv[k * n + c]).sum();
                let expected = if r == c { 1.0 } else { 0.0 };
                assert!((prod - expected).abs() < 1e-13, "(A A+)[{r}][{c}] = {prod}");
            }
        }
    }

    /// A rank-one matrix `u u^T`: rank 1, infinite condition, and the
    /// pseudo-inverse `u u^T / |u|^4`.
    #[test]
    fn rank_deficient_drops_the_null_space() {
        let u = [1.0, 2.0, -1.0];
        let mut a: Square = [0.0; 100];
        for r in 0..3 {
            for c in 0..3 {
                a[r * 3 + c] = u[r] * u[c];
            }
        }
        let mut inv: Square = [0.0; 100];
        let info = pseudo_inverse(3, &a, 1e-10, &mut inv);
        assert_eq!(info.rank, 1);
        assert!(info.condition.is_infinite() || info.condition > 1e12);
        let norm4 = 36.0;
        for r in 0..3 {
            for c in 0..3 {
                assert!((inv[r * 3 + c] - u[r] * u[c] / norm4).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn zero_and_non_finite_matrices_have_rank_zero() {
        let mut inv: Square = [1.0; 100];
        assert_eq!(pseudo_inverse(2, &[0.0; 100], 1e-10, &mut inv).rank, 0);
        assert!(inv[..4].iter().all(|&v| v == 0.0));
        let mut nan: Square = [0.0; 100];
        nan[0] = Real::NAN;
        assert_eq!(pseudo_inverse(2, &nan, 1e-10, &mut inv).rank, 0);
        assert!(inv[..4].iter().all(|v| v.is_finite()));
    }
}
