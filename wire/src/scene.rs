//! Conversions of the scene messages (`scene.proto`): the scene spec and
//! its systems, both directions, and the tables of the enums declared
//! there. Unset optional fields take the scene file's defaults, so both
//! front doors (TOML and gRPC) build the same scene; ranges are checked
//! later by `Scene::validate`, with the same field names.

use crate::WireError;
use crate::enums::{WireEnum, enum_or, optional_enum, required_enum, wire_enum};
use crate::error::{Result, required};
use meshless_engine::approx::KernelKind;
use meshless_engine::approx::mls::Order;
use meshless_engine::fluid::ViscosityModel;
use meshless_engine::geometry::read::MeshFormat;
use meshless_engine::scene::MeshData;
use meshless_engine::scene::{
    Aabb, FluidBlock, FluidSpec, IntegratorKind, MotionKind, OscillationSpec, OutputSpec,
    ParticleSpec, RigidBodySpec, ShapeSpec, SlipKind, SolidSpec, SolidSurfaceSpec, SolverKind,
    SurfaceSpec, SystemSpec, TimeSpec, WallModel, WallVelocities, defaults, solid_defaults,
};
use meshless_engine::solid::embedded::EmbeddingMethod;
use meshless_engine::solid::{
    Hyperelastic, ImplicitParams, ImplicitScheme, LinearSolver, Plasticity,
};
use meshless_engine::{FieldKind, Scene};
use meshless_proto::v1;

wire_enum! {
    /// The fields a frame can carry (`output.fields`, frame headers).
    FieldKind <-> FieldKind, "field kind" {
        "position" => Position,
        "velocity" => Velocity,
        "density" => Density,
        "pressure" => Pressure,
        "mass" => Mass,
        "volume" => Volume,
        "kinetic_energy" => KineticEnergy,
        "elastic_energy" => ElasticEnergy,
        "id" => Id,
    }
}

wire_enum! {
    /// SPH kernels, for densities and for gradients.
    KernelKind <-> KernelKind, "kernel" {
        "poly6" => Poly6,
        "spiky" => Spiky,
        "viscosity" => Viscosity,
        "cubic_spline" => CubicSpline,
        "wendland_c2" => WendlandC2,
    }
}

wire_enum! {
    /// How a fluid meets the domain's walls.
    WallModel <-> WallModel, "wall model" {
        "solid" => Solid,
        "reflect" => Reflect,
    }
}

wire_enum! {
    /// A fluid's viscosity term.
    ViscosityModel <-> ViscosityModel, "viscosity model" {
        "morris" => Morris,
        "kernel_laplacian" => KernelLaplacian,
        "monaghan" => Monaghan,
    }
}

wire_enum! {
    /// The format of a mesh file.
    MeshFormat <-> MeshFormat, "mesh format" {
        "obj" => Obj,
        "ply" => Ply,
    }
}

wire_enum! {
    /// A fluid's pressure solver.
    SolverKind <-> SolverKind, "solver" {
        "wcsph" => Wcsph,
        "dfsph" => Dfsph,
    }
}

wire_enum! {
    /// How a rigid body moves.
    MotionKind <-> RigidMotion, "motion" {
        "static" => Static,
        "kinematic" => Kinematic,
        "dynamic" => Dynamic,
    }
}

wire_enum! {
    /// The tangential condition where the fluid meets a body.
    SlipKind <-> SlipCondition, "slip condition" {
        "free" => Free,
        "no" => No,
    }
}

wire_enum! {
    /// The MLS basis order of a solid.
    Order <-> MlsOrder, "MLS order" {
        "constant" => Constant,
        "linear" => Linear,
        "quadratic" => Quadratic,
    }
}

wire_enum! {
    /// A solid's hyperelastic energy.
    Hyperelastic <-> SolidMaterial, "material" {
        "st_venant_kirchhoff" => StVenantKirchhoff,
        "stable_neo_hookean" => StableNeoHookean,
    }
}

wire_enum! {
    /// A solid's time integrator.
    IntegratorKind <-> SolidIntegrator, "integrator" {
        "explicit" => Explicit,
        "implicit" => Implicit,
    }
}

wire_enum! {
    /// How a solid's surface follows its particles.
    EmbeddingMethod <-> EmbeddingMethod, "embedding method" {
        "shape_functions" => ShapeFunctions,
        "gradients" => Gradients,
    }
}

wire_enum! {
    /// The implicit solid's linear solver.
    LinearSolver <-> LinearSolver, "linear solver" {
        "auto" => Auto,
        "cholesky" => Cholesky,
        "conjugate_gradient" => ConjugateGradient,
    }
}

wire_enum! {
    /// The implicit solid's time discretisation.
    ImplicitScheme <-> ImplicitScheme, "implicit scheme" {
        "backward_euler" => BackwardEuler,
        "midpoint" => Midpoint,
        "static" => Static,
    }
}

/// A kernel field: unset gives `default`; a set value must name a kernel
/// (its error shows the plain number).
fn kernel_kind(value: Option<i32>, default: KernelKind, field: &str) -> Result<KernelKind> {
    value.map_or(Ok(default), |value| required_enum(value, field))
}

/// The engine form of a vector.
/// A vector field's three formulas, or none when the list is empty.
fn formulas(texts: Vec<String>, field: &str) -> Result<Option<[String; 3]>> {
    if texts.is_empty() {
        return Ok(None);
    }
    let count = texts.len();
    <[String; 3]>::try_from(texts).map(Some).map_err(|_| {
        WireError::new(
            field,
            format!("has {count} formulas; give three (x, y and z components) or none"),
        )
    })
}

