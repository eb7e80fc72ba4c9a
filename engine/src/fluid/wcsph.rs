//! Weakly compressible SPH, tutorial Algorithm 5: neighbour search ->
//! densities -> pressures -> pressure forces -> viscosity -> XSPH ->
//! explicit integration with reflection off the domain walls.

use super::dfsph::{DfsphParams, SolverScratch};
use super::rigid_body::BodyState;
use super::{BoxWalls, RigidBodies, Tait, ViscosityModel};
use crate::approx::{Kernel, KernelKind};
use crate::math::{Real, Vector};
use crate::neighbors::{CandidateSearch, NeighborList, Periodic, UniformGrid};
use crate::stats::{Stage, StageTimer};
use rayon::prelude::*;

/// Which pressure solver steps the fluid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PressureSolver {
    /// Weakly compressible SPH with the Tait equation (Algorithm 5).
    Wcsph,
    /// Divergence-free SPH (Bender & Koschier 2015), iterated to a density
    /// tolerance.
    Dfsph(DfsphParams),
}

/// Physical and numerical parameters of one fluid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FluidParams {
    /// Kernel support radius h, m.
    pub support_radius: Real,
    /// Kernel of the density sum and XSPH averages (poly6 in Algorithm 5).
    pub density_kernel: Kernel,
    /// Kernel of the pressure gradient (spiky in Algorithm 5).
    pub gradient_kernel: Kernel,
    pub eos: Tait,
    /// XSPH factor xi (Eq. 53); 0 skips the XSPH pass.
    pub xsph: Real,
    /// Dynamic viscosity mu, Pa s; 0 skips the viscosity pass.
    pub viscosity: Real,
    /// How the viscous Laplacian is approximated.
    pub viscosity_model: ViscosityModel,
    /// Mass of every particle, kg.
    pub mass: Real,
    /// Initial particle spacing, m.
    pub spacing: Real,
    pub solver: PressureSolver,
}

impl FluidParams {
    /// The particle mass that gives the interior of a cubic lattice of
    /// `spacing` exactly the rest density under the density sum with
    /// `kernel`, so the fluid starts at rest (the tutorial's advice on
    /// initial states).
    pub fn lattice_mass(spacing: Real, kernel: &Kernel, rest_density: Real) -> Real {
        let reach = (kernel.support() / spacing).ceil() as i64;
        let depth = if kernel.dim() == 2 { 0 } else { reach };
        let mut sum = 0.0;
        for i in -reach..=reach {
            for j in -reach..=reach {
                for k in -depth..=depth {
                    let d2 = ((i * i + j * j + k * k) as Real) * spacing * spacing;
                    sum += kernel.value_sq(d2);
                }
            }
        }
        rest_density / sum
    }
}

/// A fluid: particle state as structure of arrays, plus the scratch the
/// solver reuses every sub-step.
#[derive(Debug, Clone)]
pub struct Fluid {
    pub params: FluidParams,
    pub positions: Vec<Vector>,
    pub velocities: Vec<Vector>,
    /// rho_i from the last density pass, kg/m^3.
    pub densities: Vec<Real>,
    /// p_i from the last pressure pass, Pa.
    pub pressures: Vec<Real>,
    pub(super) accelerations: Vec<Vector>,
    pub(super) smoothed_velocities: Vec<Vector>,
    /// Solid walls of the domain, when the scene asks for them.
    pub(super) walls: Option<BoxWalls>,
    /// The kernel of the viscosity pass, when the scene has viscosity.
    pub(super) viscosity_kernel: Option<Kernel>,
    /// Rigid bodies in the fluid, when the scene has any.
    pub(super) rigid: Option<RigidBodies>,
    pub(super) grid: UniformGrid,
    /// Periodic axes of the domain, when the scene names any.
    pub(super) periodic: Option<Periodic>,
    pub(super) neighbors: NeighborList,
    /// Each slot's particle id (its index in the scene's order): the
    /// arrays are kept in Z order (see `reorder.rs`).
    pub(super) ids: Vec<u32>,
    pub(super) substeps_since_reorder: u32,
    pub(super) max_acceleration: Real,
    /// Scratch of the iterative solver, empty for WCSPH.
    pub(super) solver: SolverScratch,
}

