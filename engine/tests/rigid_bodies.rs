//! Rigid bodies in the SPH fluid (Akinci et al. 2012 boundary samples),
//! against analytic references: a fluid at rest stays at rest around a
//! fixed body and never enters it; Archimedes' principle sets how deep a
//! body floats; free slip keeps the angular momentum of a spinning fluid
//! and no slip does not; the coupling conserves momentum; a moving paddle
//! moves the fluid. All 2D, where they are cheap.

use meshless_engine::math::Vector;
use meshless_engine::rigid::RigidBody;
use meshless_engine::{BuildOptions, Scene, World};

mod common;
use common::{body, max_speed, particles_inside};

const G: f64 = 9.81;

/// A 2D scene: `domain` square of side `side`, a DFSPH fluid at `spacing`
/// filling `fluid_box`, then `rest` (more fluid keys and the body systems).
fn scene(
    side: f64,
    gravity: f64,
    spacing: f64,
    fluid_box: [f64; 4],
    fluid_keys: &str,
    bodies: &str,
) -> World {
    let [x0, y0, x1, y1] = fluid_box;
    // XSPH keeps the particle order the resting tanks settle into, as the
    // shipped floating_box scene does, unless the keys name their own.
    let xsph = if fluid_keys.contains("xsph") {
        ""
    } else {
        "xsph = 0.1"
    };
    let text = format!(
        r#"
dimension = 2
gravity = [0.0, {gravity}, 0.0]
[domain]
min = [0.0, 0.0, 0.0]
max = [{side}, {side}, 0.0]
[time]
dt = 0.01
[[systems]]
kind = "fluid"
solver = "dfsph"
spacing = {spacing}
{xsph}
{fluid_keys}
[[systems.blocks]]
region = {{ min = [{x0}, {y0}, 0.0], max = [{x1}, {y1}, 0.0] }}
{bodies}
"#
    );
    Scene::from_toml_str(&text)
        .expect("scene parses")
        .build(&BuildOptions::default())
        .expect("scene is valid")
}

/// (a) A static disc (r = 0.08 m) in a 0.6 m wide tank filled to 0.4 m
/// (spacing 0.02 m, 512 particles): the fluid settles from the lattice as
/// it does without the body, to a small fraction of the free-fall speed
/// `sqrt(g H)` = 2 m/s, and no particle is ever found inside the disc; the
/// reflection constraint never had to act (the boundary samples' pressure
/// alone kept the fluid out).
#[test]
fn a_static_body_leaves_a_resting_tank_at_rest() {
    let disc = r#"
[[systems]]
kind = "rigid_body"
shape = { type = "sphere", radius = 0.08 }
position = [0.3, 0.18, 0.0]
"#;
    let mut with = scene(0.6, -G, 0.02, [0.0, 0.0, 0.6, 0.4], "", disc);
    let mut without = scene(0.6, -G, 0.02, [0.0, 0.0, 0.6, 0.4], "", "");
    let mut speeds = Vec::new();
    for step in 1..=100 {
        with.step().expect("stable");
        without.step().expect("stable");
        assert_eq!(
            particles_inside(&with),
            0,
            "a particle entered the disc at step {step}"
        );
        if step % 20 == 0 {
            speeds.push((max_speed(&with), max_speed(&without)));
        }
    }
    let projections = with
        .fluid()
        .expect("fluid")
        .bodies()
        .expect("bodies")
        .projections();
    println!(
        "max speed every 0.2 s (with disc, without): {speeds:.4?}; constraint projections {projections}"
    );
    let (last, reference) = speeds[4];
    assert!(
        last < 0.05 * (G * 0.4f64).sqrt(),
        "the fluid still moves at {last} m/s after 1 s"
    );
    assert!(
        last < 2.0 * reference.max(0.01),
        "{last} m/s with the disc, {reference} m/s without"
    );
    assert_eq!(projections, 0, "the constraint had to put particles back");
}

/// The free surface far from the body: the mean over lattice columns
/// more than `clear` from it of the highest particle, plus half a spacing.
fn water_level(world: &World, clear: f64) -> f64 {
    let fluid = world.fluid().expect("fluid");
    let (dx, centre) = (fluid.params.spacing, body(world).state.position.x);
    let mut columns = std::collections::BTreeMap::new();
    for x in &fluid.positions {
        if (x.x - centre).abs() > clear {
            let top = columns.entry((x.x / dx) as i64).or_insert(0.0f64);
            *top = top.max(x.y);
        }
    }
    columns.values().sum::<f64>() / columns.len() as f64 + 0.5 * dx
}

