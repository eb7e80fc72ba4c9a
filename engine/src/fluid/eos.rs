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
}
