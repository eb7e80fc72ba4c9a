//! The constitutive law of the elastic solids (tutorial Section 7.1;
//! Müller et al. 2004), written in terms of the deformation gradient
//! `F = I + grad u` so that forces are exact derivatives of one energy:
//!
//! ```text
//! E = (F^T F - I) / 2 = (grad u + grad u^T + grad u^T grad u) / 2   (Eq. 61)
//! S = lambda tr(E) I + 2 mu E                                         (Eq. 62, isotropic)
//! W = E : S / 2                                                       (Eq. 63)
//! W_vol = k_v (det F - 1)^2 / 2                                       (Eq. 65's energy)
//! P = dW/dF = F S + k_v (det F - 1) cof F                             (Eq. 64 per unit volume)
//! ```
//!
//! `P` is the first Piola–Kirchhoff stress. The tutorial's Eq. 64 takes
//! the force as `-grad_u W`; by the chain rule through the MLS gradient
//! that is `-V P g` for every neighbour weight `g` (see `forces.rs`).
//! Eq. 65's volume force `-k_v grad_u (|I + grad u| - 1)^2` is the same
//! derivative of `W_vol` (its factor is folded into `k_v`). Green–Saint-
//! Venant strain is invariant under rotation, so a rigidly rotated body
//! has `E = 0`, `P = 0` and no force.
//!
//! In 2D the matrices keep their third row and column with `F_zz = 1`:
//! plane strain.
//!
//! **St Venant–Kirchhoff collapses.** Its energy grows with Green strain,
//! which a compression past a stretch of `1/sqrt(3)` starts to *reduce*:
//! the force along a squashed direction is `F S`, and at a stretch of 0 it
//! is zero, so a soft block under its own weight (E = 1 kPa, nu = 0.49)
//! flattened into one layer of particles and stayed there. The stable
//! neo-Hookean energy of Smith, de Goes & Kim (2018, "Stable Neo-Hookean
//! Flesh Simulation", Eq. 14 without its rest-stability log term, with its
//! Lamé parameters matched to linear elasticity),
//!
//! ```text
//! W = mu/2 (tr F^T F - 3) + (lambda + mu)/2 (J - alpha)^2 - W_0,  alpha = 1 + mu / (lambda + mu)
//! P = mu F + (lambda + mu) (J - alpha) cof F
//! ```
//!
//! with `J = det F`, resists compression all the way through inversion
//! (`J <= 0` is finite and pushes back; no logarithm of `J`, so an
//! inverted particle does not break it) and agrees with Hooke's law to
//! first order, so small-strain results match St Venant–Kirchhoff's. It
//! was chosen over corotated linear elasticity because it is a true
//! hyperelastic energy (the implicit solver's Newton steps and the
//! energies frames report need one) and needs no polar decomposition,
//! whose rotation is ill-defined at inversion.

use crate::math::Real;
use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

/// The hyperelastic energy of a solid (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Hyperelastic {
    /// St Venant–Kirchhoff (tutorial Eq. 61-64): exact for large
    /// rotations, but stops resisting compression past a stretch of
    /// `1/sqrt(3)`; plasticity needs it.
    #[default]
    StVenantKirchhoff,
    /// Stable neo-Hookean (Smith, de Goes & Kim 2018): resists
    /// compression through inversion.
    StableNeoHookean,
}

impl Hyperelastic {
    /// Whether this is the default, St Venant–Kirchhoff (which a scene
    /// file need not spell out).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }
}

/// Lamé parameters of an isotropic material plus the volume stiffness.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// First Lamé parameter, Pa.
    pub lambda: Real,
    /// Shear modulus, Pa.
    pub mu: Real,
    /// `k_v` of Eq. 65, Pa; 0 turns the volume force off.
    pub volume_stiffness: Real,
    /// The energy.
    pub model: Hyperelastic,
}

/// Stress state at one particle, kept to linearise about it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StressState {
    /// Deformation gradient `F = I + grad u`.
    pub f: Matrix3<Real>,
    /// Elastic strain: Green strain less any plastic strain.
    pub e: Matrix3<Real>,
    /// Second Piola–Kirchhoff stress of the elastic strain.
    pub s: Matrix3<Real>,
    /// `det F` and `cof F`, for the volume term.
    pub det: Real,
    /// Cofactor `cof F` (`det F F^-T` where `F` is invertible), the
    /// derivative of `det F` in Eq. 65's volume term.
    pub cof: Matrix3<Real>,
}