/// The fraction of the body's area below `level`, by midpoint quadrature
/// on a 200 x 200 grid over its bounding square.
fn submerged_fraction(b: &RigidBody, level: f64) -> f64 {
    let reach = b.shape.bounding_radius(2);
    let (mut inside, mut below) = (0usize, 0usize);
    for i in 0..200 {
        for j in 0..200 {
            let at = |k: usize| -reach + 2.0 * reach * (k as f64 + 0.5) / 200.0;
            let p = b.state.position + Vector::new(at(i), at(j), 0.0);
            if b.excluded_distance(&p) < 0.0 {
                inside += 1;
                below += usize::from(p.y < level);
            }
        }
    }
    below as f64 / inside as f64
}

/// (b) Archimedes: a square of side 0.12 m and density 500 kg/m^3, let go
/// just above its equilibrium in a tank of water 0.3 m deep (spacing
/// 0.01 m), floats with half its area submerged (rho_body / rho_0). Its
/// bobbing is averaged over the second second. (A square of relative
/// density 0.5 is unstable upright and turns towards 45 degrees, as it
/// should; the submerged fraction does not depend on the tilt.) The
/// measured fraction, 0.45, is low by about half a spacing of floating
/// height, the resolution of the boundary layer; asserted within 0.1.
#[test]
fn a_light_box_floats_half_submerged() {
    let square = r#"
[[systems]]
kind = "rigid_body"
shape = { type = "box", half_extents = [0.06, 0.06, 0.0] }
position = [0.3, 0.31, 0.0]
motion = "dynamic"
density = 500.0
"#;
    let mut world = scene(0.6, -G, 0.01, [0.0, 0.0, 0.6, 0.3], "", square);
    let (mut sum, mut count) = (0.0, 0);
    let mut trace = Vec::new();
    for step in 1..=200 {
        world.step().expect("stable");
        assert_eq!(
            particles_inside(&world),
            0,
            "a particle entered the box at step {step}"
        );
        if step > 100 {
            let fraction = submerged_fraction(body(&world), water_level(&world, 0.15));
            sum += fraction;
            count += 1;
            if step % 10 == 0 {
                trace.push(fraction);
            }
        }
    }
    let mean = sum / count as f64;
    let b = body(&world);
    println!(
        "submerged fraction every 0.1 s over the second second: {trace:.3?}; mean {mean:.3} \
         (Archimedes: 0.5); tilt {:.2} rad",
        b.state.orientation.angle()
    );
    assert!(
        (mean - 0.5).abs() < 0.1,
        "submerged fraction {mean}, expected 0.5"
    );
}

/// A square of density 2000 kg/m^3 dropped into the tank.
const HEAVY_SQUARE: &str = r#"
[[systems]]
kind = "rigid_body"
shape = { type = "box", half_extents = [0.06, 0.06, 0.0] }
position = [0.3, 0.2, 0.0]
motion = "dynamic"
density = 2000.0
"#;

/// The loads on a body are summed in a fixed order, so its motion does not
/// depend on the thread count or on how rayon splits the work: a body
/// rocking on a film of particles would turn a different rounding into a
/// different motion. The sinking square ends bitwise the same on one and
/// on three threads.
#[test]
fn a_body_moves_the_same_on_any_number_of_threads() {
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool");
        pool.install(|| {
            let mut world = scene(0.6, -G, 0.02, [0.0, 0.0, 0.6, 0.3], "", HEAVY_SQUARE);
            for _ in 0..40 {
                world.step().expect("stable");
            }
            let state = &body(&world).state;
            (state.position, state.velocity)
        })
    };
    assert_eq!(run(1), run(3));
}