impl Fluid {
    /// Particle speeds above this multiple of the speed of sound count as
    /// a blow-up (WCSPH).
    pub const SPEED_LIMIT: Real = 100.0;
    /// Speeds above this count as a blow-up for incompressible solvers,
    /// which have no sound speed: no liquid flow a scene can describe
    /// comes near it.
    pub const INCOMPRESSIBLE_SPEED_LIMIT: Real = 1e4;

    /// A fluid with the given particles; `grid` must cover the domain with
    /// cells of at least the support radius and wrap around the same
    /// `periodic` axes.
    pub fn new(
        params: FluidParams,
        positions: Vec<Vector>,
        velocities: Vec<Vector>,
        walls: Option<BoxWalls>,
        grid: UniformGrid,
        periodic: Option<Periodic>,
    ) -> Self {
        let n = positions.len();
        let mut fluid = Self {
            params,
            positions,
            velocities,
            densities: vec![params.eos.rest_density; n],
            pressures: vec![0.0; n],
            accelerations: vec![Vector::zeros(); n],
            smoothed_velocities: if params.xsph > 0.0 {
                vec![Vector::zeros(); n]
            } else {
                Vec::new()
            },
            walls,
            viscosity_kernel: (params.viscosity > 0.0).then(|| match params.viscosity_model {
                ViscosityModel::Morris => params.gradient_kernel,
                ViscosityModel::KernelLaplacian => Kernel::new(
                    KernelKind::Viscosity,
                    params.density_kernel.dim(),
                    params.support_radius,
                ),
            }),
            rigid: None,
            grid,
            periodic,
            neighbors: NeighborList::default(),
            ids: (0..n as u32).collect(),
            substeps_since_reorder: 0,
            max_acceleration: 0.0,
            solver: SolverScratch::default(),
        };
        // Densities and pressures of the initial state, so frame 0 and the
        // first stability limit see real values.
        fluid.find_neighbors();
        fluid.compute_densities();
        match params.solver {
            PressureSolver::Wcsph => fluid.compute_pressures(),
            PressureSolver::Dfsph(_) => fluid.prepare_dfsph(),
        }
        fluid.reorder();
        fluid
    }

    /// Puts rigid bodies into the fluid and recomputes the densities,
    /// pressures and solver factors they change.
    pub fn attach_bodies(&mut self, bodies: RigidBodies) {
        self.rigid = Some(bodies);
        self.find_neighbors();
        self.compute_densities();
        match self.params.solver {
            PressureSolver::Wcsph => self.compute_pressures(),
            PressureSolver::Dfsph(_) => self.prepare_dfsph(),
        }
    }

    /// The rigid bodies in the fluid, if any.
    pub fn bodies(&self) -> Option<&RigidBodies> {
        self.rigid.as_ref()
    }

    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Neighbour pairs (ordered, self-pairs included) of the last search.
    pub fn neighbor_pairs(&self) -> usize {
        self.neighbors.pair_count()
    }

