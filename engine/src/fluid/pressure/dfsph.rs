//! Divergence-free SPH (Bender & Koschier, "Divergence-free smoothed
//! particle hydrodynamics", SCA 2015; TVCG 2017): an incompressible solver
//! that iterates pressure until the predicted density error falls below a
//! tolerance, so the time step follows the flow speed, not a sound speed.
//!
//! A sub-step: non-pressure accelerations (gravity, viscosity, XSPH) ->
//! constant-density solve on the predicted velocities -> advection ->
//! neighbour search, densities and factors -> divergence-free solve.
//! Both solves share one update: with the factor
//! `alpha_i = rho_i / (|sum_j m_j grad W_ij|^2 + sum_j |m_j grad W_ij|^2)`,
//! a density source `s_i` becomes `kappa_i = s_i alpha_i / dt^k` and
//! `v_i -= dt sum_j m_j (kappa_i / rho_i + kappa_j / rho_j) grad W_ij`, the
//! symmetric pressure form of Eq. 51 with `kappa = p / rho`. Walls enter
//! through the gradient of their density (see [`crate::fluid::BoxWalls`]).

use super::{PressureSolver, SolveInfo};
use crate::cancel::{Cancel, Cancelled};
use crate::fluid::particles::confine;
use crate::fluid::reorder::gather;
use crate::fluid::{Fluid, FluidParams};
use crate::math::{Real, Vector};
use crate::neighbors::NeighborList;
use crate::stats::{Stage, StageTimer};
use nalgebra::Vector3;
use rayon::prelude::*;

/// Parameters of the DFSPH solves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DfsphParams {
    /// Largest average density error the constant-density solve accepts,
    /// as a fraction of the rest density (0.001 = 0.1 %).
    pub density_tolerance: Real,
    /// Largest average density change the divergence solve accepts, as a
    /// fraction of the rest density, per sub-step at CFL 0.4 (a shorter
    /// sub-step is held to the same rate).
    pub divergence_tolerance: Real,
    /// Iteration cap of each solve; reaching it leaves the error above
    /// tolerance (reported, not fatal).
    pub max_iterations: u32,
}

/// The DFSPH solver: its parameters and the per-particle scratch of its
/// solves.
#[derive(Debug, Clone)]
pub struct Dfsph {
    params: DfsphParams,
    /// `alpha_i`.
    factors: Vec<Real>,
    /// Gradient of the density of the walls and rigid bodies at each
    /// particle.
    wall_gradients: Vec<Vector>,
    /// With rigid bodies: `sum_b psi_b v_b . grad W_ib`, the density change
    /// the bodies' motion causes (empty without bodies).
    boundary_flux: Vec<Real>,
    /// With rigid bodies: the divergence solve's `kappa / rho` summed over its
    /// iterations, whose reaction the bodies feel (empty without bodies).
    divergence_kappa: Vec<Real>,
    /// `m_j grad W_ij` of every pair, aligned with the neighbour list
    /// (`NeighborList::range`): computed once per sub-step with the
    /// factors and read by every iteration of both solves, which otherwise
    /// spent most of their time re-evaluating the kernel. Single precision
    /// halves the memory and the traffic; its relative rounding of 6e-8 is
    /// far below the solver tolerances, and rounding `g` and `-g` gives
    /// `-round(g)`, so the pair terms stay antisymmetric.
    gradients: Vec<Vector3<f32>>,
    /// The density source of the current iteration.
    source: Vec<Real>,
    /// `kappa_i / rho_i` of the current iteration: the form the pair terms
    /// use, so that they need no division.
    kappa: Vec<Real>,
    /// The last sub-step's total `kappa / rho` of the constant-density
    /// solve: `p / rho^2`, a physical quantity independent of the step,
    /// which warm-starts the next solve, decayed by [`Dfsph::memory`].
    density_kappa: Vec<Real>,
    /// The current sub-step over the one [`PACE_CFL`] allows now, at most
    /// 1: how much of a standing density error this sub-step corrects and
    /// how much of the warm start it forgets (see [`Dfsph::memory`]).
    pace: Real,
}