pub(crate) fn vec3(v: v1::Vec3) -> [f64; 3] {
    let v1::Vec3 { x, y, z } = v;
    [x, y, z]
}

/// The wire form of a vector.
pub(crate) fn to_vec3(v: [f64; 3]) -> v1::Vec3 {
    v1::Vec3 {
        x: v[0],
        y: v[1],
        z: v[2],
    }
}

/// The engine box of a required `Aabb` field.
pub(crate) fn aabb(b: Option<v1::Aabb>, field: &str) -> Result<Aabb> {
    let v1::Aabb { min, max } = required(b, field)?;
    Ok(Aabb {
        min: vec3(required(min, &format!("{field}.min"))?),
        max: vec3(required(max, &format!("{field}.max"))?),
    })
}

/// The wire form of a box.
pub(crate) fn to_aabb(b: &Aabb) -> v1::Aabb {
    v1::Aabb {
        min: Some(to_vec3(b.min)),
        max: Some(to_vec3(b.max)),
    }
}

/// checked later by `Scene::validate`, with the same field names.
pub fn scene_from_proto(spec: v1::SceneSpec) -> Result<Scene> {
    let v1::SceneSpec {
        name,
        domain,
        gravity,
        time,
        systems,
        output,
        dimension,
        periodic,
    } = spec;
    let v1::TimeSpec {
        dt,
        max_substeps,
        cfl,
    } = required(time, "time")?;
    let systems = systems
        .into_iter()
        .enumerate()
        .map(|(s, system)| system_from_proto(system, &format!("systems[{s}]")))
        .collect::<Result<Vec<_>>>()?;
    let output = match output {
        None => OutputSpec::default(),
        Some(v1::OutputSpec {
            fields,
            frame_every,
            surface,
        }) => OutputSpec {
            fields: fields
                .into_iter()
                .enumerate()
                .map(|(i, f)| required_enum::<FieldKind>(f, &format!("output.fields[{i}]")))
                .collect::<Result<_>>()?,
            frame_every: frame_every.unwrap_or(defaults::FRAME_EVERY),
            surface: surface.map(|surface| {
                let v1::SurfaceSpec { cell, iso } = surface;
                SurfaceSpec {
                    cell,
                    iso: iso.unwrap_or(defaults::SURFACE_ISO),
                }
            }),
        },
    };
    Ok(Scene {
        name,
        dimension: dimension.map_or(3, |d| d as usize),
        domain: aabb(domain, "domain")?,
        periodic: periodic.map_or([false; 3], |v1::Periodic { x, y, z }| [x, y, z]),
        gravity: gravity.map_or(defaults::GRAVITY, vec3),
        time: TimeSpec {
            dt,
            max_substeps: max_substeps.unwrap_or(defaults::MAX_SUBSTEPS),
            cfl: cfl.unwrap_or(defaults::CFL),
        },
        systems,
        output,
    })
}

fn system_from_proto(system: v1::SystemSpec, field: &str) -> Result<SystemSpec> {
    let v1::SystemSpec { kind } = system;
    match kind {
        Some(v1::system_spec::Kind::Fluid(fluid)) => {
            Ok(SystemSpec::Fluid(fluid_from_proto(fluid, field)?))
        }
        Some(v1::system_spec::Kind::RigidBody(body)) => {
            Ok(SystemSpec::RigidBody(body_from_proto(body, field)?))
        }
        Some(v1::system_spec::Kind::Solid(solid)) => {
            Ok(SystemSpec::Solid(solid_from_proto(solid, field)?))
        }
        Some(v1::system_spec::Kind::ModalSolid(solid)) => Ok(SystemSpec::ModalSolid(
            crate::modal::modal_from_proto(solid, field)?,
        )),
        None => Err(WireError::new(
            format!("{field}.kind"),
            "unknown or missing system kind; this server simulates: fluid, rigid_body, solid, \
             modal_solid",
        )),
    }
}

/// The engine shape of a required `Shape` field.
pub(crate) fn shape_from_proto(shape: Option<v1::Shape>, field: &str) -> Result<ShapeSpec> {
    let v1::Shape { kind } = required(shape, field)?;
    match kind {
        Some(v1::shape::Kind::Box(v1::BoxShape { half_extents })) => Ok(ShapeSpec::Box {
            half_extents: vec3(required(half_extents, &format!("{field}.half_extents"))?),
        }),
        Some(v1::shape::Kind::Sphere(v1::SphereShape { radius })) => {
            Ok(ShapeSpec::Sphere { radius })
        }
        Some(v1::shape::Kind::Capsule(v1::CapsuleShape {
            half_length,
            radius,
        })) => Ok(ShapeSpec::Capsule {
            half_length,
            radius,
        }),
        Some(v1::shape::Kind::Plane(v1::PlaneShape { normal, offset })) => Ok(ShapeSpec::Plane {
            normal: vec3(required(normal, &format!("{field}.normal"))?),
            offset,
        }),
        Some(v1::shape::Kind::Mesh(v1::MeshShape { path, scale, data })) => {
            let data = data
                .map(
                    |v1::MeshData {
                         format,
                         content,
                         length: _,
                     }| {
                        Ok::<_, WireError>(MeshData {
                            format: required_enum(format, &format!("{field}.data.format"))?,
                            content,
                        })
                    },
                )
                .transpose()?;
            Ok(ShapeSpec::Mesh {
                path: (!path.is_empty()).then_some(path),
                data,
                scale,
            })
        }
        None => Err(WireError::new(
            format!("{field}.kind"),
            "unknown or missing shape; use box, sphere, capsule, plane or mesh",
        )),
    }
}