    /// The largest sub-step the scheme allows now. WCSPH: the CFL condition
    /// `cfl * h / (c_0 + |v|_max)` and the force condition
    /// `cfl * sqrt(h / |a|_max)` (Monaghan 1992). DFSPH: `cfl * dx / |v|_max`
    /// and `0.25 cfl sqrt(dx / |a|_max)`. With viscosity, also the diffusion
    /// condition `0.125 (h/2)^2 rho_0 / mu` (Morris et al. 1997).
    pub fn stable_dt(&self, cfl: Real) -> Real {
        let h = self.params.support_radius;
        let v_max = self
            .velocities
            .par_iter()
            .map(|v| v.norm_squared())
            .reduce(|| 0.0, Real::max)
            .sqrt()
            .max(self.rigid.as_ref().map_or(0.0, RigidBodies::max_speed));
        let mut dt = match self.params.solver {
            PressureSolver::Wcsph => cfl * h / (self.params.eos.sound_speed() + v_max),
            // No sound speed: a particle moves at most `cfl` spacings.
            PressureSolver::Dfsph(_) => cfl * self.params.spacing / v_max,
        };
        if self.max_acceleration > 0.0 {
            dt = dt.min(match self.params.solver {
                PressureSolver::Wcsph => cfl * (h / self.max_acceleration).sqrt(),
                // Measured, not derived: a resting DFSPH tank under gravity
                // rings from about 2x this step (tests/tests/validation_tank.rs).
                PressureSolver::Dfsph(_) => {
                    0.25 * cfl * (self.params.spacing / self.max_acceleration).sqrt()
                }
            });
        }
        if self.params.viscosity > 0.0 {
            // Morris et al. state the condition with the smoothing length
            // of kernels whose support is twice it, so here with `h / 2`;
            // the support radius itself made a Taylor–Green vortex blow up
            // (tests/tests/validation_periodic.rs).
            let smoothing = 0.5 * h;
            dt = dt.min(
                0.125 * smoothing * smoothing * self.params.eos.rest_density
                    / self.params.viscosity,
            );
        }
        dt
    }

    /// One sub-step of length `dt` with the scene's solver, reflecting
    /// particles off the walls of `[min, max]`.
    pub fn substep(
        &mut self,
        dt: Real,
        gravity: &Vector,
        min: &Vector,
        max: &Vector,
        timer: &mut StageTimer,
    ) {
        self.substeps_since_reorder += 1;
        match self.params.solver {
            PressureSolver::Wcsph => self.wcsph_substep(dt, gravity, min, max, timer),
            PressureSolver::Dfsph(params) => {
                self.dfsph_substep(dt, gravity, min, max, &params, timer)
            }
        }
    }

    /// One explicit WCSPH sub-step (Algorithm 5).
    fn wcsph_substep(
        &mut self,
        dt: Real,
        gravity: &Vector,
        min: &Vector,
        max: &Vector,
        timer: &mut StageTimer,
    ) {
        timer.time(Stage::NeighborSearch, || self.find_neighbors());
        timer.time(Stage::Density, || {
            self.compute_densities();
            self.compute_pressures();
        });
        timer.time(Stage::PressureForce, || {
            pressure_accelerations(
                &self.positions,
                &self.densities,
                &self.pressures,
                self.params.mass,
                &self.neighbors,
                &self.params.gradient_kernel,
                self.walls.as_ref(),
                gravity,
                &mut self.accelerations,
            );
            if let Some(rigid) = &mut self.rigid {
                rigid.add_forces(
                    &self.positions,
                    &self.velocities,
                    &self.densities,
                    Some(&self.pressures),
                    self.params.mass,
                    &mut self.accelerations,
                );
            }
        });
        if let Some(kernel) = self.viscosity_kernel {
            let model = self.params.viscosity_model;
            timer.time(Stage::Viscosity, || self.apply_viscosity(model, &kernel));
        }
        if self.params.xsph > 0.0 {
            timer.time(Stage::Xsph, || self.apply_xsph());
        }
        timer.time(Stage::Integrate, || {
            self.integrate(dt, min, max);
            self.move_bodies(dt, gravity, min, max);
        });
    }

    pub(super) fn find_neighbors(&mut self) {
        self.grid.rebuild(&self.positions);
        self.neighbors.build_periodic(
            &self.grid,
            &self.positions,
            self.params.support_radius,
            self.periodic,
        );
        if let Some(rigid) = &mut self.rigid {
            rigid.find_neighbors(&self.positions);
        }
    }