/// The CFL number of the sub-step DFSPH paces its memory and corrections
/// by: the scene's default `time.cfl`, at which the solver is validated.
/// A shorter sub-step, whether from a short `time.dt` or a smaller
/// `time.cfl`, forgets and corrects proportionally less, so that the
/// fluid does over a time what a sub-step at this pace would, however
/// that time is cut.
const PACE_CFL: Real = 0.4;

/// Which density source a solve drives to zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Solve {
    /// The density predicted after the sub-step, above rest density.
    ConstantDensity,
    /// The rate of compression.
    DivergenceFree,
}

impl Solve {
    /// Iterations a solve runs even when its error starts below tolerance.
    ///
    /// The error a short sub-step adds shrinks with it (gravity compresses
    /// a resting column by `g dt^2`), while the warm start gives back less
    /// than the last pressure. A solve allowed to stop at once let a
    /// resting fluid fall for as many short sub-steps as its error took to
    /// pass the tolerance: with the memory and pace of [`Dfsph::memory`]
    /// alone, a 2D tank at 1e-4 s still sank 2 % of its depth, at 0.16 m/s.
    /// Rebuilding the missing pressure every sub-step, however small its
    /// error, holds it (`tests/tests/validation_tank.rs`).
    fn min_iterations(self) -> u32 {
        match self {
            Self::ConstantDensity => 2,
            Self::DivergenceFree => 1,
        }
    }
}

impl Dfsph {
    /// Speeds above this count as a blow-up: an incompressible solver has
    /// no sound speed, and no liquid flow a scene can describe comes near
    /// it.
    pub const SPEED_LIMIT: Real = 1e4;

    /// A solver with `params` and no scratch yet (sized by the fluid it
    /// joins).
    pub fn new(params: DfsphParams) -> Self {
        Self {
            params,
            factors: Vec::new(),
            wall_gradients: Vec::new(),
            boundary_flux: Vec::new(),
            divergence_kappa: Vec::new(),
            gradients: Vec::new(),
            source: Vec::new(),
            kappa: Vec::new(),
            density_kappa: Vec::new(),
            pace: 1.0,
        }
    }

    /// The share of the last sub-step's pressure that warm-starts the
    /// next: one half per sub-step at [`PACE_CFL`], as is usual.
    ///
    /// The solves add pressure only where the fluid compresses (free
    /// surfaces may expand), so pressure falls only by this decay; it is
    /// what keeps a pressure that is no longer needed from pushing on.
    /// Forgetting half *per sub-step* made the memory's half-life the
    /// sub-step: at 1e-5 s a resting column lost its hydrostatic pressure
    /// within a few sub-steps, fell, and was pushed back at a speed
    /// `1 / dt` once its error passed the tolerance (a 2D tank gained
    /// 24 % of its energy scale at 1e-4 s and 2,435 % at 1e-5 s). Halving
    /// per paced sub-step keeps the half-life a time of the flow.
    fn memory(&self) -> Real {
        (0.5 as Real).powf(self.pace)
    }

    /// The parameters of the solves.
    pub fn params(&self) -> &DfsphParams {
        &self.params
    }
}

impl PressureSolver for Dfsph {
    /// Allocates the solver scratch and computes the factors of the
    /// current state.
    fn init(&mut self, fluid: &mut Fluid) {
        let n = fluid.len();
        self.factors.resize(n, 0.0);
        self.wall_gradients.resize(n, Vector::zeros());
        self.source.resize(n, 0.0);
        self.kappa.resize(n, 0.0);
        self.density_kappa.resize(n, 0.0);
        let coupled = if fluid.rigid.is_some() { n } else { 0 };
        self.boundary_flux.resize(coupled, 0.0);
        self.divergence_kappa.resize(coupled, 0.0);
        self.compute_factors(fluid);
    }

