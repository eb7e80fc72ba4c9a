//! Faults for a fluid or an elastic solid that goes wrong while every
//! value is still finite (non-finite and runaway values are
//! `first_invalid`'s, collapsed solids `ElasticSolid::collapsed`'s):
//! compression far outside what a weakly compressible or divergence-free
//! fluid allows, and mechanical energy gained from nowhere.
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
//!
//! **Solids** are watched the same way: `E = KE + U - sum m g . x` with
//! `U` the stored energy (elastic, volume, hourglass, and the implicit
//! contact penalty's), which backward Euler, damping, friction and plastic
//! flow can only lower; the scale is `KE_0 + U_0 + M |g| H + M c_p^2 /
//! 1000` (`H` the walls' extent along gravity, or the body's own without
//! walls; `c_p` the fastest elastic wave, so the last term is the energy
//! of straining the body by about 4.5 %). The stored energy `U_0` is in
//! the scale because the explicit integrator's energy swings about its
//! conserved value by a fraction of what is stored, within its stability
//! limit: a block released from a 50 % stretch swung by 4.7 % in its
//! first step. A solid edited between steps
//! (`World::solid_mut`) is measured again. At E = 1e12 Pa a block whose
//! Newton solves stopped at their cap once gained 1.8e8 times its energy
//! with only a warning; a step that gains more than [`MAX_ENERGY_GAIN`]
//! of the scale now faults, and names the unconverged solves when there
//! were any.
use super::StepError;
use crate::fluid::FluidSystem;
use crate::math::{Real, Vector};
use crate::solid::ElasticSolid;

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

    /// Moves the start by `by` joules: what a change of the energy
    /// functional itself (cracks that cut pairs) added at fixed positions
    /// and velocities is not a gain of the scheme's.
    pub fn shift(&mut self, by: Real) {
        if let Some((start, _)) = self.start.as_mut() {
            *start += by;
        }
    }

    /// Measures the start `(E_0, S)` with `measure` at the first step
    /// after a restart; call before the step.
    pub fn begin_with(&mut self, measure: impl FnOnce() -> (Real, Real)) {
        if self.start.is_none() {
            self.start = Some(measure());
        }
    }

    /// The gain `(J, fraction of the scale)` of `energy` over the start,
    /// when it exceeds [`MAX_ENERGY_GAIN`].
    pub fn excess(&self, energy: Real) -> Option<(Real, Real)> {
        let (start, scale) = self.start?;
        let gained = energy - start;
        (gained > MAX_ENERGY_GAIN * scale).then(|| (gained, gained / scale))
    }

    /// Measures a fluid's start at the first step after a restart; call
    /// before the step.
    pub fn begin(&mut self, system: &FluidSystem, gravity: &Vector, bounds: &(Vector, Vector)) {
        self.begin_with(|| {
            let fluid = system.fluid();
            let mass = fluid.total_mass();
            let height: Real = (0..3)
                .map(|a| gravity[a].abs() * (bounds.1[a] - bounds.0[a]))
                .sum();
            let sound = fluid.params.eos.sound_speed();
            let kinetic = fluid.kinetic_energy();
            let scale = kinetic + mass * height + 1e-3 * mass * sound * sound;
            (kinetic + fluid.potential_energy(gravity), scale)
        });
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
        if fluid.has_energy_source() {
            return Ok(());
        }
        let energy = fluid.kinetic_energy() + fluid.potential_energy(gravity);
        match self.excess(energy) {
            Some((gained, fraction)) => Err(StepError::EnergyGained {
                gained,
                advice: energy_advice(system),
                fraction,
                limit: MAX_ENERGY_GAIN,
                step,
            }),
            None => Ok(()),
        }
    }

    /// The fault of a solid's finished step of `dt`, if it gained energy
    /// from nowhere; `unconverged` says whether its solve stopped at its
    /// cap, which the advice then names.
    pub fn check_solid(
        &self,
        solid: &ElasticSolid,
        system: usize,
        gravity: &Vector,
        dt: Real,
        unconverged: bool,
        step: u64,
    ) -> Result<(), StepError> {
        match self.excess(solid.mechanical_energy(gravity, dt)) {
            Some((gained, fraction)) => Err(StepError::SolidEnergyGained {
                system,
                gained,
                fraction,
                limit: MAX_ENERGY_GAIN,
                advice: solid_energy_advice(solid, unconverged),
                step,
            }),
            None => Ok(()),
        }
    }
}

/// What to change when a solid gains energy: an unconverged implicit
/// solve is not the backward Euler step it claims to be; an explicit
/// step beyond its limit, or a contact projection, is what is left.
fn solid_energy_advice(solid: &ElasticSolid, unconverged: bool) -> &'static str {
    if unconverged {
        "its Newton solve stopped at max_newton_iterations above newton_tolerance: raise          max_newton_iterations, set linear_solver = \"cholesky\", or lower time.dt"
    } else if solid.is_implicit() {
        "lower time.dt, or set linear_solver = \"cholesky\""
    } else {
        "lower time.dt or the integrator's cfl, or use integrator = \"implicit\""
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_watch_measures_once_and_flags_only_a_gain_past_its_limit() {
        let mut watch = EnergyWatch::default();
        assert_eq!(watch.excess(1e9), None, "nothing measured yet");
        watch.begin_with(|| (10.0, 100.0));
        watch.begin_with(|| panic!("measured once until restarted"));
        assert_eq!(watch.excess(10.0 + 0.99 * MAX_ENERGY_GAIN * 100.0), None);
        assert_eq!(watch.excess(-1e6), None, "losing energy is allowed");
        let (gained, fraction) = watch.excess(30.0).expect("a gain of 20 % of the scale");
        assert!((gained - 20.0).abs() < 1e-12 && (fraction - 0.2).abs() < 1e-12);
        watch.restart();
        assert_eq!(watch.start(), None);
    }
}
