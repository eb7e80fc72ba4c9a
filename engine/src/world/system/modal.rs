//! A modal EFG solid as the world keeps it: the adapter between
//! [`ModalSolid`] (discretised and reduced by its scene check) and the
//! world's [`Simulated`] trait, with the scene's mode playback and grabs.

use super::simulated::{GrabRefusal, Invalid, RemoveError, Simulated, StepEnv};
use crate::efg::{
    Grab, GrabError, ModalSolid, ModalState, MotionError, NonlinearError, StepReport,
};
use crate::frame::{FieldKind, SolidSurface};
use crate::geometry::TriMesh;
use crate::math::{Real, Vector};
use crate::scene::{ModalSolidSpec, PlaybackSpec, Scene};
use crate::snapshot::{SnapshotError, check_finite};
use crate::stats::{Stage, StageTimer};
use crate::world::outcome::{StepError, StepInfo};
use crate::world::saved::{StateError, SystemState};
use crate::world::watch::{EnergyWatch, MAX_ENERGY_GAIN};
use std::f64::consts::TAU;

/// A modal solid of the scene.
#[derive(Debug, Clone)]
pub(crate) struct ModalEntry {
    /// Index of its system in the scene.
    pub index: usize,
    /// The solid.
    pub solid: ModalSolid,
    /// Its state at the start of the current step.
    pub backup: ModalState,
    /// A mode shape played back instead of the dynamics.
    pub playback: Option<PlaybackSpec>,
    /// The scene's own grabs, which every later set keeps.
    pub scene_grabs: Vec<Grab>,
    /// The energy the solid started from, which it may not exceed while
    /// nothing holds it (grabs and playback supply energy).
    pub watch: EnergyWatch,
}

impl ModalEntry {
    /// Holds the scene's grabs and `extra`.
    ///
    /// # Errors
    /// [`GrabError`]; the previous grabs then stay.
    pub(crate) fn set_grabs(&mut self, extra: &[Grab]) -> Result<(), GrabError> {
        let all: Vec<Grab> = self.scene_grabs.iter().chain(extra).copied().collect();
        self.solid.set_grabs(&all)?;
        // Released or newly held: the energy starts again from here.
        self.watch.restart();
        Ok(())
    }

    /// The grabs besides the scene's.
    pub(crate) fn extra_grabs(&self) -> &[Grab] {
        &self.solid.grabs()[self.scene_grabs.len().min(self.solid.grabs().len())..]
    }

    /// The playback's pose at time `t`: the mode at `amplitude sin(omega
    /// t)`, a rigid mode at 1 Hz.
    fn play(&mut self, playback: PlaybackSpec, t: Real) -> Result<(), StepError> {
        let mode = playback.mode as usize;
        let omega = self
            .solid
            .eigenvalues()
            .get(mode)
            .map(|lambda| lambda.sqrt())
            .filter(|w| *w > 0.0 && mode >= self.solid.zero_modes())
            .unwrap_or(TAU);
        self.solid
            .pose_mode(mode, playback.amplitude * (omega * t).sin())
            .map_err(|_| self.unstable("modal amplitude", Real::NAN, 0))
    }

    fn unstable(&self, quantity: &'static str, value: Real, step: u64) -> StepError {
        StepError::SolidUnstable {
            system: self.index,
            quantity,
            particle: 0,
            value,
            step,
        }
    }
}

impl Simulated for ModalEntry {
    fn index(&self) -> usize {
        self.index
    }

