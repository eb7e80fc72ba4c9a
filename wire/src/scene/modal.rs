//! Conversions of the modal-solid messages (`ModalSolidSpec`, `Grab`,
//! `Playback` and `MassForm` in `scene.proto`), both directions. Unset
//! optional fields take the scene file's defaults
//! ([`meshless_engine::scene::modal_defaults`]).

use super::geometry::{aabb, shape_from_proto, to_aabb, to_shape, to_vec3, vec3};
use crate::enums::{WireEnum, optional_enum, wire_enum};
use crate::error::{Result, required};
use meshless_engine::approx::mls::Order;
use meshless_engine::efg::{Dynamics, MassForm};
use meshless_engine::scene::{
    GrabSpec, ModalSolidSpec, PlaybackSpec, modal_defaults as defaults, solid_defaults,
};
use meshless_proto::v1;

wire_enum! {
    /// How a modal solid moves.
    Dynamics <-> ModalDynamics, "dynamics" {
        "modal" => Modal,
        "nonlinear" => Nonlinear,
    }
}

wire_enum! {
    /// The mass matrix of a modal solid.
    MassForm <-> MassForm, "mass form" {
        "consistent" => Consistent,
        "lumped" => Lumped,
    }
}

/// The engine grab of a `Grab` message at `field`.
fn grab_from_proto(grab: v1::Grab, field: &str) -> Result<GrabSpec> {
    let v1::Grab {
        point,
        position,
        rotation,
    } = grab;
    Ok(GrabSpec {
        point: vec3(required(point, &format!("{field}.point"))?),
        position: position.map(vec3),
        rotation: rotation.map(vec3),
    })
}

/// The `Grab` message of an engine grab.
fn to_grab(grab: &GrabSpec) -> v1::Grab {
    v1::Grab {
        point: Some(to_vec3(grab.point)),
        position: grab.position.map(to_vec3),
        rotation: grab.rotation.map(to_vec3),
    }
}

/// The engine spec of a `ModalSolidSpec` at `field`.
pub(super) fn modal_from_proto(spec: v1::ModalSolidSpec, field: &str) -> Result<ModalSolidSpec> {
    let v1::ModalSolidSpec {
        shape,
        position,
        orientation,
        density,
        young,
        poisson,
        cell,
        interior_levels,
        alpha,
        basis,
        quadrature_order,
        subdivision,
        boundary_refinement,
        mass,
        penalty,
        modes,
        eigen_tolerance,
        warping,
        mass_damping,
        stiffness_damping,
        grab_eta,
        grab_gamma,
        anchors,
        grabs,
        playback,
        surface_subdivisions,
        dynamics,
    } = spec;
    Ok(ModalSolidSpec {
        dynamics: optional_enum(dynamics, Dynamics::Modal, &format!("{field}.dynamics"))?,
        shape: shape_from_proto(shape, &format!("{field}.shape"))?,
        position: vec3(required(position, &format!("{field}.position"))?),
        orientation: orientation.map_or([0.0; 3], vec3),
        density: density.unwrap_or(solid_defaults::DENSITY),
        young,
        poisson: poisson.unwrap_or(solid_defaults::POISSON),
        cell,
        interior_levels: interior_levels.unwrap_or(0),
        alpha: alpha.unwrap_or(defaults::ALPHA),
        basis: optional_enum(basis, Order::Linear, &format!("{field}.basis"))?,
        quadrature_order: quadrature_order.unwrap_or(defaults::QUADRATURE_ORDER),
        subdivision: subdivision.unwrap_or(defaults::SUBDIVISION),
        boundary_refinement: boundary_refinement.unwrap_or(defaults::BOUNDARY_REFINEMENT),
        mass: optional_enum(mass, MassForm::Consistent, &format!("{field}.mass"))?,
        penalty: penalty.unwrap_or(defaults::PENALTY),
        modes: modes.unwrap_or(defaults::MODES),
        eigen_tolerance: eigen_tolerance.unwrap_or(defaults::EIGEN_TOLERANCE),
        warping: warping.unwrap_or(true),
        mass_damping: mass_damping.unwrap_or(0.0),
        stiffness_damping: stiffness_damping.unwrap_or(0.0),
        grab_eta: grab_eta.unwrap_or(defaults::GRAB_RATE),
        grab_gamma: grab_gamma.unwrap_or(defaults::GRAB_RATE),
        anchors: anchors
            .into_iter()
            .enumerate()
            .map(|(k, b)| aabb(Some(b), &format!("{field}.anchors[{k}]")))
            .collect::<Result<_>>()?,
        grabs: grabs
            .into_iter()
            .enumerate()
            .map(|(k, g)| grab_from_proto(g, &format!("{field}.grabs[{k}]")))
            .collect::<Result<_>>()?,
        playback: playback.map(|p| {
            let v1::Playback { mode, amplitude } = p;
            PlaybackSpec { mode, amplitude }
        }),
        surface_subdivisions: surface_subdivisions.unwrap_or(defaults::SURFACE_SUBDIVISIONS),
    })
}