    /// Advances the rigid bodies by `dt` under the loads the fluid put on
    /// them, then puts fluid particles that ended up in a body back out.
    pub(super) fn move_bodies(&mut self, dt: Real, gravity: &Vector, min: &Vector, max: &Vector) {
        if let Some(rigid) = &mut self.rigid {
            rigid.advance(dt, gravity, min, max);
            rigid.enforce(
                &mut self.positions,
                &mut self.velocities,
                self.params.mass,
                dt,
            );
        }
    }

    /// `rho_i = sum_j m_j omega(|x_i - x_j|)` (Algorithm 5; poly6 by
    /// default), plus the walls' ghost layers (Eq. 55).
    pub(super) fn compute_densities(&mut self) {
        let (positions, neighbors, kernel, mass, walls, rigid) = (
            &self.positions,
            &self.neighbors,
            &self.params.density_kernel,
            self.params.mass,
            self.walls.as_ref(),
            self.rigid.as_ref(),
        );
        self.densities
            .par_iter_mut()
            .enumerate()
            .for_each(|(i, rho)| {
                *rho = mass
                    * neighbors
                        .pairs(i, positions)
                        .map(|(_, r)| kernel.value_sq(r.norm_squared()))
                        .sum::<Real>()
                    + walls.map_or(0.0, |w| w.density(&positions[i]))
                    + rigid.map_or(0.0, |r| r.density(i, &positions[i]));
            });
    }

    fn compute_pressures(&mut self) {
        let eos = self.params.eos;
        self.pressures
            .par_iter_mut()
            .zip(self.densities.par_iter())
            .for_each(|(p, &rho)| *p = eos.pressure(rho));
    }

    /// XSPH artificial viscosity (tutorial Eq. 53, Monaghan 1989) in its
    /// difference form:
    /// `v_i <- v_i + xi sum_j (2 m / (rho_i + rho_j)) (v_j - v_i) omega_ij`.
    ///
    /// Eq. 53 blends `v_i` with the SPH average `sum_j (m_j / rho_j) v_j
    /// omega_ij`; both agree where that average reproduces constants
    /// (`sum_j (m_j / rho_j) omega_ij = 1`), but where the neighbourhood is
    /// cut (free surfaces, walls) the average falls short and Eq. 53 as
    /// written brakes uniform motion, every sub-step. The difference form
    /// leaves uniform motion alone and, with the pair-symmetric density,
    /// conserves momentum.
    pub(super) fn apply_xsph(&mut self) {
        let (positions, velocities, densities, neighbors, kernel, mass) = (
            &self.positions,
            &self.velocities,
            &self.densities,
            &self.neighbors,
            &self.params.density_kernel,
            self.params.mass,
        );
        let xi = self.params.xsph;
        self.smoothed_velocities
            .par_iter_mut()
            .enumerate()
            .for_each(|(i, out)| {
                let (vi, rho_i) = (velocities[i], densities[i]);
                let correction =
                    neighbors
                        .pairs(i, positions)
                        .fold(Vector::zeros(), |acc, (j, r)| {
                            let w = kernel.value_sq(r.norm_squared());
                            acc + (velocities[j] - vi) * (2.0 * mass / (rho_i + densities[j]) * w)
                        });
                *out = vi + correction * xi;
            });
        std::mem::swap(&mut self.velocities, &mut self.smoothed_velocities);
    }

    /// Eq. 58-59 (symplectic Euler), then reflection off the walls.
    pub(super) fn integrate(&mut self, dt: Real, min: &Vector, max: &Vector) {
        self.record_max_acceleration();
        let periodic = self.periodic.as_ref();
        self.positions
            .par_iter_mut()
            .zip(self.velocities.par_iter_mut())
            .zip(self.accelerations.par_iter())
            .for_each(|((x, v), a)| {
                *v += a * dt;
                *x += *v * dt;
                confine(x, v, min, max, periodic);
            });
    }

    /// Keeps the largest acceleration for the force condition of the next
    /// sub-step's limit.
    pub(super) fn record_max_acceleration(&mut self) {
        self.max_acceleration = self
            .accelerations
            .par_iter()
            .map(|a| a.norm_squared())
            .reduce(|| 0.0, Real::max)
            .sqrt();
    }

