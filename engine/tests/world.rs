//! Whole-world behaviour of the SPH fluid: conservation, containment,
//! sub-stepping, fault containment and passes run only when named.

use meshless_engine::scene::{ParticleSpec, SolverKind, SystemSpec};
use meshless_engine::stats::Stage;
use meshless_engine::{BuildOptions, FieldKind, Scene, StepError, World};

/// A coarse dam break: 720 particles, cheap enough to run many steps.
fn dam_break() -> Scene {
    let mut scene = Scene::from_toml_str(include_str!("../../scenes/dam_break.toml"))
        .expect("the shipped scene parses");
    let SystemSpec::Fluid(fluid) = &mut scene.systems[0] else {
        panic!("the first system is the fluid")
    };
    fluid.spacing = 0.04;
    fluid.support_radius = Some(0.08);
    scene
}

fn build(scene: &Scene) -> World {
    scene.build(&BuildOptions::default()).expect("valid scene")
}

fn total_mass(world: &World) -> f64 {
    let fluid = world.fluid().expect("fluid");
    fluid.params.mass * fluid.len() as f64
}

/// The shipped dam break collapses without leaving the tank or producing a
/// non-finite value, and mass is conserved exactly (particles carry it).
#[test]
fn dam_break_stays_finite_inside_the_box_and_keeps_its_mass() {
    let scene = dam_break();
    let mut world = build(&scene);
    let mass = total_mass(&world);
    let count = world.particle_count();
    assert_eq!(count, 7 * 15 * 7);
    let (min, max) = (scene.domain.min, scene.domain.max);
    for _ in 0..40 {
        world.step().expect("stable step");
    }
    assert!((world.clock().time - 0.4).abs() < 1e-9);
    assert_eq!(world.particle_count(), count);
    assert_eq!(total_mass(&world), mass);
    let fluid = world.fluid().expect("fluid");
    for (i, x) in fluid.positions.iter().enumerate() {
        for a in 0..3 {
            assert!(
                x[a].is_finite() && x[a] >= min[a] && x[a] <= max[a],
                "particle {i} at {x:?} left the box at step {}",
                world.clock().step
            );
        }
    }
    // The column collapsed: the front moved well away from x = 0.3.
    let front = fluid.positions.iter().map(|x| x.x).fold(0.0, f64::max);
    assert!(front > 0.6, "surge front only at x = {front}");
}

/// A step longer than the CFL limit is split into sub-steps, and the frame
/// reports how.
#[test]
fn long_steps_are_substepped_and_reported() {
    let mut scene = dam_break();
    scene.time.dt = 0.05;
    let mut world = build(&scene);
    let info = world.step().expect("stable step");
    assert!(info.substeps > 1, "{info:?}");
    assert!(!info.capped);
    let frame = world.frame();
    assert_eq!(frame.substeps, info.substeps);
    assert!(frame.substep_dt <= 0.05 / info.substeps as f64 + 1e-15);
}

/// A very stiff fluid with one sub-step per step blows up. The step
/// reports which quantity went non-finite, and the world keeps its last
/// good state: no NaN ever reaches a frame.
#[test]
fn a_blow_up_is_reported_and_the_last_good_state_kept() {
    let mut scene = dam_break();
    let SystemSpec::Fluid(fluid) = &mut scene.systems[0] else {
        panic!("the first system is the fluid")
    };
    fluid.stiffness = 1e12;
    scene.time.max_substeps = 1;
    let mut world = build(&scene);
    let mut failure = None;
    for _ in 0..50 {
        let before = world.frame();
        match world.step() {
            Ok(info) => assert!(info.capped),
            Err(e) => {
                failure = Some(e);
                assert_eq!(world.frame(), before, "a failed step changed the world");
                break;
            }
        }
    }
    let Some(StepError::Unstable { step, .. }) = failure else {
        panic!("expected a blow-up within 50 steps");
    };
    assert_eq!(step, world.clock().step + 1);
    let frame = world.frame();
    for field in &frame.fields {
        assert!(
            field.values.iter().all(|v| v.is_finite()),
            "{:?}",
            field.kind
        );
    }
}

