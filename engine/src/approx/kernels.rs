//! SPH smoothing kernels in 2D and 3D, normalised so that their integral
//! over the plane or space is 1 (Adams–Wicke tutorial, Section 2.1 and
//! Appendix A).
//!
//! Every kernel has compact support of radius `h`: it is zero for `r >= h`.
//! Each is a radial profile `w(q)` of `q = r / h` times a normalisation
//! `sigma_d / h^d` that depends on the dimension `d`:
//!
//! | kind | profile `w(q)` on `[0, 1]` | `sigma_2` | `sigma_3` | source |
//! |---|---|---|---|---|
//! | poly6 | `(1 - q^2)^3` | `4 / pi` | `315 / (64 pi)` | Müller et al. 2003, tutorial Eq. 86, 89 |
//! | spiky | `(1 - q)^3` | `10 / pi` | `15 / pi` | Müller et al. 2003, tutorial Eq. 92, 95 |
//! | viscosity | `-q^3/2 + q^2 + 1/(2q) - 1` | `10 / (3 pi)` | `15 / (2 pi)` | Müller et al. 2003 |
//! | cubic spline | `1 - 6q^2 + 6q^3` (q <= 1/2), `2 (1 - q)^3` | `40 / (7 pi)` | `8 / pi` | Monaghan 1992, support `h` |
//! | Wendland C2 | `(1 - q)^4 (1 + 4q)` | `7 / pi` | `21 / (2 pi)` | Wendland 1995; Dehnen & Aly 2012 |
//!
//! The Laplacian of a radial function in `d` dimensions is
//! `w'' + (d - 1) w' / r`. The tutorial's flattened Eq. 11 reads
//! `Delta omega = omega''`, which drops the second term; the tests pin the
//! full form against finite differences.

use crate::math::{Real, Vector};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Which kernel profile.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum KernelKind {
    /// Smooth at the origin, cheap (needs only `r^2`): densities, averages.
    Poly6,
    /// Non-vanishing slope at the origin: pressure gradients without
    /// clumping.
    Spiky,
    /// Positive Laplacian everywhere: viscosity (singular value at 0).
    Viscosity,
    /// The classic B-spline of SPH literature.
    CubicSpline,
    /// Positive Fourier transform, no pairing instability.
    WendlandC2,
}

impl KernelKind {
    /// Every kind, in declaration order, for tests that sweep all kernels.
    pub const ALL: [KernelKind; 5] = [
        KernelKind::Poly6,
        KernelKind::Spiky,
        KernelKind::Viscosity,
        KernelKind::CubicSpline,
        KernelKind::WendlandC2,
    ];

    /// `sigma_d`: the profile's normalisation for `h = 1`.
    fn sigma(self, dim: usize) -> Real {
        match (self, dim) {
            (Self::Poly6, 2) => 4.0 / PI,
            (Self::Poly6, _) => 315.0 / (64.0 * PI),
            (Self::Spiky, 2) => 10.0 / PI,
            (Self::Spiky, _) => 15.0 / PI,
            (Self::Viscosity, 2) => 10.0 / (3.0 * PI),
            (Self::Viscosity, _) => 15.0 / (2.0 * PI),
            (Self::CubicSpline, 2) => 40.0 / (7.0 * PI),
            (Self::CubicSpline, _) => 8.0 / PI,
            (Self::WendlandC2, 2) => 7.0 / PI,
            (Self::WendlandC2, _) => 21.0 / (2.0 * PI),
        }
    }

    /// The profile and its first two derivatives in `q`, for `0 < q < 1`.
    #[inline]
    pub(crate) fn profile(self, q: Real) -> [Real; 3] {
        match self {
            Self::Poly6 => {
                let s = 1.0 - q * q;
                [s * s * s, -6.0 * q * s * s, 6.0 * s * (5.0 * q * q - 1.0)]
            }
            Self::Spiky => {
                let s = 1.0 - q;
                [s * s * s, -3.0 * s * s, 6.0 * s]
            }
            Self::Viscosity => [
                -0.5 * q * q * q + q * q + 0.5 / q - 1.0,
                -1.5 * q * q + 2.0 * q - 0.5 / (q * q),
                -3.0 * q + 2.0 + 1.0 / (q * q * q),
            ],
            Self::CubicSpline => {
                if q <= 0.5 {
                    [
                        1.0 - 6.0 * q * q + 6.0 * q * q * q,
                        -12.0 * q + 18.0 * q * q,
                        -12.0 + 36.0 * q,
                    ]
                } else {
                    let s = 1.0 - q;
                    [2.0 * s * s * s, -6.0 * s * s, 12.0 * s]
                }
            }
            Self::WendlandC2 => {
                let s = 1.0 - q;
                let s2 = s * s;
                [
                    s2 * s2 * (1.0 + 4.0 * q),
                    -20.0 * q * s2 * s,
                    -20.0 * s2 * (1.0 - 4.0 * q),
                ]
            }
        }
    }

