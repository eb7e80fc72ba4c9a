//! The composite quadratic tensor-product weight of Guo–Qin (Section 3.2,
//! Eq. 12-13), the weight of the Element-Free Galerkin solids.
//!
//! Its support is a box, not a ball: the octree's cubic covers
//! (Section 4.1.1) are exactly its supports, so the covers of a point and
//! the integration cells they meet are known from the octree without a
//! search. With `d = x - x_I` and the half side lengths `a` of node `I`'s
//! box,
//!
//! ```text
//! w(x, x_I) = c(d_x / a_x) c(d_y / a_y) c(d_z / a_z)          (Eq. 12)
//!
//!        / 1 - 2 s^2      0   <= s < 1/2
//! c(s) = | 2 (1 - s)^2    1/2 <= s < 1                          (Eq. 13)
//!        \ 0              1   <= s
//! ```
//!
//! for `s = |d_k / a_k|`. The extraction of the paper flattened the
//! first branch's bracket; it is the one that meets the second with the
//! same value (1/2) and slope (-2) at `s = 1/2`, so `c` is C1 and so is
//! every MLS shape function built on it (Section 3.2: continuity of the
//! weight is continuity of the approximation). The tests pin the value,
//! the slope and that matching. Its second derivative jumps at `s = 1/2`
//! (C1, not C2), so second derivatives of the shape functions built on it
//! (a thin shell's bending strains) are piecewise smooth, with jumps
//! across those lines.

use crate::math::Real;

/// `c(s)` and `dc/ds` of Eq. 13 for a signed `s` (the weight is even).
pub fn quadratic_spline(s: Real) -> (Real, Real) {
    let a = s.abs();
    let sign = if s < 0.0 { -1.0 } else { 1.0 };
    if a < 0.5 {
        (1.0 - 2.0 * a * a, -4.0 * a * sign)
    } else if a < 1.0 {
        let t = 1.0 - a;
        (2.0 * t * t, -4.0 * t * sign)
    } else {
        (0.0, 0.0)
    }
}

/// The weight of Eq. 12 and its gradient in `x` for the offset
/// `d = x - x_I` from a node whose support box has half side lengths
/// `half`, or `None` outside the open box (and for non-finite input).
pub fn tensor_weight(d: &[Real; 3], half: &[Real; 3]) -> Option<(Real, [Real; 3])> {
    let mut c = [0.0; 3];
    let mut dc = [0.0; 3];
    for k in 0..3 {
        let s = d[k] / half[k];
        // Also refuses NaN.
        if s.abs().partial_cmp(&1.0) != Some(std::cmp::Ordering::Less) {
            return None;
        }
        let (value, slope) = quadratic_spline(s);
        c[k] = value;
        dc[k] = slope / half[k];
    }
    let w = c[0] * c[1] * c[2];
    if w <= 0.0 {
        return None;
    }
    Some((
        w,
        [
            dc[0] * c[1] * c[2],
            c[0] * dc[1] * c[2],
            c[0] * c[1] * dc[2],
        ],
    ))
}

/// `d^2 c / ds^2` of Eq. 13 for a signed `s`: -4 on the inner branch, 4
/// on the outer, 0 outside. It jumps at `|s| = 1/2` (the spline is C1,
/// not C2); there it takes the outer branch's value, as
/// [`quadratic_spline`] takes the outer branch's value and slope.
pub fn quadratic_spline_curvature(s: Real) -> Real {
    let a = s.abs();
    if a < 0.5 {
        -4.0
    } else if a < 1.0 {
        4.0
    } else {
        0.0
    }
}

/// A weight's value, gradient and Hessian in `x`.
pub type WeightHessian = (Real, [Real; 3], [[Real; 3]; 3]);

