//! Complete polynomial bases of order 0, 1 and 2 in 1, 2 and 3 dimensions,
//! evaluated at the centred, scaled offset `s = (x_i - x) / h` (Adams–Wicke
//! tutorial Eq. 28-29, after Saad 1986): every entry of `p(s)` is then of
//! order one on the support whatever `h` is, so the moment matrix's
//! condition number depends on the layout's shape, not its scale.
//!
//! The monomials are ordered by degree, `[1, s_0 .. s_{d-1}, s_a s_b (a <=
//! b)]`, so the basis of a lower order is a prefix of a higher one: one
//! evaluation at the highest order serves every order of the rank fallback.

use crate::math::Real;
use serde::{Deserialize, Serialize};

/// Size of the largest basis, the complete quadratic in 3D.
pub const MAX_BASIS: usize = 10;

/// Order of a complete polynomial basis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Order {
    /// `[1]`: Shepard interpolation, reproduces constants.
    Constant,
    /// `[1, x, y, z]`: reproduces linear fields (and their gradients).
    Linear,
    /// Adds the products `x^2, xy, ...`: reproduces quadratic fields.
    Quadratic,
}

impl Order {
    /// Every order, lowest first, for tests that sweep them.
    pub const ALL: [Order; 3] = [Order::Constant, Order::Linear, Order::Quadratic];

    /// Polynomial degree, 0, 1 or 2.
    pub fn degree(self) -> usize {
        match self {
            Self::Constant => 0,
            Self::Linear => 1,
            Self::Quadratic => 2,
        }
    }

    /// The next lower order, for the MLSPH rank fallback (Dilts 1999;
    /// tutorial Section 4); `None` below the constant basis.
    pub fn lower(self) -> Option<Order> {
        match self {
            Self::Constant => None,
            Self::Linear => Some(Self::Constant),
            Self::Quadratic => Some(Self::Linear),
        }
    }

    /// Number of monomials of degree at most this order in `dim`
    /// dimensions: 1/2/3 in 1D, 1/3/6 in 2D, 1/4/10 in 3D.
    pub fn basis_size(self, dim: usize) -> usize {
        match self {
            Self::Constant => 1,
            Self::Linear => 1 + dim,
            Self::Quadratic => 1 + dim + dim * (dim + 1) / 2,
        }
    }
}

/// `p(s)` and its derivatives `dp/ds_k` (`k < dim`) at the centred,
/// scaled offset `s`, up to `order`; entries past the basis size are left
/// untouched.
#[derive(Debug, Clone, Copy)]
pub(crate) struct BasisValues {
    pub p: [Real; MAX_BASIS],
    pub dp: [[Real; MAX_BASIS]; 3],
}

impl BasisValues {
    pub fn new(dim: usize, order: Order, s: &[Real; 3]) -> Self {
        let mut p = [0.0; MAX_BASIS];
        let mut dp = [[0.0; MAX_BASIS]; 3];
        p[0] = 1.0;
        if order >= Order::Linear {
            for a in 0..dim {
                p[1 + a] = s[a];
                dp[a][1 + a] = 1.0;
            }
        }
        if order >= Order::Quadratic {
            let mut n = 1 + dim;
            for a in 0..dim {
                for b in a..dim {
                    p[n] = s[a] * s[b];
                    // d(s_a s_b)/ds_k = delta_ak s_b + delta_bk s_a.
                    dp[a][n] += s[b];
                    dp[b][n] += s[a];
                    n += 1;
                }
            }
        }
        Self { p, dp }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sizes are those of complete polynomial spaces, `C(d + n, n)`.
    #[test]
    fn sizes_are_binomial() {
        let binomial = |n: usize, k: usize| -> usize {
            (1..=k).map(|i| n + 1 - i).product::<usize>() / (1..=k).product::<usize>()
        };
        for dim in 1..=3 {
            for order in Order::ALL {
                let n = order.degree();
                assert_eq!(
                    order.basis_size(dim),
                    binomial(dim + n, n),
                    "{dim}D {order:?}"
                );
            }
        }
    }

    /// The derivatives match central differences of the values.
    #[test]
    fn derivatives_match_finite_differences() {
        let s = [0.3, -0.7, 0.45];
        let eps = 1e-6;
        for dim in 1..=3 {
            let m = Order::Quadratic.basis_size(dim);
            let b = BasisValues::new(dim, Order::Quadratic, &s);
            for k in 0..dim {
                let (mut sp, mut sm) = (s, s);
                sp[k] += eps;
                sm[k] -= eps;
                let (bp, bm) = (
                    BasisValues::new(dim, Order::Quadratic, &sp),
                    BasisValues::new(dim, Order::Quadratic, &sm),
                );
                for n in 0..m {
                    let fd = (bp.p[n] - bm.p[n]) / (2.0 * eps);
                    assert!(
                        (fd - b.dp[k][n]).abs() < 1e-8,
                        "{dim}D d/ds_{k} of monomial {n}"
                    );
                }
            }
        }
    }
}
