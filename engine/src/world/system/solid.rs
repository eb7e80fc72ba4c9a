//! An elastic MLS solid as the world keeps it: built from the particles
//! and surface its check sampled, colliding with the domain's walls and
//! the scene's static bodies, stepped by its own integrator.

use super::simulated::{Invalid, RemoveError, Simulated, StepEnv};
use crate::frame::{FieldKind, SolidSurface};
use crate::geometry::MeshSdf;
use crate::math::{Vector, vector};
use crate::scene::{SampledSolid, Scene, SolidSpec};
use crate::snapshot::check_finite;
use crate::solid::embedded::{DeformedSurface, EmbeddedSurface, EmbeddingMethod};
use crate::solid::{ElasticSolid, Obstacle, Obstacles, SolidState};
use crate::stats::StageTimer;
use crate::world::outcome::{StepError, StepInfo};
use crate::world::saved::{StateError, SystemState};
use crate::world::watch::EnergyWatch;
use std::sync::Arc;

/// An elastic solid of the scene as the world keeps it.
#[derive(Debug, Clone)]
pub(crate) struct SolidEntry {
    /// Index of its system in the scene.
    pub index: usize,
    /// The solid.
    pub solid: ElasticSolid,
    /// Its state at the start of the current step.
    pub backup: SolidState,
    /// Its embedded surface, when the scene asks for one.
    pub surface: Option<EmbeddedSurface>,
    /// The reference surface as a distance field, for a fracturing solid
    /// with a surface: each fragment's closed surface is cut from it.
    pub outline: Option<Arc<MeshSdf>>,
    /// The energy the solid started from, which it may not exceed.
    pub watch: EnergyWatch,
}

impl Simulated for SolidEntry {
    fn index(&self) -> usize {
        self.index
    }

