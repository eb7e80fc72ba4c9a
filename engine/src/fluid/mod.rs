//! SPH fluids: the weakly compressible solver of the Adams–Wicke tutorial
//! (Section 6, Algorithm 5) with the Tait equation of state, DFSPH, the
//! domain's walls and rigid bodies coupled both ways.
//!
//! [`Fluid`] (`particles.rs`) is the particles' state with the passes
//! every solver shares; [`Pressure`] (`pressure/`) is the solver, which
//! owns its parameters and scratch; [`FluidSystem`], here, is the two
//! together: what a world steps.

mod eos;
mod particles;
mod pressure;
mod reorder;
mod snapshot;
mod viscosity;
mod walls;

pub use eos::Tait;
pub use particles::{Fluid, FluidParams, FluidState, Invalid};
pub use pressure::{Dfsph, DfsphParams, Pressure, SolveInfo, Wcsph};
pub use snapshot::FluidSnapshot;
pub use viscosity::ViscosityModel;
pub use walls::BoxWalls;

use crate::cancel::{Cancel, Cancelled};
use crate::expression::VectorField;
use crate::math::{Real, Vector};
use crate::neighbors::{Periodic, UniformGrid};
use crate::rigid::RigidBodies;
use crate::stats::StageTimer;

/// A fluid and its pressure solver: built, sub-stepped, checked, saved
/// and restored as one.
#[derive(Debug, Clone)]
pub struct FluidSystem {
    fluid: Fluid,
    pressure: Pressure,
}

impl FluidSystem {
    /// A fluid with the given particles, stepped by `pressure`; `grid`
    /// must cover the domain with cells of at least the support radius and
    /// wrap around the same `periodic` axes.
    pub fn new(
        params: FluidParams,
        mut pressure: Pressure,
        positions: Vec<Vector>,
        velocities: Vec<Vector>,
        walls: Option<BoxWalls>,
        grid: UniformGrid,
        periodic: Option<Periodic>,
    ) -> Self {
        let mut fluid = Fluid::new(params, positions, velocities, walls, grid, periodic);
        // Densities and pressures of the initial state, so frame 0 and the
        // first stability limit see real values.
        fluid.find_neighbors();
        fluid.compute_densities();
        pressure.solver_mut().init(&mut fluid);
        let mut system = Self { fluid, pressure };
        system.reorder();
        system
    }

    /// Puts rigid bodies into the fluid and recomputes the densities,
    /// pressures and solver factors they change.
    pub fn attach_bodies(&mut self, bodies: RigidBodies) {
        self.fluid.rigid = Some(bodies);
        self.refresh();
    }

    /// Adds `force` (per unit mass, at each particle's position) to
    /// gravity at every sub-step.
    pub fn set_body_force(&mut self, force: VectorField) {
        self.fluid.body_force = Some(force);
    }

    /// The fluid's particles.
    pub fn fluid(&self) -> &Fluid {
        &self.fluid
    }

    /// The fluid's particles, to set up an initial state a scene cannot
    /// describe.
    pub fn fluid_mut(&mut self) -> &mut Fluid {
        &mut self.fluid
    }

    /// The pressure solver.
    pub fn pressure(&self) -> &Pressure {
        &self.pressure
    }

    /// The largest sub-step the scheme allows now under `gravity`: the
    /// solver's CFL and force conditions (see each solver) and, with
    /// viscosity, the diffusion condition.
    ///
    /// The force condition takes the largest acceleration of the last
    /// sub-step, and never less than gravity: a fluid that has not stepped
    /// yet (a start, a restored snapshot) has recorded none, and its first
    /// sub-step took the whole of `time.dt` unlimited. A DFSPH tank at
    /// rest, 40 particles deep, stepped at 0.02 s so took one 0.02 s
    /// sub-step, its pressure solve stopped at its cap, and the fluid was
    /// launched upward (tests/tests/validation_tank.rs).
    pub fn stable_dt(&self, cfl: Real, gravity: &Vector) -> Real {
        let v_max = self.fluid.max_speed();
        let a_max = self.fluid.max_acceleration.max(gravity.norm());
        let dt = self
            .pressure
            .solver()
            .stable_dt(&self.fluid, cfl, v_max, a_max);
        self.fluid.viscous_limit(dt)
    }

