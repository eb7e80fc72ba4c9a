//! Conversions of the shell messages (`ShellSpec`, `ShellIntegrator` and
//! `ShellMechanics` in `scene.proto`), both directions. Unset optional fields take the
//! scene file's defaults ([`meshless_engine::scene::shell_defaults`]).

use super::geometry::{aabb, shape_from_proto, to_aabb, to_shape, to_vec3, vec3};
use crate::enums::{WireEnum, optional_enum, wire_enum};
use crate::error::{Result, required};
use meshless_engine::approx::mls::Order;
use meshless_engine::scene::{ShellSpec, shell_defaults as defaults};
use meshless_engine::shell::{Integrator, Mechanics};
use meshless_proto::v1;

wire_enum! {
    /// How a shell relates velocity and acceleration to displacement.
    Integrator <-> ShellIntegrator, "shell integrator" {
        "backward_euler" => BackwardEuler,
        "newmark" => Newmark,
    }
}

wire_enum! {
    /// How a shell's internal forces follow its displacement.
    Mechanics <-> ShellMechanics, "shell mechanics" {
        "nonlinear" => Nonlinear,
        "linear" => Linear,
    }
}

/// The engine spec of a `ShellSpec` at `field`.
pub(super) fn shell_from_proto(spec: v1::ShellSpec, field: &str) -> Result<ShellSpec> {
    let v1::ShellSpec {
        shape,
        position,
        orientation,
        thickness,
        density,
        young,
        poisson,
        resolution,
        eta,
        basis,
        quadrature_order,
        subdivision,
        integrator,
        mass_damping,
        stiffness_damping,
        penalty,
        tolerance,
        max_iterations,
        pressure,
        clamped,
        pinned,
        surface_cells,
        mechanics,
    } = spec;
    let boxes = |list: Vec<v1::Aabb>, name: &str| {
        list.into_iter()
            .enumerate()
            .map(|(k, b)| aabb(Some(b), &format!("{field}.{name}[{k}]")))
            .collect::<Result<Vec<_>>>()
    };
    Ok(ShellSpec {
        shape: shape_from_proto(shape, &format!("{field}.shape"))?,
        position: vec3(required(position, &format!("{field}.position"))?),
        orientation: orientation.map_or([0.0; 3], vec3),
        thickness,
        density: density.unwrap_or(defaults::DENSITY),
        young,
        poisson: poisson.unwrap_or(defaults::POISSON),
        resolution,
        eta: eta.unwrap_or(defaults::ETA),
        basis: optional_enum(basis, Order::Quadratic, &format!("{field}.basis"))?,
        quadrature_order: quadrature_order.unwrap_or(defaults::QUADRATURE_ORDER),
        subdivision: subdivision.unwrap_or(defaults::SUBDIVISION),
        integrator: optional_enum(
            integrator,
            Integrator::BackwardEuler,
            &format!("{field}.integrator"),
        )?,
        mass_damping: mass_damping.unwrap_or(0.0),
        stiffness_damping: stiffness_damping.unwrap_or(0.0),
        penalty: penalty.unwrap_or(defaults::PENALTY),
        tolerance: tolerance.unwrap_or(defaults::TOLERANCE),
        max_iterations: max_iterations.unwrap_or(defaults::MAX_ITERATIONS),
        pressure: pressure.unwrap_or(0.0),
        clamped: boxes(clamped, "clamped")?,
        pinned: boxes(pinned, "pinned")?,
        surface_cells: surface_cells.unwrap_or(defaults::SURFACE_CELLS),
        mechanics: optional_enum(
            mechanics,
            Mechanics::Nonlinear,
            &format!("{field}.mechanics"),
        )?,
    })
}

