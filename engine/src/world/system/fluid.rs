//! The fluid (with its rigid bodies) as the world keeps it: built from
//! its spec, stepped in sub-steps within its stability limit, its frame
//! fields in particle-id order, its particles removed between steps.

use super::simulated::{InsertError, Invalid, ParticleChanges, RemoveError, Simulated, StepEnv};
use crate::approx::Kernel;
use crate::expression::VectorField;
use crate::fluid::{
    BoxWalls, Dfsph, DfsphParams, FluidParams, FluidState, FluidSystem, Pressure, Tait, Wcsph,
};
use crate::frame::{BodyPose, FieldKind};
use crate::geometry::{Shape, TriMesh};
use crate::math::{Real, Vector, vector};
use crate::neighbors::{Periodic, UniformGrid};
use crate::rigid::{BodyState, Motion, Oscillation, RigidBodies, RigidBody, Slip};
use crate::scene::{
    FluidSpec, MotionKind, RigidBodySpec, Scene, SlipKind, SolverKind, WallModel, body_pose,
    shape_axes,
};
use crate::snapshot::{SnapshotError, check_finite};
use crate::stats::StageTimer;
use crate::surface::SurfaceExtractor;
use crate::world::outcome::{StepError, StepInfo};
use crate::world::saved::{StateError, SystemState, check_layout};
use crate::world::watch::EnergyWatch;

/// The fluid of a scene as the world keeps it.
#[derive(Debug, Clone)]
pub(crate) struct FluidEntry {
    /// Index of its system in the scene.
    pub index: usize,
    /// The fluid and its pressure solver.
    pub fluid: FluidSystem,
    /// Fluid state at the start of the current step, restored when the
    /// step fails.
    pub backup: FluidState,
    /// The box its particles stay in (see `Scene::simulation_box`).
    pub bounds: (Vector, Vector),
    /// Meshes the fluid's surface into each frame, when the scene asks.
    pub surface: Option<SurfaceExtractor>,
    /// Particles to remove and to add at the start of the next step.
    pub changes: ParticleChanges,
    /// The most particles it may hold: as many as it was built with, the
    /// memory its scene was admitted with.
    pub capacity: usize,
    /// The energy the fluid started from, which it may not exceed.
    pub watch: EnergyWatch,
}

impl Simulated for FluidEntry {
    fn index(&self) -> usize {
        self.index
    }

