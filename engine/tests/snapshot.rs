//! Snapshots of a world's state: restored into a world built from the
//! same scene, the state steps on bit for bit as the world it was taken
//! from did (fluids with rigid bodies and pending removals, explicit and
//! implicit solids, a plastic solid whose reference shape re-based); a
//! state that does not fit is refused with an error naming what, and
//! never panics.

use meshless_engine::fluid::FluidSnapshot;
use meshless_engine::{BuildOptions, Scene, StateError, SystemState, World, WorldState};

fn scene(toml: &str) -> Scene {
    Scene::from_toml_str(toml).expect("the scene parses")
}

fn build(scene: &Scene) -> World {
    scene
        .build(&BuildOptions::default())
        .expect("a valid scene")
}

/// Every number a frame carries, as bits: fields, poses, surfaces, clock.
fn frame_bits(world: &World) -> Vec<u64> {
    let frame = world.frame();
    let mut bits = vec![
        frame.step,
        frame.time.to_bits(),
        u64::from(frame.substeps),
        u64::from(frame.solver_iterations),
        frame.density_error.to_bits(),
    ];
    for field in &frame.fields {
        bits.extend(field.values.iter().map(|v| u64::from(v.to_bits())));
    }
    for pose in &frame.bodies {
        for part in [
            &pose.position[..],
            &pose.orientation,
            &pose.velocity,
            &pose.angular_velocity,
        ] {
            bits.extend(part.iter().map(|v| v.to_bits()));
        }
    }
    bits
}

/// Steps `world` `before` steps, snapshots it, restores the snapshot into
/// a fresh build of `scene`, then steps both `after` more steps and
/// checks each frame on the way is the same, bit for bit.
fn continues_bit_for_bit(scene: &Scene, mut world: World, before: u64, after: u64) -> WorldState {
    for _ in 0..before {
        world.step().expect("a stable step");
    }
    let state = world.state();
    let mut restored = build(scene).restored(&state).expect("the state fits");
    assert_eq!(restored.clock(), world.clock());
    assert_eq!(restored.state(), state, "restoring keeps every value");
    for k in 0..after {
        world.step().expect("a stable step");
        restored.step().expect("a stable step");
        assert_eq!(
            frame_bits(&restored),
            frame_bits(&world),
            "step {} after the snapshot differs",
            k + 1
        );
        assert_eq!(restored.state(), world.state(), "step {}", k + 1);
    }
    state
}

/// A 2D DFSPH tank with a floating box, a paddle swinging and viscosity:
/// the pressure solver's warm start, the body states and the Z-order of
/// the particles all carry over.
const FLUID_WITH_BODIES: &str = r#"
dimension = 2
[domain]
min = [0.0, 0.0, 0.0]
max = [0.8, 0.6, 0.0]
[time]
dt = 0.004
[output]
fields = ["velocity", "density", "pressure"]
[[systems]]
kind = "fluid"
solver = "dfsph"
spacing = 0.02
xsph = 0.1
viscosity = 1e-3
[[systems.blocks]]
region = { min = [0.0, 0.0, 0.0], max = [0.8, 0.3, 0.0] }
[[systems]]
kind = "rigid_body"
shape = { type = "box", half_extents = [0.06, 0.06, 0.06] }
position = [0.5, 0.4, 0.0]
orientation = [0.0, 0.0, 0.3]
motion = "dynamic"
density = 500.0
[[systems]]
kind = "rigid_body"
shape = { type = "box", half_extents = [0.02, 0.2, 0.15] }
position = [0.1, 0.2, 0.0]
motion = "kinematic"
oscillation = { amplitude = [0.04, 0.0, 0.0], frequency = 1.0 }
"#;

#[test]
fn a_fluid_with_rigid_bodies_continues_bit_for_bit() {
    let scene = scene(FLUID_WITH_BODIES);
    // Past the first re-sort of the particles, so the slots are not in
    // id order.
    let state = continues_bit_for_bit(&scene, build(&scene), 30, 12);
    let SystemState::Fluid { fluid, .. } = &state.systems[0] else {
        panic!("the fluid comes first")
    };
    assert!(!fluid.warm_start.is_empty(), "DFSPH keeps a warm start");
    assert_eq!(fluid.bodies.len(), 2);
    assert!(
        fluid.ids.windows(2).any(|w| w[0] > w[1]),
        "the particles were re-sorted before the snapshot"
    );
}

/// A WCSPH tank: particles removed before the snapshot stay removed, and
/// those marked for removal at the next step leave after the restore.
#[test]
fn removals_done_and_pending_carry_over() {
    let scene = scene(
        r#"
        dimension = 2
        [domain]
        min = [0.0, 0.0, 0.0]
        max = [1.0, 1.0, 0.0]
        [time]
        dt = 0.002
        [[systems]]
        kind = "fluid"
        spacing = 0.025
        stiffness = 1e4
        [[systems.blocks]]
        region = { min = [0.0, 0.0, 0.0], max = [0.5, 0.5, 0.0] }
        "#,
    );
    let mut world = build(&scene);
    let built = world.particle_count();
    world.remove_particles(0, &[0, 5, 17]).expect("ids exist");
    for _ in 0..4 {
        world.step().expect("stable");
    }
    world.remove_particles(0, &[3, 4]).expect("ids exist");
    let state = continues_bit_for_bit(&scene, world, 0, 6);
    let SystemState::Fluid {
        fluid, removals, ..
    } = &state.systems[0]
    else {
        panic!("the fluid comes first")
    };
    assert_eq!(fluid.ids.len(), built - 3);
    assert_eq!(removals, &[3, 4]);
    // Ids are stable: the snapshot keeps the gaps and the ids given.
    assert_eq!(fluid.next_id as usize, built);
    assert!(fluid.ids.iter().all(|id| ![0, 5, 17].contains(id)));
}

