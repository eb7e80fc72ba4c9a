//! A thin shell as the world keeps it: the adapter between
//! [`ShellDynamics`] (built by its scene check) and the world's
//! [`Simulated`] trait. Frames list the shell's nodes as particles (their
//! positions are the nodal coefficients `X_I + u_I`) and carry the
//! surface the shell was given, deformed, as a solid surface. Runtime
//! grabs hold material points of the surface at positions, each a spring
//! pulling the shell's point there, an orientation (its tangents, and so
//! its director, held rotated), or both.

use super::simulated::{GrabRefusal, Invalid, RemoveError, Simulated, StepEnv};
use crate::efg::Grab;
use crate::frame::{FieldKind, SolidSurface};
use crate::geometry::TriMesh;
use crate::geometry::atlas::Atlas;
use crate::math::{Real, Vector, bounds};
use crate::scene::{PreparedShell, Scene};
use crate::shell::{self, Embedded, ShellDynamics, ShellError, ShellState, ShellStep};
use crate::snapshot::{SnapshotError, check_vectors};
use crate::stats::{Stage, StageTimer};
use crate::world::outcome::{StepError, StepInfo};
use crate::world::saved::{StateError, SystemState};
use crate::world::watch::{EnergyWatch, MAX_ENERGY_GAIN};

/// A shell of the scene.
#[derive(Debug, Clone)]
pub(crate) struct ShellEntry {
    /// Index of its system in the scene.
    pub index: usize,
    /// The shell.
    pub dynamics: ShellDynamics,
    /// Its state at the start of the current step.
    backup: ShellState,
    /// The surface it carries in frames.
    surface: Embedded,
    triangles: Vec<[u32; 3]>,
    /// Each node's lumped mass, for the per-particle fields.
    masses: Vec<Real>,
    /// The part of the energy watch's scale that never changes: `|f_ext|
    /// L + M E / (1000 rho)` (`L` the diagonal of the shell's box; the
    /// last term the energy of straining it by about 4.5 %, so that a
    /// shell at rest without load does not fault on round-off).
    scale_floor: Real,
    /// The surface's atlas, where a grab's point is found.
    atlas: Atlas,
    /// How far from the surface a grab's point may lie, m.
    grab_reach: Real,
    /// A grab's spring, N/m.
    grab_stiffness: Real,
    /// The grabs in force as they were given, and as the shell holds
    /// them.
    grabs: Vec<(Grab, shell::Grab)>,
    /// Backward Euler and damping only lose energy, and Newmark keeps a
    /// linear shell's; a nonlinear Newmark step that gains energy from
    /// nowhere faults instead of running on. Not watched while grabbed
    /// (a grab supplies energy).
    watch: EnergyWatch,
}

/// What to change when a shell gains energy.
const ENERGY_ADVICE: &str =
    "lower time.dt, or set integrator = \"backward_euler\", which damps what Newmark keeps";

impl ShellEntry {
    /// The shell's grab of `grab`, the `index`-th: its material point
    /// found on the surface's atlas.
    fn held(&self, index: usize, grab: &Grab) -> Result<shell::Grab, GrabRefusal> {
        let refuse = |reason: String| GrabRefusal {
            index: Some(index),
            reason: format!("grab {index}: {reason}"),
        };
        if grab.position.is_none() && grab.rotation.is_none() {
            return Err(refuse(
                "sets neither a position nor an orientation; set one".into(),
            ));
        }
        let (target, rotation) = (
            grab.position.unwrap_or_default(),
            grab.rotation.unwrap_or_default(),
        );
        if !(grab.point.iter().chain(&target).chain(&rotation)).all(|c| c.is_finite()) {
            return Err(refuse("a coordinate is not finite".into()));
        }
        let (at, distance) = self
            .atlas
            .parameter_of(&grab.point)
            .ok_or_else(|| refuse("the shell's surface has no triangle to hold".into()))?;
        if distance > self.grab_reach {
            return Err(refuse(format!(
                "the point is {distance:.3e} m from the shell's rest surface, more than its \
                 resolution ({:.3e} m); pick a point of the surface",
                self.grab_reach
            )));
        }
        self.dynamics
            .model()
            .stencil(at)
            .map_err(|e| refuse(e.to_string()))?;
        Ok(shell::Grab {
            at,
            target: grab.position,
            rotation: grab.rotation,
            stiffness: self.grab_stiffness,
        })
    }