    /// No sound speed: a particle moves at most `cfl` spacings,
    /// `cfl * dx / |v|_max`, and the force condition
    /// `0.25 cfl sqrt(dx / |a|_max)`.
    fn stable_dt(&self, fluid: &Fluid, cfl: Real, v_max: Real, a_max: Real) -> Real {
        let mut dt = cfl * fluid.params.spacing / v_max;
        if a_max > 0.0 {
            // Measured, not derived: a resting DFSPH tank under gravity
            // rings from about 2x this step (tests/tests/validation_tank.rs).
            dt = dt.min(0.25 * cfl * (fluid.params.spacing / a_max).sqrt());
        }
        dt
    }

    fn speed_limit(&self, _params: &FluidParams) -> Real {
        Self::SPEED_LIMIT
    }

    /// One DFSPH sub-step of length `dt`.
    fn substep(
        &mut self,
        fluid: &mut Fluid,
        dt: Real,
        gravity: &Vector,
        min: &Vector,
        max: &Vector,
        timer: &mut StageTimer,
        cancel: &Cancel,
    ) -> Result<(), Cancelled> {
        let g = *gravity;
        fluid.accelerations.par_iter_mut().for_each(|a| *a = g);
        fluid.add_body_force();
        if let Some(kernel) = fluid.viscosity_kernel {
            let model = fluid.params.viscosity_model;
            timer.time(Stage::Viscosity, || fluid.apply_viscosity(model, &kernel));
        }
        if let Some(rigid) = &mut fluid.rigid {
            // No-slip bodies' viscosity; pressure comes from the solves.
            timer.time(Stage::Viscosity, || {
                rigid.add_forces(
                    &fluid.positions,
                    &fluid.neighbors,
                    &fluid.velocities,
                    &fluid.densities,
                    None,
                    fluid.params.mass,
                    &mut fluid.accelerations,
                )
            });
        }
        if fluid.params.xsph > 0.0 {
            timer.time(Stage::Xsph, || fluid.apply_xsph());
        }
        fluid.record_max_acceleration();
        // The sub-step at the pace's CFL under the accelerations just
        // summed (a resting fluid's first sub-step has recorded none yet),
        // unbounded only where nothing moves and no force acts.
        let limit = fluid.viscous_limit(self.stable_dt(
            fluid,
            PACE_CFL,
            fluid.max_speed(),
            fluid.max_acceleration,
        ));
        self.pace = (dt / limit).min(1.0);
        timer.time(Stage::Integrate, || {
            fluid
                .velocities
                .par_iter_mut()
                .zip(fluid.accelerations.par_iter())
                .for_each(|(v, a)| *v += a * dt);
        });
        fluid.pressures.par_iter_mut().for_each(|p| *p = 0.0);
        let memory = self.memory();
        self.density_kappa.par_iter_mut().for_each(|k| *k *= memory);
        let (density_iterations, density_error) = timer.time(Stage::PressureSolve, || {
            self.solve(fluid, Solve::ConstantDensity, dt, cancel)
        })?;
        if let Some(rigid) = &mut fluid.rigid {
            // The solve's total kappa is what `density_kappa` now holds.
            rigid.add_pressure_reaction(&fluid.positions, &self.density_kappa, fluid.params.mass);
        }
        timer.time(Stage::Integrate, || {
            let periodic = fluid.periodic.as_ref();
            fluid
                .positions
                .par_iter_mut()
                .zip(fluid.velocities.par_iter_mut())
                .for_each(|(x, v)| {
                    *x += *v * dt;
                    confine(x, v, min, max, periodic);
                });
            fluid.move_bodies(dt, gravity, min, max);
        });
        timer.time(Stage::NeighborSearch, || fluid.find_neighbors());
        timer.time(Stage::Density, || {
            fluid.compute_densities();
            self.compute_factors(fluid);
        });
        let (divergence_iterations, divergence_error) = timer
            .time(Stage::DivergenceSolve, || {
                self.solve(fluid, Solve::DivergenceFree, dt, cancel)
            })?;
        if let Some(rigid) = &mut fluid.rigid {
            // The fluid's velocities changed at the end of the sub-step;
            // so do the bodies'.
            rigid.add_pressure_reaction(
                &fluid.positions,
                &self.divergence_kappa,
                fluid.params.mass,
            );
            rigid.kick(dt);
        }
        fluid.last_solve = SolveInfo {
            density_iterations,
            density_error,
            divergence_iterations,
            divergence_error,
            unconverged: u32::from(density_error > self.params.density_tolerance)
                + u32::from(divergence_error > self.params.divergence_tolerance),
        };
        Ok(())
    }