/// (b) A square of density 2000 kg/m^3 sinks (spacing 0.02 m) and comes
/// to rest on the floor of the tank: its lowest corner less than one
/// spacing above the floor (a film of one particle layer stays trapped
/// beneath it, as in any particle method) and its mean vertical speed
/// over the last 0.5 s below 2 cm/s (1.4 m/s, had it fallen freely
/// through its 0.1 m drop).
#[test]
fn a_heavy_box_sinks_to_the_floor() {
    let mut world = scene(0.6, -G, 0.02, [0.0, 0.0, 0.6, 0.3], "", HEAVY_SQUARE);
    let mut heights = Vec::new();
    for step in 1..=150 {
        world.step().expect("stable");
        if step % 25 == 0 {
            heights.push(body(&world).state.position.y);
        }
    }
    let b = body(&world);
    let corners = [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)];
    let lowest = corners
        .iter()
        .map(|&(x, y)| {
            (b.state.position + b.state.orientation * Vector::new(0.06 * x, 0.06 * y, 0.0)).y
        })
        .fold(f64::INFINITY, f64::min);
    println!(
        "centre height every 0.25 s: {heights:.4?}; lowest corner at {lowest:.4} m, velocity {:.4?} m/s",
        b.state.velocity
    );
    let sinking = (heights[3] - heights[5]) / 0.5;
    println!("mean sinking speed over the last 0.5 s: {sinking:.4} m/s");
    // Contact is resolved at the surface samples, which sit half a
    // spacing (0.01 m) inside the faces; a box tilted by theta reaches
    // `inset (cos theta + sin theta - 1)` further down at a corner, up to
    // (sqrt(2) - 1) inset = 4.1 mm.
    let tilt_allowance = (2.0f64.sqrt() - 1.0) * 0.01;
    assert!(
        (-tilt_allowance..0.02).contains(&lowest),
        "lowest corner at {lowest} m, the floor is at 0"
    );
    assert!(sinking.abs() < 0.02, "still sinking at {sinking} m/s");
}

/// Angular momentum about `centre` of the fluid, per metre of depth.
fn angular_momentum(world: &World, centre: &Vector) -> f64 {
    let fluid = world.fluid().expect("fluid");
    fluid
        .positions
        .iter()
        .zip(&fluid.velocities)
        .map(|(x, v)| (x - centre).cross(v).z * fluid.params.mass)
        .sum()
}

/// Runs 0.5 s of water spinning as a rigid body at 2 rad/s inside a static
/// circular container of radius 0.2 m (no gravity, no XSPH, no fluid
/// viscosity; spacing 0.01 m) and returns the fraction of its angular
/// momentum left.
fn spin_down(slip: &str) -> f64 {
    let container = format!(
        r#"
[[systems]]
kind = "rigid_body"
shape = {{ type = "sphere", radius = 0.2 }}
position = [0.3, 0.3, 0.0]
hollow = true
{slip}
"#
    );
    let mut world = scene(
        0.6,
        0.0,
        0.01,
        [0.0, 0.0, 0.6, 0.6],
        "xsph = 0.0",
        &container,
    );
    let centre = Vector::new(0.3, 0.3, 0.0);
    let fluid = world.fluid_mut().expect("fluid");
    for (x, v) in fluid.positions.iter().zip(fluid.velocities.iter_mut()) {
        *v = Vector::z().cross(&(x - centre)) * 2.0;
    }
    let start = angular_momentum(&world, &centre);
    let mut trace = Vec::new();
    for step in 1..=50 {
        world.step().expect("stable");
        assert_eq!(
            particles_inside(&world),
            0,
            "a particle left the container at step {step}"
        );
        if step % 10 == 0 {
            trace.push(angular_momentum(&world, &centre) / start);
        }
    }
    println!("{slip}: angular momentum left every 0.1 s: {trace:.4?}");
    trace[4]
}

/// (c) Free slip exerts only normal forces (each boundary force acts along
/// the line to its sample, which for a circle runs nearly through the
/// centre), so the spinning water keeps its angular momentum: more than
/// 95 % after 0.5 s. A no-slip wall with mu = 10 Pa s brakes it (spin-down
/// time of order R^2 / nu = 4 s): it must lose at least five times as much.
#[test]
fn free_slip_keeps_a_spinning_fluid_spinning_and_no_slip_brakes_it() {
    let free = spin_down("slip = \"free\"");
    let no = spin_down("slip = \"no\"\nviscosity = 10.0");
    println!("angular momentum left after 0.5 s: free slip {free:.4}, no slip {no:.4}");
    assert!(
        free > 0.95,
        "free slip kept only {free} of the angular momentum"
    );
    assert!(
        1.0 - no > 5.0 * (1.0 - free),
        "no slip lost {} against free slip's {}",
        1.0 - no,
        1.0 - free
    );
}