    fn kind_name(&self) -> &'static str {
        "fluid"
    }

    fn is_solid(&self) -> bool {
        false
    }

    fn particle_count(&self) -> usize {
        self.fluid.fluid().len()
    }

    fn start_step(&mut self, _step: u64) -> Result<u32, StepError> {
        let mut added = 0;
        if !self.changes.is_empty() {
            let (removed, positions, velocities) = self.changes.take().into_parts();
            if !removed.is_empty() {
                self.fluid.remove(&removed);
            }
            if !positions.is_empty() {
                // The ids were checked when the particles were queued.
                let _ = self.fluid.insert(&positions, &velocities);
                added = positions.len() as u32;
            }
            self.watch.restart();
        }
        self.fluid.reorder_if_due();
        Ok(added)
    }

    fn save(&mut self) {
        self.fluid.save(&mut self.backup);
    }

    fn restore(&mut self) {
        self.fluid.restore(&self.backup);
    }

    /// Sub-steps of at most the fluid's stable step (up to
    /// `env.max_substeps` of them), checked after each; the flag is read
    /// before each.
    fn step(&mut self, env: &StepEnv, timer: &mut StageTimer) -> Result<StepInfo, StepError> {
        let dt = env.dt;
        let mut info = StepInfo::start(dt);
        self.watch.begin(&self.fluid, &env.gravity, &self.bounds);
        let (min, max) = self.bounds;
        let mut elapsed = 0.0;
        while dt - elapsed > dt * 1e-9 {
            env.check()?;
            let remaining = dt - elapsed;
            let limit = self.fluid.stable_dt(env.cfl, &env.gravity);
            let budget = env.max_substeps - info.substeps;
            let wanted = (remaining / limit).ceil().max(1.0);
            if wanted > budget as Real {
                info.capped = true;
            }
            let sub = remaining / wanted.min(budget as Real);
            self.fluid
                .substep(sub, &env.gravity, &min, &max, timer, env.cancel)
                .map_err(|_| env.cancelled())?;
            let solve = self.fluid.fluid().last_solve();
            info.solver_iterations += solve.density_iterations + solve.divergence_iterations;
            info.density_error = info.density_error.max(solve.density_error);
            info.unconverged += solve.unconverged;
            info.substeps += 1;
            info.min_substep = info.min_substep.min(sub);
            elapsed += sub;
            if let Some(invalid) = self.first_invalid() {
                return Err(StepError::Unstable {
                    quantity: invalid.quantity,
                    particle: invalid.particle,
                    value: invalid.value,
                    step: env.step,
                    substep: info.substeps,
                });
            }
        }
        self.watch.check(&self.fluid, &env.gravity, env.step)?;
        Ok(info)
    }

    fn first_invalid(&self) -> Option<Invalid> {
        let invalid = self.fluid.first_invalid()?;
        Some(Invalid {
            quantity: invalid.quantity,
            particle: invalid.particle,
            value: invalid.value,
        })
    }

    fn write_field(&self, kind: FieldKind, out: &mut Vec<f32>) {
        // Frames list particles in id order, whatever order the fluid
        // keeps.
        let fluid = self.fluid.fluid();
        let vectors = |v: &[Vector], out: &mut Vec<f32>| {
            fluid.in_id_order(out, |k| v[k].map(|c| c as f32).into())
        };
        let scalars = |s: &[Real], out: &mut Vec<f32>| fluid.in_id_order(out, |k| [s[k] as f32]);
        match kind {
            FieldKind::Position => vectors(&fluid.positions, out),
            FieldKind::Velocity => vectors(&fluid.velocities, out),
            FieldKind::Density => scalars(&fluid.densities, out),
            FieldKind::Pressure => scalars(&fluid.pressures, out),
            FieldKind::Mass => fluid.in_id_order(out, |_| [fluid.params.mass as f32]),
            FieldKind::Volume => {
                fluid.in_id_order(out, |k| [(fluid.params.mass / fluid.densities[k]) as f32])
            }
            FieldKind::KineticEnergy => fluid.in_id_order(out, |k| {
                [(0.5 * fluid.params.mass * fluid.velocities[k].norm_squared()) as f32]
            }),
            FieldKind::Id => fluid.in_id_order(out, |k| [fluid.ids()[k] as f32]),
            // A fluid has no fragments.
            FieldKind::Fragment => fluid.in_id_order(out, |_| [f32::NAN]),
            FieldKind::ElasticEnergy => {
                let stored = self.fluid.pressure().has_equation_of_state();
                fluid.in_id_order(out, |k| {
                    let e = if stored {
                        fluid.params.mass * fluid.params.eos.energy(fluid.densities[k])
                    } else {
                        0.0
                    };
                    [e as f32]
                })
            }
        }
    }

    fn write_ids(&self, out: &mut Vec<u32>) {
        let fluid = self.fluid.fluid();
        fluid.in_id_order(out, |k| [fluid.ids()[k]]);
    }

    /// Ids are checked against the live particles: an id already gone
    /// (or marked and gone at the next step) names no particle.
    fn mark_removed(&mut self, ids: &[usize]) -> Result<(), RemoveError> {
        let fluid = self.fluid.fluid();
        let count = fluid.next_id() as usize;
        let mut live = vec![false; count];
        for &id in fluid.ids() {
            live[id as usize] = true;
        }
        if let Some(&particle) = ids
            .iter()
            .find(|&&id| !live.get(id).copied().unwrap_or(false))
        {
            return Err(RemoveError::NoParticle {
                system: self.index,
                particle,
                count,
            });
        }
        self.changes.mark(self.index, count, ids)
    }

    fn pending_changes(&mut self) -> Option<&mut ParticleChanges> {
        Some(&mut self.changes)
    }

    /// New particles must lie in the domain, not crowd (as the scene's
    /// own particles), move at finite velocities, and fit the fluid's
    /// capacity after the changes already queued.
    fn mark_inserted(
        &mut self,
        scene: &Scene,
        positions: &[Vector],
        velocities: &[Vector],
    ) -> Result<std::ops::Range<u32>, InsertError> {
        let system = self.index;
        if positions.len() != velocities.len() {
            return Err(InsertError::Lengths {
                positions: positions.len(),
                velocities: velocities.len(),
            });
        }
        let (queued, _) = self.changes.inserted();
        let count = (self.particle_count() + queued.len() + positions.len())
            .saturating_sub(self.changes.removed_count());
        if count > self.capacity {
            return Err(InsertError::Capacity {
                system,
                count,
                capacity: self.capacity,
            });
        }
        let next_id = self.fluid.fluid().next_id();
        let first = u32::try_from(queued.len())
            .ok()
            .and_then(|q| next_id.checked_add(q));
        let end = first.and_then(|f| f.checked_add(u32::try_from(positions.len()).ok()?));
        let (Some(first), Some(end)) = (first, end) else {
            return Err(InsertError::IdsExhausted { system, next_id });
        };
        let invalid = |reason: String| InsertError::Invalid { system, reason };
        if let Some(i) = velocities
            .iter()
            .position(|v| !v.iter().all(|c| c.is_finite()))
        {
            return Err(invalid(format!(
                "velocities[{i}] is not finite; give each new particle a finite velocity"
            )));
        }
        let spec = scene.fluid().ok_or(InsertError::NoSystem { system })?;
        let planar = scene.dimension == 2;
        let flat = |x: &Vector| [x.x, x.y, if planar { 0.0 } else { x.z }];
        scene
            .check_fluid_positions(spec, queued.iter().chain(positions).map(flat), &|i| match i
                .checked_sub(queued.len())
            {
                Some(i) => format!("positions[{i}]"),
                None => format!("an earlier queued particle ({i})"),
            })
            .map_err(|e| invalid(e.to_string()))?;
        let planar_vectors = |v: &[Vector]| -> Vec<Vector> {
            v.iter()
                .map(|x| {
                    if planar {
                        Vector::new(x.x, x.y, 0.0)
                    } else {
                        *x
                    }
                })
                .collect()
        };
        self.changes
            .insert(&planar_vectors(positions), &planar_vectors(velocities));
        Ok(first..end)
    }

    fn kind_article(&self) -> &'static str {
        "a fluid"
    }

    /// The colour field with each particle's volume `m / rho_i` from the
    /// last density pass, when the scene asks for a surface.
    fn fluid_surface(&self) -> Option<TriMesh> {
        let (surface, fluid) = (self.surface.as_ref()?, self.fluid.fluid());
        let volumes: Vec<Real> = fluid
            .densities
            .iter()
            .map(|&rho| fluid.params.mass / rho)
            .collect();
        Some(surface.extract(&fluid.positions, &volumes))
    }

    fn write_body_poses(&self, out: &mut Vec<BodyPose>) {
        let Some(rigid) = self.fluid.fluid().bodies() else {
            return;
        };
        out.extend(rigid.bodies().iter().map(|b| {
            // The frame the scene gave the shape in, about the centre.
            let q = (b.state.orientation * shape_axes(&b.shape).inverse()).into_inner();
            BodyPose {
                system: b.system,
                position: b.state.position.into(),
                orientation: [q.i, q.j, q.k, q.w],
                velocity: b.state.velocity.into(),
                angular_velocity: b.state.angular_velocity.into(),
            }
        }));
    }

    fn capture(&self) -> SystemState {
        SystemState::Fluid {
            index: self.index,
            fluid: self.fluid.snapshot(),
            removals: self.changes.marked_ids(),
            insertions: {
                let (x, v) = self.changes.inserted();
                x.iter().copied().zip(v.iter().copied()).collect()
            },
            energy_start: self.watch.start(),
        }
    }

    fn restore_state(&mut self, state: &SystemState, scene: &Scene) -> Result<(), StateError> {
        let SystemState::Fluid {
            fluid,
            removals,
            insertions,
            energy_start,
            ..
        } = state
        else {
            return Err(StateError::kind((self.kind_name(), self.index), state));
        };
        let system = self.index;
        let at = |source| StateError::System { system, source };
        check_layout(scene, self.index, fluid)?;
        self.fluid.restore_snapshot(fluid).map_err(at)?;
        let ids: Vec<usize> = removals.iter().map(|&id| id as usize).collect();
        let count = fluid.next_id as usize;
        self.changes = ParticleChanges::default();
        self.mark_removed(&ids).map_err(|_| {
            at(SnapshotError::Length {
                what: "removals (ids of no particle)",
                expected: count,
                got: ids.iter().copied().max().map_or(0, |m| m + 1),
            })
        })?;
        let (positions, velocities): (Vec<Vector>, Vec<Vector>) =
            insertions.iter().copied().unzip();
        self.mark_inserted(scene, &positions, &velocities)
            .map_err(|e| StateError::Insertions {
                system,
                reason: e.to_string(),
            })?;
        if let Some((e0, scale)) = *energy_start {
            check_finite("energy start", &[e0, scale]).map_err(at)?;
        }
        self.watch.set_start(*energy_start);
        Ok(())
    }
}