    /// The warm-start pressures move with their particles; everything
    /// else is recomputed before it is read.
    fn follow(&mut self, order: &[u32], slots: usize) {
        gather(&mut self.density_kappa, order, slots);
    }

    /// The warm-start pressures of the next constant-density solve.
    fn save(&self, out: &mut Vec<Real>) {
        out.clone_from(&self.density_kappa);
    }

    fn restore(&mut self, saved: &[Real]) {
        self.density_kappa.clear();
        self.density_kappa.extend_from_slice(saved);
    }

    /// The factors and pair gradients belong to the neighbour lists.
    fn rebuild(&mut self, fluid: &Fluid) {
        self.compute_factors(fluid);
    }
}

impl Dfsph {
    /// `alpha_i`, the walls' and bodies' density gradient at every
    /// particle and the pair gradients `m_j grad W_ij` the solves reuse.
    fn compute_factors(&mut self, fluid: &Fluid) {
        let (positions, densities, neighbors, kernel, mass, walls, rigid) = (
            &fluid.positions,
            &fluid.densities,
            &fluid.neighbors,
            &fluid.params.gradient_kernel,
            fluid.params.mass,
            fluid.walls.as_ref(),
            fluid.rigid.as_ref(),
        );
        self.gradients
            .resize(neighbors.pair_count(), Vector3::zeros());
        self.factors
            .par_chunks_mut(BLOCK)
            .zip(self.wall_gradients.par_chunks_mut(BLOCK))
            .zip(pair_blocks(neighbors, &mut self.gradients))
            .enumerate()
            .for_each(|(b, ((factors, wall_gradients), gradients))| {
                let first = b * BLOCK;
                let base = neighbors.range(first).start;
                for (k, (alpha, wall)) in factors.iter_mut().zip(wall_gradients).enumerate() {
                    let i = first + k;
                    let xi = positions[i];
                    *wall = walls.map_or(Vector::zeros(), |w| w.density_gradient(&xi))
                        + rigid.map_or(Vector::zeros(), |r| r.density_gradient(i, &xi));
                    let mut sum = *wall;
                    let mut squares = 0.0;
                    let range = neighbors.range(i);
                    let out = &mut gradients[range.start - base..range.end - base];
                    for (slot, (_, r)) in out.iter_mut().zip(neighbors.pairs(i, positions)) {
                        let grad = kernel.gradient(&r, r.norm()) * mass;
                        *slot = grad.cast();
                        sum += grad;
                        squares += grad.norm_squared();
                    }
                    let denominator = sum.norm_squared() + squares;
                    *alpha = if denominator > 0.0 {
                        densities[i] / denominator
                    } else {
                        0.0
                    };
                }
            });
    }