impl Material {
    /// From Young's modulus `young` (Pa) and Poisson's ratio `poisson`
    /// (in [0, 0.5)).
    pub fn from_young_poisson(young: Real, poisson: Real, volume_stiffness: Real) -> Self {
        Self {
            lambda: young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson)),
            mu: young / (2.0 * (1.0 + poisson)),
            volume_stiffness,
            model: Hyperelastic::StVenantKirchhoff,
        }
    }

    /// The same constants with the energy `model`.
    pub fn with_model(self, model: Hyperelastic) -> Self {
        Self { model, ..self }
    }

    /// The stable neo-Hookean's `(lambda + mu, alpha)`.
    fn neo_hookean(&self) -> (Real, Real) {
        let bulk = self.lambda + self.mu;
        (bulk, 1.0 + self.mu / bulk)
    }

    /// The state of an undeformed particle.
    pub fn rest_state() -> StressState {
        StressState {
            f: Matrix3::identity(),
            e: Matrix3::zeros(),
            s: Matrix3::zeros(),
            det: 1.0,
            cof: Matrix3::identity(),
        }
    }

    /// P-wave modulus `lambda + 2 mu + k_v`: the stiffness that sets the
    /// fastest wave and so the explicit step limit.
    pub fn wave_modulus(&self) -> Real {
        self.lambda + 2.0 * self.mu + self.volume_stiffness
    }

    /// `S = C : E`.
    pub fn hooke(&self, e: &Matrix3<Real>) -> Matrix3<Real> {
        Matrix3::identity() * (self.lambda * e.trace()) + e * (2.0 * self.mu)
    }

    /// The stress state at `f`, with `plastic` strain removed from the
    /// Green strain (Eq. 69).
    pub fn state(&self, f: Matrix3<Real>, plastic: Option<&Matrix3<Real>>) -> StressState {
        let mut e = green_strain(&f);
        if let Some(p) = plastic {
            e -= p;
        }
        StressState {
            f,
            e,
            s: match self.model {
                Hyperelastic::StVenantKirchhoff => self.hooke(&e),
                // Not needed: its stress is written in F directly.
                Hyperelastic::StableNeoHookean => Matrix3::zeros(),
            },
            det: f.determinant(),
            cof: cofactor(&f),
        }
    }

    /// `P = dW/dF` at `state`.
    pub fn first_piola(&self, state: &StressState) -> Matrix3<Real> {
        let volume = state.cof * (self.volume_stiffness * (state.det - 1.0));
        match self.model {
            Hyperelastic::StVenantKirchhoff => state.f * state.s + volume,
            Hyperelastic::StableNeoHookean => {
                let (bulk, alpha) = self.neo_hookean();
                state.f * self.mu + state.cof * (bulk * (state.det - alpha)) + volume
            }
        }
    }

    /// Strain energy density `W + W_vol` at `state`, J/m^3 (zero at rest).
    pub fn energy_density(&self, state: &StressState) -> Real {
        let dv = state.det - 1.0;
        let volume = 0.5 * self.volume_stiffness * dv * dv;
        match self.model {
            Hyperelastic::StVenantKirchhoff => 0.5 * state.e.dot(&state.s) + volume,
            Hyperelastic::StableNeoHookean => {
                let (bulk, alpha) = self.neo_hookean();
                // tr F^T F - 3 = 2 tr E.
                self.mu * state.e.trace()
                    + 0.5 * bulk * ((state.det - alpha).powi(2) - (1.0 - alpha).powi(2))
                    + volume
            }
        }
    }

    /// The directional derivative `dP[dF]` of [`Self::first_piola`] at
    /// `state`, for the implicit integrator's tangent stiffness.
    pub fn first_piola_derivative(&self, state: &StressState, df: &Matrix3<Real>) -> Matrix3<Real> {
        // cof is quadratic in F: cof(F + dF) = cof F + L(F, dF) + cof dF
        // exactly, so its linear part needs no division.
        let d_cof = || cofactor(&(state.f + df)) - state.cof - cofactor(df);
        let mut dp = match self.model {
            Hyperelastic::StVenantKirchhoff => {
                let de = (df.transpose() * state.f + state.f.transpose() * df) * 0.5;
                df * state.s + state.f * self.hooke(&de)
            }
            Hyperelastic::StableNeoHookean => {
                let (bulk, alpha) = self.neo_hookean();
                df * self.mu
                    + (state.cof * state.cof.dot(df) + d_cof() * (state.det - alpha)) * bulk
            }
        };
        if self.volume_stiffness != 0.0 {
            let d_det = state.cof.dot(df);
            dp += (state.cof * d_det + d_cof() * (state.det - 1.0)) * self.volume_stiffness;
        }
        dp
    }
}

/// Green–Saint-Venant strain `(F^T F - I) / 2` (Eq. 61).
pub fn green_strain(f: &Matrix3<Real>) -> Matrix3<Real> {
    (f.transpose() * f - Matrix3::identity()) * 0.5
}