/// A 2D solid beam, clamped at one end, with the given extra settings.
fn beam(settings: &str) -> Scene {
    scene(&format!(
        r#"
        dimension = 2
        [domain]
        min = [-0.2, -0.5, 0.0]
        max = [1.2, 0.5, 0.0]
        [time]
        dt = 0.002
        [output]
        fields = ["velocity", "density", "pressure", "elastic_energy"]
        [[systems]]
        kind = "solid"
        shape = {{ type = "box", half_extents = [0.3, 0.04, 0.05] }}
        position = [0.3, 0.0, 0.0]
        spacing = 0.02
        density = 1000.0
        young = 2e5
        poisson = 0.3
        anchors = [{{ min = [-0.06, -0.06, 0.0], max = [0.05, 0.06, 0.0] }}]
        {settings}
        "#
    ))
}

#[test]
fn an_explicit_solid_continues_bit_for_bit() {
    let scene = beam("");
    continues_bit_for_bit(&scene, build(&scene), 20, 10);
}

#[test]
fn an_implicit_solid_continues_bit_for_bit() {
    let scene = beam(
        r#"integrator = "implicit"
        implicit = { linear_solver = "conjugate_gradient", scheme = "midpoint" }"#,
    );
    continues_bit_for_bit(&scene, build(&scene), 8, 6);
}

/// A soft plastic beam sagging under gravity: its strains pass the
/// re-base limit, so the reference shape it continues from is not the
/// one it was built with.
#[test]
fn a_plastic_solid_continues_from_its_rebased_shape() {
    let scene = beam(
        r#"integrator = "implicit"
        plasticity = { yield = 0.001, creep = 0.5, max = 1.0, rebase = 0.002 }"#,
    );
    let built = build(&scene);
    let state = continues_bit_for_bit(&scene, built.clone(), 30, 8);
    let SystemState::Solid { solid, .. } = &state.systems[0] else {
        panic!("the solid")
    };
    let (rest, _) = solid
        .reference
        .as_ref()
        .expect("a re-basing solid keeps its shape");
    let SystemState::Solid { solid: first, .. } = &built.state().systems[0] else {
        panic!("the solid")
    };
    let (built_rest, _) = first.reference.as_ref().expect("kept");
    assert_ne!(rest, built_rest, "the beam re-based before the snapshot");
    assert!(solid.plastic.is_some());
}

/// The fluid state of `state`, to corrupt.
fn fluid_of(state: &mut WorldState) -> &mut FluidSnapshot {
    match &mut state.systems[0] {
        SystemState::Fluid { fluid, .. } => fluid,
        SystemState::Solid { .. } | SystemState::Modal { .. } | SystemState::Shell { .. } => {
            panic!("the fluid comes first")
        }
    }
}

/// A change to a good state, and what the refusal must say.
type Corruption<'a> = (&'a dyn Fn(&mut WorldState), &'a str);

/// Each corruption of a good state is refused with the error that names
/// it; the corrupted state never panics the restore.
#[test]
fn states_that_do_not_fit_are_refused() {
    let scene = scene(FLUID_WITH_BODIES);
    let mut world = build(&scene);
    world.step().expect("stable");
    let good = world.state();
    let refused = |change: &dyn Fn(&mut WorldState)| -> String {
        let mut state = good.clone();
        change(&mut state);
        build(&scene)
            .restored(&state)
            .expect_err("refused")
            .to_string()
    };
    let cases: [Corruption; 8] = [
        (&|s| fluid_of(s).ids[0] = fluid_of(s).ids[1], "permutation"),
        (
            &|s| fluid_of(s).velocities[3].x = f64::NAN,
            "velocities of entry 3",
        ),
        (
            &|s| {
                fluid_of(s).positions.pop();
            },
            "positions holds",
        ),
        (&|s| fluid_of(s).densities[0] = 0.0, "densities of entry 0"),
        (
            &|s| {
                fluid_of(s).bodies[1].orientation =
                    nalgebra::Unit::new_unchecked(nalgebra::Quaternion::new(2.0, 0.0, 0.0, 0.0))
            },
            "rigid body state of entry 1",
        ),
        (
            &|s| {
                fluid_of(s).bodies.pop();
            },
            "bodies holds 1",
        ),
        (&|s| s.clock.time = f64::INFINITY, "time is not finite"),
        (
            &|s| {
                s.systems.clear();
            },
            "other scene",
        ),
    ];
    for (change, expected) in cases {
        let message = refused(change);
        assert!(
            message.contains(expected)
                || (expected == "other scene" && message.contains("taken in another scene")),
            "{message}"
        );
    }
    // More particles than the scene builds.
    let mut state = good.clone();
    let fluid = fluid_of(&mut state);
    let n = fluid.ids.len() as u32;
    fluid.ids.push(n);
    let message = build(&scene)
        .restored(&state)
        .expect_err("refused")
        .to_string();
    assert!(message.contains("at most"), "{message}");
    // A solid's state into a fluid's world.
    let beam = beam("");
    let solid_state = build(&beam).state();
    let err = build(&scene).restored(&solid_state).expect_err("refused");
    assert!(matches!(err, StateError::Systems { .. }), "{err}");
}