    /// Iterates one solve until its average error is below tolerance or
    /// the cap is reached; returns the iterations and the error reached.
    /// The constant-density solve starts from [`Self::memory`] of the
    /// previous sub-step's pressure, which the sub-step has left in
    /// `density_kappa` (warm start): without it, pressure has to be
    /// rebuilt from nothing every sub-step, one particle layer per
    /// iteration. The divergence solve starts from zero: warm-starting it
    /// as well made a resting tank blow up.
    ///
    /// Each iteration reads `cancel` (up to `max_iterations` of them, each
    /// a pass over every particle, can run for seconds).
    fn solve(
        &mut self,
        fluid: &mut Fluid,
        solve: Solve,
        dt: Real,
        cancel: &Cancel,
    ) -> Result<(u32, Real), Cancelled> {
        let params = self.params;
        let rest = fluid.params.eos.rest_density;
        let n = fluid.len().max(1) as Real;
        let (tolerance, scale) = match solve {
            Solve::ConstantDensity => (params.density_tolerance, 1.0 / dt / dt),
            Solve::DivergenceFree => (params.divergence_tolerance, 1.0 / dt),
        };
        if let Some(rigid) = &fluid.rigid {
            let positions = &fluid.positions;
            self.boundary_flux
                .par_iter_mut()
                .enumerate()
                .for_each(|(i, flux)| *flux = rigid.velocity_flux(i, &positions[i]));
            self.divergence_kappa.par_iter_mut().for_each(|k| *k = 0.0);
        }
        if solve == Solve::ConstantDensity {
            self.kappa.clone_from(&self.density_kappa);
            self.apply_kappa(fluid, dt);
            self.add_pressure(fluid);
        }
        let mut iterations = 0;
        loop {
            let mean = self.compute_source(fluid, solve, dt) / n;
            let error = match solve {
                Solve::ConstantDensity => mean / rest,
                // Per paced sub-step, not per sub-step: a per-sub-step
                // tolerance let a sub-step of 1e-5 s keep compression
                // rates a paced sub-step would correct.
                Solve::DivergenceFree if self.pace > 0.0 => mean * (dt / self.pace) / rest,
                Solve::DivergenceFree => mean * dt / rest,
            };
            let converged = error <= tolerance && iterations >= solve.min_iterations();
            if converged || iterations >= params.max_iterations {
                return Ok((iterations, error));
            }
            cancel.check()?;
            let densities = &fluid.densities;
            self.kappa
                .par_iter_mut()
                .zip(self.source.par_iter())
                .zip(self.factors.par_iter())
                .zip(densities.par_iter())
                .for_each(|(((kappa, s), alpha), rho)| *kappa = s * alpha * scale / rho);
            let total = match solve {
                Solve::ConstantDensity => &mut self.density_kappa,
                // Empty without rigid bodies: nothing to sum.
                Solve::DivergenceFree => &mut self.divergence_kappa,
            };
            total
                .par_iter_mut()
                .zip(self.kappa.par_iter())
                .for_each(|(total, kappa)| *total += kappa);
            self.add_pressure(fluid);
            self.apply_kappa(fluid, dt);
            iterations += 1;
        }
    }

    /// Both solves push with the pressure form of Eq. 51, `kappa = p / rho`:
    /// the pressure a frame reports is their sum, `p = rho sum kappa`.
    fn add_pressure(&self, fluid: &mut Fluid) {
        let kappa = &self.kappa;
        fluid
            .pressures
            .par_iter_mut()
            .zip(fluid.densities.par_iter())
            .enumerate()
            .for_each(|(i, (p, rho))| *p += kappa[i] * rho * rho);
    }