    /// The first particle whose state cannot go on: a position, velocity,
    /// density or pressure that is not finite or does not fit a frame's
    /// f32, or a speed above [`Self::SPEED_LIMIT`] times the speed of
    /// sound (the weakly compressible model is void there; this is how an
    /// unstable run shows before it overflows).
    pub fn first_invalid(&self) -> Option<Invalid> {
        const MAX: Real = f32::MAX as Real;
        let bad_vector = |v: &Vector| v.iter().any(|c| !c.is_finite() || c.abs() >= MAX);
        // NaN fails `is_finite`; infinities and huge values fail the bound.
        let bad_scalar = |s: &Real| !s.is_finite() || s.abs() >= MAX;
        let max_speed = match self.params.solver {
            PressureSolver::Wcsph => Self::SPEED_LIMIT * self.params.eos.sound_speed(),
            PressureSolver::Dfsph(_) => Self::INCOMPRESSIBLE_SPEED_LIMIT,
        };
        let found = |quantity, i: Option<usize>, value: Real| {
            i.map(|slot| Invalid {
                quantity,
                particle: self.ids[slot] as usize,
                value,
            })
        };
        let i = self.positions.par_iter().position_first(bad_vector);
        if let Some(v) = found("position", i, i.map_or(0.0, |i| self.positions[i].norm())) {
            return Some(v);
        }
        let i = self
            .velocities
            .par_iter()
            .position_first(|v| bad_vector(v) || v.norm() > max_speed);
        if let Some(v) = found("velocity", i, i.map_or(0.0, |i| self.velocities[i].norm())) {
            return Some(v);
        }
        let i = self.densities.par_iter().position_first(bad_scalar);
        if let Some(v) = found("density", i, i.map_or(0.0, |i| self.densities[i])) {
            return Some(v);
        }
        let i = self.pressures.par_iter().position_first(bad_scalar);
        if let Some(v) = found("pressure", i, i.map_or(0.0, |i| self.pressures[i])) {
            return Some(v);
        }
        let (k, quantity, value) = self.rigid.as_ref()?.first_invalid()?;
        Some(Invalid {
            quantity,
            particle: k,
            value,
        })
    }

    /// Copies the evolving state into `backup`, reusing its buffers.
    pub fn save(&self, backup: &mut FluidState) {
        backup.positions.clone_from(&self.positions);
        backup.velocities.clone_from(&self.velocities);
        backup.densities.clone_from(&self.densities);
        backup.pressures.clone_from(&self.pressures);
        backup.max_acceleration = self.max_acceleration;
        if let Some(rigid) = &self.rigid {
            rigid.save(&mut backup.bodies);
        }
    }

    /// Puts back a state saved by [`Fluid::save`], with the neighbour
    /// lists (and DFSPH's factors and pair gradients) of its positions, so
    /// that the next step starts from the saved state alone.
    pub fn restore(&mut self, backup: &FluidState) {
        self.positions.clone_from(&backup.positions);
        self.velocities.clone_from(&backup.velocities);
        self.densities.clone_from(&backup.densities);
        self.pressures.clone_from(&backup.pressures);
        self.max_acceleration = backup.max_acceleration;
        if let Some(rigid) = &mut self.rigid {
            rigid.restore(&backup.bodies);
        }
        self.find_neighbors();
        if let PressureSolver::Dfsph(_) = self.params.solver {
            self.compute_factors();
        }
    }
}

/// The part of a fluid a step changes, kept to undo a failed step.
#[derive(Debug, Clone, Default)]
pub struct FluidState {
    positions: Vec<Vector>,
    velocities: Vec<Vector>,
    densities: Vec<Real>,
    pressures: Vec<Real>,
    max_acceleration: Real,
    bodies: Vec<BodyState>,
}

/// A particle quantity that left its valid range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Invalid {
    pub quantity: &'static str,
    /// The particle (or, for a body quantity, the body's index among the
    /// fluid's bodies).
    pub particle: usize,
    /// The offending value (a norm for vectors).
    pub value: Real,
}

