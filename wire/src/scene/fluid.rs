//! Conversions of the fluid's messages (`FluidSpec`), both directions,
//! and the tables of the enums only a fluid names (kernels, walls,
//! viscosity, pressure solver).

use super::geometry::{aabb, to_aabb, to_vec3, vec3};
use crate::enums::{WireEnum, optional_enum, required_enum, wire_enum};
use crate::error::WireError;
use crate::error::{Result, required};
use meshless_engine::approx::KernelKind;
use meshless_engine::fluid::ViscosityModel;
use meshless_engine::scene::{
    FluidBlock, FluidSpec, ParticleSpec, SolverKind, WallModel, WallVelocities, defaults,
};
use meshless_proto::v1;

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
    /// A fluid's pressure solver.
    SolverKind <-> SolverKind, "solver" {
        "wcsph" => Wcsph,
        "dfsph" => Dfsph,
    }
}

/// A kernel field: unset gives `default`; a set value must name a kernel
/// (its error shows the plain number).
fn kernel_kind(value: Option<i32>, default: KernelKind, field: &str) -> Result<KernelKind> {
    value.map_or(Ok(default), |value| required_enum(value, field))
}

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

/// The engine fluid of a `FluidSpec`.
pub(super) fn fluid_from_proto(fluid: v1::FluidSpec, field: &str) -> Result<FluidSpec> {
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

/// The wire form of a fluid, every default made explicit.
pub(super) fn to_fluid(f: &FluidSpec) -> v1::FluidSpec {
    v1::FluidSpec {
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
    }
}