    /// The density source of each particle from the current velocities:
    /// for the constant-density solve the predicted density excess
    /// `max(e_i + dt D rho_i / Dt, 0)`, for the divergence solve
    /// `max(D rho_i / Dt, 0)`, with the standing error
    /// `e_i = rho_i - rho_0` where it is a deficit (room to compress) and
    /// `pace^2 (rho_i - rho_0)` where it is an excess: the sub-step stops
    /// all new compression but corrects an excess it found only as fast as
    /// a paced sub-step would. Correcting it all within the sub-step moves
    /// particles at `(excess / rho_0) h / dt`, so a start from a lattice a
    /// fraction of a per cent dense at its walls launched the fluid at
    /// metres per second when stepped at 1e-5 s. The square because the
    /// pressure that corrects it (`kappa ~ e / dt^2`) is remembered for
    /// `1 / pace` sub-steps: `pace^2 e / dt^2 = e / dt_pace^2`, a
    /// pressure independent of how the time is cut. And
    /// `D rho_i / Dt = sum_j m_j (v_i - v_j) . grad W_ij + v_i . grad rho_wall`,
    /// less `sum_b psi_b v_b . grad W_ib` where rigid bodies move.
    /// Only compression is corrected: free surfaces may expand.
    fn compute_source(&mut self, fluid: &Fluid, solve: Solve, dt: Real) -> Real {
        let (velocities, densities, neighbors) =
            (&fluid.velocities, &fluid.densities, &fluid.neighbors);
        let rest = fluid.params.eos.rest_density;
        let pace = self.pace;
        let (walls, flux, gradients) = (&self.wall_gradients, &self.boundary_flux, &self.gradients);
        self.source
            .par_iter_mut()
            .enumerate()
            .for_each(|(i, source)| {
                let vi = velocities[i];
                let mut rate = vi.dot(&walls[i]) - flux.get(i).copied().unwrap_or(0.0);
                let range = neighbors.range(i);
                for (&j, grad) in neighbors.of(i).iter().zip(&gradients[range]) {
                    rate += (vi - velocities[j as usize]).dot(&grad.cast());
                }
                *source = match solve {
                    Solve::ConstantDensity => {
                        let standing = densities[i] - rest;
                        let standing = if standing > 0.0 {
                            pace * pace * standing
                        } else {
                            standing
                        };
                        (standing + dt * rate).max(0.0)
                    }
                    Solve::DivergenceFree => rate.max(0.0),
                };
            });
        // Summed in order: a parallel sum's grouping follows the work
        // stealing, so its last bits (and, at the tolerance, the iteration
        // count) varied from run to run, and a restored snapshot did not
        // always continue bit for bit (`engine/tests/snapshot.rs`).
        self.source.iter().sum()
    }

    /// `v_i -= dt (sum_j m_j (kappa_i / rho_i + kappa_j / rho_j) grad W_ij
    /// + kappa_i / rho_i grad rho_wall)`.
    fn apply_kappa(&self, fluid: &mut Fluid, dt: Real) {
        let neighbors = &fluid.neighbors;
        let (kappa, walls, gradients) = (&self.kappa, &self.wall_gradients, &self.gradients);
        fluid
            .velocities
            .par_iter_mut()
            .enumerate()
            .for_each(|(i, v)| {
                let ki = kappa[i];
                let mut push = walls[i] * ki;
                let range = neighbors.range(i);
                // The self-pair's gradient is zero.
                for (&j, grad) in neighbors.of(i).iter().zip(&gradients[range]) {
                    push += grad.cast::<Real>() * (ki + kappa[j as usize]);
                }
                *v -= push * dt;
            });
    }
}

/// Particles per parallel work item of `Dfsph::compute_factors`.
const BLOCK: usize = 256;

/// Splits per-pair data aligned with `neighbors` into the runs of
/// consecutive blocks of [`BLOCK`] particles, so that the blocks can be
/// filled in parallel.
fn pair_blocks<'a, T: Send>(neighbors: &NeighborList, mut data: &'a mut [T]) -> Vec<&'a mut [T]> {
    let n = neighbors.len();
    (0..n.div_ceil(BLOCK))
        .map(|b| {
            let len = neighbors.range((b * BLOCK + BLOCK).min(n) - 1).end
                - neighbors.range(b * BLOCK).start;
            let (head, tail) = std::mem::take(&mut data).split_at_mut(len);
            data = tail;
            head
        })
        .collect()
}