/// (d) Two-way coupling conserves momentum: without gravity, a disc of
/// water's density thrown at 0.5 m/s through a floating block of water far
/// from the walls hands momentum to the fluid, and fluid plus disc keep
/// the total to 1e-9 of the disc's initial momentum (every boundary force
/// is applied, reversed, to the disc in the same sub-step).
#[test]
fn fluid_and_body_conserve_momentum_together() {
    let disc = r#"
[[systems]]
kind = "rigid_body"
shape = { type = "sphere", radius = 0.06 }
position = [0.4, 0.5, 0.0]
motion = "dynamic"
density = 1000.0
velocity = [0.5, 0.0, 0.0]
"#;
    let mut world = scene(1.0, 0.0, 0.01, [0.25, 0.35, 0.75, 0.65], "", disc);
    let momentum = |world: &World| {
        let fluid = world.fluid().expect("fluid");
        let b = body(world);
        let mass = match b.motion {
            meshless_engine::rigid::Motion::Dynamic { mass, .. } => mass,
            _ => panic!("the disc is dynamic"),
        };
        let fluid_momentum: Vector = fluid.velocities.iter().sum::<Vector>() * fluid.params.mass;
        (fluid_momentum, b.state.velocity * mass)
    };
    let (f0, b0) = momentum(&world);
    let scale = b0.norm();
    let mut worst: f64 = 0.0;
    for _ in 0..20 {
        world.step().expect("stable");
        let (f, b) = momentum(&world);
        worst = worst.max((f + b - f0 - b0).norm() / scale);
    }
    let (f, b) = momentum(&world);
    println!(
        "after 0.2 s: disc momentum {:.4} of its initial, fluid {:.4}; worst drift of the total {worst:.2e}",
        b.x / b0.x,
        f.x / b0.x
    );
    assert!(b.x < 0.9 * b0.x, "the fluid did not slow the disc");
    assert!(
        worst < 1e-9,
        "total momentum drifted by {worst} of the disc's"
    );
}

/// Root-mean-square fluid speed.
fn rms_speed(world: &World) -> f64 {
    let fluid = world.fluid().expect("fluid");
    (fluid
        .velocities
        .iter()
        .map(|v| v.norm_squared())
        .sum::<f64>()
        / fluid.len() as f64)
        .sqrt()
}

/// (e) A kinematic paddle (a 0.04 x 0.2 m plate standing in 0.3 m of
/// water) oscillating 5 cm at 1 Hz (peak speed 0.31 m/s) makes waves: the
/// water's rms speed after 1 s is more than five times that of the same
/// tank with the paddle held still, and more than 10 % of the paddle's
/// peak speed.
#[test]
fn a_kinematic_paddle_moves_the_fluid() {
    let paddle = |motion: &str| {
        format!(
            r#"
[[systems]]
kind = "rigid_body"
shape = {{ type = "box", half_extents = [0.02, 0.1, 0.0] }}
position = [0.15, 0.2, 0.0]
{motion}
"#
        )
    };
    let moving = paddle(
        "motion = \"kinematic\"\noscillation = { amplitude = [0.05, 0.0, 0.0], frequency = 1.0 }",
    );
    let mut driven = scene(0.6, -G, 0.02, [0.0, 0.0, 0.6, 0.3], "", &moving);
    let mut still = scene(0.6, -G, 0.02, [0.0, 0.0, 0.6, 0.3], "", &paddle(""));
    for step in 1..=100 {
        driven.step().expect("stable");
        still.step().expect("stable");
        assert_eq!(
            particles_inside(&driven),
            0,
            "a particle entered the paddle at step {step}"
        );
    }
    let (v_driven, v_still) = (rms_speed(&driven), rms_speed(&still));
    let x = body(&driven).state.position.x;
    let projections = driven
        .fluid()
        .expect("fluid")
        .bodies()
        .expect("bodies")
        .projections();
    println!(
        "rms speed after 1 s: driven {v_driven:.4} m/s, still {v_still:.4} m/s; paddle at x = {x:.4}; \
         constraint projections {projections}"
    );
    assert!(
        (x - 0.15).abs() < 1e-9,
        "after one period the paddle is back at 0.15, not {x}"
    );
    assert!(
        v_driven > 5.0 * v_still,
        "driven {v_driven} m/s against {v_still} m/s"
    );
    assert!(v_driven > 0.1 * 0.05 * 2.0 * std::f64::consts::PI);
}