    /// One sub-step of length `dt` with the scene's solver, reflecting
    /// particles off the walls of `[min, max]`.
    ///
    /// # Errors
    /// [`Cancelled`] when `cancel` stopped an iterating solver part-way:
    /// put back a state [`Self::save`]d before the step.
    pub fn substep(
        &mut self,
        dt: Real,
        gravity: &Vector,
        min: &Vector,
        max: &Vector,
        timer: &mut StageTimer,
        cancel: &Cancel,
    ) -> Result<(), Cancelled> {
        self.fluid.substeps_since_reorder += 1;
        self.pressure
            .solver_mut()
            .substep(&mut self.fluid, dt, gravity, min, max, timer, cancel)
    }

    /// The first particle whose state cannot go on: a position, velocity,
    /// density or pressure that is not finite or does not fit a frame's
    /// f32, or a speed above the solver's limit ([`Wcsph::SPEED_LIMIT`]
    /// times the speed of sound, [`Dfsph::SPEED_LIMIT`]); or a rigid
    /// body's state that is not finite.
    pub fn first_invalid(&self) -> Option<Invalid> {
        let limit = self.pressure.solver().speed_limit(&self.fluid.params);
        self.fluid.first_invalid(limit)
    }

    /// Copies the evolving state, the solver's warm start included, into
    /// `backup`, reusing its buffers.
    pub fn save(&self, backup: &mut FluidState) {
        self.fluid.save(backup);
        self.pressure.solver().save(&mut backup.warm_start);
    }

    /// Puts back a state saved by [`Self::save`], with the neighbour
    /// lists (and DFSPH's factors and pair gradients) of its positions, so
    /// that the next step starts from the saved state alone.
    pub fn restore(&mut self, backup: &FluidState) {
        self.fluid.restore(backup);
        let solver = self.pressure.solver_mut();
        solver.restore(&backup.warm_start);
        solver.rebuild(&self.fluid);
    }

    /// Removes the particles whose ids `removed` lists (sorted; an id of
    /// no particle is passed over); the survivors keep their ids.
    /// Recomputes the survivors' densities, pressures and solver factors,
    /// as after bodies attach. Call between steps, never during one.
    pub fn remove(&mut self, removed: &[u32]) {
        let slots = self.fluid.len();
        let kept = self.fluid.retain(removed);
        self.pressure.solver_mut().follow(&kept, slots);
        self.refresh();
    }

    /// Adds particles at `positions` moving at `velocities` (as many of
    /// each), with the next ids in order, and recomputes every particle's
    /// density, pressure and solver factors in the new neighbourhoods (a
    /// new particle's warm start is zero). Call between steps, never
    /// during one. Returns the first new id.
    ///
    /// # Errors
    /// [`IdsExhausted`] when the new ids would pass `u32::MAX`; nothing is
    /// added then.
    pub fn insert(
        &mut self,
        positions: &[Vector],
        velocities: &[Vector],
    ) -> Result<u32, IdsExhausted> {
        let count = positions.len().min(velocities.len());
        if u32::try_from(count)
            .ok()
            .and_then(|k| self.fluid.next_id.checked_add(k))
            .is_none()
        {
            return Err(IdsExhausted {
                next_id: self.fluid.next_id,
            });
        }
        let first = self.fluid.append(&positions[..count], &velocities[..count]);
        self.refresh();
        Ok(first)
    }

    /// Neighbours, densities and what the solver derives from them
    /// (sized to the particles), from scratch.
    fn refresh(&mut self) {
        self.fluid.find_neighbors();
        self.fluid.compute_densities();
        self.pressure.solver_mut().init(&mut self.fluid);
    }
}

/// A fluid has given every id a `u32` holds: ids are never reused, so it
/// takes no new particle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("the fluid has given {next_id} particle ids, the most it can; it takes no new particle")]
pub struct IdsExhausted {
    /// The id the next particle would get.
    pub next_id: u32,
}