    fn kind_name(&self) -> &'static str {
        "solid"
    }

    fn is_solid(&self) -> bool {
        true
    }

    fn kind_article(&self) -> &'static str {
        "an elastic solid"
    }

    fn particle_count(&self) -> usize {
        self.solid.len()
    }

    /// A resampling solid splits the particles its cracks left short of
    /// neighbours; new particles are appended, so every slot keeps its
    /// particle.
    fn start_step(&mut self, step: u64) -> Result<u32, StepError> {
        let done = self
            .solid
            .resample()
            .map_err(|reason| StepError::ParticleLimit {
                system: self.index,
                reason,
                step,
            })?;
        if done.added > 0 {
            // The new shape functions change the energy's form.
            self.watch.restart();
        }
        Ok(done.added)
    }

    fn save(&mut self) {
        self.solid.save(&mut self.backup);
    }

    fn restore(&mut self) {
        self.solid.restore(&self.backup);
    }

    /// The solid sub-steps itself, reading the flag at each sub-step or
    /// Newton and CG iteration; its state is checked after the step.
    fn step(&mut self, env: &StepEnv, timer: &mut StageTimer) -> Result<StepInfo, StepError> {
        let solid = &self.solid;
        self.watch.begin_with(|| {
            (
                solid.mechanical_energy(&env.gravity, env.dt),
                solid.energy_scale(&env.gravity),
            )
        });
        let step = self
            .solid
            .step_cancellable(env.dt, &env.gravity, env.max_substeps, env.cancel, timer)
            .map_err(|_| env.cancelled())?;
        let info = StepInfo {
            substeps: step.substeps,
            min_substep: step.min_substep,
            capped: step.capped,
            solver_iterations: step.iterations,
            density_error: 0.0,
            solid_iterations: step.iterations,
            solid_residual: step.residual,
            unconverged: u32::from(step.unconverged),
            added: 0,
        };
        if let Some(invalid) = self.first_invalid() {
            return Err(StepError::SolidUnstable {
                system: self.index,
                quantity: invalid.quantity,
                particle: invalid.particle,
                value: invalid.value,
                step: env.step,
            });
        }
        if let Some((particle, ratio)) = self.solid.collapsed() {
            return Err(StepError::Collapsed {
                system: self.index,
                particle,
                ratio,
                limit: ElasticSolid::MIN_VOLUME_RATIO,
                advice: self.solid.collapse_advice(),
                step: env.step,
            });
        }
        // Cracks change the energy's form at fixed positions, which the
        // watch must not read as a gain.
        let cracked = self
            .solid
            .fracture_step()
            .map_err(|reason| StepError::CracksOutgrown {
                system: self.index,
                reason,
                step: env.step,
            })?;
        if let Some(particles) = self.solid.free_in_statics() {
            return Err(StepError::FragmentFreeInStatics {
                system: self.index,
                particles,
                step: env.step,
            });
        }
        self.watch.shift(cracked.energy_change);
        self.watch.check_solid(
            &self.solid,
            self.index,
            &env.gravity,
            env.dt,
            step.unconverged,
            env.step,
        )?;
        Ok(info)
    }

    fn first_invalid(&self) -> Option<Invalid> {
        let (particle, quantity, value) = self.solid.first_invalid()?;
        Some(Invalid {
            quantity,
            particle,
            value,
        })
    }

    fn write_field(&self, kind: FieldKind, out: &mut Vec<f32>) {
        let solid = &self.solid;
        let vectors = |v: &[Vector], out: &mut Vec<f32>| {
            out.extend(v.iter().flat_map(|x| [x.x as f32, x.y as f32, x.z as f32]));
        };
        match kind {
            FieldKind::Position => vectors(&solid.positions, out),
            FieldKind::Velocity => vectors(&solid.velocities, out),
            FieldKind::Density => out.extend(solid.densities().into_iter().map(|d| d as f32)),
            FieldKind::Pressure => out.extend(solid.pressures().into_iter().map(|p| p as f32)),
            FieldKind::Mass => out.extend(solid.masses().iter().map(|&m| m as f32)),
            FieldKind::Volume => out.extend(
                solid
                    .masses()
                    .iter()
                    .zip(solid.densities())
                    .map(|(m, rho)| (m / rho) as f32),
            ),
            FieldKind::KineticEnergy => out.extend(
                solid
                    .masses()
                    .iter()
                    .zip(&solid.velocities)
                    .map(|(m, v)| (0.5 * m * v.norm_squared()) as f32),
            ),
            FieldKind::ElasticEnergy => {
                out.extend(solid.elastic_energies().into_iter().map(|e| e as f32));
            }
            // Exact below 2^24; frames carry ids as integers.
            FieldKind::Id => out.extend((0..solid.len()).map(|id| id as f32)),
            FieldKind::Fragment => match solid.fracture() {
                Some(f) => out.extend(f.fragments().iter().map(|&k| k as f32)),
                None => out.extend(std::iter::repeat_n(0.0, solid.len())),
            },
        }
    }

    /// New particles are appended and none removed: ids are indices.
    fn write_ids(&self, out: &mut Vec<u32>) {
        out.extend(0..self.solid.len() as u32);
    }

    fn mark_removed(&mut self, _ids: &[usize]) -> Result<(), RemoveError> {
        Err(RemoveError::Unsupported {
            system: self.index,
            kind: self.kind_article(),
        })
    }

    /// The embedded surface, moved with the particles (by their
    /// displacement gradients when it asks for them).
    fn solid_surface(&self) -> Option<SolidSurface> {
        let surface = self.surface.as_ref()?;
        if let Some((mesh, normals)) = self
            .outline
            .as_deref()
            .and_then(|outline| self.solid.fragment_surface(outline))
        {
            return Some(SolidSurface {
                system: self.index,
                mesh,
                normals,
            });
        }
        let mut gradients = Vec::new();
        if surface.method() == EmbeddingMethod::Gradients {
            self.solid.displacement_gradients(&mut gradients);
        }
        let mut deformed = DeformedSurface::new();
        // The surface was built from this solid's particles; those a
        // resampling split added since follow them (their ids after the
        // solid's), and the surface keeps following the particles it
        // was built on (without the cut, a whole solid that split some
        // particles framed no surface).
        let built = surface.particle_count();
        surface
            .update(
                self.solid.positions.get(..built)?,
                gradients.get(..built.min(gradients.len()))?,
                &mut deformed,
            )
            .ok()?;
        Some(SolidSurface {
            system: self.index,
            mesh: deformed.to_mesh(surface.triangles()),
            normals: deformed.normals,
        })
    }

    fn crack_surface(&self) -> Option<SolidSurface> {
        let (mesh, normals) = self.solid.crack_surface()?;
        Some(SolidSurface {
            system: self.index,
            mesh,
            normals,
        })
    }

    fn capture(&self) -> SystemState {
        SystemState::Solid {
            index: self.index,
            solid: self.solid.snapshot(),
            energy_start: self.watch.start(),
        }
    }

    fn restore_state(&mut self, state: &SystemState, _scene: &Scene) -> Result<(), StateError> {
        let SystemState::Solid {
            solid,
            energy_start,
            ..
        } = state
        else {
            return Err(StateError::kind((self.kind_name(), self.index), state));
        };
        let at = |source| StateError::System {
            system: self.index,
            source,
        };
        self.solid.restore_snapshot(solid).map_err(at)?;
        if let Some((e0, scale)) = *energy_start {
            check_finite("energy start", &[e0, scale]).map_err(at)?;
        }
        self.watch.set_start(*energy_start);
        Ok(())
    }
}

/// The solid of system `index` of a validated scene, from the particles
/// and surface its check sampled, colliding with the domain's walls and
/// `obstacles` (the scene's static bodies).
pub(super) fn build(
    scene: &Scene,
    index: usize,
    spec: &SolidSpec,
    sampled: SampledSolid,
    obstacles: &[Obstacle],
) -> SolidEntry {
    let dim = scene.dimension;
    let (rest, velocities): (Vec<Vector>, Vec<Vector>) = sampled.particles.into_iter().unzip();
    let fixed = rest.iter().map(|x| spec.anchored(x, dim)).collect();
    let obstacles = Obstacles {
        shapes: obstacles.to_vec(),
        walls: Some((vector(scene.domain.min), vector(scene.domain.max))),
    };
    let mut solid = ElasticSolid::new(spec.params(dim), rest, velocities, fixed, obstacles)
        .expect("validated by Scene::check");
    if let Some(fracture) = &spec.fracture {
        let notches: Vec<_> = fracture.notches.iter().map(|n| n.notch()).collect();
        solid
            .notch(&notches)
            .expect("notches validated by Scene::check");
    }
    SolidEntry {
        index,
        solid,
        backup: SolidState::default(),
        surface: sampled.surface,
        outline: sampled.outline,
        watch: EnergyWatch::default(),
    }
}