/// Destructured whole, so a new engine field fails to build here until it
/// crosses the protocol.
pub(super) fn to_shell(spec: &ShellSpec) -> v1::ShellSpec {
    let ShellSpec {
        shape,
        position,
        orientation,
        thickness,
        density,
        young,
        poisson,
        resolution,
        eta,
        basis,
        quadrature_order,
        subdivision,
        integrator,
        mass_damping,
        stiffness_damping,
        penalty,
        tolerance,
        max_iterations,
        pressure,
        clamped,
        pinned,
        surface_cells,
        mechanics,
    } = spec;
    v1::ShellSpec {
        shape: Some(to_shape(shape)),
        position: Some(to_vec3(*position)),
        orientation: Some(to_vec3(*orientation)),
        thickness: *thickness,
        density: Some(*density),
        young: *young,
        poisson: Some(*poisson),
        resolution: *resolution,
        eta: Some(*eta),
        basis: Some(basis.to_i32()),
        quadrature_order: Some(*quadrature_order),
        subdivision: Some(*subdivision),
        integrator: Some(integrator.to_i32()),
        mass_damping: Some(*mass_damping),
        stiffness_damping: Some(*stiffness_damping),
        penalty: Some(*penalty),
        tolerance: Some(*tolerance),
        max_iterations: Some(*max_iterations),
        pressure: Some(*pressure),
        clamped: clamped.iter().map(to_aabb).collect(),
        pinned: pinned.iter().map(to_aabb).collect(),
        surface_cells: Some(*surface_cells),
        mechanics: Some(mechanics.to_i32()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{scene_from_proto, scene_to_proto};
    use crate::snapshot::{world_state_from_proto, world_state_to_proto};
    use meshless_engine::scene::{Aabb, ShapeSpec, SystemSpec};
    use meshless_engine::{BuildOptions, Scene};

    fn shipped() -> Scene {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/shell_plate.toml");
        Scene::from_toml_file(std::path::Path::new(path)).expect("the shipped scene parses")
    }

    #[test]
    fn shells_round_trip_through_the_protocol() {
        let mut scene = shipped();
        let SystemSpec::Shell(spec) = &mut scene.systems[0] else {
            panic!("a shell");
        };
        spec.integrator = Integrator::BackwardEuler;
        spec.basis = Order::Linear;
        spec.pressure = -250.0;
        spec.pinned.push(Aabb {
            min: [0.9, -0.1, -0.3],
            max: [1.1, 0.1, 0.3],
        });
        let back = scene_from_proto(scene_to_proto(&scene)).expect("converts back");
        assert_eq!(back, scene);
    }

    #[test]
    fn unset_shell_fields_take_the_scene_file_defaults() {
        let spec = v1::ShellSpec {
            shape: Some(to_shape(&ShapeSpec::Box {
                half_extents: [0.5, 0.0, 0.25],
            })),
            position: Some(to_vec3([0.0; 3])),
            thickness: 0.01,
            young: 1e9,
            resolution: 0.1,
            ..Default::default()
        };
        let from_wire = shell_from_proto(spec, "systems[0]").expect("converts");
        let scene = Scene::from_toml_str(
            "[domain]\nmin = [-1.0, -1.0, -1.0]\nmax = [1.0, 1.0, 1.0]\n[time]\ndt = 0.01\n\
             [[systems]]\nkind = \"shell\"\n\
             shape = { type = \"box\", half_extents = [0.5, 0.0, 0.25] }\n\
             position = [0.0, 0.0, 0.0]\nthickness = 0.01\nyoung = 1e9\nresolution = 0.1",
        )
        .expect("parses");
        let SystemSpec::Shell(from_toml) = &scene.systems[0] else {
            panic!("a shell");
        };
        assert_eq!(&from_wire, from_toml);
        let bad = shell_from_proto(
            v1::ShellSpec {
                shape: from_wire_shape(),
                position: Some(to_vec3([0.0; 3])),
                integrator: Some(9),
                ..Default::default()
            },
            "systems[2]",
        )
        .expect_err("unknown integrator");
        assert!(
            bad.to_string().starts_with("systems[2].integrator"),
            "{bad}"
        );
        assert!(bad.to_string().contains("newmark"), "{bad}");
    }

    fn from_wire_shape() -> Option<v1::Shape> {
        Some(to_shape(&ShapeSpec::Box {
            half_extents: [0.5, 0.0, 0.25],
        }))
    }

    /// A stepped shell's state (Newmark's accelerations and its clock
    /// among it) survives the snapshot message bit for bit; a ragged
    /// array is refused naming it.
    #[test]
    fn a_shell_state_round_trips_bit_for_bit() {
        let mut world = shipped().build(&BuildOptions::default()).expect("builds");
        for _ in 0..2 {
            world.step().expect("stable");
        }
        let state = world.state();
        let message = world_state_to_proto(&state);
        let back = world_state_from_proto(message.clone()).expect("converts");
        assert_eq!(back, state);
        let mut ragged = message;
        let Some(v1::system_snapshot::Kind::Shell(shell)) = &mut ragged.systems[0].kind else {
            panic!("a shell snapshot");
        };
        shell.accelerations.pop();
        let error = world_state_from_proto(ragged).expect_err("refused");
        assert_eq!(error.field, "world.systems[0].shell.accelerations");
        assert!(world.restored(&back).is_ok());
    }
}
