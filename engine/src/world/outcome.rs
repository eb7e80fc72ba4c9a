//! What a step reports: how it was carried out ([`StepInfo`]) or why it
//! failed ([`StepError`]), shared by every kind of system.

use crate::math::Real;

/// How the last step was carried out.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepInfo {
    /// Sub-steps the step was split into.
    pub substeps: u32,
    /// Shortest sub-step, s.
    pub min_substep: Real,
    /// Whether `max_substeps` capped the split, so sub-steps exceeded the
    /// stability limit.
    pub capped: bool,
    /// Pressure-solver iterations over all sub-steps (0 for WCSPH).
    pub solver_iterations: u32,
    /// Worst average density error after a sub-step's pressure solve
    /// (fraction of rho_0; 0 for WCSPH).
    pub density_error: Real,
    /// Of `solver_iterations`, the implicit solids' Newton and CG
    /// iterations.
    pub solid_iterations: u32,
    /// The implicit solids' worst final Newton residual (relative; see
    /// `SolidStep::residual`).
    pub solid_residual: Real,
    /// Solves that stopped at their iteration cap above their tolerance:
    /// DFSPH pressure solves and implicit solids' Newton solves. Nonzero
    /// means the step is not as accurate as the scene asked.
    pub unconverged: u32,
    /// Particles the systems gained at the step's start, new ids after
    /// their system's last (a fracturing solid's resampling, a fluid's
    /// queued insertions).
    pub added: u32,
}

impl StepInfo {
    /// A step of `dt` before any system took part in it.
    pub(crate) fn start(dt: Real) -> Self {
        Self {
            substeps: 0,
            min_substep: dt,
            capped: false,
            solver_iterations: 0,
            density_error: 0.0,
            solid_iterations: 0,
            solid_residual: 0.0,
            unconverged: 0,
            added: 0,
        }
    }

    /// Adds one system's share: the most sub-steps and the shortest of
    /// any system, the iterations of all.
    pub(crate) fn merge(&mut self, system: &StepInfo) {
        self.substeps = self.substeps.max(system.substeps);
        self.min_substep = self.min_substep.min(system.min_substep);
        self.capped |= system.capped;
        self.solver_iterations += system.solver_iterations;
        self.density_error = self.density_error.max(system.density_error);
        self.solid_iterations += system.solid_iterations;
        self.solid_residual = self.solid_residual.max(system.solid_residual);
        self.unconverged += system.unconverged;
        self.added += system.added;
    }
}