    /// Advances by `env.dt`: one implicit step, or where its Newton solve
    /// does not converge or its tangent will not factor (a shell yanked
    /// by a grab, snapping through), the step again in 2, 4, ... pieces,
    /// whose larger inertia holds Newton, up to `env.max_substeps`.
    /// Returns the last piece's report (iterations summed) and the
    /// pieces.
    fn advance(&mut self, env: &StepEnv) -> Result<(ShellStep, u32), ShellError> {
        let start = self.dynamics.state();
        let mut pieces: u32 = 1;
        loop {
            self.dynamics.set_time_step(env.dt / Real::from(pieces))?;
            let mut done = ShellStep {
                iterations: 0,
                residual: 0.0,
            };
            let mut failure = None;
            for _ in 0..pieces {
                match self.dynamics.step(env.cancel) {
                    Ok(report) => {
                        done.iterations += report.iterations;
                        done.residual = done.residual.max(report.residual);
                    }
                    Err(e) => {
                        failure = Some(e);
                        break;
                    }
                }
            }
            let Some(error) = failure else {
                return Ok((done, pieces));
            };
            let retry = matches!(
                error,
                ShellError::NotConverged { .. } | ShellError::Singular
            );
            if !retry || pieces.saturating_mul(2) > env.max_substeps {
                return Err(error);
            }
            // The state the step started from, taken above.
            self.dynamics.restore(start.clone())?;
            pieces *= 2;
        }
    }

    fn failed(&self, reason: ShellError, step: u64) -> StepError {
        StepError::ShellFailed {
            system: self.index,
            reason,
            step,
        }
    }

    /// `E = KE + U - f_ext . u` and the scale its gain is measured
    /// against, `KE_0 + U_0` plus [`Self::scale_floor`].
    fn energy(&mut self) -> Result<(Real, Real), ShellError> {
        let e = self.dynamics.energy()?;
        Ok((
            e.kinetic + e.strain - e.work,
            e.kinetic + e.strain + self.scale_floor,
        ))
    }
}

impl Simulated for ShellEntry {
    fn index(&self) -> usize {
        self.index
    }