/// Destructured whole, so a new engine field fails to build here until it
/// crosses the protocol.
pub(super) fn to_modal(spec: &ModalSolidSpec) -> v1::ModalSolidSpec {
    let ModalSolidSpec {
        shape,
        position,
        orientation,
        density,
        young,
        poisson,
        cell,
        interior_levels,
        alpha,
        basis,
        quadrature_order,
        subdivision,
        boundary_refinement,
        mass,
        penalty,
        modes,
        eigen_tolerance,
        warping,
        mass_damping,
        stiffness_damping,
        grab_eta,
        grab_gamma,
        anchors,
        grabs,
        playback,
        surface_subdivisions,
        dynamics,
    } = spec;
    v1::ModalSolidSpec {
        dynamics: Some(dynamics.to_i32()),
        shape: Some(to_shape(shape)),
        position: Some(to_vec3(*position)),
        orientation: Some(to_vec3(*orientation)),
        density: Some(*density),
        young: *young,
        poisson: Some(*poisson),
        cell: *cell,
        interior_levels: Some(*interior_levels),
        alpha: Some(*alpha),
        basis: Some(basis.to_i32()),
        quadrature_order: Some(*quadrature_order),
        subdivision: Some(*subdivision),
        boundary_refinement: Some(*boundary_refinement),
        mass: Some(mass.to_i32()),
        penalty: Some(*penalty),
        modes: Some(*modes),
        eigen_tolerance: Some(*eigen_tolerance),
        warping: Some(*warping),
        mass_damping: Some(*mass_damping),
        stiffness_damping: Some(*stiffness_damping),
        grab_eta: Some(*grab_eta),
        grab_gamma: Some(*grab_gamma),
        anchors: anchors.iter().map(to_aabb).collect(),
        grabs: grabs.iter().map(to_grab).collect(),
        playback: playback.map(|p| v1::Playback {
            mode: p.mode,
            amplitude: p.amplitude,
        }),
        surface_subdivisions: Some(*surface_subdivisions),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{scene_from_proto, scene_to_proto};
    use meshless_engine::Scene;
    use meshless_engine::scene::SystemSpec;

    fn shipped() -> Scene {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/modal_beam.toml");
        Scene::from_toml_file(std::path::Path::new(path)).expect("the shipped scene parses")
    }

    #[test]
    fn modal_solids_round_trip_through_the_protocol() {
        let mut scene = shipped();
        let SystemSpec::ModalSolid(spec) = &mut scene.systems[0] else {
            panic!("a modal solid");
        };
        spec.mass = MassForm::Lumped;
        spec.dynamics = Dynamics::Nonlinear;
        spec.basis = Order::Quadratic;
        spec.warping = false;
        spec.grabs.push(GrabSpec {
            point: [0.27, 0.0, 0.0],
            position: Some([0.26, 0.05, 0.0]),
            rotation: None,
        });
        spec.playback = Some(PlaybackSpec {
            mode: 3,
            amplitude: 0.5,
        });
        let back = scene_from_proto(scene_to_proto(&scene)).expect("converts back");
        assert_eq!(back, scene);
    }

    #[test]
    fn unset_modal_fields_take_the_scene_file_defaults() {
        let spec = v1::ModalSolidSpec {
            shape: Some(to_shape(&meshless_engine::scene::ShapeSpec::Sphere {
                radius: 0.1,
            })),
            position: Some(to_vec3([0.0; 3])),
            young: 1e6,
            cell: 0.02,
            ..Default::default()
        };
        let from_wire = modal_from_proto(spec, "systems[0]").expect("converts");
        let scene = Scene::from_toml_str(
            "[domain]\nmin = [-1.0, -1.0, -1.0]\nmax = [1.0, 1.0, 1.0]\n[time]\ndt = 0.01\n\
             [[systems]]\nkind = \"modal_solid\"\n\
             shape = { type = \"sphere\", radius = 0.1 }\nposition = [0.0, 0.0, 0.0]\n\
             young = 1e6\ncell = 0.02",
        )
        .expect("parses");
        let SystemSpec::ModalSolid(from_toml) = &scene.systems[0] else {
            panic!("a modal solid");
        };
        assert_eq!(&from_wire, from_toml);
        let missing = modal_from_proto(
            v1::ModalSolidSpec {
                position: None,
                ..v1::ModalSolidSpec::default()
            },
            "systems[1]",
        )
        .expect_err("no shape");
        assert!(
            missing.to_string().starts_with("systems[1].shape"),
            "{missing}"
        );
        let bad = modal_from_proto(
            v1::ModalSolidSpec {
                shape: Some(to_shape(&meshless_engine::scene::ShapeSpec::Sphere {
                    radius: 0.1,
                })),
                position: Some(to_vec3([0.0; 3])),
                mass: Some(7),
                ..Default::default()
            },
            "systems[0]",
        )
        .expect_err("unknown mass form");
        assert!(bad.to_string().contains("consistent or lumped"), "{bad}");
    }
}