/// The wire form of a shape.
pub(crate) fn to_shape(shape: &ShapeSpec) -> v1::Shape {
    let kind = match shape {
        ShapeSpec::Box { half_extents } => v1::shape::Kind::Box(v1::BoxShape {
            half_extents: Some(to_vec3(*half_extents)),
        }),
        ShapeSpec::Sphere { radius } => {
            v1::shape::Kind::Sphere(v1::SphereShape { radius: *radius })
        }
        ShapeSpec::Capsule {
            half_length,
            radius,
        } => v1::shape::Kind::Capsule(v1::CapsuleShape {
            half_length: *half_length,
            radius: *radius,
        }),
        ShapeSpec::Plane { normal, offset } => v1::shape::Kind::Plane(v1::PlaneShape {
            normal: Some(to_vec3(*normal)),
            offset: *offset,
        }),
        ShapeSpec::Mesh { path, data, scale } => v1::shape::Kind::Mesh(v1::MeshShape {
            path: path.clone().unwrap_or_default(),
            scale: *scale,
            data: data.as_ref().map(|d| v1::MeshData {
                format: d.format.to_i32(),
                content: d.content.clone(),
                length: 0,
            }),
        }),
    };
    v1::Shape { kind: Some(kind) }
}

fn body_from_proto(body: v1::RigidBodySpec, field: &str) -> Result<RigidBodySpec> {
    let v1::RigidBodySpec {
        shape,
        position,
        orientation,
        motion,
        density,
        velocity,
        angular_velocity,
        oscillation,
        slip,
        viscosity,
        hollow,
    } = body;
    let oscillation = oscillation
        .map(|o| {
            let v1::Oscillation {
                amplitude,
                frequency,
            } = o;
            Ok::<_, WireError>(OscillationSpec {
                amplitude: vec3(required(
                    amplitude,
                    &format!("{field}.oscillation.amplitude"),
                )?),
                frequency,
            })
        })
        .transpose()?;
    Ok(RigidBodySpec {
        shape: shape_from_proto(shape, &format!("{field}.shape"))?,
        position: vec3(required(position, &format!("{field}.position"))?),
        orientation: orientation.map_or([0.0; 3], vec3),
        motion: enum_or(motion, defaults::MOTION, &format!("{field}.motion"))?,
        density,
        velocity: velocity.map_or([0.0; 3], vec3),
        angular_velocity: angular_velocity.map_or([0.0; 3], vec3),
        oscillation,
        slip: enum_or(slip, defaults::SLIP, &format!("{field}.slip"))?,
        viscosity,
        hollow,
    })
}

fn to_body(b: &RigidBodySpec) -> v1::RigidBodySpec {
    v1::RigidBodySpec {
        shape: Some(to_shape(&b.shape)),
        position: Some(to_vec3(b.position)),
        orientation: Some(to_vec3(b.orientation)),
        motion: b.motion.to_i32(),
        density: b.density,
        velocity: Some(to_vec3(b.velocity)),
        angular_velocity: Some(to_vec3(b.angular_velocity)),
        oscillation: b.oscillation.map(|o| v1::Oscillation {
            amplitude: Some(to_vec3(o.amplitude)),
            frequency: o.frequency,
        }),
        slip: b.slip.to_i32(),
        viscosity: b.viscosity,
        hollow: b.hollow,
    }
}

/// Implicit settings with each unset field at the engine's default.
fn implicit_from_proto(
    settings: Option<v1::ImplicitSettings>,
    field: &str,
) -> Result<ImplicitParams> {
    let defaults = ImplicitParams::default();
    let Some(v1::ImplicitSettings {
        newton_tolerance,
        max_newton_iterations,
        cg_tolerance,
        max_cg_iterations,
        linear_solver,
        scheme,
    }) = settings
    else {
        return Ok(defaults);
    };
    Ok(ImplicitParams {
        newton_tolerance: newton_tolerance.unwrap_or(defaults.newton_tolerance),
        max_newton_iterations: max_newton_iterations.unwrap_or(defaults.max_newton_iterations),
        cg_tolerance: cg_tolerance.unwrap_or(defaults.cg_tolerance),
        max_cg_iterations: max_cg_iterations.unwrap_or(defaults.max_cg_iterations),
        linear_solver: enum_or::<LinearSolver>(
            linear_solver,
            defaults.linear_solver,
            &format!("{field}.implicit.linear_solver"),
        )?,
        scheme: enum_or::<ImplicitScheme>(
            scheme,
            defaults.scheme,
            &format!("{field}.implicit.scheme"),
        )?,
    })
}

fn to_implicit(params: &ImplicitParams) -> v1::ImplicitSettings {
    let ImplicitParams {
        newton_tolerance,
        max_newton_iterations,
        cg_tolerance,
        max_cg_iterations,
        linear_solver,
        scheme,
    } = *params;
    v1::ImplicitSettings {
        newton_tolerance: Some(newton_tolerance),
        max_newton_iterations: Some(max_newton_iterations),
        cg_tolerance: Some(cg_tolerance),
        max_cg_iterations: Some(max_cg_iterations),
        linear_solver: linear_solver.to_i32(),
        scheme: scheme.to_i32(),
    }
}