    fn kind_name(&self) -> &'static str {
        "shell"
    }

    fn is_solid(&self) -> bool {
        true
    }

    fn kind_article(&self) -> &'static str {
        "a shell"
    }

    fn particle_count(&self) -> usize {
        self.dynamics.model().node_count()
    }

    /// A shell's scene names no grabs.
    fn scene_grab_count(&self) -> Option<usize> {
        Some(0)
    }

    fn runtime_grabs(&self) -> Vec<Grab> {
        self.grabs.iter().map(|(g, _)| *g).collect()
    }

    /// Grabs at the same points as those in force only move their
    /// targets (a drag); others rebuild the assembly's pattern.
    fn set_runtime_grabs(&mut self, grabs: &[Grab]) -> Result<(), GrabRefusal> {
        let held: Vec<shell::Grab> = grabs
            .iter()
            .enumerate()
            .map(|(k, g)| self.held(k, g))
            .collect::<Result<_, _>>()?;
        let same_points = held.len() == self.grabs.len()
            && held.iter().zip(&self.grabs).all(|(a, (_, b))| {
                a.at == b.at
                    && a.target.is_some() == b.target.is_some()
                    && a.rotation.is_some() == b.rotation.is_some()
            });
        if same_points {
            for (k, g) in held.iter().enumerate() {
                // Checked finite, and `k` indexes a grab in force held the
                // same way.
                let _ = self.dynamics.move_grab(k, g.target, g.rotation);
            }
        } else {
            self.dynamics.set_grabs(&held).map_err(|e| GrabRefusal {
                index: None,
                reason: e.to_string(),
            })?;
        }
        self.grabs = grabs.iter().copied().zip(held).collect();
        // Released or newly held: the energy starts again from here.
        self.watch.restart();
        Ok(())
    }

    /// Nodes never change.
    fn start_step(&mut self, _step: u64) -> Result<u32, StepError> {
        Ok(0)
    }

    fn save(&mut self) {
        self.backup = self.dynamics.state();
    }

    fn restore(&mut self) {
        // The backup was taken from this shell: its lengths match.
        let _ = self.dynamics.restore(self.backup.clone());
    }

    /// One implicit step (Newton on the sparse tangent) of any length:
    /// both integrators are unconditionally stable for a linear shell, so
    /// no sub-steps.
    fn step(&mut self, env: &StepEnv, timer: &mut StageTimer) -> Result<StepInfo, StepError> {
        env.check()?;
        let watched = self.grabs.is_empty();
        if watched && self.watch.start().is_none() {
            let start = self.energy().map_err(|e| self.failed(e, env.step))?;
            self.watch.begin_with(|| start);
        }
        let (report, pieces) = timer
            .time(Stage::ShellSolve, || self.advance(env))
            .map_err(|e| {
                if matches!(e, ShellError::Cancelled) {
                    env.cancelled()
                } else {
                    self.failed(e, env.step)
                }
            })?;
        if let Some(invalid) = self.first_invalid() {
            return Err(StepError::SolidUnstable {
                system: self.index,
                quantity: invalid.quantity,
                particle: invalid.particle,
                value: invalid.value,
                step: env.step,
            });
        }
        let energy = if watched {
            Some(self.energy().map_err(|e| self.failed(e, env.step))?.0)
        } else {
            None
        };
        if let Some((gained, fraction)) = energy.and_then(|e| self.watch.excess(e)) {
            return Err(StepError::SolidEnergyGained {
                system: self.index,
                gained,
                fraction,
                limit: MAX_ENERGY_GAIN,
                advice: ENERGY_ADVICE,
                step: env.step,
            });
        }
        let mut info = StepInfo::start(env.dt);
        info.substeps = pieces;
        info.min_substep = env.dt / Real::from(pieces);
        info.solid_iterations = u32::try_from(report.iterations).unwrap_or(u32::MAX);
        // Of the step's solver iterations (`StepInfo::solid_iterations`).
        info.solver_iterations = info.solid_iterations;
        info.solid_residual = report.residual;
        Ok(info)
    }

    fn first_invalid(&self) -> Option<Invalid> {
        for (quantity, values) in [
            ("displacement", self.dynamics.displacement()),
            ("velocity", self.dynamics.velocity()),
        ] {
            if let Some((particle, v)) = values
                .iter()
                .enumerate()
                .find(|(_, v)| !v.iter().all(|c| c.is_finite()))
            {
                return Some(Invalid {
                    quantity,
                    particle,
                    value: v.norm(),
                });
            }
        }
        None
    }

    fn write_field(&self, kind: FieldKind, out: &mut Vec<f32>) {
        let model = self.dynamics.model();
        let n = model.node_count();
        let u = self.dynamics.displacement();
        let v = self.dynamics.velocity();
        let vectors = |it: &mut dyn Iterator<Item = Vector>, out: &mut Vec<f32>| {
            out.extend(it.flat_map(|x| [x.x as f32, x.y as f32, x.z as f32]));
        };
        let density = model.material().density;
        match kind {
            FieldKind::Position => {
                vectors(
                    &mut model.reference().iter().zip(u).map(|(x, u)| x + u),
                    out,
                );
            }
            FieldKind::Velocity => vectors(&mut v.iter().copied(), out),
            FieldKind::Density => out.extend(std::iter::repeat_n(density as f32, n)),
            // A shell's stresses are not a pressure: zero, as for the
            // modal solids.
            FieldKind::Pressure => out.extend(std::iter::repeat_n(0.0, n)),
            FieldKind::Mass => out.extend(self.masses.iter().map(|&m| m as f32)),
            FieldKind::Volume => out.extend(self.masses.iter().map(|&m| (m / density) as f32)),
            // Lumped: the consistent mass's row sums.
            FieldKind::KineticEnergy => out.extend(
                self.masses
                    .iter()
                    .zip(v)
                    .map(|(m, v)| (0.5 * m * v.norm_squared()) as f32),
            ),
            // Each node's share of the membrane and bending energy; a
            // state the last step accepted does not fold, but a fold
            // would show as zeros rather than fail the frame.
            FieldKind::ElasticEnergy => match model.nodal_energies(u) {
                Ok(e) => out.extend(e.into_iter().map(|e| e as f32)),
                Err(_) => out.extend(std::iter::repeat_n(0.0, n)),
            },
            // Exact below 2^24; frames carry ids as integers.
            FieldKind::Id => out.extend((0..n).map(|id| id as f32)),
            // A shell does not tear yet: one fragment.
            FieldKind::Fragment => out.extend(std::iter::repeat_n(0.0, n)),
        }
    }

    /// Nodes never change: their ids are their indices.
    fn write_ids(&self, out: &mut Vec<u32>) {
        out.extend(0..self.particle_count() as u32);
    }

    fn mark_removed(&mut self, _ids: &[usize]) -> Result<(), RemoveError> {
        Err(RemoveError::Unsupported {
            system: self.index,
            kind: self.kind_article(),
        })
    }

    /// The carried surface, deformed, with the middle surface's normals.
    fn solid_surface(&self) -> Option<SolidSurface> {
        let (vertices, normals) = self.surface.surface(
            self.dynamics.model().reference(),
            self.dynamics.displacement(),
        );
        Some(SolidSurface {
            system: self.index,
            mesh: TriMesh {
                vertices,
                triangles: self.triangles.clone(),
            },
            normals,
        })
    }

    fn capture(&self) -> SystemState {
        SystemState::Shell {
            index: self.index,
            state: self.dynamics.state(),
        }
    }

    fn restore_state(&mut self, saved: &SystemState, _scene: &Scene) -> Result<(), StateError> {
        let SystemState::Shell { state, .. } = saved else {
            return Err(StateError::kind((self.kind_name(), self.index), saved));
        };
        let at = |source| StateError::System {
            system: self.index,
            source,
        };
        let n = self.particle_count();
        for (what, values) in [
            ("shell displacements", &state.displacement),
            ("shell velocities", &state.velocity),
            ("shell accelerations", &state.acceleration),
        ] {
            check_vectors(what, values, n).map_err(at)?;
        }
        if !state.time.is_finite() {
            return Err(at(SnapshotError::Invalid {
                what: "shell time",
                index: 0,
                value: state.time,
            }));
        }
        // Checked above: the restore takes it.
        self.dynamics.restore(state.clone()).map_err(|_| {
            at(SnapshotError::Length {
                what: "shell state",
                expected: n,
                got: state.displacement.len(),
            })
        })?;
        self.watch.restart();
        Ok(())
    }
}

/// The shell of system `index`, as its check built it.
pub(super) fn build(index: usize, shell: PreparedShell) -> ShellEntry {
    let PreparedShell {
        dynamics,
        surface,
        triangles,
        atlas,
        grab_reach,
        grab_stiffness,
    } = shell;
    let model = dynamics.model();
    let masses = model.lumped_masses();
    let (lo, hi) = bounds(model.reference());
    let material = model.material();
    let scale_floor = dynamics.load_magnitude() * (hi - lo).norm()
        + 1e-3 * masses.iter().sum::<Real>() * material.young / material.density;
    ShellEntry {
        index,
        backup: dynamics.state(),
        masses,
        scale_floor,
        dynamics,
        surface,
        triangles,
        atlas,
        grab_reach,
        grab_stiffness,
        grabs: Vec::new(),
        watch: EnergyWatch::default(),
    }
}