/// "A scene pays only for what it names": with xsph = 0 no XSPH pass runs.
#[test]
fn passes_run_only_when_the_scene_names_them() {
    let mut scene = dam_break();
    let mut world = build(&scene);
    world.step().expect("step");
    assert!(world.stages().get(Stage::Xsph).runs > 0);

    let SystemSpec::Fluid(fluid) = &mut scene.systems[0] else {
        panic!("the first system is the fluid")
    };
    fluid.xsph = 0.0;
    let mut world = build(&scene);
    world.step().expect("step");
    assert_eq!(world.stages().get(Stage::Xsph).runs, 0);
    assert!(world.stages().get(Stage::PressureForce).runs > 0);
}

/// Frames carry positions plus exactly the requested fields.
#[test]
fn frames_carry_the_requested_fields() {
    let mut scene = dam_break();
    scene.output.fields = vec![FieldKind::Pressure];
    let world = build(&scene);
    let frame = world.frame();
    let kinds: Vec<_> = frame.fields.iter().map(|f| f.kind).collect();
    assert_eq!(kinds, vec![FieldKind::Position, FieldKind::Pressure]);
    assert_eq!(frame.fields[0].values.len(), 3 * frame.particle_count);
    assert_eq!(frame.fields[1].values.len(), frame.particle_count);
}

/// Stepping is deterministic: two worlds from one scene agree bit for bit.
#[test]
fn stepping_is_deterministic() {
    let scene = dam_break();
    let (mut a, mut b) = (build(&scene), build(&scene));
    for _ in 0..5 {
        a.step().expect("step");
        b.step().expect("step");
    }
    assert_eq!(a.frame(), b.frame());
}

/// XSPH smooths velocity differences only: a fluid moving uniformly (no
/// gravity, no walls in reach) keeps its velocity exactly, although its
/// free surface cuts every outer neighbourhood. The tutorial's Eq. 53 as
/// printed would brake it there.
#[test]
fn xsph_leaves_uniform_motion_alone() {
    let mut scene = dam_break();
    scene.gravity = [0.0; 3];
    scene.domain.max = [4.0, 4.0, 4.0];
    let SystemSpec::Fluid(fluid) = &mut scene.systems[0] else {
        panic!("the first system is the fluid")
    };
    fluid.blocks[0].region.min = [1.0, 1.0, 1.0];
    fluid.blocks[0].region.max = [1.4, 1.4, 1.4];
    fluid.blocks[0].velocity = [0.5, -0.25, 0.1];
    fluid.xsph = 0.5;
    let mut world = build(&scene);
    for _ in 0..3 {
        world.step().expect("step");
    }
    assert!(world.stages().get(Stage::Xsph).runs > 0);
    for (i, v) in world.fluid().expect("fluid").velocities.iter().enumerate() {
        let error = (v - nalgebra::Vector3::new(0.5, -0.25, 0.1)).norm();
        assert!(error < 1e-9, "particle {i} changed velocity by {error}");
    }
}

/// Laplacian viscosity (Eq. 52) runs only when named, conserves momentum
/// (its pair terms are antisymmetric) and slows a shear layer.
#[test]
fn viscosity_conserves_momentum_and_damps_shear() {
    let mut scene = dam_break();
    scene.gravity = [0.0; 3];
    scene.domain.max = [4.0, 4.0, 4.0];
    let SystemSpec::Fluid(fluid) = &mut scene.systems[0] else {
        panic!("the first system is the fluid")
    };
    let lower = fluid.blocks[0].clone();
    fluid.blocks = vec![lower.clone(), lower];
    fluid.blocks[0].region.min = [1.0, 1.0, 1.0];
    fluid.blocks[0].region.max = [1.4, 1.2, 1.4];
    fluid.blocks[0].velocity = [0.2, 0.0, 0.0];
    fluid.blocks[1].region.min = [1.0, 1.2, 1.0];
    fluid.blocks[1].region.max = [1.4, 1.4, 1.4];
    fluid.blocks[1].velocity = [-0.2, 0.0, 0.0];
    fluid.xsph = 0.0;

    let shear = |world: &World| {
        let f = world.fluid().expect("fluid");
        let (mut lower, mut upper) = (0.0, 0.0);
        for (x, v) in f.positions.iter().zip(&f.velocities) {
            if x.y < 1.2 {
                lower += v.x
            } else {
                upper += v.x
            }
        }
        (lower - upper) / f.len() as f64
    };
    let momentum = |world: &World| {
        let f = world.fluid().expect("fluid");
        f.velocities.iter().sum::<nalgebra::Vector3<f64>>() * f.params.mass
    };

    let mut inviscid = build(&scene);
    inviscid.step().expect("step");
    assert_eq!(inviscid.stages().get(Stage::Viscosity).runs, 0);

    let SystemSpec::Fluid(fluid) = &mut scene.systems[0] else {
        panic!("the first system is the fluid")
    };
    fluid.viscosity = 20.0;
    let mut viscous = build(&scene);
    let (p0, s0) = (momentum(&viscous), shear(&viscous));
    for _ in 0..5 {
        viscous.step().expect("step");
        inviscid.step().expect("step");
    }
    assert!(viscous.stages().get(Stage::Viscosity).runs > 0);
    let scale = viscous.fluid().expect("fluid").params.mass * viscous.particle_count() as f64 * 0.2;
    assert!(
        (momentum(&viscous) - p0).norm() < 1e-9 * scale,
        "viscosity changed momentum"
    );
    assert!(
        shear(&viscous) < 0.95 * s0,
        "shear {} from {s0}",
        shear(&viscous)
    );
    assert!(shear(&viscous) < shear(&inviscid));
}

