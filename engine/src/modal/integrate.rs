//! Implicit integration of the decoupled modal equations
//! `zddot + C_z zdot + K_z z = F_z` (Guo & Qin Eq. 25 / 30, after
//! Baraff & Witkin 1998): the force at the end of the step is linearised,
//! `dzdot = h (F_0 - K_z (z0 + dz) - C_z (zdot0 + dzdot))` with
//! `dz = h (zdot0 + dzdot)`, which regroups into Eq. 31,
//! `A_z dzdot = b_z`, `A_z = I + h C_z + h^2 K_z`,
//! `b_z = h (F_0 - K_z z0 - (C_z + h K_z) zdot0)`.
//!
//! For linear modal forces this is backward Euler: first order, and
//! unconditionally stable (each mode's amplification has modulus
//! `1 / sqrt(1 + h c + h^2 k) <= 1`), so a stiff mode never limits the
//! step; it only damps it. `A_z` is diagonal, so the unconstrained solve
//! is a division per mode.

use nalgebra::DVector;

use super::ModalError;
use crate::math::Real;

/// Rayleigh damping `C = alpha M + beta K`, i.e. `C_z = alpha I + beta
/// Lambda` in modal coordinates (Eq. 25): mass-proportional damping
/// slows the rigid and soft modes, stiffness-proportional damping the
/// stiff ones.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Damping {
    alpha: Real,
    beta: Real,
}

impl Damping {
    /// Damping with coefficients `alpha` (1/s) and `beta` (s).
    ///
    /// # Errors
    /// [`ModalError::Coefficient`] when one is negative or not finite
    /// (negative damping adds energy and breaks the stability above).
    pub fn new(alpha: Real, beta: Real) -> Result<Self, ModalError> {
        for (name, value) in [("alpha", alpha), ("beta", beta)] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(ModalError::Coefficient { name, value });
            }
        }
        Ok(Self { alpha, beta })
    }

    /// The mass-proportional coefficient `alpha`.
    pub fn alpha(&self) -> Real {
        self.alpha
    }

    /// The stiffness-proportional coefficient `beta`.
    pub fn beta(&self) -> Real {
        self.beta
    }
}

/// Fills the diagonal `a` of `A_z` and the right-hand side `b` of Eq. 31
/// for step `h`, modal stiffnesses `lambda`, modal force `force` and the
/// state `(z, zdot)` at the start of the step.
pub(super) fn assemble(
    h: Real,
    lambda: &DVector<Real>,
    damping: Damping,
    force: &DVector<Real>,
    (z, zdot): (&DVector<Real>, &DVector<Real>),
    a: &mut DVector<Real>,
    b: &mut DVector<Real>,
) {
    for (j, &k) in lambda.iter().enumerate() {
        let c = damping.alpha + damping.beta * k;
        a[j] = 1.0 + h * c + h * h * k;
        b[j] = h * (force[j] - k * z[j] - (c + h * k) * zdot[j]);
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::DMatrix;

    use super::*;
    use crate::math::Vector;
    use crate::modal::{ModalBasis, ModalSystem};

    const TAU: Real = std::f64::consts::TAU;

    /// One node, one mode along x of stiffness `k`: `F_z` is the x load.
    fn oscillator(k: Real, damping: Damping) -> ModalSystem {
        let psi = DMatrix::from_column_slice(3, 1, &[1.0, 0.0, 0.0]);
        let basis = ModalBasis::new(&DVector::from_element(1, k), &psi, &DMatrix::zeros(3, 1))
            .expect("valid");
        ModalSystem::new(basis, damping, false)
    }

    /// `z(t)` of `z'' + c z' + k z = f` from `(z0, v0)`, underdamped.
    fn exact(k: Real, c: Real, f: Real, (z0, v0): (Real, Real), t: Real) -> Real {
        let zp = f / k;
        let e0 = z0 - zp;
        let sigma = 0.5 * c;
        let wd = (k - sigma * sigma).sqrt();
        zp + (-sigma * t).exp() * (e0 * (wd * t).cos() + (v0 + sigma * e0) / wd * (wd * t).sin())
    }

    #[test]
    fn one_mode_converges_at_first_order_to_the_damped_oscillator() {
        let k = TAU * TAU; // period 1 s
        let damping = Damping::new(0.5, 0.01).expect("valid");
        let c = damping.alpha() + damping.beta() * k;
        let (f, start) = (3.0, (0.2, -1.0));
        let steps = [100, 200, 400, 800, 1600];
        let errors: Vec<Real> = steps
            .iter()
            .map(|&n| {
                let mut system = oscillator(k, damping);
                let state = (
                    DVector::from_element(1, start.0),
                    DVector::from_element(1, start.1),
                );
                system.set_state(&state.0, &state.1).expect("valid");
                let h = 1.0 / n as Real;
                for _ in 0..n {
                    system
                        .step(h, &[Vector::new(f, 0.0, 0.0)])
                        .expect("valid step");
                }
                (system.amplitudes()[0] - exact(k, c, f, start, 1.0)).abs()
            })
            .collect();
        let orders: Vec<Real> = errors.windows(2).map(|e| (e[0] / e[1]).log2()).collect();
        // Backward Euler: the measured order climbs to 1 as h halves
        // (0.90, 0.95, 0.97, 0.99 here, the O(h^2) term fading).
        for (i, pair) in orders.windows(2).enumerate() {
            assert!(
                pair[0] < pair[1] && pair[1] < 1.01,
                "orders {orders:?} should rise towards 1 (steps {:?}, errors {errors:?})",
                &steps[i..i + 3]
            );
        }
        let finest = orders[orders.len() - 1];
        assert!(
            (finest - 1.0).abs() < 0.02,
            "order {finest} at {} steps",
            steps[steps.len() - 1]
        );
    }

    #[test]
    fn a_step_of_a_thousand_periods_is_stable() {
        let k = TAU * TAU;
        let h = 1e3; // 1e3 periods
        for damping in [Damping::new(0.0, 0.0), Damping::new(0.5, 0.01)] {
            let mut system = oscillator(k, damping.expect("valid"));
            let z0 = DVector::from_element(1, 1.0);
            system
                .set_state(&z0, &DVector::from_element(1, 5.0))
                .expect("valid");
            let energy = |s: &ModalSystem| {
                0.5 * s.velocities()[0].powi(2) + 0.5 * k * s.amplitudes()[0].powi(2)
            };
            let mut last = energy(&system);
            let first = last;
            for step in 0..10 {
                system.step(h, &[Vector::zeros()]).expect("valid step");
                let now = energy(&system);
                assert!(
                    now.is_finite() && now <= last,
                    "step {step}: energy {last} -> {now}"
                );
                last = now;
            }
            assert!(last < 1e-12 * first, "energy {first} -> {last}");
            // Under a constant load it settles on the static answer f / k.
            let f = 2.0;
            for _ in 0..10 {
                system
                    .step(h, &[Vector::new(f, 0.0, 0.0)])
                    .expect("valid step");
            }
            let z = system.amplitudes()[0];
            assert!(
                (z - f / k).abs() < 1e-9 * f / k,
                "z = {z}, static {}",
                f / k
            );
        }
    }

    #[test]
    fn negative_or_non_finite_damping_is_refused() {
        for (alpha, beta, name) in [(-1.0, 0.0, "alpha"), (0.0, Real::NAN, "beta")] {
            match Damping::new(alpha, beta) {
                Err(ModalError::Coefficient { name: got, .. }) => assert_eq!(got, name),
                other => panic!("({alpha}, {beta}) gave {other:?}"),
            }
        }
    }
}
