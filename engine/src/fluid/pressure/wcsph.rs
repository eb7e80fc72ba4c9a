//! Weakly compressible SPH, tutorial Algorithm 5: neighbour search ->
//! densities -> pressures (Tait, Eq. 47) -> pressure forces -> viscosity
//! -> XSPH -> explicit integration with reflection off the domain walls.
//!
//! The solver has no parameters of its own (the equation of state is the
//! fluid's, [`FluidParams::eos`]) and no scratch.

use super::PressureSolver;
use crate::approx::Kernel;
use crate::cancel::{Cancel, Cancelled};
use crate::fluid::{BoxWalls, Fluid, FluidParams};
use crate::math::{Real, Vector};
use crate::neighbors::NeighborList;
use crate::stats::{Stage, StageTimer};
use rayon::prelude::*;

/// The weakly compressible solver (Algorithm 5): explicit, its step
/// limited by the sound speed the Tait stiffness sets.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Wcsph;

impl Wcsph {
    /// Particle speeds above this multiple of the speed of sound count as
    /// a blow-up: the weakly compressible model is void there.
    pub const SPEED_LIMIT: Real = 100.0;
}

impl PressureSolver for Wcsph {
    fn init(&mut self, fluid: &mut Fluid) {
        fluid.compute_densities_with(true);
        compute_pressures(fluid);
    }

    /// The CFL condition `cfl * h / (c_0 + |v|_max)` and the force
    /// condition `cfl * sqrt(h / |a|_max)` (Monaghan 1992).
    fn stable_dt(&self, fluid: &Fluid, cfl: Real, v_max: Real, a_max: Real) -> Real {
        let h = fluid.params.support_radius;
        let mut dt = cfl * h / (fluid.params.eos.sound_speed() + v_max);
        if a_max > 0.0 {
            dt = dt.min(cfl * (h / a_max).sqrt());
        }
        dt
    }

    fn speed_limit(&self, params: &FluidParams) -> Real {
        Self::SPEED_LIMIT * params.eos.sound_speed()
    }

    /// One explicit WCSPH sub-step (Algorithm 5): a few passes, nothing
    /// to cancel within.
    fn substep(
        &mut self,
        fluid: &mut Fluid,
        dt: Real,
        gravity: &Vector,
        min: &Vector,
        max: &Vector,
        timer: &mut StageTimer,
        _cancel: &Cancel,
    ) -> Result<(), Cancelled> {
        timer.time(Stage::NeighborSearch, || fluid.find_neighbors());
        timer.time(Stage::Density, || {
            fluid.compute_densities_with(true);
            compute_pressures(fluid);
        });
        timer.time(Stage::PressureForce, || {
            pressure_accelerations(
                &fluid.positions,
                &fluid.densities,
                &fluid.pressures,
                fluid.params.mass,
                &fluid.neighbors,
                &fluid.params.gradient_kernel,
                fluid.walls.as_ref(),
                gravity,
                &mut fluid.accelerations,
            );
            fluid.add_body_force();
            if let Some(rigid) = &mut fluid.rigid {
                rigid.add_forces(
                    &fluid.positions,
                    &fluid.neighbors,
                    &fluid.velocities,
                    &fluid.densities,
                    Some(&fluid.pressures),
                    fluid.params.mass,
                    &mut fluid.accelerations,
                );
            }
        });
        if let Some(kernel) = fluid.viscosity_kernel {
            let model = fluid.params.viscosity_model;
            timer.time(Stage::Viscosity, || fluid.apply_viscosity(model, &kernel));
        }
        if fluid.params.xsph > 0.0 {
            timer.time(Stage::Xsph, || fluid.apply_xsph());
        }
        timer.time(Stage::Integrate, || {
            fluid.integrate(dt, min, max);
            fluid.move_bodies(dt, gravity, min, max);
        });
        Ok(())
    }

    /// Nothing to follow: the solver keeps no scratch.
    fn follow(&mut self, _order: &[u32], _slots: usize) {}

    /// Nothing to rebuild: pressures come from the next density pass.
    fn rebuild(&mut self, _fluid: &Fluid) {}

    /// No warm start: each sub-step starts from the state alone.
    fn save(&self, out: &mut Vec<Real>) {
        out.clear();
    }

    fn restore(&mut self, _saved: &[Real]) {}
}

/// `p_i` from `rho_i` by the fluid's equation of state (tutorial Eq. 47).
fn compute_pressures(fluid: &mut Fluid) {
    let eos = fluid.params.eos;
    fluid
        .pressures
        .par_iter_mut()
        .zip(fluid.densities.par_iter())
        .for_each(|(p, &rho)| *p = eos.pressure(rho));
}