/// Whether `e` is one of the faults of a finite state that went wrong
/// (engine/src/world/watch.rs) or of one that left its valid range.
fn is_fault(e: &StepError) -> bool {
    matches!(
        e,
        StepError::Unstable { .. } | StepError::Compressed { .. } | StepError::EnergyGained { .. }
    )
}

/// Stability at the extremes: stiffness over five decades, a step 100x the
/// stable one, a lone particle. Each either runs (sub-stepped, every value
/// finite and inside the box) or stops with a step error; none produces
/// NaN; a fluid too soft or too stiff for its sub-steps may instead fault
/// with the reason (compressed, or gaining energy: see `faults.rs`).
#[test]
fn extremes_run_or_fail_cleanly() {
    let check = |world: &World| {
        let fluid = world.fluid().expect("fluid");
        let (min, max) = (world.scene().domain.min, world.scene().domain.max);
        for x in &fluid.positions {
            for a in 0..3 {
                assert!(
                    x[a].is_finite() && x[a] >= min[a] && x[a] <= max[a],
                    "{x:?}"
                );
            }
        }
    };
    for stiffness in [1e2, 1e4, 1e5, 1e7] {
        let mut scene = dam_break();
        let SystemSpec::Fluid(fluid) = &mut scene.systems[0] else {
            panic!("the first system is the fluid")
        };
        fluid.stiffness = stiffness;
        let mut world = build(&scene);
        let mut fault = None;
        for _ in 0..5 {
            match world.step() {
                Ok(info) => assert!(!info.capped, "K = {stiffness}: {info:?}"),
                Err(e) => {
                    fault = Some(e);
                    break;
                }
            }
        }
        if let Some(e) = fault {
            assert!(
                matches!(
                    e,
                    StepError::Compressed { .. } | StepError::EnergyGained { .. }
                ),
                "K = {stiffness}: {e}"
            );
        }
        check(&world);
    }

    // 100x the stable step: sub-stepped up to the cap.
    let mut scene = dam_break();
    scene.time.dt = 1.0;
    let mut world = build(&scene);
    match world.step() {
        Ok(info) => {
            assert_eq!(info.substeps, scene.time.max_substeps);
            check(&world);
        }
        Err(e) => assert!(is_fault(&e), "{e}"),
    }

    // One particle: it falls and bounces off the floor, forever finite.
    let mut scene = dam_break();
    let SystemSpec::Fluid(fluid) = &mut scene.systems[0] else {
        panic!("the first system is the fluid")
    };
    fluid.blocks[0].region.max = [0.04, 0.5, 0.04];
    fluid.blocks[0].region.min = [0.0, 0.46, 0.0];
    let mut world = build(&scene);
    assert_eq!(world.particle_count(), 1);
    for _ in 0..100 {
        world.step().expect("a lone particle is stable");
    }
    check(&world);

    // Particles at one position, in the air and inside the column, with
    // both solvers: the kernel gradient of a coincident pair is zero (no
    // direction to push along), so nothing divides by their distance.
    // Each pair feels identical forces and moves as one particle of twice
    // the mass: finite, inside the box, and still together.
    for solver in [SolverKind::Wcsph, SolverKind::Dfsph] {
        let mut scene = dam_break();
        let SystemSpec::Fluid(fluid) = &mut scene.systems[0] else {
            panic!("the first system is the fluid")
        };
        fluid.solver = solver;
        for position in [
            [0.6, 0.7, 0.15],
            [0.6, 0.7, 0.15],
            [0.1, 0.1, 0.1],
            [0.1, 0.1, 0.1],
        ] {
            fluid.particles.push(ParticleSpec {
                position,
                velocity: [0.0; 3],
            });
        }
        let mut world = build(&scene);
        for _ in 0..20 {
            world.step().expect("coincident particles are stable");
        }
        check(&world);
        let fluid = world.fluid().expect("fluid");
        let n = fluid.len();
        let at = |id| fluid.position_of(id).expect("particle id");
        assert_eq!(at(n - 1), at(n - 2), "{solver:?}");
        assert_eq!(at(n - 3), at(n - 4), "{solver:?}");
    }
}

