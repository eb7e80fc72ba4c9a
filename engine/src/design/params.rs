//! The optimiser's knobs. Each trades speed for accuracy in a way the
//! study command measures (`meshless study --knob design-*`).
//!
//! **Units of the energies.** The tutorial's Eq. 74-84 mix lengths,
//! volumes and times, so their weights would change with the model's
//! scale. Here every term is made dimensionless with the design spacing
//! `s`, a particle's lattice volume `s^dim` and the motion's duration `T`:
//!
//! | term | energy |
//! |---|---|
//! | handle / keyframe (Eq. 74) | `sum_k |f(x_k) - x'_k|^2 / s^2` |
//! | rigidity (Eq. 76) | `sum_i (V_i / s^dim) |grad f^T grad f - I|_F^2` |
//! | volume (Eq. 77) | `sum_i (V_i / s^dim) (det grad f - 1)^2` |
//! | velocity (Eq. 82) | `sum_k sum_i (V_i / s^dim) |du/dt - v_k|^2 (T / s)^2` |
//! | acceleration (Eq. 83) | `sum_j (h_j / T) sum_i (V_i / s^dim) |d2u/dt2|^2 (T^2 / s)^2` |
//! | obstacle (Eq. 84) | `sum_j (h_j / T) sum_i (V_i / s^dim) max(0, r_i - d_i)^2 / s^2` |
//!
//! so a weight means the same for a teapot and a bridge. A motion's rigidity
//! and volume terms are weighted per frame by `h_j / T` too, so adding
//! frames refines the time integral instead of stiffening the shape.

use crate::math::Real;
use serde::{Deserialize, Serialize};

/// The weights `lambda_1 .. lambda_6` of Eq. 78 and Eq. 85.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Weights {
    /// Handles and keyframes: high, so targets are met closely.
    pub handle: Real,
    /// Rigidity, Eq. 76.
    pub rigidity: Real,
    /// 0 lets the volume drift (the tutorial's Figure 13, middle).
    pub volume: Real,
    /// Velocities at keyframe times, Eq. 82 (motion only).
    pub velocity: Real,
    /// Acceleration at frame times, Eq. 83 (motion only).
    pub acceleration: Real,
    /// Obstacle penetration, Eq. 84 (motion only).
    pub obstacle: Real,
}

impl Weights {
    /// The weights by name, in the order of Eq. 85.
    pub fn named(&self) -> [(&'static str, Real); 6] {
        [
            ("handle", self.handle),
            ("rigidity", self.rigidity),
            ("volume", self.volume),
            ("velocity", self.velocity),
            ("acceleration", self.acceleration),
            ("obstacle", self.obstacle),
        ]
    }
}

impl Default for Weights {
    fn default() -> Self {
        Self {
            handle: 1e3,
            rigidity: 1.0,
            volume: 10.0,
            velocity: 10.0,
            acceleration: 1e-4,
            obstacle: 1e3,
        }
    }
}

/// The nonlinear least-squares solver (Levenberg–Marquardt).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SolverParams {
    /// Stops when the gradient's largest entry, relative to the energy's
    /// scale, or the step, relative to the spacing, falls below it.
    pub tolerance: Real,
    /// Levenberg–Marquardt iterations at most in one solve.
    pub max_iterations: u32,
    /// Relative residual of the inner conjugate-gradient solve.
    pub linear_tolerance: Real,
    /// Conjugate-gradient iterations at most in one inner solve.
    pub max_linear_iterations: u32,
}

impl Default for SolverParams {
    fn default() -> Self {
        Self {
            tolerance: 1e-4,
            max_iterations: 200,
            linear_tolerance: 0.05,
            max_linear_iterations: 500,
        }
    }
}

/// How the shape is discretised and what is optimised.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DesignParams {
    /// Spacing of the design particles, m: few particles (tens to
    /// hundreds) carry a detailed surface. 0 picks the spacing that puts
    /// about `particles` in the shape.
    pub spacing: Real,
    /// Used when `spacing` is 0.
    pub particles: u32,
    /// MLS support radius in spacings (linear basis, Eq. 72).
    pub support: Real,
    /// Where rigidity and volume are measured.
    pub quadrature: Quadrature,
    /// The energy terms' weights (Eq. 78, Eq. 85).
    pub weights: Weights,
    /// Settings of the Levenberg–Marquardt solver.
    pub solver: SolverParams,
}

/// Where the rigidity and volume energies (Eq. 76-77) are measured.
///
/// The tutorial measures them at the particles only. A linear field can
/// then trade volume between the particles and the space around them: in
/// the Figure 13 stretch, the volume at the particles holds to 0.4 % while
/// the surface encloses 4.2 % more (1.8 % measured at the cells). Measuring at the centres of the
/// `2^dim` sub-cells of each particle's cell closes that gap at `2^dim`
/// times the cost of these terms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Quadrature {
    /// At the particles (the tutorial's Eq. 76-77).
    Particles,
    /// At `2^dim` points per particle, a quarter spacing off it on
    /// every axis.
    Cells,
}

impl Default for DesignParams {
    fn default() -> Self {
        Self {
            spacing: 0.0,
            particles: 120,
            support: 2.2,
            quadrature: Quadrature::Particles,
            weights: Weights::default(),
            solver: SolverParams::default(),
        }
    }
}

/// Motion design (Section 8.2): the time span, the particles' sphere
/// radius against obstacles and the adaptive temporal sampling.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MotionParams {
    /// Insert frames where the error between frames is largest.
    pub adaptive: bool,
    /// Stop inserting once the largest error between frames is below
    /// this: the worst penetration of a particle sphere and the worst
    /// non-rigidity `|grad f^T grad f - I|_F`, the first in spacings.
    pub tolerance: Real,
    /// Times checked between two frames (the paper uses about 10).
    pub samples: u32,
    /// Frames at most, keyframes included.
    pub max_frames: u32,
    /// Each particle's sphere radius against obstacles, in spacings: 0.87
    /// (half the 3D lattice diagonal) makes the spheres cover the shape.
    pub radius: Real,
}

impl Default for MotionParams {
    fn default() -> Self {
        Self {
            adaptive: true,
            tolerance: 0.1,
            samples: 10,
            max_frames: 24,
            radius: 0.87,
        }
    }
}