    /// Whether the profile has zero slope at the origin, so that the
    /// Laplacian there is finite (`d * w''(0)`).
    pub(crate) fn smooth_at_origin(self) -> bool {
        matches!(self, Self::Poly6 | Self::CubicSpline | Self::WendlandC2)
    }
}

/// A kernel of one kind, dimension and support radius.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kernel {
    kind: KernelKind,
    dim: usize,
    h: Real,
    inv_h: Real,
    /// `sigma_d / h^d`.
    norm: Real,
}

impl Kernel {
    /// A kernel of support radius `h` in `dim` (2 or 3) dimensions.
    ///
    /// # Panics
    /// When `dim` is not 2 or 3 (a programming error, never user input:
    /// scenes are validated first).
    pub fn new(kind: KernelKind, dim: usize, h: Real) -> Self {
        assert!(
            dim == 2 || dim == 3,
            "kernels exist in 2D and 3D, not {dim}D"
        );
        Self {
            kind,
            dim,
            h,
            inv_h: 1.0 / h,
            norm: kind.sigma(dim) / h.powi(dim as i32),
        }
    }

    /// A 3D kernel.
    pub fn new_3d(kind: KernelKind, h: Real) -> Self {
        Self::new(kind, 3, h)
    }

    /// Which profile this kernel evaluates.
    pub fn kind(&self) -> KernelKind {
        self.kind
    }

    /// The dimension (2 or 3) the normalisation `sigma_d / h^d` is for.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Support radius `h`.
    pub fn support(&self) -> Real {
        self.h
    }

    #[inline]
    fn profile(&self, r: Real) -> Option<[Real; 3]> {
        let q = r * self.inv_h;
        (q < 1.0).then(|| self.kind.profile(q))
    }

    /// `omega_h(r)` for `r >= 0`. The viscosity kernel is infinite at 0.
    #[inline]
    pub fn value(&self, r: Real) -> Real {
        match self.kind {
            // The poly6 profile needs no square root.
            KernelKind::Poly6 => self.value_sq(r * r),
            _ => self.profile(r).map_or(0.0, |p| self.norm * p[0]),
        }
    }

    /// `omega_h` from the squared distance. Saves a square root for poly6.
    #[inline]
    pub fn value_sq(&self, r2: Real) -> Real {
        match self.kind {
            KernelKind::Poly6 => {
                let s = 1.0 - r2 * self.inv_h * self.inv_h;
                if s > 0.0 { self.norm * s * s * s } else { 0.0 }
            }
            _ => self.value(r2.sqrt()),
        }
    }

    /// `d omega_h / dr`.
    #[inline]
    pub fn derivative(&self, r: Real) -> Real {
        self.profile(r)
            .map_or(0.0, |p| self.norm * self.inv_h * p[1])
    }

    /// `d^2 omega_h / dr^2`.
    #[inline]
    pub fn second_derivative(&self, r: Real) -> Real {
        self.profile(r)
            .map_or(0.0, |p| self.norm * self.inv_h * self.inv_h * p[2])
    }

    /// `grad_x omega_h(|x|)` at offset `x` with `|x| = r`; zero at `r = 0`
    /// where the direction is undefined.
    #[inline]
    pub fn gradient(&self, x: &Vector, r: Real) -> Vector {
        if r > Real::EPSILON * self.h {
            x * (self.derivative(r) / r)
        } else {
            Vector::zeros()
        }
    }

