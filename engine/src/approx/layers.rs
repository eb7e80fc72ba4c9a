//! Kernel integrals over the planar layers of a ghost lattice: the sums
//! that stand in for the ghost particles behind a solid wall, integrated
//! exactly along the wall (see `fluid/walls.rs`), and Morris et al.'s
//! extrapolation of the fluid's velocity onto them. The domain's walls
//! tabulate them; rigid bodies use them to scale their single layer of
//! boundary samples (`rigid/ghosts.rs`).

use super::Kernel;
use crate::math::Real;
use std::f64::consts::PI;

/// `beta`: the relative velocity of a particle at distance `d` from the
/// wall and a ghost at `depth` behind it, over the particle's own velocity
/// relative to the wall, `1 + depth / d`, with `d` no nearer than half a
/// spacing (where a lattice's first row sits).
///
/// Morris et al. cap `beta` at 1.5 to keep particles touching the wall
/// finite. The cap cuts the extrapolation short for every layer deeper
/// than half the particle's distance, so the ghosts drag too little and
/// the flow's no-slip plane lay 0.2 spacings behind the wall, its first
/// row 54 % fast in a Poiseuille channel (`validation_viscous`). Bounding
/// `d` instead keeps the extrapolation exact wherever a lattice puts
/// particles and still finite at the wall.
pub(crate) fn extrapolation(depth: Real, d: Real, spacing: Real) -> Real {
    1.0 + depth / d.max(0.5 * spacing)
}

/// One ghost layer's friction sums at distance `z` from the particle:
/// `(int x_t^2 g dA, int z^2 g dA)` over the layer's plane (3D) or line
/// (2D), with `g(r) = W'(r) / (r (r^2 + eta^2))`.
pub(crate) fn friction_layer(kernel: &Kernel, z: Real) -> (Real, Real) {
    let h = kernel.support();
    if z >= h {
        return (0.0, 0.0);
    }
    let eta2 = 0.01 * h * h;
    let g = |s: Real| {
        let r2 = s * s + z * z;
        let r = r2.sqrt();
        kernel.derivative(r) / (r * (r2 + eta2))
    };
    let reach = (h * h - z * z).sqrt();
    if kernel.dim() == 2 {
        (
            2.0 * integrate(0.0, reach, |s| s * s * g(s)),
            2.0 * z * z * integrate(0.0, reach, g),
        )
    } else {
        (
            PI * integrate(0.0, reach, |s| s * s * s * g(s)),
            2.0 * PI * z * z * integrate(0.0, reach, |s| s * g(s)),
        )
    }
}

/// `int_a^b f(x) dx` by 3-point Gauss–Legendre on 64 panels.
pub(crate) fn integrate(a: Real, b: Real, f: impl Fn(Real) -> Real) -> Real {
    let panels = 64;
    let nodes = [-(0.6 as Real).sqrt(), 0.0, (0.6 as Real).sqrt()];
    let weights = [5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0];
    let width = (b - a) / panels as Real;
    let mut sum = 0.0;
    for p in 0..panels {
        let mid = a + (p as Real + 0.5) * width;
        for (x, w) in nodes.iter().zip(weights) {
            sum += w * 0.5 * width * f(mid + 0.5 * width * x);
        }
    }
    sum
}