/// Keeps a particle in the domain: wraps it around the periodic axes, then
/// reflects it off the walls of the others.
#[inline]
pub(super) fn confine(
    x: &mut Vector,
    v: &mut Vector,
    min: &Vector,
    max: &Vector,
    periodic: Option<&Periodic>,
) {
    if let Some(p) = periodic {
        // Wrapped coordinates lie in [min, max), where reflection is a
        // no-op: only the walled axes reflect.
        p.wrap(x);
    }
    reflect(x, v, min, max);
}

/// Mirrors a particle that crossed a wall back inside and flips its normal
/// velocity ("reflect them off solid boundaries", tutorial Section 6.4).
#[inline]
pub(super) fn reflect(x: &mut Vector, v: &mut Vector, min: &Vector, max: &Vector) {
    for a in 0..3 {
        if x[a] < min[a] {
            x[a] = min[a] + (min[a] - x[a]);
            v[a] = v[a].abs();
        } else if x[a] > max[a] {
            x[a] = max[a] - (x[a] - max[a]);
            v[a] = -v[a].abs();
        }
        // A particle fast enough to cross the whole box stays inside.
        x[a] = x[a].clamp(min[a], max[a]);
    }
}

/// Accelerations from the symmetric SPH pressure gradient (tutorial
/// Eq. 51), the walls' pressure (see [`BoxWalls`]) and gravity:
/// `a_i = g - sum_j m_j (p_i / rho_i^2 + p_j / rho_j^2) grad omega(x_i - x_j)`
/// (spiky in Algorithm 5). The pair terms are antisymmetric, so pressure
/// conserves linear and angular momentum.
#[allow(clippy::too_many_arguments)]
pub(crate) fn pressure_accelerations(
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
        let wall = walls.map_or(Vector::zeros(), |w| {
            w.pressure_acceleration(&xi, pressures[i], densities[i])
        });
        *a = gravity - sum * mass + wall;
    });
}

#[cfg(test)]
mod tests {
    use super::*;
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

    /// The calibrated mass gives interior lattice particles the rest
    /// density, for every kernel fit for densities.
    #[test]
    fn lattice_mass_gives_rest_density() {
        let spacing = 0.05;
        let h = 0.1;
        for kind in [
            KernelKind::Poly6,
            KernelKind::CubicSpline,
            KernelKind::WendlandC2,
            KernelKind::Spiky,
        ] {
            let kernel = Kernel::new_3d(kind, h);
            let mass = FluidParams::lattice_mass(spacing, &kernel, 1000.0);
            assert!(
                (interior_density(spacing, &kernel, mass) - 1000.0).abs() < 1e-9,
                "{kind:?}"
            );
        }
    }

    fn interior_density(spacing: Real, kernel: &Kernel, mass: Real) -> Real {
        let mut positions = Vec::new();
        for i in 0..9 {
            for j in 0..9 {
                for k in 0..9 {
                    positions.push(Vector::new(i as Real, j as Real, k as Real) * spacing);
                }
            }
        }
        let centre = 4 * 81 + 4 * 9 + 4;
        positions
            .iter()
            .map(|x| mass * kernel.value_sq((x - positions[centre]).norm_squared()))
            .sum()
    }

    #[test]
    fn reflection_keeps_particles_inside() {
        let min = Vector::zeros();
        let max = Vector::repeat(1.0);
        let mut x = Vector::new(-0.1, 1.2, 0.5);
        let mut v = Vector::new(-2.0, 3.0, 0.0);
        reflect(&mut x, &mut v, &min, &max);
        assert!((x - Vector::new(0.1, 0.8, 0.5)).norm() < 1e-12);
        assert_eq!(v, Vector::new(2.0, -3.0, 0.0));
        let mut x = Vector::new(-50.0, 0.5, 0.5);
        reflect(&mut x, &mut v, &min, &max);
        assert!(x.x >= 0.0 && x.x <= 1.0);
    }
}