/// The shipped 3D scene builds, runs 0.05 s, and frames carry both bodies'
/// poses: the box (released above the water) falls, the paddle follows its
/// oscillation `0.04 sin(2 pi t)`.
#[test]
fn the_shipped_floating_box_scene_runs() {
    let scene = Scene::from_toml_str(include_str!("../../scenes/floating_box.toml"))
        .expect("shipped scene parses");
    let mut world = scene.build(&BuildOptions::default()).expect("valid");
    for _ in 0..5 {
        world.step().expect("stable");
    }
    let frame = world.frame();
    assert_eq!(frame.bodies.len(), 2);
    let (box_pose, paddle) = (frame.bodies[0], frame.bodies[1]);
    println!("after 0.05 s: box {box_pose:?}; paddle {paddle:?}");
    assert!(box_pose.position[1] < 0.4 && box_pose.velocity[1] < 0.0);
    let expected = 0.1 + 0.04 * (2.0 * std::f64::consts::PI * 0.05).sin();
    assert!((paddle.position[0] - expected).abs() < 1e-9);
}

/// A periodic channel (x wraps, no-slip walls at y = 0 and 0.3 m) driven
/// by a body force, with `body` as its rigid-body systems.
fn periodic_channel(body: &str) -> Result<World, meshless_engine::SceneError> {
    let text = format!(
        r#"
dimension = 2
periodic = [true, false, false]
gravity = [0.0, 0.0, 0.0]
[domain]
min = [0.0, 0.0, 0.0]
max = [0.6, 0.3, 0.0]
[time]
dt = 0.01
[[systems]]
kind = "fluid"
spacing = 0.015
stiffness = 2e3
viscosity = 1.0
wall_slip = "no"
body_force = ["1", "0", "0"]
[[systems.blocks]]
region = {{ min = [0.0, 0.0, 0.0], max = [0.6, 0.3, 0.0] }}
{body}
"#
    );
    Scene::from_toml_str(&text)?.build(&BuildOptions::default())
}

fn mean_flow(world: &World) -> f64 {
    let fluid = world.fluid().expect("fluid");
    fluid.velocities.iter().map(|v| v.x).sum::<f64>() / fluid.len() as f64
}

/// Flow past a cylinder in a periodic channel: a static disc a support
/// radius clear of the periodic faces is allowed, no particle ever enters
/// it, and it holds the driven flow back against the same channel
/// without it. A moving body, or one reaching a periodic face, is refused
/// with the field named.
#[test]
fn a_static_body_sits_in_a_periodic_channel() {
    let disc = r#"
[[systems]]
kind = "rigid_body"
shape = { type = "sphere", radius = 0.06 }
position = [0.3, 0.15, 0.0]
slip = "no"
"#;
    let mut with = periodic_channel(disc).expect("a static disc in a periodic channel");
    let mut without = periodic_channel("").expect("valid");
    for step in 0..30 {
        with.step().expect("stable");
        without.step().expect("stable");
        assert_eq!(
            particles_inside(&with),
            0,
            "a particle entered at step {step}"
        );
    }
    let (held, free) = (mean_flow(&with), mean_flow(&without));
    println!("mean flow after 0.3 s: {held:.4} m/s past the disc, {free:.4} m/s without");
    assert!(held > 0.0 && held < 0.9 * free, "{held} against {free}");

    let moving = disc.replace(
        "slip = \"no\"",
        "motion = \"kinematic\"\nvelocity = [0.1, 0.0, 0.0]",
    );
    let Err(meshless_engine::SceneError::Invalid { field, .. }) = periodic_channel(&moving) else {
        panic!("a moving body in a periodic domain was accepted")
    };
    assert_eq!(field, "systems[1].motion");
    let near = disc.replace("position = [0.3", "position = [0.05");
    let Err(meshless_engine::SceneError::Invalid { field, message }) = periodic_channel(&near)
    else {
        panic!("a body at a periodic face was accepted")
    };
    assert_eq!(field, "systems[1].position", "{message}");
}
