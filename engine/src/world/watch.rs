//! Faults for a fluid that goes wrong while every value is still finite
//! (non-finite and runaway values are `first_invalid`'s): compression far
//! outside what a weakly compressible or divergence-free fluid allows, and
//! mechanical energy gained from nowhere.
//!
//! Both caught real silent garbage: a 2D WCSPH dam break at `time.dt =
//! 0.3 s`, its sub-steps capped by `max_substeps`, ran to the end with
//! speeds of 2,205 m/s and densities of 1.62 rho_0; `negative_pressure_scale
//! = 1` raised the kinetic energy of an inviscid drop by 81 % in 0.1 s.
//! (engine/tests/world.rs pins both.)
//!
//! **Compression**: the largest density may exceed the rest density by at
//! most [`MAX_COMPRESSION`]. A weakly compressible fluid is tuned for about
//! 1 % (sound speed ten times the flow speed); 30 % means the sound speed is
//! below twice the flow speed, or the pressure solve is not holding the
//! fluid at all.
//!
//! **Energy**: the fluid's mechanical energy `E = sum m (|v|^2 / 2 - g . x)`
//! can only fall (viscosity, XSPH, walls and static bodies dissipate;
//! compression stores a little) unless something supplies it: moving walls
//! or moving bodies, whose fluids are not watched. It is measured from the
//! first step (and again after particles are removed), and may exceed its
//! start by at most [`MAX_ENERGY_GAIN`] of the scale
//! `S = KE_0 + M |g| H + M c^2 / 1000` (`H` the domain's extent along
//! gravity, `c` the Tait sound speed: the last term is the energy of
//! compressing the fluid by about 4.5 %, which keeps a fluid starting at
//! rest without gravity from faulting on round-off).

use super::StepError;
use crate::fluid::FluidSystem;
use crate::math::{Real, Vector};

/// Largest density excess over the rest density, as a fraction.
pub const MAX_COMPRESSION: Real = 0.3;

/// Largest mechanical energy gain over the start, as a fraction of the
/// scale in the module documentation.
pub const MAX_ENERGY_GAIN: Real = 0.1;

/// The energy a fluid started from, once measured.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct EnergyWatch {
    /// `(E_0, S)`.
    start: Option<(Real, Real)>,
}

impl EnergyWatch {
    /// Measures the start again at the next step (after particles were
    /// removed: the energy they took along is no gain).
    pub fn restart(&mut self) {
        self.start = None;
    }

    /// The start `(E_0, S)`, once measured.
    pub fn start(&self) -> Option<(Real, Real)> {
        self.start
    }

    /// Sets what [`Self::start`] reads (a restored snapshot's).
    pub fn set_start(&mut self, start: Option<(Real, Real)>) {
        self.start = start;
    }

    /// Measures the start at the first step after a restart; call before
    /// the step.
    pub fn begin(&mut self, system: &FluidSystem, gravity: &Vector, bounds: &(Vector, Vector)) {
        if self.start.is_some() {
            return;
        }
        let fluid = system.fluid();
        let mass = fluid.total_mass();
        let height: Real = (0..3)
            .map(|a| gravity[a].abs() * (bounds.1[a] - bounds.0[a]))
            .sum();
        let sound = fluid.params.eos.sound_speed();
        let kinetic = fluid.kinetic_energy();
        let scale = kinetic + mass * height + 1e-3 * mass * sound * sound;
        self.start = Some((kinetic + fluid.potential_energy(gravity), scale));
    }

    /// The fault of a finished step, if its state left the band or gained
    /// energy from nowhere.
    pub fn check(
        &self,
        system: &FluidSystem,
        gravity: &Vector,
        step: u64,
    ) -> Result<(), StepError> {
        let fluid = system.fluid();
        let (particle, ratio) = fluid.max_compression();
        if ratio > 1.0 + MAX_COMPRESSION {
            return Err(StepError::Compressed {
                particle: fluid.id_of(particle),
                ratio,
                limit: 1.0 + MAX_COMPRESSION,
                step,
            });
        }
        if let Some((start, scale)) = self.start
            && !fluid.has_energy_source()
        {
            let energy = fluid.kinetic_energy() + fluid.potential_energy(gravity);
            let gained = energy - start;
            if gained > MAX_ENERGY_GAIN * scale {
                return Err(StepError::EnergyGained {
                    gained,
                    advice: energy_advice(system),
                    fraction: gained / scale,
                    limit: MAX_ENERGY_GAIN,
                    step,
                });
            }
        }
        Ok(())
    }
}

/// What to change when a fluid gains energy, by what gains it in each
/// solver. WCSPH's gain comes from its explicit step, tensile instability
/// or a kernel pair that does not conserve energy. DFSPH has no step to
/// shorten: it is paced by its CFL sub-step however short the sub-steps
/// (a shorter `time.dt` used to be what pumped it), so what is left is a
/// solve stopped at its cap with the fluid compressed, pushed back within
/// one sub-step.
fn energy_advice(system: &FluidSystem) -> &'static str {
    if system.pressure().has_equation_of_state() {
        "lower time.dt, set negative_pressure_scale = 0, or use one kernel for densities and \
         pressure"
    } else {
        "raise max_solver_iterations or lower density_tolerance so that the pressure solves \
         converge (a solve stopped at its cap leaves the fluid compressed); a shorter time.dt \
         does not help DFSPH"
    }
}