    /// `Delta omega_h(|x|) = omega'' + (d - 1) omega' / r`. At `r = 0` it is
    /// the limit `d omega''(0)` for kernels smooth at the origin; spiky and
    /// viscosity are singular there, and this returns 0 for them, which
    /// drops the self-pair from a sum (the corrected operators never need
    /// it: their self-term has the factor `f_i - f_i`).
    #[inline]
    pub fn laplacian(&self, r: Real) -> Real {
        if r > Real::EPSILON * self.h {
            self.second_derivative(r) + (self.dim - 1) as Real * self.derivative(r) / r
        } else if self.kind.smooth_at_origin() {
            self.dim as Real * self.norm * self.inv_h * self.inv_h * self.kind.profile(0.0)[2]
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `integral over R^d of omega` by the radial rule
    /// `int 2 pi r w dr` (2D) or `int 4 pi r^2 w dr` (3D), Gauss–Legendre
    /// on many panels so the singular viscosity profile integrates too.
    fn radial_integral(kernel: &Kernel) -> Real {
        let h = kernel.support();
        let panels = 4000;
        // 3-point Gauss-Legendre nodes and weights on [-1, 1].
        let nodes = [-(0.6 as Real).sqrt(), 0.0, (0.6 as Real).sqrt()];
        let weights = [5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0];
        let width = h / panels as Real;
        let mut sum = 0.0;
        for p in 0..panels {
            let mid = (p as Real + 0.5) * width;
            for (x, w) in nodes.iter().zip(weights) {
                let r = mid + 0.5 * width * x;
                let shell = if kernel.dim() == 2 {
                    2.0 * PI * r
                } else {
                    4.0 * PI * r * r
                };
                sum += w * 0.5 * width * shell * kernel.value(r);
            }
        }
        sum
    }

    /// Midpoint-rule integral over the cube `[-h, h]^3`: checks the radial
    /// evaluation in Cartesian space, independent of the radial rule.
    fn cartesian_integral_3d(kernel: &Kernel, n: usize) -> Real {
        let h = kernel.support();
        let cell = 2.0 * h / n as Real;
        let mut sum = 0.0;
        for i in 0..n {
            for j in 0..n {
                for k in 0..n {
                    let p = Vector::new(
                        -h + (i as Real + 0.5) * cell,
                        -h + (j as Real + 0.5) * cell,
                        -h + (k as Real + 0.5) * cell,
                    );
                    sum += kernel.value(p.norm());
                }
            }
        }
        sum * cell * cell * cell
    }

    /// Normalisation: every kernel in 2D and 3D integrates to one, for
    /// several support radii. The flattened text lost the constants; this
    /// pins the table of the module docs.
    #[test]
    fn kernels_integrate_to_one_in_2d_and_3d() {
        for kind in KernelKind::ALL {
            for dim in [2, 3] {
                for h in [0.01, 0.5, 3.0] {
                    let integral = radial_integral(&Kernel::new(kind, dim, h));
                    assert!(
                        (integral - 1.0).abs() < 1e-6,
                        "{kind:?} in {dim}D with h = {h} integrates to {integral}"
                    );
                }
            }
            // The viscosity kernel's 1/r singularity defeats a midpoint rule.
            if kind != KernelKind::Viscosity {
                let integral = cartesian_integral_3d(&Kernel::new_3d(kind, 0.5), 120);
                assert!(
                    (integral - 1.0).abs() < 1e-3,
                    "{kind:?}: cube sum {integral}"
                );
            }
        }
    }

    /// First and second radial derivatives against central differences, at
    /// distances across the support (away from the cubic spline's joint at
    /// q = 1/2, where the second derivative jumps).
    #[test]
    fn kernel_derivatives_match_finite_differences() {
        let h = 0.7;
        for kind in KernelKind::ALL {
            for dim in [2, 3] {
                let kernel = Kernel::new(kind, dim, h);
                for q in [0.05, 0.2, 0.37, 0.63, 0.8, 0.95] {
                    let r = q * h;
                    let eps = 1e-5 * h;
                    let d1 = (kernel.value(r + eps) - kernel.value(r - eps)) / (2.0 * eps);
                    let d2 = (kernel.value(r + eps) - 2.0 * kernel.value(r)
                        + kernel.value(r - eps))
                        / (eps * eps);
                    // Relative to the derivative itself, or to the kernel's
                    // scale where the derivative crosses zero.
                    let scale = kernel.value(0.3 * h).abs() / (h * h);
                    let tol1 = 1e-6 * kernel.derivative(r).abs().max(scale * h);
                    let tol2 = 1e-3 * kernel.second_derivative(r).abs().max(scale);
                    assert!(
                        (d1 - kernel.derivative(r)).abs() < tol1,
                        "{kind:?} {dim}D w'({q}h): analytic {} vs numeric {d1}",
                        kernel.derivative(r)
                    );
                    assert!(
                        (d2 - kernel.second_derivative(r)).abs() < tol2,
                        "{kind:?} {dim}D w''({q}h): analytic {} vs numeric {d2}",
                        kernel.second_derivative(r)
                    );
                }
            }
        }
    }

    /// The gradient and the full Laplacian `w'' + (d-1) w'/r` against
    /// finite differences of the kernel as a function of position.
    #[test]
    fn kernel_gradient_and_laplacian_match_finite_differences() {
        let h = 0.7;
        let offsets = [
            Vector::new(0.1, 0.05, -0.2),
            Vector::new(-0.3, 0.2, 0.25),
            Vector::new(0.0, 0.5, 0.1),
            Vector::new(0.03, -0.02, 0.015),
        ];
        for kind in KernelKind::ALL {
            for dim in [2, 3] {
                let kernel = Kernel::new(kind, dim, h);
                for mut x in offsets {
                    if dim == 2 {
                        x.z = 0.0;
                    }
                    // A step relative to the distance keeps the truncation
                    // error small near the viscosity kernel's singularity.
                    let eps = 1e-3 * x.norm();
                    let at = |p: Vector| kernel.value(p.norm());
                    let analytic = kernel.gradient(&x, x.norm());
                    let mut laplacian = 0.0;
                    for axis in 0..dim {
                        let mut e = Vector::zeros();
                        e[axis] = eps;
                        let numeric = (at(x + e) - at(x - e)) / (2.0 * eps);
                        let scale = analytic.norm().max(1.0);
                        assert!(
                            (numeric - analytic[axis]).abs() < 1e-5 * scale,
                            "{kind:?} {dim}D gradient at {x:?}, axis {axis}"
                        );
                        laplacian += (at(x + e) - 2.0 * at(x) + at(x - e)) / (eps * eps);
                    }
                    let exact = kernel.laplacian(x.norm());
                    assert!(
                        (laplacian - exact).abs() < 1e-3 * exact.abs().max(1.0),
                        "{kind:?} {dim}D Laplacian at {x:?}: analytic {exact} vs numeric {laplacian}"
                    );
                }
            }
        }
    }

    /// Müller's viscosity kernel was built for its Laplacian,
    /// `45 / (pi h^6) (h - r)` in 3D: positive everywhere in the support.
    #[test]
    fn viscosity_laplacian_is_the_closed_form() {
        let h = 0.4;
        let kernel = Kernel::new_3d(KernelKind::Viscosity, h);
        for r in [0.01, 0.1, 0.25, 0.39] {
            let closed = 45.0 / (PI * h.powi(6)) * (h - r);
            assert!((kernel.laplacian(r) - closed).abs() < 1e-9 * closed);
        }
    }

    #[test]
    fn kernels_vanish_outside_their_support() {
        for kind in KernelKind::ALL {
            let kernel = Kernel::new_3d(kind, 0.2);
            assert_eq!(kernel.value(0.2), 0.0);
            assert_eq!(kernel.value(0.3), 0.0);
            assert_eq!(kernel.derivative(0.2), 0.0);
            assert!(kernel.value(0.1) > 0.0, "{kind:?}");
        }
    }

    #[test]
    fn poly6_value_from_squared_distance_matches_value() {
        let kernel = Kernel::new_3d(KernelKind::Poly6, 1.3);
        for r in [0.0, 0.2, 0.9, 1.29, 1.31] {
            assert_eq!(kernel.value_sq(r * r), kernel.value(r));
            let profile = kernel.profile(r).map_or(0.0, |p| kernel.norm * p[0]);
            assert!((profile - kernel.value(r)).abs() < 1e-12 * kernel.norm);
        }
    }
}