/// DFSPH: a block of fluid at rest in a tank (the dam-break column with a
/// dam: all of it, no gravity) stays at rest, and each step holds the
/// density error under the tolerance within few iterations.
#[test]
fn dfsph_keeps_a_resting_fluid_at_rest() {
    let mut scene = dam_break();
    scene.gravity = [0.0; 3];
    let SystemSpec::Fluid(fluid) = &mut scene.systems[0] else {
        panic!("the first system is the fluid")
    };
    fluid.solver = meshless_engine::scene::SolverKind::Dfsph;
    fluid.density_kernel = meshless_engine::approx::KernelKind::CubicSpline;
    fluid.gradient_kernel = meshless_engine::approx::KernelKind::CubicSpline;
    let mut world = build(&scene);
    for _ in 0..20 {
        let info = world.step().expect("stable");
        assert!(info.density_error <= 0.001, "{info:?}");
    }
    assert!(world.stages().get(Stage::PressureSolve).runs > 0);
    assert_eq!(
        world.stages().get(Stage::PressureForce).runs,
        0,
        "no WCSPH pass"
    );
    let fluid = world.fluid().expect("fluid");
    let fastest = fluid
        .velocities
        .iter()
        .map(|v| v.norm())
        .fold(0.0, f64::max);
    assert!(fastest < 1e-3, "a resting fluid moved at {fastest} m/s");
}

/// 2D scenes: particles live in the plane z = 0 and stay there, with the
/// 2D kernel normalisation giving the lattice the rest density.
#[test]
fn two_dimensional_scenes_stay_in_their_plane() {
    let scene = Scene::from_toml_str(include_str!("../../scenes/dam_break_2d.toml"))
        .expect("the shipped 2D scene parses");
    let mut world = build(&scene);
    assert_eq!(world.particle_count(), 15 * 30);
    let mut densities = world.fluid().expect("fluid").densities.clone();
    densities.sort_by(f64::total_cmp);
    let median = densities[densities.len() / 2];
    assert!(
        (median - 1000.0).abs() < 5.0,
        "median lattice density {median}"
    );
    for _ in 0..20 {
        world.step().expect("stable");
    }
    let fluid = world.fluid().expect("fluid");
    assert!(fluid.positions.iter().all(|x| x.z == 0.0));
    assert!(fluid.velocities.iter().all(|v| v.z == 0.0));

    let mut bad = scene.clone();
    bad.dimension = 4;
    let err = bad.validate(&BuildOptions::default()).expect_err("4D");
    assert!(err.to_string().starts_with("dimension:"), "{err}");
}

/// The fluid keeps its particles in Z order, re-sorted as they move;
/// frames must still list them by id, the scene's order: a particle's
/// entry in every frame is that particle, wherever its slot went.
#[test]
fn frames_list_particles_by_id_while_the_fluid_reorders() {
    let mut world = build(&dam_break());
    for _ in 0..30 {
        world.step().expect("stable");
    }
    let fluid = world.fluid().expect("fluid");
    let ids = fluid.ids();
    assert!(
        ids.iter()
            .enumerate()
            .any(|(slot, &id)| slot != id as usize),
        "the sort moved particles"
    );
    let frame = world.frame();
    let positions = &frame.field(FieldKind::Position).expect("positions").values;
    for id in [0, 1, fluid.len() / 2, fluid.len() - 1] {
        let x = fluid.position_of(id).expect("id");
        for a in 0..3 {
            assert_eq!(positions[3 * id + a], x[a] as f32, "particle {id}");
        }
    }
}