fn solid_from_proto(solid: v1::SolidSpec, field: &str) -> Result<SolidSpec> {
    let v1::SolidSpec {
        shape,
        position,
        orientation,
        spacing,
        density,
        young,
        poisson,
        volume_stiffness,
        order,
        support,
        hourglass,
        damping,
        friction,
        integrator,
        cfl,
        implicit,
        velocity,
        angular_velocity,
        anchors,
        plasticity,
        surface,
        material,
    } = solid;
    let surface = surface
        .map(|surface| {
            let v1::SolidSurfaceSpec {
                method,
                subdivisions,
            } = surface;
            Ok::<_, WireError>(SolidSurfaceSpec {
                method: optional_enum(
                    method,
                    EmbeddingMethod::ShapeFunctions,
                    &format!("{field}.surface.method"),
                )?,
                subdivisions: subdivisions.unwrap_or(solid_defaults::SURFACE_SUBDIVISIONS),
            })
        })
        .transpose()?;
    let anchors = anchors
        .into_iter()
        .enumerate()
        .map(|(k, anchor)| aabb(Some(anchor), &format!("{field}.anchors[{k}]")))
        .collect::<Result<_>>()?;
    let plasticity = plasticity.map(|p| {
        let v1::Plasticity {
            yield_strain,
            creep,
            max,
            rebase,
        } = p;
        Plasticity {
            yield_strain,
            creep,
            max,
            rebase,
        }
    });
    Ok(SolidSpec {
        shape: shape_from_proto(shape, &format!("{field}.shape"))?,
        position: vec3(required(position, &format!("{field}.position"))?),
        orientation: orientation.map_or([0.0; 3], vec3),
        spacing,
        density: density.unwrap_or(solid_defaults::DENSITY),
        young,
        poisson: poisson.unwrap_or(solid_defaults::POISSON),
        volume_stiffness: volume_stiffness.unwrap_or(0.0),
        order: optional_enum(order, solid_defaults::ORDER, &format!("{field}.order"))?,
        support: support.unwrap_or(solid_defaults::SUPPORT),
        hourglass: hourglass.unwrap_or(solid_defaults::HOURGLASS),
        damping: damping.unwrap_or(0.0),
        friction: friction.unwrap_or(solid_defaults::FRICTION),
        integrator: optional_enum(
            integrator,
            IntegratorKind::default(),
            &format!("{field}.integrator"),
        )?,
        cfl: cfl.unwrap_or(solid_defaults::CFL),
        implicit: implicit_from_proto(implicit, field)?,
        velocity: velocity.map_or([0.0; 3], vec3),
        angular_velocity: angular_velocity.map_or([0.0; 3], vec3),
        anchors,
        plasticity,
        surface,
        material: optional_enum(
            material,
            Hyperelastic::default(),
            &format!("{field}.material"),
        )?,
    })
}

/// Destructured whole, so a new engine field fails to build here until it
/// crosses the protocol.
fn to_solid(solid: &SolidSpec) -> v1::SolidSpec {
    let SolidSpec {
        shape,
        position,
        orientation,
        spacing,
        density,
        young,
        poisson,
        volume_stiffness,
        order,
        support,
        hourglass,
        damping,
        friction,
        integrator,
        cfl,
        implicit,
        velocity,
        angular_velocity,
        anchors,
        plasticity,
        surface,
        material,
    } = solid;
    v1::SolidSpec {
        shape: Some(to_shape(shape)),
        position: Some(to_vec3(*position)),
        orientation: Some(to_vec3(*orientation)),
        spacing: *spacing,
        density: Some(*density),
        young: *young,
        poisson: Some(*poisson),
        volume_stiffness: Some(*volume_stiffness),
        order: Some(order.to_i32()),
        support: Some(*support),
        hourglass: Some(*hourglass),
        damping: Some(*damping),
        friction: Some(*friction),
        integrator: Some(integrator.to_i32()),
        cfl: Some(*cfl),
        implicit: Some(to_implicit(implicit)),
        velocity: Some(to_vec3(*velocity)),
        angular_velocity: Some(to_vec3(*angular_velocity)),
        material: Some(material.to_i32()),
        anchors: anchors.iter().map(to_aabb).collect(),
        plasticity: plasticity.map(|p| {
            let Plasticity {
                yield_strain,
                creep,
                max,
                rebase,
            } = p;
            v1::Plasticity {
                yield_strain,
                creep,
                max,
                rebase,
            }
        }),
        surface: surface.as_ref().map(|surface| {
            let SolidSurfaceSpec {
                method,
                subdivisions,
            } = *surface;
            v1::SolidSurfaceSpec {
                method: Some(method.to_i32()),
                subdivisions: Some(subdivisions),
            }
        }),
    }
}

