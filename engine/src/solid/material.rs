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

use crate::math::Real;
use nalgebra::Matrix3;

/// Lamé parameters of an isotropic material plus the volume stiffness.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// First Lamé parameter, Pa.
    pub lambda: Real,
    /// Shear modulus, Pa.
    pub mu: Real,
    /// `k_v` of Eq. 65, Pa; 0 turns the volume force off.
    pub volume_stiffness: Real,
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
        }
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
            s: self.hooke(&e),
            det: f.determinant(),
            cof: cofactor(&f),
        }
    }

    /// `P = dW/dF` at `state`.
    pub fn first_piola(&self, state: &StressState) -> Matrix3<Real> {
        state.f * state.s + state.cof * (self.volume_stiffness * (state.det - 1.0))
    }

    /// Strain energy density `W + W_vol` at `state`, J/m^3.
    pub fn energy_density(&self, state: &StressState) -> Real {
        let dv = state.det - 1.0;
        0.5 * state.e.dot(&state.s) + 0.5 * self.volume_stiffness * dv * dv
    }

    /// The directional derivative `dP[dF]` of [`Self::first_piola`] at
    /// `state`, for the implicit integrator's tangent stiffness.
    pub fn first_piola_derivative(&self, state: &StressState, df: &Matrix3<Real>) -> Matrix3<Real> {
        let de = (df.transpose() * state.f + state.f.transpose() * df) * 0.5;
        let ds = self.hooke(&de);
        let mut dp = df * state.s + state.f * ds;
        if self.volume_stiffness != 0.0 {
            let d_det = state.cof.dot(df);
            // cof is quadratic in F: cof(F + dF) = cof F + L(F, dF) + cof dF
            // exactly, so its linear part needs no division.
            let d_cof = cofactor(&(state.f + df)) - state.cof - cofactor(df);
            dp += (state.cof * d_det + d_cof * (state.det - 1.0)) * self.volume_stiffness;
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