/// Accelerations from the symmetric SPH pressure gradient (tutorial
/// Eq. 51), the walls' pressure (see [`BoxWalls`]) and gravity:
/// `a_i = g - sum_j m_j (p_i / rho_i^2 + p_j / rho_j^2) grad omega(x_i - x_j)`
/// (spiky in Algorithm 5). The pair terms are antisymmetric, so pressure
/// conserves linear and angular momentum.
#[allow(clippy::too_many_arguments)]
fn pressure_accelerations(
    positions: &[Vector],
    densities: &[Real],
    pressures: &[Real],
    mass: Real,
    neighbors: &NeighborList,
    kernel: &Kernel,
    walls: Option<&BoxWalls>,
    gravity: &Vector,
    out: &mut [Vector],
) {
    out.par_iter_mut().enumerate().for_each(|(i, a)| {
        let xi = positions[i];
        let pi = pressures[i] / (densities[i] * densities[i]);
        let mut sum = Vector::zeros();
        for (j, r) in neighbors.pairs(i, positions) {
            if j == i {
                continue;
            }
            let pj = pressures[j] / (densities[j] * densities[j]);
            sum += kernel.gradient(&r, r.norm()) * (pi + pj);
        }
        // The walls' mirror images of every neighbour, self included, at
        // the neighbour's own pressure (see `BoxWalls::mirrors`).
        if let Some(w) = walls {
            w.mirrors(&xi, |planes| {
                for (j, r) in neighbors.pairs(i, positions) {
                    let image = BoxWalls::mirrored(planes, &r, &xi, &positions[j]);
                    let norm = image.norm();
                    if norm > 0.0 {
                        let pj = pressures[j] / (densities[j] * densities[j]);
                        sum += kernel.gradient(&image, norm) * (pi + pj);
                    }
                }
            });
        }
        *a = gravity - sum * mass;
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::approx::KernelKind;
    use crate::neighbors::{CandidateSearch, UniformGrid};
    use crate::testing::uniform;

    /// Eq. 51 is antisymmetric in each pair, so on any particle layout and
    /// any pressures the pressure forces sum to zero: the total momentum
    /// change from pressure must vanish to round-off, relative to the sum of
    /// the force magnitudes.
    #[test]
    fn symmetric_pressure_forces_sum_to_zero() {
        let mut seed = 11;
        let h = 0.1;
        let spacing = 0.05;
        let mut positions = Vec::new();
        for i in 0..12 {
            for j in 0..12 {
                for k in 0..12 {
                    let jitter =
                        Vector::new(uniform(&mut seed), uniform(&mut seed), uniform(&mut seed))
                            .map(|c| (c - 0.5) * 0.6 * spacing);
                    positions.push(
                        Vector::new(i as Real, j as Real, k as Real) * spacing
                            + Vector::repeat(0.2)
                            + jitter,
                    );
                }
            }
        }
        let n = positions.len();
        let min = Vector::zeros();
        let max = Vector::repeat(1.0);
        let mut grid = UniformGrid::new(min, max, h).expect("grid");
        grid.rebuild(&positions);
        let mut neighbors = NeighborList::default();
        neighbors.build(&grid, &positions, h);
        let densities: Vec<Real> = (0..n).map(|_| 900.0 + 200.0 * uniform(&mut seed)).collect();
        let pressures: Vec<Real> = (0..n).map(|_| -1e3 + 1e5 * uniform(&mut seed)).collect();
        let mass = 0.125;
        let mut accelerations = vec![Vector::zeros(); n];
        pressure_accelerations(
            &positions,
            &densities,
            &pressures,
            mass,
            &neighbors,
            &Kernel::new_3d(KernelKind::Spiky, h),
            None,
            &Vector::zeros(),
            &mut accelerations,
        );
        let total: Vector = accelerations.iter().map(|a| a * mass).sum();
        let scale: Real = accelerations.iter().map(|a| a.norm() * mass).sum();
        assert!(scale > 0.0);
        assert!(
            total.norm() < 1e-9 * scale,
            "net pressure force {total:?} against total magnitude {scale}"
        );
        // Angular momentum: every pair force is parallel to x_i - x_j.
        let torque: Vector = positions
            .iter()
            .zip(&accelerations)
            .map(|(x, a)| x.cross(&(a * mass)))
            .sum();
        assert!(
            torque.norm() < 1e-9 * scale,
            "net pressure torque {torque:?}"
        );
    }
}