fn fluid_from_proto(fluid: v1::FluidSpec, field: &str) -> Result<FluidSpec> {
    let v1::FluidSpec {
        spacing,
        support_radius,
        rest_density,
        stiffness,
        gamma,
        negative_pressure_scale,
        xsph,
        blocks,
        density_kernel,
        gradient_kernel,
        viscosity,
        walls,
        solver,
        density_tolerance,
        divergence_tolerance,
        max_solver_iterations,
        particles,
        viscosity_model: model,
        wall_slip,
        wall_velocity,
        velocity_field,
        body_force,
    } = fluid;
    let velocity_field = formulas(velocity_field, &format!("{field}.velocity_field"))?;
    let body_force = formulas(body_force, &format!("{field}.body_force"))?;
    let wall_velocity = wall_velocity.map_or_else(WallVelocities::default, |w| {
        let v1::WallVelocities {
            min_x,
            max_x,
            min_y,
            max_y,
            min_z,
            max_z,
        } = w;
        WallVelocities {
            min_x: min_x.map(vec3),
            max_x: max_x.map(vec3),
            min_y: min_y.map(vec3),
            max_y: max_y.map(vec3),
            min_z: min_z.map(vec3),
            max_z: max_z.map(vec3),
        }
    });
    let particles = particles
        .into_iter()
        .enumerate()
        .map(|(i, particle)| {
            let v1::Particle { position, velocity } = particle;
            Ok(ParticleSpec {
                position: vec3(required(
                    position,
                    &format!("{field}.particles[{i}].position"),
                )?),
                velocity: velocity.map_or([0.0; 3], vec3),
            })
        })
        .collect::<Result<_>>()?;
    let blocks = blocks
        .into_iter()
        .enumerate()
        .map(|(b, block)| {
            let v1::FluidBlock { region, velocity } = block;
            Ok(FluidBlock {
                region: aabb(region, &format!("{field}.blocks[{b}].region"))?,
                velocity: velocity.map_or([0.0; 3], vec3),
            })
        })
        .collect::<Result<_>>()?;
    Ok(FluidSpec {
        spacing,
        support_radius,
        rest_density: rest_density.unwrap_or(defaults::REST_DENSITY),
        stiffness,
        gamma: gamma.unwrap_or(defaults::GAMMA),
        negative_pressure_scale: negative_pressure_scale
            .unwrap_or(defaults::NEGATIVE_PRESSURE_SCALE),
        xsph: xsph.unwrap_or(defaults::XSPH),
        viscosity: viscosity.unwrap_or(defaults::VISCOSITY),
        viscosity_model: optional_enum(
            model,
            defaults::VISCOSITY_MODEL,
            &format!("{field}.viscosity_model"),
        )?,
        walls: optional_enum(walls, defaults::WALLS, &format!("{field}.walls"))?,
        wall_slip: optional_enum(wall_slip, defaults::SLIP, &format!("{field}.wall_slip"))?,
        wall_velocity,
        velocity_field,
        body_force,
        solver: optional_enum(solver, defaults::SOLVER, &format!("{field}.solver"))?,
        density_tolerance: density_tolerance.unwrap_or(defaults::DENSITY_TOLERANCE),
        divergence_tolerance: divergence_tolerance.unwrap_or(defaults::DIVERGENCE_TOLERANCE),
        max_solver_iterations: max_solver_iterations.unwrap_or(defaults::MAX_SOLVER_ITERATIONS),
        density_kernel: kernel_kind(
            density_kernel,
            defaults::DENSITY_KERNEL,
            &format!("{field}.density_kernel"),
        )?,
        gradient_kernel: kernel_kind(
            gradient_kernel,
            defaults::GRADIENT_KERNEL,
            &format!("{field}.gradient_kernel"),
        )?,
        blocks,
        particles,
    })
}

/// The `SceneSpec` of an engine scene, every default made explicit.
pub fn scene_to_proto(scene: &Scene) -> v1::SceneSpec {
    v1::SceneSpec {
        name: scene.name.clone(),
        dimension: Some(scene.dimension as u32),
        domain: Some(to_aabb(&scene.domain)),
        periodic: scene.periodic.contains(&true).then_some(v1::Periodic {
            x: scene.periodic[0],
            y: scene.periodic[1],
            z: scene.periodic[2],
        }),
        gravity: Some(to_vec3(scene.gravity)),
        time: Some(v1::TimeSpec {
            dt: scene.time.dt,
            max_substeps: Some(scene.time.max_substeps),
            cfl: Some(scene.time.cfl),
        }),
        systems: scene
            .systems
            .iter()
            .map(|system| v1::SystemSpec {
                kind: Some(match system {
                    SystemSpec::Fluid(f) => v1::system_spec::Kind::Fluid(v1::FluidSpec {
                        spacing: f.spacing,
                        support_radius: Some(f.support_radius()),
                        rest_density: Some(f.rest_density),
                        stiffness: f.stiffness,
                        gamma: Some(f.gamma),
                        negative_pressure_scale: Some(f.negative_pressure_scale),
                        xsph: Some(f.xsph),
                        density_kernel: Some(f.density_kernel.to_i32()),
                        gradient_kernel: Some(f.gradient_kernel.to_i32()),
                        viscosity: Some(f.viscosity),
                        viscosity_model: Some(f.viscosity_model.to_i32()),
                        walls: Some(f.walls.to_i32()),
                        wall_slip: Some(f.wall_slip.to_i32()),
                        wall_velocity: (!f.wall_velocity.is_still()).then(|| {
                            let w = &f.wall_velocity;
                            v1::WallVelocities {
                                min_x: w.min_x.map(to_vec3),
                                max_x: w.max_x.map(to_vec3),
                                min_y: w.min_y.map(to_vec3),
                                max_y: w.max_y.map(to_vec3),
                                min_z: w.min_z.map(to_vec3),
                                max_z: w.max_z.map(to_vec3),
                            }
                        }),
                        velocity_field: f.velocity_field.clone().map(Vec::from).unwrap_or_default(),
                        body_force: f.body_force.clone().map(Vec::from).unwrap_or_default(),
                        solver: Some(f.solver.to_i32()),
                        density_tolerance: Some(f.density_tolerance),
                        divergence_tolerance: Some(f.divergence_tolerance),
                        max_solver_iterations: Some(f.max_solver_iterations),
                        blocks: f
                            .blocks
                            .iter()
                            .map(|b| v1::FluidBlock {
                                region: Some(to_aabb(&b.region)),
                                velocity: Some(to_vec3(b.velocity)),
                            })
                            .collect(),
                        particles: f
                            .particles
                            .iter()
                            .map(|p| v1::Particle {
                                position: Some(to_vec3(p.position)),
                                velocity: Some(to_vec3(p.velocity)),
                            })
                            .collect(),
                    }),
                    SystemSpec::RigidBody(b) => v1::system_spec::Kind::RigidBody(to_body(b)),
                    SystemSpec::Solid(s) => v1::system_spec::Kind::Solid(to_solid(s)),
                    SystemSpec::ModalSolid(s) => {
                        v1::system_spec::Kind::ModalSolid(crate::modal::to_modal(s))
                    }
                }),
            })
            .collect(),
        output: Some(v1::OutputSpec {
            fields: scene.output.fields.iter().map(|&k| k.to_i32()).collect(),
            frame_every: Some(scene.output.frame_every),
            surface: scene.output.surface.as_ref().map(|surface| {
                let spacing = scene.fluid().map(|f| f.spacing);
                v1::SurfaceSpec {
                    cell: spacing.map_or(surface.cell, |dx| Some(surface.cell(dx))),
                    iso: Some(surface.iso),
                }
            }),
        }),
    }
}

