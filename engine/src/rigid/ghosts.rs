//! The depth a rigid body's single layer of boundary samples lacks, made
//! up for in its no-slip friction (see [`GhostDepth`]).

use crate::approx::Kernel;
use crate::approx::layers::{extrapolation, friction_layer};
use crate::math::Real;

/// Samples of the extrapolation table over `[0, h]`.
const SAMPLES: usize = 512;

/// What a rigid body's single layer of boundary samples needs to drag
/// the fluid as the ghost lattice of a no-slip wall does
/// (`rigid/coupling.rs`).
///
/// A body carries one layer of samples `dx/2` beneath its surface, each
/// standing for the volume `V_b = 1 / sum_k W(x_b - x_k)` over its layer
/// (Akinci et al. 2012, Eq. 4), and drags the fluid through Monaghan's pair
/// form at the body's own velocity. The domain's walls instead integrate
/// every ghost layer at depths `d_k = (k + 1/2) dx` behind the wall, each
/// moving so that the pair's relative velocity is `beta_k = 1 + d_k / d`
/// times the particle's (`approx::layers::extrapolation`, Morris et al. 1997). The body
/// makes up for both with a scale per fluid particle: the volume its
/// neighbourhood misses, weighted as the friction weighs it,
/// `C_miss = C_full - sum_j (m / rho_j) phi(r_ij)` with
/// `phi(r) = -r W'(r) / (r^2 + eta^2)` and `C_full` that sum over a full
/// lattice, over the volume the samples supply, `sum_b V_b phi(r_ib)`,
/// times the extrapolation the ghost lattice would give on average at the
/// particle's distance `d` from the surface,
/// `beta(d) = sum_k beta_k t(d + d_k) / sum_k t(d + d_k)` (`t` the
/// tangential friction of one planar layer, as the walls' tables weigh
/// it). A particle kept off the surface (the samples' volume is dense
/// near it, so the fluid stands farther off than a lattice's half
/// spacing) misses more volume and is dragged harder, as the ghosts
/// filling that gap would drag it.
#[derive(Debug, Clone)]
pub struct GhostDepth {
    h: Real,
    eta2: Real,
    kernel: Kernel,
    full: Real,
    beta: Vec<Real>,
}

impl GhostDepth {
    /// For a fluid sampled at `spacing` with particle `mass` and
    /// `rest_density`, its friction from `gradient_kernel`.
    pub fn new(spacing: Real, mass: Real, rest_density: Real, gradient_kernel: &Kernel) -> Self {
        let h = gradient_kernel.support();
        let eta2 = 0.01 * h * h;
        let axes = gradient_kernel.dim();
        let reach = (h / spacing).ceil() as i64;
        let depth = if axes == 3 { reach } else { 0 };
        let mut full = 0.0;
        for i in -reach..=reach {
            for j in -reach..=reach {
                for k in -depth..=depth {
                    let r = ((i * i + j * j + k * k) as Real).sqrt() * spacing;
                    full += -r * gradient_kernel.derivative(r) / (r * r + eta2);
                }
            }
        }
        full *= mass / rest_density;
        let layers = (h / spacing).ceil() as usize + 1;
        let mut beta: Vec<Real> = Vec::with_capacity(SAMPLES);
        for i in 0..SAMPLES {
            let d = h * i as Real / (SAMPLES - 1) as Real;
            let (weighted, plain) = (0..layers).fold((0.0, 0.0), |(w, p), k| {
                let depth = (k as Real + 0.5) * spacing;
                let t = friction_layer(gradient_kernel, d + depth).0;
                (w + extrapolation(depth, d, spacing) * t, p + t)
            });
            let b = if plain.abs() > 0.0 {
                weighted / plain
            } else {
                beta.last().copied().unwrap_or(1.0)
            };
            beta.push(b);
        }
        Self {
            h,
            eta2,
            kernel: *gradient_kernel,
            full,
            beta,
        }
    }

    /// `phi(r) = -r W'(r) / (r^2 + eta^2)`, the friction's weight.
    #[inline]
    pub fn weight(&self, r: Real) -> Real {
        -r * self.kernel.derivative(r) / (r * r + self.eta2)
    }

    /// `C_full`: the weighted volume of a full lattice neighbourhood.
    #[inline]
    pub fn full(&self) -> Real {
        self.full
    }

    /// `beta(d)` at distance `d` from the surface (linear interpolation).
    #[inline]
    pub fn extrapolation(&self, d: Real) -> Real {
        let x = (d.max(0.0) / self.h).min(1.0) * (SAMPLES - 1) as Real;
        let i = (x as usize).min(SAMPLES - 2);
        let t = x - i as Real;
        self.beta[i] * (1.0 - t) + self.beta[i + 1] * t
    }
}