/// The rigid body of system `system`, coupled to `fluid`.
fn build_body(
    system: usize,
    spec: &RigidBodySpec,
    shape: Shape,
    fluid: &FluidSpec,
    dim: usize,
) -> RigidBody {
    let motion = match spec.motion {
        MotionKind::Static => Motion::Static,
        MotionKind::Kinematic => Motion::Kinematic {
            velocity: vector(spec.velocity),
            angular_velocity: vector(spec.angular_velocity),
            oscillation: spec.oscillation.map(|o| Oscillation {
                amplitude: vector(o.amplitude),
                frequency: o.frequency,
            }),
        },
        MotionKind::Dynamic => {
            // Validated: dynamic bodies are bounded and have a density.
            let density = spec.density.unwrap_or(fluid.rest_density);
            Motion::Dynamic {
                mass: density * shape.volume(dim).unwrap_or(0.0),
                inertia: shape.inertia(density, dim).unwrap_or_else(Vector::zeros),
            }
        }
    };
    let slip = match spec.slip {
        SlipKind::Free => Slip::Free,
        SlipKind::No => Slip::No {
            viscosity: spec.viscosity.unwrap_or(fluid.viscosity),
        },
    };
    let (position, orientation) = body_pose(spec, &shape, dim);
    let velocity = if spec.motion == MotionKind::Dynamic {
        vector(spec.velocity)
    } else {
        Vector::zeros()
    };
    let state = BodyState {
        position,
        orientation,
        velocity,
        angular_velocity: if spec.motion == MotionKind::Dynamic {
            vector(spec.angular_velocity)
        } else {
            Vector::zeros()
        },
        time: 0.0,
    };
    RigidBody::new(shape, motion, slip, spec.hollow, system, dim, state)
}