/// Cofactor matrix, `d det F / dF` (`det F F^-T` where F is invertible,
/// and defined where it is not).
pub fn cofactor(f: &Matrix3<Real>) -> Matrix3<Real> {
    let c = |r0: usize, r1: usize, c0: usize, c1: usize| {
        f[(r0, c0)] * f[(r1, c1)] - f[(r0, c1)] * f[(r1, c0)]
    };
    Matrix3::new(
        c(1, 2, 1, 2),
        -c(1, 2, 0, 2),
        c(1, 2, 0, 1),
        -c(0, 2, 1, 2),
        c(0, 2, 0, 2),
        -c(0, 2, 0, 1),
        c(0, 1, 1, 2),
        -c(0, 1, 0, 2),
        c(0, 1, 0, 1),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn materials() -> [Material; 2] {
        let svk = Material::from_young_poisson(1e5, 0.3, 2e4);
        [svk, svk.with_model(Hyperelastic::StableNeoHookean)]
    }

    /// An arbitrary, well-conditioned deformation gradient.
    fn deformed() -> Matrix3<Real> {
        Matrix3::new(1.1, 0.2, -0.05, 0.03, 0.9, 0.1, -0.1, 0.04, 1.05)
    }

    /// Both energies rest at zero with zero stress, and agree with Hooke's
    /// law (`P = lambda tr(eps) I + 2 mu eps`) to first order: the stable
    /// neo-Hookean's Lamé parameters are matched to linear elasticity.
    #[test]
    fn both_rest_at_zero_and_agree_with_hooke_at_small_strain() {
        let grad = Matrix3::new(0.3, -0.2, 0.1, 0.5, -0.4, 0.2, -0.1, 0.3, 0.25) * 1e-7;
        for m in materials() {
            let rest = m.state(Matrix3::identity(), None);
            assert_eq!(m.energy_density(&rest), 0.0, "{:?}", m.model);
            assert!(m.first_piola(&rest).norm() < 1e-9, "{:?}", m.model);
            let eps = (grad + grad.transpose()) * 0.5;
            let hooke = m.hooke(&eps) + Matrix3::identity() * (m.volume_stiffness * eps.trace());
            let p = m.first_piola(&m.state(Matrix3::identity() + grad, None));
            assert!(
                (p - hooke).norm() < 1e-6 * hooke.norm(),
                "{:?}: {p} against {hooke}",
                m.model
            );
        }
    }

    /// `P` is the derivative of the energy and `dP` that of `P`: central
    /// differences at a finite deformation, for both energies.
    #[test]
    fn the_stress_and_the_tangent_are_the_energys_derivatives() {
        let f = deformed();
        let h = 1e-6;
        for m in materials() {
            let state = m.state(f, None);
            let p = m.first_piola(&state);
            let dir = Matrix3::new(0.2, -0.1, 0.3, 0.05, 0.4, -0.2, 0.1, 0.1, -0.3);
            let energy = |g: Matrix3<Real>| m.energy_density(&m.state(g, None));
            let numeric = (energy(f + dir * h) - energy(f - dir * h)) / (2.0 * h);
            assert!(
                (numeric - p.dot(&dir)).abs() < 1e-6 * p.norm(),
                "{:?}: dW {numeric} against P:dF {}",
                m.model,
                p.dot(&dir)
            );
            let stress = |g: Matrix3<Real>| m.first_piola(&m.state(g, None));
            let numeric = (stress(f + dir * h) - stress(f - dir * h)) / (2.0 * h);
            let tangent = m.first_piola_derivative(&state, &dir);
            assert!(
                (numeric - tangent).norm() < 1e-6 * tangent.norm(),
                "{:?}: dP {numeric} against {tangent}",
                m.model
            );
        }
    }

    /// Squeezing along one axis (`F = diag(1, 1, s)`, lateral stretch held):
    /// St Venant–Kirchhoff's push-back `P_33 = (lambda/2 + mu) s (s^2 - 1)`
    /// is strongest at `s = 1/sqrt(3)` and vanishes at 0, so a squashed
    /// particle stops resisting; the stable neo-Hookean's is
    /// `(lambda + 2 mu)(s - 1)`, growing all the way to `s = 0` and on
    /// through inversion.
    #[test]
    fn st_venant_kirchhoff_stops_resisting_compression_and_neo_hookean_does_not() {
        let [svk, snh] = materials().map(|m| Material {
            volume_stiffness: 0.0,
            ..m
        });
        let push = |m: &Material, s: Real| {
            m.first_piola(&m.state(Matrix3::from_diagonal(&[1.0, 1.0, s].into()), None))[(2, 2)]
        };
        let (lambda, mu) = (svk.lambda, svk.mu);
        for k in 0..=24 {
            let s = 1.0 - k as Real * 0.05;
            let exact = (lambda / 2.0 + mu) * s * (s * s - 1.0);
            assert!((push(&svk, s) - exact).abs() < 1e-9 * lambda, "StVK at {s}");
            let exact = (lambda + 2.0 * mu) * (s - 1.0);
            assert!((push(&snh, s) - exact).abs() < 1e-9 * lambda, "SNH at {s}");
        }
        let weakest = 1.0 / (3.0 as Real).sqrt();
        assert!(push(&svk, weakest) < push(&svk, 0.3) && push(&svk, 0.3) < push(&svk, 0.05));
        assert!(
            push(&svk, 0.0).abs() < 1e-9,
            "StVK holds nothing at a stretch of 0"
        );
        assert!(push(&snh, 0.0) < push(&snh, weakest) && push(&snh, -0.2) < push(&snh, 0.0));
    }
}
