//! Per-stage counters of a world's step: how often each pass ran and how
//! long it took, for every system kind (the fluid's passes, then the
//! elastic solids' and the modal solids'). They make "a scene pays only
//! for what it names" testable and show where the time goes.

use std::time::Instant;

/// A pass of the step pipeline.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// Grid rebuild and neighbour lists.
    NeighborSearch,
    /// Density sums (and WCSPH's equation of state, DFSPH's factors).
    Density,
    /// WCSPH's pressure accelerations (Eq. 51).
    PressureForce,
    /// DFSPH's constant-density solve.
    PressureSolve,
    /// DFSPH's divergence-free solve.
    DivergenceSolve,
    /// Physical viscosity (and bodies' no-slip terms).
    Viscosity,
    /// XSPH smoothing (Eq. 53).
    Xsph,
    /// Time integration and the bodies' motion.
    Integrate,
    /// An elastic solid's internal forces: MLS deformation gradients,
    /// stresses and their forces (explicit sub-steps).
    SolidForces,
    /// An implicit elastic solid's Newton solve: assembly and linear
    /// solves.
    SolidSolve,
    /// An elastic solid's velocity and position update.
    SolidIntegrate,
    /// An elastic solid's contact with obstacles and walls, and its
    /// plastic flow.
    SolidContact,
    /// A modal solid's step: the reduced (or, under nonlinear dynamics,
    /// the full Newton) solve, or its playback.
    ModalSolve,
    /// A shell's step: its Newton solve on the sparse tangent.
    ShellSolve,
}

impl Stage {
    /// Every stage, in pipeline order.
    pub const ALL: [Stage; 14] = [
        Stage::NeighborSearch,
        Stage::Density,
        Stage::PressureForce,
        Stage::PressureSolve,
        Stage::DivergenceSolve,
        Stage::Viscosity,
        Stage::Xsph,
        Stage::Integrate,
        Stage::SolidForces,
        Stage::SolidSolve,
        Stage::SolidIntegrate,
        Stage::SolidContact,
        Stage::ModalSolve,
        Stage::ShellSolve,
    ];

    /// The stage's name for people.
    pub fn name(self) -> &'static str {
        match self {
            Stage::NeighborSearch => "neighbour search",
            Stage::Density => "density and pressure",
            Stage::PressureForce => "pressure force",
            Stage::PressureSolve => "pressure solve",
            Stage::DivergenceSolve => "divergence solve",
            Stage::Viscosity => "viscosity",
            Stage::Xsph => "XSPH",
            Stage::Integrate => "integration",
            Stage::SolidForces => "solid forces",
            Stage::SolidSolve => "solid implicit solve",
            Stage::SolidIntegrate => "solid integration",
            Stage::SolidContact => "solid contact",
            Stage::ModalSolve => "modal solve",
            Stage::ShellSolve => "shell solve",
        }
    }
}

/// Runs and wall-clock seconds of one stage.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageStats {
    /// Times the stage ran.
    pub runs: u64,
    /// Wall-clock seconds it took in all.
    pub seconds: f64,
}

/// Counters for every [`Stage`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StageTimer {
    stats: [StageStats; Stage::ALL.len()],
}

impl StageTimer {
    /// Runs `work`, counting it under `stage`.
    #[inline]
    pub fn time<R>(&mut self, stage: Stage, work: impl FnOnce() -> R) -> R {
        let start = Instant::now();
        let result = work();
        let s = &mut self.stats[stage as usize];
        s.runs += 1;
        s.seconds += start.elapsed().as_secs_f64();
        result
    }

    /// The counters of one stage.
    pub fn get(&self, stage: Stage) -> StageStats {
        self.stats[stage as usize]
    }

    /// `(stage, stats)` for every stage, in pipeline order.
    pub fn iter(&self) -> impl Iterator<Item = (Stage, StageStats)> + '_ {
        Stage::ALL.iter().map(|&s| (s, self.get(s)))
    }
}