    fn kind_name(&self) -> &'static str {
        "modal solid"
    }

    fn is_solid(&self) -> bool {
        true
    }

    fn kind_article(&self) -> &'static str {
        "a modal solid"
    }

    fn scene_grab_count(&self) -> Option<usize> {
        Some(self.scene_grabs.len())
    }

    fn runtime_grabs(&self) -> Vec<Grab> {
        self.extra_grabs().to_vec()
    }

    fn set_runtime_grabs(&mut self, grabs: &[Grab]) -> Result<(), GrabRefusal> {
        self.set_grabs(grabs).map_err(|e| GrabRefusal {
            index: match e {
                GrabError::Empty { index }
                | GrabError::NotFinite { index }
                | GrabError::Outside { index, .. }
                | GrabError::Orientation { index } => Some(index),
                GrabError::TooMany { .. } | GrabError::Modal(_) => None,
            },
            reason: e.to_string(),
        })
    }

    fn particle_count(&self) -> usize {
        self.solid.len()
    }

    /// Nodes never change.
    fn start_step(&mut self, _step: u64) -> Result<u32, StepError> {
        Ok(0)
    }

    fn save(&mut self) {
        self.backup = self.solid.state();
    }

    fn restore(&mut self) {
        // The backup was taken from this solid: its lengths match.
        let _ = self.solid.set_state(&self.backup);
    }

    /// One implicit modal step (Eq. 31, or Eq. 33 with grabs) of any
    /// length: the integrator is unconditionally stable, so no sub-steps.
    fn step(&mut self, env: &StepEnv, timer: &mut StageTimer) -> Result<StepInfo, StepError> {
        env.check()?;
        let watched = self.playback.is_none() && self.solid.grabs().is_empty();
        if watched {
            let solid = &self.solid;
            self.watch.begin_with(|| {
                (
                    solid.mechanical_energy(&env.gravity),
                    solid.energy_scale(&env.gravity),
                )
            });
        }
        let mut report = StepReport {
            converged: true,
            ..StepReport::default()
        };
        if let Some(playback) = self.playback {
            timer.time(Stage::ModalSolve, || {
                self.play(playback, env.step as Real * env.dt)
            })?;
        } else {
            let solid = &mut self.solid;
            report = timer
                .time(Stage::ModalSolve, || {
                    solid.step_cancellable(env.dt, &env.gravity, env.cancel)
                })
                .map_err(|e| match e {
                    MotionError::Nonlinear(NonlinearError::Cancelled) => env.cancelled(),
                    MotionError::Nonlinear(_) => {
                        self.unstable("nonlinear displacement", Real::INFINITY, env.step)
                    }
                    MotionError::Modal(_) | MotionError::NoModes => {
                        self.unstable("modal amplitude", Real::INFINITY, env.step)
                    }
                })?;
        }
        if watched
            && let Some((gained, fraction)) = self
                .watch
                .excess(self.solid.mechanical_energy(&env.gravity))
        {
            return Err(StepError::SolidEnergyGained {
                system: self.index,
                gained,
                fraction,
                limit: MAX_ENERGY_GAIN,
                advice: self.solid.energy_advice(),
                step: env.step,
            });
        }
        match self.first_invalid() {
            Some(invalid) => Err(StepError::SolidUnstable {
                system: self.index,
                quantity: invalid.quantity,
                particle: invalid.particle,
                value: invalid.value,
                step: env.step,
            }),
            None => {
                let mut info = StepInfo::start(env.dt);
                info.substeps = 1;
                // Nonlinear dynamics: its Newton solve, reported as the
                // elastic solids' is.
                info.solid_iterations = u32::try_from(report.iterations).unwrap_or(u32::MAX);
                // Counted among the step's solver iterations, as the
                // elastic solids' are (`StepInfo::solid_iterations`).
                info.solver_iterations = info.solid_iterations;
                info.solid_residual = report.residual;
                info.unconverged = u32::from(!report.converged);
                Ok(info)
            }
        }
    }

    fn first_invalid(&self) -> Option<Invalid> {
        let (particle, u) = self
            .solid
            .displacements()
            .iter()
            .enumerate()
            .find(|(_, u)| !u.iter().all(|c| c.is_finite()))?;
        Some(Invalid {
            quantity: "displacement",
            particle,
            value: u.norm(),
        })
    }

    fn write_field(&self, kind: FieldKind, out: &mut Vec<f32>) {
        let solid = &self.solid;
        let vectors = |v: &mut dyn Iterator<Item = Vector>, out: &mut Vec<f32>| {
            out.extend(v.flat_map(|x| [x.x as f32, x.y as f32, x.z as f32]));
        };
        let density = solid.efg().material().density;
        match kind {
            FieldKind::Position => vectors(&mut solid.positions(), out),
            FieldKind::Velocity => vectors(&mut solid.velocities().into_iter(), out),
            FieldKind::Density => out.extend(std::iter::repeat_n(density as f32, solid.len())),
            // Linear elasticity has no pressure of its own.
            FieldKind::Pressure => out.extend(std::iter::repeat_n(0.0, solid.len())),
            FieldKind::Mass => out.extend(solid.masses().iter().map(|&m| m as f32)),
            FieldKind::Volume => out.extend(solid.masses().iter().map(|&m| (m / density) as f32)),
            FieldKind::KineticEnergy => out.extend(
                solid
                    .masses()
                    .iter()
                    .zip(solid.velocities())
                    .map(|(m, v)| (0.5 * m * v.norm_squared()) as f32),
            ),
            FieldKind::ElasticEnergy => {
                out.extend(solid.elastic_energies().into_iter().map(|e| e as f32));
            }
            // Exact below 2^24; frames carry ids as integers.
            FieldKind::Id => out.extend((0..solid.len()).map(|id| id as f32)),
            // A modal solid never cracks: one fragment.
            FieldKind::Fragment => out.extend(std::iter::repeat_n(0.0, solid.len())),
        }
    }

    /// Nodes never change: their ids are their indices.
    fn write_ids(&self, out: &mut Vec<u32>) {
        out.extend(0..self.solid.len() as u32);
    }

    fn mark_removed(&mut self, _ids: &[usize]) -> Result<(), RemoveError> {
        Err(RemoveError::Unsupported {
            system: self.index,
            kind: self.kind_article(),
        })
    }

    /// The deformed skin.
    fn solid_surface(&self) -> Option<SolidSurface> {
        let skin = self.solid.skin()?;
        Some(SolidSurface {
            system: self.index,
            mesh: TriMesh {
                vertices: skin.positions,
                triangles: skin.triangles.to_vec(),
            },
            normals: skin.normals,
        })
    }

    /// Its reduced state, or its full one under nonlinear dynamics (its
    /// grabs belong to whoever set them, and are set again after a
    /// restore).
    fn capture(&self) -> SystemState {
        SystemState::Modal {
            index: self.index,
            state: self.solid.state(),
        }
    }

    fn restore_state(&mut self, saved: &SystemState, _scene: &Scene) -> Result<(), StateError> {
        let SystemState::Modal { state, .. } = saved else {
            return Err(StateError::kind((self.kind_name(), self.index), saved));
        };
        let at = |source| StateError::System {
            system: self.index,
            source,
        };
        // Modes, or three per node under nonlinear dynamics.
        let modes = self.solid.state_len();
        for (what, values) in [
            ("modal amplitudes", &state.amplitudes),
            ("modal velocities", &state.velocities),
        ] {
            if values.len() != modes {
                return Err(at(SnapshotError::Length {
                    what,
                    expected: modes,
                    got: values.len(),
                }));
            }
            check_finite(what, values).map_err(at)?;
        }
        self.solid.set_state(state).map_err(|_| {
            at(SnapshotError::Length {
                what: "modal state",
                expected: modes,
                got: state.amplitudes.len(),
            })
        })?;
        // Its backward Euler step only loses energy, so the watch may
        // start again from the restored state.
        self.watch.restart();
        Ok(())
    }
}

/// The modal solid of system `index`, as its check built it.
pub(super) fn build(index: usize, spec: &ModalSolidSpec, solid: ModalSolid) -> ModalEntry {
    ModalEntry {
        index,
        backup: solid.state(),
        scene_grabs: solid.grabs().to_vec(),
        solid,
        playback: spec.playback,
        watch: EnergyWatch::default(),
    }
}