/// A step failed; the world is left as it was before the step.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StepError {
    /// The fluid blew up.
    #[error(
        "the {quantity} of particle {particle} left its valid range ({value:e}) in sub-step \
         {substep} of step {step}; the simulation is unstable: lower time.dt, time.cfl or the \
         stiffness, or raise time.max_substeps"
    )]
    Unstable {
        /// What left its range ("position", "velocity", ...).
        quantity: &'static str,
        /// The particle's id (or a body's index among the fluid's bodies).
        particle: usize,
        /// The offending value (a norm for vectors).
        value: f64,
        /// The step that failed.
        step: u64,
        /// The sub-step of it that failed, from 1.
        substep: u32,
    },
    /// An elastic solid blew up.
    #[error(
        "the {quantity} of particle {particle} (of the solid in systems[{system}]) left its \
         valid range ({value:e}) in step {step}; the solid is unstable: lower time.dt or its \
         cfl, raise time.max_substeps, or set integrator = \"implicit\""
    )]
    SolidUnstable {
        /// Index of the solid's system in the scene.
        system: usize,
        /// What left its range ("position", "velocity", ...).
        quantity: &'static str,
        /// The particle, in the solid's order.
        particle: usize,
        /// The offending value (a norm for vectors).
        value: f64,
        /// The step that failed.
        step: u64,
    },
    /// An elastic solid's particle was squeezed to a sliver of its volume
    /// or turned inside out ([`crate::solid::ElasticSolid::MIN_VOLUME_RATIO`]).
    #[error(
        "particle {particle} of the solid in systems[{system}] was squeezed to {ratio:.3} of its \
         volume in step {step} (below the {limit} a solid allows; 0 or less is inside out): the \
         solid collapsed; {advice}"
    )]
    Collapsed {
        /// Index of the solid's system in the scene.
        system: usize,
        /// The particle, in the solid's order.
        particle: usize,
        /// Its volume ratio `det F`.
        ratio: f64,
        /// The smallest ratio allowed.
        limit: f64,
        /// What to change, for the solid's material.
        advice: &'static str,
        /// The step that failed.
        step: u64,
    },
    /// A fracturing solid in the static scheme let a fragment break free
    /// of every anchor: a free body under load has no static equilibrium.
    #[error(
        "the solid in systems[{system}] stopped in step {step}: its cracks freed a fragment of \
         {particles} particles from every anchor, and the static scheme has no equilibrium for \
         a free body; use scheme = \"backward_euler\" for a solid whose pieces may fall, or \
         anchor every piece"
    )]
    FragmentFreeInStatics {
        /// Index of the solid's system in the scene.
        system: usize,
        /// The free fragment's particles (the largest, where several).
        particles: usize,
        /// The step that failed.
        step: u64,
    },
    /// A resampling solid would grow past the particles it was admitted
    /// with.
    #[error("the solid in systems[{system}] stopped in step {step}: {reason}")]
    ParticleLimit {
        /// Index of the solid's system in the scene.
        system: usize,
        /// How many, and what to change.
        reason: crate::solid::ResampleError,
        /// The step that failed.
        step: u64,
    },
    /// A shell's step could not be solved (Newton did not converge, the
    /// surface folded flat, the tangent was singular).
    #[error("the shell in systems[{system}] stopped in step {step}: {reason}")]
    ShellFailed {
        /// Index of the shell's system in the scene.
        system: usize,
        /// Why, with what to change.
        reason: crate::shell::ShellError,
        /// The step that failed.
        step: u64,
    },
    /// A fracturing solid's cracks outgrew the bound on their geometry.
    #[error("the solid in systems[{system}] stopped in step {step}: {reason}")]
    CracksOutgrown {
        /// Index of the solid's system in the scene.
        system: usize,
        /// Why, with the bound.
        reason: crate::solid::FractureError,
        /// The step that failed.
        step: u64,
    },
    /// A fluid particle was compressed beyond the band a fluid allows
    /// ([`crate::world::watch::MAX_COMPRESSION`]).
    #[error(
        "the density of fluid particle {particle} reached {ratio:.3} times the rest density in \
         step {step}, beyond the {limit} a fluid allows: the pressure solve is not holding the \
         fluid; lower time.dt or raise time.max_substeps, raise the stiffness (wcsph) or lower \
         density_tolerance (dfsph)"
    )]
    Compressed {
        /// The particle's id.
        particle: usize,
        /// Its density over the rest density.
        ratio: Real,
        /// The largest ratio allowed.
        limit: Real,
        /// The step that failed.
        step: u64,
    },
    /// The fluid gained mechanical energy with nothing to supply it
    /// ([`crate::world::watch::MAX_ENERGY_GAIN`]).
    #[error(
        "the fluid's mechanical energy rose by {gained:.3e} J since it started ({:.1} % of its \
         scale, beyond the {:.0} % allowed) in step {step}, with no moving wall or body to supply \
         it: the scheme is adding energy; {advice}", 100.0 * fraction, 100.0 * limit
    )]
    EnergyGained {
        /// Joules gained (per metre of depth in 2D).
        gained: Real,
        /// What to change, for the fluid's pressure solver.
        advice: &'static str,
        /// The gain as a fraction of the energy scale.
        fraction: Real,
        /// The largest fraction allowed.
        limit: Real,
        /// The step that failed.
        step: u64,
    },
    /// An elastic solid gained mechanical energy with nothing to supply it
    /// ([`crate::world::watch::MAX_ENERGY_GAIN`]).
    #[error(
        "the solid in systems[{system}] gained {gained:.3e} J of mechanical energy since it \
         started ({:.1} % of its scale, beyond the {:.0} % allowed) in step {step}: the step is \
         adding energy; {advice}", 100.0 * fraction, 100.0 * limit
    )]
    SolidEnergyGained {
        /// Index of the solid's system in the scene.
        system: usize,
        /// Joules gained (per metre of depth in 2D).
        gained: Real,
        /// The gain as a fraction of the energy scale.
        fraction: Real,
        /// The largest fraction allowed.
        limit: Real,
        /// What to change, for the solid's integrator and its solve.
        advice: &'static str,
        /// The step that failed.
        step: u64,
    },
    /// The step's [`Cancel`](crate::cancel::Cancel) was raised before it
    /// finished (see
    /// [`World::step_cancellable`](crate::world::World::step_cancellable)): not a fault, the step can be taken
    /// again.
    #[error("step {step} was cancelled before it finished; the world is as it was before the step")]
    Cancelled {
        /// The step that was cancelled (steps completed plus one).
        step: u64,
    },
    /// The step counter is at its largest value (a restored snapshot can
    /// put it there): one more step would wrap it to 0, and frames,
    /// checkpoints and progress would count from there. Refused before
    /// anything changes.
    #[error(
        "the world is at step {step}, the largest step count there is, and takes no more steps \
         (the counter never wraps); reset the session or restore an earlier snapshot"
    )]
    CounterFull {
        /// The step the world is at: [`u64::MAX`].
        step: u64,
    },
}
