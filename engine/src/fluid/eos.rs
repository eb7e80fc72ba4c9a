//! Equations of state: pressure as a function of density.

use crate::math::Real;

/// The Tait equation (tutorial Eq. 47) with negative-pressure scaling
/// (Eq. 54): `p = K ((rho / rho_0)^gamma - 1)`, and `p <- zeta p` where
/// `p < 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tait {
    /// K, Pa.
    pub stiffness: Real,
    /// gamma: 7 after Monaghan, 1 in much graphics work.
    pub gamma: Real,
    /// rho_0, kg/m^3.
    pub rest_density: Real,
    /// zeta in [0, 1]: 0 clamps negative pressures (no cohesion at free
    /// surfaces), 1 keeps them.
    pub negative_scale: Real,
}

impl Tait {
    /// Pressure at density `rho`.
    #[inline]
    pub fn pressure(&self, rho: Real) -> Real {
        let ratio = rho / self.rest_density;
        let power = if self.gamma == 7.0 {
            let r2 = ratio * ratio;
            r2 * r2 * r2 * ratio
        } else if self.gamma == 1.0 {
            ratio
        } else {
            ratio.powf(self.gamma)
        };
        let p = self.stiffness * (power - 1.0);
        if p < 0.0 { self.negative_scale * p } else { p }
    }

    /// Energy stored per unit mass at density `rho`, J/kg: the work
    /// `int_rho0^rho p(r) / r^2 dr` of compressing (or, with `zeta > 0`,
    /// stretching) the fluid from rest, so that `d e / d rho = p / rho^2`.
    pub fn energy(&self, rho: Real) -> Real {
        let (k, g, r0) = (self.stiffness, self.gamma, self.rest_density);
        // The antiderivative of K ((r / r0)^g - 1) / r^2.
        let primitive = |r: Real| {
            if g == 1.0 {
                k * ((r / r0).ln() + r0 / r) / r0
            } else {
                k * (r.powf(g - 1.0) / ((g - 1.0) * r0.powf(g)) + 1.0 / r)
            }
        };
        let e = primitive(rho) - primitive(r0);
        if rho < r0 { self.negative_scale * e } else { e }
    }

    /// Speed of sound at rest, `sqrt(dp/drho) = sqrt(gamma K / rho_0)`; it
    /// sets the CFL limit of the explicit solver.
    pub fn sound_speed(&self) -> Real {
        (self.gamma * self.stiffness / self.rest_density).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tait(gamma: Real, zeta: Real) -> Tait {
        Tait {
            stiffness: 2.0e5,
            gamma,
            rest_density: 1000.0,
            negative_scale: zeta,
        }
    }

    #[test]
    fn tait_vanishes_at_rest_density() {
        for gamma in [1.0, 7.0, 3.5] {
            assert_eq!(tait(gamma, 0.5).pressure(1000.0), 0.0);
        }
    }

    /// Eq. 47 evaluated by hand for both common exponents and a general one.
    #[test]
    fn tait_matches_eq_47() {
        let rho = 1013.0;
        for gamma in [1.0, 7.0, 2.5] {
            let expected = 2.0e5 * ((rho / 1000.0 as Real).powf(gamma) - 1.0);
            let p = tait(gamma, 0.0).pressure(rho);
            assert!(
                (p - expected).abs() < 1e-9 * expected.abs(),
                "gamma {gamma}: {p} vs {expected}"
            );
        }
    }

    /// Eq. 54: negative pressures are multiplied by zeta.
    #[test]
    fn negative_pressure_is_scaled() {
        let rho = 990.0;
        let full = tait(7.0, 1.0).pressure(rho);
        assert!(full < 0.0);
        assert_eq!(tait(7.0, 0.0).pressure(rho), 0.0);
        assert!((tait(7.0, 0.25).pressure(rho) - 0.25 * full).abs() < 1e-9 * full.abs());
    }

    #[test]
    fn sound_speed_is_sqrt_gamma_k_over_rho() {
        assert!((tait(7.0, 0.0).sound_speed() - (1400.0 as Real).sqrt()).abs() < 1e-12);
    }

    /// `d e / d rho = p / rho^2`, on both sides of the rest density, for
    /// the exponents with their own branches and a general one.
    #[test]
    fn energy_is_the_work_of_the_pressure() {
        for gamma in [1.0, 7.0, 2.5] {
            let eos = tait(gamma, 0.5);
            assert_eq!(eos.energy(1000.0), 0.0);
            for rho in [950.0, 990.0, 1010.0, 1100.0] {
                let h = 1e-3;
                let slope = (eos.energy(rho + h) - eos.energy(rho - h)) / (2.0 * h);
                let expected = eos.pressure(rho) / (rho * rho);
                assert!(
                    (slope - expected).abs() < 1e-6 * expected.abs(),
                    "gamma {gamma}, rho {rho}: {slope} against {expected}"
                );
                assert!(eos.energy(rho) > 0.0, "stored energy is positive");
            }
        }
    }
}