/// The scene as a server echoes it (`Session.scene`): [`scene_to_proto`]
/// with every mesh's bytes left out and their length given instead, so
/// that getting or listing sessions never sends their meshes back.
pub fn scene_echo_to_proto(scene: &Scene) -> v1::SceneSpec {
    let mut spec = scene_to_proto(scene);
    for system in &mut spec.systems {
        let shape = match &mut system.kind {
            Some(v1::system_spec::Kind::RigidBody(body)) => body.shape.as_mut(),
            Some(v1::system_spec::Kind::Solid(solid)) => solid.shape.as_mut(),
            Some(v1::system_spec::Kind::ModalSolid(solid)) => solid.shape.as_mut(),
            Some(v1::system_spec::Kind::Fluid(_)) | None => None,
        };
        if let Some(v1::Shape {
            kind:
                Some(v1::shape::Kind::Mesh(v1::MeshShape {
                    data: Some(data), ..
                })),
        }) = shape
        {
            data.length = data.content.len() as u64;
            data.content = Vec::new();
        }
    }
    spec
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::frame_to_proto;
    use meshless_engine::BuildOptions;

    fn dam_break() -> Scene {
        Scene::from_toml_str(include_str!("../../scenes/dam_break.toml")).expect("shipped scene")
    }

    /// engine -> proto -> engine is the identity once defaults are explicit.
    #[test]
    fn scenes_round_trip_through_the_protocol() {
        let scene = dam_break();
        let back = scene_from_proto(scene_to_proto(&scene)).expect("round trip");
        let mut explicit = scene.clone();
        let SystemSpec::Fluid(f) = &mut explicit.systems[0] else {
            panic!("the first system is the fluid")
        };
        f.support_radius = Some(f.support_radius());
        assert_eq!(back, explicit);
        back.validate(&BuildOptions::default())
            .expect("still valid");

        // Periodic axes and single particles survive the trip too.
        let mut scene = explicit;
        scene.periodic = [true, false, true];
        let SystemSpec::Fluid(f) = &mut scene.systems[0] else {
            panic!("the dam break is a fluid")
        };
        f.particles.push(ParticleSpec {
            position: [3.5, 0.5, 0.5],
            velocity: [-1.0, 0.0, 0.25],
        });
        assert_eq!(
            scene_from_proto(scene_to_proto(&scene)).expect("round trip"),
            scene
        );
    }

    /// Rigid bodies survive engine -> proto -> engine, and frames carry
    /// their poses.
    #[test]
    fn bodies_round_trip_and_frames_carry_poses() {
        let scene = Scene::from_toml_str(include_str!("../../scenes/floating_box.toml"))
            .expect("shipped scene");
        let back = scene_from_proto(scene_to_proto(&scene)).expect("round trip");
        assert_eq!(back.systems[1..], scene.systems[1..]);
        let world = back.build(&BuildOptions::default()).expect("valid");
        let wire = frame_to_proto("s", &world.frame());
        assert_eq!(wire.bodies.len(), 2);
        assert_eq!(wire.bodies[0].system, 1);
        let q = wire.bodies[0].orientation.expect("orientation");
        assert!((q.z - 0.15f64.sin()).abs() < 1e-12 && (q.w - 0.15f64.cos()).abs() < 1e-12);

        let mut spec = scene_to_proto(&scene);
        if let Some(v1::system_spec::Kind::RigidBody(b)) = &mut spec.systems[1].kind {
            b.shape = None;
        }
        let err = scene_from_proto(spec).expect_err("no shape");
        assert!(err.to_string().starts_with("systems[1].shape:"), "{err}");
    }

    /// Mesh shapes cross with their path and scale (the path as the
    /// scene file's directory made it), and the world built from the wire
    /// reads the same files.
    #[test]
    fn mesh_bodies_round_trip() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/mesh_body.toml");
        let scene = Scene::from_toml_file(&path).expect("shipped scene");
        assert!(matches!(
            &scene.systems[1],
            SystemSpec::RigidBody(RigidBodySpec { shape: ShapeSpec::Mesh { scale: Some(s), .. }, .. })
                if *s == 0.06
        ));
        let back = scene_from_proto(scene_to_proto(&scene)).expect("round trip");
        assert_eq!(back.systems[1..], scene.systems[1..]);
        let world = back.build(&BuildOptions::default()).expect("valid");
        assert_eq!(frame_to_proto("s", &world.frame()).bodies.len(), 2);

        // Loaded, the bytes cross too, and a host that reads no file
        // builds the same world from them.
        let mut loaded = scene.clone();
        loaded
            .load_meshes(&BuildOptions::default())
            .expect("the shipped meshes load");
        let back = scene_from_proto(scene_to_proto(&loaded)).expect("round trip");
        assert!(
            back.systems[1..] == loaded.systems[1..],
            "the meshes changed"
        );
        let no_files = BuildOptions {
            mesh_files: meshless_engine::scene::MeshFiles::None,
            ..BuildOptions::default()
        };
        let world = back.build(&no_files).expect("built from the bytes");
        assert_eq!(frame_to_proto("s", &world.frame()).bodies.len(), 2);
        let err = scene.build(&no_files).expect_err("paths need files");
        assert!(err.to_string().contains("`data`"), "{err}");

        // The echo leaves the bytes out and says how many there were.
        let echo = scene_echo_to_proto(&loaded);
        let Some(v1::system_spec::Kind::RigidBody(body)) = &echo.systems[1].kind else {
            panic!("a body");
        };
        let Some(v1::Shape {
            kind: Some(v1::shape::Kind::Mesh(mesh)),
        }) = &body.shape
        else {
            panic!("a mesh");
        };
        let data = mesh.data.as_ref().expect("data");
        assert!(data.content.is_empty());
        assert!(data.length > 100, "{}", data.length);
        assert!(mesh.path.ends_with("icosphere.obj"), "{}", mesh.path);
    }

    fn shipped(name: &str) -> Scene {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../scenes")
            .join(name);
        Scene::from_toml_file(&path).expect("shipped scene")
    }

    /// Solids survive engine -> proto -> engine with every field set away
    /// from its default, and frames say where their particles are.
    #[test]
    fn solids_round_trip_and_frames_carry_their_ranges() {
        for name in ["elastic_beam.toml", "jelly_drop.toml"] {
            let scene = shipped(name);
            let back = scene_from_proto(scene_to_proto(&scene)).expect("round trip");
            assert_eq!(back, scene, "{name}");
        }

        // A surface crosses with its method and subdivisions, and frames
        // carry it deformed, with a normal per vertex.
        let mut scene = shipped("jelly_drop.toml");
        let SystemSpec::Solid(solid) = &mut scene.systems[0] else {
            panic!("the jelly is a solid")
        };
        solid.surface = Some(SolidSurfaceSpec {
            method: EmbeddingMethod::Gradients,
            subdivisions: 2,
        });
        let back = scene_from_proto(scene_to_proto(&scene)).expect("round trip");
        assert_eq!(back, scene);
        let frame = back.build(&BuildOptions::default()).expect("valid").frame();
        let [surface] = &frame.solid_surfaces[..] else {
            panic!("one solid surface")
        };
        let wire = frame_to_proto("s", &frame);
        let [
            v1::SolidSurface {
                system: 0,
                mesh: Some(mesh),
            },
        ] = &wire.solid_surfaces[..]
        else {
            panic!(
                "the jelly's surface on the wire: {:?}",
                wire.solid_surfaces.len()
            )
        };
        assert_eq!(mesh.vertices.len(), 12 * surface.mesh.vertices.len());
        assert_eq!(mesh.normals.len(), mesh.vertices.len());
        assert_eq!(mesh.triangles.len(), 12 * surface.mesh.triangles.len());
        let last = surface.normals.len() - 1;
        let ny = f32::from_le_bytes(
            mesh.normals[12 * last + 4..12 * last + 8]
                .try_into()
                .expect("4 bytes"),
        );
        assert_eq!(ny, surface.normals[last].y as f32);

        let mut scene = shipped("jelly_drop.toml");
        let SystemSpec::Solid(solid) = &mut scene.systems[0] else {
            panic!("the jelly is a solid")
        };
        *solid = SolidSpec {
            shape: ShapeSpec::Capsule {
                half_length: 0.05,
                radius: 0.08,
            },
            orientation: [0.1, -0.2, 0.3],
            density: 1200.0,
            poisson: 0.45,
            order: Order::Quadratic,
            support: 2.5,
            hourglass: 0.3,
            friction: 0.1,
            integrator: IntegratorKind::Implicit,
            cfl: 0.25,
            implicit: ImplicitParams {
                newton_tolerance: 1e-4,
                max_newton_iterations: 7,
                cg_tolerance: 1e-2,
                max_cg_iterations: 33,
                linear_solver: LinearSolver::ConjugateGradient,
                scheme: ImplicitScheme::Midpoint,
            },
            velocity: [1.0, 2.0, 3.0],
            angular_velocity: [-1.0, 0.5, 0.25],
            anchors: vec![Aabb {
                min: [0.4, 0.6, 0.4],
                max: [0.6, 0.7, 0.6],
            }],
            plasticity: Some(Plasticity {
                yield_strain: 0.01,
                creep: 0.2,
                max: 0.5,
                rebase: Some(0.3),
            }),
            // A capsule has no surface to embed; the jelly's crossed above.
            surface: None,
            ..solid.clone()
        };
        let back = scene_from_proto(scene_to_proto(&scene)).expect("round trip");
        assert_eq!(back, scene);
        let SystemSpec::Solid(solid) = &mut scene.systems[0] else {
            panic!("a solid")
        };
        solid.plasticity.as_mut().expect("plastic").rebase = None;
        let back = scene_from_proto(scene_to_proto(&scene)).expect("round trip");
        assert_eq!(back, scene, "no re-basing stays none");

        let world = back.build(&BuildOptions::default()).expect("valid");
        let frame = world.frame();
        let wire = frame_to_proto("s", &frame);
        assert_eq!(
            wire.solids,
            vec![v1::SolidRange {
                system: 0,
                first: 0,
                count: frame.particle_count as u64,
            }]
        );
    }

    /// A solid message with only the required fields set builds the same
    /// solid as the TOML with only those keys: both front doors share
    /// the defaults.
    #[test]
    fn unset_solid_fields_take_the_scene_file_defaults() {
        let toml = r#"
            [domain]
            min = [0.0, 0.0, 0.0]
            max = [1.0, 1.0, 1.0]
            [time]
            dt = 0.01
            [[systems]]
            kind = "solid"
            shape = { type = "sphere", radius = 0.2 }
            position = [0.5, 0.5, 0.5]
            spacing = 0.05
            young = 1.0e5
            surface = {}
        "#;
        let scene = Scene::from_toml_str(toml).expect("valid");
        let mut spec = scene_to_proto(&scene);
        spec.systems[0].kind = Some(v1::system_spec::Kind::Solid(v1::SolidSpec {
            shape: Some(v1::Shape {
                kind: Some(v1::shape::Kind::Sphere(v1::SphereShape { radius: 0.2 })),
            }),
            position: Some(to_vec3([0.5; 3])),
            spacing: 0.05,
            young: 1.0e5,
            surface: Some(v1::SolidSurfaceSpec::default()),
            ..Default::default()
        }));
        assert_eq!(scene_from_proto(spec.clone()).expect("valid"), scene);

        let mut no_method = spec.clone();
        let v1::SystemSpec {
            kind: Some(v1::system_spec::Kind::Solid(solid)),
        } = &mut spec.systems[0]
        else {
            panic!("a solid")
        };
        solid.order = Some(v1::MlsOrder::Unspecified as i32);
        let err = scene_from_proto(spec).expect_err("no order");
        assert!(err.to_string().starts_with("systems[0].order:"), "{err}");

        let v1::SystemSpec {
            kind: Some(v1::system_spec::Kind::Solid(solid)),
        } = &mut no_method.systems[0]
        else {
            panic!("a solid")
        };
        solid.surface = Some(v1::SolidSurfaceSpec {
            method: Some(v1::EmbeddingMethod::Unspecified as i32),
            subdivisions: None,
        });
        let err = scene_from_proto(no_method).expect_err("no method");
        assert!(
            err.to_string().starts_with("systems[0].surface.method:"),
            "{err}"
        );
    }

    #[test]
    fn missing_messages_name_their_field() {
        let mut spec = scene_to_proto(&dam_break());
        spec.time = None;
        assert!(
            scene_from_proto(spec)
                .expect_err("no time")
                .to_string()
                .starts_with("time:")
        );

        let mut spec = scene_to_proto(&dam_break());
        spec.systems[0].kind = None;
        let err = scene_from_proto(spec).expect_err("no kind");
        assert!(err.to_string().starts_with("systems[0].kind:"), "{err}");

        let mut spec = scene_to_proto(&dam_break());
        spec.output.as_mut().expect("output").fields.push(99);
        let err = scene_from_proto(spec).expect_err("bad field");
        assert!(err.to_string().starts_with("output.fields[3]:"), "{err}");
    }

    /// A surface request crosses with its default cell made explicit, and
    /// a frame's mesh goes out as packed f32 vertices and u32 indices.
    #[test]
    fn surfaces_cross_the_protocol() {
        let mut scene = dam_break();
        scene.output.surface = Some(SurfaceSpec {
            cell: None,
            iso: 0.4,
        });
        let spec = scene_to_proto(&scene);
        let wire = spec
            .output
            .as_ref()
            .and_then(|o| o.surface)
            .expect("surface");
        assert_eq!((wire.cell, wire.iso), (Some(0.01), Some(0.4)));
        let back = scene_from_proto(spec).expect("round trip");
        assert_eq!(
            back.output.surface,
            Some(SurfaceSpec {
                cell: Some(0.01),
                iso: 0.4
            })
        );

        let frame = back.build(&BuildOptions::default()).expect("world").frame();
        let mesh = frame.surface.as_ref().expect("a surface");
        let wire = frame_to_proto("s", &frame).surface.expect("on the wire");
        assert_eq!(wire.vertices.len(), 12 * mesh.vertices.len());
        assert!(
            wire.normals.is_empty(),
            "the fluid's surface has no normals"
        );
        assert_eq!(wire.triangles.len(), 12 * mesh.triangles.len());
        let last = mesh.vertices.len() - 1;
        let z = f32::from_le_bytes(
            wire.vertices[12 * last + 8..12 * last + 12]
                .try_into()
                .expect("4"),
        );
        assert_eq!(z, mesh.vertices[last].z as f32);
        let t = u32::from_le_bytes(wire.triangles[4..8].try_into().expect("4 bytes"));
        assert_eq!(t, mesh.triangles[0][1]);
    }
}