/// The fluid of a validated scene (system `index`) with its rigid bodies.
pub(super) fn build(
    scene: &Scene,
    index: usize,
    spec: &FluidSpec,
    body_specs: Vec<(usize, &RigidBodySpec, Shape)>,
) -> FluidEntry {
    let h = spec.support_radius();
    let dim = scene.dimension;
    let density_kernel = Kernel::new(spec.density_kernel, dim, h);
    let gradient_kernel = Kernel::new(spec.gradient_kernel, dim, h);
    let params = FluidParams {
        support_radius: h,
        density_kernel,
        gradient_kernel,
        eos: Tait {
            stiffness: spec.stiffness,
            gamma: spec.gamma,
            rest_density: spec.rest_density,
            negative_scale: spec.negative_pressure_scale,
        },
        xsph: spec.xsph,
        viscosity: spec.viscosity,
        viscosity_model: spec.viscosity_model,
        mass: FluidParams::lattice_mass(spec.spacing, &density_kernel, spec.rest_density),
        spacing: spec.spacing,
    };
    let pressure = match spec.solver {
        SolverKind::Wcsph => Pressure::Wcsph(Wcsph),
        SolverKind::Dfsph => Pressure::Dfsph(Box::new(Dfsph::new(DfsphParams {
            density_tolerance: spec.density_tolerance,
            divergence_tolerance: spec.divergence_tolerance,
            max_iterations: spec.max_solver_iterations,
        }))),
    };
    let (min, max) = scene.simulation_box(h);
    let periodic_axes = scene.periodic_axes();
    let walls = match spec.walls {
        WallModel::Solid => Some(
            BoxWalls::new(
                min,
                max,
                spec.spacing,
                params.mass,
                &density_kernel,
                &gradient_kernel,
            )
            .without_axes(periodic_axes),
        )
        .map(|walls| match spec.wall_slip {
            SlipKind::Free => walls,
            SlipKind::No => {
                let velocity = spec
                    .wall_velocity
                    .by_wall()
                    .map(|sides| sides.map(|(_, v)| v.map_or(Vector::zeros(), vector)));
                walls.with_friction(
                    spec.spacing,
                    params.mass,
                    &gradient_kernel,
                    spec.viscosity_model,
                    velocity,
                )
            }
        }),
        WallModel::Reflect => None,
    };
    let parse = |texts: &Option<[String; 3]>| {
        texts
            .as_ref()
            .map(|t| VectorField::parse(t).expect("validated by Scene::check"))
    };
    let velocity_field = parse(&spec.velocity_field);
    let bodies: Vec<RigidBody> = body_specs
        .into_iter()
        .map(|(s, body, shape)| build_body(s, body, shape, spec, dim))
        .collect();
    // Bodies carve the fluid blocks: no particle starts within half a
    // spacing of a body's surface or inside it.
    let clear = 0.5 * spec.spacing;
    let (positions, velocities): (Vec<Vector>, Vec<Vector>) = spec
        .lattice(dim)
        .map(|(x, block)| {
            let x = vector(x);
            let v = velocity_field
                .as_ref()
                .map_or(vector(spec.blocks[block].velocity), |field| field.eval(&x));
            (x, v)
        })
        .chain(spec.particles.iter().map(|p| {
            let (mut x, mut v) = (vector(p.position), vector(p.velocity));
            if dim == 2 {
                (x.z, v.z) = (0.0, 0.0);
            }
            (x, v)
        }))
        .filter(|(x, _)| bodies.iter().all(|b| b.excluded_distance(x) >= clear))
        .unzip();
    let grid = UniformGrid::with_periodic(min, max, h, periodic_axes)
        .expect("validated by Scene::validate");
    let periodic = Periodic::new(min, max, periodic_axes);
    let mut fluid = FluidSystem::new(
        params,
        pressure,
        positions,
        velocities,
        walls,
        grid.clone(),
        periodic,
    );
    let fluid_len = fluid.fluid().len();
    if let Some(force) = parse(&spec.body_force) {
        fluid.set_body_force(force);
    }
    if !bodies.is_empty() {
        fluid.attach_bodies(RigidBodies::new(
            bodies,
            &params.boundary(),
            &min,
            &max,
            grid,
        ));
    }
    let surface = scene.output.surface.as_ref().map(|wanted| {
        SurfaceExtractor::new(
            params.density_kernel,
            wanted.cell(spec.spacing),
            wanted.iso,
            min,
            max,
        )
        .expect("validated by Scene::validate")
    });
    FluidEntry {
        index,
        fluid,
        backup: FluidState::default(),
        bounds: (min, max),
        surface,
        changes: ParticleChanges::default(),
        capacity: fluid_len,
        watch: EnergyWatch::default(),
    }
}