/// The viscous pair forces conserve angular momentum exactly with
/// Monaghan's form, whose forces lie along the pairs, and not with
/// Morris's: a free 2D block with a sheared, swirling velocity field, far
/// from every wall, no gravity, one step.
#[test]
fn monaghan_viscosity_conserves_angular_momentum_to_round_off() {
    let change = |model: &str| {
        let text = format!(
            r#"
dimension = 2
gravity = [0.0, 0.0, 0.0]
[domain]
min = [0.0, 0.0, 0.0]
max = [2.0, 2.0, 0.0]
[time]
dt = 0.001
[[systems]]
kind = "fluid"
spacing = 0.02
stiffness = 1e4
viscosity = 5.0
viscosity_model = "{model}"
velocity_field = ["sin(9*y) + 0.3*x", "cos(7*x)*y", "0"]
[[systems.blocks]]
region = {{ min = [0.8, 0.8, 0.0], max = [1.2, 1.2, 0.0] }}
"#
        );
        let mut world = build(&Scene::from_toml_str(&text).expect("parses"));
        let moment = |w: &World| {
            let f = w.fluid().expect("fluid");
            f.positions
                .iter()
                .zip(&f.velocities)
                .map(|(x, v)| x.x * v.y - x.y * v.x)
                .sum::<f64>()
        };
        let scale = {
            let f = world.fluid().expect("fluid");
            f.positions
                .iter()
                .zip(&f.velocities)
                .map(|(x, v)| x.norm() * v.norm())
                .sum::<f64>()
        };
        let before = moment(&world);
        world.step().expect("stable");
        (moment(&world) - before).abs() / scale
    };
    let (monaghan, morris) = (change("monaghan"), change("morris"));
    println!(
        "relative change of angular momentum in one step: monaghan {monaghan:.1e}, morris {morris:.1e}"
    );
    assert!(monaghan < 1e-12, "{monaghan}");
    assert!(morris > 1e-7 && morris > 1e6 * monaghan, "{morris}");
}

/// Every system kind counts its own stages, and a scene counts only those
/// of the kinds it names: an explicit solid its forces, integration and
/// contact; an implicit one its Newton solve too; a modal solid its modal
/// solve; the fluid none of theirs.
#[test]
fn each_kind_counts_its_own_stages() {
    let solid_stages = [
        Stage::SolidForces,
        Stage::SolidSolve,
        Stage::SolidIntegrate,
        Stage::SolidContact,
    ];
    let fluid_stages = [Stage::NeighborSearch, Stage::Density, Stage::Integrate];
    let runs = |world: &World, stages: &[Stage]| -> Vec<u64> {
        stages.iter().map(|&s| world.stages().get(s).runs).collect()
    };

    let mut fluid = build(&dam_break());
    fluid.step().expect("step");
    assert_eq!(runs(&fluid, &solid_stages), [0; 4]);
    assert_eq!(runs(&fluid, &[Stage::ModalSolve]), [0]);

    let mut jelly = Scene::from_toml_str(include_str!("../../scenes/jelly_drop.toml"))
        .expect("the shipped scene parses");
    let mut explicit = build(&jelly);
    explicit.step().expect("step");
    let counted = runs(&explicit, &solid_stages);
    assert!(
        counted[0] > 0 && counted[2] == counted[0] && counted[3] == counted[0],
        "one forces, integration and contact pass per sub-step: {counted:?}"
    );
    assert_eq!(counted[1], 0, "an explicit solid solves nothing");
    assert_eq!(runs(&explicit, &fluid_stages), [0; 3]);
    let SystemSpec::Solid(solid) = &mut jelly.systems[0] else {
        panic!("the jelly is a solid")
    };
    solid.integrator = meshless_engine::scene::IntegratorKind::Implicit;
    let mut implicit = build(&jelly);
    implicit.step().expect("step");
    let counted = runs(&implicit, &solid_stages);
    assert_eq!(counted, [0, 1, 1, 1], "one Newton solve per implicit step");
    let seconds = world_seconds(&implicit, Stage::SolidSolve);
    assert!(seconds > 0.0, "{seconds}");

    let modal = Scene::from_toml_str(include_str!("../../tests/fixtures/small_modal.toml"))
        .expect("the fixture parses");
    let mut modal = build(&modal);
    for _ in 0..3 {
        modal.step().expect("step");
    }
    assert_eq!(runs(&modal, &[Stage::ModalSolve]), [3]);
    assert_eq!(runs(&modal, &solid_stages), [0; 4]);
}

fn world_seconds(world: &World, stage: Stage) -> f64 {
    world.stages().get(stage).seconds
}
