//! SPH smoothing kernels in 3D, normalised so that their integral over
//! space is 1 (Adams–Wicke tutorial, Appendix A; Müller et al. 2003).
//!
//! Every kernel has compact support of radius `h`: it is zero for `d >= h`.

use crate::math::{Real, Vector};
use std::f64::consts::PI;

/// A radially symmetric smoothing kernel `omega_h(d)` of support radius `h`.
pub trait Kernel: Sync {
    /// Support radius `h`.
    fn support(&self) -> Real;
    /// `omega_h(d)` for a distance `d >= 0`.
    fn value(&self, d: Real) -> Real;
    /// `d omega_h / d d` for a distance `d >= 0`.
    fn derivative(&self, d: Real) -> Real;

    /// `grad_x omega_h(|x|)` at offset `x` with `|x| = d`. Zero at `d = 0`,
    /// where the direction is undefined and symmetric kernels have no slope.
    #[inline]
    fn gradient(&self, x: &Vector, d: Real) -> Vector {
        if d > Real::EPSILON * self.support() {
            x * (self.derivative(d) / d)
        } else {
            Vector::zeros()
        }
    }
}

/// The poly6 kernel of Müller et al., tutorial Eq. 86:
/// `omega(d) = 315 / (64 pi h^3) (1 - d^2/h^2)^3` for `d < h`.
///
/// Smooth at the origin and cheap: it needs only `d^2`. Used for density
/// and XSPH averaging.
#[derive(Debug, Clone, Copy)]
pub struct Poly6 {
    h: Real,
    inv_h2: Real,
    norm: Real,
}

impl Poly6 {
    pub fn new(h: Real) -> Self {
        Self {
            h,
            inv_h2: 1.0 / (h * h),
            norm: 315.0 / (64.0 * PI * h * h * h),
        }
    }

    /// `omega(d)` from the squared distance, without a square root.
    #[inline]
    pub fn value_sq(&self, d2: Real) -> Real {
        let q = 1.0 - d2 * self.inv_h2;
        if q > 0.0 { self.norm * q * q * q } else { 0.0 }
    }
}

impl Kernel for Poly6 {
    fn support(&self) -> Real {
        self.h
    }

    #[inline]
    fn value(&self, d: Real) -> Real {
        self.value_sq(d * d)
    }

    /// Tutorial Eq. 87: `-945 / (32 pi h^3) (d / h^2) (1 - d^2/h^2)^2`.
    #[inline]
    fn derivative(&self, d: Real) -> Real {
        let q = 1.0 - d * d * self.inv_h2;
        if q > 0.0 {
            -6.0 * self.norm * d * self.inv_h2 * q * q
        } else {
            0.0
        }
    }
}

/// The spiky kernel of Müller et al., tutorial Eq. 92:
/// `omega(d) = 15 / (pi h^3) (1 - d/h)^3` for `d < h`.
///
/// Its slope does not vanish at the origin, so pressure forces keep
/// particles from clumping. Used for the pressure gradient.
#[derive(Debug, Clone, Copy)]
pub struct Spiky {
    h: Real,
    inv_h: Real,
    norm: Real,
}

impl Spiky {
    pub fn new(h: Real) -> Self {
        Self {
            h,
            inv_h: 1.0 / h,
            norm: 15.0 / (PI * h * h * h),
        }
    }
}

impl Kernel for Spiky {
    fn support(&self) -> Real {
        self.h
    }

    #[inline]
    fn value(&self, d: Real) -> Real {
        let q = 1.0 - d * self.inv_h;
        if q > 0.0 { self.norm * q * q * q } else { 0.0 }
    }

    /// Tutorial Eq. 93: `-45 / (pi h^4) (1 - d/h)^2`.
    #[inline]
    fn derivative(&self, d: Real) -> Real {
        let q = 1.0 - d * self.inv_h;
        if q > 0.0 {
            -3.0 * self.norm * self.inv_h * q * q
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Midpoint-rule integral of a kernel over the cube `[-h, h]^3` with `n`
    /// cells per axis.
    fn integral_3d(kernel: &dyn Kernel, n: usize) -> Real {
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

    /// Normalisation: a kernel approximates the Dirac delta only if it
    /// integrates to one. The flattened text of Eq. 86 and 92 lost the
    /// constants; this pins them for several support radii.
    #[test]
    fn kernels_integrate_to_one_in_3d() {
        for h in [0.01, 0.5, 3.0] {
            let kernels: [(&str, Box<dyn Kernel>); 2] = [
                ("poly6", Box::new(Poly6::new(h))),
                ("spiky", Box::new(Spiky::new(h))),
            ];
            for (name, kernel) in kernels {
                let integral = integral_3d(kernel.as_ref(), 120);
                assert!(
                    (integral - 1.0).abs() < 1e-3,
                    "{name} with h = {h} integrates to {integral}, not 1"
                );
            }
        }
    }

    /// The analytic derivatives (Eq. 87, 93) against central differences of
    /// the values, at distances across the whole support.
    #[test]
    fn kernel_gradients_match_finite_differences() {
        let h = 0.7;
        let kernels: [(&str, Box<dyn Kernel>); 2] = [
            ("poly6", Box::new(Poly6::new(h))),
            ("spiky", Box::new(Spiky::new(h))),
        ];
        let offsets = [
            Vector::new(0.1, 0.05, -0.2),
            Vector::new(-0.3, 0.2, 0.25),
            Vector::new(0.0, 0.6, 0.1),
            Vector::new(0.01, -0.02, 0.015),
        ];
        let eps = 1e-6;
        for (name, kernel) in kernels {
            for x in offsets {
                let analytic = kernel.gradient(&x, x.norm());
                for axis in 0..3 {
                    let mut e = Vector::zeros();
                    e[axis] = eps;
                    let numeric =
                        (kernel.value((x + e).norm()) - kernel.value((x - e).norm())) / (2.0 * eps);
                    let scale = analytic.norm().max(1.0);
                    assert!(
                        (numeric - analytic[axis]).abs() < 1e-6 * scale,
                        "{name} gradient at {x:?}, axis {axis}: analytic {} vs numeric {numeric}",
                        analytic[axis]
                    );
                }
            }
        }
    }

    #[test]
    fn kernels_vanish_outside_their_support() {
        let h = 0.2;
        for kernel in [&Poly6::new(h) as &dyn Kernel, &Spiky::new(h)] {
            assert_eq!(kernel.value(h), 0.0);
            assert_eq!(kernel.value(1.5 * h), 0.0);
            assert_eq!(kernel.derivative(h), 0.0);
            assert!(kernel.value(0.5 * h) > 0.0);
        }
    }

    #[test]
    fn poly6_value_from_squared_distance_matches_value() {
        let kernel = Poly6::new(1.3);
        for d in [0.0, 0.2, 0.9, 1.29, 1.31] {
            assert_eq!(kernel.value_sq(d * d), kernel.value(d));
        }
    }
}
