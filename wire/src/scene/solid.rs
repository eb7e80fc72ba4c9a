//! Conversions of the MLS elastic solid's messages (`SolidSpec`,
//! `ImplicitSettings`), both directions, and the tables of the enums a
//! solid names (MLS order, material, integrator, embedding, linear solver,
//! implicit scheme).

use super::geometry::{aabb, shape_from_proto, to_aabb, to_shape, to_vec3, vec3};
use crate::enums::{WireEnum, enum_or, optional_enum, wire_enum};
use crate::error::WireError;
use crate::error::{Result, required};
use meshless_engine::approx::mls::Order;
use meshless_engine::scene::{
    FractureSpec, IntegratorKind, NotchSpec, SolidSpec, SolidSurfaceSpec, solid_defaults,
};
use meshless_engine::solid::FractureParams;
use meshless_engine::solid::embedded::EmbeddingMethod;
use meshless_engine::solid::fracture::{CrackCriterion, Resampling};
use meshless_engine::solid::{
    Hyperelastic, ImplicitParams, ImplicitScheme, LinearSolver, Plasticity,
};
use meshless_proto::v1;

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

wire_enum! {
    /// How a crack cuts the pairs it passes between.
    CrackCriterion <-> CrackCriterion, "crack criterion" {
        "transparency" => Transparency,
        "visibility" => Visibility,
    }
}

/// Fracture with each unset field at the scene file's default.
fn fracture_from_proto(fracture: v1::Fracture, field: &str) -> Result<FractureSpec> {
    let v1::Fracture {
        stress,
        plastic_strain,
        criterion,
        kappa,
        advance,
        max_cracks,
        toughness,
        notches,
        branching,
        resample,
        surface_cell,
    } = fracture;
    Ok(FractureSpec {
        stress,
        toughness,
        plastic_strain,
        criterion: optional_enum(
            criterion,
            CrackCriterion::default(),
            &format!("{field}.fracture.criterion"),
        )?,
        kappa: kappa.unwrap_or(FractureParams::DEFAULT_KAPPA),
        advance: advance.unwrap_or(FractureParams::DEFAULT_ADVANCE),
        max_cracks: max_cracks.unwrap_or(FractureParams::DEFAULT_MAX_CRACKS),
        surface_cell: surface_cell.unwrap_or(FractureParams::DEFAULT_SURFACE_CELL),
        branching,
        resample: resample.map(|r| Resampling {
            q_min: r.q_min.unwrap_or(Resampling::DEFAULT_Q_MIN),
            min_radius_ratio: r
                .min_radius_ratio
                .unwrap_or(Resampling::DEFAULT_MIN_RADIUS_RATIO),
            max_particles: r.max_particles,
        }),
        notches: notches
            .into_iter()
            .enumerate()
            .map(|(k, n)| {
                let at = format!("{field}.fracture.notches[{k}]");
                let v1::Notch {
                    center,
                    normal,
                    radius,
                } = n;
                Ok(NotchSpec {
                    center: vec3(required(center, &format!("{at}.center"))?),
                    normal: vec3(required(normal, &format!("{at}.normal"))?),
                    radius,
                })
            })
            .collect::<Result<_>>()?,
    })
}

fn to_fracture(fracture: &FractureSpec) -> v1::Fracture {
    let FractureSpec {
        stress,
        toughness,
        plastic_strain,
        criterion,
        kappa,
        advance,
        max_cracks,
        branching,
        resample,
        ref notches,
        surface_cell,
    } = *fracture;
    v1::Fracture {
        stress,
        plastic_strain,
        criterion: Some(criterion.to_i32()),
        kappa: Some(kappa),
        advance: Some(advance),
        max_cracks: Some(max_cracks),
        toughness,
        branching,
        surface_cell: Some(surface_cell),
        resample: resample.map(|r| v1::Resample {
            q_min: Some(r.q_min),
            min_radius_ratio: Some(r.min_radius_ratio),
            max_particles: r.max_particles,
        }),
        notches: notches
            .iter()
            .map(|n| v1::Notch {
                center: Some(to_vec3(n.center)),
                normal: Some(to_vec3(n.normal)),
                radius: n.radius,
            })
            .collect(),
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

/// The engine solid of a `SolidSpec`.
pub(super) fn solid_from_proto(solid: v1::SolidSpec, field: &str) -> Result<SolidSpec> {
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
        fracture,
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
    let fracture = fracture
        .map(|f| fracture_from_proto(f, field))
        .transpose()?;
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
        fracture,
        material: optional_enum(
            material,
            Hyperelastic::default(),
            &format!("{field}.material"),
        )?,
    })
}

/// Destructured whole, so a new engine field fails to build here until it
/// crosses the protocol.
pub(super) fn to_solid(solid: &SolidSpec) -> v1::SolidSpec {
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
        fracture,
    } = solid;
    v1::SolidSpec {
        fracture: fracture.as_ref().map(to_fracture),
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