/// The weight of Eq. 12 restricted to the first `dim` axes (a node of a
/// 2D parametric domain has a square support), with its gradient and
/// Hessian in `x`, or `None` outside the open box; axes past `dim` are
/// neither read nor differentiated. The second derivatives the bending
/// energy of a thin shell needs (Guo–Qin Section 5.2): `d^2 w / dx_k
/// dx_l = c'_k c'_l / (a_k a_l)` times the other factors off the
/// diagonal, `c''_k / a_k^2` times them on it.
pub fn tensor_weight_hessian(dim: usize, d: &[Real; 3], half: &[Real; 3]) -> Option<WeightHessian> {
    let mut c = [1.0; 3];
    let mut dc = [0.0; 3];
    let mut ddc = [0.0; 3];
    for k in 0..dim {
        let s = d[k] / half[k];
        if s.abs().partial_cmp(&1.0) != Some(std::cmp::Ordering::Less) {
            return None;
        }
        let (value, slope) = quadratic_spline(s);
        c[k] = value;
        dc[k] = slope / half[k];
        ddc[k] = quadratic_spline_curvature(s) / (half[k] * half[k]);
    }
    let w: Real = c.iter().product();
    if w <= 0.0 {
        return None;
    }
    // The product of the factors other than those named.
    let others = |skip: &[usize]| -> Real {
        (0..dim)
            .filter(|m| !skip.contains(m))
            .map(|m| c[m])
            .product()
    };
    let mut gradient = [0.0; 3];
    let mut hessian = [[0.0; 3]; 3];
    for k in 0..dim {
        gradient[k] = dc[k] * others(&[k]);
        hessian[k][k] = ddc[k] * others(&[k]);
        for l in 0..k {
            let mixed = dc[k] * dc[l] * others(&[k, l]);
            hessian[k][l] = mixed;
            hessian[l][k] = mixed;
        }
    }
    Some((w, gradient, hessian))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_spline_takes_the_values_of_eq_13() {
        assert_eq!(quadratic_spline(0.0), (1.0, 0.0));
        assert_eq!(quadratic_spline(0.25).0, 1.0 - 2.0 * 0.0625);
        assert_eq!(quadratic_spline(0.75).0, 2.0 * 0.0625);
        assert_eq!(quadratic_spline(1.0), (0.0, 0.0));
        assert_eq!(quadratic_spline(-0.75), (0.125, 1.0));
        assert_eq!(quadratic_spline(3.0), (0.0, 0.0));
    }

    #[test]
    fn the_branches_meet_with_equal_value_and_slope() {
        let e = 1e-12;
        let (below, slope_below) = quadratic_spline(0.5 - e);
        let (above, slope_above) = quadratic_spline(0.5 + e);
        assert!((below - 0.5).abs() < 1e-11 && (above - 0.5).abs() < 1e-11);
        assert!((slope_below + 2.0).abs() < 1e-11 && (slope_above + 2.0).abs() < 1e-11);
        // And it reaches zero with zero slope at s = 1.
        let (end, end_slope) = quadratic_spline(1.0 - e);
        assert!(end < 1e-23 && end_slope.abs() < 1e-11);
    }

    #[test]
    fn the_slope_matches_central_differences() {
        let e = 1e-6;
        for s in [-0.9, -0.6, -0.3, 0.1, 0.4, 0.55, 0.8, 0.99] {
            let fd = (quadratic_spline(s + e).0 - quadratic_spline(s - e).0) / (2.0 * e);
            assert!((quadratic_spline(s).1 - fd).abs() < 1e-8, "s = {s}");
        }
    }

    #[test]
    fn the_tensor_weight_is_a_product_with_a_matching_gradient() {
        let half = [0.5, 1.0, 2.0];
        let d = [0.1, -0.6, 1.3];
        let (w, grad) = tensor_weight(&d, &half).expect("inside the box");
        let expected: Real = (0..3).map(|k| quadratic_spline(d[k] / half[k]).0).product();
        assert!((w - expected).abs() < 1e-15);
        let e = 1e-7;
        for k in 0..3 {
            let mut plus = d;
            plus[k] += e;
            let mut minus = d;
            minus[k] -= e;
            let fd = (tensor_weight(&plus, &half).expect("inside").0
                - tensor_weight(&minus, &half).expect("inside").0)
                / (2.0 * e);
            assert!((grad[k] - fd).abs() < 1e-7, "component {k}");
        }
    }

    #[test]
    fn the_curvature_is_the_slopes_derivative_on_each_branch() {
        let e = 1e-6;
        for s in [-0.9, -0.6, -0.3, 0.1, 0.4, 0.55, 0.8, 0.99] {
            let fd = (quadratic_spline(s + e).1 - quadratic_spline(s - e).1) / (2.0 * e);
            assert!((quadratic_spline_curvature(s) - fd).abs() < 1e-6, "s = {s}");
        }
        assert_eq!(quadratic_spline_curvature(1.0), 0.0);
    }

    #[test]
    fn the_hessian_matches_differences_of_the_gradient_in_2d_and_3d() {
        let half = [0.5, 1.0, 2.0];
        let d = [0.1, -0.6, 1.3];
        for dim in [2, 3] {
            let (w, grad, hess) = tensor_weight_hessian(dim, &d, &half).expect("inside");
            let expected: Real = (0..dim)
                .map(|k| quadratic_spline(d[k] / half[k]).0)
                .product();
            assert!((w - expected).abs() < 1e-15);
            let e = 1e-6;
            for l in 0..3 {
                let mut plus = d;
                plus[l] += e;
                let mut minus = d;
                minus[l] -= e;
                let (_, gp, _) = tensor_weight_hessian(dim, &plus, &half).expect("inside");
                let (_, gm, _) = tensor_weight_hessian(dim, &minus, &half).expect("inside");
                for k in 0..3 {
                    let fd = (gp[k] - gm[k]) / (2.0 * e);
                    assert!((hess[k][l] - fd).abs() < 1e-6, "{dim}D ({k}, {l})");
                }
            }
            if dim == 3 {
                let (w3, g3) = tensor_weight(&d, &half).expect("inside");
                assert!((w3 - w).abs() < 1e-15);
                assert!((0..3).all(|k| (g3[k] - grad[k]).abs() < 1e-15));
            } else {
                // The third axis is not read.
                assert_eq!(grad[2], 0.0);
                assert!(tensor_weight_hessian(2, &[0.1, 0.2, 99.0], &half).is_some());
            }
        }
    }

    #[test]
    fn the_support_is_the_open_box() {
        let half = [1.0; 3];
        assert!(tensor_weight(&[0.99, 0.99, 0.99], &half).is_some());
        assert!(tensor_weight(&[1.0, 0.0, 0.0], &half).is_none());
        assert!(tensor_weight(&[0.0, -1.5, 0.0], &half).is_none());
        assert!(tensor_weight(&[Real::NAN, 0.0, 0.0], &half).is_none());
    }
}
